//! The tile directory `split -o` writes and `pack`, `unpack` and `convert` read: `info.json`
//! ([`info`], specified in docs/info-json.md) beside one file per tile, named by a positional
//! pattern ([`filename`]). [`TiledDir`] reads one back, completing the thesis's version-0
//! files with defaults. It is a format, not a stage: the directory sink writes it, the tiled
//! sources and `repack` read it.

pub mod filename;
pub mod info;
mod named;
mod read;

pub use named::NamedDir;
pub use read::SplitOutput;

use std::path::Path;

use vortex_pack::{Description, Level};

use crate::codec::{Bc7Effort, Codec, JxlEffort, PngLevel, RowFilter, Subsampling};
use crate::codec::{DEFAULT_BC7_EFFORT, DEFAULT_JXL_QUALITY, DEFAULT_ZSTD_LEVEL};
use crate::error::{Result, TilerError};
use crate::layout::{Layout, lods_for};
use crate::pixel::{Channels, Depth, PixelLayout};
use filename::FilenameFormat;
use info::{FORMAT_VERSION, InfoFile};

/// A tiled directory's `info.json`, completed with defaults for the thesis's version-0 files.
pub struct TiledDir {
    /// The file as read, absent members left absent.
    pub info: InfoFile,
    /// The pyramid as a pack's header describes one: size, tile size, border, levels, texels.
    pub description: Description,
    /// The page grid of every LOD, as a pack's level table states it.
    pub levels: Vec<Level>,
    /// The tile files' names (`filenameFormat`).
    pub names: FilenameFormat,
    /// The tiles' codec and its settings, as `info.json` states them.
    pub codec: Codec,
}

impl TiledDir {
    /// Reads and checks `dir/info.json`: every member a run needs present or defaulted as
    /// the thesis's files imply, and consistent with the others.
    pub fn read(dir: &Path) -> Result<TiledDir> {
        let path = dir.join("info.json");
        let mut info = InfoFile::read(&path)?;
        let missing =
            |field: &str| TilerError::Info { path: path.clone(), field: field.into(), message: "is required".into() };
        let tile_size = info.tile_size.ok_or_else(|| missing("tileSize"))?;
        let (columns, rows) = info.grid().ok_or_else(|| missing("tileColumns"))?;
        let border = info.border.unwrap_or(info::BORDER_WHEN_ABSENT);
        let payload = tile_size.checked_sub(2 * border).filter(|p| *p > 0).ok_or_else(|| TilerError::Info {
            path: path.clone(),
            field: "border".into(),
            message: format!("{border} leaves no payload in {tile_size}-texel tiles"),
        })?;
        // The thesis's files have no size: the image fills the grid.
        let (width, height) = match (info.width, info.height) {
            (Some(w), Some(h)) => (w, h),
            _ => {
                let side = |pages: u32| u32::try_from(pages as u64 * payload as u64).map_err(|_| missing("width"));
                (side(columns)?, side(rows)?)
            }
        };
        let names = info.filename_format.clone().ok_or_else(|| missing("filenameFormat"))?;
        let names = FilenameFormat::parse(&names, 3).map_err(|e| TilerError::Info {
            path: path.clone(),
            field: "filenameFormat".into(),
            message: e.to_string(),
        })?;
        let codec = codec_of(&info, names.extension()).filter(Codec::writes_files).ok_or_else(|| TilerError::Info {
            path: path.clone(),
            field: "codec".into(),
            message: "neither codec nor the file extension says jpeg, png or jxl".into(),
        })?;
        let channels = Channels::from_tile_format(info.tile_format.as_deref().unwrap_or("rgb")).ok_or_else(|| {
            TilerError::Info { path: path.clone(), field: "tileFormat".into(), message: "not supported".into() }
        })?;
        let depth = Depth::from_tile_type(info.tile_type.as_deref().unwrap_or("unsignedByte")).ok_or_else(|| {
            TilerError::Info { path: path.clone(), field: "tileType".into(), message: "not supported".into() }
        })?;
        let lod_count = lods_for(columns.max(rows));
        let description = Description {
            width,
            height,
            tile_size,
            border,
            level_count: lod_count,
            channels: channels.count() as u8,
            sample_bytes: depth.bytes() as u8,
            sample_format: depth.pack_sample_format(),
        };
        let levels = if info.tile_columns.is_some() {
            // A per-axis grid is the one the image and tile size give.
            let layout = Layout::new(width as u64, height as u64, tile_size, border)?;
            if (layout.columns, layout.rows) != (columns, rows) {
                return Err(TilerError::Info {
                    path: path.clone(),
                    field: "tileColumns".into(),
                    message: format!(
                        "{columns} x {rows} pages, but a {width}x{height} image in {tile_size}-texel tiles (border {border}) has {} x {}",
                        layout.columns, layout.rows
                    ),
                });
            }
            layout.pack_levels()
        } else {
            // Older files: a square power-of-two grid, the image at its top-left.
            square_levels(&description, columns)
        };
        // The pack's metadata is the completed description.
        info.format_version = Some(FORMAT_VERSION);
        info.lod_count = Some(lod_count);
        info.border = Some(border);
        info.width = Some(description.width);
        info.height = Some(description.height);
        info.tile_format = Some(channels.tile_format().into());
        info.tile_type = Some(depth.tile_type().into());
        info.codec = Some(codec.name().into());
        Ok(TiledDir { info, description, levels, names, codec })
    }

