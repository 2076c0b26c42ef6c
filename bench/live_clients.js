// What live viewers cost a run: `m3dp run SCENE --serve 0` with 0 and N Foxglove WebSocket clients
// (@foxglove/ws-protocol over `ws`, each subscribed to /particles, /tf and /run), alternating, and
// the run's wall time (summary.json) side by side with the frames each client got per second.
//   node bench/live_clients.js [--m3dp build/apps/m3dp/m3dp] [--scene bench/scenes/live_tank_100k.sdf]
//                              [--clients 4] [--pairs 3]
// The clients run in this process, on the same machine as the run: on two cores they compete with
// the solver for the CPU, which is part of what this measures.
// With --server-only, build/bench/bench_live_server publishes a 10⁵-particle frame at --rate (20)
// per second to the clients instead, and says how much of a core the server used.
"use strict";
const { spawn } = require("child_process");
const fs = require("fs");
const os = require("os");
const path = require("path");
const { FoxgloveClient } = require("@foxglove/ws-protocol");
const WebSocket = require("ws");

const option = (name, fallback) => {
  const index = process.argv.indexOf(`--${name}`);
  return index > 0 ? process.argv[index + 1] : fallback;
};
const root = path.join(__dirname, "..");
const m3dp = option("m3dp", path.join(root, "build/apps/m3dp/m3dp"));
const scene = option("scene", path.join(__dirname, "scenes/live_tank_100k.sdf"));
const clientCount = Number(option("clients", 4));
const pairs = Number(option("pairs", 3));

function viewer(port, topics) {
  const ws = new WebSocket(`ws://127.0.0.1:${port}`, [FoxgloveClient.SUPPORTED_SUBPROTOCOL]);
  const client = new FoxgloveClient({ ws });
  const stats = { frames: 0, bytes: 0, first: 0, last: 0 };
  const particles = new Set();
  client.on("advertise", (channels) => {
    for (const channel of channels)
      if (topics.includes(channel.topic)) {
        const id = client.subscribe(channel.id);
        if (channel.topic === "/particles") particles.add(id);
      }
  });
  client.on("message", ({ subscriptionId, data }) => {
    stats.bytes += data.byteLength;
    if (!particles.has(subscriptionId)) return;
    stats.last = Date.now();
    if (stats.frames++ === 0) stats.first = stats.last;
  });
  client.on("error", () => {});
  return stats;
}

async function run(clients) {
  const folder = fs.mkdtempSync(path.join(os.tmpdir(), "m3dp_live_bench_"));
  const child = spawn(m3dp, ["run", scene, "-o", folder, "--serve", "0", "--quiet"], { stdio: ["ignore", "pipe", "inherit"] });
  let stdout = "";
  const viewers = [];
  await new Promise((resolve, reject) => {
    child.stdout.on("data", (chunk) => {
      stdout += chunk;
      const match = stdout.match(/live at ws:\/\/127\.0\.0\.1:(\d+)/);
      if (match && viewers.length === 0 && clients > 0)
        for (let c = 0; c < clients; ++c) viewers.push(viewer(Number(match[1]), ["/particles", "/tf", "/run"]));
    });
    child.on("exit", (code) => (code === 0 ? resolve() : reject(new Error(`m3dp exited with ${code}`))));
  });
  const summary = JSON.parse(fs.readFileSync(path.join(folder, "summary.json"), "utf8"));
  fs.rmSync(folder, { recursive: true, force: true });
  const rates = viewers.map((stats) => (stats.frames > 1 ? (stats.frames - 1) / ((stats.last - stats.first) / 1000) : 0));
  return {
    wall: summary.wall_time_s,
    steps: summary.steps,
    particles: summary.particles,
    frameRate: rates.length ? rates.reduce((a, b) => a + b) / rates.length : 0,
    megabytes: viewers.reduce((sum, stats) => sum + stats.bytes, 0) / 1e6,
    dropped: summary.live.messages_dropped,
  };
}

async function serverOnly() {
  const rate = option("rate", "20");
  const child = spawn(path.join(root, "build/bench/bench_live_server"), ["--clients", String(clientCount), "--rate", rate],
    { stdio: ["ignore", "pipe", "inherit"] });
  let stdout = "";
  const viewers = [];
  await new Promise((resolve, reject) => {
    child.stdout.on("data", (chunk) => {
      stdout += chunk;
      const match = stdout.match(/port (\d+)/);
      if (match && viewers.length === 0) for (let c = 0; c < clientCount; ++c) viewers.push(viewer(Number(match[1]), ["/particles"]));
    });
    child.on("exit", (code) => (code === 0 ? resolve() : reject(new Error(`bench_live_server exited with ${code}`))));
  });
  const rates = viewers.map((stats) => (stats.frames > 1 ? (stats.frames - 1) / ((stats.last - stats.first) / 1000) : 0));
  console.log(stdout.split("\n").slice(1).join("\n").trim());
  console.log(`frames per second each client received: ${rates.map((r) => r.toFixed(1)).join(", ")}`);
}

(async () => {
  if (process.argv.includes("--server-only")) return serverOnly();
  console.log(`scene ${scene}, ${clientCount} clients against none, ${pairs} alternating pairs`);
  console.log("clients,wall_s,steps,particles,frames_per_s_per_client,MB_received,messages_dropped");
  const walls = { 0: [], [clientCount]: [] };
  for (let pair = 0; pair < pairs; ++pair)
    for (const clients of [0, clientCount]) {
      const result = await run(clients);
      walls[clients].push(result.wall);
      console.log([clients, result.wall.toFixed(2), result.steps, result.particles, result.frameRate.toFixed(1),
        result.megabytes.toFixed(0), result.dropped].join(","));
    }
  const ratios = walls[0].map((alone, i) => walls[clientCount][i] / alone);
  console.log(`wall time with ${clientCount} clients / none, per pair: ${ratios.map((r) => r.toFixed(3)).join(", ")}`);
})().catch((error) => {
  console.error(error);
  process.exit(1);
});
