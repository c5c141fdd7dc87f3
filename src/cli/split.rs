//! `split`: flags to options, the pipeline with a progress bar, one summary line.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result, bail};

use vortex_tiler::background::Background;
use vortex_tiler::codec::{Bc7Effort, PngLevel, Subsampling};
use vortex_tiler::layout::Layout;
use vortex_tiler::limits::Limits;
use vortex_tiler::output::{Existing, Product};
use vortex_tiler::pixel::Depth;
use vortex_tiler::pyramid::Filter;
use vortex_tiler::settings::{self, CodecChoice, Requested};
use vortex_tiler::sink::DirSink;
use vortex_tiler::sink::PackSink;
use vortex_tiler::source::RowSource;
use vortex_tiler::tile_dir::info::InfoFile;
use vortex_tiler::{source, split};

use super::report;

#[derive(clap::Args, Debug)]
pub struct SplitArgs {
    /// Image to cut: PNG, TIFF/BigTIFF, JPEG, PPM/PGM stream in bands; WebP, GIF, BMP, TGA and
    /// QOI are decoded whole within --max-memory.
    #[arg(value_name = "INPUT", required_unless_present = "input_flag")]
    input: Option<PathBuf>,

    /// The input, spelled as the original tool did (--input=in.png).
    #[arg(long = "input", value_name = "INPUT", conflicts_with = "input")]
    input_flag: Option<PathBuf>,

    /// Tile file names, printf-like with positional arguments 1 = LOD, 2 = x, 3 = y; '/' makes
    /// subdirectories [default: lod%1$02s-x%2$04s-y%3$04s.<ext>].
    #[arg(long, visible_alias = "ff", value_name = "PATTERN")]
    filename_format: Option<String>,

    #[command(flatten)]
    out: OutputArgs,
}

/// What `split` and `convert` write, and how.
#[derive(clap::Args, Debug)]
pub struct OutputArgs {
    /// Output directory (created; replaced only if it holds nothing but a previous output:
    /// its info.json and the tiles that names).
    #[arg(short, long, value_name = "DIR", required_unless_present = "pack", conflicts_with = "pack")]
    output: Option<PathBuf>,

    /// Write one pack file instead of a directory of tiles (docs/pack-format.md). An existing
    /// pack is replaced; any other file only with --force.
    #[arg(long, value_name = "FILE")]
    pack: Option<PathBuf>,

    /// Replace a regular file at --pack that is not a pack. Never replaces a directory, a
    /// device, a FIFO, a link or the input.
    #[arg(long)]
    force: bool,

    #[command(flatten)]
    pack_layout: super::PackLayout,

    /// Side of a stored tile in texels, borders included [default: 128]. LOD 0 has
    /// ceil(width / payload) x ceil(height / payload) pages (payload = tile size - 2 x border),
    /// each LOD half as many per axis (rounding up), down to the first LOD of one page.
    #[arg(long, value_name = "N")]
    tile_size: Option<u32>,

    /// Texels copied from neighbouring pages into each tile edge, for filtering on the GPU
    /// (1 for bilinear, 4 as in id Tech 5 for anisotropic) [default: 0].
    #[arg(long, value_name = "N")]
    border: Option<u32>,

    #[command(flatten)]
    enc: CodecArgs,

    /// Fill for the padding in the last page of each row and column, between the image's edge
    /// and the page's: edge (repeat the image's edge), #rrggbb, #rrggbbaa, r,g,b[,a] or a grey
    /// level [default: edge].
    #[arg(long, value_name = "COLOUR")]
    background: Option<Background>,

    /// Composite alpha over --background (black if edge) so that RGBA sources can be stored as JPEG.
    #[arg(long)]
    flatten: bool,

    /// How each LOD is made from the finer ones [default: linear-premultiplied]. box, linear,
    /// premultiplied and linear-premultiplied are exact means over the source footprint,
    /// rounded once (linear: in linear light; premultiplied: colour weighted by alpha, no
    /// fringes from transparent texels; box: of the stored values, as vips dzsave averages);
    /// lanczos3 and mitchell resample each LOD from the previous one.
    #[arg(long, value_enum)]
    filter: Option<Filter>,

