//! `convert`: an already-tiled input re-tiled through the same pipeline as `split`.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Result, bail};
use vortex_tiler::background::Background;
use vortex_tiler::error::ShowPath;
use vortex_tiler::formats::pack::PackInput;
use vortex_tiler::formats::tiles::{NamedDir, SplitOutput};
use vortex_tiler::formats::viewer::dzi::DeepZoom;
use vortex_tiler::formats::viewer::iiif::Iiif;
use vortex_tiler::formats::viewer::xyz::{Order, Xyz};
use vortex_tiler::formats::viewer::{is_iiif_dir, is_zip, open_zip};
use vortex_tiler::limits::Limits;
use vortex_tiler::pixel::{Depth, PixelLayout};
use vortex_tiler::source::tiled::{TileGrid, TiledSource, check_tiles_found};
use vortex_tiler::source::{self, Streamed};

use super::split::{OutputArgs, tile};
use vortex_tiler::limits::Budget;

/// How the input's tiles are laid out on disk.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum InputLayout {
    /// Decide from the input: a .dzi descriptor, a .zip archive (what is inside), a directory
    /// with a IIIF info.json or with ours, a pack file, or (with --filename-format) a directory
    /// of named tiles.
    Auto,
    /// Google tiles as z/y/x.<ext> (vips dzsave --layout google); the highest z is read.
    Google,
    /// XYZ web-map tiles as z/x/y.<ext>; the highest z is read.
    Xyz,
}

impl InputLayout {
    /// The tile order the flag asks for, if it asks for one.
    fn order(self) -> Option<Order> {
        match self {
            InputLayout::Auto => None,
            InputLayout::Google => Some(Order::Zyx),
            InputLayout::Xyz => Some(Order::Zxy),
        }
    }
}

#[derive(clap::Args, Debug)]
pub struct ConvertArgs {
    /// The tiled input: a directory of tiles, this tool's split output (info.json + tiles), a
    /// pack (.vtpk), a Deep Zoom descriptor (.dzi, e.g. from vips dzsave), a IIIF Image API 2
    /// or 3 directory (its info.json, vips dzsave --layout iiif|iiif3), a zip archive of one of
    /// those or of z/y/x tiles (vips dzsave NAME.zip), or, with --input-layout google|xyz, a
    /// z/y/x or z/x/y directory. For pyramids, the finest level is the source and coarser input
    /// levels are ignored.
    #[arg(value_name = "INPUT")]
    input: PathBuf,

    /// The input is a directory of tiles named by --filename-format (the original tool's flag).
    #[arg(long)]
    tiled: bool,

    /// Names of the input tiles, printf-like: argument 1 = column, 2 = row, e.g. 'x%02s-y%02s.png'.
    #[arg(long, visible_alias = "ff", value_name = "PATTERN")]
    filename_format: Option<String>,

    /// How the input's tiles are laid out.
    #[arg(long, value_enum, default_value = "auto", value_name = "LAYOUT")]
    input_layout: InputLayout,

    /// A missing input tile is an error (otherwise it is filled with --background, or zeros,
    /// and reported as a warning).
    #[arg(long)]
    strict: bool,

    /// Convert a .dzi or IIIF input even when most of the tiles its descriptor declares are
    /// missing. Off by default: such an input is more likely damaged or hostile (a descriptor
    /// claiming 300000x300000 over one tile) than sparse, and would be filled for minutes.
    #[arg(long)]
    allow_missing_tiles: bool,

    /// Output tile names, as split's --filename-format [default: lod%1$02s-x%2$04s-y%3$04s.<ext>].
    #[arg(long, value_name = "PATTERN")]
    output_filename_format: Option<String>,

    /// Keep the texels in the colours of the input pyramid's ICC profile (the `iccProfile` of
    /// a tile directory or pack a `split --keep-icc` run wrote), and the profile in the output's
    /// JPEG and PNG tiles and info.json, as `split --keep-icc` does [default: convert them to
    /// sRGB, as split does]. (A tile pyramid carries no EXIF orientation: there is no
    /// --no-autorotate here.)
    #[arg(long)]
    keep_icc: bool,

    /// Map a float or 32-bit integer input (a raw/zstd pack or tile directory of `float` or
    /// `unsignedInt` tiles) linearly onto 8 bits (16 with --tile-type unsignedShort), as split's
    /// --range does: MIN to 0, MAX to the top code [default: none; without it such an input goes
    /// only to raw/zstd packs, since JPEG and PNG would cut its range]. Samples outside (and NaN)
    /// are clamped and counted in the summary.
    #[arg(long, value_name = "MIN:MAX", allow_hyphen_values = true)]
    range: Option<source::range::Range>,

    #[command(flatten)]
    pub out: OutputArgs,
}

