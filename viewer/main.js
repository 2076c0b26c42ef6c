// The viewer's page: connects to the server that served it (m3dp view's replay or m3dp run --view's
// live stream), draws the world and the particles (world.js), plays, pauses and scrubs a replay,
// and shows the cameras' images and the run's numbers as plots; with print heads, the print against
// its design (/quality: each layer's bead width and height, the surface's deviation histogram) and
// the printed mesh coloured by its distance to the design (/quality/deviation).
import uPlot from "uplot";
import { Connection, PlaybackStatus } from "./protocol.js";
import { World, rampColor, CATEGORIES } from "./world.js";

const $ = (id) => document.getElementById(id);
const state = {
  world: new World($("scene")),
  connection: new Connection(`ws://${location.host}/`),
  run: null,            // the newest m3dp.RunStats
  quality: null,        // the newest m3dp.QualityStats
  cloud: null,          // the newest particle cloud (decoded point fields)
  frames: 0,            // particle frames drawn
  time: 0,              // ns, the clock
  playing: false,
  scrubbing: false,
  fps: 0,
  errors: [],
};
// What the tests read back (and anyone curious in the console).
window.m3dp = state;
window.addEventListener("error", (event) => state.errors.push(String(event.message)));

// ---- particles ------------------------------------------------------------------------------

const FIELDS = {
  speed: { label: "speed (m/s)" },
  density_error: { label: "density error (%)", range: [-5, 5] },
  viscosity: { label: "log10 viscosity (Pa·s)" },
  age: { label: "age (s)" },
  rest_time: { label: "time at rest (s)" },
  material: { label: "material", categories: true },
};

/** The cloud's points as typed arrays: positions and every field the colour menu offers. */
function decodeCloud(message, time) {
  const stride = message.point_stride, data = message.data;
  const count = Math.floor(data.length / stride);
  const view = new DataView(data.buffer, data.byteOffset, data.byteLength);
  const offset = Object.fromEntries(message.fields.map((field) => [field.name, field.offset]));
  const float = (i, name) => view.getFloat32(i * stride + offset[name], true);
  const densities = state.run?.material_density ?? [];
  const cloud = { count, positions: new Float32Array(3 * count), fields: {} };
  for (const name of Object.keys(FIELDS)) cloud.fields[name] = new Float32Array(count);
  const seconds = time * 1e-9;
  for (let i = 0; i < count; ++i) {
    cloud.positions[3 * i] = float(i, "x");
    cloud.positions[3 * i + 1] = float(i, "y");
    cloud.positions[3 * i + 2] = float(i, "z");
    const material = view.getUint16(i * stride + offset.material, true);
    cloud.fields.speed[i] = Math.hypot(float(i, "vx"), float(i, "vy"), float(i, "vz"));
    const rest = densities[material];
    cloud.fields.density_error[i] = rest ? 100 * (float(i, "density") / rest - 1) : 0;
    cloud.fields.viscosity[i] = Math.log10(Math.max(float(i, "viscosity"), 1e-9));
    cloud.fields.age[i] = seconds - float(i, "birth_time");
    cloud.fields.rest_time[i] = float(i, "rest_time");
    cloud.fields.material[i] = material;
  }
  return cloud;
}

function drawParticles() {
  const cloud = state.cloud;
  if (!cloud) return;
  const name = $("field").value, field = FIELDS[name], values = cloud.fields[name];
  let [low, high] = field.range ?? [Infinity, -Infinity];
  if (!field.range) {
    for (const value of values) {
      low = Math.min(low, value);
      high = Math.max(high, value);
    }
    if (!(high > low)) high = low + 1;
  }
  state.world.setParticles(cloud.positions, values, state.run?.particle_radius || 0.0015, low, high, Boolean(field.categories));
  state.world.particles.visible = $("show-particles").checked;
  drawColorbar(field, low, high);
}

