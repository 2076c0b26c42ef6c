// The live stream, watched by the Foxglove WebSocket client we did not write (@foxglove/ws-protocol
// over the `ws` package):
//   node tests/e2e/live_stream.js M3DP SCENE URDF SLOW_SCENE OUT
// 1. `m3dp run SCENE --serve 0 --pace 1`: two clients at once; the first subscribes to everything
//    and gets the scene with every UR10 link, the transforms of every link and a particle frame,
//    then disconnects; it connects again mid-run and gets the scene first, then the stream.
// 2. The same run without a client: every particle frame bit-identical.
// 3. A client that stops reading (SLOW_SCENE has tens of thousands of particles per frame): the run
//    goes on, another client keeps getting frames, the stalled one's old frames are dropped, and it
//    is told so when it reads again; summary.json counts the drops.
"use strict";
const { spawn } = require("child_process");
const fs = require("fs");
const path = require("path");
const assert = require("assert/strict");
const protobuf = require("protobufjs");
require("protobufjs/ext/descriptor");
const { FoxgloveClient } = require("@foxglove/ws-protocol");
const WebSocket = require("ws");

const [m3dp, scene, urdfFile, slowScene, out] = process.argv.slice(2);
const sleep = (ms) => new Promise((resolve) => setTimeout(resolve, ms));

/// Resolves once `condition()` holds, polling; rejects after `seconds` with `what`.
async function until(condition, seconds, what) {
  const deadline = Date.now() + seconds * 1000;
  while (!condition()) {
    if (Date.now() > deadline) throw new Error(`timed out after ${seconds} s waiting for ${what}`);
    await sleep(20);
  }
}

/// `m3dp run` with the given arguments; resolves the live port it prints and the exit promise.
function startRun(args) {
  const child = spawn(m3dp, args, { stdio: ["ignore", "pipe", "pipe"] });
  let stdout = "", stderr = "";
  const exited = new Promise((resolve) => child.on("exit", (code, signal) => resolve({ code, signal, stdout, stderr })));
  const port = new Promise((resolve, reject) => {
    child.stdout.on("data", (chunk) => {
      stdout += chunk;
      const match = stdout.match(/live at ws:\/\/127\.0\.0\.1:(\d+)/);
      if (match) resolve(Number(match[1]));
    });
    child.stderr.on("data", (chunk) => (stderr += chunk));
    child.on("exit", (code) => reject(new Error(`m3dp exited (${code}) before serving:\n${stdout}\n${stderr}`)));
  });
  return { child, port, exited };
}

/// A client: decodes every message by the schema its channel advertised (protobuf descriptors).
class Viewer {
  constructor(port, name) {
    this.name = name;
    this.ws = new WebSocket(`ws://127.0.0.1:${port}`, [FoxgloveClient.SUPPORTED_SUBPROTOCOL]);
    this.client = new FoxgloveClient({ ws: this.ws });
    this.channels = new Map();     // id → { topic, type }
    this.topicOfSubscription = new Map();
    this.received = [];            // { topic, value, receivedAt }
    this.statuses = [];
    this.times = [];
    this.closed = false;
    this.serverInfo = null;
    this.client.on("serverInfo", (info) => (this.serverInfo = info));
    this.client.on("advertise", (channels) => {
      for (const channel of channels) {
        assert.equal(channel.encoding, "protobuf");
        const descriptor = Buffer.from(channel.schema, "base64");
        const type = protobuf.Root.fromDescriptor(descriptor).lookupType(channel.schemaName);
        this.channels.set(channel.id, { topic: channel.topic, type });
      }
    });
    this.client.on("message", ({ subscriptionId, data }) => {
      const topic = this.topicOfSubscription.get(subscriptionId);
      assert.ok(topic, `${name}: a message for subscription ${subscriptionId}, which it never made`);
      const type = [...this.channels.values()].find((channel) => channel.topic === topic).type;
      const bytes = new Uint8Array(data.buffer, data.byteOffset, data.byteLength);
      this.received.push({ topic, value: type.decode(bytes), receivedAt: Date.now() });
    });
    this.client.on("status", (status) => this.statuses.push(status));
    this.client.on("time", ({ timestamp }) => this.times.push(timestamp));
    this.client.on("close", () => (this.closed = true));
    this.client.on("error", (error) => this.statuses.push({ level: 2, message: String(error) }));
  }
  async subscribe(topics) {
    await until(() => topics.every((topic) => [...this.channels.values()].some((c) => c.topic === topic)), 10, `${this.name}: advertised ${topics}`);
    for (const topic of topics) {
      const [id] = [...this.channels.entries()].find(([, channel]) => channel.topic === topic);
      this.topicOfSubscription.set(this.client.subscribe(id), topic);
    }
  }
  of(topic) {
    return this.received.filter((message) => message.topic === topic);
  }
  particleCounts() {
    return this.of("/particles").map(({ value }) => value.data.length / value.point_stride);
  }
  close() {
    this.client.close();
  }
}

const allTopics = ["/scene", "/tf", "/particles", "/printed", "/joints", "/run"];
const urdf = fs.readFileSync(urdfFile, "utf8");
const links = [...urdf.matchAll(/<link\s+name="([^"]+)"\s*>([\s\S]*?)<\/link>/g)]
  .filter((match) => match[2].includes("<collision"))
  .map((match) => `ur10/${match[1]}`);

