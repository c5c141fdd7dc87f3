// @ts-check
/**
 * A `.vtpk` tile pack (docs/pack-format.md) read over HTTP `Range` requests, and an
 * OpenSeadragon tile source drawing it: one file on any static host, no server of ours.
 *
 * ```js
 * import { VtpkTileSource } from "./vtpk.js";
 * OpenSeadragon({ id: "viewer", tileSources: await VtpkTileSource.open("photo.vtpk") });
 * ```
 *
 * What it reads, in order: the first 512 bytes (header, level table and, for a tiny pack, the
 * whole index and metadata), then the index (whole when it is at most `wholeIndexUpTo` bytes,
 * else in blocks of 64 entries as tiles need them), then tile payloads. Reads asked for within
 * a few milliseconds of each other are sorted and merged when they lie close together in the
 * file, so a view's tiles usually arrive in a handful of requests. Everything fetched is
 * checked: the header's CRC-32C and fields before anything is sized from them, the metadata's
 * CRC, the CRC of the level table and index and the content hash (before any entry is used
 * when the index is read whole; once every block has arrived otherwise, each entry being
 * checked for sense before use, and every later read failing if they do not match), and every
 * tile payload's CRC. A tile that fails is reported (`errors`, the `onError` option,
 * OpenSeadragon's `tile-load-failed`) and not drawn.
 *
 * What a server sends is held to what was asked: a reply is read as a stream and refused (and
 * its connection dropped) as soon as it runs past the bytes asked for, whatever its headers say
 * (a `Content-Length` over them is refused before the body is read); each request has an
 * overall deadline (`timeout`). Every failure is a {@link VtpkError} whose `kind` says what the
 * caller can do about it.
 *
 * JPEG and PNG tiles are decoded by the browser, and JPEG XL tiles where the browser decodes
 * JPEG XL (Chrome 155, Firefox 158, Safari 17 on; `open` asks it once, with a 1x1 image, and
 * refuses a JPEG XL pack in a browser that does not); raw tiles (8 or 16 bits) are converted
 * here, which is cheap. zstd, zstd-delta, BC1 and BC7 tiles would need a decoder shipped with
 * the page, so such packs are refused at `open` with a message saying how to write one that
 * works.
 * @module vtpk
 */

/** The pack signature: `\x89VTP\r\n\x1a\n`. */
const SIGNATURE = [0x89, 0x56, 0x54, 0x50, 0x0d, 0x0a, 0x1a, 0x0a];
const HEADER_LEN = 192;
const LEVEL_LEN = 32;
const ENTRY_LEN = 24;
/** Index entries fetched together in block mode: 1.5 KiB. A view needs a few entries of each
 * of a few tile rows; neighbouring blocks are merged into one request, so small blocks cost
 * no requests and fetch fewer entries no view needs (256-entry blocks made the first view of a
 * 16384² pack fetch 2 KiB of entries it never used). */
const BLOCK_ENTRIES = 64;
/** The first read: the header and a level table of up to 10 levels (a pack up to 512 pages a
 * side; a longer table is read next) and, for packs of a few tiles, index and metadata; small,
 * since what follows is index entries and finest-level tiles that a first view does not show. */
const FIRST_READ = 512;
/** The caps vortex_pack::Limits holds a header to by default, so a hostile header sizes nothing
 * big: the tile size, the tiles, and any one buffer (the metadata, a payload). */
const MAX_TILE_SIZE = 16384;
const MAX_TILES = 2 ** 29;
const MAX_DECODED_BYTES = 2 ** 30;
/** The default overall deadline of one request, in milliseconds: a reply of `maxSpan` (4 MiB)
 * needs about 1.1 Mbit/s to make it. */
const TIMEOUT = 30000;

/** Tile kinds (docs/pack-format.md, "Index"). */
const KIND = { absent: 0, constant: 1, raw: 2, zstd: 3, png: 4, jpeg: 5, bc1: 6, bc7: 7, zstdDelta: 8, jxl: 9 };
const KIND_NAMES = ["absent", "constant", "raw", "zstd", "png", "jpeg", "bc1", "bc7", "zstd-delta", "jxl"];
/** The image type a browser decodes each image kind's payload as. */
const IMAGE_TYPES = { [KIND.png]: "image/png", [KIND.jpeg]: "image/jpeg", [KIND.jxl]: "image/jxl" };

/** A 1x1 lossless JPEG XL image (`cjxl -d 0 -e 1` of one red texel). */
const JXL_PROBE = new Uint8Array([
  0xff, 0x0a, 0x00, 0x10, 0x10, 0x50, 0x5c, 0x08, 0x08, 0x02, 0x01, 0x00, 0x3c, 0x00, 0x4b,
  0x12, 0xa5, 0x42, 0x85, 0x24, 0xd6, 0xc8, 0xed, 0x1b, 0x0f, 0x00, 0xdf, 0xaf, 0x03,
]);
/** @type {Promise<boolean> | null} */
let jxlDecodes = null;

/** Whether this browser decodes JPEG XL: the probe image decoded, once a page. @returns {Promise<boolean>} */
function browserDecodesJxl() {
  if (typeof createImageBitmap !== "function") return Promise.resolve(false);
  jxlDecodes ??= createImageBitmap(new Blob([JXL_PROBE], { type: "image/jxl" })).then(
    (bitmap) => {
      const ok = bitmap.width === 1 && bitmap.height === 1;
      bitmap.close();
      return ok;
    },
    () => false,
  );
  return jxlDecodes;
}

/**
 * What went wrong, which says what the caller can do about it:
 *
 * - `io`: the request failed this time (no connection, a connection dropped or a reply cut
 *   short, no complete reply within `timeout`, HTTP 408, 429 or 5xx). Reading again later may
 *   work.
 * - `host`: the server answers, but not as a pack needs: it ignores `Range` (200), hides
 *   `Content-Range` from the page (CORS), answers another range, sends more than was asked (by
 *   `Content-Length` or by the body) or compresses the reply (`Content-Encoding`). Reading again
 *   gives the same; the host's configuration must change.
 * - `unavailable`: the pack cannot be read at this URL and waiting will not change that (any
 *   status but 200, 206, 408, 429 and 5xx: 404, 403, another 4xx), or it changed on the server
 *   while being read.
 * - `corrupt`: the pack's bytes are wrong (a header field, a CRC-32C, the level table, an index
 *   entry, a payload); the message names which. Reading again gives the same bytes.
 * - `unsupported`: a sound pack this reader does not show (another major version, unknown
 *   required features, 32-bit or float samples, tiles a browser cannot decode, a tile size,
 *   tile count, metadata or payload over the caps, an offset past 2^53), or no canvas to draw
 *   tiles in.
 * - `usage`: the caller's mistake (OpenSeadragon not loaded, a tile outside the pack, a bad URL).
 * @typedef {"io" | "host" | "unavailable" | "corrupt" | "unsupported" | "usage"} VtpkErrorKind
 */