function drawColorbar(field, low, high) {
  const canvas = $("colorbar-canvas"), context = canvas.getContext("2d");
  for (let y = 0; y < canvas.height; ++y) {
    const t = 1 - y / (canvas.height - 1);
    const color = field.categories ? CATEGORIES[Math.min(CATEGORIES.length - 1, Math.floor(t * CATEGORIES.length))] : rampColor(t);
    context.fillStyle = `rgb(${color.map((c) => Math.round(255 * c)).join(",")})`;
    context.fillRect(0, y, canvas.width, 1);
  }
  const format = (value) => (Math.abs(value) >= 100 || Math.abs(value) < 0.01 ? value.toExponential(2) : value.toFixed(3));
  $("colorbar-label").textContent = field.label;
  $("colorbar-max").textContent = field.categories ? "" : format(high);
  $("colorbar-min").textContent = field.categories ? "" : format(low);
}

// ---- plots ------------------------------------------------------------------------------------

const PLOTS = [
  { title: "stage times per step (ms)", series: ["step", "neighbours", "pressure", "world"],
    values: (run) => [run.step_ms, run.neighbor_ms, run.pressure_ms, run.world_ms] },
  { title: "real-time factor", series: ["simulated s per wall s"], values: (run) => [run.real_time_factor] },
  { title: "particles", series: ["moving", "at rest"],
    values: (run) => [Number(run.particles || 0) - Number(run.resting_particles || 0), Number(run.resting_particles || 0)] },
  { title: "density error (%)", series: ["mean", "max"], values: (run) => [100 * (run.density_error_mean || 0), 100 * (run.density_error_max || 0)] },
  { title: "nozzle tracking error (mm)", series: ["nozzle"], values: (run) => [1000 * (run.nozzles?.[0]?.tracking_error || 0)] },
];
const COLORS = ["#ffb000", "#4aa3ff", "#5fd17a", "#e05a6b"];
for (const plot of PLOTS) {
  const box = document.createElement("div");
  box.className = "plot";
  box.innerHTML = `<div class="title">${plot.title}</div>`;
  $("plots").appendChild(box);
  plot.data = [[], ...plot.series.map(() => [])];
  plot.chart = new uPlot({
    width: 310, height: 120, legend: { show: true }, scales: { x: { time: false } },
    axes: [{ stroke: "#aab", grid: { stroke: "#333" } }, { stroke: "#aab", grid: { stroke: "#333" }, size: 50 }],
    series: [{ label: "t (s)" }, ...plot.series.map((label, k) => ({ label, stroke: COLORS[k], width: 1.5 }))],
  }, plot.data, box);
}
state.plots = PLOTS;

function addRunStats(run) {
  const t = Number(run.time || 0);
  for (const plot of PLOTS) {
    const times = plot.data[0];
    // A replay that went back: forget what lies after.
    while (times.length && times[times.length - 1] >= t) plot.data.forEach((column) => column.pop());
    times.push(t);
    plot.values(run).forEach((value, k) => plot.data[k + 1].push(Number(value) || 0));
  }
}
let plotsDue = 0;
function drawPlots(now) {
  if (now < plotsDue) return;
  plotsDue = now + 250;
  for (const plot of PLOTS) plot.chart.setData(plot.data);
}

