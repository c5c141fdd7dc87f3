//! Resolving the output settings: command-line flags override an existing `info.json` in the
//! output directory (the thesis tool's way of configuring a run), which overrides defaults.
//! Members that contradict each other, the flags or the input are errors naming the member.

use std::path::Path;

use base64::Engine;

use crate::background::Background;
use crate::codec::{Bc7Effort, Codec, JxlEffort, PngLevel, RowFilter, Subsampling, ZSTD_LEVELS};
pub(crate) use crate::codec::{DEFAULT_BC7_EFFORT, DEFAULT_JXL_QUALITY, DEFAULT_ZSTD_LEVEL};
use crate::error::{Result, TilerError};
pub use crate::formats::tiles::filename::DEFAULT_FILENAME_STEM;
use crate::formats::tiles::filename::FilenameFormat;
use crate::formats::tiles::info::{BORDER_WHEN_ABSENT, FORMAT_VERSION, InfoFile};
use crate::job::SplitOptions;
use crate::layout::Layout;
use crate::limits::Limits;
use crate::pixel::{Channels, Depth, PixelLayout};
use crate::pyramid::filter::Filter;
use crate::source::ImageHeader;

pub(crate) const DEFAULT_TILE_SIZE: u32 = 128;
/// Border of `--layout vortex` tiles when neither the flag nor an `info.json` sets one: one
/// texel is what bilinear and trilinear filtering read across a page edge, so the runtime's
/// default filter shows no seams (border 0 does: docs/gpu-sampling.md).
pub(crate) const DEFAULT_BORDER: u32 = 1;
pub(crate) const DEFAULT_QUALITY: u8 = 85;

/// Which codec: `auto` picks JPEG for 8-bit grey or RGB and PNG for anything with alpha or 16 bits.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CodecChoice {
    /// JPEG for 8-bit grey or RGB, PNG with alpha or 16 bits.
    Auto,
    /// Lossy, 8-bit grey or RGB (--quality, --subsampling).
    Jpeg,
    /// Lossless, any layout (--png-compression).
    Png,
    /// Uncompressed texels, any layout: a pack's (as a GPU uploads them), a TIFF's tiles, a
    /// DICOM series' native frames.
    Raw,
    /// Packs only: raw texels compressed with zstd (--zstd-level).
    Zstd,
    /// Packs only: zstd of raw texels whose rows are left-delta filtered first.
    ZstdDelta,
    /// Packs only: BC1 blocks, opaque 8-bit RGB (tile size a multiple of 4).
    Bc1,
    /// Packs only: BC7 blocks, 8-bit RGB or RGBA (tile size a multiple of 4; --bc7-effort).
    Bc7,
    /// TIFF only: lossless zlib (Adobe Deflate), integer samples horizontally differenced.
    Deflate,
    /// TIFF only: lossless LZW (compression 5), integer samples horizontally differenced.
    Lzw,
    /// JPEG XL, any layout: lossy (--quality, mapped to a distance) or --lossless; --jxl-effort.
    Jxl,
}

impl CodecChoice {
    /// Every choice, in the order `--help` lists them.
    pub const ALL: [CodecChoice; 11] = [
        CodecChoice::Auto,
        CodecChoice::Jpeg,
        CodecChoice::Png,
        CodecChoice::Jxl,
        CodecChoice::Raw,
        CodecChoice::Zstd,
        CodecChoice::ZstdDelta,
        CodecChoice::Bc1,
        CodecChoice::Bc7,
        CodecChoice::Deflate,
        CodecChoice::Lzw,
    ];

    /// The name used on the command line (`--codec`) and in `info.json`.
    pub fn name(self) -> &'static str {
        match self {
            CodecChoice::Auto => "auto",
            CodecChoice::Jpeg => "jpeg",
            CodecChoice::Png => "png",
            CodecChoice::Raw => "raw",
            CodecChoice::Zstd => "zstd",
            CodecChoice::ZstdDelta => "zstd-delta",
            CodecChoice::Bc1 => "bc1",
            CodecChoice::Bc7 => "bc7",
            CodecChoice::Deflate => "deflate",
            CodecChoice::Lzw => "lzw",
            CodecChoice::Jxl => "jxl",
        }
    }

    /// The choice `name` names, if any.
    pub fn from_name(name: &str) -> Option<CodecChoice> {
        CodecChoice::ALL.into_iter().find(|c| c.name() == name)
    }

    /// One line on what the choice does (`--help` lists it).
    pub fn about(self) -> &'static str {
        match self {
            CodecChoice::Auto => "JPEG for 8-bit grey or RGB, PNG with alpha or 16 bits",
            CodecChoice::Jpeg => "Lossy, 8-bit grey or RGB (--quality, --subsampling)",
            CodecChoice::Png => "Lossless, any layout (--png-compression)",
            CodecChoice::Raw => {
                "Uncompressed texels, any layout: packs (as a GPU uploads them), TIFF tiles, DICOM native frames"
            }
            CodecChoice::Zstd => "Packs only: raw texels compressed with zstd (--zstd-level)",
            CodecChoice::ZstdDelta => "Packs only: zstd of raw texels whose rows are left-delta filtered first",
            CodecChoice::Bc1 => "Packs only: BC1 blocks, opaque 8-bit RGB (tile size a multiple of 4)",
            CodecChoice::Bc7 => "Packs only: BC7 blocks, 8-bit RGB or RGBA (tile size a multiple of 4; --bc7-effort)",
            CodecChoice::Deflate => "TIFF only (-o FILE.tif): lossless zlib, integer samples differenced first",
            CodecChoice::Lzw => "TIFF only (-o FILE.tif): lossless LZW, integer samples differenced first",
            CodecChoice::Jxl => {
                "JPEG XL, any layout: lossy at --quality (90 = distance 1.0), or --lossless; --jxl-effort. Tile directories, packs, Deep Zoom, IIIF, XYZ; copied JPEG tiles are recompressed losslessly"
            }
        }
    }
}

