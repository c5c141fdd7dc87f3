//! Where finished tiles go: the stage after the encoders. A sink receives encoded tiles from
//! many threads in any order and is finished once, after the last tile, with the pyramid's
//! description.
//!
//! Each format's sink lives with its format ([`crate::formats`]); [`DirSink`] (`dir.rs`)
//! lives here because two formats write through it: the tile directory of
//! [`crate::formats::tiles`] and the viewer layouts of [`crate::formats::viewer`]. All write
//! under a temporary name and rename into place when complete; at an `s3://` URL, see
//! [`crate::store`].

mod dir;
pub(crate) mod icc;

pub use dir::DirSink;
pub(crate) use dir::ResumeFrom;

use crate::error::{Result, TilerError};
use crate::layout::Crop;

/// Takes the encoded tiles of one run.
pub trait TileSink: Sync {
    /// Stores tile `(x, y)` of LOD `lod` (column and row of its level's page grid, from the
    /// top left), `bytes` as the codec encoded it. Called from the encoding threads, at most
    /// once per place; in LOD and row order only where [`TileSink::ordered`] says so.
    fn write_tile(&self, lod: u32, x: u32, y: u32, bytes: &[u8]) -> Result<()>;
    /// Stores tile `(x, y)` of LOD `lod` as [`TileSink::write_tile`] does, `bytes` being the
    /// source's stored JPEG tile, copied (or cropped losslessly), not coded by this run: a
    /// sink that states how its tiles were coded (a DICOM series' lossy history) counts them.
    fn write_stored(&self, lod: u32, x: u32, y: u32, bytes: &[u8]) -> Result<()> {
        self.write_tile(lod, x, y, bytes)
    }
    /// Stores tile `(x, y)` of LOD `lod` as [`TileSink::write_tile`] does, `jxl` being the
    /// source's stored JPEG tile recompressed losslessly into JPEG XL (`--codec jxl`): a sink
    /// that states how its tiles were coded (a DICOM series' transfer syntax) counts them.
    fn write_recompressed(&self, lod: u32, x: u32, y: u32, jxl: &[u8]) -> Result<()> {
        self.write_tile(lod, x, y, jxl)
    }
    /// Whether one-colour tiles should come as their colour (`write_constant`) rather than
    /// encoded.
    fn takes_constants(&self) -> bool {
        false
    }
    /// A tile whose texels all equal `texel` (samples of the stored layout, little-endian);
    /// only called when `takes_constants`.
    fn write_constant(&self, lod: u32, x: u32, y: u32, _texel: &[u8]) -> Result<()> {
        Err(TilerError::Internal(format!("tile (lod {lod}, x {x}, y {y}): this sink stores no one-colour tiles")))
    }
    /// Whether tiles must arrive in the same order on every run (a pack's bytes depend on it;
    /// a directory's do not, and takes them from many threads at once).
    fn ordered(&self) -> bool {
        false
    }
    /// Whether a source's stored JPEG tile (`jpeg`, a complete file) may be stored as it is:
    /// a file that describes its own JPEGs (a tile file, a pack) takes any; a TIFF, whose tags
    /// say the colour space and subsampling of every tile of a level, only one that matches
    /// them. A tile some sink refuses is encoded for all of them instead.
    fn takes_stored_jpeg(&self, _jpeg: &[u8]) -> bool {
        true
    }
    /// The part of page (lod, x, y) to encode, where the sink's layout keeps less than the
    /// whole page (a viewer layout's edge tiles); `None` keeps it all.
    fn crop(&self, _lod: u32, _x: u32, _y: u32) -> Option<Crop> {
        None
    }
    /// Whether tile `(x, y)` of LOD `lod` is in the output already, kept from an interrupted
    /// run that this one resumes (`--resume`, [`crate::resume`]): the run need not encode it,
    /// and the sink ignores it if it comes. `false` for every tile of a run that resumes nothing.
    fn kept(&self, _lod: u32, _x: u32, _y: u32) -> bool {
        false
    }
    /// Bytes of tile data written so far.
    fn bytes_written(&self) -> u64;
}

/// A sink and the levels of the pyramid it takes, LOD 0 up to `lods` (exclusive): one run may
/// feed several sinks ([`crate::split::split_to`]), a pack stopping at its one-page level where
/// Deep Zoom goes on down to one texel.
#[derive(Clone, Copy)]
pub(crate) struct Target<'a> {
    pub sink: &'a dyn TileSink,
    pub lods: u32,
    /// What its padding holds: pages cut with the edge repeated are filled with its colour
    /// where they lie past the image.
    pub background: crate::background::Background,
    /// How its tiles are encoded (targets of one pyramid may differ).
    pub encoding: crate::job::TileEncoding,
}
