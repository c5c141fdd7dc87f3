//! Resolving the output settings: command-line flags override an existing `info.json` in the
//! output directory (the thesis tool's way of configuring a run), which overrides defaults.
//! Members that contradict each other, the flags or the input are errors naming the member.

use std::path::Path;

use crate::background::Background;
use crate::codec::{Bc7Effort, Codec, PngLevel, Subsampling, ZSTD_LEVELS};
pub use crate::codec::{DEFAULT_BC7_EFFORT, DEFAULT_ZSTD_LEVEL};
use crate::error::{Result, TilerError};
use crate::job::SplitOptions;
use crate::layout::Layout;
use crate::pixel::{Channels, Depth, PixelLayout};
use crate::pyramid::filter::Filter;
pub use crate::tile_dir::filename::DEFAULT_FILENAME_STEM;
use crate::tile_dir::filename::FilenameFormat;
use crate::tile_dir::info::{BORDER_WHEN_ABSENT, FORMAT_VERSION, InfoFile};

pub const DEFAULT_TILE_SIZE: u32 = 128;
/// Border of `--layout vortex` tiles when neither the flag nor an `info.json` sets one: one
/// texel is what bilinear and trilinear filtering read across a page edge, so the runtime's
/// default filter shows no seams (border 0 does: docs/gpu-sampling.md).
pub const DEFAULT_BORDER: u32 = 1;
pub const DEFAULT_QUALITY: u8 = 85;

/// Which codec: `auto` picks JPEG for 8-bit grey or RGB and PNG for anything with alpha or 16 bits.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CodecChoice {
    /// JPEG for 8-bit grey or RGB, PNG with alpha or 16 bits.
    Auto,
    /// Lossy, 8-bit grey or RGB (--quality, --subsampling).
    Jpeg,
    /// Lossless, any layout (--png-compression).
    Png,
    /// Packs only: texels as a GPU uploads them, any layout.
    Raw,
    /// Packs only: raw texels compressed with zstd (--zstd-level).
    Zstd,
    /// Packs only: zstd of raw texels whose rows are left-delta filtered first.
    ZstdDelta,
    /// Packs only: BC1 blocks, opaque 8-bit RGB (tile size a multiple of 4).
    Bc1,
    /// Packs only: BC7 blocks, 8-bit RGB or RGBA (tile size a multiple of 4; --bc7-effort).
    Bc7,
}

impl CodecChoice {
    /// Every choice, in the order `--help` lists them.
    pub const ALL: [CodecChoice; 8] = [
        CodecChoice::Auto,
        CodecChoice::Jpeg,
        CodecChoice::Png,
        CodecChoice::Raw,
        CodecChoice::Zstd,
        CodecChoice::ZstdDelta,
        CodecChoice::Bc1,
        CodecChoice::Bc7,
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
            CodecChoice::Raw => "Packs only: texels as a GPU uploads them, any layout",
            CodecChoice::Zstd => "Packs only: raw texels compressed with zstd (--zstd-level)",
            CodecChoice::ZstdDelta => "Packs only: zstd of raw texels whose rows are left-delta filtered first",
            CodecChoice::Bc1 => "Packs only: BC1 blocks, opaque 8-bit RGB (tile size a multiple of 4)",
            CodecChoice::Bc7 => "Packs only: BC7 blocks, 8-bit RGB or RGBA (tile size a multiple of 4; --bc7-effort)",
        }
    }
}

/// What the command line asked for; `None` means "not given".
#[derive(Clone, Debug, Default)]
pub struct Requested {
    pub tile_size: Option<u32>,
    pub border: Option<u32>,
    pub codec: Option<CodecChoice>,
    pub quality: Option<u8>,
    pub subsampling: Option<Subsampling>,
    pub png_level: Option<PngLevel>,
    pub zstd_level: Option<i32>,
    pub bc7_effort: Option<Bc7Effort>,
    pub background: Option<Background>,
    pub flatten: bool,
    pub tile_depth: Option<Depth>,
    pub filename_format: Option<String>,
    pub filter: Option<Filter>,
    /// `--max-memory` (not an `info.json` member).
    pub max_memory: Option<u64>,
    /// `--reencode`: encode the source's stored JPEG tiles again rather than copy them.
    pub reencode: bool,
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
    if let (Some(filter), true) = (labels, matches!(codec, Codec::Jpeg { .. } | Codec::Bc1 | Codec::Bc7 { .. })) {
        return Err(TilerError::Options(format!(
            "--filter {filter} keeps label values exact, which --codec {} would blur; use png, raw, zstd or zstd-delta",
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
    let lossy = matches!(info_codec, Some(CodecChoice::Jpeg | CodecChoice::Bc1 | CodecChoice::Bc7));
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
pub fn changed_by_file(
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
pub fn check_grid(info_path: &Path, info: &InfoFile, req: &Requested, layout: &Layout) -> Result<()> {
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
            field_err("codec", format!("'{name}' is not a codec (jpeg, png, raw, zstd, zstd-delta, bc1, bc7)"))
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
        CodecChoice::Zstd => Codec::Zstd { level: zstd_level, delta: false },
        CodecChoice::ZstdDelta => Codec::Zstd { level: zstd_level, delta: true },
        CodecChoice::Bc1 => Codec::Bc1,
        CodecChoice::Bc7 => Codec::Bc7 {
            effort: req
                .bc7_effort
                .or(parse_member(info.bc7_effort.as_deref(), Bc7Effort::from_name, "bc7Effort", field_err)?)
                .unwrap_or(DEFAULT_BC7_EFFORT),
        },
    };
    match codec {
        Codec::Jpeg { quality, .. } if !(1..=100).contains(&quality) => {
            Err(TilerError::Options(format!("JPEG quality {quality} (--quality) is outside 1..=100")))
        }
        Codec::Zstd { level, .. } if !ZSTD_LEVELS.contains(&level) => Err(TilerError::Options(format!(
            "zstd level {level} (--zstd-level) is outside {}..={}",
            ZSTD_LEVELS.start(),
            ZSTD_LEVELS.end()
        ))),
        codec => Ok(codec),
    }
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
        subsampling: codec.subsampling,
        png_compression: codec.png_compression,
        zstd_level: codec.zstd_level,
        bc7_effort: codec.bc7_effort,
        filter: Some(opts.filter.name().into()),
        icc_profile: None,
    }
}

/// The `info.json` members that describe `codec` (`codec` and its settings); no others.
pub fn describe_codec(codec: Codec) -> InfoFile {
    let mut info = InfoFile { codec: Some(codec.name().into()), ..InfoFile::default() };
    match codec {
        Codec::Jpeg { quality, subsampling } => {
            (info.quality, info.subsampling) = (Some(quality), Some(subsampling.name().into()))
        }
        Codec::Png { level } => info.png_compression = Some(level.name().into()),
        Codec::Zstd { level, .. } => info.zstd_level = Some(level),
        Codec::Bc7 { effort } => info.bc7_effort = Some(effort.name().into()),
        Codec::Raw | Codec::Bc1 => {}
    }
    info
}
