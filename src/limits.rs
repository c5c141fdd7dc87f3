//! The caps every command checks before it allocates, whatever its input claims.
//!
//! A header, an `info.json`, a pack's metadata or a flag can claim any size. Each command
//! computes what it will need from those claims first (the pyramid's tile count, the pack
//! index, a whole decoded image, frames, threads, file-name
//! length) and checks it here; over a cap the error names the figure, the cap and the flag
//! that raises it, instead of an abort, an OOM kill or a run that never ends.

use std::sync::atomic::{AtomicU64, Ordering};

use crate::error::TilerError;
use crate::layout::Layout;

/// The caps of one run.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Limits {
    /// Bytes a run may hold at once (`--max-memory`): bands and pages in flight, a pack's
    /// index, a whole decoded image, a row of input tiles.
    pub memory: u64,
    /// Tiles in the whole pyramid. A pack indexes each one; a directory gets one file each.
    pub tiles: u64,
    /// Frames `render` draws.
    pub frames: u64,
    /// Worker threads (`--threads`).
    pub threads: usize,
    /// Bytes of one tile's file name (a file-name pattern can pad numbers to any width).
    pub filename_bytes: usize,
}

/// `--max-memory`'s default.
pub const DEFAULT_MEMORY: u64 = 1 << 30;

/// How much memory a run may hold at once (`--max-memory`): what a source's reader may hold
/// ([`crate::source::open`]) and what a run's outputs share ([`crate::outputs::Plan`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub struct Budget(u64);

impl Budget {
    /// A budget of `bytes`.
    pub fn new(bytes: u64) -> Budget {
        Budget(bytes)
    }

    /// The budget in bytes.
    pub fn bytes(self) -> u64 {
        self.0
    }
}

/// [`DEFAULT_MEMORY`], `split`'s default.
impl Default for Budget {
    fn default() -> Budget {
        Budget(DEFAULT_MEMORY)
    }
}

/// The largest `--tile-align` (a pack's payload alignment) that `split`, `pack` and `convert`
/// accept and that `merge` accepts from a shard: 1 MiB. Each payload is padded to it, so a
/// larger one makes a file mostly of padding (2 GiB made 44 tiles a 71 GB file), and no
/// memory page or GPU sparse block (64 KiB) asks for more.
pub const MAX_TILE_ALIGN: u32 = 1 << 20;

/// The largest `--align` (of the data section, padded to it once): 2 GiB.
pub const MAX_ALIGN: u32 = 1 << 31;

impl Default for Limits {
    fn default() -> Limits {
        Limits {
            memory: DEFAULT_MEMORY,
            // What a pack reader accepts, so that every pyramid written can be read back.
            tiles: vortex_pack::Limits::default().max_tiles,
            frames: 1_000_000,
            threads: max_threads(),
            filename_bytes: 4096,
        }
    }
}

/// The most worker threads accepted: 4 per core, enough to hide I/O waits, not enough to
/// spend minutes starting threads.
pub(crate) fn max_threads() -> usize {
    4 * std::thread::available_parallelism().map_or(1, |n| n.get())
}

/// Index bytes per tile of a pack (one entry per tile of the pyramid).
const INDEX_ENTRY_BYTES: u64 = vortex_pack::format::ENTRY_LEN as u64;

impl Limits {
    fn over(figure: &str, need: u64, cap: u64, flag: &str) -> TilerError {
        TilerError::Limit(format!(
            "{figure} needs {}, more than {flag} ({}); raise {flag}",
            human_bytes(need),
            human_bytes(cap)
        ))
    }

    /// Checks a pyramid's tile count and, for a pack, its index.
    pub(crate) fn check_pyramid(&self, layout: &Layout, pack: bool) -> Result<(), TilerError> {
        let tiles = layout.total_tiles();
        if tiles > self.tiles {
            return Err(TilerError::Limit(format!(
                "the pyramid has {tiles} tiles ({} LODs of up to {} x {} tiles), more than the {} a pyramid may have; a larger tile size gives fewer",
                layout.lod_count, layout.columns, layout.rows, self.tiles
            )));
        }
        if pack {
            let index = tiles.saturating_mul(INDEX_ENTRY_BYTES);
            if index > self.memory {
                return Err(Limits::over(
                    &format!("the pack's index of {tiles} tiles"),
                    index,
                    self.memory,
                    "--max-memory",
                ));
            }
        }
        Ok(())
    }

