//! What each tile codec costs and gives: encode time per tile on one core, bytes per tile and
//! PSNR against the tile's texels, for every codec and setting `split --pack` offers. A
//! benchmark, not a test.
//!
//!     cargo run --release -p vortex-bench --bin codec_speed -- IMAGE [--tile-size N] [--tiles N] [--alpha]
//!
//! IMAGE is decoded whole (keep it small: a few thousand texels a side, e.g. from
//! `cargo run --release -p vortex-bench --bin gen_image -- 2048 2048 img.png`); its first `--tiles` whole
//! tiles (default 64) of `--tile-size` (default 256) are encoded, RGB 8-bit (RGBA with
//! `--alpha`). Prints a markdown table: ms per tile (median), KiB per tile (mean), bits per
//! texel, PSNR in dB over the colour samples (and alpha, with `--alpha`).
#![allow(clippy::unwrap_used, clippy::expect_used)] // tests and measurement programs may panic on a broken set-up

use std::time::Instant;

use anyhow::{Context, Result, bail};
use vortex_bench::measure;
use vortex_pack::{Description, Tile, TileKind};
use vortex_tiler::codec::{Bc7Effort, Codec, PngLevel, RowFilter, Subsampling, TileEncoder};
use vortex_tiler::formats::pack::tile_kind;
use vortex_tiler::pixel::{Channels, Depth, PixelLayout};

fn flag(args: &[String], name: &str, default: u32) -> Result<u32> {
    match args.iter().position(|a| a == name) {
        Some(i) => args.get(i + 1).context("a flag without its value")?.parse().context(name.to_string()),
        None => Ok(default),
    }
}

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some(path) = args.first().filter(|a| !a.starts_with("--")) else {
        bail!("usage: codec_speed IMAGE [--tile-size N] [--tiles N] [--alpha]")
    };
    let side = flag(&args, "--tile-size", 256)?;
    let count = flag(&args, "--tiles", 64)? as usize;
    let alpha = args.iter().any(|a| a == "--alpha");
    let image = image::open(path).with_context(|| path.clone())?;
    let (channels, texels) = match alpha {
        true => (Channels::Rgba, image.to_rgba8().into_raw()),
        false => (Channels::Rgb, image.to_rgb8().into_raw()),
    };
    let (width, height) = (image.width(), image.height());
    let c = channels.count();
    let tiles: Vec<Vec<u8>> = (0..height / side)
        .flat_map(|ty| (0..width / side).map(move |tx| (tx, ty)))
        .take(count)
        .map(|(tx, ty)| {
            let mut t = Vec::with_capacity((side * side) as usize * c);
            for y in ty * side..(ty + 1) * side {
                let row = (y * width + tx * side) as usize * c;
                t.extend_from_slice(&texels[row..row + side as usize * c]);
            }
            t
        })
        .collect();
    if tiles.is_empty() {
        bail!("{path} is {width}x{height}: smaller than one {side}-texel tile");
    }
    let layout = PixelLayout::new(channels, Depth::U8);
    let description = Description {
        width: side,
        height: side,
        tile_size: side,
        border: 0,
        level_count: 1,
        channels: c as u8,
        sample_bytes: 1,
        sample_format: 0,
    };

    let mut codecs = Vec::new();
    if !alpha {
        for quality in [50, 75, 85, 95] {
            for subsampling in [Subsampling::S420, Subsampling::S444] {
                codecs.push((format!("jpeg q{quality} {}", subsampling.name()), Codec::Jpeg { quality, subsampling }));
            }
        }
    }
    for level in [PngLevel::Fast, PngLevel::Default, PngLevel::Best] {
        codecs.push((format!("png {}", level.name()), Codec::Png { level }));
    }
    codecs.push(("raw".into(), Codec::Raw));
    for delta in [false, true] {
        for level in [1, 3, 9, 19] {
            let codec = Codec::Zstd { level, filter: RowFilter::delta(delta) };
            codecs.push((format!("{} {level}", codec.name()), codec));
        }
    }
    if !alpha {
        codecs.push(("bc1".into(), Codec::Bc1));
    }
    for effort in [Bc7Effort::UltraFast, Bc7Effort::VeryFast, Bc7Effort::Fast, Bc7Effort::Basic, Bc7Effort::Slow] {
        codecs.push((format!("bc7 {}", effort.name()), Codec::Bc7 { effort }));
    }

    println!(
        "{} tiles of {side}x{side} {layout} from {path}, one core\n\n| codec | ms/tile | KiB/tile | bits/texel | PSNR dB |\n|---|---:|---:|---:|---:|",
        tiles.len()
    );
    for (label, codec) in codecs {
        let encoder = TileEncoder::<u8>::new(codec, layout, false, None, side, Vec::new())?;
        let (mut times, mut bytes, mut squared, mut samples) = (Vec::new(), 0usize, 0f64, 0f64);
        for tile in &tiles {
            let mut out = Vec::new();
            let started = Instant::now();
            encoder.encode(tile, &mut out).map_err(anyhow::Error::msg)?;
            times.push(started.elapsed().as_secs_f64() * 1e3);
            bytes += out.len();
            let back = decode(tile_kind(codec)?, &out, &description)?;
            for (a, b) in tile.iter().zip(&back) {
                squared += (*a as f64 - *b as f64).powi(2);
                samples += 1.0;
            }
        }
        let per_tile = bytes as f64 / tiles.len() as f64;
        let psnr = measure::psnr_8bit(squared, samples);
        println!(
            "| {label} | {:.3} | {:.1} | {:.2} | {} |",
            measure::median(&mut times),
            per_tile / 1024.0,
            per_tile * 8.0 / (side * side) as f64,
            if psnr.is_finite() { format!("{psnr:.2}") } else { "lossless".into() }
        );
    }
    Ok(())
}

/// A payload back to the tile's texels (RGB or RGBA 8-bit).
fn decode(kind: TileKind, bytes: &[u8], d: &Description) -> Result<Vec<u8>> {
    Ok(match kind {
        TileKind::Png | TileKind::Jpeg => {
            let image = image::load_from_memory(bytes)?;
            if d.channels == 4 { image.to_rgba8().into_raw() } else { image.to_rgb8().into_raw() }
        }
        _ => Tile::Data(kind, bytes).decode_texels(d, 1 << 30)?,
    })
}