const ERROR_KINDS = ["io", "host", "unavailable", "corrupt", "unsupported", "usage"];

/** An error about a pack: what is wrong, naming the URL and the field or tile, and its `kind`. */
export class VtpkError extends Error {
  /**
   * @param {VtpkErrorKind} kind what the caller can do about it
   * @param {string} message
   * @param {unknown} [cause] the error this one wraps
   */
  constructor(kind, message, cause) {
    super(message, cause === undefined ? undefined : { cause });
    if (!ERROR_KINDS.includes(kind)) throw new TypeError(`VtpkError: unknown kind ${JSON.stringify(kind)}`);
    this.name = "VtpkError";
    /** @type {VtpkErrorKind} */
    this.kind = kind;
  }
}

/** What error `e` says, with the errors it wraps (fetch's "fetch failed" wraps the reason).
 * @param {unknown} e @returns {string} */
const said = (e) => {
  if (!(e instanceof Error)) return String(e);
  return e.cause === undefined || e.cause === e ? e.message : `${e.message}: ${said(e.cause)}`;
};

const CRC_TABLE = (() => {
  const table = new Uint32Array(256);
  for (let n = 0; n < 256; n++) {
    let c = n;
    for (let k = 0; k < 8; k++) c = c & 1 ? 0x82f63b78 ^ (c >>> 1) : c >>> 1;
    table[n] = c >>> 0;
  }
  return table;
})();

/**
 * CRC-32C (Castagnoli) of `bytes`, continuing from `crc` (the CRC of what came before).
 * @param {Uint8Array} bytes
 * @param {number} [crc]
 * @returns {number}
 */
export function crc32c(bytes, crc = 0) {
  let c = ~crc >>> 0;
  for (let i = 0; i < bytes.length; i++) c = CRC_TABLE[(c ^ bytes[i]) & 0xff] ^ (c >>> 8);
  return ~c >>> 0;
}

/**
 * FNV-1a 64 of `bytes`, continuing from `hash` (the header's content hash: of the metadata,
 * then the index), as the two 32-bit halves [high, low] of the 64-bit value.
 * @param {Uint8Array} bytes
 * @param {[number, number]} [hash] default: the offset basis, 0xcbf29ce484222325
 * @returns {[number, number]}
 */
function fnv1a(bytes, [hi, lo] = [0xcbf29ce4, 0x84222325]) {
  // Times the prime 2^40 + 0x1b3, mod 2^64, in exact doubles: each product stays under 2^42.
  for (let i = 0; i < bytes.length; i++) {
    lo = (lo ^ bytes[i]) >>> 0;
    const low = lo * 0x1b3;
    const carry = Math.floor(low / 2 ** 32);
    hi = (hi * 0x1b3 + carry + ((lo << 8) >>> 0)) % 2 ** 32;
    lo = low % 2 ** 32;
  }
  return [hi, lo];
}

/** @param {number} v */
const hex = (v) => "0x" + (v >>> 0).toString(16).padStart(8, "0");

/**
 * Counts for measuring: HTTP requests and bytes fetched, payloads read (a shared payload
 * once), and tiles drawn without a payload (constant, from the index).
 * @typedef {{ requests: number, bytes: number, payloads?: number, constants?: number }} VtpkStats
 */

/**
 * HTTP `Range` reads of one URL, merged: reads asked for in the same few milliseconds are
 * sorted and those closer than `gap` bytes are fetched as one request of at most `maxSpan`.
 */
class RangeReader {
  /**
   * @param {string} url
   * @param {VtpkOptions} options
   */
  constructor(url, options) {
    this.url = url;
    this.fetch = options.fetch ?? globalThis.fetch.bind(globalThis);
    this.gap = options.gap ?? 4096;
    this.maxSpan = options.maxSpan ?? 4 << 20;
    this.headers = options.headers ?? {};
    this.timeout = options.timeout ?? TIMEOUT;
    /** @type {VtpkStats} */
    this.stats = { requests: 0, bytes: 0 };
    /** The whole file's length, from the first reply's `Content-Range`. */
    this.length = -1;
    /** @type {{ start: number, end: number, resolve: (b: Uint8Array) => void, reject: (e: Error) => void }[]} */
    this.pending = [];
    /** @type {ReturnType<typeof setTimeout> | null} */
    this.timer = null;
    /** @type {number | null} When the oldest pending read was asked for. */
    this.firstPending = null;
    this.wait = options.wait ?? 20;
    this.maxWait = options.maxWait ?? 60;
  }

  /**
   * Bytes `start` to `end` (exclusive), merged with the reads asked for alongside.
   * @param {number} start
   * @param {number} end
   * @returns {Promise<Uint8Array>}
   */
  read(start, end) {
    return new Promise((resolve, reject) => {
      this.pending.push({ start, end, resolve, reject });
      // Wait until no read has come for `wait` ms (OpenSeadragon asks for a view's tiles over
      // several frames, `maxTilesPerFrame` at a time), but never more than `maxWait` ms in all.
      const now = Date.now();
      this.firstPending ??= now;
      if (this.timer !== null) clearTimeout(this.timer);
      const delay = Math.max(0, Math.min(this.wait, this.firstPending + this.maxWait - now));
      this.timer = setTimeout(() => this.flush(), delay);
    });
  }