/// What the command line asked for; `None` means "not given".
#[derive(Clone, Debug, Default)]
pub struct Requested {
    /// `--tile-size`: side of a stored tile in texels, borders included.
    pub tile_size: Option<u32>,
    /// `--border`: texels each tile repeats from its neighbours on every side.
    pub border: Option<u32>,
    /// `--codec`.
    pub codec: Option<CodecChoice>,
    /// `--quality`: JPEG quality, 1 to 100.
    pub quality: Option<u8>,
    /// `--subsampling`: JPEG chroma subsampling.
    pub subsampling: Option<Subsampling>,
    /// `--png-compression`.
    pub png_level: Option<PngLevel>,
    /// `--zstd-level`: 1 to 22, for zstd and zstd-delta tiles.
    pub zstd_level: Option<i32>,
    /// `--bc7-effort`.
    pub bc7_effort: Option<Bc7Effort>,
    /// `--lossless`: JPEG XL tiles that keep every sample.
    pub lossless: bool,
    /// `--jxl-effort`: 1 to 9.
    pub jxl_effort: Option<u8>,
    /// `--background`: what fills the padding past the image's edge.
    pub background: Option<Background>,
    /// `--flatten`: composite alpha over the background, so RGBA can be stored as JPEG.
    pub flatten: bool,
    /// `--tile-type`: the stored samples' depth, where it may differ from the source's.
    pub tile_depth: Option<Depth>,
    /// `--filename-format`: the tile files' names (`info.json`'s `filenameFormat`).
    pub filename_format: Option<String>,
    /// `--filter`: how LODs 1 and up are made.
    pub filter: Option<Filter>,
    /// `--max-memory` (not an `info.json` member).
    pub max_memory: Option<u64>,
    /// `--reencode`: encode the source's stored JPEG tiles again rather than copy them.
    pub reencode: bool,
    /// `--fast-shrink`: the first reduced level from the stored JPEG tiles decoded at half size.
    pub fast_shrink: bool,
}

