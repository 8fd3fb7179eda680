#!/usr/bin/env node
// Read dualarm run.mcap files with Foxglove Studio 1.48.0's own parsers, in Node (~1 s per run after
// ~3 s loading Studio's code; the browser check, open-in-studio.cjs, takes ~30 s per run).
//
//   node check-mcap.cjs [--layout LAYOUT.json] RUN.mcap [[--layout LAYOUT.json] RUN.mcap ...]
//
// Prints one JSON line per channel of each file ({"mcap", "topic", ..., "ok"}):
//   - Studio's parseChannel (JSON schema / protobuf -> datatypes + deserializer) must succeed,
//   - Studio's McapIndexedIterableSource must report no problem for the topic (these are what its
//     Problems tab lists), and every message must decode through its messageIterator,
//   - /robot_description (std_msgs/String) must parse with Studio's URDF parser (xacro pass, then
//     parseRobot) as the 3D panel's URDF layer does, and every mesh it draws must be one Studio can
//     fetch in a page and load (meshError); "urdf" gives its link/joint/mesh counts.
// With --layout (the layout for the next file), one more line per panel ({"mcap", "panel", ...}):
//   - Plot: each path as Studio's path input judges it (parseRosPath; traverseStructure over the
//     player's datatypes ending on one of the Plot panel's plotableRosTypes), and how many messages
//     hold a value there;
//   - Tab: its tabs' panels, each of which must be configured in the layout;
//   - 3D: the topics it configures that the file lacks, whether its followTf frame is on /tf, the
//     frames of its SceneUpdate topics that /tf does not join to that frame, and each URDF layer's URDF,
//     fetched from its url and checked as /robot_description is ("urdf_layers").
// Exit 0 when every line is ok, 1 otherwise, 2 when the harness itself failed.
"use strict";

const fs = require("node:fs");
const { JSDOM } = require("jsdom");
const { McapIndexedReader } = require("@mcap/core");
const { loadDecompressHandlers } = require("@mcap/support");
const { loadMcapSupport, loadUrdfParser, loadMessagePathSupport } = require("./lib/studioBundle.cjs");

const URDF_TOPIC = "/robot_description";

/** A @mcap/core IReadable over a file. */
async function fileReadable(file) {
  const handle = await fs.promises.open(file, "r");
  const { size } = await handle.stat();
  return {
    handle,
    size: async () => BigInt(size),
    read: async (offset, length) => {
      const buffer = new Uint8Array(Number(length));
      await handle.read(buffer, 0, buffer.byteLength, Number(offset));
      return buffer;
    },
  };
}

/** The XML DOM Studio's URDF parser expects of a browser, from jsdom. */
function installDom() {
  const { window } = new JSDOM("");
  for (const name of ["DOMParser", "XMLDocument", "XMLSerializer", "Node", "Element", "Document"]) globalThis[name] ??= window[name];
}

/** Problems Studio's source reported for a topic (its messages name the topic). */
function problemsFor(problems, topic, channelId) {
  return problems.filter((p) => p.message.includes(`topic ${topic} (channel ${channelId})`) || p.message.endsWith(` on ${topic}`));
}

/** A problem as Studio's Problems tab shows it: its message, plus its error's when not already in it. */
function problemText(problem) {
  const detail = problem.error?.message ?? (problem.error === undefined ? "" : String(problem.error));
  return detail === "" || problem.message.includes(detail) ? problem.message : `${problem.message}: ${detail}`;
}

// The media types Studio's ModelCache loads a mesh by (ModelCache.js), and its file name endings.
const MESH_TYPES = [
  [["model/gltf", "model/gltf-binary", "model/gltf+json"], /\.gl(b|tf)$/i],
  [["model/stl", "model/x.stl-ascii", "model/x.stl-binary", "application/sla"], /\.stl$/i],
  [["model/vnd.collada+xml"], /\.dae$/i],
  [["model/obj", "text/prs.wavefront-obj"], /\.obj$/i],
];

