// Types for vtpk.js (which carries the same in JSDoc, checked with `// @ts-check`).

/**
 * What the caller can do about an error: `io` try again later (no connection, a reply cut short,
 * the timeout, HTTP 408/429/5xx); `host` fix the server (it ignores Range, hides Content-Range,
 * answers another range, sends more than asked or compresses); `unavailable` the pack is not
 * there (any status but 200, 206, 408, 429 and 5xx: 404, 403, another 4xx) or changed while
 * being read; `corrupt` the pack's bytes are wrong; `unsupported` a sound pack this module does
 * not show (or no canvas to draw tiles in); `usage` the caller's mistake.
 */
export type VtpkErrorKind = "io" | "host" | "unavailable" | "corrupt" | "unsupported" | "usage";

/** An error about a pack, naming the URL and the field or tile, and its kind. */
export class VtpkError extends Error {
  constructor(kind: VtpkErrorKind, message: string, cause?: unknown);
  readonly kind: VtpkErrorKind;
}

/** CRC-32C (Castagnoli) of `bytes`, continuing from `crc`. */
export function crc32c(bytes: Uint8Array, crc?: number): number;

/** Requests and bytes fetched so far; payloads read (a shared one once); constant tiles drawn. */
export interface VtpkStats {
  requests: number;
  bytes: number;
  payloads?: number;
  constants?: number;
}

export interface VtpkLevel {
  tilesW: number;
  tilesH: number;
  firstEntry: number;
  width: number;
  height: number;
}

export interface VtpkEntry {
  /** 0 absent, 1 constant, 2 raw, 4 png, 5 jpeg, 9 jxl. */
  kind: number;
  offset: number;
  len: number;
  crc: number;
  value: Uint8Array;
}

export interface VtpkOptions {
  /** The fetch to use (default: the page's). */
  fetch?: typeof fetch;
  /** Extra request headers. */
  headers?: Record<string, string>;
  /** Read and check the whole index first when it is at most this many bytes (default 32768). */
  wholeIndexUpTo?: number;
  /** Merge reads less than this many bytes apart (default 4096, or the payload alignment if larger). */
  gap?: number;
  /** Never merge reads into a request longer than this (default 4 MiB). */
  maxSpan?: number;
  /** Gather reads until none has come for this many milliseconds (default 20). */
  wait?: number;
  /** But never hold a read back longer than this (default 60). */
  maxWait?: number;
  /** OpenSeadragon gets no level whose long side is under this many texels, past the first one
   * under it (default 512; 0: every level). The coarsest levels are only placeholders while a
   * view loads, and a pack stores them as whole, padded tiles. */
  minSide?: number;
  /** The most milliseconds one request may take, reply and body together (default 30000; 0:
   * none); a request that takes longer fails with a `VtpkError` of kind `io`. */
  timeout?: number;
  /** Called by `VtpkTileSource` with each tile that fails, whatever the kind; and, by `VtpkPack`
   * too, when an index read in blocks fails its check (CRC, content hash) once every block is in. */
  onError?: (error: VtpkError) => void;
  /** The OpenSeadragon namespace (default: the global one). */
  OpenSeadragon?: unknown;
}

/** An open pack: header, levels, metadata; tiles on demand. */
export class VtpkPack {
  static open(url: string, options?: VtpkOptions): Promise<VtpkPack>;
  readonly url: string;
  readonly width: number;
  readonly height: number;
  readonly tileSize: number;
  readonly border: number;
  readonly levelCount: number;
  readonly channels: number;
  readonly sampleBytes: number;
  readonly levels: VtpkLevel[];
  readonly metadata: Record<string, unknown>;
  /** Whether the level table and index matched their CRC and the content hash (null until all
   * of it was read; once false, every `entry` fails). */
  readonly indexChecked: boolean | null;
  readonly stats: VtpkStats;
  entry(lod: number, x: number, y: number): Promise<VtpkEntry>;
  tile(lod: number, x: number, y: number): Promise<{ canvas: HTMLCanvasElement | OffscreenCanvas; absent: boolean }>;
}

/** An OpenSeadragon.TileSource showing a pack, with the pack and the errors met. */
export interface VtpkOpenSeadragonSource {
  vtpk: VtpkPack;
  errors: string[];
  minLevel: number;
  maxLevel: number;
  [key: string]: unknown;
}

export class VtpkTileSource {
  /** Opens the pack at `url` and gives a tile source for `OpenSeadragon({tileSources})`. */
  static open(url: string, options?: VtpkOptions): Promise<VtpkOpenSeadragonSource>;
}
