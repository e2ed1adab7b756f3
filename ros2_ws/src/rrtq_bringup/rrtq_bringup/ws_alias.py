"""Accept both names of the Foxglove WebSocket subprotocol in front of the SDK's server.

The official Foxglove SDK serves the Foxglove WebSocket protocol under the subprotocol
name ``foxglove.sdk.v1`` and refuses, at the handshake (HTTP 400), a client that offers
only the protocol's older name ``foxglove.websocket.v1`` — older Foxglove and Lichtblick
releases, ``@foxglove/ws-protocol`` clients, scripts. The messages under both names are
the same (serverInfo, advertise, subscribe, binary message data; Foxglove's stated
position, and what Lichtblick did when it added the new name). :class:`SubprotocolAlias`
therefore listens on the user's port and relays every connection to the SDK's server on
another loopback port: in the opening handshake it renames an offered
``foxglove.websocket.v1`` (when the client does not also offer ``foxglove.sdk.v1``) to
``foxglove.sdk.v1`` and the server's answer back, so each client gets the name it asked
for; after the handshake bytes pass through untouched, both ways. A client that offers
``foxglove.sdk.v1`` is relayed unchanged. Only 127.0.0.1 is ever bound or dialled.

Pure asyncio, no ROS: the live node runs it on a thread of its own (:meth:`start`).
"""

from __future__ import annotations

import asyncio
import re
import socket
import threading

SDK_NAME = 'foxglove.sdk.v1'
OLD_NAME = 'foxglove.websocket.v1'
HOST = '127.0.0.1'
MAX_HEADER = 64 * 1024
"""Bytes of an HTTP handshake head beyond which a connection is dropped."""

_PROTOCOL = re.compile(rb'^sec-websocket-protocol:[ \t]*(.*?)[ \t]*$', re.IGNORECASE | re.MULTILINE)


def rename_request(head: bytes) -> tuple[bytes, bool]:
    """The client's handshake head with ``OLD_NAME`` offered as ``SDK_NAME``.

    Returns the head to forward and whether it was renamed (only when the client offers
    the old name and not the new one; every other offer is left as it is).
    """
    offered = [p.strip() for m in _PROTOCOL.finditer(head)
               for p in m.group(1).decode('latin-1').split(',')]
    if OLD_NAME not in offered or SDK_NAME in offered:
        return head, False
    renamed = _PROTOCOL.sub(lambda m: m.group(0).replace(OLD_NAME.encode(), SDK_NAME.encode()),
                            head)
    return renamed, True


def rename_response(head: bytes) -> bytes:
    """The server's handshake answer with the chosen ``SDK_NAME`` given back as ``OLD_NAME``."""
    return _PROTOCOL.sub(lambda m: m.group(0).replace(SDK_NAME.encode(), OLD_NAME.encode()), head)


async def _read_head(reader: asyncio.StreamReader) -> bytes:
    """Bytes up to and including the blank line that ends an HTTP head."""
    return await reader.readuntil(b'\r\n\r\n')


async def _pipe(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
    try:
        while data := await reader.read(1 << 16):
            writer.write(data)
            await writer.drain()
    except (ConnectionError, asyncio.CancelledError):
        pass
    finally:
        writer.close()


class SubprotocolAlias:
    """Listen on ``HOST:port`` and relay to the SDK's server on ``HOST:upstream_port``.

    Parameters
    ----------
    listener
        A bound, listening TCP socket on 127.0.0.1 (the user's port); bound by the caller
        so that a port in use is found before anything starts.
    upstream_port
        The SDK server's port on 127.0.0.1.
    """

    def __init__(self, listener: socket.socket, upstream_port: int) -> None:
        host = listener.getsockname()[0]
        if host != HOST:
            raise ValueError(f'the live view listens on {HOST} only, not {host}')
        self._listener = listener
        self.port = int(listener.getsockname()[1])
        self.upstream_port = upstream_port
        self._loop = asyncio.new_event_loop()
        self._thread = threading.Thread(target=self._run, name='ws-alias', daemon=True)
        self._ready = threading.Event()
        self._server: asyncio.base_events.Server | None = None

    @staticmethod
    def bind(port: int) -> socket.socket:
        """A listening socket on 127.0.0.1:``port`` (0: any free port); OSError when in use."""
        sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        sock.bind((HOST, port))
        sock.listen(16)
        return sock

    def start(self) -> SubprotocolAlias:
        """Serve on a daemon thread; returns once the listener accepts connections."""
        self._thread.start()
        self._ready.wait(10.0)
        return self

    def stop(self) -> None:
        """Close the listener and every relayed connection; join the thread."""
        if self._thread.is_alive():
            self._loop.call_soon_threadsafe(self._shutdown)
            self._thread.join(5.0)

    def _run(self) -> None:
        asyncio.set_event_loop(self._loop)
        self._server = self._loop.run_until_complete(
            asyncio.start_server(self._relay, sock=self._listener, limit=MAX_HEADER))
        self._ready.set()
        self._loop.run_forever()
        self._loop.close()

    def _shutdown(self) -> None:
        if self._server is not None:
            self._server.close()
        for task in asyncio.all_tasks(self._loop):
            task.cancel()
        self._loop.call_later(0.1, self._loop.stop)

    async def _relay(self, client_r: asyncio.StreamReader, client_w: asyncio.StreamWriter) -> None:
        try:
            head, renamed = rename_request(await _read_head(client_r))
            server_r, server_w = await asyncio.open_connection(HOST, self.upstream_port,
                                                               limit=MAX_HEADER)
            server_w.write(head)
            await server_w.drain()
            answer = await _read_head(server_r)
            client_w.write(rename_response(answer) if renamed else answer)
            await client_w.drain()
        except (asyncio.IncompleteReadError, asyncio.LimitOverrunError, ConnectionError, OSError):
            client_w.close()
            return
        try:
            await asyncio.gather(_pipe(client_r, server_w), _pipe(server_r, client_w))
        except asyncio.CancelledError:      # stop(): the connections end with the server
            client_w.close()
            server_w.close()
