// Parts of Foxglove Studio's own shipped code, loaded in Node.
//
// Why chunks are evaluated: @foxglove/studio-base 1.48.0 on npm ships its webpack build in assets/: a
// UMD entry (index.js, 56 MB) and ~80 numbered chunks ("<id>.<hash>.js") that push their module
// factories onto self.webpackChunk_foxglove_studio_base. The code we need was never published as a
// package of its own: the MCAP support code (parseChannel, McapIndexedIterableSource: monorepo
// workspace package @foxglove/mcap-support) and the URDF parser (@foxglove/den/urdf) exist only inside
// those chunks, and the message path code the Plot panel validates its paths with only inside index.js.
// This file is a minimal webpack-5 runtime that evaluates that code as shipped and hands out the
// functions Studio itself calls; nothing of Foxglove's code is copied or rewritten here.
"use strict";

const fs = require("node:fs");
const path = require("node:path");
const vm = require("node:vm");

const ASSETS_DIR = path.join(path.dirname(require.resolve("@foxglove/studio-base/package.json")), "assets");
const ENTRY = path.join(ASSETS_DIR, "index.js");
const CHUNK_GLOBAL = "webpackChunk_foxglove_studio_base";
/** The comment webpack writes before each module factory: a line "/***\/ <id>:". */
const MODULE_HEADER = /^\/\*\*\*\/ (\d+):$/gm;

/** Module factories by id, filled as chunks (or single modules of index.js) are evaluated. */
const factories = new Map();
/** Module exports cache by id. */
const cache = new Map();
/** Chunk file name of each module id (built once by scanning the chunk files). */
let moduleToChunkFile;
/** Text of index.js and, per module id, where its factory starts (built on first need). */
let entry;
const loadedChunkFiles = new Set();

function chunkFiles() {
  return fs.readdirSync(ASSETS_DIR).filter((name) => /^\d+\.[0-9a-f]+\.js$/.test(name));
}

function indexModules() {
  if (moduleToChunkFile === undefined) {
    moduleToChunkFile = new Map();
    for (const name of chunkFiles()) {
      const text = fs.readFileSync(path.join(ASSETS_DIR, name), "utf8");
      for (const match of text.matchAll(MODULE_HEADER)) {
        if (!moduleToChunkFile.has(match[1])) moduleToChunkFile.set(match[1], name);
      }
    }
  }
  return moduleToChunkFile;
}

function installChunkGlobal() {
  globalThis.self ??= globalThis;
  if (globalThis[CHUNK_GLOBAL] !== undefined) return;
  const queue = [];
  queue.push = ([_chunkIds, moreModules]) => {
    for (const [id, factory] of Object.entries(moreModules)) {
      if (!factories.has(id)) factories.set(id, factory);
    }
    return 0;
  };
  globalThis[CHUNK_GLOBAL] = queue;
}

function loadChunkFile(name) {
  if (loadedChunkFiles.has(name)) return;
  installChunkGlobal();
  const file = path.join(ASSETS_DIR, name);
  vm.runInThisContext(fs.readFileSync(file, "utf8"), { filename: file });
  loadedChunkFiles.add(name);
}

/**
 * The factory of one module of index.js, evaluated on its own. Running index.js whole would start
 * Studio (React, the DOM); its modules sit in one object literal, each "/***\/ <id>:" header followed
 * by "/***\/ ((module, exports, require) => {...})," — that expression is cut out and evaluated.
 */
function entryModules() {
  if (entry === undefined) {
    const text = fs.readFileSync(ENTRY, "utf8");
    const starts = new Map();
    for (const match of text.matchAll(MODULE_HEADER)) starts.set(match[1], match.index + match[0].length);
    entry = { text, starts };
  }
  return entry;
}

function entryFactory(id) {
  entryModules();
  const start = entry.starts.get(id);
  if (start === undefined) return undefined;
  const header = new RegExp(MODULE_HEADER.source, "gm"); // a copy: exec moves lastIndex, which matchAll would inherit
  header.lastIndex = start;
  const next = header.exec(entry.text);
  const end = next ? next.index : entry.text.indexOf("\n/******/", start);
  const source = entry.text.slice(start, end).trimEnd().replace(/,$/, "");
  return vm.runInThisContext(source, { filename: `${ENTRY}#module-${id}` });
}

