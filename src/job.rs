//! What a run is asked to make ([`SplitOptions`]), what watches it ([`Progress`]) and what it
//! reports ([`Summary`]): the vocabulary the pipeline's stages, the settings and the sharded
//! runs share, kept apart from the orchestration in `split` so that none of them depends on it.

use crate::background::Background;
use crate::codec::Codec;
use crate::error::Result;
use crate::layout::Layout;
use crate::limits::Peaks;
use crate::pixel::{Depth, PixelLayout};
use crate::pyramid::Filter;
use crate::source::stored::Quality;
use crate::stages::StageTimes;

/// How to cut and store the pyramid.
#[derive(Clone, Debug, PartialEq)]
pub struct SplitOptions {
    /// Side of every stored tile in texels, borders included (`--tile-size`).
    pub tile_size: u32,
    /// Texels each tile repeats from its neighbours on every side (`--border`).
    pub border: u32,
    /// How tiles are encoded.
    pub codec: Codec,
    /// What fills the padding past the image's right and bottom edges (`--background`).
    pub background: Background,
    /// Composite alpha over the background (or black) instead of storing it.
    pub flatten: bool,
    /// Store tiles at this depth instead of the source's (JPEG is always 8-bit).
    pub tile_depth: Option<Depth>,
    /// How each LOD is made from the finer ones.
    pub filter: Filter,
    /// Bytes the pipeline may hold (`--max-memory`); a wider image is cut in stripes.
    pub max_memory: u64,
    /// Go on below one page until the image is one texel, as Deep Zoom's levels do
    /// ([`Layout::down_to_one_texel`]).
    pub down_to_one_texel: bool,
    /// Why the source's stored JPEG tiles are encoded again rather than copied where they
    /// line up with the finest level's pages (`--reencode`, an explicit `--quality` or
    /// `--subsampling`); `None` copies them (`StoredTiles`).
    pub reencode: Option<&'static str>,
    /// Make the first reduced level from the source's stored JPEG tiles decoded at half size
    /// in the DCT domain (`--fast-shrink`), where the finest level copies them: faster, not
    /// exact (docs/accuracy.md). Off: every level from the exact sums of the decoded texels.
    pub fast_shrink: bool,
}

impl SplitOptions {
    /// The page grid these options cut a `width x height` image into.
    pub fn layout(&self, width: u32, height: u32) -> Result<Layout> {
        let layout = Layout::new(width as u64, height as u64, self.tile_size, self.border)?;
        Ok(if self.down_to_one_texel { layout.down_to_one_texel() } else { layout })
    }

    /// How these options turn a cut page into a tile: what outputs that share the pyramid may
    /// still differ by.
    pub(crate) fn encoding(&self) -> TileEncoding {
        TileEncoding {
            codec: self.codec,
            flatten: self.flatten,
            // The colour alpha is composited over; without flattening it is no part of a tile.
            matte: if self.flatten { self.background } else { Background::Edge },
            tile_depth: self.tile_depth,
            reencode: self.reencode,
        }
    }

    /// What outputs that share this pyramid have in common: these options without their
    /// encoding ([`encoding`](Self::encoding)), how deep the levels go and the padding's colour
    /// (pages cut with the edge repeated take any target's colour).
    pub(crate) fn pyramid_key(&self) -> SplitOptions {
        SplitOptions {
            codec: Codec::Raw,
            flatten: false,
            tile_depth: None,
            reencode: None,
            down_to_one_texel: false,
            background: Background::Edge,
            ..self.clone()
        }
    }
}

/// How one target of a run encodes the pages it gets: several targets of one pyramid may
/// encode them differently (a Deep Zoom's JPEG tiles beside an OME-Zarr's raw chunks), each
/// page then encoded once per distinct encoding.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct TileEncoding {
    pub codec: Codec,
    pub flatten: bool,
    /// The colour alpha is composited over where `flatten` ([`Background::Edge`]: black).
    pub matte: Background,
    pub tile_depth: Option<Depth>,
    /// Why the source's stored JPEG tiles are encoded again ([`SplitOptions::reencode`]).
    pub reencode: Option<&'static str>,
}

impl TileEncoding {
    /// The texels its tiles hold, of a `source` pyramid.
    pub fn stored(&self, source: PixelLayout) -> Result<PixelLayout> {
        self.codec.stored_layout(source, self.flatten, self.tile_depth)
    }

    /// Why its tiles cannot be a source's stored JPEG tiles, copied (`None`: they can, where
    /// the pages line up with them).
    pub fn declines_stored(&self) -> Option<String> {
        match (self.reencode, self.codec) {
            (Some(why), _) => Some(format!("{why} asked")),
            // JPEG XL takes them recompressed losslessly (`encoders::File::Recompressed`).
            (None, Codec::Jpeg { .. } | Codec::Jxl { .. }) => None,
            (None, codec) => Some(format!("the tiles are {}", codec.name())),
        }
    }
}

