#!/usr/bin/env node
// Open dualarm runs in Foxglove Studio 1.48.0 (@foxglove/studio-base's own web build, web/ hosts it) in
// headless Debian Chromium driven by playwright-core, each with its layout, and report what Studio shows:
//   - problems: the player's problems, as the Data source sidebar's Problems tab lists them (per-topic
//     schema and decoding errors);
//   - urdf_error: the URDF layer's parse error ("Failed to parse URDF", logged by Studio), if any;
//   - layer_errors: what the 3D panel's layers report ("[topics > /task/reference_path] Missing
//     transform from frame <base_link> to frame <world>"); Studio logs each when it is first raised;
//   - robot_pixels_on_open: how much of the robot is drawn on opening, before anything is clicked
//     (watched for OPEN_LIMIT_MS until it settles); 3d-open.png;
//   - robot_pixels: whether the robot is drawn, in the middle of the run (the harness clicks the middle
//     of the timeline). The harness gives the layout's 3D panel a twin below it, same shape and camera,
//     with /robot_description and URDF layers hidden: the pixels that differ are the robot.
//
//   node open-in-studio.cjs [--out DIR] [--import K] --layout LAYOUT.json RUN.mcap [--layout LAYOUT.json RUN.mcap ...]
//
// --import K: open each file with Studio's default layout, then import its layout K times from the Layouts sidebar,
// as a user does (otherwise the page opens the file with its layout in place). From the second import on, Studio
// mounts the panels again with the topics they had, and sends them nothing until a seek
// (IterablePlayer.setSubscriptions backfills only when the set of topics changes).
//
// Prints one JSON line per run; writes DIR/<run directory name>/{studio.png, 3d-urdf.png, 3d-bare.png}.
// Exit 0 when every run has no problem and no layer error, its URDF parsed, robot pixels > 0 mid-run and at least
// OPEN_SHARE of them on opening;
// 1 otherwise; 2 when the harness itself failed. Runs are opened one after the other in one browser.
// Environment: CHROMIUM (default /usr/bin/chromium), STUDIO_DEBUG=1 echoes the page's console.
"use strict";

const fs = require("node:fs");
const path = require("node:path");
const { chromium } = require("playwright-core");
const { PNG } = require("pngjs");
const { listen } = require("./serve.cjs");

const CHROMIUM = process.env.CHROMIUM ?? "/usr/bin/chromium";
// Debian's chromium as root (no sandbox), quiet (no first-run, sync or update traffic), and WebGL
// rendered on the CPU by SwiftShader: no GPU and no X server (xvfb) needed.
const CHROMIUM_ARGS = [
  "--no-sandbox",
  "--no-first-run",
  "--disable-background-networking",
  "--disable-component-update",
  "--disable-sync",
  "--disable-quic",
  "--use-angle=swiftshader",
  "--enable-unsafe-swiftshader",
];
// Upper bounds on waiting (Studio takes 10-20 s to load on two shared cores), not assertions on time.
const LOAD_LIMIT_MS = 180_000;
const SETTLE_LIMIT_MS = 60_000;
// How long the 3D panel is watched for the robot on opening, before the harness touches anything, and the share of
// the robot's pixels mid-run it must cover then (the frame axes of its links alone cover 15 % of them).
const OPEN_LIMIT_MS = 10_000;
const OPEN_SHARE = 0.5;
const BARE_PANEL = "3D!dualarm-check-bare";
/** The browser window a layout is judged in [px], and the height of Studio's playback bar below the panels. */
const VIEWPORT = { width: 1600, height: 1000 };
const PLAYBACK_BAR_PX = 80;

function parseArgs(argv) {
  const args = { out: ".", runs: [], imports: 0 };
  let layout;
  for (let i = 0; i < argv.length; i++) {
    if (argv[i] === "--out") args.out = argv[++i];
    else if (argv[i] === "--import") args.imports = Number(argv[++i]);
    else if (argv[i] === "--layout") layout = argv[++i];
    else {
      args.runs.push({ mcap: path.resolve(argv[i]), layout });
      layout = undefined;
    }
  }
  if (args.runs.length === 0 || args.runs.some((r) => r.layout === undefined)) {
    process.stderr.write("usage: node open-in-studio.cjs [--out DIR] --layout LAYOUT.json RUN.mcap [--layout LAYOUT.json RUN.mcap ...]\n");
    process.exit(2);
  }
  return args;
}