/**
 * Whether Studio's 3D panel can draw a URDF mesh, as its URDF layer and ModelCache do it: the URL is
 * `new URL(filename, baseUrl)` with no base for a URDF from a topic (Urdfs.js createMeshMarker), fetched
 * by the page (only a data: URL is there offline: a browser page reads no file:// or package://), and
 * loaded by its media type or its name's ending (ModelCache._loadModel). Null when it can, else why not.
 */
async function meshError(filename) {
  let url;
  try {
    url = new URL(filename);
  } catch (err) {
    return `Failed to construct 'URL': Invalid URL (${filename.slice(0, 80)})`;
  }
  if (url.protocol !== "data:") return `${url.protocol} URL ${filename.slice(0, 80)}: a page cannot fetch it offline`;
  const response = await fetch(url);
  const bytes = (await response.arrayBuffer()).byteLength;
  const type = response.headers.get("content-type") ?? "";
  if (bytes < 4) return `${bytes} bytes received`;
  if (!MESH_TYPES.some(([types, ending]) => types.includes(type) || ending.test(filename))) return `Unknown ${bytes} byte mesh (content-type: "${type}")`;
  return null;
}

async function checkUrdf(parseRobot, message) {
  if (typeof message?.data !== "string") return { ok: false, error: "message has no string field 'data' (std_msgs/String)" };
  let robot;
  try {
    robot = await parseRobot(message.data, async (url) => {
      throw new Error(`URDF refers to an external file ${url}`);
    });
  } catch (err) {
    return { ok: false, error: String(err?.message ?? err) };
  }
  // what the URDF layer draws: each link's visuals, or its colliders when it has none (Urdfs.js _loadRobot)
  const shapes = [...robot.links.values()].flatMap((link) => (link.visuals.length > 0 ? link.visuals : link.colliders));
  const meshes = shapes.filter((shape) => shape.geometry.geometryType === "mesh");
  const errors = (await Promise.all(meshes.map((shape) => meshError(shape.geometry.filename)))).filter((e) => e !== null);
  return {
    ok: errors.length === 0,
    robot: robot.name,
    links: robot.links.size,
    joints: robot.joints.size,
    meshes: meshes.length,
    ...(errors.length > 0 ? { error: `${errors.length} of ${meshes.length} meshes cannot be drawn: ${errors[0]}` } : {}),
  };
}

/** The value at `names` inside a decoded message, or undefined. */
function valueAt(message, names) {
  let value = message;
  for (const name of names) value = value == undefined ? undefined : value[name];
  return value;
}

/** Panels of a layout as checks: Plot paths (parsed, with a value counter) and 3D panels. */
function layoutChecks(layout, studio, init) {
  const structures = studio.messagePathStructures(init.datatypes);
  const checks = [];
  for (const [panel, config] of Object.entries(layout.configById ?? {})) {
    const kind = panel.split("!")[0];
    if (kind === "Plot") {
      const paths = (config.paths ?? []).filter((p) => p.enabled !== false).map((p) => {
        const rosPath = studio.parseRosPath(p.value);
        const topic = rosPath && init.topics.find((t) => t.name === rosPath.topicName);
        let error;
        if (!rosPath) error = "not a message path";
        else if (!topic) error = `no topic ${rosPath.topicName}`;
        else {
          const traversal = studio.traverseStructure(structures[topic.schemaName], rosPath.messagePath);
          if (!traversal.valid || !studio.validTerminatingStructureItem(traversal.structureItem, studio.plotableRosTypes)) error = "not a plottable field of the topic's schema";
        }
        const names = rosPath?.messagePath.every((part) => part.type === "name") ? rosPath.messagePath.map((part) => part.name) : undefined;
        return { path: p.value, topic: rosPath?.topicName, names, error, values: 0 };
      });
      checks.push({ panel, kind, paths });
    } else if (kind === "Tab") {
      // each tab's panels, the leaves of its layout tree (Studio's mosaic: a panel id, or {first, second, ...})
      const leaves = (node) => (typeof node === "string" ? [node] : node ? [...leaves(node.first), ...leaves(node.second)] : []);
      const tabs = (config.tabs ?? []).map((tab) => ({ title: tab.title, panels: leaves(tab.layout) }));
      checks.push({ panel, kind, tabs, missing: tabs.flatMap((tab) => tab.panels).filter((id) => !(id in layout.configById)) });
    } else if (kind === "3D") {
      const urdfLayers = Object.entries(config.layers ?? {}).filter(([, layer]) => layer.layerId === "foxglove.Urdf" && layer.visible !== false);
      checks.push({ panel, kind, follow: config.followTf, topics: Object.keys(config.topics ?? {}), urdfLayers });
    }
  }
  return checks;
}