/// Combines flags, an existing `info.json` (at `info_path`) and the source into settings.
pub fn resolve(
    req: &Requested,
    existing: Option<(&Path, &InfoFile)>,
    source: PixelLayout,
) -> Result<(SplitOptions, FilenameFormat)> {
    let empty = InfoFile::default();
    let (info_path, info) = existing.unwrap_or((Path::new("info.json"), &empty));
    let field_err =
        |field: &str, message: String| TilerError::Info { path: info_path.to_path_buf(), field: field.into(), message };

    let tile_size = req.tile_size.or(info.tile_size).unwrap_or(DEFAULT_TILE_SIZE);
    // An existing info.json without `border` is the thesis's (its tiles have none): its grid
    // members and names describe border-0 tiles, as a reader takes them.
    let border = req.border.or(info.border).unwrap_or(match existing {
        Some(_) => BORDER_WHEN_ABSENT,
        None => DEFAULT_BORDER,
    });
    let names_given = req.filename_format.clone().or(info.filename_format.clone());
    let ext = names_given.as_deref().and_then(|f| FilenameFormat::parse(f, 3).ok()).and_then(|f| f.extension());

    // Codec: flag, then info.json's codec, then the file extension, then auto.
    let info_codec = info_codec(info, &field_err)?;
    let ext_codec = match ext.as_deref() {
        Some("jpg" | "jpeg") => Some(CodecChoice::Jpeg),
        Some("png") => Some(CodecChoice::Png),
        Some("jxl") => Some(CodecChoice::Jxl),
        _ => None,
    };
    let mut choice = req.codec.or(info_codec).or(ext_codec).unwrap_or(CodecChoice::Auto);
    // info.json's tileFormat/tileType say what the tiles must hold.
    let want_channels = match info.tile_format.as_deref() {
        None => None,
        Some(f) => Some(Channels::from_tile_format(f).ok_or_else(|| {
            field_err("tileFormat", format!("'{f}' is not supported (luminance, luminanceAlpha, rgb, rgba)"))
        })?),
    };
    let info_depth = match info.tile_type.as_deref() {
        None => None,
        Some(t) => Some(Depth::from_tile_type(t).ok_or_else(|| {
            field_err(
                "tileType",
                format!("'{t}' is not supported (unsignedByte, unsignedShort, unsignedInt, float, half)"),
            )
        })?),
    };
    let tile_depth = req.tile_depth.or(info_depth);
    refuse_lossy_defaults(req, info, source, want_channels, info_depth, info_codec, &field_err)?;
    let flatten = req.flatten;
    // A label image's values name objects: a lossy codec would invent labels as a mean does.
    let labels = match req.filter {
        Some(f) => Some(f),
        None => parse_member(info.filter.as_deref(), Filter::from_name, "filter", &field_err)?,
    }
    .filter(|f| f.is_label());
    if choice == CodecChoice::Auto {
        let lossless = (source.channels.has_alpha() && !flatten)
            || tile_depth.unwrap_or(source.depth) != Depth::U8
            || labels.is_some();
        choice = if lossless { CodecChoice::Png } else { CodecChoice::Jpeg };
    }
    let codec = build_codec(choice, req, info, &field_err)?;
    if let (Some(filter), true) = (labels, codec.is_lossy()) {
        return Err(TilerError::Options(format!(
            "--filter {filter} keeps label values exact, which --codec {} would blur; use png, raw, zstd, zstd-delta or jxl --lossless",
            codec.name()
        )));
    }
    codec.check_tile_size(tile_size)?;
    if let (Some(e), false) = (&ext, ext_codec.is_none_or(|c| c == choice)) {
        let message = format!("ends in .{e} but the codec is {}", codec.name());
        return Err(match req.filename_format {
            Some(_) => TilerError::Options(format!("the filename format {message}")),
            // The names came from the previous run's info.json; a flag replaces them.
            None => field_err(
                "filenameFormat",
                format!(
                    "{message}; pass --filename-format with a .{} pattern, or choose another output",
                    codec.extension()
                ),
            ),
        });
    }
    let names = match names_given {
        Some(f) => f,
        None => format!("{DEFAULT_FILENAME_STEM}.{}", codec.extension()),
    };
    let names = FilenameFormat::parse(&names, 3).map_err(|m| TilerError::Options(format!("filename format: {m}")))?;

    let opts = SplitOptions {
        tile_size,
        border,
        codec,
        background: match (req.background, info.background.as_deref()) {
            (Some(b), _) => b,
            (None, Some(b)) => b.parse().map_err(|m| field_err("background", m))?,
            (None, None) => Background::Edge,
        },
        flatten,
        tile_depth,
        filter: match req.filter {
            Some(f) => f,
            None => parse_member(info.filter.as_deref(), Filter::from_name, "filter", &field_err)?
                .unwrap_or(Filter::default_for(source.depth)),
        },
        max_memory: req.max_memory.unwrap_or(crate::limits::DEFAULT_MEMORY),
        down_to_one_texel: false,
        // A quality or subsampling asked for on the command line is one the copies would not
        // have (one from an earlier run's info.json is only that run's default).
        reencode: match (req.reencode, req.quality, req.subsampling) {
            (true, _, _) => Some("--reencode"),
            (_, Some(_), _) => Some("--quality"),
            (_, _, Some(_)) => Some("--subsampling"),
            _ => None,
        },
        fast_shrink: req.fast_shrink,
    };
    opts.filter.check(source).map_err(TilerError::Options)?;
    let stored = codec.stored_layout(source, flatten, tile_depth)?;
    if let Some(want) = want_channels.filter(|c| *c != stored.channels) {
        return Err(field_err(
            "tileFormat",
            format!(
                "is {} but {source} tiles stored as {} would be {}",
                want.tile_format(),
                codec.name(),
                stored.channels.tile_format()
            ),
        ));
    }
    Ok((opts, names))
}

/// What a `--layout vortex` run writes: a tile directory holds image files; a pack holds the
/// tiles of any codec.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Destination {
    /// A directory of image files and `info.json` (JPEG or PNG tiles only).
    TileDir,
    /// One pack file (`.vtpk`), whose tiles may be of any codec.
    Pack,
}

/// A `--layout vortex` run (a tile directory or a pack) as the user asked for it, checked
/// against the source and a previous output's `info.json` before the first tile is cut: each
/// setting is the flag's where one is given, else the previous `info.json`'s (the original
/// tool's way of configuring a run), else the default ([`resolve`]).
#[derive(Clone, Debug)]
pub struct Plan {
    /// What the run is asked: tile size, border, codec, filter, background, memory.
    pub opts: SplitOptions,
    /// The tile files' names (a tile directory's; a pack keeps it in its `info.json`).
    pub names: FilenameFormat,
    /// The page grid the source is cut into.
    pub layout: Layout,
    /// The texels the tiles hold, after flattening and the tile depth.
    pub stored: PixelLayout,
    /// The output's `info.json`.
    pub info: InfoFile,
    /// `name value` of each member the previous `info.json` changed from what the flags alone
    /// give; empty without one.
    pub changed: Vec<String>,
}