/**
 * The layout with a twin of its first 3D panel (the URDF layer hidden) below it, splitting its place in
 * two. The window is twice as tall as the one the layout is shown in (VIEWPORT), so each of the two has
 * the shape the layout's 3D panel has there, and the camera frames the same scene.
 */
function withBareTwin(layout) {
  const panel = Object.keys(layout.configById).find((id) => id.startsWith("3D!"));
  if (panel === undefined) throw new Error("the layout has no 3D panel");
  const bare = structuredClone(layout.configById[panel]);
  bare.topics = { ...bare.topics, "/robot_description": { ...bare.topics?.["/robot_description"], visible: false } };
  bare.layers = Object.fromEntries(
    Object.entries(bare.layers ?? {}).map(([id, layer]) => [id, layer.layerId === "foxglove.Urdf" ? { ...layer, visible: false } : layer]),
  );
  const split = (node) => {
    if (node === panel) return { first: panel, second: BARE_PANEL, direction: "column", splitPercentage: 50 };
    if (typeof node === "object" && node !== null) return { ...node, first: split(node.first), second: split(node.second) };
    return node;
  };
  return { panel, layout: { ...layout, configById: { ...layout.configById, [BARE_PANEL]: bare }, layout: split(layout.layout) } };
}

/**
 * Pixels of image A that no pixel of image B within `shiftPx` matches (RGB within `tol`), over the
 * images' common area: the two panels of a 50 % split may differ by a pixel in width and so project the
 * same scene up to a pixel apart. Left out: the panel edges, and the top band and right strip where
 * the panel toolbar and the 3D panel's buttons are drawn over the canvas.
 */
function differingPixels(pngA, pngB, { tol = 24, shiftPx = 1, skipTopPx = 130, skipRightPx = 80, skipLeftPx = 4, skipBottomPx = 4 } = {}) {
  const a = PNG.sync.read(pngA);
  const b = PNG.sync.read(pngB);
  const width = Math.min(a.width, b.width);
  const height = Math.min(a.height, b.height);
  const close = (i, j) => Math.abs(a.data[i] - b.data[j]) <= tol && Math.abs(a.data[i + 1] - b.data[j + 1]) <= tol && Math.abs(a.data[i + 2] - b.data[j + 2]) <= tol;
  let n = 0;
  for (let y = skipTopPx; y < height - skipBottomPx; y++) {
    for (let x = skipLeftPx; x < width - skipRightPx; x++) {
      const i = (y * a.width + x) * 4;
      let matched = false;
      for (let dy = -shiftPx; dy <= shiftPx && !matched; dy++) {
        for (let dx = -shiftPx; dx <= shiftPx && !matched; dx++) matched = close(i, ((y + dy) * b.width + (x + dx)) * 4);
      }
      if (!matched) n++;
    }
  }
  return { pixels: n, of: (height - skipTopPx - skipBottomPx) * (width - skipLeftPx - skipRightPx) };
}

/** Poll `predicate` until it holds; an exception counts as not yet (Studio may re-mount a panel's canvas). */
async function waitFor(predicate, limitMs, stepMs = 500) {
  const until = Date.now() + limitMs;
  while (Date.now() < until) {
    if (await predicate().catch(() => false)) return true;
    await new Promise((r) => setTimeout(r, stepMs));
  }
  return false;
}

/** The Data source sidebar's Problems tab: its list items (one per problem), read after clicking the tab. */
async function readProblems(page) {
  const tab = () => [...document.querySelectorAll('[role="tab"]')].find((el) => el.innerText.startsWith("Problems"));
  await page.evaluate(`(${tab})().click()`);
  await page.waitForFunction(`(${tab})().getAttribute("aria-selected") === "true"`);
  return page.evaluate(`(() => {
    let sidebar = (${tab})();
    while (sidebar && !sidebar.querySelector("hr")) sidebar = sidebar.parentElement;
    return {
      problems: sidebar ? [...sidebar.querySelectorAll("ul > li")].map((li) => li.innerText.trim()) : [],
      says: sidebar && sidebar.innerText.includes("No problems found") ? "No problems found" : undefined,
    };
  })()`);
}

