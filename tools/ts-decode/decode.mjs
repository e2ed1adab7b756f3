// Independent check of a recording with the libraries Foxglove itself uses:
// @mcap/core reads the file, @foxglove/rosmsg parses the schema text and
// @foxglove/rosmsg2-serialization decodes every CDR message.
// Usage: node decode.mjs RUN.mcap   (after `npm ci` in this folder)
import { open } from 'node:fs/promises';
import { McapIndexedReader } from '@mcap/core';
import { parse } from '@foxglove/rosmsg';
import { MessageReader } from '@foxglove/rosmsg2-serialization';
import { decompress } from 'fzstd';

const path = process.argv[2];
const handle = await open(path, 'r');
const readable = {
  size: async () => BigInt((await handle.stat()).size),
  read: async (offset, length) => {
    const buffer = new Uint8Array(Number(length));
    await handle.read(buffer, 0, Number(length), Number(offset));
    return buffer;
  },
};
const reader = await McapIndexedReader.Initialize({
  readable,
  decompressHandlers: { zstd: (data, size) => decompress(data, new Uint8Array(Number(size))) },
});
const readers = new Map();
const counts = {};
for (const [id, channel] of reader.channelsById) {
  const schema = reader.schemasById.get(channel.schemaId);
  const text = new TextDecoder().decode(schema.data);
  readers.set(id, new MessageReader(parse(text, { ros2: true })));
  counts[channel.topic] = { type: schema.name, count: 0, qos: channel.metadata.get('offered_qos_profiles'),
                            hash: channel.metadata.get('topic_type_hash') };
}
for await (const message of reader.readMessages()) {
  const channel = reader.channelsById.get(message.channelId);
  readers.get(message.channelId).readMessage(message.data);
  counts[channel.topic].count += 1;
}
console.log(JSON.stringify({ profile: reader.header.profile, topics: counts }, null, 1));
await handle.close();