impl Plan {
    /// Plans a run of `source` into `destination` from the flags `asked` and the `info.json`
    /// of the output it replaces (`existing`, with its path), within `limits`; `icc` is the
    /// source's colour profile where the run keeps it (`--keep-icc`).
    pub fn new(
        asked: &Requested,
        existing: Option<(&Path, &InfoFile)>,
        source: &ImageHeader,
        destination: Destination,
        limits: &Limits,
        icc: Option<&[u8]>,
    ) -> Result<Plan> {
        let (opts, names) = resolve(asked, existing, source.layout)?;
        if destination == Destination::TileDir && !opts.codec.writes_files() {
            return Err(TilerError::Options(format!(
                "--codec {} writes packs only (its tiles are not image files): write --pack FILE instead of --output, or use --codec png for lossless tile files",
                opts.codec.name()
            )));
        }
        let layout = opts.layout(source.width, source.height)?;
        if let Some((path, info)) = existing {
            check_grid(path, info, asked, &layout)?;
        }
        let stored = opts.codec.stored_layout(source.layout, opts.flatten, opts.tile_depth)?;
        limits.check_pyramid(&layout, destination == Destination::Pack)?;
        let mut info = describe(&layout, stored, &opts, &names);
        info.icc_profile = icc.map(|icc| base64::engine::general_purpose::STANDARD.encode(icc));
        let changed = match existing {
            Some(_) => changed_by_file(asked, source.layout, source.width, source.height, &info),
            None => Vec::new(),
        };
        Ok(Plan { opts, names, layout, stored, info, changed })
    }
}

/// An existing `info.json` sets this run's defaults, but never ones that would lose data the
/// source holds: its alpha (`tileFormat` without it), its 16 bits (`tileType` unsignedByte) or
/// its exactness (a lossy `codec` where the source's default is lossless). Those are errors
/// naming the member and the flag that asks for the loss explicitly.
fn refuse_lossy_defaults(
    req: &Requested,
    info: &InfoFile,
    source: PixelLayout,
    want_channels: Option<Channels>,
    info_depth: Option<Depth>,
    info_codec: Option<CodecChoice>,
    field_err: &dyn Fn(&str, String) -> TilerError,
) -> Result<()> {
    let has_alpha = source.channels.has_alpha();
    if has_alpha && !req.flatten && want_channels.is_some_and(|c| !c.has_alpha()) {
        return Err(field_err(
            "tileFormat",
            format!(
                "is {} but the source is {source}: its alpha would be dropped; pass --flatten to composite it away, or choose another output",
                want_channels.map_or("", |c| c.tile_format())
            ),
        ));
    }
    if source.depth == Depth::U16 && req.tile_depth.is_none() && info_depth == Some(Depth::U8) {
        return Err(field_err(
            "tileType",
            format!(
                "is unsignedByte but the source is {source}: its 16 bits would be cut to 8; pass --tile-type unsignedByte to do so, or choose another output"
            ),
        ));
    }
    let lossless_source = (has_alpha && !req.flatten) || source.depth != Depth::U8;
    let lossy = match info_codec {
        Some(CodecChoice::Jpeg | CodecChoice::Bc1 | CodecChoice::Bc7) => true,
        Some(CodecChoice::Jxl) => info.lossless != Some(true),
        _ => false,
    };
    if lossless_source && lossy && req.codec.is_none() {
        return Err(field_err(
            "codec",
            format!(
                "is {} but the source is {source}, stored losslessly by default; pass --codec {} to use it anyway, or choose another output",
                info.codec.as_deref().unwrap_or_default(),
                info.codec.as_deref().unwrap_or_default()
            ),
        ));
    }
    Ok(())
}

/// The members of `this_run`'s description that an existing `info.json` changed: what the
/// flags alone would have given differs. `name value` each, for the line that says so; every
/// settable member when the flags alone give no valid run.
pub(crate) fn changed_by_file(
    req: &Requested,
    source: PixelLayout,
    width: u32,
    height: u32,
    this_run: &InfoFile,
) -> Vec<String> {
    // Derived from the grid, which tileSize and border already show.
    const DERIVED: [&str; 7] = ["formatVersion", "width", "height", "tileCount", "tileColumns", "tileRows", "lodCount"];
    let without_file = resolve(req, None, source).and_then(|(opts, names)| {
        let layout = Layout::new(width as u64, height as u64, opts.tile_size, opts.border)?;
        let stored = opts.codec.stored_layout(source, opts.flatten, opts.tile_depth)?;
        Ok(describe(&layout, stored, &opts, &names))
    });
    let as_map = |info: &InfoFile| match serde_json::to_value(info) {
        Ok(serde_json::Value::Object(map)) => map,
        _ => serde_json::Map::new(),
    };
    let without = without_file.as_ref().map(as_map).unwrap_or_default();
    as_map(this_run)
        .into_iter()
        .filter(|(name, value)| !DERIVED.contains(&name.as_str()) && without.get(name) != Some(value))
        .map(|(name, value)| match value {
            serde_json::Value::String(v) => format!("{name} {v}"),
            v => format!("{name} {v}"),
        })
        .collect()
}