  flush() {
    const reads = this.pending.sort((a, b) => a.start - b.start);
    this.pending = [];
    this.timer = null;
    this.firstPending = null;
    let i = 0;
    while (i < reads.length) {
      const run = [reads[i]];
      let end = reads[i].end;
      while (
        ++i < reads.length &&
        reads[i].start - end <= this.gap &&
        Math.max(end, reads[i].end) - run[0].start <= this.maxSpan
      ) {
        run.push(reads[i]);
        end = Math.max(end, reads[i].end);
      }
      const start = run[0].start;
      this.fetchRange(start, end).then(
        (bytes) => run.forEach((r) => r.resolve(bytes.subarray(r.start - start, r.end - start))),
        (e) => run.forEach((r) => r.reject(e)),
      );
    }
  }

  /**
   * One request, under its deadline; the reply must be the asked range (206), or the end of a
   * shorter file, and is read no further than that.
   * @param {number} start
   * @param {number} end
   * @returns {Promise<Uint8Array>}
   */
  async fetchRange(start, end) {
    this.stats.requests++;
    const asked = `${this.url}: bytes ${start}-${end - 1}`;
    // One controller ends the request, the body's stream and the connection: on the deadline,
    // and after a reply refused before its end (aborting one read to its end does nothing).
    const controller = new AbortController();
    let late = false;
    const timer =
      this.timeout > 0
        ? setTimeout(() => {
            late = true;
            controller.abort();
          }, this.timeout)
        : null;
    try {
      return await this.exchange(start, end, asked, controller.signal);
    } catch (e) {
      if (late) throw new VtpkError("io", `${asked}: no complete reply within ${this.timeout} ms (the timeout option)`, e);
      if (e instanceof VtpkError) throw e;
      throw new VtpkError("io", `${asked}: ${said(e)}`, e);
    } finally {
      if (timer !== null) clearTimeout(timer);
      controller.abort();
    }
  }

  /**
   * The request and its reply, checked: status, `Content-Range`, encoding and length, then the
   * body as a stream, refused as soon as it runs past the bytes asked for.
   * @param {number} start
   * @param {number} end
   * @param {string} asked the request, for messages
   * @param {AbortSignal} signal
   * @returns {Promise<Uint8Array>}
   * @private
   */
  async exchange(start, end, asked, signal) {
    const reply = await this.fetch(this.url, { headers: { ...this.headers, Range: `bytes=${start}-${end - 1}` }, signal });
    if (reply.status === 200) {
      throw new VtpkError(
        "host",
        `${this.url}: the server ignored the Range header (200 instead of 206): a pack needs a host that serves byte ranges`,
      );
    }
    if (reply.status !== 206) {
      const transient = reply.status === 408 || reply.status === 429 || reply.status >= 500;
      throw new VtpkError(transient ? "io" : "unavailable", `${asked}: HTTP ${reply.status}`);
    }
    const header = reply.headers.get("Content-Range");
    if (header === null) {
      throw new VtpkError(
        "host",
        `${this.url}: a 206 reply without Content-Range (a host on another origin must expose it: Access-Control-Expose-Headers: Content-Range)`,
      );
    }
    const range = /^bytes (\d+)-(\d+)\/(\d+)$/.exec(header);
    const total = range ? Number(range[3]) : NaN;
    const want = Math.min(end, total) - start;
    if (!range || Number(range[1]) !== start || Number(range[2]) !== start + want - 1 || !(want > 0)) {
      throw new VtpkError("host", `${this.url}: asked for bytes ${start}-${end - 1}, got Content-Range "${header}"`);
    }
    if (this.length >= 0 && total !== this.length) {
      throw new VtpkError("unavailable", `${this.url}: the file changed length from ${this.length} to ${total} bytes while being read`);
    }
    this.length = total;
    // A compressed reply's Content-Range counts compressed bytes: its ranges are not the file's.
    // (A page sees this header only from its own origin or where the host exposes it; the
    // length bound below holds either way.)
    const encoding = reply.headers.get("Content-Encoding");
    if (encoding !== null && encoding.trim().toLowerCase() !== "identity") {
      throw new VtpkError("host", `${asked}: a compressed reply (Content-Encoding: ${encoding}): serve the pack as it is, uncompressed`);
    }
    const length = reply.headers.get("Content-Length");
    if (length !== null && Number(length) > want) {
      throw new VtpkError("host", `${asked}: a reply of ${length} bytes (Content-Length) for ${want} bytes asked`);
    }
    /** @type {Uint8Array[]} */
    const chunks = [];
    let got = 0;
    if (reply.body) {
      const reader = reply.body.getReader();
      for (;;) {
        let next;
        try {
          next = await reader.read();
        } catch (e) {
          throw new VtpkError("io", `${asked}: the reply broke off after ${got} of ${want} bytes: ${said(e)}`, e);
        }
        const { done, value } = next;
        if (done) break;
        got += value.length;
        this.stats.bytes += value.length;
        // The controller's abort (fetchRange's `finally`) ends the stream and the connection.
        if (got > want) {
          throw new VtpkError("host", `${asked}: the reply runs past the ${want} bytes asked (${got} bytes so far)`);
        }
        chunks.push(value);
      }
    }
    if (got < want) throw new VtpkError("io", `${asked}: the reply ended after ${got} of ${want} bytes`);
    if (chunks.length === 1) return chunks[0];
    const bytes = new Uint8Array(want);
    let at = 0;
    for (const chunk of chunks) {
      bytes.set(chunk, at);
      at += chunk.length;
    }
    return bytes;
  }
}

/**
 * @typedef {object} VtpkLevel
 * @property {number} tilesW tiles per row
 * @property {number} tilesH tile rows
 * @property {number} firstEntry index position of tile (0, 0)
 * @property {number} width real image width at this level
 * @property {number} height real image height at this level
 */

/**
 * @typedef {object} VtpkEntry
 * @property {number} kind 0 absent, 1 constant, 2 raw, 4 png, 5 jpeg, 9 jxl (others are refused)
 * @property {number} offset payload offset (0 without payload)
 * @property {number} len payload length
 * @property {number} crc CRC-32C of the payload
 * @property {Uint8Array} value the 8 bytes of a constant tile's samples
 */

