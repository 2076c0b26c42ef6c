// The browser viewer in a real headless Chromium (Debian's chromium, driven by puppeteer-core):
//   node tests/e2e/viewer.js M3DP SCENE OUT
// 1. A short recorded run (SCENE, the UR10 demo) played back by `m3dp view`: the page gets the
//    scene and a particle frame after a seek through its own timeline; the arm's links and the
//    particles show their colours where they project; toggling the printed mesh and scrubbing to
//    another time change the picture; the printed mesh coloured by its deviation from the design
//    shows, and the quality plots have /quality's layers and histogram; the plots have data and the camera panels images; playing
//    moves the clock. 2. A live run with --view: the page gets frames while it runs.
// The page must log no error. Screenshots are kept in OUT for a person to look at.
"use strict";
const { spawn } = require("child_process");
const fs = require("fs");
const path = require("path");
const assert = require("assert/strict");
const puppeteer = require("puppeteer-core");

const [m3dp, scene, out] = process.argv.slice(2);
const sleep = (ms) => new Promise((resolve) => setTimeout(resolve, ms));

function start(args, pattern) {
  const child = spawn(m3dp, args, { stdio: ["ignore", "pipe", "pipe"] });
  let output = "";
  const exited = new Promise((resolve) => child.on("exit", (code) => resolve(code)));
  const url = new Promise((resolve, reject) => {
    const look = (chunk) => {
      output += chunk;
      const match = output.match(pattern);
      if (match) resolve(match[1]);
    };
    child.stdout.on("data", look);
    child.stderr.on("data", look);
    child.on("exit", (code) => reject(new Error(`m3dp ${args[0]} exited (${code}):\n${output}`)));
  });
  return { child, url, exited };
}

async function run(args) {
  const child = spawn(m3dp, args, { stdio: "ignore" });
  const code = await new Promise((resolve) => child.on("exit", resolve));
  assert.equal(code, 0, `m3dp ${args.join(" ")} failed`);
}

async function openPage(browser, url, problems) {
  const page = await browser.newPage();
  await page.setViewport({ width: 1280, height: 800 });
  page.on("console", (message) => {
    // WebGL's performance notes from the software renderer are not the page's errors.
    if (message.type() === "error") problems.push(`console: ${message.text()}`);
  });
  page.on("pageerror", (error) => problems.push(`page: ${error.message}`));
  page.on("response", (response) => response.status() >= 400 && problems.push(`HTTP ${response.status()} ${response.url()}`));
  await page.goto(url);
  return page;
}

/** The rendered picture: RGBA of the 3D canvas (the page keeps its drawing buffer). */
async function picture(page) {
  return page.evaluate(() => {
    const canvas = window.m3dp.world.renderer.domElement;
    const copy = document.createElement("canvas");
    [copy.width, copy.height] = [canvas.width, canvas.height];
    const context = copy.getContext("2d");
    context.drawImage(canvas, 0, 0);
    return Array.from(context.getImageData(0, 0, copy.width, copy.height).data);
  });
}
function differingPixels(a, b) {
  let count = 0;
  for (let i = 0; i < a.length; i += 4) if (Math.abs(a[i] - b[i]) + Math.abs(a[i + 1] - b[i + 1]) + Math.abs(a[i + 2] - b[i + 2]) > 30) ++count;
  return count;
}

async function seek(page, seconds) {
  await page.evaluate((ms) => {
    const scrub = document.getElementById("scrub");
    scrub.value = String(ms);
    scrub.dispatchEvent(new Event("input"));
    scrub.dispatchEvent(new Event("change"));
  }, Math.round(seconds * 1000));
  await page.waitForFunction((t) => Math.abs(window.m3dp.time * 1e-9 - t) < 0.15 && window.m3dp.cloud, { timeout: 20000 }, seconds);
  await sleep(700);  // the frame drawn
}

