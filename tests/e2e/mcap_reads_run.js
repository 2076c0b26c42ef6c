// Reads a run's run.mcap with readers M3DP did not write and checks what it holds:
//   node tests/e2e/mcap_reads_run.js RUN_DIR URDF [--killed]
// - @mcap/core's stream reader reads every record with CRCs checked (chunks decompressed by fzstd);
//   the data section's CRC is recomputed with @foxglove/crc;
// - @mcap/core's indexed reader opens the summary (its CRC checked), and its chunk and message
//   indexes give the same messages as the stream, and the statistics count them;
// - every message decodes against its schema record's FileDescriptorSet (what Foxglove, Lichtblick
//   and Rerun read), and the foxglove.* ones decode the same against @foxglove/schemas' own
//   definitions;
// - the content: every UR10 link of the URDF in /scene and on /tf in every frame, the particles'
//   point cloud well formed and as many as the run's summary says, times that advance, the joints'
//   positions, velocities and efforts (the shoulder holding the arm up), the cameras' images sized as
//   their calibrations say, in their optical frames; the print against its design on /quality and
//   the printed mesh coloured by its deviation on /quality/deviation, which read back agree.
// With --killed the file is what a run killed by SIGKILL left: summary.json says "running" (no final figures), and every record up to
// the cut must still read and decode.
"use strict";
const fs = require("fs");
const path = require("path");
const assert = require("assert/strict");
const protobuf = require("protobufjs");
require("protobufjs/ext/descriptor");
const { McapStreamReader, McapIndexedReader } = require("@mcap/core");
const { crc32 } = require("@foxglove/crc");
const fzstd = require("fzstd");
const { generateProto, foxgloveMessageSchemas, foxgloveEnumSchemas } = require("@foxglove/schemas/internal");

const [runDir, urdfFile] = process.argv.slice(2).filter((arg) => !arg.startsWith("--"));
const killed = process.argv.includes("--killed");
const file = path.join(runDir, "run.mcap");
const bytes = new Uint8Array(fs.readFileSync(file));
const decompressHandlers = { zstd: (data, size) => fzstd.decompress(data, new Uint8Array(Number(size))) };

// @foxglove/schemas' definitions of every foxglove.* message, as its own generator writes them.
const foxgloveRoot = new protobuf.Root();
for (const schema of Object.values(foxgloveMessageSchemas)) {
  const enums = Object.values(foxgloveEnumSchemas).filter((e) => e.parentSchemaName === schema.name);
  protobuf.parse(generateProto(schema, enums), foxgloveRoot, { keepCase: true });
}
for (const wkt of ["timestamp", "duration"]) foxgloveRoot.addJSON(protobuf.common[`google/protobuf/${wkt}.proto`].nested);
foxgloveRoot.resolveAll();

const toObjectOptions = { longs: String, bytes: String, enums: Number, defaults: false };

// 1. Every record in file order, as a streaming reader (a viewer of a live file) meets it.
const stream = new McapStreamReader({ decompressHandlers, validateCrcs: true });
stream.append(bytes);
const records = [];
for (let record; (record = stream.nextRecord()); ) records.push(record);
assert.equal(records[0].type, "Header", "the first record is the header");
const schemas = new Map(), channels = new Map(), messages = [];
const types = new Map();  // schema id → { file: protobufjs Type from the file, foxglove: from @foxglove/schemas }
for (const record of records) {
  if (record.type === "Schema") {
    assert.equal(record.encoding, "protobuf");
    const type = protobuf.Root.fromDescriptor(record.data).lookupType(record.name);
    types.set(record.id, { file: type, foxglove: record.name.startsWith("foxglove.") ? foxgloveRoot.lookupType(record.name) : null });
    schemas.set(record.id, record);
  } else if (record.type === "Channel") {
    assert.ok(schemas.has(record.schemaId), `channel ${record.topic} before its schema`);
    assert.equal(record.messageEncoding, "protobuf");
    channels.set(record.id, record);
  } else if (record.type === "Message") {
    assert.ok(channels.has(record.channelId), `a message on channel ${record.channelId} before the channel`);
    messages.push(record);
  }
}
assert.ok(messages.length > 0, "no messages");