/**
 * Click the middle of Studio's timeline (its Scrubber: the first child of the playback bar, above the
 * row of buttons, which carry titles). A seek hands each panel the last message at or before the new time on every topic it
 * shows, among them the robot description and the line strips logged once at t = 0; Studio may
 * re-mount the 3D panels after its first seek on opening the file, and they then lack those until the
 * next seek. The robot is then checked mid-motion.
 */
async function seekToMiddle(page) {
  const box = await page.evaluate(() => {
    const button = document.querySelector('button[title="Seek backward"]');
    const top = button?.getBoundingClientRect().top;
    // up from the button to the playback bar, whose first child (the Scrubber) lies above the buttons' row
    for (let node = button?.parentElement; node; node = node.parentElement) {
      const rect = node.firstElementChild.getBoundingClientRect();
      if (rect.bottom <= top) return { x: rect.x, y: rect.y, width: rect.width, height: rect.height };
    }
    return undefined;
  });
  if (process.env.STUDIO_DEBUG) process.stderr.write(`[timeline] ${JSON.stringify(box)}\n`);
  if (!box || box.width < 100) throw new Error("Studio's timeline not found");
  await page.mouse.click(box.x + box.width / 2, box.y + box.height / 2);
  await page.mouse.move(0, 0); // away from the timeline, whose hover tooltip would stay in the screenshot
}

/**
 * Import `layout` as a user does once the file is open: the Layouts sidebar's "Import layout" button, whose file
 * picker (window.showOpenFilePicker, which headless Chromium cannot show) hands Studio the layout as a file.
 */
async function importLayout(page, layout) {
  await page.evaluate((json) => {
    const file = new File([json], "foxglove-layout.json", { type: "application/json" });
    window.showOpenFilePicker = async () => [{ getFile: async () => file }];
  }, JSON.stringify(layout));
  const button = page.locator('button[title="Import layout"]');
  if (!(await button.isVisible())) await page.locator('[data-sidebar-key="layouts"]').click(); // the tab toggles it
  await button.click();
  await page.locator('[data-testid="panel-mouseenter-container 3D!dualarm-check-bare"]').waitFor({ timeout: SETTLE_LIMIT_MS });
}