/** The frames /tf joins to `frame` (breadth-first over parent-child edges, either way). */
function joined(edges, frame) {
  const seen = new Set([frame]);
  const todo = [frame];
  while (todo.length > 0) {
    for (const next of edges.get(todo.pop()) ?? []) {
      if (!seen.has(next)) {
        seen.add(next);
        todo.push(next);
      }
    }
  }
  return seen;
}

async function checkFile(file, layoutFile, studio) {
  const readable = await fileReadable(file);
  const reader = await McapIndexedReader.Initialize({ readable, decompressHandlers: await loadDecompressHandlers() });
  const source = new studio.McapIndexedIterableSource(reader);
  const init = await source.initialize();
  const checks = layoutFile ? layoutChecks(JSON.parse(fs.readFileSync(layoutFile, "utf8")), studio, init) : [];
  const plotPaths = checks.flatMap((c) => c.paths ?? []).filter((p) => p.error === undefined && p.names);

  const decoded = new Map(); // topic -> {count, first}
  const decodeProblems = [];
  const edges = new Map(); // /tf frame -> frames it is a parent or child of
  const entityFrames = new Map(); // SceneUpdate topic -> frame ids of its entities
  for await (const item of source.messageIterator({ topics: init.topics.map((t) => t.name) })) {
    if (item.type === "problem") {
      decodeProblems.push(item.problem);
      continue;
    }
    const { topic, message, schemaName } = item.msgEvent;
    const entry = decoded.get(topic) ?? { count: 0, first: message };
    entry.count += 1;
    decoded.set(topic, entry);
    for (const p of plotPaths) {
      if (p.topic === topic && ["number", "bigint", "boolean"].includes(typeof valueAt(message, p.names))) p.values += 1;
    }
    if (schemaName === "foxglove.FrameTransforms") {
      for (const t of message.transforms) {
        edges.set(t.parent_frame_id, (edges.get(t.parent_frame_id) ?? new Set()).add(t.child_frame_id));
        edges.set(t.child_frame_id, (edges.get(t.child_frame_id) ?? new Set()).add(t.parent_frame_id));
      }
    } else if (schemaName === "foxglove.SceneUpdate") {
      const frames = entityFrames.get(topic) ?? new Set();
      for (const entity of message.entities) frames.add(entity.frame_id);
      entityFrames.set(topic, frames);
    }
  }

  const problems = [...init.problems, ...decodeProblems];
  const lines = [];
  for (const channel of [...reader.channelsById.values()].sort((a, b) => a.id - b.id)) {
    const schema = reader.schemasById.get(channel.schemaId);
    const line = { mcap: file, topic: channel.topic, schema: schema?.name, messages: Number(reader.statistics?.channelMessageCounts.get(channel.id) ?? 0n) };
    try {
      line.datatypes = studio.parseChannel({ messageEncoding: channel.messageEncoding, schema }).datatypes.size;
    } catch (err) {
      line.parse_error = String(err?.message ?? err);
    }
    line.problems = problemsFor(problems, channel.topic, channel.id).map(problemText);
    line.decoded = decoded.get(channel.topic)?.count ?? 0;
    if (channel.topic === URDF_TOPIC) {
      line.urdf = line.decoded > 0 ? await checkUrdf(studio.parseRobot, decoded.get(URDF_TOPIC).first) : { ok: false, error: "no decoded message" };
    }
    line.ok = line.parse_error === undefined && line.problems.length === 0 && line.decoded === line.messages && (line.urdf?.ok ?? true);
    lines.push(line);
  }
  for (const problem of problems.filter((p) => !lines.some((l) => l.problems.includes(problemText(p))))) {
    lines.push({ mcap: file, topic: null, ok: false, problems: [problemText(problem)] });
  }
  for (const check of checks) {
    const line = { mcap: file, layout: layoutFile, panel: check.panel, kind: check.kind };
    if (check.kind === "Plot") {
      line.paths = check.paths.map(({ path, error, values }) => ({ path, error, values }));
      line.ok = check.paths.every((p) => p.error === undefined && p.values > 0);
    } else if (check.kind === "Tab") {
      line.tabs = check.tabs;
      line.missing_panels = check.missing;
      line.ok = check.tabs.length > 0 && check.missing.length === 0;
    } else {
      const reach = joined(edges, check.follow);
      line.follow = check.follow;
      line.follow_on_tf = edges.has(check.follow);
      line.absent_topics = check.topics.filter((t) => !init.topics.some((known) => known.name === t));
      line.unjoined_frames = Object.fromEntries(check.topics.filter((t) => entityFrames.has(t)).map((t) => [t, [...entityFrames.get(t)].filter((f) => !reach.has(f))]));
      // a URDF layer is fetched from its url when the panel mounts (Urdfs.js _loadUrdf -> _fetchUrdf), then parsed as
      // the /robot_description topic is
      line.urdf_layers = {};
      for (const [id, layer] of check.urdfLayers) {
        let text;
        try {
          text = await (await fetch(layer.url)).text();
        } catch (err) {
          line.urdf_layers[id] = { ok: false, error: `Failed to load URDF from "${String(layer.url).slice(0, 80)}": ${err?.message ?? err}` };
          continue;
        }
        line.urdf_layers[id] = await checkUrdf(studio.parseRobot, { data: text });
      }
      line.ok =
        line.follow_on_tf &&
        Object.values(line.unjoined_frames).every((frames) => frames.length === 0) &&
        Object.values(line.urdf_layers).every((urdf) => urdf.ok);
    }
    lines.push(line);
  }
  await readable.handle.close();
  return lines;
}