/// Checks an existing `info.json`'s derived members against what this run will produce.
pub(crate) fn check_grid(info_path: &Path, info: &InfoFile, req: &Requested, layout: &Layout) -> Result<()> {
    // Flags that change the grid make the old counts moot.
    if req.tile_size.is_some() || req.border.is_some() {
        return Ok(());
    }
    // An older file's square `tileCount` is the side of the smallest power-of-two square
    // grid holding this one; it has one LOD per halving, as this grid does.
    let square_side = 1 << (layout.lod_count - 1);
    for (field, old, new) in [
        ("tileColumns", info.tile_columns, layout.columns),
        ("tileRows", info.tile_rows, layout.rows),
        ("tileCount", info.tile_count, square_side),
        ("lodCount", info.lod_count, layout.lod_count),
    ] {
        if let Some(old) = old.filter(|o| *o != new) {
            return Err(TilerError::Info {
                path: info_path.to_path_buf(),
                field: field.into(),
                message: format!(
                    "is {old} but this {}x{} image in {}-texel tiles (border {}) needs {new}; remove the old info.json or choose another output",
                    layout.width, layout.height, layout.tile_size, layout.border
                ),
            });
        }
    }
    Ok(())
}

/// `info.json`'s `codec`, if any.
fn info_codec(info: &InfoFile, field_err: &dyn Fn(&str, String) -> TilerError) -> Result<Option<CodecChoice>> {
    match info.codec.as_deref() {
        None | Some("auto") => Ok(None),
        Some(name) => CodecChoice::from_name(name).map(Some).ok_or_else(|| {
            field_err("codec", format!("'{name}' is not a codec (jpeg, png, jxl, raw, zstd, zstd-delta, bc1, bc7)"))
        }),
    }
}

/// The codec `choice` (not `auto`) with its settings: flags, then `info.json`, then defaults.
fn build_codec(
    choice: CodecChoice,
    req: &Requested,
    info: &InfoFile,
    field_err: &dyn Fn(&str, String) -> TilerError,
) -> Result<Codec> {
    let zstd_level = req.zstd_level.or(info.zstd_level).unwrap_or(DEFAULT_ZSTD_LEVEL);
    refuse_jxl_flags(choice, req)?;
    let codec = match choice {
        CodecChoice::Jpeg => Codec::Jpeg {
            quality: req.quality.or(info.quality).unwrap_or(DEFAULT_QUALITY),
            subsampling: req
                .subsampling
                .or(parse_member(info.subsampling.as_deref(), Subsampling::from_name, "subsampling", field_err)?)
                .unwrap_or(Subsampling::S420),
        },
        CodecChoice::Auto | CodecChoice::Png => Codec::Png {
            level: req
                .png_level
                .or(parse_member(info.png_compression.as_deref(), PngLevel::from_name, "pngCompression", field_err)?)
                .unwrap_or(PngLevel::Fast),
        },
        CodecChoice::Raw => Codec::Raw,
        CodecChoice::Zstd => Codec::Zstd { level: zstd_level, filter: RowFilter::None },
        CodecChoice::ZstdDelta => Codec::Zstd { level: zstd_level, filter: RowFilter::Delta },
        CodecChoice::Bc1 => Codec::Bc1,
        CodecChoice::Deflate | CodecChoice::Lzw => {
            return Err(TilerError::Options(format!(
                "--codec {} compresses the tiles of a TIFF (-o FILE.tif or FILE.ome.tif); tile files and packs take png, raw or zstd",
                choice.name()
            )));
        }
        CodecChoice::Jxl => {
            // `--lossless` on the command line wins over a lossy info.json, `--quality` over
            // a lossless one.
            let lossless = req.lossless || (req.quality.is_none() && info.lossless == Some(true));
            let quality = (!lossless).then(|| req.quality.or(info.quality).unwrap_or(DEFAULT_JXL_QUALITY));
            let effort = match req.jxl_effort.or(info.jxl_effort) {
                Some(e) => JxlEffort::new(e).map_err(|e| TilerError::Options(format!("{e} (--jxl-effort)")))?,
                None => Codec::jxl_default_effort(quality),
            };
            Codec::Jxl { quality, effort }
        }
        CodecChoice::Bc7 => Codec::Bc7 {
            effort: req
                .bc7_effort
                .or(parse_member(info.bc7_effort.as_deref(), Bc7Effort::from_name, "bc7Effort", field_err)?)
                .unwrap_or(DEFAULT_BC7_EFFORT),
        },
    };
    match codec {
        Codec::Jpeg { quality, .. } | Codec::Jxl { quality: Some(quality), .. } if !(1..=100).contains(&quality) => {
            Err(TilerError::Options(format!("quality {quality} (--quality) is outside 1..=100")))
        }
        Codec::Zstd { level, .. } if !ZSTD_LEVELS.contains(&level) => Err(TilerError::Options(format!(
            "zstd level {level} (--zstd-level) is outside {}..={}",
            ZSTD_LEVELS.start(),
            ZSTD_LEVELS.end()
        ))),
        codec => Ok(codec),
    }
}

