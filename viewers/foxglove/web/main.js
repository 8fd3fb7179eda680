// Mount Foxglove Studio's App (studio-base 1.48.0) as its web build does, with in-memory settings and
// layouts instead of the browser's IndexedDB (each run opens in a fresh page).
//   /?ds=remote-file&ds.url=<URL of run.mcap>&layoutId=<id>&layout=<URL of a layout .json>
// "ds"/"ds.url" are Studio's own deep link parameters (its RemoteDataSourceFactory reads the MCAP over
// HTTP Range requests); "layoutId" selects the layout stored under that id: the one fetched from "layout".
"use strict";
(async () => {
  const studio = window; // the UMD build of studio-base puts its exports on window
  const e = React.createElement;

  /** Studio's IAppConfiguration, in memory. */
  class MemoryAppConfiguration {
    constructor() {
      this.values = new Map();
      this.listeners = new Map();
    }
    get(key) {
      return this.values.get(key);
    }
    async set(key, value) {
      this.values.set(key, value);
      for (const cb of this.listeners.get(key) ?? []) cb(value);
    }
    addChangeListener(key, cb) {
      this.listeners.set(key, [...(this.listeners.get(key) ?? []), cb]);
    }
    removeChangeListener(key, cb) {
      this.listeners.set(key, (this.listeners.get(key) ?? []).filter((c) => c !== cb));
    }
  }

  /** Studio's ILayoutStorage, in memory. */
  class MemoryLayoutStorage {
    constructor(layouts) {
      this.layouts = new Map(layouts.map((l) => [l.id, l]));
    }
    async list() {
      return [...this.layouts.values()];
    }
    async get(_namespace, id) {
      return this.layouts.get(id);
    }
    async put(_namespace, layout) {
      this.layouts.set(layout.id, layout);
      return layout;
    }
    async delete(_namespace, id) {
      this.layouts.delete(id);
    }
    async importLayouts() {}
  }

  const params = new URLSearchParams(location.search);
  const layouts = [];
  if (params.get("layout")) {
    const data = await (await fetch(params.get("layout"))).json(); // the JSON "Export layout" writes
    const id = params.get("layoutId") ?? "dualarm";
    layouts.push({ id, name: "dualarm", permission: "CREATOR_WRITE", baseline: { data, savedAt: new Date().toISOString() }, working: undefined, syncInfo: undefined });
  }

  await studio.initI18n();
  ReactDOM.render(
    e(studio.App, {
      deepLinks: [location.href],
      appConfiguration: new MemoryAppConfiguration(),
      dataSources: [new studio.RemoteDataSourceFactory()],
      layoutStorage: new MemoryLayoutStorage(layouts),
      extensionLoaders: [],
      enableGlobalCss: true,
    }),
    document.getElementById("root"),
  );
})().catch((err) => console.error(err));
