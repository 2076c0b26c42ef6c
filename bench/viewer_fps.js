// The browser viewer's frame rate in headless Chromium's software renderer (SwiftShader) with a
// recording of many particles: node bench/viewer_fps.js [--m3dp build/apps/m3dp/m3dp]
//   [--scene bench/scenes/live_tank_100k.sdf] [--until 0.02]
// Records the scene, replays it with m3dp view at a 1280x800 page, and prints the page's frames
// per second paused (the picture redrawn, orbiting) and playing.
"use strict";
const { spawn, spawnSync } = require("child_process");
const fs = require("fs");
const os = require("os");
const path = require("path");
const puppeteer = require("puppeteer-core");

const option = (name, fallback) => {
  const index = process.argv.indexOf(`--${name}`);
  return index > 0 ? process.argv[index + 1] : fallback;
};
const root = path.join(__dirname, "..");
const m3dp = option("m3dp", path.join(root, "build/apps/m3dp/m3dp"));
const scene = option("scene", path.join(__dirname, "scenes/live_tank_100k.sdf"));
const until = option("until", "0.02");
const sleep = (ms) => new Promise((resolve) => setTimeout(resolve, ms));

(async () => {
  const folder = fs.mkdtempSync(path.join(os.tmpdir(), "m3dp_viewer_fps_"));
  const recorded = spawnSync(m3dp, ["run", scene, "-o", folder, "--until", until, "--record", "--quiet"], { stdio: "inherit" });
  if (recorded.status !== 0) throw new Error("the recording failed");
  const view = spawn(m3dp, ["view", folder, "--port", "0", "--paused", "--loop"], { stdio: ["ignore", "pipe", "inherit"] });
  const url = await new Promise((resolve) => {
    let text = "";
    view.stdout.on("data", (chunk) => {
      text += chunk;
      const match = text.match(/(http:\/\/127\.0\.0\.1:\d+\/)/);
      if (match) resolve(match[1]);
    });
  });
  const browser = await puppeteer.launch({ executablePath: "/usr/bin/chromium", headless: true,
    args: ["--no-sandbox", "--disable-gpu", "--no-first-run", "--disable-background-networking", "--use-angle=swiftshader", "--enable-unsafe-swiftshader"] });
  try {
    const page = await browser.newPage();
    await page.setViewport({ width: 1280, height: 800 });
    await page.goto(url);
    await page.waitForFunction(() => window.m3dp.cloud && window.m3dp.cloud.count > 0, { timeout: 60000 });
    const particles = await page.evaluate(() => window.m3dp.cloud.count);
    // Paused: orbit the camera, so every frame is drawn anew.
    await page.evaluate(() => setInterval(() => window.m3dp.world.camera.position.applyAxisAngle(window.m3dp.world.camera.up, 0.01), 10));
    await sleep(4000);
    const paused = await page.evaluate(() => window.m3dp.fps);
    await page.click("#play");
    await sleep(4000);
    const playing = await page.evaluate(() => ({ fps: window.m3dp.fps, frames: window.m3dp.frames }));
    console.log(`${particles} particles: ${paused.toFixed(1)} frames/s paused (orbiting), ${playing.fps.toFixed(1)} playing ` +
      `(${playing.frames} particle frames received)`);
  } finally {
    await browser.close();
    view.kill("SIGINT");
    fs.rmSync(folder, { recursive: true, force: true });
  }
})().catch((error) => {
  console.error(error);
  process.exit(1);
});