    /// Sample type of stored tiles: unsignedByte or unsignedShort (png, raw, zstd, zstd-delta)
    /// [default: the source's].
    #[arg(long, value_name = "TYPE", value_parser = super::parse_tile_type)]
    tile_type: Option<Depth>,

    /// Most memory a run may hold at once, checked before allocating: an image decoded whole
    /// when its format cannot be streamed (interlaced PNG, progressive JPEG, one-strip TIFF,
    /// WebP, ...), the bands and tiles in flight, a pack's index; e.g. 512M, 4G. An image too
    /// wide for its bands to fit is cut in vertical stripes, reading the source once per
    /// stripe, for the same tiles.
    #[arg(long, value_name = "SIZE", default_value = "1G", value_parser = super::parse_size)]
    max_memory: u64,

    /// Worker threads for encoding, at most 4 per core [default: one per core]. Output is
    /// identical for any count.
    #[arg(long, value_name = "N")]
    threads: Option<usize>,

    /// No progress bar and no summary line.
    #[arg(short, long)]
    quiet: bool,
}

/// How tiles are encoded: `split`, `convert` and `pack` share these flags.
#[derive(clap::Args, Debug)]
pub struct CodecArgs {
    /// Tile codec [default: auto, or what the filename format's extension says]. raw, zstd,
    /// zstd-delta, bc1 and bc7 have no file format and write packs only.
    #[arg(long, value_enum)]
    pub codec: Option<CodecChoice>,

    /// JPEG quality, 1-100 [default: 85].
    #[arg(long, value_name = "Q")]
    pub quality: Option<u8>,

    /// JPEG chroma subsampling [default: 420].
    #[arg(long, value_enum)]
    pub subsampling: Option<Subsampling>,

    /// PNG compression effort [default: fast].
    #[arg(long, value_enum)]
    pub png_compression: Option<PngLevel>,

    /// zstd level for --codec zstd and zstd-delta, 1-22 [default: 3].
    #[arg(long, value_name = "N", allow_negative_numbers = true)]
    pub zstd_level: Option<i32>,

    /// BC7 encoder effort, fastest first (Intel ISPC presets) [default: ultra-fast].
    #[arg(long, value_enum)]
    pub bc7_effort: Option<Bc7Effort>,
}

impl CodecArgs {
    /// These flags as the codec part of a request.
    pub fn requested(&self) -> Requested {
        Requested {
            codec: self.codec,
            quality: self.quality,
            subsampling: self.subsampling,
            png_level: self.png_compression,
            zstd_level: self.zstd_level,
            bc7_effort: self.bc7_effort,
            ..Requested::default()
        }
    }

    /// Whether any of them was given.
    pub fn any(&self) -> bool {
        let r = self.requested();
        r.codec.is_some()
            || r.quality.is_some()
            || r.subsampling.is_some()
            || r.png_level.is_some()
            || r.zstd_level.is_some()
            || r.bc7_effort.is_some()
    }
}

pub fn run(a: SplitArgs) -> Result<()> {
    let started = Instant::now();
    let input = a.input.or(a.input_flag).context("an input image is required")?;
    let source = source::open(&input, a.out.max_memory)?;
    tile(source, &input, a.filename_format, &a.out, started)
}

/// Runs the pipeline from `source` into the output `out` names, with the progress bar and
/// the summary line. `names` is the output filename format flag.
impl OutputArgs {
    pub fn background(&self) -> Option<Background> {
        self.background
    }

    pub fn max_memory(&self) -> u64 {
        self.max_memory
    }
}