/**
 * @typedef {object} VtpkOptions
 * @property {typeof fetch} [fetch] the fetch to use (default: the page's)
 * @property {Record<string, string>} [headers] extra request headers (authorisation, ...)
 * @property {number} [wholeIndexUpTo] read and check the whole index before use when it is at
 *   most this many bytes (default 32 KiB, about 1,300 tiles: a 4096^2 image in 128-texel tiles
 *   or 8192^2 in 256); larger indexes are read in blocks, which a first view needs few of
 * @property {number} [gap] merge reads less than this many bytes apart (default 4 KiB, or the
 *   pack's payload alignment where larger: tiles of a row lie that far apart)
 * @property {number} [maxSpan] never merge reads into a request longer than this (default 4 MiB)
 * @property {number} [wait] gather reads until none has come for this many milliseconds
 *   (default 20: OpenSeadragon asks for a tile or a few per frame)
 * @property {number} [maxWait] but never hold a read back longer than this (default 60 ms)
 * @property {number} [minSide] OpenSeadragon is given no level whose long side is under this
 *   many texels, beyond the first one under it (default 512, a small viewer's width): it draws
 *   the coarsest levels first as placeholders, and a pack stores those whole, padding and all,
 *   where Deep Zoom crops them to a few texels; 0 gives it every level
 * @property {number} [timeout] the most milliseconds one request may take, reply and body
 *   together (default 30000; 0: none): one that takes longer is ended, a `VtpkError` of kind `io`
 * @property {(error: VtpkError) => void} [onError] called by `VtpkTileSource` with each tile
 *   that fails, whatever the kind; and, by `VtpkPack` too, when an index read in blocks fails
 *   its check (CRC, content hash) once every block is in
 * @property {any} [OpenSeadragon] the OpenSeadragon namespace (default: the global one)
 */

/** An open pack: its header, levels and metadata, and its tiles on demand. */
export class VtpkPack {
  /**
   * Opens the pack at `url`: reads and checks its header, level table and metadata.
   * @param {string} url
   * @param {VtpkOptions} [options]
   * @returns {Promise<VtpkPack>}
   */
  static async open(url, options = {}) {
    const reader = new RangeReader(url, options);
    const first = await reader.read(0, FIRST_READ);
    const pack = new VtpkPack(url, reader, first, options);
    await pack.readIndexAndMetadata(first);
    if (pack.holdsJxl && !(await browserDecodesJxl())) {
      throw new VtpkError(
        "unsupported",
        `${url}: its tiles are JPEG XL, which this browser does not decode (Chrome 155, Firefox 158 and Safari 17 do); ` +
          "write the pack with --codec jpeg or --codec png to show it here",
      );
    }
    return pack;
  }

  /**
   * @param {string} url
   * @param {RangeReader} reader
   * @param {Uint8Array} first
   * @param {VtpkOptions} options
   * @private
   */
  constructor(url, reader, first, options) {
    this.url = url;
    this.reader = reader;
    this.options = options;
    // The header is checked as vortex_pack's `PackLayout::read_header` checks it, in its order,
    // with the section placement that `verify` asks for (the spec's offsets, exactly).
    const fail = (/** @type {VtpkErrorKind} */ kind, /** @type {string} */ what) => {
      throw new VtpkError(kind, `${url}: ${what}`);
    };
    const corrupt = (/** @type {string} */ what) => fail("corrupt", what);
    if (SIGNATURE.some((b, i) => i < first.length && first[i] !== b)) {
      corrupt(first.subarray(0, 8).every((b) => b === 0)
        ? "starts with zeros: an unfinished pack (the writer was stopped before its header)"
        : "not a .vtpk pack (no pack signature)");
    }
    if (first.length < HEADER_LEN) corrupt(`${first.length} bytes, shorter than a pack header`);
    const view = new DataView(first.buffer, first.byteOffset, HEADER_LEN);
    const u16 = (/** @type {number} */ o) => view.getUint16(o, true);
    const u32 = (/** @type {number} */ o) => view.getUint32(o, true);
    const u64 = (/** @type {number} */ o, /** @type {string} */ field) => {
      const v = view.getBigUint64(o, true);
      if (v > BigInt(Number.MAX_SAFE_INTEGER)) fail("unsupported", `${field} ${v} is beyond what a browser can address`);
      return Number(v);
    };
    if (crc32c(first.subarray(0, 188)) !== u32(188)) corrupt("the header's CRC-32C does not match: the header is damaged");
    if (first[71] || first.subarray(144, 188).some((b) => b)) corrupt("reserved header bytes are not zero");
    if (u16(8) !== 1) fail("unsupported", `format major version ${u16(8)}, this reader reads 1`);
    const required = view.getBigUint64(16, true);
    if (required & ~7n) {
      fail("unsupported", `required features ${hex(Number(required & 0xffffffffn))} include some this reader does not know`);
    }
    if (u32(12) !== HEADER_LEN) corrupt(`header_len ${u32(12)}, not ${HEADER_LEN}`);
    if (u32(104) !== ENTRY_LEN) corrupt(`entry_len ${u32(104)}, not ${ENTRY_LEN}`);
    this.width = u32(48);
    this.height = u32(52);
    this.tileSize = u32(56);
    this.border = u32(60);
    this.levelCount = u32(64);
    this.channels = first[68];
    this.sampleBytes = first[69];
    const sampleFormat = first[70];
    this.indexCount = u64(96, "index_count");
    if (this.tileSize > MAX_TILE_SIZE) fail("unsupported", `tile_size ${this.tileSize}, over the cap of ${MAX_TILE_SIZE}`);
    if (this.indexCount > MAX_TILES) fail("unsupported", `index_count ${this.indexCount}, over the cap of ${MAX_TILES} tiles`);
    this.fileLen = u64(32, "file_len");
    if (this.fileLen !== reader.length) corrupt(`the header says ${this.fileLen} bytes, the file has ${reader.length} (truncated or extended)`);
    // Texels: 1 to 4 channels of unsigned 1-, 2- or 4-byte samples or 2- or 4-byte floats; the
    // 4-byte and float ones with required-feature bit 1, and not shown here.
    const sizes = sampleFormat === 0 ? [1, 2, 4] : sampleFormat === 1 ? [2, 4] : [];
    if (this.channels < 1 || this.channels > 4 || !sizes.includes(this.sampleBytes)) {
      corrupt(`${this.channels} channels of ${this.sampleBytes}-byte samples of format ${sampleFormat} is not a texel format`);
    }
    const wide = this.sampleBytes === 4 || sampleFormat !== 0;
    if (wide && !(required & 2n)) corrupt("32-bit or float samples without required-feature bit 0x2");
    if (required & 2n) {
      fail("unsupported", `its samples are ${this.sampleBytes * 8}-bit ${sampleFormat ? "floats" : "integers"}: this reader shows 8- and 16-bit unsigned samples`);
    }
    if (!this.width || !this.height) corrupt(`image size ${this.width}x${this.height}`);
    if (this.tileSize === 0) corrupt("tile_size 0");
    if (2 * this.border >= this.tileSize) corrupt(`border ${this.border} leaves nothing of a ${this.tileSize}-texel tile`);
    if (this.levelCount < 1 || this.levelCount > 32) corrupt(`level_count ${this.levelCount}, not 1 to 32`);
    const alignment = u32(72);
    this.payloadAlignment = u32(76);
    for (const [field, value] of [["alignment", alignment], ["payload_alignment", this.payloadAlignment]]) {
      if (value < 8 || value & (value - 1)) corrupt(`${field} ${value}, not a power of two of at least 8`);
    }
    const levelsOffset = u64(80, "levels_offset");
    this.indexOffset = u64(88, "index_offset");
    this.indexCrc = u32(108);
    this.metaOffset = u64(112, "meta_offset");
    this.metaLen = u32(120);
    this.metaCrc = u32(124);
    this.dataOffset = u64(128, "data_offset");
    const dataLen = u64(136, "data_len");
    const contentHash = [u32(44), u32(40)];
    if (levelsOffset !== HEADER_LEN) corrupt(`levels_offset ${levelsOffset}, not ${HEADER_LEN}`);
    if (this.indexOffset !== levelsOffset + LEVEL_LEN * this.levelCount) corrupt(`index_offset ${this.indexOffset} does not follow the level table`);
    if (this.metaOffset !== this.indexOffset + ENTRY_LEN * this.indexCount) corrupt(`meta_offset ${this.metaOffset} does not follow the index`);
    if (this.metaOffset + this.metaLen > this.dataOffset || this.dataOffset % alignment) corrupt(`data_offset ${this.dataOffset} overlaps the metadata or is not aligned`);
    if (this.dataOffset > this.fileLen || dataLen !== this.fileLen - this.dataOffset) corrupt(`data_len ${dataLen} does not end the file`);
    // What this reader allocates, held to the cap the Rust reader of remote packs holds it to.
    if (this.metaLen > MAX_DECODED_BYTES) fail("unsupported", `meta_len ${this.metaLen}, over the cap of ${MAX_DECODED_BYTES} bytes`);
    if (required & 1n) this.refuse("zstd-delta");
    /** Required-feature bit 2: the pack holds JPEG XL tiles, which `open` asks the browser about. */
    this.holdsJxl = (required & 4n) !== 0n;
    // Payloads are padded to their alignment: neighbours in a row are that far apart at most.
    if (options.gap === undefined) reader.gap = Math.max(reader.gap, this.payloadAlignment);
    /** @type {VtpkLevel[]} */
    this.levels = [];
    /** Index blocks by number, each checked for sense when it arrives. @type {Map<number, Promise<Uint8Array>>} */
    this.blocks = new Map();
    /** Payloads being fetched or recently fetched, by offset: shared tiles are fetched once. */
    this.payloads = new Map();
    /** @type {Uint8Array | null} The level table, kept for the index CRC. */
    this.levelTable = null;
    /** Index blocks that have arrived, by number. @type {Map<number, Uint8Array>} */
    this.arrivedBlocks = new Map();
    /** The index check: null until every block is here, then whether it passed. @type {boolean | null} */
    this.indexChecked = null;
    /** Why the index check failed, which every later `entry` says. @type {string | null} */
    this.indexFailure = null;
    /** The metadata's bytes, for the content hash. */
    this.meta = new Uint8Array(0);
    /** The header's content hash, high and low halves. */
    this.contentHash = contentHash;
    this.metadata = {};
    this.payloadReads = 0;
    this.constants = 0;
  }