/// JPEG XL's flags with another codec, and `--lossless` with `--quality`, are refused: each
/// would be ignored without a word.
fn refuse_jxl_flags(choice: CodecChoice, req: &Requested) -> Result<()> {
    if choice != CodecChoice::Jxl {
        let flag = match (req.lossless, req.jxl_effort) {
            (true, _) => "--lossless",
            (false, Some(_)) => "--jxl-effort",
            (false, None) => return Ok(()),
        };
        let already = match choice {
            CodecChoice::Png | CodecChoice::Raw | CodecChoice::Zstd | CodecChoice::ZstdDelta => {
                format!(" (--codec {} is lossless already)", choice.name())
            }
            _ => String::new(),
        };
        return Err(TilerError::Options(format!(
            "{flag} is JPEG XL's: add --codec jxl, or leave {flag} out for --codec {}{already}",
            choice.name()
        )));
    }
    if req.lossless && req.quality.is_some() {
        return Err(TilerError::Options(
            "--lossless keeps every sample, so --quality has nothing to set: give one or the other".into(),
        ));
    }
    if req.subsampling.is_some() {
        return Err(TilerError::Options(
            "--subsampling is JPEG's; JPEG XL tiles code colour at full resolution".into(),
        ));
    }
    Ok(())
}

/// The codec to re-encode tiles of `source` layout with, for `pack`: the flags in `req` over
/// the tiled directory's `info.json` (at `info_path`), whose codec is the default.
pub fn resolve_codec(req: &Requested, info_path: &Path, info: &InfoFile, source: PixelLayout) -> Result<Codec> {
    let field_err =
        |field: &str, message: String| TilerError::Info { path: info_path.to_path_buf(), field: field.into(), message };
    let mut choice = req.codec.or(info_codec(info, &field_err)?).unwrap_or(CodecChoice::Auto);
    if choice == CodecChoice::Auto {
        let lossless = source.channels.has_alpha() || source.depth != Depth::U8;
        choice = if lossless { CodecChoice::Png } else { CodecChoice::Jpeg };
    }
    // Settings of the directory's own codec apply only to that codec.
    let same = info_codec(info, &field_err)? == Some(choice);
    let info_settings = if same { info.clone() } else { InfoFile::default() };
    let codec = build_codec(choice, req, &info_settings, &field_err)?;
    codec.stored_layout(source, false, None)?;
    if let Some(side) = info.tile_size {
        codec.check_tile_size(side)?;
    }
    Ok(codec)
}

/// The value an `info.json` member names (`from_name` of its type), if the member is present.
fn parse_member<V>(
    value: Option<&str>,
    from_name: fn(&str) -> Option<V>,
    field: &str,
    err: &dyn Fn(&str, String) -> TilerError,
) -> Result<Option<V>> {
    value.map(|v| from_name(v).ok_or_else(|| err(field, format!("'{v}' is not a valid value")))).transpose()
}

/// The `info.json` describing a finished run.
pub fn describe(l: &Layout, stored: PixelLayout, opts: &SplitOptions, names: &FilenameFormat) -> InfoFile {
    let codec = describe_codec(opts.codec);
    InfoFile {
        format_version: Some(FORMAT_VERSION),
        tile_size: Some(l.tile_size),
        tile_count: l.square_tile_count(),
        tile_columns: Some(l.columns),
        tile_rows: Some(l.rows),
        lod_count: Some(l.lod_count),
        tile_format: Some(stored.channels.tile_format().into()),
        tile_type: Some(stored.depth.tile_type().into()),
        filename_format: Some(names.as_str().into()),
        border: Some(l.border),
        width: Some(l.width),
        height: Some(l.height),
        background: Some(opts.background.to_string()),
        codec: codec.codec,
        quality: codec.quality,
        lossless: codec.lossless,
        jxl_effort: codec.jxl_effort,
        subsampling: codec.subsampling,
        png_compression: codec.png_compression,
        zstd_level: codec.zstd_level,
        bc7_effort: codec.bc7_effort,
        filter: Some(opts.filter.name().into()),
        icc_profile: None,
    }
}

/// The `info.json` members that describe `codec` (`codec` and its settings); no others.
pub(crate) fn describe_codec(codec: Codec) -> InfoFile {
    let mut info = InfoFile { codec: Some(codec.name().into()), ..InfoFile::default() };
    match codec {
        Codec::Jpeg { quality, subsampling } => {
            (info.quality, info.subsampling) = (Some(quality), Some(subsampling.name().into()))
        }
        Codec::Png { level } => info.png_compression = Some(level.name().into()),
        Codec::Zstd { level, .. } => info.zstd_level = Some(level),
        Codec::Bc7 { effort } => info.bc7_effort = Some(effort.name().into()),
        Codec::Jxl { quality, effort } => {
            info.quality = quality;
            info.lossless = quality.is_none().then_some(true);
            info.jxl_effort = Some(effort.get());
        }
        Codec::Raw | Codec::Bc1 | Codec::Deflate { .. } | Codec::Lzw { .. } => {}
    }
    info
}

#[cfg(test)]
mod tests {
    use serde_json::{Value, json};

    use super::*;