    /// Tiles over all LODs.
    pub fn tile_total(&self) -> u64 {
        self.levels.iter().map(|l| l.tiles_w as u64 * l.tiles_h as u64).sum()
    }

    /// The texel layout of the tiles.
    pub fn layout(&self) -> PixelLayout {
        layout_of(&self.description)
    }
}

/// The texel layout a pack's description states.
pub(crate) fn layout_of(d: &Description) -> PixelLayout {
    PixelLayout::new(
        [Channels::Grey, Channels::GreyAlpha, Channels::Rgb, Channels::Rgba][d.channels as usize - 1],
        if d.sample_bytes == 2 { Depth::U16 } else { Depth::U8 },
    )
}

/// The codec `info.json` names, or else the one the tile files' extension implies.
pub(crate) fn codec_of(info: &InfoFile, extension: Option<String>) -> Option<Codec> {
    let name = info.codec.clone().or(extension).unwrap_or_default();
    let subsampling = info.subsampling.as_deref().and_then(Subsampling::from_name).unwrap_or(Subsampling::S420);
    let level = match info.png_compression.as_deref() {
        Some("default") => PngLevel::Default,
        Some("best") => PngLevel::Best,
        _ => PngLevel::Fast,
    };
    let zstd_level = info.zstd_level.unwrap_or(DEFAULT_ZSTD_LEVEL);
    let effort = info.bc7_effort.as_deref().and_then(Bc7Effort::from_name);
    match name.as_str() {
        "jpeg" | "jpg" => Some(Codec::Jpeg { quality: info.quality.unwrap_or(85), subsampling }),
        "png" => Some(Codec::Png { level }),
        "jxl" => {
            let quality = (info.lossless != Some(true)).then(|| info.quality.unwrap_or(DEFAULT_JXL_QUALITY));
            let effort = info.jxl_effort.and_then(|e| JxlEffort::new(e).ok());
            Some(Codec::Jxl { quality, effort: effort.unwrap_or(Codec::jxl_default_effort(quality)) })
        }
        // Never a file extension: these tiles are not files.
        _ if info.codec.is_none() => None,
        "raw" => Some(Codec::Raw),
        "zstd" => Some(Codec::Zstd { level: zstd_level, filter: RowFilter::None }),
        "zstd-delta" => Some(Codec::Zstd { level: zstd_level, filter: RowFilter::Delta }),
        "bc1" => Some(Codec::Bc1),
        "bc7" => Some(Codec::Bc7 { effort: effort.unwrap_or(DEFAULT_BC7_EFFORT) }),
        _ => None,
    }
}

/// The level table of an older directory: a square power-of-two grid of `tiles` x `tiles`
/// pages at LOD 0, halved at each level, the image (`ceil(size / 2^lod)` at each) at its
/// top-left.
pub(crate) fn square_levels(d: &Description, tiles: u32) -> Vec<Level> {
    (0..d.level_count)
        .map(|lod| {
            let shrink = |v: u32| ((u64::from(v) + (1u64 << lod) - 1) >> lod) as u32;
            Level::new(tiles >> lod, tiles >> lod, shrink(d.width), shrink(d.height))
        })
        .collect()
}
