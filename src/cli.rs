//! Flags and subcommands.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use clap::{Parser, Subcommand};

use vortex_tiler::background::Background;
use vortex_tiler::codec::{PngLevel, Subsampling};
use vortex_tiler::info::InfoFile;
use vortex_tiler::layout::Layout;
use vortex_tiler::pixel::Depth;
use vortex_tiler::settings::{self, CodecChoice, Requested};
use vortex_tiler::sink::DirSink;
use vortex_tiler::{source, split};

use crate::report;

#[derive(Parser, Debug)]
#[command(
    name = "vortex-tiler",
    version,
    about = "Cut huge images into virtual-texture tiles with every power-of-two LOD, in bounded memory"
)]
pub struct Args {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Cut one image into tiles plus every power-of-two LOD, streaming it in bands.
    ///
    /// The output directory gets one file per tile of every LOD and an info.json describing the
    /// pyramid (docs/info-json.md). If it already holds an info.json, that file's members set
    /// the defaults for this run (the original tool's behaviour) and flags override them.
    ///
    /// Examples:
    ///   vortex-tiler split huge.tif -o out/ --tile-size 128 --border 4 --codec jpeg --quality 85
    ///   vortex-tiler split --input=in.png --output=out
    #[command(verbatim_doc_comment)]
    Split(SplitArgs),
}

#[derive(clap::Args, Debug)]
struct SplitArgs {
    /// Image to cut: PNG, TIFF/BigTIFF, JPEG, PPM/PGM stream in bands; WebP, GIF, BMP, TGA and
    /// QOI are decoded whole within --max-memory.
    #[arg(value_name = "INPUT", required_unless_present = "input_flag")]
    input: Option<PathBuf>,

    /// The input, spelled as the original tool did (--input=in.png).
    #[arg(long = "input", value_name = "INPUT", conflicts_with = "input")]
    input_flag: Option<PathBuf>,

    /// Output directory (created; replaced only if it holds a previous output's info.json).
    #[arg(short, long, value_name = "DIR")]
    output: PathBuf,

    /// Side of a stored tile in texels, borders included [default: 128].
    #[arg(long, value_name = "N")]
    tile_size: Option<u32>,

    /// Texels copied from neighbouring pages into each tile edge, for filtering on the GPU
    /// (1 for bilinear, 4 as in id Tech 5 for anisotropic) [default: 0].
    #[arg(long, value_name = "N")]
    border: Option<u32>,

    /// Tile codec; auto = JPEG for 8-bit grey/RGB, PNG with alpha or 16 bits [default: auto,
    /// or what the filename format's extension says].
    #[arg(long, value_enum)]
    codec: Option<CodecChoice>,

    /// JPEG quality, 1-100 [default: 85].
    #[arg(long, value_name = "Q")]
    quality: Option<u8>,

    /// JPEG chroma subsampling [default: 420].
    #[arg(long, value_enum)]
    subsampling: Option<Subsampling>,

    /// PNG compression effort [default: fast].
    #[arg(long, value_enum)]
    png_compression: Option<PngLevel>,

    /// Fill for the padding between the image and the square power-of-two virtual texture:
    /// edge (repeat the image's edge), #rrggbb, #rrggbbaa, r,g,b[,a] or a grey level [default: edge].
    #[arg(long, value_name = "COLOUR")]
    background: Option<Background>,

    /// Composite alpha over --background (black if edge) so that RGBA sources can be stored as JPEG.
    #[arg(long)]
    flatten: bool,

    /// Sample type of stored tiles: unsignedByte or unsignedShort (PNG only) [default: the source's].
    #[arg(long, value_name = "TYPE", value_parser = parse_tile_type)]
    tile_type: Option<Depth>,

    /// Tile file names, printf-like with positional arguments 1 = LOD, 2 = x, 3 = y; '/' makes
    /// subdirectories [default: lod%1$02s-x%2$04s-y%3$04s.<ext>].
    #[arg(long, visible_alias = "ff", value_name = "PATTERN")]
    filename_format: Option<String>,

