// Static HTTP server for the Studio page, on 127.0.0.1 only:
//   /          -> web/ (index.html, main.js)
//   /studio/   -> @foxglove/studio-base's assets/ (Studio's own webpack build, unchanged)
//   /vendor/   -> node_modules/ (React 17's UMD builds, the externals of that build)
//   /data/<i>/ -> the i-th data directory (a run directory holding run.mcap), with HTTP Range
//                 requests, which Studio's remote-file data source reads the MCAP index with.
//
//   node serve.cjs DATA_DIR [PORT]      (PORT 0 = any free port; prints the URL)
"use strict";
const http = require("node:http");
const path = require("node:path");
const serveStatic = require("serve-static");
const finalhandler = require("finalhandler");

function createServer(dataDirs) {
  const mounts = [
    ["/studio/", serveStatic(path.join(path.dirname(require.resolve("@foxglove/studio-base/package.json")), "assets"))],
    ["/vendor/", serveStatic(path.join(__dirname, "node_modules"))],
    ...dataDirs.map((dir, i) => [`/data/${i}/`, serveStatic(path.resolve(dir), { acceptRanges: true })]),
    ["/", serveStatic(path.join(__dirname, "web"))],
  ];
  return http.createServer((req, res) => {
    const done = finalhandler(req, res);
    const mount = mounts.find(([prefix]) => req.url.startsWith(prefix));
    req.url = req.url.slice(mount[0].length - 1);
    mount[1](req, res, done);
  });
}

/** Serve `dataDirs` (as /data/0/, /data/1/, ...) on a free port of 127.0.0.1; resolves to {server, url}. */
function listen(dataDirs, port = 0) {
  return new Promise((resolve) => {
    const server = createServer(dataDirs);
    server.listen(port, "127.0.0.1", () => resolve({ server, url: `http://127.0.0.1:${server.address().port}` }));
  });
}

module.exports = { listen };

if (require.main === module) {
  listen([process.argv[2] ?? "."], Number(process.argv[3] ?? 0)).then(({ url }) => console.log(`${url}/?ds=remote-file&ds.url=${url}/data/0/run.mcap`));
}