// The print against its design, redrawn at each /quality: per layer (x: the layer) the beads' mean
// width and height, printed and designed, over every head; and the surface's deviation histogram.
const QUALITY_PLOTS = [
  { title: "bead per layer (mm)", x: "layer", series: ["width", "design width", "height", "design height"], dash: [null, [6, 4], null, [6, 4]],
    data: (quality) => {
      const layers = new Map();
      for (const layer of quality.layers) {
        const printed = (layer.sections ?? 0) - (layer.empty ?? 0);
        if (printed <= 0) continue;
        const sum = layers.get(layer.layer ?? 0) ?? [0, 0, 0, 0, 0];
        [layer.width, layer.design_width, layer.height, layer.design_height].forEach((value, k) => (sum[k] += printed * 1e3 * (value ?? 0)));
        sum[4] += printed;
        layers.set(layer.layer ?? 0, sum);
      }
      const numbers = [...layers.keys()].sort((a, b) => a - b);
      return [numbers, ...[0, 1, 2, 3].map((k) => numbers.map((n) => layers.get(n)[k] / layers.get(n)[4]))];
    } },
  { title: "printed surface off the design (mesh vertices)", x: "mm", series: ["vertices"], bars: true,
    data: (quality) => {
      const edges = quality.histogram_edges ?? [], counts = (quality.histogram_counts ?? []).map(Number);
      return [counts.map((_, b) => 500 * (edges[b] + edges[b + 1])), counts];
    } },
];
for (const plot of QUALITY_PLOTS) {
  const box = document.createElement("div");
  box.className = "plot quality";
  box.innerHTML = `<div class="title">${plot.title}</div>`;
  box.hidden = true;  // until the run sends /quality
  $("plots").appendChild(box);
  plot.box = box;
  plot.points = [[], ...plot.series.map(() => [])];
  plot.chart = new uPlot({
    width: 310, height: 120, legend: { show: true }, scales: { x: { time: false } },
    axes: [{ stroke: "#aab", grid: { stroke: "#333" } }, { stroke: "#aab", grid: { stroke: "#333" }, size: 50 }],
    series: [{ label: plot.x }, ...plot.series.map((label, k) => ({
      label, stroke: COLORS[k], width: 1.5, dash: plot.dash?.[k] ?? undefined,
      ...(plot.bars ? { fill: `${COLORS[k]}88`, paths: uPlot.paths.bars({ size: [0.9] }), points: { show: false } } : { points: { show: true } }),
    }))],
  }, plot.points, box);
}
state.qualityPlots = QUALITY_PLOTS;

function showQuality(quality) {
  state.quality = quality;
  for (const plot of QUALITY_PLOTS) {
    plot.points = plot.data(quality);
    plot.box.hidden = false;
    plot.chart.setData(plot.points);
  }
  const range = 1e3 * (quality.deviation_range || 0);
  $("deviation-legend").innerHTML = `<span class="under">−${range.toFixed(1)} mm inside</span> · 0 · ` +
    `<span class="over">+${range.toFixed(1)} mm outside</span>; p95 ${(1e3 * (quality.deviation_p95 || 0)).toFixed(2)} mm`;
}

// ---- cameras ----------------------------------------------------------------------------------

const cameras = new Map();  // name → {canvas, caption, mode}
function cameraPanel(name) {
  if (!cameras.has(name)) {
    const figure = document.createElement("figure");
    const canvas = document.createElement("canvas");
    const caption = document.createElement("figcaption");
    figure.append(canvas, caption);
    $("cameras").appendChild(figure);
    const panel = { canvas, caption, mode: "image" };
    // A click cycles what the panel shows: colour, depth, segmentation.
    canvas.addEventListener("click", () => {
      panel.mode = { image: "depth", depth: "segmentation", segmentation: "image" }[panel.mode];
    });
    cameras.set(name, panel);
  }
  return cameras.get(name);
}

function drawCameraImage(name, kind, image) {
  const panel = cameraPanel(name);
  if (kind === "image") panel.hasImage = true;
  // A depth camera has no colour image: its panel starts on the depth.
  const shown = panel.mode === "image" && !panel.hasImage ? "depth" : panel.mode;
  if (kind !== shown) return;
  const { width, height } = image, data = image.data;
  panel.canvas.width = width;
  panel.canvas.height = height;
  const context = panel.canvas.getContext("2d");
  const pixels = context.createImageData(width, height);
  const view = new DataView(data.buffer, data.byteOffset, data.byteLength);
  if (kind === "image") {
    for (let p = 0; p < width * height; ++p) pixels.data.set([data[3 * p], data[3 * p + 1], data[3 * p + 2], 255], 4 * p);
  } else if (kind === "depth") {
    let low = Infinity, high = -Infinity;
    for (let p = 0; p < width * height; ++p) {
      const d = view.getFloat32(4 * p, true);
      if (Number.isFinite(d)) [low, high] = [Math.min(low, d), Math.max(high, d)];
    }
    for (let p = 0; p < width * height; ++p) {
      const d = view.getFloat32(4 * p, true);
      const color = Number.isFinite(d) ? rampColor(1 - (d - low) / Math.max(high - low, 1e-6)) : [0, 0, 0];
      pixels.data.set([...color.map((c) => 255 * c), 255], 4 * p);
    }
  } else {
    for (let p = 0; p < width * height; ++p) {
      const id = view.getUint16(2 * p, true);
      const hash = (id * 2654435761) >>> 0;
      pixels.data.set(id === 0 ? [0, 0, 0, 255] : [hash & 255, (hash >> 8) & 255, (hash >> 16) & 255, 255], 4 * p);
    }
  }
  context.putImageData(pixels, 0, 0);
  panel.caption.textContent = `${name}: ${kind} (click: next)`;
}