// 2. Every message decodes, and foxglove.* ones decode the same by @foxglove/schemas' definitions.
const decoded = messages.map((message) => {
  const channel = channels.get(message.channelId);
  const { file: fileType, foxglove } = types.get(channel.schemaId);
  const value = fileType.decode(message.data);
  const error = fileType.verify(value);
  assert.equal(error, null, `${channel.topic}: ${error}`);
  if (foxglove) {
    const ours = JSON.stringify(fileType.toObject(value, toObjectOptions));
    const theirs = JSON.stringify(foxglove.toObject(foxglove.decode(message.data), toObjectOptions));
    assert.equal(ours, theirs, `${channel.topic} decodes differently by @foxglove/schemas`);
  }
  return { topic: channel.topic, logTime: message.logTime, sequence: message.sequence, value };
});

const byTopic = (topic) => decoded.filter((message) => message.topic === topic);
const topics = new Set([...channels.values()].map((channel) => channel.topic));
for (const topic of ["/scene", "/tf", "/particles", "/printed", "/joints", "/run"]) assert.ok(topics.has(topic), `no ${topic} channel`);

// 3. The content. Links: every URDF link with a collision, in the first scene update and on /tf.
const urdf = fs.readFileSync(urdfFile, "utf8");
const urdfLinks = [...urdf.matchAll(/<link\s+name="([^"]+)"\s*>([\s\S]*?)<\/link>/g)]
  .filter((match) => match[2].includes("<collision"))
  .map((match) => `ur10/${match[1]}`);
assert.ok(urdfLinks.length >= 6, `the URDF has ${urdfLinks.length} links with collisions`);
const scene = byTopic("/scene")[0].value;
const entityIds = new Set(scene.entities.map((entity) => entity.id));
for (const link of urdfLinks) assert.ok(entityIds.has(link), `/scene has no entity ${link}`);
for (const entity of scene.entities.filter((e) => urdfLinks.includes(e.id))) {
  assert.equal(entity.frame_id, entity.id, `${entity.id} is not drawn in its own frame`);
  assert.ok(entity.triangles.length > 0 && entity.triangles[0].points.length >= 3, `${entity.id} has no triangles`);
}
assert.ok(scene.entities.some((entity) => entity.id.startsWith("path/") && entity.lines.length > 0), "no commanded path");
const transforms = byTopic("/tf");
for (const { value } of transforms) {
  const children = new Set(value.transforms.map((transform) => transform.child_frame_id));
  for (const link of urdfLinks) assert.ok(children.has(link), `a /tf message has no ${link}`);
  assert.ok([...children].some((child) => child.startsWith("nozzle/")), "a /tf message has no nozzle frame");
  for (const transform of value.transforms) {
    const q = transform.rotation;
    const norm = Math.hypot(q.x ?? 0, q.y ?? 0, q.z ?? 0, q.w ?? 0);
    assert.ok(Math.abs(norm - 1) < 1e-5, `${transform.child_frame_id}: rotation of norm ${norm}`);
  }
}

// Particles: packed points whose fields fit the stride, positions finite and near the print.
const clouds = byTopic("/particles");
let lastCount = 0;
for (const { value } of clouds) {
  const fieldNames = value.fields.map((field) => field.name);
  for (const name of ["x", "y", "z", "vx", "density", "material", "id"]) assert.ok(fieldNames.includes(name), `no point field ${name}`);
  assert.equal(value.data.length % value.point_stride, 0, "the data is not whole points");
  const count = value.data.length / value.point_stride;
  const view = new DataView(value.data.buffer, value.data.byteOffset, value.data.byteLength);
  const offset = (name) => value.fields.find((field) => field.name === name).offset;
  for (let i = 0; i < count; ++i)
    for (const axis of ["x", "y", "z"]) {
      const coordinate = view.getFloat32(i * value.point_stride + offset(axis), true);
      assert.ok(Number.isFinite(coordinate) && Math.abs(coordinate) < 10, `particle ${i} ${axis} = ${coordinate}`);
    }
  lastCount = count;
}
assert.ok(lastCount > 0, "no particles in the last frame");