    /// Largest image this tool will hold whole in memory when a format cannot be streamed
    /// (interlaced PNG, progressive JPEG, one-strip TIFF, WebP, ...), e.g. 512M, 4G.
    #[arg(long, value_name = "SIZE", default_value = "1G", value_parser = parse_size)]
    max_memory: u64,

    /// Worker threads for encoding [default: all cores]. Output is identical for any count.
    #[arg(long, value_name = "N")]
    threads: Option<usize>,

    /// No progress bar and no summary line.
    #[arg(short, long)]
    quiet: bool,
}

pub fn run(args: Args) -> Result<()> {
    match args.command {
        Command::Split(a) => run_split(a),
    }
}

fn run_split(a: SplitArgs) -> Result<()> {
    let started = Instant::now();
    let input = a.input.or(a.input_flag).expect("clap requires one");
    let info_path = a.output.join("info.json");
    let existing = if info_path.is_file() { Some(InfoFile::read(&info_path)?) } else { None };

    let source = source::open(&input, a.max_memory)?;
    let requested = Requested {
        tile_size: a.tile_size,
        border: a.border,
        codec: a.codec,
        quality: a.quality,
        subsampling: a.subsampling,
        png_level: a.png_compression,
        background: a.background,
        flatten: a.flatten,
        tile_depth: a.tile_type,
        filename_format: a.filename_format,
    };
    let (opts, names) =
        settings::resolve(&requested, existing.as_ref().map(|i| (info_path.as_path(), i)), source.layout())?;
    let layout = Layout::new(source.width() as u64, source.height() as u64, opts.tile_size, opts.border)?;
    if let Some(info) = &existing {
        settings::check_grid(&info_path, info, &requested, &layout)?;
    }
    let decoder = source.describe();
    let (width, height) = (source.width(), source.height());

    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(a.threads.unwrap_or(0))
        .build()
        .context("starting worker threads")?;
    let sink = DirSink::create(&a.output, names.clone())?;
    let watch = report::Watch::new(layout.total_tiles(), a.quiet);
    let result = pool.install(|| split::split(source, &sink, &opts, &watch));
    watch.bar.finish_and_clear();
    let summary = match result {
        Ok(s) => s,
        Err(e) => {
            sink.abandon();
            return Err(e.into());
        }
    };
    if summary.tiles != layout.total_tiles() {
        sink.abandon();
        bail!("internal error: wrote {} tiles of {}", summary.tiles, layout.total_tiles());
    }
    sink.finish(&settings::describe(&summary, &opts, &names))?;
    if !a.quiet {
        println!("{}", report::summary_line(&summary, &a.output, width, height, &decoder, started.elapsed()));
    }
    Ok(())
}

fn parse_tile_type(s: &str) -> Result<Depth, String> {
    Depth::from_tile_type(s).ok_or_else(|| format!("'{s}' is not a tile type (unsignedByte, unsignedShort)"))
}

/// `1048576`, `512K`, `64M`, `2G`, `1GiB`...
fn parse_size(s: &str) -> Result<u64, String> {
    let t = s.trim().to_ascii_uppercase();
    let t = t.trim_end_matches("IB").trim_end_matches('B');
    let (num, shift) = match t.chars().last() {
        Some('K') => (&t[..t.len() - 1], 10),
        Some('M') => (&t[..t.len() - 1], 20),
        Some('G') => (&t[..t.len() - 1], 30),
        Some('T') => (&t[..t.len() - 1], 40),
        _ => (t, 0),
    };
    let n: f64 = num.trim().parse().map_err(|_| format!("'{s}' is not a size (e.g. 512M, 4G)"))?;
    if !(n.is_finite() && n >= 0.0) {
        return Err(format!("'{s}' is not a size"));
    }
    Ok((n * (1u64 << shift) as f64) as u64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes() {
        assert_eq!(parse_size("1G"), Ok(1 << 30));
        assert_eq!(parse_size("512MiB"), Ok(512 << 20));
        assert_eq!(parse_size("1.5k"), Ok(1536));
        assert_eq!(parse_size("100"), Ok(100));
        assert!(parse_size("lots").is_err());
    }
}