  /** What was fetched so far. @returns {VtpkStats} */
  get stats() {
    return { ...this.reader.stats, payloads: this.payloadReads, constants: this.constants };
  }

  /** @param {string} codec @returns {never} */
  refuse(codec) {
    throw new VtpkError(
      "unsupported",
      `${this.url}: its tiles are ${codec}, which a browser cannot decode without a decoder of its own; ` +
        "write the pack with --codec jpeg or --codec png to show it in a browser",
    );
  }

  /**
   * Reads the level table, the metadata and (when small enough) the whole index.
   * @param {Uint8Array} first
   * @private
   */
  async readIndexAndMetadata(first) {
    const metaEnd = this.metaOffset + this.metaLen;
    const indexBytes = this.metaOffset - this.indexOffset;
    const whole = indexBytes <= (this.options.wholeIndexUpTo ?? 32768);
    // Whole: level table to metadata end in one read. Blocks: the level table (always in the
    // first read, 32 levels being 1 KiB), then the metadata with the last index block beside
    // it, which holds the coarse levels every view starts with.
    const lastBlock = Math.floor((this.indexCount - 1) / BLOCK_ENTRIES);
    const from = whole ? HEADER_LEN : Math.min(this.indexOffset + lastBlock * BLOCK_ENTRIES * ENTRY_LEN, this.metaOffset);
    // A level table longer than the first read is read beside the index block (whole: with it).
    const inFirst = this.indexOffset <= first.length;
    const rest = inFirst || whole ? null : this.reader.read(HEADER_LEN, this.indexOffset);
    const bytes = metaEnd <= first.length ? first : await this.reader.read(from, metaEnd);
    const at = (/** @type {number} */ offset) => (bytes === first ? offset : offset - from);
    const table = inFirst ? first.subarray(HEADER_LEN, this.indexOffset) : (await rest) ?? bytes.subarray(0, at(this.indexOffset));
    this.levelTable = table;
    this.readLevels(table);
    const meta = bytes.subarray(at(this.metaOffset), at(metaEnd));
    if (crc32c(meta) !== this.metaCrc) throw new VtpkError("corrupt", `${this.url}: the metadata's CRC-32C does not match`);
    this.meta = meta;
    try {
      this.metadata = this.metaLen ? JSON.parse(new TextDecoder("utf-8", { fatal: true }).decode(meta)) : {};
    } catch (e) {
      throw new VtpkError("corrupt", `${this.url}: the metadata is not UTF-8 JSON: ${said(e)}`, e);
    }
    const codec = this.metadata.codec;
    if (["zstd", "zstd-delta", "bc1", "bc7"].includes(codec)) this.refuse(codec);
    if (whole || bytes === first) {
      // Every block is here: check the index before any entry is used.
      const index = bytes.subarray(at(this.indexOffset), at(this.metaOffset));
      const wrong = this.indexError([index]);
      if (wrong) throw new VtpkError("corrupt", `${this.url}: ${wrong}`);
      this.indexChecked = true;
      for (let b = 0; b <= lastBlock; b++) {
        const start = b * BLOCK_ENTRIES * ENTRY_LEN;
        const block = index.subarray(start, Math.min(start + BLOCK_ENTRIES * ENTRY_LEN, indexBytes));
        this.blocks.set(b, Promise.resolve(block));
        this.arrivedBlocks.set(b, block);
      }
    } else {
      const block = bytes.subarray(0, this.metaOffset - from);
      this.blocks.set(lastBlock, Promise.resolve(block));
      // An index of one block is whole now: checked here.
      this.arrived(lastBlock, block);
      if (this.indexFailure) throw new VtpkError("corrupt", `${this.url}: ${this.indexFailure}`);
    }
  }