function ensureFactory(id) {
  const key = String(id);
  if (!factories.has(key)) {
    const file = indexModules().get(key);
    if (file !== undefined) {
      loadChunkFile(file);
    } else {
      const factory = entryFactory(key);
      if (factory === undefined) throw new Error(`studio-base module ${key} is neither in a chunk nor in index.js of ${ASSETS_DIR}`);
      factories.set(key, factory);
    }
  }
  return factories.get(key);
}

function webpackRequire(id) {
  const key = String(id);
  if (cache.has(key)) return cache.get(key).exports;
  const module = { id: key, loaded: false, exports: {} };
  cache.set(key, module);
  ensureFactory(key).call(module.exports, module, module.exports, webpackRequire);
  module.loaded = true;
  return module.exports;
}

// The runtime helpers webpack 5 emits calls to (as in the runtime at the end of any webpack 5 bundle).
webpackRequire.d = (exports, definition) => {
  for (const key of Object.keys(definition)) {
    if (!Object.prototype.hasOwnProperty.call(exports, key)) Object.defineProperty(exports, key, { enumerable: true, get: definition[key] });
  }
};
webpackRequire.o = (obj, prop) => Object.prototype.hasOwnProperty.call(obj, prop);
webpackRequire.r = (exports) => {
  Object.defineProperty(exports, Symbol.toStringTag, { value: "Module" });
  Object.defineProperty(exports, "__esModule", { value: true });
};
webpackRequire.n = (module) => {
  const getter = module && module.__esModule ? () => module["default"] : () => module;
  webpackRequire.d(getter, { a: getter });
  return getter;
};
webpackRequire.t = function createFakeNamespace(value, mode) {
  if (mode & 1) value = webpackRequire(value);
  if (mode & 8) return value;
  if (typeof value === "object" && value) {
    if (mode & 4 && value.__esModule) return value;
    if (mode & 16 && typeof value.then === "function") return value;
  }
  const ns = Object.create(null);
  webpackRequire.r(ns);
  const def = {};
  const leaf = [null, Object.getPrototypeOf({}), Object.getPrototypeOf([]), Object.getPrototypeOf(Object.getPrototypeOf)];
  for (let current = mode & 2 && value; typeof current === "object" && !leaf.includes(current); current = Object.getPrototypeOf(current)) {
    for (const key of Object.getOwnPropertyNames(current)) def[key] = () => value[key];
  }
  def["default"] = () => value;
  webpackRequire.d(ns, def);
  return ns;
};
webpackRequire.g = globalThis;
webpackRequire.p = `file://${ASSETS_DIR}/`;
webpackRequire.nmd = (module) => {
  module.paths = [];
  module.children ??= [];
  return module;
};
webpackRequire.e = async (chunkId) => {
  const name = chunkFiles().find((file) => file.startsWith(`${chunkId}.`));
  if (name === undefined) throw new Error(`studio-base chunk ${chunkId} not found in ${ASSETS_DIR}`);
  loadChunkFile(name);
};

/** The (first) chunk file whose text contains `marker`, and its text. */
function findChunkText(marker) {
  for (const name of chunkFiles()) {
    const text = fs.readFileSync(path.join(ASSETS_DIR, name), "utf8");
    if (text.includes(marker)) return { name, text };
  }
  throw new Error(`no studio-base chunk contains ${JSON.stringify(marker)}`);
}

/** The id of the module (its "/***\/ <id>:" header) that contains text offset `offset`. */
function moduleIdAt(text, offset) {
  let id;
  for (const match of text.matchAll(MODULE_HEADER)) {
    if (match.index > offset) break;
    id = match[1];
  }
  return id;
}

/**
 * Evaluate one webpack module again with one statement appended to its body that hands out top-level
 * bindings of the modules concatenated into it (webpack drops unused exports: Studio's MCAP worker
 * module exports nothing, but its scope holds parseChannel etc.). It calls comlink's expose on the
 * worker global at load, which needs an `addEventListener`: a no-op here.
 */
function exposeFromModule(moduleId, names) {
  const source = ensureFactory(moduleId).toString();
  const close = source.lastIndexOf("}");
  const patched = `${source.slice(0, close)}\n;__fxExpose({ ${names.join(", ")} });\n}`;
  let exposed;
  globalThis.__fxExpose = (bindings) => {
    exposed = bindings;
  };
  globalThis.addEventListener ??= () => {};
  const rebuilt = vm.runInThisContext(`(${patched})`, { filename: `studio-base-module-${moduleId}.js` });
  const module = { id: `${moduleId}-exposed`, loaded: false, exports: {} };
  rebuilt.call(module.exports, module, module.exports, webpackRequire);
  delete globalThis.__fxExpose;
  return exposed;
}