pub fn run(a: ConvertArgs) -> Result<()> {
    let started = Instant::now();
    if !a.tiled && a.filename_format.is_none() && source::is_dicom_input(&a.input) {
        // A DICOM whole-slide series is tiled, and read as `split` reads it (source::dicom).
        let options =
            source::OpenOptions { keep_icc: a.keep_icc, ..source::OpenOptions::shown(Budget::new(a.out.max_memory())) };
        let source::Opened { mut source, icc, pitch, lossy, channel, .. } = source::open_with(&a.input, options)?;
        if let Some(range) = a.range {
            source = source::range::map(source, range, a.out.tile_type().unwrap_or(Depth::U8))?;
        }
        let carried = super::split::Carried { icc, geo: None, pitch, lossy, channel };
        return tile(source, &a.input, a.output_filename_format.clone(), &a.out, started, carried);
    }
    let grid = open_grid(&a)?;
    check_tiles_found(grid.as_ref(), a.allow_missing_tiles)?;
    let header = grid.header();
    let grid_cell = grid.cell();
    let icc = grid.icc_profile()?;
    let source = TiledSource::new(grid, fill_texel(a.out.background(), header.layout), a.strict)
        .with_budget(Budget::new(a.out.max_memory()));
    Limits { memory: a.out.max_memory(), ..Limits::default() }.check_memory(
        &format!(
            "reading a row of {}x{} input tiles of the {}x{} image (and one tile at a time)",
            grid_cell.0, grid_cell.1, header.width, header.height
        ),
        source.memory_needed(),
    )?;
    let missing = source.missing_log();
    let (mut source, kept_icc) = source::with_profile(&a.input, Box::new(source), icc, a.keep_icc)?;
    if let Some(range) = a.range {
        source = source::range::map(source, range, a.out.tile_type().unwrap_or(Depth::U8))?;
    }
    let carried = super::split::Carried { icc: kept_icc, ..Default::default() };
    let result = tile(source, &a.input, a.output_filename_format.clone(), &a.out, started, carried);
    let missing = missing.lock().map(|m| m.clone()).unwrap_or_default();
    if !missing.is_empty() {
        eprintln!(
            "warning: {} input tile(s) missing, filled with {}: {}{}",
            missing.len(),
            a.out.background().map_or("zeros".to_string(), |b| b.to_string()),
            missing.iter().take(5).cloned().collect::<Vec<_>>().join(", "),
            if missing.len() > 5 { ", ..." } else { "" }
        );
    }
    result
}

fn open_grid(a: &ConvertArgs) -> Result<Box<dyn TileGrid>> {
    let input = &a.input;
    if a.tiled || a.filename_format.is_some() {
        let Some(pattern) = &a.filename_format else {
            bail!("--tiled needs --filename-format (e.g. 'x%02s-y%02s.png')")
        };
        return Ok(Box::new(NamedDir::open(input, pattern)?));
    }
    if !input.exists() {
        bail!("{}: no such file or directory", input.shown());
    }
    let order = a.input_layout.order();
    if input.is_file() && is_zip(input) {
        return Ok(open_zip(input, order)?);
    }
    if let Some(order) = order {
        return Ok(Box::new(Xyz::open(input, order)?));
    }
    if input.extension().is_some_and(|e| e.eq_ignore_ascii_case("dzi")) {
        return Ok(Box::new(DeepZoom::open(input)?));
    }
    if input.is_file() && input.file_name().is_some_and(|n| n == "info.json") {
        // The descriptor itself names its directory.
        let dir = input.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
        return Ok(if is_iiif_dir(dir) { Box::new(Iiif::open(dir)?) } else { Box::new(SplitOutput::open(dir)?) });
    }
    if input.is_file() {
        if let Some(kind) = image_kind(input) {
            bail!(
                "{}: is a {kind} image, not a tiled input; `vortex-tiler split {} -o DIR` (or --pack FILE) cuts an image",
                input.shown(),
                input.shown()
            );
        }
        return Ok(Box::new(PackInput::open(input)?));
    }
    if is_iiif_dir(input) {
        return Ok(Box::new(Iiif::open(input)?));
    }
    if input.join("info.json").is_file() {
        return Ok(Box::new(SplitOutput::open(input)?));
    }
    bail!(
        "{}: a directory without info.json; for named tiles pass --tiled --filename-format PATTERN, for z/y/x tiles --input-layout google (z/x/y: --input-layout xyz)",
        input.shown()
    )
}

/// The image format `path` starts like, if any: `convert` takes tiles, `split` images.
fn image_kind(path: &Path) -> Option<&'static str> {
    let mut magic = Vec::with_capacity(Streamed::SNIFF_BYTES);
    let file = std::fs::File::open(path).ok()?;
    std::io::Read::read_to_end(&mut std::io::Read::take(file, Streamed::SNIFF_BYTES as u64), &mut magic).ok()?;
    Streamed::sniff(&magic).map(Streamed::name)
}

/// One texel of `background` in the grid's layout, native-endian; zeros without a colour.
fn fill_texel(background: Option<Background>, layout: PixelLayout) -> Vec<u8> {
    fn bytes<T: vortex_tiler::pixel::Sample>(colour: Background, layout: PixelLayout) -> Vec<u8> {
        let texel = colour.texel::<T>(layout.channels).unwrap_or_else(|| vec![T::default(); layout.channels.count()]);
        bytemuck::cast_slice(&texel).to_vec()
    }
    let colour = background.unwrap_or_default();
    match layout.depth {
        Depth::U8 => bytes::<u8>(colour, layout),
        Depth::U16 => bytes::<u16>(colour, layout),
        Depth::U32 => bytes::<u32>(colour, layout),
        Depth::F32 => bytes::<f32>(colour, layout),
        // Never a grid the pipeline reads (half is a stored type only).
        Depth::F16 => vec![0; layout.bytes_per_pixel()],
    }
}