  /** @param {Uint8Array} table @private */
  readLevels(table) {
    const view = new DataView(table.buffer, table.byteOffset, table.length);
    const payload = this.tileSize - 2 * this.border;
    let next = 0;
    for (let lod = 0; lod < this.levelCount; lod++) {
      const o = lod * LEVEL_LEN;
      const level = {
        tilesW: view.getUint32(o, true),
        tilesH: view.getUint32(o + 4, true),
        firstEntry: Number(view.getBigUint64(o + 8, true)),
        width: view.getUint32(o + 16, true),
        height: view.getUint32(o + 20, true),
      };
      const fail = (/** @type {string} */ what) => {
        throw new VtpkError("corrupt", `${this.url}: level ${lod}: ${what}`);
      };
      if (level.firstEntry !== next) fail(`first_entry ${level.firstEntry}, not ${next}`);
      if (level.width !== Math.ceil(this.width / 2 ** lod) || level.height !== Math.ceil(this.height / 2 ** lod)) {
        fail(`${level.width}x${level.height} texels, not the ${this.width}x${this.height} image halved ${lod} times`);
      }
      if (level.tilesW < Math.ceil(level.width / payload) || level.tilesH < Math.ceil(level.height / payload)) {
        fail(`${level.tilesW}x${level.tilesH} tiles do not cover ${level.width}x${level.height} texels`);
      }
      if (table.subarray(o + 24, o + 32).some((b) => b)) fail("reserved bytes are not zero");
      next += level.tilesW * level.tilesH;
      if (next > this.indexCount) fail(`its tiles run past the ${this.indexCount} of the index`);
      this.levels.push(level);
    }
    if (next !== this.indexCount) throw new VtpkError("corrupt", `${this.url}: the levels hold ${next} tiles, the index ${this.indexCount}`);
  }

  /**
   * The index entry of tile (`lod`, `x`, `y`), checked for sense as vortex_pack's
   * `PackLayout::place` and `verify` check it; refused once the index failed its CRC.
   * @param {number} lod
   * @param {number} x
   * @param {number} y
   * @returns {Promise<VtpkEntry>}
   */
  async entry(lod, x, y) {
    const level = this.levels[lod];
    const where = `${this.url}: tile (lod ${lod}, x ${x}, y ${y})`;
    if (!level || x < 0 || y < 0 || x >= level.tilesW || y >= level.tilesH) throw new VtpkError("usage", `${where} is not in the pack`);
    const position = level.firstEntry + y * level.tilesW + x;
    const block = await this.block(Math.floor(position / BLOCK_ENTRIES));
    if (this.indexFailure) throw new VtpkError("corrupt", `${where}: ${this.indexFailure}`);
    const o = (position % BLOCK_ENTRIES) * ENTRY_LEN;
    const view = new DataView(block.buffer, block.byteOffset + o, ENTRY_LEN);
    const entry = {
      kind: block[o + 16],
      offset: Number(view.getBigUint64(0, true)),
      len: view.getUint32(8, true),
      crc: view.getUint32(12, true),
      value: block.subarray(o, o + 8),
    };
    const damaged = (/** @type {string} */ what) => {
      throw new VtpkError("corrupt", `${where}: ${what}: the index is damaged`);
    };
    if (block.subarray(o + 17, o + 24).some((b) => b)) damaged("reserved index bytes are not zero");
    if (entry.kind >= KIND_NAMES.length) damaged(`unknown tile kind ${entry.kind}`);
    // A pack with zstd-delta tiles sets required-feature bit 0, which `open` refused.
    if (entry.kind === KIND.zstdDelta) damaged("a zstd-delta tile in a pack without required-feature bit 0x1");
    if (entry.kind === KIND.jxl && !this.holdsJxl) damaged("a jxl tile in a pack without required-feature bit 0x4");
    if (entry.kind === KIND.constant || entry.kind === KIND.absent) {
      // No payload: length and CRC zero, and nothing past the texel's samples (all of it for
      // absent). Until the index CRC is checked, this is what catches a damaged entry.
      const used = entry.kind === KIND.constant ? this.channels * this.sampleBytes : 0;
      if (entry.len || entry.crc || entry.value.subarray(used).some((b) => b)) {
        damaged(`a ${KIND_NAMES[entry.kind]} entry with payload fields set`);
      }
      return entry;
    }
    if (entry.len === 0 || entry.offset < this.dataOffset || entry.offset + entry.len > this.fileLen) {
      damaged(`its payload (${entry.len} bytes at ${entry.offset}) is not inside the data section`);
    }
    if (entry.offset % this.payloadAlignment) damaged(`its payload at ${entry.offset} is not aligned to ${this.payloadAlignment} bytes`);
    if (entry.kind !== KIND.raw && !IMAGE_TYPES[entry.kind]) this.refuse(KIND_NAMES[entry.kind]);
    const raw = this.tileSize * this.tileSize * this.channels * this.sampleBytes;
    if (entry.kind === KIND.raw && entry.len !== raw) damaged(`a raw tile of ${entry.len} bytes, not ${raw}`);
    if (entry.len > MAX_DECODED_BYTES) {
      throw new VtpkError("unsupported", `${where}: a payload of ${entry.len} bytes, over the cap of ${MAX_DECODED_BYTES}`);
    }
    return entry;
  }