/// Watches a run: told of finished tiles, asked whether to stop.
pub trait Progress: Sync {
    /// `tiles` more tiles are stored, a tile counted once for every sink it went to (called
    /// from the run's threads); the calls of a finished run add up to [`Summary::tiles`].
    fn advance(&self, _tiles: u64) {}
    /// The run's tiles in all, where writing finds them other than planned: an output that
    /// holds a slide's own levels copies their tiles, not the pyramid the plan counted.
    fn total(&self, _tiles: u64) {}
    /// Checked once per source row and per batch of tiles; a run that sees `true` stops with
    /// [`TilerError::Interrupted`](crate::error::TilerError::Interrupted).
    fn cancelled(&self) -> bool {
        false
    }
}

/// No progress reporting, never cancelled.
impl Progress for () {}

/// What a finished run produced.
#[derive(Clone, Debug)]
pub struct Summary {
    /// The page grid the image was cut into.
    pub layout: Layout,
    /// The texels the source delivered.
    pub source: PixelLayout,
    /// The texels the tiles hold (after flattening and the tile depth).
    pub stored: PixelLayout,
    /// Tiles stored, every LOD, summed over the run's sinks (one sink: each page once).
    pub tiles: u64,
    /// What each target of the run got (`split_to`); one for a run into one sink.
    pub(crate) per_target: Vec<Written>,
    /// Tiles encoded; the others share an identical neighbour's bytes, were stored as their one
    /// colour or were copied.
    pub encoded: u64,
    /// Tiles kept from the interrupted run this one resumed (`--resume`, [`crate::resume`]):
    /// in the output already, checked against its journal, neither encoded nor written again.
    pub kept: u64,
    /// Tiles of the finest level copied from the source's stored JPEG tiles.
    pub copied: u64,
    /// Of the copied tiles, those cropped losslessly to an edge page's part inside the image.
    pub cropped: u64,
    /// Of the copied tiles, those recompressed losslessly into JPEG XL (`--codec jxl`).
    pub recompressed: Recompressed,
    /// The source's stored tiles, where it has some, and whether they were copied.
    pub stored_tiles: Option<StoredReport>,
    /// Bytes of tile data the sinks wrote, summed over them (not their files' other bytes).
    pub bytes: u64,
    /// Vertical stripes the fine LODs were cut in (1: one band over the whole width, or one
    /// stripe of the fine LODs and a coarse pass; 0: a shard, whose passes are its rectangles).
    pub stripes: usize,
    /// Times the source was read: 1 for one band, the stripes plus one for the coarse pass, a
    /// shard's rectangles (each only its rows, where the source can seek).
    pub passes: usize,
    /// Where the wall time went.
    pub stages: StageTimes,
    /// Where the memory went.
    pub memory: MemoryReport,
}

/// What one sink of a run got: tiles (places) and bytes of tile data, and of the tiles those
/// copied from the source's stored tiles (some cropped at the image's edge).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Written {
    pub tiles: u64,
    pub bytes: u64,
    pub copied: u64,
    pub cropped: u64,
    pub recompressed: Recompressed,
}

/// The source's stored JPEG tiles that `--codec jxl` recompressed losslessly into JPEG XL
/// (libjxl's JPEG reconstruction: `djxl` gives each JPEG back byte for byte).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Recompressed {
    /// Tiles recompressed.
    pub tiles: u64,
    /// Their bytes as the stored JPEG files (cropped ones as cropped).
    pub jpeg_bytes: u64,
    /// Their bytes as JPEG XL files.
    pub jxl_bytes: u64,
    /// Stored tiles libjxl could not recompress exactly (an unusual JPEG), encoded from their
    /// texels instead.
    pub refused: u64,
}

impl Recompressed {
    /// Bytes the recompression saved (negative where the JPEG XL files are larger).
    pub fn saved(&self) -> i64 {
        self.jpeg_bytes as i64 - self.jxl_bytes as i64
    }
}

/// Where a run's memory went (issue 28), by the stages' own count of their buffers beside the
/// budget: what `split --json` reports under `memory` (docs/cli.md).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct MemoryReport {
    /// `--max-memory`.
    pub budget: u64,
    /// What the plan counted on holding at most, its bound for the parts below
    /// (`pyramid::stripes`); `None` where no plan was made (a shard, merge's coarse levels).
    pub planned: Option<u64>,
    /// What each part held at most, and all of them at once.
    pub peaks: Peaks,
}

/// A source's stored JPEG tiles as the summary tells of them.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct StoredReport {
    /// Texels across and down of a stored tile.
    pub tile_size: (u32, u32),
    /// The quality they were stored at, from their quantisation tables.
    pub quality: Option<Quality>,
    /// Why none was copied (`None`: those wholly inside the image and on the pages' grid were).
    pub declined: Option<String>,
    /// The first reduced level was made from them decoded at half size (`--fast-shrink`).
    pub halved: bool,
}
