// Two recordings of the same run hold the same messages: node mcap_same_messages.js A.mcap B.mcap
// Read by @mcap/core's stream reader (CRCs checked); every message in order with the same topic,
// times, sequence and bytes, except /run, whose real-time factor and stage times are wall-clock
// figures (its simulated figures must still match). Used to check that a run resumed from checkpoints
// recorded what a run never stopped recorded.
"use strict";
const fs = require("fs");
const assert = require("assert/strict");
const protobuf = require("protobufjs");
require("protobufjs/ext/descriptor");
const { McapStreamReader } = require("@mcap/core");
const fzstd = require("fzstd");

function read(file) {
  const stream = new McapStreamReader({
    decompressHandlers: { zstd: (data, size) => fzstd.decompress(data, new Uint8Array(Number(size))) },
    validateCrcs: true,
  });
  stream.append(new Uint8Array(fs.readFileSync(file)));
  const channels = new Map(), schemas = new Map(), messages = [];
  let footer = false;
  for (let record; (record = stream.nextRecord()); ) {
    if (record.type === "Schema") schemas.set(record.id, record);
    else if (record.type === "Channel") channels.set(record.id, record);
    else if (record.type === "Message") messages.push(record);
    else if (record.type === "Footer") footer = true;
  }
  assert.ok(stream.done(), `${file}: bytes after the last record`);
  assert.ok(footer, `${file}: no footer (the run did not end)`);
  return { channels, schemas, messages };
}

const [a, b] = process.argv.slice(2).map(read);
assert.equal(a.messages.length, b.messages.length, "message counts differ");
const runType = (recording, channel) => {
  const schema = recording.schemas.get(channel.schemaId);
  return protobuf.Root.fromDescriptor(schema.data).lookupType(schema.name);
};
const counts = {};
for (let i = 0; i < a.messages.length; ++i) {
  const ma = a.messages[i], mb = b.messages[i];
  const ca = a.channels.get(ma.channelId), cb = b.channels.get(mb.channelId);
  const where = `message ${i} (${ca.topic} at ${ma.logTime} ns)`;
  assert.equal(ca.topic, cb.topic, `${where}: topics differ`);
  assert.equal(ma.logTime, mb.logTime, `${where}: log times differ`);
  assert.equal(ma.sequence, mb.sequence, `${where}: sequence numbers differ`);
  if (ca.topic === "/run") {
    const object = (recording, channel, data) => {
      const type = runType(recording, channel);
      return type.toObject(type.decode(data), { longs: String, defaults: true });
    };
    const ra = object(a, ca, ma.data), rb = object(b, cb, mb.data);
    for (const field of ["timestamp", "time", "particles", "resting_particles", "density_error_mean", "density_error_max", "time_step",
                         "pressure_iterations"])
      assert.deepEqual(ra[field], rb[field], `${where}: ${field} differs`);
  } else {
    assert.ok(Buffer.from(ma.data).equals(Buffer.from(mb.data)), `${where}: the message's bytes differ`);
  }
  counts[ca.topic] = (counts[ca.topic] || 0) + 1;
}
console.log(`same ${a.messages.length} messages: ${JSON.stringify(counts)}`);