  /** Index block `b`, fetched once; the index is checked when the last one arrives. @param {number} b @private */
  block(b) {
    let block = this.blocks.get(b);
    if (!block) {
      const start = this.indexOffset + b * BLOCK_ENTRIES * ENTRY_LEN;
      block = this.reader.read(start, Math.min(start + BLOCK_ENTRIES * ENTRY_LEN, this.metaOffset));
      this.blocks.set(b, block);
      // Registered before any caller's, so the check is done before a caller sees the block.
      block.then((bytes) => this.arrived(b, bytes), () => this.blocks.delete(b));
    }
    return block;
  }

  /**
   * Keeps index block `b`; once every block is here, checks the index (CRC and content hash).
   * A failure is reported to `onError` and fails every later `entry`.
   * @param {number} b @param {Uint8Array} bytes @private
   */
  arrived(b, bytes) {
    this.arrivedBlocks.set(b, bytes);
    const count = Math.ceil(this.indexCount / BLOCK_ENTRIES);
    if (this.indexChecked !== null || this.arrivedBlocks.size < count) return;
    const parts = Array.from({ length: count }, (_, n) => /** @type {Uint8Array} */ (this.arrivedBlocks.get(n)));
    this.indexFailure = this.indexError(parts);
    this.indexChecked = this.indexFailure === null;
    if (this.indexFailure) this.options.onError?.(new VtpkError("corrupt", `${this.url}: ${this.indexFailure}`));
  }

  /**
   * What is wrong with the index given whole, in consecutive `parts`: its CRC-32C (with the
   * level table's) or the header's content hash (FNV-1a 64 of the metadata, then the index).
   * @param {Uint8Array[]} parts
   * @returns {string | null}
   * @private
   */
  indexError(parts) {
    const crc = parts.reduce((c, part) => crc32c(part, c), crc32c(/** @type {Uint8Array} */ (this.levelTable)));
    if (crc !== this.indexCrc) return "the CRC-32C of the level table and index does not match: the index is damaged";
    const [hi, lo] = parts.reduce((h, part) => fnv1a(part, h), fnv1a(this.meta));
    if (hi !== this.contentHash[0] || lo !== this.contentHash[1]) {
      const h64 = (/** @type {number[]} */ [a, b]) => hex(a) + hex(b).slice(2);
      return `the header's content hash is ${h64(this.contentHash)}, the metadata and index hash to ${h64([hi, lo])}: the header does not belong to this index`;
    }
    return null;
  }

  /**
   * The payload of a tile with data, its CRC-32C checked; shared payloads are fetched once.
   * @param {VtpkEntry} entry
   * @param {string} where the tile, for messages
   * @returns {Promise<Uint8Array>}
   */
  payload(entry, where) {
    const key = `${entry.offset}:${entry.len}`;
    let bytes = this.payloads.get(key);
    if (!bytes) {
      this.payloadReads++;
      bytes = this.reader.read(entry.offset, entry.offset + entry.len).then((b) => {
        const crc = crc32c(b);
        if (crc !== entry.crc) {
          throw new VtpkError("corrupt", `${where}: the CRC-32C of its ${entry.len}-byte payload at offset ${entry.offset} is ${hex(crc)}, the index says ${hex(entry.crc)}: the tile is damaged`);
        }
        return b;
      });
      this.payloads.set(key, bytes);
      // Keep recent payloads for tiles that share them, in a bounded map (insertion order).
      bytes.catch(() => this.payloads.delete(key));
      if (this.payloads.size > 256) this.payloads.delete(this.payloads.keys().next().value);
    }
    return bytes;
  }

  /**
   * Tile (`lod`, `x`, `y`) decoded into a canvas of `tileSize` texels, borders included.
   * Constant tiles are drawn from the index, absent ones as a transparent canvas.
   * @param {number} lod
   * @param {number} x
   * @param {number} y
   * @returns {Promise<{ canvas: OffscreenCanvas | HTMLCanvasElement, absent: boolean }>}
   */
  async tile(lod, x, y) {
    const where = `${this.url}: tile (lod ${lod}, x ${x}, y ${y})`;
    const entry = await this.entry(lod, x, y);
    const size = this.tileSize;
    const canvas = makeCanvas(size, size);
    const ctx = /** @type {CanvasRenderingContext2D} */ (canvas.getContext("2d"));
    if (entry.kind === KIND.absent) return { canvas, absent: true };
    if (entry.kind === KIND.constant) {
      this.constants++;
      const [r, g, b, a] = this.rgba(entry.value, 0);
      ctx.fillStyle = `rgba(${r},${g},${b},${a / 255})`;
      ctx.fillRect(0, 0, size, size);
      return { canvas, absent: false };
    }
    const bytes = await this.payload(entry, where);
    if (entry.kind === KIND.raw) {
      const texel = this.channels * this.sampleBytes;
      if (bytes.length !== size * size * texel) throw new VtpkError("corrupt", `${where}: a raw tile of ${bytes.length} bytes, not ${size * size * texel}`);
      const image = ctx.createImageData(size, size);
      for (let i = 0; i < size * size; i++) image.data.set(this.rgba(bytes, i * texel), 4 * i);
      ctx.putImageData(image, 0, 0);
      return { canvas, absent: false };
    }
    let bitmap;
    try {
      bitmap = await createImageBitmap(new Blob([bytes], { type: IMAGE_TYPES[entry.kind] }), { colorSpaceConversion: "none" });
    } catch (e) {
      throw new VtpkError("corrupt", `${where}: the browser cannot decode its ${KIND_NAMES[entry.kind]} payload: ${said(e)}`, e);
    }
    if (bitmap.width !== size || bitmap.height !== size) {
      throw new VtpkError("corrupt", `${where}: a ${bitmap.width}x${bitmap.height} image, not ${size}x${size}`);
    }
    ctx.drawImage(bitmap, 0, 0);
    bitmap.close();
    return { canvas, absent: false };
  }