    /// A 1000x600 source of `channels` at `depth`.
    fn header(channels: Channels, depth: Depth) -> ImageHeader {
        ImageHeader { width: 1000, height: 600, layout: PixelLayout::new(channels, depth) }
    }

    /// The plan for `flags` over a previous `info.json` holding `previous` (none where `None`).
    fn plan(flags: &Requested, previous: Option<Value>, source: ImageHeader, to: Destination) -> Result<Plan> {
        let file: Option<InfoFile> = previous.map(|v| serde_json::from_value(v).expect("an info.json"));
        let at = Path::new("out/info.json");
        Plan::new(flags, file.as_ref().map(|f| (at, f)), &source, to, &Limits::default(), None)
    }

    /// Each row is one rule: the flags, a previous `info.json` (or none), and the member of the
    /// new `info.json` they decide. The expected values are written out, not the library's
    /// constants, so that a changed default fails here (docs/info-json.md lists them).
    #[test]
    fn a_flag_wins_over_info_json_which_wins_over_the_default() {
        let none = Requested::default;
        let cases: Vec<(&str, Requested, Option<Value>, &str, Value)> = vec![
            ("tile size by default", none(), None, "tileSize", json!(128)),
            ("tile size from info.json", none(), Some(json!({"tileSize": 256})), "tileSize", json!(256)),
            (
                "tile size: the flag over info.json",
                Requested { tile_size: Some(64), ..none() },
                Some(json!({"tileSize": 256})),
                "tileSize",
                json!(64),
            ),
            ("border by default", none(), None, "border", json!(1)),
            ("border of an info.json without one (the thesis's)", none(), Some(json!({})), "border", json!(0)),
            ("border from info.json", none(), Some(json!({"border": 2})), "border", json!(2)),
            (
                "border: the flag over info.json",
                Requested { border: Some(3), ..none() },
                Some(json!({"border": 2})),
                "border",
                json!(3),
            ),
            ("codec by default for 8-bit RGB", none(), None, "codec", json!("jpeg")),
            ("codec from info.json", none(), Some(json!({"codec": "png"})), "codec", json!("png")),
            (
                "codec from info.json's file names",
                none(),
                Some(json!({"filenameFormat": "t%1$d_%2$d_%3$d.png"})),
                "codec",
                json!("png"),
            ),
            (
                "codec: info.json's codec over its file names",
                none(),
                Some(json!({"codec": "zstd", "filenameFormat": "t%1$d_%2$d_%3$d.bin"})),
                "codec",
                json!("zstd"),
            ),
            (
                "codec: the flag over info.json",
                Requested { codec: Some(CodecChoice::Zstd), ..none() },
                Some(json!({"codec": "png"})),
                "codec",
                json!("zstd"),
            ),
            ("quality by default", none(), None, "quality", json!(85)),
            ("quality from info.json", none(), Some(json!({"quality": 70})), "quality", json!(70)),
            (
                "quality: the flag over info.json",
                Requested { quality: Some(90), ..none() },
                Some(json!({"quality": 70})),
                "quality",
                json!(90),
            ),
            (
                "zstd level by default",
                Requested { codec: Some(CodecChoice::Zstd), ..none() },
                None,
                "zstdLevel",
                json!(3),
            ),
            (
                "zstd level from info.json",
                Requested { codec: Some(CodecChoice::Zstd), ..none() },
                Some(json!({"zstdLevel": 9})),
                "zstdLevel",
                json!(9),
            ),
            (
                "zstd level: the flag over info.json",
                Requested { codec: Some(CodecChoice::Zstd), zstd_level: Some(5), ..none() },
                Some(json!({"zstdLevel": 9})),
                "zstdLevel",
                json!(5),
            ),
            ("filter by default for 8 bits", none(), None, "filter", json!("linear-premultiplied")),
            ("filter from info.json", none(), Some(json!({"filter": "lanczos3"})), "filter", json!("lanczos3")),
            (
                "filter: the flag over info.json",
                Requested { filter: Some(Filter::Box), ..none() },
                Some(json!({"filter": "lanczos3"})),
                "filter",
                json!("box"),
            ),
            ("background by default", none(), None, "background", json!("edge")),
            (
                "background from info.json",
                none(),
                Some(json!({"background": "#102030"})),
                "background",
                json!("#102030"),
            ),
            (
                "background: the flag over info.json",
                Requested { background: Some(Background::Colour([1, 2, 3, 255])), ..none() },
                Some(json!({"background": "#102030"})),
                "background",
                json!("#010203"),
            ),
            ("names by default", none(), None, "filenameFormat", json!("lod%1$02s-x%2$04s-y%3$04s.jpg")),
            (
                "names from info.json",
                none(),
                Some(json!({"filenameFormat": "t%1$d_%2$d_%3$d.jpg"})),
                "filenameFormat",
                json!("t%1$d_%2$d_%3$d.jpg"),
            ),
            (
                "names: the flag over info.json",
                Requested { filename_format: Some("%1$d/%2$d/%3$d.jpg".into()), ..none() },
                Some(json!({"filenameFormat": "t%1$d_%2$d_%3$d.jpg"})),
                "filenameFormat",
                json!("%1$d/%2$d/%3$d.jpg"),
            ),
        ];
        for (rule, flags, previous, member, want) in cases {
            let plan = plan(&flags, previous, header(Channels::Rgb, Depth::U8), Destination::Pack)
                .unwrap_or_else(|e| panic!("{rule}: {e}"));
            let info = serde_json::to_value(&plan.info).expect("info.json as JSON");
            assert_eq!(info[member], want, "{rule}");
        }
    }