// Times: frames advance, every frame has its transforms, particles, joints and numbers.
const runTimes = byTopic("/run").map((message) => message.value.time);
for (let i = 1; i < runTimes.length; ++i) assert.ok(runTimes[i] > runTimes[i - 1], `/run time goes back at ${i}`);
// The nozzle's volume balance on /run: what was asked for left the exit, was lost while blocked, or
// went into the bore beyond what primed it, within the layers due but not yet emitted.
for (const nozzle of byTopic("/run").at(-1).value.nozzles) {
  const { volume_commanded: commanded, volume_laid: laid, volume_in_bore: inBore, volume_primed: primed, volume_lost: lost } = nozzle;
  assert.ok([commanded, laid, inBore, primed, lost].every(Number.isFinite), `${nozzle.name}: ${JSON.stringify(nozzle)}`);
  assert.ok(inBore >= 0 && (primed > 0) === (inBore > 0), `${nozzle.name}: ${inBore} m³ in its bore, ${primed} primed it`);
  if (commanded > 0) assert.ok(laid > 0 && Math.abs(commanded - (laid + lost + inBore - primed)) < 0.25 * commanded,
    `${nozzle.name}: ${commanded} m³ commanded, ${laid} laid, ${lost} lost, ${inBore} in the bore, ${primed} primed it`);
}
for (const topic of ["/tf", "/particles", "/joints"]) assert.ok(Math.abs(byTopic(topic).length - runTimes.length) <= 1, `${topic}: ${byTopic(topic).length} messages for ${runTimes.length} frames`);
const joints = byTopic("/joints").at(-1).value;
assert.equal(joints.robot, "ur10");
assert.equal(joints.names.length, 6, `joints ${joints.names}`);
for (const field of ["positions", "velocities", "efforts"]) {
  assert.equal(joints[field].length, 6, `${field}: ${joints[field]}`);
  assert.ok(joints[field].every(Number.isFinite), `${field}: ${joints[field]}`);
}
// The shoulder's servo holds the arm up against gravity: tens of N·m.
const shoulderEffort = joints.efforts[joints.names.indexOf("shoulder_lift_joint")];
assert.ok(Math.abs(shoulderEffort) > 5, `the shoulder lift exerts ${shoulderEffort} N·m`);

// Cameras (the scene's wrist and overview cameras): each image as big as its calibration says, in
// its optical frame, and the frame on /tf.
const cameraNames = [...topics].filter((topic) => /^\/camera\/[^/]+\/calibration$/.test(topic)).map((topic) => topic.split("/")[2]);
assert.deepEqual(cameraNames.sort(), ["overview", "wrist"], `cameras ${cameraNames}`);
for (const name of cameraNames) {
  const calibrations = byTopic(`/camera/${name}/calibration`);
  assert.ok(calibrations.length >= 2, `${name}: ${calibrations.length} calibrations`);
  const { width, height, K, frame_id } = calibrations[0].value;
  assert.equal(frame_id, `camera/${name}/optical`);
  assert.ok(K[0] > 0 && K[4] === K[0] && Math.abs(K[2] - width / 2) < 1e-9 && Math.abs(K[5] - height / 2) < 1e-9, `${name}: K ${K}`);
  for (const [topic, encoding, bytesPerPixel] of [["image", "rgb8", 3], ["depth", "32FC1", 4], ["segmentation", "16UC1", 2]]) {
    const images = byTopic(`/camera/${name}/${topic}`);
    assert.equal(images.length, calibrations.length, `${name}/${topic}: ${images.length} images for ${calibrations.length} calibrations`);
    for (const { value } of images) {
      assert.equal(value.encoding, encoding);
      assert.equal(value.width, width);
      assert.equal(value.height, height);
      assert.equal(value.data.length, width * height * bytesPerPixel, `${name}/${topic}: ${value.data.length} bytes`);
      assert.equal(value.frame_id, `camera/${name}/optical`);
    }
  }
  const clouds = byTopic(`/camera/${name}/points`);
  if (clouds.length === 0) continue;  // a camera without <point_cloud>
  const cloud = clouds.at(-1).value;
  assert.equal(cloud.frame_id, `camera/${name}/optical`);
  const points = cloud.data.length / cloud.point_stride;
  assert.ok(points > 0 && points <= width * height, `${name}: ${points} points`);
  const view = new DataView(cloud.data.buffer, cloud.data.byteOffset, cloud.data.byteLength);
  const zOffset = cloud.fields.find((field) => field.name === "z").offset;
  for (let i = 0; i < points; ++i) assert.ok(view.getFloat32(i * cloud.point_stride + zOffset, true) > 0, `${name}: a point behind the camera`);
  assert.ok(transforms.every(({ value }) => value.transforms.some((t) => t.child_frame_id === `camera/${name}/optical`)),
    `${name}'s optical frame is not on /tf`);
}

