// vtpk.js against hostile or broken HTTP servers on 127.0.0.1, one case per run:
//
//   node --max-old-space-size=64 tests/vtpk/hostile_hosts.mjs CASE [PACK]
//
// prints one line of JSON: what `VtpkPack.open` (and, for a good pack, a tile's entry and
// payload) gave (`kind` and `message` of the error, or "OK"), the body bytes the server wrote
// (`served`), the process's peak resident memory (`maxRssKiB`) and the request headers the
// server saw. `tests/it/vtpk_js.rs` runs every case and judges the lines.
//
// Hostile servers pour up to POUR bytes, waiting whenever the socket is full, and stop when the
// client hangs up: a reader that stops at the bytes it asked for makes them stop within a few
// socket buffers, one that reads whole replies makes them pour everything into its memory.
import { createServer } from "node:http";
import { readFileSync } from "node:fs";
import { gzipSync } from "node:zlib";
import { VtpkPack } from "../../web/vtpk/vtpk.js";

const POUR = 256 << 20;
const [name, packPath] = process.argv.slice(2);
const pack = packPath ? readFileSync(packPath) : null;
/** The "file" the hostile servers claim to serve: its length, for their Content-Range. */
const FILE_LEN = 1 << 20;

let served = 0;
/** @type {Record<string, string | undefined>[]} */
const seen = [];

/**
 * Writes `chunk` over and over, up to `limit` bytes, waiting for the socket to drain; stops when
 * the client goes away.
 * @param {import("node:http").ServerResponse} res
 * @param {Buffer} chunk
 * @param {number} limit
 */
async function pour(res, chunk, limit = POUR) {
  let closed = false;
  const gone = new Promise((resolve) => res.once("close", resolve)).then(() => (closed = true));
  for (let sent = 0; sent < limit && !closed; sent += chunk.length) {
    served += chunk.length;
    if (!res.write(chunk)) await Promise.race([new Promise((resolve) => res.once("drain", resolve)), gone]);
  }
  if (!closed) res.end();
}

/** The asked range of a request: [start, end] inclusive. @param {import("node:http").IncomingMessage} req */
function asked(req) {
  const m = /^bytes=(\d+)-(\d+)$/.exec(req.headers.range ?? "");
  if (!m) throw new Error(`no range in ${JSON.stringify(req.headers)}`);
  return [Number(m[1]), Number(m[2])];
}

const noise = Buffer.alloc(64 << 10, 0x5a);
// 1 MiB of zeros is 1 KiB of gzip; members repeated are one valid gzip stream (RFC 1952).
const member = gzipSync(Buffer.alloc(1 << 20), { level: 9 });

/** Each case: how the server answers, and the options the reader is given. */
const cases = {
  // A correct 206 head, then a body that never ends (no Content-Length: chunked).
  "endless body": (req, res) => {
    const [a, b] = asked(req);
    res.writeHead(206, { "Content-Range": `bytes ${a}-${b}/${FILE_LEN}` });
    pour(res, noise);
  },
  // A 206 whose body is 1 KiB of gzip per MiB it inflates to.
  "gzip bomb": (req, res) => {
    const [a, b] = asked(req);
    res.writeHead(206, { "Content-Range": `bytes ${a}-${b}/${FILE_LEN}`, "Content-Encoding": "gzip" });
    pour(res, member, POUR >> 10);
  },
  // The same, read as a page on another origin reads it: Content-Encoding is not exposed to it.
  "gzip bomb, encoding hidden": "gzip bomb",
  // A Content-Length of 1 GiB for a 512-byte range, and the bytes to go with it.
  "oversize Content-Length": (req, res) => {
    const [a, b] = asked(req);
    res.writeHead(206, { "Content-Range": `bytes ${a}-${b}/${FILE_LEN}`, "Content-Length": String(1 << 30) });
    pour(res, noise, 1 << 30);
  },
  // Takes the request and never answers.
  "silent": () => {},
  // Answers the head, then one byte every 100 ms.
  "trickle": (req, res) => {
    const [a, b] = asked(req);
    res.writeHead(206, { "Content-Range": `bytes ${a}-${b}/${FILE_LEN}`, "Content-Length": String(b - a + 1) });
    const timer = setInterval(() => {
      served++;
      res.write(Buffer.from([0]));
    }, 100);
    res.on("close", () => clearInterval(timer));
  },
  // Promises the range, sends part of it and closes the connection.
  "cut short": (req, res) => {
    const [a, b] = asked(req);
    res.writeHead(206, { "Content-Range": `bytes ${a}-${b}/${FILE_LEN}`, "Content-Length": String(b - a + 1) });
    served += 100;
    res.write(Buffer.alloc(100), () => res.destroy());
  },
  // Nothing listens at the port.
  "refused": null,
  "503": (req, res) => res.writeHead(503).end(),
  "404": (req, res) => res.writeHead(404).end(),
  // A plain static host with the pack: everything must work.
  "good": (req, res) => {
    if (!pack) throw new Error("the good case needs a pack");
    const [a, b] = asked(req);
    const end = Math.min(b, pack.length - 1);
    res.writeHead(206, { "Content-Range": `bytes ${a}-${end}/${pack.length}`, "Content-Length": String(end - a + 1) });
    served += end - a + 1;
    res.end(pack.subarray(a, end + 1));
  },
};

if (!(name in cases)) throw new Error(`no case ${JSON.stringify(name)}: ${Object.keys(cases).join(", ")}`);
let handler = cases[name];
if (typeof handler === "string") handler = cases[handler];
const server = createServer((req, res) => {
  seen.push({ range: req.headers.range, "accept-encoding": req.headers["accept-encoding"] });
  handler(req, res);
});
await new Promise((resolve) => server.listen(0, "127.0.0.1", resolve));
let port = server.address().port;
if (handler === null) await new Promise((resolve) => server.close(resolve));

/** @type {import("../../web/vtpk/vtpk.js").VtpkOptions} */
const options = { timeout: name === "silent" || name === "trickle" ? 1000 : undefined };
if (name.endsWith("encoding hidden")) {
  options.fetch = async (url, init) => {
    const reply = await fetch(url, init);
    const headers = new Headers(reply.headers);
    headers.delete("Content-Encoding");
    return new Response(reply.body, { status: reply.status, headers });
  };
}
let result;
try {
  const p = await VtpkPack.open(`http://127.0.0.1:${port}/photo.vtpk`, options);
  const entry = await p.entry(0, 0, 0);
  if (entry.len) await p.payload(entry, "tile (0, 0, 0)");
  result = { kind: "OK", message: "" };
} catch (e) {
  result = e && e.name === "VtpkError" ? { kind: e.kind, message: e.message } : { kind: `not a VtpkError: ${e && e.name}`, message: String(e && e.message) };
}
server.closeAllConnections?.();
server.close();
// The peak of this process's own memory (VmHWM), not ru_maxrss: Linux carries into ru_maxrss
// the memory of the test process that forked node before its exec.
const hwm = /VmHWM:\s+(\d+) kB/.exec(readFileSync("/proc/self/status", "utf8"));
const maxRssKiB = hwm ? Number(hwm[1]) : process.resourceUsage().maxRSS;
console.log(JSON.stringify({ name, ...result, served, maxRssKiB, seen }));
process.exit(0);