pub fn tile(
    source: Box<dyn RowSource>,
    input: &Path,
    names: Option<String>,
    a: &OutputArgs,
    started: Instant,
) -> Result<()> {
    let limits = Limits { memory: a.max_memory, ..Limits::default() };
    limits.check_threads(a.threads.unwrap_or(0))?;
    let (dest, product) = match (&a.output, &a.pack) {
        (Some(dir), _) => (dir, Product::TileDir),
        (None, Some(file)) => (file, Product::Pack),
        (None, None) => unreachable!("clap requires --output or --pack"),
    };
    let claim = report::claim(dest, product, &[input], a.force)?;
    // A previous output directory's info.json sets this run's defaults (the original tool's
    // way of configuring a run); the claim above made sure the directory is ours.
    let info_path = (product == Product::TileDir && claim.replaces == Some(Existing::Ours))
        .then(|| dest.join("info.json"))
        .filter(|p| p.is_file());
    let existing = info_path.as_deref().map(InfoFile::read).transpose()?;
    let requested = Requested {
        tile_size: a.tile_size,
        border: a.border,
        background: a.background,
        flatten: a.flatten,
        tile_depth: a.tile_type,
        filename_format: names,
        filter: a.filter,
        max_memory: Some(a.max_memory),
        ..a.enc.requested()
    };
    let existing_ref = info_path.as_deref().zip(existing.as_ref());
    let (opts, names) = settings::resolve(&requested, existing_ref, source.layout())?;
    if a.output.is_some() && !opts.codec.writes_files() {
        bail!(
            "--codec {} writes packs only (its tiles are not image files): write --pack FILE instead of --output, or use --codec png for lossless tile files",
            opts.codec.name()
        );
    }
    let layout = Layout::new(source.width() as u64, source.height() as u64, opts.tile_size, opts.border)?;
    if let Some((path, info)) = existing_ref {
        settings::check_grid(path, info, &requested, &layout)?;
    }
    let stored = opts.codec.stored_layout(source.layout(), opts.flatten, opts.tile_depth)?;
    limits.check_pyramid(&layout, product == Product::Pack)?;
    let info = settings::describe(&layout, stored, &opts, &names);
    // Said once everything is checked, just before the work starts.
    if let (Some(path), false) = (&info_path, a.quiet) {
        let changed = settings::changed_by_file(&requested, source.layout(), source.width(), source.height(), &info);
        if !changed.is_empty() {
            eprintln!("settings from {}: {}", path.display(), changed.join(", "));
        }
    }
    let decoder = source.describe();
    let (width, height) = (source.width(), source.height());

    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(a.threads.unwrap_or(0))
        .build()
        .context("starting worker threads")?;
    let watch = report::Watch::new(layout.total_tiles(), a.quiet)?;
    let (summary, destination) = match (&a.output, &a.pack) {
        (Some(dir), _) => {
            let sink = DirSink::create(&claim, names)?;
            let result = pool.install(|| split::split(source, &sink, &opts, &watch));
            watch.bar.finish_and_clear();
            match result {
                Ok(s) if s.tiles == layout.total_tiles() => {
                    sink.finish(&info)?;
                    (s, dir)
                }
                Ok(s) => {
                    sink.abandon();
                    bail!("internal error: wrote {} tiles of {}", s.tiles, layout.total_tiles());
                }
                Err(e) => {
                    sink.abandon();
                    return Err(e.into());
                }
            }
        }
        (None, Some(file)) => {
            let sink = PackSink::create(
                file,
                &layout,
                stored,
                opts.codec,
                info.to_json_pretty().as_bytes(),
                a.pack_layout.options()?,
            )?;
            // On error the sink is dropped, which deletes the unfinished pack.
            let s = pool.install(|| split::split(source, &sink, &opts, &watch));
            watch.bar.finish_and_clear();
            let s = s?;
            let written = sink.finish()?;
            if !a.quiet {
                say!("{}", report::pack_line(&written));
            }
            (s, file)
        }
        (None, None) => unreachable!("clap requires --output or --pack"),
    };
    if !a.quiet {
        say!("{}", report::summary_line(&summary, destination, width, height, &decoder, started.elapsed()));
    }
    Ok(())
}