function parseArgs(argv) {
  const files = [];
  let layout;
  for (let i = 0; i < argv.length; i++) {
    if (argv[i] === "--layout") layout = argv[++i];
    else {
      files.push({ mcap: argv[i], layout });
      layout = undefined;
    }
  }
  return files;
}

async function main(argv) {
  const files = parseArgs(argv);
  if (files.length === 0) {
    process.stderr.write("usage: node check-mcap.cjs [--layout LAYOUT.json] RUN.mcap [...]\n");
    return 2;
  }
  installDom();
  const studio = { ...loadMcapSupport(), ...loadUrdfParser(), ...loadMessagePathSupport() };
  let bad = 0;
  for (const { mcap, layout } of files) {
    const lines = await checkFile(mcap, layout, studio);
    for (const line of lines) process.stdout.write(`${JSON.stringify(line)}\n`);
    const failing = lines.filter((l) => !l.ok).length;
    process.stderr.write(`${mcap}: ${lines.length - failing} ok, ${failing} failing (Foxglove studio-base 1.48.0 parsers)\n`);
    bad += failing;
  }
  return bad === 0 ? 0 : 1;
}

main(process.argv.slice(2)).then(
  (code) => process.exit(code),
  (err) => {
    process.stderr.write(`${err?.stack ?? err}\n`);
    process.exit(2);
  },
);