    /// The same rules for JPEG XL tiles, in a tile directory (packs do not hold them yet).
    #[test]
    fn jxl_settings_come_from_flags_then_info_json_then_defaults() {
        let none = Requested::default;
        let jxl = || Requested { codec: Some(CodecChoice::Jxl), ..none() };
        let cases: Vec<(&str, Requested, Option<Value>, &str, Value)> = vec![
            ("jxl: quality 90 by default", jxl(), None, "quality", json!(90)),
            ("jxl: lossy effort 5 by default", jxl(), None, "jxlEffort", json!(5)),
            ("jxl: lossless effort 3 by default", Requested { lossless: true, ..jxl() }, None, "jxlEffort", json!(3)),
            (
                "jxl: lossless from info.json",
                jxl(),
                Some(json!({"codec": "jxl", "lossless": true})),
                "lossless",
                json!(true),
            ),
            (
                "jxl: --quality over a lossless info.json",
                Requested { quality: Some(70), ..jxl() },
                Some(json!({"codec": "jxl", "lossless": true})),
                "quality",
                json!(70),
            ),
            (
                "jxl: codec from the file names",
                none(),
                Some(json!({"filenameFormat": "%1$d/%2$d_%3$d.jxl"})),
                "codec",
                json!("jxl"),
            ),
        ];
        for (rule, flags, previous, member, want) in cases {
            let plan = plan(&flags, previous, header(Channels::Rgb, Depth::U8), Destination::TileDir)
                .unwrap_or_else(|e| panic!("{rule}: {e}"));
            let info = serde_json::to_value(&plan.info).expect("info.json as JSON");
            assert_eq!(info[member], want, "{rule}");
        }
        let pack = plan(&jxl(), None, header(Channels::Rgb, Depth::U8), Destination::Pack).unwrap();
        assert_eq!(serde_json::to_value(&pack.info).unwrap()["codec"], json!("jxl"));
    }

    #[test]
    fn the_source_decides_what_neither_flag_nor_info_json_does() {
        // The codec is asked for only where the source's own default (png) cannot hold it.
        let cases = [
            ("8-bit grey", Channels::Grey, Depth::U8, None, "jpeg", "linear-premultiplied"),
            ("8-bit RGBA", Channels::Rgba, Depth::U8, None, "png", "linear-premultiplied"),
            ("16-bit grey", Channels::Grey, Depth::U16, None, "png", "linear-premultiplied"),
            ("float grey in raw tiles", Channels::Grey, Depth::F32, Some(CodecChoice::Raw), "raw", "box"),
        ];
        for (what, channels, depth, codec_flag, codec, filter) in cases {
            let flags = Requested { codec: codec_flag, ..Requested::default() };
            let plan = plan(&flags, None, header(channels, depth), Destination::Pack).expect(what);
            assert_eq!((plan.opts.codec.name(), plan.opts.filter.name()), (codec, filter), "{what}");
        }
    }

    #[test]
    fn the_plan_says_what_info_json_changed_and_refuses_what_a_destination_cannot_hold() {
        let source = header(Channels::Rgb, Depth::U8);
        let changed =
            plan(&Requested::default(), Some(json!({"tileSize": 256, "quality": 70})), source, Destination::Pack)
                .expect("a plan")
                .changed;
        // An info.json without a border is the thesis's, whose tiles have none.
        assert_eq!(changed, ["border 0", "quality 70", "tileSize 256"]);
        let flagged = Requested { tile_size: Some(256), ..Requested::default() };
        let plan_of_flags =
            plan(&flagged, Some(json!({"tileSize": 256, "border": 1})), source, Destination::Pack).expect("a plan");
        assert!(plan_of_flags.changed.is_empty(), "{:?}", plan_of_flags.changed);
        assert!(plan(&Requested::default(), None, source, Destination::Pack).expect("a plan").changed.is_empty());

        let raw = Requested { codec: Some(CodecChoice::Raw), ..Requested::default() };
        assert!(plan(&raw, None, source, Destination::Pack).is_ok());
        let err = plan(&raw, None, source, Destination::TileDir).expect_err("raw tiles are not image files");
        assert!(matches!(&err, TilerError::Options(m) if m.starts_with("--codec raw writes packs only")), "{err}");
        let lossy_over_16 = plan(
            &Requested::default(),
            Some(json!({"codec": "jpeg"})),
            header(Channels::Grey, Depth::U16),
            Destination::Pack,
        );
        assert!(matches!(&lossy_over_16, Err(TilerError::Info { field, .. }) if field == "codec"), "{lossy_over_16:?}");
    }
}
