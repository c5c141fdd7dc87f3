//! A pyramid this tool wrote (`info.json` + tile files): its LOD 0 is the image, each tile's
//! payload the cell, its border skipped.

use std::path::{Path, PathBuf};

use crate::error::{Result, ShowPath};
use crate::formats::tiles::TiledDir;
use crate::formats::tiles::filename::FilenameFormat;
use crate::pixel::{Channels, Depth, PixelLayout};
use crate::source::ImageHeader;
use crate::source::tiled::{CellData, TileGrid, info_icc_profile, read_file};

/// A tile directory this tool wrote (`info.json` and its tiles), read back as its LOD 0
/// image for `convert`: each tile's border cut off.
pub struct SplitOutput {
    dir: PathBuf,
    names: FilenameFormat,
    header: ImageHeader,
    payload: u32,
    border: u32,
}

impl SplitOutput {
    /// Reads `dir/info.json` ([`TiledDir::read`]) and checks what `convert` can read.
    pub fn open(dir: &Path) -> Result<SplitOutput> {
        let t = TiledDir::read(dir)?;
        let d = t.description;
        let channels = [Channels::Grey, Channels::GreyAlpha, Channels::Rgb, Channels::Rgba][d.channels as usize - 1];
        let depth = Depth::from_pack(d.sample_bytes, d.sample_format).unwrap_or(Depth::U8);
        // A JPEG pyramid stores 8-bit samples whatever tileType says.
        let header = ImageHeader { width: d.width, height: d.height, layout: PixelLayout::new(channels, depth) };
        Ok(SplitOutput {
            dir: dir.to_path_buf(),
            names: t.names,
            header,
            payload: d.tile_size - 2 * d.border,
            border: d.border,
        })
    }
}

impl TileGrid for SplitOutput {
    fn describe(&self) -> String {
        format!("LOD 0 of the pyramid in {} ({}-texel payload, border {})", self.dir.shown(), self.payload, self.border)
    }
    fn header(&self) -> ImageHeader {
        self.header
    }
    fn cell(&self) -> (u32, u32) {
        (self.payload, self.payload)
    }
    fn icc_profile(&self) -> Result<Option<Vec<u8>>> {
        let path = self.dir.join("info.json");
        let json = std::fs::read(&path).map_err(|e| crate::error::TilerError::io(&path, e))?;
        info_icc_profile(&path, &json)
    }
    fn read(&self, col: u32, row: u32, cap: u64) -> Result<Option<CellData>> {
        read_file(&self.dir.join(self.names.format(&[0, col, row])), cap)
    }
    fn crop(&self, _: u32, _: u32) -> (u32, u32) {
        (self.border, self.border)
    }
    fn stored_size(&self, _: u32, _: u32) -> Option<(u32, u32)> {
        let side = self.payload + 2 * self.border;
        Some((side, side))
    }
}