function checkScene(viewer) {
  const first = viewer.received[0];
  assert.ok(first, `${viewer.name} received nothing`);
  assert.equal(first.topic, "/scene", `${viewer.name}'s first message is on ${first.topic}, not the scene`);
  const ids = new Set(first.value.entities.map((entity) => entity.id));
  for (const link of links) assert.ok(ids.has(link), `${viewer.name}: the scene has no ${link}`);
  assert.ok([...ids].some((id) => id.startsWith("path/")), `${viewer.name}: the scene has no path`);
}
function hasAllLinks(viewer) {
  return viewer.of("/tf").some(({ value }) => {
    const children = new Set(value.transforms.map((transform) => transform.child_frame_id));
    return links.every((link) => children.has(link));
  });
}

async function liveRun() {
  const folder = path.join(out, "live");
  const run = startRun(["run", scene, "-o", folder, "--until", "3.5", "--serve", "0", "--pace", "1", "--quiet"]);
  const port = await run.port;
  // Two clients at once.
  const first = new Viewer(port, "first");
  const second = new Viewer(port, "second");
  await first.subscribe(allTopics);
  await second.subscribe(["/tf", "/particles"]);
  assert.equal(first.serverInfo.name, "m3dp");
  await until(() => hasAllLinks(first) && first.particleCounts().some((count) => count > 0), 20, "first: every link's transform and a particle frame");
  checkScene(first);
  const firstCount = Math.max(...first.particleCounts());
  first.close();
  await sleep(300);
  // Reconnect mid-run: the scene first, then the stream.
  const again = new Viewer(port, "again");
  await again.subscribe(allTopics);
  await until(() => hasAllLinks(again) && again.particleCounts().some((count) => count > firstCount), 20, "again: the stream after reconnecting");
  checkScene(again);
  assert.ok(again.times.length > 0, "no Time messages");
  const result = await run.exited;
  assert.equal(result.code, 0, `m3dp exited with ${result.code}:\n${result.stderr}`);
  await until(() => second.closed && again.closed, 5, "the server to close its connections at the end");
  assert.ok(second.particleCounts().length >= 3, `second got ${second.particleCounts().length} particle frames`);
  const summary = JSON.parse(fs.readFileSync(path.join(folder, "summary.json"), "utf8"));
  assert.equal(summary.live.clients, 3, `summary.json counts ${summary.live.clients} clients`);
  console.log(`live: 3 clients; first got ${first.received.length} messages, then ${again.received.length} after reconnecting, ` +
    `second ${second.particleCounts().length} particle frames (last ${second.particleCounts().at(-1)} particles)`);
  return folder;
}

async function sameAsWithoutClients(liveFolder) {
  const folder = path.join(out, "alone");
  fs.rmSync(folder, { recursive: true, force: true });
  const run = spawn(m3dp, ["run", scene, "-o", folder, "--until", "3.5", "--quiet"], { stdio: "ignore" });
  const code = await new Promise((resolve) => run.on("exit", resolve));
  assert.equal(code, 0);
  const frames = fs.readdirSync(path.join(folder, "particles")).sort();
  assert.deepEqual(fs.readdirSync(path.join(liveFolder, "particles")).sort(), frames, "other particle frames");
  for (const frame of frames) {
    const alone = fs.readFileSync(path.join(folder, "particles", frame));
    const live = fs.readFileSync(path.join(liveFolder, "particles", frame));
    assert.ok(alone.equals(live), `${frame} differs with clients connected`);
  }
  console.log(`bit-identical: ${frames.length} particle frames with and without live clients`);
}

async function slowClient() {
  const folder = path.join(out, "slow");
  const run = startRun(["run", slowScene, "-o", folder, "--serve", "0", "--quiet"]);
  const port = await run.port;
  const stalled = new Viewer(port, "stalled");
  const reader = new Viewer(port, "reader");
  await stalled.subscribe(["/particles"]);
  await reader.subscribe(["/particles"]);
  await until(() => stalled.particleCounts().length > 0 && reader.particleCounts().length > 0, 30, "a first frame");
  stalled.ws.pause();  // stop reading: the socket fills, then the server's queue
  const during = reader.particleCounts().length;
  await sleep(2500);
  const readerDuring = reader.particleCounts().length - during;
  stalled.ws.resume();
  const result = await run.exited;
  assert.equal(result.code, 0, `m3dp exited with ${result.code}:\n${result.stderr}`);
  await until(() => stalled.closed, 10, "the stalled client to be closed");
  const summary = JSON.parse(fs.readFileSync(path.join(folder, "summary.json"), "utf8"));
  assert.ok(readerDuring >= 3, `the reading client got ${readerDuring} frames while the other stalled`);
  assert.ok(summary.live.messages_dropped > 0, "no message was dropped for the stalled client");
  const told = stalled.statuses.filter((status) => status.level === 1 && /dropped \d+ of this client's unread messages/.test(status.message));
  assert.ok(told.length > 0, `the stalled client was not told of its drops: ${JSON.stringify(stalled.statuses)}`);
  console.log(`slow client: ${summary.live.messages_dropped} messages dropped, the other client got ${readerDuring} frames meanwhile; ` +
    `told: "${told[0].message}"`);
}

(async () => {
  fs.rmSync(out, { recursive: true, force: true });
  const liveFolder = await liveRun();
  await sameAsWithoutClients(liveFolder);
  await slowClient();
  console.log("PASS");
  process.exit(0);
})().catch((error) => {
  console.error(error);
  process.exit(1);
});