/** Where the page draws things: bluish pixels at the arm's links, the material's colour at particles. */
async function probe(page) {
  return page.evaluate(() => {
    const state = window.m3dp, world = state.world, canvas = world.renderer.domElement;
    const copy = document.createElement("canvas");
    [copy.width, copy.height] = [canvas.width, canvas.height];
    copy.getContext("2d").drawImage(canvas, 0, 0);
    const pixels = copy.getContext("2d").getImageData(0, 0, copy.width, copy.height).data;
    const Vector3 = world.camera.position.constructor;
    const at = (point) => {
      const p = point.clone().project(world.camera);
      const x = Math.round((p.x * 0.5 + 0.5) * copy.width), y = Math.round((0.5 - p.y * 0.5) * copy.height);
      if (x < 0 || y < 0 || x >= copy.width || y >= copy.height) return null;
      const i = 4 * (y * copy.width + x);
      return [pixels[i], pixels[i + 1], pixels[i + 2]];
    };
    // Links: the middle of each link's drawn box.
    let links = 0, bluish = 0;
    for (const [id, group] of world.entities) {
      if (!id.startsWith("ur10/") || !group.children.length) continue;
      const color = at(world.entityCenter(id));
      if (!color) continue;
      ++links;
      if (color[2] > color[0] + 20) ++bluish;
    }
    // Particles, coloured by material (the first category is orange): near a drawn particle.
    const cloud = state.cloud;
    let sampled = 0, orange = 0;
    for (let i = 0; i < cloud.count; i += Math.max(1, Math.floor(cloud.count / 60))) {
      const color = at(new Vector3(cloud.positions[3 * i], cloud.positions[3 * i + 1], cloud.positions[3 * i + 2]));
      if (!color) continue;
      ++sampled;
      if (color[0] > color[2] + 30 && color[0] > 60) ++orange;
    }
    return { links, bluish, sampled, orange, particles: cloud.count };
  });
}

