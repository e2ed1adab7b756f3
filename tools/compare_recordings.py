"""Compare the messages of two recordings of the same lock-step run, byte for byte.

A lock-step run is a function of its scenario and seed, so two recordings of it (before
and after a change that must not alter behaviour) carry the same CDR bytes on every
topic, except for fields that measure wall time. Those bytes are zeroed in place before
the comparison (their offset found by serialising the message with two marker values);
every other byte is compared as recorded. A run ends when the supervisor's pause reaches
the simulator, which may take a few more steps in one recording than in the other: a
recording that equals the other's first messages and differs only by its last few is
reported as such. A step that was resent (the simulator republishes its
odometry after a stall, and every node answers it again) repeats a message byte for
byte: repeats of an earlier message of the same topic are dropped on both sides.

    python tools/compare_recordings.py A.mcap B.mcap [--topics /odom /cmd_force ...]

Exit status 0 when every compared topic is identical, 1 otherwise.
"""

from __future__ import annotations

import argparse
import importlib
import struct
import sys
from collections import defaultdict

from mcap.reader import make_reader

# Fields that hold wall-clock measurements: zeroed before comparing.
WALL_FIELDS = {
    '/controller/state': ('step_ms',),
    '/planner/stats': ('cycle_ms', 'last_repair_ms'),
}
DEFAULT_TOPICS = ('/odom', '/cmd_force', '/controller/state')
SKIPPED = ('/rosout', '/parameter_events')


def _message_class(type_name: str) -> type:
    package, interface, name = type_name.split('/')
    return getattr(importlib.import_module(f'{package}.{interface}'), name)


_MARKERS = (1.2345678901234567e-300, 7.654321098765432e-301)


def _masked(data: bytes, cls: type, fields: tuple[str, ...]) -> bytes:
    """``data`` with the float64 ``fields`` zeroed where they sit in the CDR (little endian)."""
    from rclpy.serialization import deserialize_message, serialize_message
    msg = deserialize_message(data, cls)
    out = bytearray(data)
    for name in fields:
        encoded = []
        for marker in _MARKERS:
            setattr(msg, name, marker)
            encoded.append(bytes(serialize_message(msg)))
        first, second = (struct.pack('<d', m) for m in _MARKERS)
        offset = encoded[0].find(first)
        if offset < 0 or encoded[1][offset:offset + 8] != second:
            raise ValueError(f'{cls.__name__}.{name}: not found in the serialised message')
        out[offset:offset + 8] = bytes(8)
    return bytes(out)


def read(path: str, topics: set[str] | None) -> tuple[dict[str, list[bytes]], dict[str, int]]:
    """Per topic the distinct messages in recording order, and how many repeats were dropped."""
    out: dict[str, list[bytes]] = defaultdict(list)
    seen: dict[str, set[bytes]] = defaultdict(set)
    repeats: dict[str, int] = defaultdict(int)
    with open(path, 'rb') as f:
        reader = make_reader(f)
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            topic = channel.topic
            if topic in SKIPPED or (topics is not None and topic not in topics):
                continue
            data = bytes(message.data)
            if topic in WALL_FIELDS:
                data = _masked(data, _message_class(schema.name), WALL_FIELDS[topic])
            if data in seen[topic]:
                repeats[topic] += 1
                continue
            seen[topic].add(data)
            out[topic].append(data)
    return out, repeats


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('a')
    ap.add_argument('b')
    ap.add_argument('--topics', nargs='*', default=list(DEFAULT_TOPICS),
                    help=f'topics to compare (default {" ".join(DEFAULT_TOPICS)}); '
                    "'all' for every topic but /rosout")
    ap.add_argument('--tail', type=int, default=10,
                    help='messages one recording may have beyond the other at its end '
                    '(default 10: the pause races the stepping, most in processes mode)')
    args = ap.parse_args(argv)
    topics = None if args.topics == ['all'] else set(args.topics)
    a, rep_a = read(args.a, topics)
    b, rep_b = read(args.b, topics)
    names = sorted(set(a) | set(b)) if topics is None else sorted(topics)
    ok = True
    for topic in names:
        ma, mb = a.get(topic, []), b.get(topic, [])
        first = next((i for i, (x, y) in enumerate(zip(ma, mb)) if x != y), None)
        if first is not None:
            verdict, note = 'DIFFERENT', f'  first difference at message {first}'
        elif len(ma) == len(mb):
            verdict, note = 'identical', ''
        elif abs(len(ma) - len(mb)) <= args.tail:
            verdict, note = 'identical', (f'  (common prefix of {min(len(ma), len(mb))}; '
                                          'the longer run stepped on until the pause arrived)')
        else:
            verdict, note = 'DIFFERENT', '  one is a prefix of the other'
        ok &= verdict == 'identical'
        masked = f" (masked: {', '.join(WALL_FIELDS[topic])})" if topic in WALL_FIELDS else ''
        print(f'{verdict}  {topic}: {len(ma)} vs {len(mb)} messages, repeats dropped '
              f'{rep_a.get(topic, 0)}/{rep_b.get(topic, 0)}{masked}{note}')
    return 0 if ok else 1


if __name__ == '__main__':
    sys.exit(main())