// The print against its design (a finished run: its final mesh closes the file): /quality's figures
// and /quality/deviation, the printed mesh with a colour per vertex by the documented map. The
// deviations read back from the colours make the histogram /quality sends, and its p95.
let qualityLine = "";
if (!killed) {
  const qualities = byTopic("/quality"), deviations = byTopic("/quality/deviation");
  assert.ok(qualities.length >= 1, "no /quality message");
  assert.equal(deviations.length, qualities.length, "a /quality without its coloured mesh");
  const quality = qualities.at(-1).value, entity = deviations.at(-1).value.entities[0];
  assert.equal(entity.id, "printed_deviation");
  const triangles = entity.triangles[0];
  assert.ok(triangles.points.length > 100, `the coloured mesh has ${triangles.points.length} vertices`);
  assert.equal(triangles.colors.length, triangles.points.length, "not one colour per vertex");
  assert.equal(Number(quality.vertices), triangles.points.length);
  const metadata = Object.fromEntries(entity.metadata.map(({ key, value }) => [key, value]));
  const range = Number(metadata.deviation_range_m);
  assert.ok(range > 0 && Math.abs(range - quality.deviation_range) < 1e-12, `range ${metadata.deviation_range_m} vs ${quality.deviation_range}`);
  const white = 0.95, blue = [0.23, 0.3, 0.75], red = [0.75, 0.1, 0.1];
  const recovered = triangles.colors.map((c) => {
    const t = (c.b ?? 0) > (c.r ?? 0) ? -(white - (c.r ?? 0)) / (white - blue[0]) : (white - (c.g ?? 0)) / (white - red[1]);
    assert.ok(t >= -1 - 1e-9 && t <= 1 + 1e-9, `a colour off the map: ${JSON.stringify(c)}`);
    return t * range;
  });
  const edges = quality.histogram_edges, counts = quality.histogram_counts.map(Number), bins = counts.length;
  assert.equal(edges.length, bins + 1);
  assert.ok(Math.abs(edges[0] + range) < 1e-12 && Math.abs(edges[bins] - range) < 1e-12, `edges ${edges[0]} … ${edges[bins]}`);
  assert.equal(counts.reduce((a, b) => a + b, 0), triangles.points.length, "the histogram does not count every vertex");
  const ours = new Array(bins).fill(0);
  for (const value of recovered) ++ours[Math.min(bins - 1, Math.max(0, Math.floor(((value + range) / (2 * range)) * bins)))];
  const moved = ours.reduce((sum, count, b) => sum + Math.abs(count - counts[b]), 0);
  assert.ok(moved <= 0.01 * triangles.points.length, `the colours' histogram differs by ${moved} counts: ${ours} vs ${counts}`);
  const magnitudes = recovered.map(Math.abs).sort((a, b) => a - b);
  const p95 = magnitudes[Math.min(magnitudes.length - 1, Math.floor(0.95 * magnitudes.length))];
  assert.ok(Math.abs(p95 - Math.min(quality.deviation_p95, range)) < 0.02 * range, `p95 from colours ${p95}, sent ${quality.deviation_p95}`);
  // Layers: the first is printed, its bead within a factor of two of its design.
  const printedLayers = quality.layers.filter((layer) => layer.sections > (layer.empty ?? 0));
  assert.ok(printedLayers.length >= 1, `layers ${JSON.stringify(quality.layers)}`);
  for (const layer of printedLayers)
    assert.ok(layer.width > 0.5 * layer.design_width && layer.width < 2 * layer.design_width, `layer ${layer.layer ?? 0}: ${JSON.stringify(layer)}`);
  assert.ok(quality.fill_designed > 0, "no designed volume");
  qualityLine = `; quality at ${quality.time.toFixed(2)} s: ${triangles.points.length} vertices, p95 ${(1e3 * quality.deviation_p95).toFixed(2)} mm ` +
    `(from colours ${(1e3 * p95).toFixed(2)}), ${printedLayers.length} layers printed`;
}