(async () => {
  fs.rmSync(out, { recursive: true, force: true });
  fs.mkdirSync(out, { recursive: true });
  await run(["run", scene, "-o", path.join(out, "run"), "--until", "6", "--quiet"]);
  const browser = await puppeteer.launch({
    executablePath: "/usr/bin/chromium", headless: true,
    args: ["--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run", "--disable-background-networking",
      "--disable-component-update", "--disable-sync", "--use-angle=swiftshader", "--enable-unsafe-swiftshader"],
  });
  const problems = [];
  try {
    // 1. The replay.
    const view = start(["view", path.join(out, "run"), "--port", "0", "--paused"], /(http:\/\/127\.0\.0\.1:\d+\/)/);
    const page = await openPage(browser, await view.url, problems);
    await page.waitForFunction(() => window.m3dp.connection.ranged && window.m3dp.world.entities.size > 8, { timeout: 20000 });
    await page.select("#field", "material");
    await seek(page, 5);
    await page.click("#show-mesh");  // off: the particles under it in view
    await sleep(500);
    await page.screenshot({ path: path.join(out, "replay_5s.png") });
    const seen = await probe(page);
    assert.ok(seen.links >= 6 && seen.bluish >= seen.links - 1, `the arm's links: ${JSON.stringify(seen)}`);
    assert.ok(seen.sampled >= 20 && seen.orange >= 0.6 * seen.sampled, `the particles' colour: ${JSON.stringify(seen)}`);
    const withoutMesh = await picture(page);
    await page.click("#show-mesh");
    await sleep(500);
    const withMesh = await picture(page);
    const meshPixels = differingPixels(withoutMesh, withMesh);
    assert.ok(meshPixels > 200, `toggling the printed mesh changed ${meshPixels} pixels`);
    // The print against its design: the mesh coloured by its deviation replaces the plain one, and
    // the quality plots show the layers and the histogram of what /quality sent.
    await page.waitForFunction(() => window.m3dp.quality && window.m3dp.world.entities.has("printed_deviation"), { timeout: 20000 });
    await page.click("#show-deviation");
    await sleep(500);
    await page.screenshot({ path: path.join(out, "replay_5s_deviation.png") });
    const deviationPixels = differingPixels(withMesh, await picture(page));
    // A quarter of the pixels the mesh covers at least: a bead that holds to its design (p95 1.5 mm) is
    // coloured near the plain tone where it deviates least (half the mesh changed at 5 s, 191 of 383).
    assert.ok(deviationPixels > meshPixels / 4, `colouring the mesh by its deviation changed ${deviationPixels} pixels of the mesh's ${meshPixels}`);
    const quality = await page.evaluate(() => {
      const world = window.m3dp.world, coloured = world.entities.get("printed_deviation"), plain = world.entities.get("printed_material");
      const mesh = coloured.children[0];
      return {
        shown: coloured.visible && !(plain && plain.visible), vertexColors: mesh.material.vertexColors,
        colours: mesh.geometry.getAttribute("color")?.count ?? 0, vertices: Number(window.m3dp.quality.vertices),
        plots: window.m3dp.qualityPlots.map((plot) => ({ hidden: plot.box.hidden, x: plot.points[0].length, y: plot.points.slice(1) })),
        legend: document.getElementById("deviation-legend").textContent,
      };
    });
    assert.ok(quality.shown && quality.vertexColors && quality.colours === quality.vertices, `the coloured mesh: ${JSON.stringify({ ...quality, plots: 0 })}`);
    const [layerPlot, histogramPlot] = quality.plots;
    assert.ok(!layerPlot.hidden && layerPlot.x >= 1 && layerPlot.y.every((series) => series.every((mm) => mm > 1 && mm < 40)),
      `the layer plot: ${JSON.stringify(layerPlot)}`);
    assert.equal(histogramPlot.y[0].reduce((a, b) => a + b, 0), quality.vertices, "the histogram plot does not count every vertex");
    assert.match(quality.legend, /mm inside .* mm outside; p95 \d/);
    await page.click("#show-deviation");
    await seek(page, 2.5);
    await page.screenshot({ path: path.join(out, "replay_2.5s.png") });
    const earlier = await picture(page);
    const scrubPixels = differingPixels(withMesh, earlier);
    assert.ok(scrubPixels > 500, `scrubbing from 5 s to 2.5 s changed ${scrubPixels} pixels`);
    const panels = await page.evaluate(() => [...document.querySelectorAll("#cameras canvas")].map((c) => [c.width, c.height]));
    assert.deepEqual(panels.map(([w]) => w > 0), [true, true], `camera panels ${JSON.stringify(panels)}`);
    const plots = await page.evaluate(() => window.m3dp.plots.map((plot) => plot.data[0].length));
    assert.ok(plots.every((points) => points > 0), `plot points ${plots}`);
    // Play: the clock moves.
    const before = await page.evaluate(() => window.m3dp.time);
    await page.click("#play");
    await page.waitForFunction((t) => window.m3dp.playing && window.m3dp.time > t + 0.5e9, { timeout: 20000 }, before);
    const fps = await page.evaluate(() => window.m3dp.fps);
    const errors = await page.evaluate(() => window.m3dp.errors);
    assert.deepEqual(errors, [], "the page's own errors");
    console.log(`replay: ${seen.links} links seen (${seen.bluish} bluish), ${seen.orange} of ${seen.sampled} particles in their colour ` +
      `(${seen.particles} particles at 5 s); the mesh toggled ${meshPixels} pixels, its deviation colours ${deviationPixels}, scrubbing ${scrubPixels}; ` +
      `plots ${plots}; ${fps.toFixed(0)} fps`);
    await page.close();
    view.child.kill("SIGINT");
    assert.equal(await view.exited, 0);

    // 2. A live run, watched while it prints.
    const live = start(["run", scene, "-o", path.join(out, "live"), "--until", "4", "--serve", "0", "--view", "--pace", "2", "--quiet"],
      /the viewer at (http:\/\/127\.0\.0\.1:\d+\/)/);
    const livePage = await openPage(browser, await live.url, problems);
    await livePage.waitForFunction(() => window.m3dp.frames >= 2 && window.m3dp.cloud && window.m3dp.cloud.count > 0, { timeout: 30000 });
    await livePage.screenshot({ path: path.join(out, "live.png") });
    const liveState = await livePage.evaluate(() => ({ ranged: window.m3dp.connection.ranged, frames: window.m3dp.frames, errors: window.m3dp.errors }));
    assert.equal(liveState.ranged, false);
    assert.deepEqual(liveState.errors, []);
    assert.equal(await live.exited, 0);
    console.log(`live: ${liveState.frames} particle frames drawn while it ran`);
    assert.deepEqual(problems, [], "the page logged errors");
    console.log(`PASS (screenshots in ${out})`);
  } finally {
    await browser.close();
  }
})().catch((error) => {
  console.error(error);
  process.exit(1);
});