    /// Checks that `figure` (what needs the memory, for the message) fits in `--max-memory`.
    pub fn check_memory(&self, figure: &str, need: u64) -> Result<(), TilerError> {
        if need > self.memory {
            return Err(Limits::over(figure, need, self.memory, "--max-memory"));
        }
        Ok(())
    }

    /// Checks a `--threads` request.
    pub fn check_threads(&self, threads: usize) -> Result<(), TilerError> {
        if threads > self.threads {
            return Err(TilerError::Limit(format!(
                "--threads {threads} is more than {} (4 per core); 0 means one per core",
                self.threads
            )));
        }
        Ok(())
    }

    /// Checks a frame count.
    pub fn check_frames(&self, frames: u64) -> Result<(), TilerError> {
        if frames > self.frames {
            return Err(TilerError::Limit(format!("{frames} frames is more than the {} a run may draw", self.frames)));
        }
        Ok(())
    }
}

/// `1536` -> "1.5 KiB".
pub fn human_bytes(bytes: u64) -> String {
    let units = ["B", "KiB", "MiB", "GiB", "TiB", "PiB", "EiB"];
    let mut value = bytes as f64;
    let mut unit = 0;
    while value >= 1024.0 && unit + 1 < units.len() {
        value /= 1024.0;
        unit += 1;
    }
    if unit == 0 { format!("{bytes} B") } else { format!("{value:.1} {}", units[unit]) }
}

/// What a run holds, part by part, as its stages count their own buffers (issue 28): where the
/// memory under `--max-memory` went, for `split --json`. Each part's bytes now and at most, and
/// the most all parts held at once (at most the sum of the parts' peaks, which need not
/// coincide). Capacities, not lengths: what the allocator was asked for.
#[derive(Debug, Default)]
pub(crate) struct Gauge {
    now: [AtomicU64; PARTS],
    peak: [AtomicU64; PARTS],
    total: AtomicU64,
    total_peak: AtomicU64,
}

/// The parts a `Gauge` counts, in the pipeline's order.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Part {
    /// The source decoder's own buffers beyond the rows it fills (a TIFF's row of tiles).
    Decoder,
    /// Chunks of source rows read ahead, queued, summed or being cut (`source::read_ahead`).
    ReadAhead,
    /// The rows the pyramid's sums made of those chunks, waiting for the cutting thread.
    SumRows,
    /// Every level's row of tiles being filled (`pyramid::band`).
    Bands,
    /// Tiles cut and not yet encoded: queued for the encoders, in lots, being encoded.
    Tiles,
    /// Encoded tiles waiting for the writer (ordered sinks: packs).
    Encoded,
}

const PARTS: usize = 6;

/// Each part's most bytes, and the most all of them held at once.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Peaks {
    /// The most bytes each [`Part`] held, indexed by `Part as usize`; read with [`Peaks::part`].
    pub parts: [u64; PARTS],
    /// The most bytes all parts held at one moment (at most the parts' sum).
    pub total: u64,
}

impl Peaks {
    /// The most bytes `part` held at once.
    pub fn part(&self, part: Part) -> u64 {
        self.parts[part as usize]
    }
}

impl Gauge {
    /// `bytes` more (or fewer, negative) held for `part`.
    pub fn add(&self, part: Part, bytes: i64) {
        if bytes == 0 {
            return;
        }
        bump(&self.now[part as usize], &self.peak[part as usize], bytes as u64);
        bump(&self.total, &self.total_peak, bytes as u64);
    }

    /// `part` holds `bytes` now (a buffer that is resized rather than allocated and freed), for
    /// a part only ever set, never added to. One atomic swap: two threads setting the part at
    /// once each move the total by the difference from what they replaced, so the deltas add
    /// up to the last value set whatever the order (a load then an add could count one twice).
    pub fn set(&self, part: Part, bytes: u64) {
        let old = self.now[part as usize].swap(bytes, Ordering::Relaxed);
        self.peak[part as usize].fetch_max(bytes, Ordering::Relaxed);
        bump(&self.total, &self.total_peak, bytes.wrapping_sub(old));
    }

    /// What all parts hold now.
    #[cfg(test)]
    fn held(&self) -> u64 {
        self.total.load(Ordering::Relaxed)
    }

    pub fn peaks(&self) -> Peaks {
        Peaks {
            parts: std::array::from_fn(|i| self.peak[i].load(Ordering::Relaxed)),
            total: self.total_peak.load(Ordering::Relaxed),
        }
    }
}

