//! Writes a synthetic test image of any size without holding it in memory: smooth gradients,
//! a zone plate (every spatial frequency), hard-edged discs and per-pixel noise, so that codecs
//! and filters meet photo-like, high-frequency and line content at once.
//!
//!     cargo run --release -p vortex-bench --bin gen_image -- WIDTH HEIGHT OUT.{tif,png,ppm} [--grey] [--alpha] [--16] [--noise F]
//!
//! `--noise` sets the noise amplitude (default 0.12 of full scale; small fixtures use less so
//! that they compress).
#![allow(clippy::unwrap_used, clippy::expect_used)] // tests and measurement programs may panic on a broken set-up

use std::fs::File;
use std::io::{BufWriter, Write};

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let usage = "usage: gen_image WIDTH HEIGHT OUT.{tif,png,ppm} [--grey] [--alpha] [--16] [--noise F]";
    let (w, h, out) = match &args[..] {
        [w, h, out, ..] => (w.parse::<u32>().expect(usage), h.parse::<u32>().expect(usage), out.clone()),
        _ => panic!("{usage}"),
    };
    let alpha = args.iter().any(|a| a == "--alpha");
    let wide = args.iter().any(|a| a == "--16");
    let noise: f64 = args.iter().position(|a| a == "--noise").map_or(0.12, |i| args[i + 1].parse().expect(usage));
    let grey = args.iter().any(|a| a == "--grey");
    let channels = if alpha { 4 } else { 3 };
    let row = |y: u32| -> Vec<u16> {
        let mut r = Vec::with_capacity(w as usize * channels);
        for x in 0..w {
            let t = texel(x, y, w, h, noise);
            if grey {
                let luma = ((t[0] as u32 * 299 + t[1] as u32 * 587 + t[2] as u32 * 114) / 1000) as u16;
                r.push(luma);
                if alpha {
                    r.push(t[3]);
                }
            } else {
                r.extend_from_slice(&t[..channels]);
            }
        }
        r
    };
    let file = BufWriter::with_capacity(1 << 20, File::create(&out).expect("create output"));
    if out.ends_with(".tif") || out.ends_with(".tiff") {
        assert!(!grey, "TIFF output is RGB(A) only");
        write_tiff(file, w, h, alpha, wide, row);
    } else if out.ends_with(".png") {
        let mut enc = png::Encoder::new(file, w, h);
        enc.set_color(match (grey, alpha) {
            (true, false) => png::ColorType::Grayscale,
            (true, true) => png::ColorType::GrayscaleAlpha,
            (false, false) => png::ColorType::Rgb,
            (false, true) => png::ColorType::Rgba,
        });
        enc.set_depth(if wide { png::BitDepth::Sixteen } else { png::BitDepth::Eight });
        enc.set_compression(png::Compression::High);
        let mut writer = enc.write_header().unwrap();
        let mut stream = writer.stream_writer().unwrap();
        for y in 0..h {
            stream.write_all(&bytes(&row(y), wide, true)).unwrap();
        }
        stream.finish().unwrap();
    } else if out.ends_with(".ppm") {
        assert!(!alpha && !grey, "PPM output is RGB only");
        let mut f = file;
        write!(f, "P6\n{w} {h}\n{}\n", if wide { 65535 } else { 255 }).unwrap();
        for y in 0..h {
            f.write_all(&bytes(&row(y), wide, true)).unwrap();
        }
    } else {
        panic!("{usage}");
    }
}

fn bytes(samples: &[u16], wide: bool, big_endian: bool) -> Vec<u8> {
    if wide {
        samples.iter().flat_map(|s| if big_endian { s.to_be_bytes() } else { s.to_le_bytes() }).collect()
    } else {
        samples.iter().map(|s| (s >> 8) as u8).collect()
    }
}

fn write_tiff(file: BufWriter<File>, w: u32, h: u32, alpha: bool, wide: bool, row: impl Fn(u32) -> Vec<u16>) {
    use tiff::encoder::{TiffEncoder, colortype};
    let mut enc = TiffEncoder::new_big(file).unwrap();
    let strip = 64u32;
    macro_rules! write {
        ($ct:ty, $conv:expr) => {{
            let mut img = enc.new_image::<$ct>(w, h).unwrap();
            img.rows_per_strip(strip).unwrap();
            let mut y = 0;
            while img.next_strip_sample_count() > 0 {
                let mut data = Vec::new();
                for yy in y..(y + strip).min(h) {
                    data.extend(row(yy).into_iter().map($conv));
                }
                img.write_strip(&data).unwrap();
                y += strip;
            }
            img.finish().unwrap();
        }};
    }
    match (alpha, wide) {
        (false, false) => write!(colortype::RGB8, |s: u16| (s >> 8) as u8),
        (true, false) => write!(colortype::RGBA8, |s: u16| (s >> 8) as u8),
        (false, true) => write!(colortype::RGB16, |s: u16| s),
        (true, true) => write!(colortype::RGBA16, |s: u16| s),
    }
}

/// 16-bit RGBA at (x, y).
fn texel(x: u32, y: u32, w: u32, h: u32, noise_amp: f64) -> [u16; 4] {
    let (fx, fy) = (x as f64 / w as f64, y as f64 / h as f64);
    // Zone plate centred in the image: frequency rises with the distance from the centre.
    let (dx, dy) = (fx - 0.5, fy - 0.5);
    let zone = (0.5 + 0.5 * ((dx * dx + dy * dy) * w.min(h) as f64 * 1.5).cos()) * 0.35;
    let noise = (hash(x, y) & 0xffff) as f64 / 65535.0 * noise_amp;
    // A grid of hard-edged discs every 1/8 of the image.
    let (cx, cy) = ((fx * 8.0).fract() - 0.5, (fy * 8.0).fract() - 0.5);
    let disc = if cx * cx + cy * cy < 0.09 { 0.25 } else { 0.0 };
    let r = 0.55 * fx + zone + noise + disc;
    let g = 0.55 * fy + zone + noise * 0.8;
    let b = 0.55 * (1.0 - fx) + zone * 0.7 + noise * 0.6 + disc * 0.5;
    let a = if disc > 0.0 { 0.5 } else { 0.6 + 0.4 * fx };
    let q = |v: f64| (v.clamp(0.0, 1.0) * 65535.0).round() as u16;
    [q(r), q(g), q(b), q(a)]
}

fn hash(x: u32, y: u32) -> u32 {
    let mut h = x.wrapping_mul(0x9E37_79B1) ^ y.wrapping_mul(0x85EB_CA77);
    h ^= h >> 15;
    h = h.wrapping_mul(0x2C1B_3C6D);
    h ^= h >> 12;
    h
}