/**
 * Foxglove's MCAP support code as bundled in Studio (the MCAP worker module): parseChannel and the
 * McapIndexedIterableSource whose initialize() and messageIterator() report the player's "problems".
 */
function loadMcapSupport() {
  const marker = ";// CONCATENATED MODULE: ../mcap-support/src/parseChannel.ts";
  const { text } = findChunkText(marker);
  return exposeFromModule(moduleIdAt(text, text.indexOf(marker)), ["parseChannel", "McapIndexedIterableSource"]);
}

/**
 * Foxglove's URDF parser (@foxglove/den/urdf: parser.ts and index.ts), cut out of the 3D panel's chunk
 * between webpack's own "CONCATENATED MODULE" markers. It needs DOMParser and XMLDocument (the caller
 * provides them, from jsdom) and the bundled xacro-parser module it names.
 */
function loadUrdfParser() {
  const start = ";// CONCATENATED MODULE: ../den/urdf/parser.ts";
  const indexMarker = ";// CONCATENATED MODULE: ../den/urdf/index.ts";
  const { text } = findChunkText(start);
  const from = text.indexOf(start);
  const indexAt = text.indexOf(indexMarker, from);
  const to = text.indexOf(";// CONCATENATED MODULE:", indexAt + indexMarker.length);
  const xacro = /var XacroParser = __webpack_require__\((\d+)\);/.exec(text.slice(Math.max(0, from - 400), from));
  if (indexAt < 0 || to < 0 || !xacro) throw new Error("studio-base chunk layout not as expected around ../den/urdf");
  const body = `${text.slice(from, to)}\n;return { parseRobot: urdf_parseRobot };`;
  const make = vm.runInThisContext(`(function (XacroParser) {\n${body}\n})`, { filename: "studio-base-den-urdf.js" });
  return make(webpackRequire(xacro[1]));
}

/**
 * A module's exports by the names they have in Studio's source: webpack renames exports ("pb", "ZP")
 * and writes the source name beside each in a comment, `"pb": () => (/* binding *\/ messagePathStructures)`.
 */
function bindings(moduleId) {
  const exports = webpackRequire(moduleId);
  const named = {};
  for (const [, key, name] of ensureFactory(moduleId).toString().matchAll(/"(\w+)": \(\) => \((?:\/\* binding \*\/ )?(\w+)\)/g)) {
    named[name] = exports[key];
  }
  return named;
}

/**
 * What Studio's message path input (MessagePathInput.tsx) uses to mark a Plot path valid: parseRosPath,
 * and messagePathStructures / traverseStructure / validTerminatingStructureItem over the player's
 * datatypes, with the Plot panel's plotableRosTypes (a literal array in the Plot panel's chunk, read
 * from there: the panel's module itself needs React).
 */
function loadMessagePathSupport() {
  const { text } = entryModules();
  const structuresAt = text.indexOf(";// CONCATENATED MODULE: ./src/components/MessagePathSyntax/messagePathsForDatatype.ts");
  const parseRosPathId = /\/\/ EXTERNAL MODULE: \.\/src\/components\/MessagePathSyntax\/parseRosPath\.ts\nvar parseRosPath = __webpack_require__\((\d+)\);/.exec(text);
  const { text: plotText } = findChunkText("const plotableRosTypes = [");
  const plotable = /const plotableRosTypes = (\[[^\]]*\]);/.exec(plotText);
  if (structuresAt < 0 || !parseRosPathId || !plotable) throw new Error("studio-base layout not as expected around the MessagePathSyntax modules");
  const { messagePathStructures, traverseStructure, validTerminatingStructureItem } = bindings(moduleIdAt(text, structuresAt));
  const parseRosPath = bindings(parseRosPathId[1]).__WEBPACK_DEFAULT_EXPORT__;
  const found = { parseRosPath, messagePathStructures, traverseStructure, validTerminatingStructureItem };
  for (const [name, value] of Object.entries(found)) {
    if (typeof value !== "function") throw new Error(`studio-base: ${name} not found`);
  }
  return { ...found, plotableRosTypes: vm.runInNewContext(plotable[1]) };
}

module.exports = { ASSETS_DIR, loadMcapSupport, loadUrdfParser, loadMessagePathSupport };