  /**
   * The 8-bit RGBA of the texel at `at` in `bytes` (samples little-endian; 16-bit ones keep
   * their high byte).
   * @param {Uint8Array} bytes
   * @param {number} at
   * @returns {number[]}
   * @private
   */
  rgba(bytes, at) {
    const s = (/** @type {number} */ k) => bytes[at + k * this.sampleBytes + this.sampleBytes - 1];
    switch (this.channels) {
      case 1: return [s(0), s(0), s(0), 255];
      case 2: return [s(0), s(0), s(0), s(1)];
      case 3: return [s(0), s(1), s(2), 255];
      default: return [s(0), s(1), s(2), s(3)];
    }
  }
}

/** @param {number} w @param {number} h */
function makeCanvas(w, h) {
  if (typeof document !== "undefined") {
    const canvas = document.createElement("canvas");
    canvas.width = w;
    canvas.height = h;
    return canvas;
  }
  if (typeof OffscreenCanvas === "undefined") {
    throw new VtpkError("unsupported", "no canvas to draw tiles in: tiles are drawn in a page or a worker");
  }
  return new OffscreenCanvas(w, h);
}

/**
 * Shows a `.vtpk` pack in OpenSeadragon.
 *
 * `await VtpkTileSource.open(url)` gives an `OpenSeadragon.TileSource` to pass as
 * `tileSources`. Pack LOD `k` is OpenSeadragon level `maxLevel - k`; the pack's tile border is
 * OpenSeadragon's tile overlap, cropped where the image ends, so tiles sit where a Deep Zoom
 * tile of the same image would. The source also carries `vtpk` (the {@link VtpkPack}) and
 * `errors` (each tile that failed, as a message).
 */
export class VtpkTileSource {
  /**
   * @param {string} url the pack's URL (relative to the page or absolute)
   * @param {VtpkOptions} [options]
   * @returns {Promise<any>} an OpenSeadragon.TileSource
   */
  static async open(url, options = {}) {
    const OSD = options.OpenSeadragon ?? /** @type {any} */ (globalThis).OpenSeadragon;
    if (!OSD) throw new VtpkError("usage", "VtpkTileSource: OpenSeadragon is not loaded (load it first, or pass it as options.OpenSeadragon)");
    /** @type {string[]} */
    const errors = [];
    const report = (/** @type {VtpkError} */ e) => {
      errors.push(e.message);
      options.onError?.(e);
    };
    let absolute;
    try {
      absolute = new URL(url, globalThis.location?.href).href;
    } catch (e) {
      throw new VtpkError("usage", `VtpkTileSource: ${JSON.stringify(url)} is not a URL: ${said(e)}`, e);
    }
    const pack = await VtpkPack.open(absolute, { ...options, onError: report });
    const maxLevel = Math.ceil(Math.log2(Math.max(pack.width, pack.height)));
    // Pack levels past OpenSeadragon's 1-texel level (a pack made down to one texel) are unused.
    const lods = Math.min(pack.levelCount, maxLevel + 1);
    // The first LOD whose long side is at most minSide: the coarsest level shown.
    const minSide = options.minSide ?? 512;
    const coarsest = minSide > 0 ? Math.max(0, Math.ceil(Math.log2(Math.max(pack.width, pack.height) / minSide))) : lods - 1;
    const payload = pack.tileSize - 2 * pack.border;
    const border = pack.border;
    const source = new OSD.TileSource({
      width: pack.width,
      height: pack.height,
      tileSize: payload,
      tileOverlap: border,
      minLevel: maxLevel - Math.min(lods - 1, coarsest),
      maxLevel,
      getTileUrl: (/** @type {number} */ level, /** @type {number} */ x, /** @type {number} */ y) =>
        `${pack.url}#${maxLevel - level}/${x}/${y}`,
      hasTransparency: () => pack.channels === 2 || pack.channels === 4,
      /** @param {any} job */
      downloadTileStart(job) {
        const [lod, x, y] = job.src.slice(job.src.lastIndexOf("#") + 1).split("/").map(Number);
        job.userData.aborted = false;
        drawTile(lod, x, y).then(
          (ctx) => job.userData.aborted || job.finish(ctx, null, "context2d"),
          (e) => {
            const error = e instanceof VtpkError ? e : new VtpkError("unsupported", `${pack.url}: tile (lod ${lod}, x ${x}, y ${y}): ${said(e)}`, e);
            report(error);
            if (!job.userData.aborted) job.fail(error.message, null);
          },
        );
      },
      /** @param {any} job */
      downloadTileAbort(job) {
        job.userData.aborted = true;
      },
    });

    /**
     * The part of tile (lod, x, y) OpenSeadragon places: the payload with the border kept
     * where a neighbour lies (its overlap) and cut where the image ends. An absent tile is its
     * parent's part, enlarged (the format's fallback).
     * @param {number} lod @param {number} x @param {number} y
     * @returns {Promise<CanvasRenderingContext2D>}
     */
    async function drawTile(lod, x, y) {
      const { width, height } = pack.levels[lod];
      const left = Math.max(x * payload - border, 0);
      const top = Math.max(y * payload - border, 0);
      const w = Math.min((x + 1) * payload + border, width) - left;
      const h = Math.min((y + 1) * payload + border, height) - top;
      const canvas = makeCanvas(w, h);
      const ctx = /** @type {CanvasRenderingContext2D} */ (canvas.getContext("2d"));
      const tile = await pack.tile(lod, x, y);
      if (!tile.absent) {
        ctx.drawImage(tile.canvas, left - (x * payload - border), top - (y * payload - border), w, h, 0, 0, w, h);
      } else if (lod + 1 < pack.levelCount) {
        const [px, py] = [x >> 1, y >> 1];
        const parent = (await drawTile(lod + 1, px, py)).canvas;
        const parentLeft = Math.max(px * payload - border, 0);
        const parentTop = Math.max(py * payload - border, 0);
        ctx.imageSmoothingEnabled = true;
        ctx.drawImage(parent, left / 2 - parentLeft, top / 2 - parentTop, w / 2, h / 2, 0, 0, w, h);
      }
      return ctx;
    }
    // Set after construction: OpenSeadragon deep-copies its options, which would copy the array.
    source.vtpk = pack;
    source.errors = errors;
    return source;
  }
}
