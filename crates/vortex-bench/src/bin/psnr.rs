//! PSNR of the finest level of a tile pyramid against its source image, streaming the source
//! top to bottom and decoding one row of tiles at a time, so that memory stays at about one
//! tile row whatever the image height.
//!
//!     cargo run --release -p vortex-bench --bin psnr -- SOURCE --vortex OUT_DIR
//!     cargo run --release -p vortex-bench --bin psnr -- SOURCE --dzi OUT_files
//!
//! `--vortex` reads vortex-tiler output: LOD 0 tiles named by `OUT_DIR/info.json`
//! (`filenameFormat`, default `lod%1$02s-x%2$04s-y%3$04s.<ext>`), each of `tileSize` texels of
//! which `border` on every side are copied from neighbours. `--dzi` reads a Deep Zoom pyramid
//! as written by `vips dzsave`: the highest-numbered directory of `OUT_files` holds
//! `<col>_<row>.<ext>`; tile size and overlap come from the `OUT.dzi` next to it, or from
//! `--tile-size` / `--overlap`. Tiles in the padding beyond the image are not compared.
//!
//! JPEG XL tiles are decoded by libjxl (`vortex-jxl`), the others by the `image` crate.
//!
//! Prints only the PSNR in dB over all colour samples (8-bit, peak 255), or `inf` for an
//! identical image; `-v` adds the sample count and mean squared error on stderr. Sources must be
//! 8-bit grey or RGB; alpha channels are ignored.
#![allow(clippy::unwrap_used, clippy::expect_used)] // tests and measurement programs may panic on a broken set-up

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail, ensure};
use rayon::prelude::*;
use vortex_tiler::formats::tiles::filename::FilenameFormat;
use vortex_tiler::formats::tiles::info::InfoFile;
use vortex_tiler::pixel::{Channels, Depth};

const USAGE: &str =
    "usage: psnr SOURCE (--vortex DIR | --dzi DIR_files [--tile-size N] [--overlap N]) [--max-memory BYTES] [-v]";

/// Where the finest-level tiles are and how they map onto the source.
enum Grid {
    Vortex { dir: PathBuf, names: FilenameFormat, border: u32 },
    Dzi { level_dir: PathBuf, ext: String, overlap: u32 },
}

impl Grid {
    fn tile_path(&self, col: u32, row: u32) -> PathBuf {
        match self {
            Grid::Vortex { dir, names, .. } => dir.join(names.format(&[0, col, row])),
            Grid::Dzi { level_dir, ext, .. } => level_dir.join(format!("{col}_{row}.{ext}")),
        }
    }

    /// Tile texel of the first source texel of page `i` (along either axis).
    fn lead(&self, i: u32) -> u32 {
        match self {
            Grid::Vortex { border, .. } => *border,
            Grid::Dzi { overlap, .. } => {
                if i == 0 {
                    0
                } else {
                    *overlap
                }
            }
        }
    }
}

fn main() {
    if let Err(e) = run() {
        // The library's errors already hold their io::Error, which `{:#}` would print twice.
        let mut line = e.to_string();
        for cause in e.chain().skip(1).map(|c| c.to_string()) {
            if !line.contains(&cause) {
                line = format!("{line}: {cause}");
            }
        }
        eprintln!("psnr: {line}");
        std::process::exit(1);
    }
}