/// Moves `now` by `delta` (two's complement: a negative delta wraps back down) and keeps `peak`.
/// A counter briefly below zero (one thread frees what another has not counted yet) is not a
/// peak.
fn bump(now: &AtomicU64, peak: &AtomicU64, delta: u64) {
    let new = now.fetch_add(delta, Ordering::Relaxed).wrapping_add(delta);
    if new <= i64::MAX as u64 {
        peak.fetch_max(new, Ordering::Relaxed);
    }
}

/// What the source's read-ahead (`source::read_ahead`) holds, which the stripes' plan counts
/// before it picks how a source is read: below both, so that the pyramid needs no source.
pub(crate) mod read_ahead {
    /// Bytes of rows read per chunk at most (at least one row): enough rows that handing a chunk
    /// over costs nothing next to decoding it.
    pub const CHUNK_BYTES: u64 = 1 << 20;

    /// Chunks queued ahead of the caller; with the one being read and the one being used, memory
    /// holds at most `CHUNKS_AHEAD + 2` chunks.
    pub(crate) const CHUNKS_AHEAD: usize = 2;

    /// Chunks a caller of `chunks` may hold beyond the one it is given: the pyramid's sums hand
    /// each chunk on to the cutting thread, which holds one and has the rest queued. With 2 (a
    /// chunk queued), the reader, the sums and the cutter stalled together whenever the encoders
    /// fell behind, and the encoders then waited for a whole row of tiles to come through them:
    /// on the 16384² benchmark their idle time fell from 0.46-0.70 s to 0.16-0.24 s with 8, for
    /// about 15 MiB more (issue 18).
    pub const CHUNKS_HANDED_ON: u64 = 8;

    /// Rows per chunk of `row_bytes`-byte rows: as many as fit [`CHUNK_BYTES`], at least one.
    pub fn rows_per_chunk(row_bytes: u64) -> u64 {
        (CHUNK_BYTES / row_bytes.max(1)).max(1)
    }

    /// Bytes the read-ahead holds at most for rows of `row_bytes` bytes of `texel_bytes`-byte
    /// texels (`readAheadBytes` and `sumRowsBytes`): every chunk that can be alive at once
    /// ([`CHUNKS_AHEAD`] queued, the one being read, and [`CHUNKS_HANDED_ON`] with the sums and
    /// the cutting thread), and what the pyramid's sums made of each of those that is handed
    /// on, and of the one they are filling ([`derived_bytes`]).
    pub fn bytes(row_bytes: u64, texel_bytes: u64) -> u64 {
        let chunks = CHUNKS_AHEAD as u64 + 2 + CHUNKS_HANDED_ON;
        let chunk = rows_per_chunk(row_bytes).saturating_mul(row_bytes);
        let derived = derived_bytes(row_bytes, texel_bytes);
        chunks.saturating_mul(chunk).saturating_add((CHUNKS_HANDED_ON + 1).saturating_mul(derived))
    }

    /// Bytes (capacity) of the rows the pyramid's sums make of one chunk (`cascade::Derived`),
    /// at most: level `k` below the source gets at most `R / 2^k + 8` rows of `W / 2^k + 1`
    /// texels from `R` rows `W` texels wide (the 8: a resampling filter's rows still due when
    /// the pass ends), so over at most 64 levels a third of the chunk, `R` texels, 8 rows and
    /// 512 texels; with a row's place (16 bytes) per row made and per source row (8). Each
    /// `Vec` grows by doubling: twice all that.
    pub fn derived_bytes(row_bytes: u64, texel_bytes: u64) -> u64 {
        let rows = rows_per_chunk(row_bytes);
        let chunk = rows.saturating_mul(row_bytes);
        let samples = (chunk / 3).saturating_add(rows * texel_bytes).saturating_add(8 * row_bytes + 512 * texel_bytes);
        let places = 16 * (rows + 512) + 8 * rows;
        2 * samples.saturating_add(places)
    }
}

/// How many cut tiles the stages keep between the cutting thread and the pack writer, which the
/// stripes' plan counts: below both, so that the pyramid needs neither the encoders nor `split`.
pub(crate) mod in_flight {
    /// Batches of tiles waiting for the encoders besides the one the cutting thread is sending:
    /// none, the channel is a rendezvous. The encoders' lots in flight keep them busy; a batch
    /// waiting in the queue too cost a row of tiles of memory (11 MiB at a 16384-texel width:
    /// 84.7 against 73.6 MiB of peak RSS) for 3% of wall time (0.86 against 0.89 s, medians of
    /// 9 on the strip BigTIFF, issue 28's sixth round in docs/benchmarks.md).
    pub const QUEUE_BATCHES: usize = 0;