if (killed) {
  assert.ok(!records.some((record) => record.type === "Footer"), "a killed run's file has a footer");
  console.log(`read ${records.length} records of a killed run: ${messages.length} messages, ${runTimes.length} frames, last at ${runTimes.at(-1)} s, ${lastCount} particles`);
  process.exit(0);
}

// 4. A finished file: data end's CRC, the summary through the indexed reader, the same messages.
const dataEnd = records.find((record) => record.type === "DataEnd");
assert.ok(dataEnd, "no data end record");
assert.ok(stream.done(), "the stream reader did not reach the footer");
(async () => {
  const readable = {
    size: async () => BigInt(bytes.length),
    read: async (offset, length) => bytes.subarray(Number(offset), Number(offset + length)),
  };
  const indexed = await McapIndexedReader.Initialize({ readable, decompressHandlers });
  assert.equal(crc32(bytes.subarray(0, Number(indexed.dataEndOffset))), dataEnd.dataSectionCrc, "data section CRC");
  const statistics = indexed.statistics;
  assert.equal(statistics.messageCount, BigInt(messages.length), "statistics' message count");
  assert.equal(statistics.channelCount, channels.size);
  assert.equal(statistics.schemaCount, schemas.size);
  assert.equal(statistics.chunkCount, indexed.chunkIndexes.length);
  for (const [channelId, count] of statistics.channelMessageCounts)
    assert.equal(count, BigInt(messages.filter((message) => message.channelId === channelId).length), `channel ${channelId}'s count`);
  const key = (message) => `${message.channelId}/${message.sequence}/${message.logTime}`;
  const indexedKeys = [];
  for await (const message of indexed.readMessages()) indexedKeys.push(key(message));
  const streamKeys = messages.map(key);
  assert.deepEqual([...indexedKeys].sort(), [...streamKeys].sort(), "the index gives other messages than the stream");
  for (const topic of ["/tf", "/particles"]) {
    let count = 0;
    for await (const message of indexed.readMessages({ topics: [topic] })) count += message ? 1 : 0;
    assert.equal(count, byTopic(topic).length, `${topic} through the index`);
  }
  const summary = JSON.parse(fs.readFileSync(path.join(runDir, "summary.json"), "utf8"));
  assert.equal(lastCount, summary.particles, `the last frame has ${lastCount} particles, the summary ${summary.particles}`);
  assert.equal(Number(statistics.messageCount), summary.recording.messages, "summary.json's message count");
  console.log(
    `read ${records.length} records, ${messages.length} messages on ${channels.size} channels in ${indexed.chunkIndexes.length} chunks; ` +
      `${runTimes.length} frames to ${runTimes.at(-1).toFixed(3)} s; ${urdfLinks.length} links; ${lastCount} particles${qualityLine}`,
  );
})().catch((error) => {
  console.error(error);
  process.exit(1);
});