fn run() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mut source = None;
    let (mut vortex, mut dzi, mut tile_size, mut overlap) = (None, None, None, None);
    let mut max_memory: u64 = 1 << 30;
    let mut verbose = false;
    let mut it = args.iter();
    while let Some(a) = it.next() {
        let mut value = || it.next().with_context(|| format!("{a} needs a value\n{USAGE}"));
        match a.as_str() {
            "--vortex" => vortex = Some(PathBuf::from(value()?)),
            "--dzi" => dzi = Some(PathBuf::from(value()?)),
            "--tile-size" => tile_size = Some(value()?.parse::<u32>().context("--tile-size")?),
            "--overlap" => overlap = Some(value()?.parse::<u32>().context("--overlap")?),
            "--max-memory" => max_memory = value()?.parse().context("--max-memory (bytes)")?,
            "-v" | "--verbose" => verbose = true,
            "-h" | "--help" => {
                println!("{USAGE}");
                return Ok(());
            }
            s if s.starts_with('-') => bail!("unknown option {s}\n{USAGE}"),
            s if source.is_none() => source = Some(PathBuf::from(s)),
            s => bail!("unexpected argument {s}\n{USAGE}"),
        }
    }
    let source = source.context(USAGE)?;
    let (grid, page) = match (vortex, dzi) {
        (Some(dir), None) => vortex_grid(dir)?,
        (None, Some(dir)) => dzi_grid(dir, tile_size, overlap)?,
        _ => bail!("give exactly one of --vortex and --dzi\n{USAGE}"),
    };

    let mut src = vortex_tiler::source::open(&source, vortex_tiler::limits::Budget::new(max_memory))?;
    let layout = src.layout();
    ensure!(layout.depth == Depth::U8, "{}: only 8-bit sources are supported, not {layout}", source.display());
    let (width, height) = (src.width(), src.height());
    let src_channels = layout.channels.count();
    let colour = layout.channels.without_alpha();
    let grey = colour == Channels::Grey;
    let cmp = colour.count();

    let cols = width.div_ceil(page);
    let mut row = vec![0u8; width as usize * layout.bytes_per_pixel()];
    let (mut sum_sq, mut samples) = (0u64, 0u64);
    for tile_row in 0..height.div_ceil(page) {
        let tiles: Vec<(Vec<u8>, u32, u32)> = (0..cols)
            .into_par_iter()
            .map(|col| {
                let path = grid.tile_path(col, tile_row);
                let img = open_tile(&path).with_context(|| format!("decoding {}", path.display()))?;
                let (w, h) = (img.width(), img.height());
                // The last texel of this page that lies in the image must be inside the tile.
                let need_w = grid.lead(col) + (width - col * page).min(page);
                let need_h = grid.lead(tile_row) + (height - tile_row * page).min(page);
                ensure!(w >= need_w && h >= need_h, "{} is {w}x{h}, smaller than {need_w}x{need_h}", path.display());
                let px = if grey { img.into_luma8().into_raw() } else { img.into_rgb8().into_raw() };
                Ok((px, w, h))
            })
            .collect::<Result<_>>()?;
        let y0 = tile_row * page;
        for y in y0..(y0 + page).min(height) {
            src.read_row(&mut row).with_context(|| format!("{}: row {y}", source.display()))?;
            let ty = (y - y0 + grid.lead(tile_row)) as usize;
            for (col, (px, tw, _)) in tiles.iter().enumerate() {
                let x0 = col as u32 * page;
                let x1 = (x0 + page).min(width);
                let tx0 = grid.lead(col as u32) as usize;
                let tile_line = &px[(ty * *tw as usize + tx0) * cmp..];
                let src_line = &row[x0 as usize * src_channels..x1 as usize * src_channels];
                for (s, t) in src_line.chunks_exact(src_channels).zip(tile_line.chunks_exact(cmp)) {
                    for c in 0..cmp {
                        let d = s[c] as i32 - t[c] as i32;
                        sum_sq += (d * d) as u64;
                    }
                }
                samples += (x1 - x0) as u64 * cmp as u64;
            }
        }
    }
    let mse = sum_sq as f64 / samples as f64;
    if verbose {
        eprintln!("{samples} samples ({width}x{height}x{cmp}), mean squared error {mse:.4}");
    }
    if sum_sq == 0 {
        println!("inf");
    } else {
        println!("{:.3}", vortex_bench::measure::psnr_8bit(sum_sq as f64, samples as f64));
    }
    Ok(())
}