// ---- the connection -----------------------------------------------------------------------------

const connection = state.connection;
connection.addEventListener("info", ({ detail }) => {
  const ranged = connection.ranged;
  for (const id of ["play", "speed", "scrub"]) $(id).disabled = !ranged;
  if (ranged) {
    state.start = Number(detail.dataStartTime), state.end = Number(detail.dataEndTime);
    $("scrub").max = String(Math.max(1, Math.round((state.end - state.start) / 1e6)));
  }
  $("status").textContent = ranged ? "replay" : "live";
});
connection.addEventListener("message", ({ detail }) => {
  const { topic, value, time } = detail;
  try {
    if (topic === "/scene" || topic === "/printed" || topic === "/quality/deviation") state.world.applySceneUpdate(value);
    else if (topic === "/quality") showQuality(value);
    else if (topic === "/tf") state.world.applyTransforms(value);
    else if (topic === "/run") {
      state.run = value;
      addRunStats(value);
    } else if (topic === "/particles") {
      state.cloud = decodeCloud(value, time);
      drawParticles();
      state.frames += 1;
      document.body.dataset.frames = String(state.frames);
    } else if (topic.startsWith("/camera/")) {
      const [, , name, kind] = topic.split("/");
      if (kind === "image" || kind === "depth" || kind === "segmentation") drawCameraImage(name, kind, value);
    }
  } catch (error) {
    state.errors.push(`${topic}: ${error}`);
  }
});
connection.addEventListener("time", ({ detail }) => (state.time = detail));
connection.addEventListener("playback", ({ detail }) => {
  state.playing = detail.status === PlaybackStatus.playing;
  state.time = detail.time;
  $("play").textContent = state.playing ? "❚❚" : "▶";
});
connection.addEventListener("status", ({ detail }) => {
  if (detail.level >= 2) state.errors.push(detail.message);
});
connection.addEventListener("close", () => ($("status").textContent = "the run ended (disconnected)"));

// ---- controls -------------------------------------------------------------------------------------

$("play").addEventListener("click", () => connection.playback(!state.playing, Number($("speed").value)));
$("speed").addEventListener("change", () => connection.playback(state.playing, Number($("speed").value)));
$("scrub").addEventListener("input", () => (state.scrubbing = true));
$("scrub").addEventListener("change", () => {
  state.scrubbing = false;
  connection.playback(state.playing, Number($("speed").value), state.start + Number($("scrub").value) * 1e6);
});
$("field").addEventListener("change", drawParticles);
$("show-mesh").addEventListener("change", () => state.world.setMeshVisible($("show-mesh").checked));
$("show-deviation").addEventListener("change", () => state.world.setDeviationVisible($("show-deviation").checked));
$("show-particles").addEventListener("change", () => state.world.particles && (state.world.particles.visible = $("show-particles").checked));
$("reset-view").addEventListener("click", () => state.world.resetView());

let last = performance.now(), frames = 0;
function animate(now) {
  state.world.render($("follow").checked);
  drawPlots(now);
  ++frames;
  if (now - last > 1000) {
    state.fps = (1000 * frames) / (now - last);
    [last, frames] = [now, 0];
  }
  const seconds = (state.time - (state.start ?? 0)) * 1e-9;
  $("clock").textContent = `t = ${(state.time * 1e-9).toFixed(3)} s · step ${state.run?.step ?? 0} · ${state.fps.toFixed(0)} fps`;
  if (connection.ranged && !state.scrubbing) $("scrub").value = String(Math.round(seconds * 1000));
  requestAnimationFrame(animate);
}

connection.connect().then(() => requestAnimationFrame(animate), (error) => {
  state.errors.push(String(error));
  $("status").textContent = `cannot start: ${error}`;
});