    /// Lots (batches received together) spawned on the pool and not yet stored: the one the
    /// writer stores and the one encoding behind it. A lot is received only once one of these
    /// places is free: spawned first and then queued for the writer, a third lot's texels
    /// waited on the pool (a row of tiles, 12 MiB at a 16384-texel width: issue 28).
    pub const LOTS_IN_FLIGHT: usize = 2;

    /// The most tiles a lot is gathered up to, whatever the thread count: the plan's memory
    /// bound, and with it the stripes a run is cut in and so a pack's order, must not depend on
    /// the machine, and each tile it allows is a tile more the plan counts in every lot. Up to
    /// 2 threads gather twice their threads; more threads gather small batches (images a few
    /// tiles wide, the coarsest levels) into lots of 4 tiles or more all the same, which leaves
    /// some of them idle on those few tiles.
    pub const GATHER_MOST: usize = 4;

    /// Cut tiles the encoders hold at most, received and not yet stored, where the producer's
    /// batches hold at most `batch_tiles` tiles each: [`LOTS_IN_FLIGHT`] lots, each gathered
    /// from batches until it holds up to [`GATHER_MOST`] tiles (so fewer than that, plus one
    /// more batch). An ordered sink's encodings wait among them, one per tile (a pack neither
    /// crops nor splits a tile's places; the plan counts each at the codec's most,
    /// `Codec::most_encoded_bytes`).
    pub fn most_tiles_in_lots(batch_tiles: u64) -> u64 {
        LOTS_IN_FLIGHT as u64 * (batch_tiles + GATHER_MOST as u64)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn too_many_tiles_are_refused_before_allocation() {
        // 2^24 texels per side in 4-texel payloads: 2^44 / 3 tiles.
        let layout = Layout::new(1 << 24, 1 << 24, 8, 2).unwrap();
        let e = Limits::default().check_pyramid(&layout, true).unwrap_err().to_string();
        assert!(e.contains("tiles") && e.contains("tile size"), "{e}");
        // A wide strip has a strip of pages: 16000000 x 1 in 128-texel pages is 250,007 tiles,
        // where the square grid had 131072^2 at LOD 0 alone.
        let strip = Layout::new(16_000_000, 1, 128, 0).unwrap();
        assert_eq!(strip.total_tiles(), 250_007);
        Limits::default().check_pyramid(&strip, true).unwrap();
    }

    #[test]
    fn ordinary_runs_pass() {
        Limits::default().check_pyramid(&Layout::new(16384, 16384, 256, 0).unwrap(), true).unwrap();
    }

    #[test]
    fn the_gauge_keeps_each_part_s_peak_and_the_total_s() {
        let g = Gauge::default();
        g.add(Part::Bands, 100);
        g.add(Part::Tiles, 50);
        g.add(Part::Bands, -100);
        g.add(Part::Tiles, 70);
        g.set(Part::Decoder, 30);
        g.set(Part::Decoder, 10);
        let p = g.peaks();
        assert_eq!((p.part(Part::Bands), p.part(Part::Tiles), p.part(Part::Decoder)), (100, 120, 30));
        // 150 with both bands and tiles held; 150 again with 120 + 30, never more.
        assert_eq!(p.total, 150);
        // Freed before counted: not a peak.
        g.add(Part::Encoded, -5);
        g.add(Part::Encoded, 5);
        assert_eq!(g.peaks().part(Part::Encoded), 0);
    }

    #[test]
    fn parts_set_from_several_threads_add_up() {
        // Each thread sets the part to its own figures and then 0: whatever the interleaving,
        // the total ends where the other parts leave it (a load then an add could leave a
        // thread's figure counted twice or not at all).
        let g = Gauge::default();
        g.add(Part::Bands, 1000);
        std::thread::scope(|s| {
            for t in 1..=4u64 {
                let g = &g;
                s.spawn(move || {
                    for i in 0..20_000 {
                        g.set(Part::Decoder, t * 100 + i % 7);
                    }
                });
            }
        });
        g.set(Part::Decoder, 0);
        assert_eq!(g.held(), 1000);
        assert_eq!(g.peaks().part(Part::Decoder), 406);
    }

    #[test]
    fn threads_and_frames() {
        let limits = Limits::default();
        assert!(limits.check_threads(1_000_000_000).unwrap_err().to_string().contains("4 per core"));
        limits.check_threads(1).unwrap();
        assert!(limits.check_frames(4_000_000_000).is_err());
    }
}