/// LOD 0 of a vortex-tiler output directory, described by its info.json.
fn vortex_grid(dir: PathBuf) -> Result<(Grid, u32)> {
    let info_path = dir.join("info.json");
    let info = InfoFile::read(&info_path)?;
    let tile_size = info.tile_size.context("info.json has no tileSize")?;
    let border = info.border.unwrap_or(0);
    let pattern = match info.filename_format {
        Some(p) => p,
        None => {
            let ext = match info.codec.as_deref() {
                Some("png") => "png",
                _ => "jpg",
            };
            format!("lod%1$02s-x%2$04s-y%3$04s.{ext}")
        }
    };
    let names = FilenameFormat::parse(&pattern, 3)
        .map_err(|e| anyhow::anyhow!("{}: filenameFormat: {e}", info_path.display()))?;
    let page = tile_size.checked_sub(2 * border).filter(|p| *p > 0).context("border leaves no payload")?;
    Ok((Grid::Vortex { dir, names, border }, page))
}

/// The finest level of a Deep Zoom pyramid `<name>_files`, with its geometry from `<name>.dzi`.
fn dzi_grid(files: PathBuf, tile_size: Option<u32>, overlap: Option<u32>) -> Result<(Grid, u32)> {
    let (_, level_dir) = std::fs::read_dir(&files)
        .with_context(|| format!("reading {}", files.display()))?
        .filter_map(|e| e.ok())
        .filter_map(|e| Some((e.file_name().to_str()?.parse::<u32>().ok()?, e.path())))
        .max_by_key(|(n, _)| *n)
        .with_context(|| format!("{} has no numbered level directories", files.display()))?;
    let first = std::fs::read_dir(&level_dir)?
        .filter_map(|e| e.ok())
        .map(|e| e.path())
        .find(|p| p.file_stem().is_some_and(|s| s == "0_0"))
        .with_context(|| format!("{} has no tile 0_0", level_dir.display()))?;
    let ext = first.extension().and_then(|e| e.to_str()).unwrap_or("jpg").to_string();
    let dzi = dzi_descriptor(&files);
    let attr = |name: &str| -> Option<u32> {
        let text = dzi.as_deref()?;
        let at = text.find(&format!("{name}=\""))? + name.len() + 2;
        text[at..].split('"').next()?.parse().ok()
    };
    let tile_size =
        tile_size.or_else(|| attr("TileSize")).context("no .dzi next to the directory: give --tile-size")?;
    let overlap = overlap.or_else(|| attr("Overlap")).unwrap_or(0);
    Ok((Grid::Dzi { level_dir, ext, overlap }, tile_size))
}

/// Text of `name.dzi` for `name_files`, if there is one.
fn dzi_descriptor(files: &Path) -> Option<String> {
    let name = files.file_name()?.to_str()?.strip_suffix("_files")?;
    std::fs::read_to_string(files.with_file_name(format!("{name}.dzi"))).ok()
}

/// A tile file decoded: JPEG XL by libjxl, anything else by the `image` crate.
fn open_tile(path: &Path) -> Result<image::DynamicImage> {
    let bytes = std::fs::read(path)?;
    if !vortex_jxl::is_jxl(&bytes) {
        return Ok(image::load_from_memory(&bytes)?);
    }
    let decoded = vortex_jxl::decode(&bytes, (1 << 16, 1 << 16))?;
    let (w, h, channels) = (decoded.header.width, decoded.header.height, decoded.header.channels);
    let vortex_jxl::Samples::U8(px) = decoded.samples else { bail!("16-bit JPEG XL tiles are not compared") };
    match channels {
        1 => image::GrayImage::from_raw(w, h, px).map(image::DynamicImage::ImageLuma8),
        2 => image::GrayAlphaImage::from_raw(w, h, px).map(image::DynamicImage::ImageLumaA8),
        3 => image::RgbImage::from_raw(w, h, px).map(image::DynamicImage::ImageRgb8),
        _ => image::RgbaImage::from_raw(w, h, px).map(image::DynamicImage::ImageRgba8),
    }
    .context("a JPEG XL tile of the wrong length")
}
