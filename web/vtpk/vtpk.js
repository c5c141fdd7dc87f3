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
 * CRC, the CRC of the level table and index (before any entry is used when the index is read
 * whole; once every block has arrived otherwise, each entry being checked for sense before
 * use), and every tile payload's CRC. A tile that fails is reported (`errors`, the `onError`
 * option, OpenSeadragon's `tile-load-failed`) and not drawn.
 *
 * JPEG and PNG tiles are decoded by the browser; raw tiles (8 or 16 bits) are converted here,
 * which is cheap. zstd, zstd-delta, BC1 and BC7 tiles would need a decoder shipped with the
 * page, so such packs are refused at `open` with a message saying how to write one that works.
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
/** The caps vortex_pack::Limits holds a header to, so a hostile header sizes nothing big. */
const MAX_TILE_SIZE = 16384;
const MAX_TILES = 2 ** 29;

/** Tile kinds (docs/pack-format.md, "Index"). */
const KIND = { absent: 0, constant: 1, raw: 2, zstd: 3, png: 4, jpeg: 5, bc1: 6, bc7: 7, zstdDelta: 8 };
const KIND_NAMES = ["absent", "constant", "raw", "zstd", "png", "jpeg", "bc1", "bc7", "zstd-delta"];

/** An error about a pack: what is wrong, naming the URL and the field or tile. */
export class VtpkError extends Error {
  /** @param {string} message */
  constructor(message) {
    super(message);
    this.name = "VtpkError";
  }
}

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
   * One request; the reply must be the asked range (206), or the end of a shorter file.
   * @param {number} start
   * @param {number} end
   * @returns {Promise<Uint8Array>}
   */
  async fetchRange(start, end) {
    this.stats.requests++;
    let reply;
    try {
      reply = await this.fetch(this.url, { headers: { ...this.headers, Range: `bytes=${start}-${end - 1}` } });
    } catch (e) {
      throw new VtpkError(`${this.url}: bytes ${start}-${end - 1}: ${e instanceof Error ? e.message : e}`);
    }
    if (reply.status === 200) {
      throw new VtpkError(
        `${this.url}: the server ignored the Range header (200 instead of 206): a pack needs a host that serves byte ranges`,
      );
    }
    if (reply.status !== 206) throw new VtpkError(`${this.url}: bytes ${start}-${end - 1}: HTTP ${reply.status}`);
    const header = reply.headers.get("Content-Range");
    if (header === null) {
      throw new VtpkError(
        `${this.url}: a 206 reply without Content-Range (a host on another origin must expose it: Access-Control-Expose-Headers: Content-Range)`,
      );
    }
    const range = /^bytes (\d+)-(\d+)\/(\d+)$/.exec(header);
    if (!range || Number(range[1]) !== start) {
      throw new VtpkError(`${this.url}: asked for bytes ${start}-${end - 1}, got Content-Range "${header}"`);
    }
    const total = Number(range[3]);
    if (this.length >= 0 && total !== this.length) {
      throw new VtpkError(`${this.url}: the file changed length from ${this.length} to ${total} bytes while being read`);
    }
    this.length = total;
    const bytes = new Uint8Array(await reply.arrayBuffer());
    this.stats.bytes += bytes.length;
    if (bytes.length !== Math.min(end, total) - start) {
      throw new VtpkError(`${this.url}: asked for bytes ${start}-${end - 1}, got ${bytes.length} bytes`);
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
 * @property {number} kind 0 absent, 1 constant, 2 raw, 4 png, 5 jpeg (others are refused)
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
 * @property {(error: VtpkError) => void} [onError] called with each tile that fails
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
    const fail = (/** @type {string} */ what) => {
      throw new VtpkError(`${url}: ${what}`);
    };
    if (SIGNATURE.some((b, i) => i < first.length && first[i] !== b)) {
      fail(first.subarray(0, 8).every((b) => b === 0)
        ? "starts with zeros: an unfinished pack (the writer was stopped before its header)"
        : "not a .vtpk pack (no pack signature)");
    }
    if (first.length < HEADER_LEN) fail(`${first.length} bytes, shorter than a pack header`);
    const view = new DataView(first.buffer, first.byteOffset, HEADER_LEN);
    const u16 = (/** @type {number} */ o) => view.getUint16(o, true);
    const u32 = (/** @type {number} */ o) => view.getUint32(o, true);
    const u64 = (/** @type {number} */ o, /** @type {string} */ field) => {
      const v = view.getBigUint64(o, true);
      if (v > BigInt(Number.MAX_SAFE_INTEGER)) fail(`${field} ${v} is beyond what a browser can address`);
      return Number(v);
    };
    if (u16(8) !== 1) fail(`format major version ${u16(8)}, this reader reads 1`);
    if (crc32c(first.subarray(0, 188)) !== u32(188)) fail("the header's CRC-32C does not match: the header is damaged");
    const required = view.getBigUint64(16, true);
    if (required & ~1n) fail(`required features ${hex(Number(required & 0xffffffffn))} include some this reader does not know`);
    this.fileLen = u64(32, "file_len");
    if (this.fileLen !== reader.length) fail(`the header says ${this.fileLen} bytes, the file has ${reader.length} (truncated or extended)`);
    this.width = u32(48);
    this.height = u32(52);
    this.tileSize = u32(56);
    this.border = u32(60);
    this.levelCount = u32(64);
    this.channels = first[68];
    this.sampleBytes = first[69];
    const alignment = u32(72);
    const payloadAlignment = u32(76);
    const levelsOffset = u64(80, "levels_offset");
    this.indexOffset = u64(88, "index_offset");
    this.indexCount = u64(96, "index_count");
    this.indexCrc = u32(108);
    this.metaOffset = u64(112, "meta_offset");
    this.metaLen = u32(120);
    this.metaCrc = u32(124);
    this.dataOffset = u64(128, "data_offset");
    if (u32(12) !== HEADER_LEN) fail(`header_len ${u32(12)}, not ${HEADER_LEN}`);
    if (!this.width || !this.height) fail(`image size ${this.width}x${this.height}`);
    if (this.tileSize === 0 || this.tileSize > MAX_TILE_SIZE) fail(`tile_size ${this.tileSize}, not 1 to ${MAX_TILE_SIZE}`);
    if (2 * this.border >= this.tileSize) fail(`border ${this.border} leaves nothing of a ${this.tileSize}-texel tile`);
    if (this.levelCount < 1 || this.levelCount > 32) fail(`level_count ${this.levelCount}, not 1 to 32`);
    if (this.channels < 1 || this.channels > 4) fail(`channels ${this.channels}, not 1 to 4`);
    if (this.sampleBytes !== 1 && this.sampleBytes !== 2) fail(`sample_bytes ${this.sampleBytes}, not 1 or 2`);
    if (alignment < 8 || alignment & (alignment - 1)) fail(`alignment ${alignment}, not a power of two of at least 8`);
    if (payloadAlignment < 8 || payloadAlignment & (payloadAlignment - 1)) {
      fail(`payload_alignment ${payloadAlignment}, not a power of two of at least 8`);
    }
    // Payloads are padded to their alignment: neighbours in a row are that far apart at most.
    if (options.gap === undefined) reader.gap = Math.max(reader.gap, payloadAlignment);
    if (this.indexCount > MAX_TILES) fail(`index_count ${this.indexCount}, over the cap of ${MAX_TILES} tiles`);
    if (u32(104) !== ENTRY_LEN) fail(`entry_len ${u32(104)}, not ${ENTRY_LEN}`);
    if (levelsOffset !== HEADER_LEN) fail(`levels_offset ${levelsOffset}, not ${HEADER_LEN}`);
    if (this.indexOffset !== levelsOffset + LEVEL_LEN * this.levelCount) fail(`index_offset ${this.indexOffset} does not follow the level table`);
    if (this.metaOffset !== this.indexOffset + ENTRY_LEN * this.indexCount) fail(`meta_offset ${this.metaOffset} does not follow the index`);
    if (this.metaOffset + this.metaLen > this.dataOffset || this.dataOffset % alignment) fail(`data_offset ${this.dataOffset} overlaps the metadata or is not aligned`);
    if (this.dataOffset > this.fileLen || u64(136, "data_len") !== this.fileLen - this.dataOffset) fail(`data_len ${u64(136, "data_len")} does not end the file`);
    if (first.subarray(70, 72).some((b) => b) || first.subarray(144, 188).some((b) => b)) fail("reserved header bytes are not zero");
    if (required & 1n) this.refuse("zstd-delta");
    /** @type {VtpkLevel[]} */
    this.levels = [];
    /** Index blocks by number, each checked for sense when it arrives. @type {Map<number, Promise<Uint8Array>>} */
    this.blocks = new Map();
    /** Payloads being fetched or recently fetched, by offset: shared tiles are fetched once. */
    this.payloads = new Map();
    /** @type {Uint8Array | null} The level table, kept for the index CRC. */
    this.levelTable = null;
    /** The index CRC: null until every block is here, then whether it matched. @type {boolean | null} */
    this.indexChecked = null;
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
    if (crc32c(meta) !== this.metaCrc) throw new VtpkError(`${this.url}: the metadata's CRC-32C does not match`);
    try {
      this.metadata = this.metaLen ? JSON.parse(new TextDecoder("utf-8", { fatal: true }).decode(meta)) : {};
    } catch (e) {
      throw new VtpkError(`${this.url}: the metadata is not UTF-8 JSON: ${e instanceof Error ? e.message : e}`);
    }
    const codec = this.metadata.codec;
    if (["zstd", "zstd-delta", "bc1", "bc7"].includes(codec)) this.refuse(codec);
    if (whole || bytes === first) {
      // Every block is here: check the index CRC before any entry is used.
      const index = bytes.subarray(at(this.indexOffset), at(this.metaOffset));
      if (crc32c(index, crc32c(table)) !== this.indexCrc) {
        throw new VtpkError(`${this.url}: the CRC-32C of the level table and index does not match: the index is damaged`);
      }
      this.indexChecked = true;
      for (let b = 0; b <= lastBlock; b++) {
        const start = b * BLOCK_ENTRIES * ENTRY_LEN;
        this.blocks.set(b, Promise.resolve(index.subarray(start, Math.min(start + BLOCK_ENTRIES * ENTRY_LEN, indexBytes))));
      }
    } else {
      this.blocks.set(lastBlock, Promise.resolve(bytes.subarray(0, this.metaOffset - from)));
      // An index of one block is whole now: check it.
      await this.checkIndexWhenComplete();
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
        throw new VtpkError(`${this.url}: level ${lod}: ${what}`);
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
    if (next !== this.indexCount) throw new VtpkError(`${this.url}: the levels hold ${next} tiles, the index ${this.indexCount}`);
  }

  /**
   * The index entry of tile (`lod`, `x`, `y`), checked for sense.
   * @param {number} lod
   * @param {number} x
   * @param {number} y
   * @returns {Promise<VtpkEntry>}
   */
  async entry(lod, x, y) {
    const level = this.levels[lod];
    const where = `${this.url}: tile (lod ${lod}, x ${x}, y ${y})`;
    if (!level || x < 0 || y < 0 || x >= level.tilesW || y >= level.tilesH) throw new VtpkError(`${where} is not in the pack`);
    const position = level.firstEntry + y * level.tilesW + x;
    const block = await this.block(Math.floor(position / BLOCK_ENTRIES));
    const o = (position % BLOCK_ENTRIES) * ENTRY_LEN;
    const view = new DataView(block.buffer, block.byteOffset + o, ENTRY_LEN);
    const entry = {
      kind: block[o + 16],
      offset: Number(view.getBigUint64(0, true)),
      len: view.getUint32(8, true),
      crc: view.getUint32(12, true),
      value: block.subarray(o, o + 8),
    };
    if (block.subarray(o + 17, o + 24).some((b) => b)) throw new VtpkError(`${where}: reserved index bytes are not zero`);
    if (entry.kind === KIND.constant || entry.kind === KIND.absent) {
      // No payload: length and CRC zero, and nothing past the texel's samples (all of it for
      // absent). Until the index CRC is checked, this is what catches a damaged entry.
      const used = entry.kind === KIND.constant ? this.channels * this.sampleBytes : 0;
      if (entry.len || entry.crc || entry.value.subarray(used).some((b) => b)) {
        throw new VtpkError(`${where}: a ${KIND_NAMES[entry.kind]} entry with payload fields set: the index is damaged`);
      }
      return entry;
    }
    if (![KIND.raw, KIND.png, KIND.jpeg].includes(entry.kind)) {
      if (entry.kind < KIND_NAMES.length) this.refuse(KIND_NAMES[entry.kind]);
      throw new VtpkError(`${where}: unknown tile kind ${entry.kind}`);
    }
    if (entry.offset < this.dataOffset || entry.offset + entry.len > this.fileLen || entry.len === 0) {
      throw new VtpkError(`${where}: its payload (${entry.len} bytes at ${entry.offset}) is not inside the data section`);
    }
    return entry;
  }

  /** Index block `b`, fetched once; the index CRC is checked when the last one arrives. @param {number} b @private */
  block(b) {
    let block = this.blocks.get(b);
    if (!block) {
      const start = this.indexOffset + b * BLOCK_ENTRIES * ENTRY_LEN;
      block = this.reader.read(start, Math.min(start + BLOCK_ENTRIES * ENTRY_LEN, this.metaOffset));
      this.blocks.set(b, block);
      block.then(() => this.checkIndexWhenComplete(), () => this.blocks.delete(b));
    }
    return block;
  }

  /** @private */
  async checkIndexWhenComplete() {
    const count = Math.ceil(this.indexCount / BLOCK_ENTRIES);
    if (this.indexChecked !== null || this.blocks.size < count || !this.levelTable) return;
    let crc = crc32c(this.levelTable);
    for (let b = 0; b < count; b++) crc = crc32c(await /** @type {Promise<Uint8Array>} */ (this.blocks.get(b)), crc);
    this.indexChecked = crc === this.indexCrc;
    if (!this.indexChecked) {
      this.options.onError?.(new VtpkError(`${this.url}: the CRC-32C of the level table and index does not match: the index is damaged`));
    }
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
          throw new VtpkError(`${where}: the CRC-32C of its ${entry.len}-byte payload at offset ${entry.offset} is ${hex(crc)}, the index says ${hex(entry.crc)}: the tile is damaged`);
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
      if (bytes.length !== size * size * texel) throw new VtpkError(`${where}: a raw tile of ${bytes.length} bytes, not ${size * size * texel}`);
      const image = ctx.createImageData(size, size);
      for (let i = 0; i < size * size; i++) image.data.set(this.rgba(bytes, i * texel), 4 * i);
      ctx.putImageData(image, 0, 0);
      return { canvas, absent: false };
    }
    const type = entry.kind === KIND.png ? "image/png" : "image/jpeg";
    let bitmap;
    try {
      bitmap = await createImageBitmap(new Blob([bytes], { type }), { colorSpaceConversion: "none" });
    } catch (e) {
      throw new VtpkError(`${where}: the browser cannot decode its ${KIND_NAMES[entry.kind]} payload: ${e instanceof Error ? e.message : e}`);
    }
    if (bitmap.width !== size || bitmap.height !== size) {
      throw new VtpkError(`${where}: a ${bitmap.width}x${bitmap.height} image, not ${size}x${size}`);
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
    if (!OSD) throw new VtpkError("VtpkTileSource: OpenSeadragon is not loaded (load it first, or pass it as options.OpenSeadragon)");
    /** @type {string[]} */
    const errors = [];
    const report = (/** @type {VtpkError} */ e) => {
      errors.push(e.message);
      options.onError?.(e);
    };
    const pack = await VtpkPack.open(new URL(url, globalThis.location?.href).href, { ...options, onError: report });
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
            const error = e instanceof VtpkError ? e : new VtpkError(`${pack.url}: tile (lod ${lod}, x ${x}, y ${y}): ${e}`);
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