async function openRun(browser, url, index, run, outDir, imports) {
  const { panel, layout } = withBareTwin(JSON.parse(fs.readFileSync(run.layout, "utf8")));
  const started = Date.now();
  const mark = (what) => process.env.STUDIO_DEBUG && process.stderr.write(`[timing] ${what} at ${Date.now() - started} ms\n`);
  const consoleErrors = [];
  const layerErrors = [];
  let loaded = false;
  const page = await browser.newPage({ viewport: { width: VIEWPORT.width, height: 2 * VIEWPORT.height - PLAYBACK_BAR_PX } });
  try {
    page.on("console", (m) => {
      const text = m.text();
      if (process.env.STUDIO_DEBUG) process.stderr.write(`[console.${m.type()}] ${text.slice(0, 400)}\n`);
      if (m.type() === "error") consoleErrors.push(text);
      // The 3D panel's LayerErrors.add() warns "[<settings path>] <message>" the first time a topic, layer or
      // frame reports an error (so an error that clears later still counts). "[general > followTf] Frame
      // not found" is left out: it is raised before /tf is read, every time (check-mcap.cjs checks the frame).
      if (m.type() === "warning" && /^\[(topics|layers|transforms) > /.test(text)) layerErrors.push(text);
      if (/^Connection @ .* finished!$/.test(text)) loaded = true; // Studio's player logs this once it has read the file's index
    });
    page.on("pageerror", (e) => consoleErrors.push(`pageerror: ${e.message}`));
    // web/main.js fetches the layout to open from /layout.json: answer with this run's layout plus the twin
    await page.route((u) => u.pathname === "/layout.json", (route) => route.fulfill({ contentType: "application/json", body: JSON.stringify(layout) }));
    const dsUrl = `${url}/data/${index}/${encodeURIComponent(path.basename(run.mcap))}`;
    const withLayout = imports > 0 ? "" : "&layoutId=dualarm-check&layout=/layout.json";
    await page.goto(`${url}/?ds=remote-file&ds.url=${encodeURIComponent(dsUrl)}${withLayout}`);
    if (!(await waitFor(async () => loaded, LOAD_LIMIT_MS))) throw new Error(`Studio did not finish loading ${dsUrl}`);
    const loadMs = Date.now() - started;
    mark("loaded");
    const { problems, says } = await readProblems(page);
    mark("problems read");
    for (let i = 0; i < imports; i++) {
      await importLayout(page, layout);
      mark(`layout imported (${i + 1})`);
    }
    // close the first-run hint each 3D panel shows ("Open settings to configure topics and layers.")
    await page.evaluate(() => document.querySelectorAll('[role="tooltip"] button').forEach((button) => button.click()));
    mark("hints closed");
    const canvas = (id) => page.locator(`[data-testid="panel-mouseenter-container ${id}"] canvas`).first();
    const shoot = async () => [await canvas(panel).screenshot(), await canvas(BARE_PANEL).screenshot()];
    // what a user sees on opening, before touching anything: the robot within OPEN_LIMIT_MS, no click
    let opened = { pixels: 0, of: 0 };
    let openShots;
    await waitFor(
      async () => {
        const before = opened.pixels;
        openShots = await shoot();
        opened = differingPixels(...openShots);
        return opened.pixels > 0 && Math.abs(opened.pixels - before) <= 0.01 * opened.pixels; // drawn, and settled
      },
      OPEN_LIMIT_MS,
      1000,
    );
    mark("open seen");
    await seekToMiddle(page);
    mark("seeked");
    const urdfError = () => consoleErrors.find((t) => t.includes("Failed to parse URDF"));
    let shots;
    let robot = { pixels: 0, of: 0 };
    await waitFor(
      async () => {
        if (urdfError()) return true;
        shots = await shoot();
        robot = differingPixels(...shots);
        return robot.pixels > 0;
      },
      SETTLE_LIMIT_MS,
      1000,
    );
    mark("robot seen");
    await page.waitForTimeout(1000); // one more second for the renderer to settle, then the final pictures
    await waitFor(async () => {
      shots = await shoot();
      robot = differingPixels(...shots);
      return true;
    }, SETTLE_LIMIT_MS);
    const dir = path.join(outDir, path.basename(path.dirname(run.mcap)));
    fs.mkdirSync(dir, { recursive: true });
    fs.writeFileSync(path.join(dir, "3d-open.png"), openShots[0]);
    fs.writeFileSync(path.join(dir, "3d-urdf.png"), shots[0]);
    fs.writeFileSync(path.join(dir, "3d-bare.png"), shots[1]);
    await page.screenshot({ path: path.join(dir, "studio.png") });
    return {
      mcap: run.mcap,
      layout: run.layout,
      studio: "@foxglove/studio-base 1.48.0",
      load_ms: loadMs,
      total_ms: Date.now() - started,
      problems,
      problems_tab: says,
      urdf_parsed: urdfError() === undefined,
      urdf_error: urdfError(),
      layer_errors: layerErrors,
      robot_pixels_on_open: opened.pixels,
      robot_pixels: robot.pixels,
      panel_pixels: robot.of,
      screenshots: dir,
      console_errors: consoleErrors.filter((t) => !t.startsWith("Player problem")).slice(0, 20),
    };
  } finally {
    await page.close();
  }
}

async function main() {
  const args = parseArgs(process.argv.slice(2));
  const { server, url } = await listen(args.runs.map((r) => path.dirname(r.mcap)));
  const browser = await chromium.launch({ executablePath: CHROMIUM, args: CHROMIUM_ARGS });
  let bad = 0;
  try {
    for (const [index, run] of args.runs.entries()) {
      const result = await openRun(browser, url, index, run, args.out, args.imports);
      result.ok =
        result.problems.length === 0 &&
        result.urdf_parsed &&
        result.layer_errors.length === 0 &&
        result.robot_pixels > 0 &&
        result.robot_pixels_on_open >= OPEN_SHARE * result.robot_pixels;
      bad += result.ok ? 0 : 1;
      process.stdout.write(`${JSON.stringify(result)}\n`);
    }
  } finally {
    await browser.close();
    server.close();
  }
  return bad === 0 ? 0 : 1;
}

main().then(
  (code) => process.exit(code),
  (err) => {
    process.stderr.write(`${err?.stack ?? err}\n`);
    process.exit(2);
  },
);
