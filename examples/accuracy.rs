//! What accuracy costs in time and size: every LOD filter and tile codec on a few synthetic test
//! images, against a float64 reference pyramid. A benchmark, not a test.
//!
//!     cargo run --release --example accuracy                    # writes docs/accuracy.md + plots
//!     cargo run --release --example accuracy -- --runs 3 --size 512x500 --out /tmp/acc
//!
//! Four deterministic 8-bit images (photo-like, high-frequency, text and line art, RGBA cut-outs
//! over transparent garbage) are split in memory through the real pipeline (`split::split`,
//! the pack sink, a temporary pack file), once per LOD filter (with lossless PNG fast and raw
//! tiles) and once per codec setting (with the default filter). Each split is timed (median
//! of the runs, interleaved over all choices), the pack's tiles are decoded with `vortex_pack`
//! and every texel of every LOD is compared with a float64 reference computed from the source:
//! the alpha-premultiplied mean in linear light over the texel's footprint (real pixels only).
//! Writes `docs/accuracy.md` (tables, defaults) and `docs/accuracy-time.svg`,
//! `docs/accuracy-size.svg` (error against time and against size, Pareto fronts).

use std::collections::BTreeMap;
use std::f64::consts::{FRAC_PI_6, TAU};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use plotters::prelude::*;
use vortex_pack::{Pack, Tile, WriteOptions, decode_rgba8};
use vortex_tiler::background::Background;
use vortex_tiler::codec::{Bc7Effort, Codec, PngLevel, Subsampling};
use vortex_tiler::error::Result as TilerResult;
use vortex_tiler::filter::Filter;
use vortex_tiler::layout::Layout;
use vortex_tiler::pack_sink::PackSink;
use vortex_tiler::pixel::{Channels, Depth, PixelLayout};
use vortex_tiler::settings::{self, CodecChoice, Requested};
use vortex_tiler::source::{ImageHeader, RowSource};
use vortex_tiler::split::{self, SplitOptions};

#[path = "common/run_info.rs"]
mod run_info;
use run_info::{load_average, machine, today, write_atomically};

/// Stored tile side and border: the README's first command (id Tech 5's 120-texel payload).
const TILE_SIZE: u32 = 128;
const BORDER: u32 = 4;
/// Default image size: 8 x 8 payloads of 120 texels hold it (4 LODs), and neither side is a
/// multiple of 8, so the last column and row of texels of LODs 1-3 have partial footprints.
const DEFAULT_SIZE: (u32, u32) = (950, 930);
/// Runs per choice; choices slower than `SLOW_RUN_S` per run stop after `SLOW_RUNS`.
const DEFAULT_RUNS: usize = 9;
const SLOW_RUNS: usize = 3;
const SLOW_RUN_S: f64 = 0.75;
/// No round starts after this many seconds of timing (the whole run should stay near 6 min).
const TIME_BUDGET_S: f64 = 270.0;
/// PSNR shown for an exact match (no error at all) in plots.
const PSNR_CAP: f64 = 99.0;

const FILTERS: [Filter; 6] = Filter::ALL;

// ---------------------------------------------------------------------------------------------
// Images

/// An 8-bit image in memory, RGB or RGBA, rows top down.
struct Img {
    key: &'static str,
    title: &'static str,
    what: &'static str,
    width: u32,
    height: u32,
    channels: usize,
    data: Arc<Vec<u8>>,
}

impl Img {
    fn layout(&self) -> PixelLayout {
        PixelLayout::new(if self.channels == 4 { Channels::Rgba } else { Channels::Rgb }, Depth::U8)
    }

    fn has_alpha(&self) -> bool {
        self.channels == 4
    }

    fn source(&self) -> MemSource {
        let header = ImageHeader { width: self.width, height: self.height, layout: self.layout() };
        MemSource { header, data: self.data.clone(), next: 0 }
    }

    fn megapixels(&self) -> f64 {
        self.width as f64 * self.height as f64 / 1e6
    }

    /// Builds an image from a function of (x, y) giving RGBA in [0, 255] (alpha ignored for RGB).
    fn from_fn(w: u32, h: u32, channels: usize, f: impl Fn(u32, u32) -> [f64; 4]) -> Vec<u8> {
        let mut data = Vec::with_capacity(w as usize * h as usize * channels);
        for y in 0..h {
            for x in 0..w {
                let px = f(x, y);
                data.extend(px[..channels].iter().map(|v| v.round().clamp(0.0, 255.0) as u8));
            }
        }
        data
    }
}

/// The image as the pipeline reads it, one row at a time.
struct MemSource {
    header: ImageHeader,
    data: Arc<Vec<u8>>,
    next: usize,
}

impl RowSource for MemSource {
    fn header(&self) -> ImageHeader {
        self.header
    }
    fn read_row(&mut self, row: &mut [u8]) -> TilerResult<()> {
        let n = row.len();
        row.copy_from_slice(&self.data[self.next * n..(self.next + 1) * n]);
        self.next += 1;
        Ok(())
    }
    fn describe(&self) -> String {
        "memory".into()
    }
}

/// A 64-bit mix of integer coordinates and a seed (splitmix64's finaliser).
fn hash(x: i64, y: i64, seed: u64) -> u64 {
    let mut h = (x as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
        ^ (y as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F)
        ^ seed.wrapping_mul(0x1656_67B1_9E37_79F9);
    h ^= h >> 30;
    h = h.wrapping_mul(0xBF58_476D_1CE4_E5B9);
    h ^= h >> 27;
    h = h.wrapping_mul(0x94D0_49BB_1331_11EB);
    h ^ (h >> 31)
}

/// Uniform in [0, 1) from a hash.
fn unit(h: u64) -> f64 {
    (h >> 11) as f64 / (1u64 << 53) as f64
}

/// Value noise in [0, 1]: hashed lattice values, smoothstep-interpolated.
fn value_noise(x: f64, y: f64, seed: u64) -> f64 {
    let (ix, iy) = (x.floor(), y.floor());
    let (fx, fy) = (x - ix, y - iy);
    let (sx, sy) = (fx * fx * (3.0 - 2.0 * fx), fy * fy * (3.0 - 2.0 * fy));
    let (ix, iy) = (ix as i64, iy as i64);
    let v = |dx: i64, dy: i64| unit(hash(ix + dx, iy + dy, seed));
    let top = v(0, 0) + (v(1, 0) - v(0, 0)) * sx;
    let bottom = v(0, 1) + (v(1, 1) - v(0, 1)) * sx;
    top + (bottom - top) * sy
}

/// Fractal (fBm) value noise in [0, 1]: `octaves` octaves, each twice the frequency and half
/// the amplitude of the previous one.
fn fbm(x: f64, y: f64, seed: u64, octaves: u32) -> f64 {
    let (mut sum, mut amp, mut freq, mut norm) = (0.0, 1.0, 1.0, 0.0);
    for o in 0..octaves {
        sum += amp * value_noise(x * freq, y * freq, seed.wrapping_add(o as u64 * 7919));
        norm += amp;
        amp *= 0.5;
        freq *= 2.0;
    }
    sum / norm
}

fn mix(a: [f64; 3], b: [f64; 3], t: f64) -> [f64; 3] {
    let t = t.clamp(0.0, 1.0);
    [a[0] + (b[0] - a[0]) * t, a[1] + (b[1] - a[1]) * t, a[2] + (b[2] - a[2]) * t]
}

fn rgba(c: [f64; 3], a: f64) -> [f64; 4] {
    [c[0], c[1], c[2], a]
}

/// Coverage of a pixel centre at signed distance `d` inside an edge (1-pixel anti-aliasing).
fn coverage(d: f64) -> f64 {
    (d + 0.5).clamp(0.0, 1.0)
}

/// Distance from (px, py) to the segment (ax, ay)-(bx, by).
fn segment_distance(px: f64, py: f64, a: (f64, f64), b: (f64, f64)) -> f64 {
    let (dx, dy) = (b.0 - a.0, b.1 - a.1);
    let len2 = dx * dx + dy * dy;
    let t = if len2 == 0.0 { 0.0 } else { (((px - a.0) * dx + (py - a.1) * dy) / len2).clamp(0.0, 1.0) };
    ((px - a.0 - t * dx).powi(2) + (py - a.1 - t * dy).powi(2)).sqrt()
}

/// Smooth sky, fractal ground texture, a shaded sphere, a building with a grid of windows,
/// sensor grain: smooth areas, texture and hard edges.
fn photo(w: u32, h: u32) -> Img {
    let (wf, hf) = (w as f64, h as f64);
    let data = Img::from_fn(w, h, 3, |x, y| {
        let (xf, yf) = (x as f64 + 0.5, y as f64 + 0.5);
        let horizon = hf * (0.40 + 0.10 * fbm(xf / 170.0, 3.5, 11, 4));
        let mut c = if yf < horizon {
            let sky = mix([60.0, 105.0, 190.0], [205.0, 220.0, 238.0], yf / horizon);
            let cloud = ((fbm(xf / 140.0, yf / 55.0, 12, 5) - 0.5) * 4.0).clamp(0.0, 1.0);
            mix(sky, [245.0, 245.0, 250.0], cloud * 0.85)
        } else {
            let t = fbm(xf / 45.0, yf / 30.0, 13, 6);
            let fine = value_noise(xf / 1.7, yf / 1.7, 14);
            let ground = mix([70.0, 95.0, 40.0], [150.0, 125.0, 70.0], t * 1.4 - 0.2);
            let shade = 0.75 + 0.5 * (yf - horizon) / (hf - horizon);
            let g = mix(ground, [30.0, 40.0, 20.0], 0.35 * fine);
            [g[0] * shade, g[1] * shade, g[2] * shade]
        };
        // A building: flat facade, dark windows every 9 texels (regular fine detail).
        let (bx0, bx1, by0) = (0.10 * wf, 0.29 * wf, 0.22 * hf);
        if xf >= bx0 && xf < bx1 && yf >= by0 && yf < horizon + 12.0 {
            let (lx, ly) = ((xf - bx0) as i64, (yf - by0) as i64);
            c = if lx % 9 >= 2 && lx % 9 < 7 && ly % 12 >= 3 && ly % 12 < 9 {
                [35.0, 40.0, 55.0]
            } else {
                mix([175.0, 165.0, 150.0], [120.0, 112.0, 100.0], (xf - bx0) / (bx1 - bx0))
            };
        }
        // A lit sphere with an anti-aliased silhouette.
        let (cx, cy, r) = (0.68 * wf, 0.64 * hf, 0.15 * wf);
        let (dx, dy) = ((xf - cx) / r, (yf - cy) / r);
        let d2 = dx * dx + dy * dy;
        let cov = coverage((1.0 - d2.sqrt()) * r);
        if cov > 0.0 {
            let nz = (1.0 - d2).max(0.0).sqrt();
            let lambert = (-0.5 * dx - 0.6 * dy + 0.62 * nz).max(0.0);
            let spec = lambert.powf(40.0);
            let s = [40.0 + 180.0 * lambert + 120.0 * spec, 25.0 + 50.0 * lambert + 120.0 * spec, 30.0 + 120.0 * spec];
            c = mix(c, s, cov);
        }
        let grain = (unit(hash(x as i64, y as i64, 15)) - 0.5) * 6.0;
        rgba([c[0] + grain, c[1] + grain, c[2] + grain], 255.0)
    });
    Img {
        key: "photo",
        title: "Photo-like",
        what: "sky gradient with fractal clouds, fractal ground texture, a shaded sphere, a building with a 9-texel window grid, sensor grain",
        width: w,
        height: h,
        channels: 3,
        data: Arc::new(data),
    }
}

/// Zone plate, one-texel checkers and stripes (black/white and colour), one-texel lines, a
/// near-Nyquist grating and a Siemens star: detail at and beyond what a LOD can hold.
fn high_frequency(w: u32, h: u32) -> Img {
    let (qw, qh) = (w / 2, h / 2);
    let data = Img::from_fn(w, h, 3, |x, y| {
        let (xf, yf) = (x as f64 + 0.5, y as f64 + 0.5);
        let grey = |v: f64| rgba([v, v, v], 255.0);
        match (x < qw, y < qh) {
            (true, true) => {
                // Zone plate: local frequency r / n cycles per texel, 0.5 at the inscribed circle.
                let (dx, dy) = (xf - qw as f64 / 2.0, yf - qh as f64 / 2.0);
                let n = qw.min(qh) as f64;
                grey(127.5 + 127.5 * (std::f64::consts::PI * (dx * dx + dy * dy) / n).cos())
            }
            (false, true) => {
                let (lx, ly) = (x - qw, y);
                match 4 * lx / (w - qw) {
                    0 => grey(if (lx + ly) % 2 == 0 { 0.0 } else { 255.0 }),
                    1 => rgba(if (lx + ly) % 2 == 0 { [255.0, 0.0, 0.0] } else { [0.0, 255.0, 0.0] }, 255.0),
                    2 => grey(if (lx / 2 + ly / 2) % 2 == 0 { 0.0 } else { 255.0 }),
                    _ => rgba(if lx % 2 == 0 { [0.0, 0.0, 255.0] } else { [255.0, 255.0, 0.0] }, 255.0),
                }
            }
            (true, false) => {
                let ly = y - qh;
                let band = 5 * ly / (h - qh);
                let on = match band {
                    0 => ly % 2 == 0,
                    1 => ly % 3 == 0,
                    2 => x % 4 == 0,
                    3 => (x + ly) % 5 == 0,
                    _ => x % 7 != 0,
                };
                grey(if on { 0.0 } else { 255.0 })
            }
            (false, false) => {
                let (lx, ly) = (xf - qw as f64, yf - qh as f64);
                if lx < (w - qw) as f64 / 2.0 {
                    // A diagonal grating at 0.45 cycles per texel, magenta/cyan.
                    let t = 0.5 + 0.5 * (2.0 * std::f64::consts::PI * 0.45 * (lx * 0.866 + ly * 0.5)).cos();
                    rgba(mix([255.0, 0.0, 255.0], [0.0, 255.0, 255.0], t), 255.0)
                } else {
                    // Siemens star, 72 spokes.
                    let (cx, cy) = ((w - qw) as f64 * 0.75, (h - qh) as f64 / 2.0);
                    let a = (ly - cy).atan2(lx - cx);
                    grey(if (a * 36.0 / std::f64::consts::PI).rem_euclid(2.0) < 1.0 { 10.0 } else { 245.0 })
                }
            }
        }
    });
    Img {
        key: "high-frequency",
        title: "High-frequency",
        what: "zone plate up to 0.5 cycles/texel, 1-texel black/white and red/green checkers, 2-texel checker, blue/yellow 1-texel stripes, 1-texel lines every 2-7 texels, a magenta/cyan grating at 0.45 cycles/texel, a 72-spoke Siemens star",
        width: w,
        height: h,
        channels: 3,
        data: Arc::new(data),
    }
}

/// A stroke: segment from `a` to `b`, `width` texels wide.
struct Stroke {
    a: (f64, f64),
    b: (f64, f64),
    width: f64,
    ink: [f64; 3],
}

/// Rows of glyph-like shapes (stems, bars, diagonals, bowls, dots) from 7 to 56 texels tall,
/// and line art (a fan of 1-texel lines, concentric rings, hatching), anti-aliased, on paper.
fn text_art(w: u32, h: u32) -> Img {
    let (wf, hf) = (w as f64, h as f64);
    let mut strokes: Vec<Stroke> = Vec::new();
    let text_right = 0.62 * wf;
    let mut y = 8.0;
    let sizes = [7.0, 9.0, 12.0, 16.0, 20.0, 28.0, 40.0, 56.0];
    let mut row = 0u64;
    while y < hf - 10.0 {
        let s: f64 = sizes[row as usize % sizes.len()];
        let ink = match row % 5 {
            3 => [20.0, 40.0, 120.0],
            4 => [170.0, 25.0, 20.0],
            _ => [22.0, 22.0, 28.0],
        };
        let width = (s / 9.0).max(1.0);
        let mut x = 6.0;
        let mut i = 0u64;
        while x + 0.7 * s < text_right {
            let r = |k: u64| unit(hash(row as i64, (i * 16 + k) as i64, 21));
            let (x0, x1, y0, y1) = (x + 0.1 * s, x + 0.6 * s, y + 0.05 * s, y + 0.95 * s);
            if r(0) < 0.12 {
                // A space.
                x += 0.5 * s;
                i += 1;
                continue;
            }
            let mut add = |a: (f64, f64), b: (f64, f64)| strokes.push(Stroke { a, b, width, ink });
            let stem = x0 + (x1 - x0) * (r(1) * 0.8).round().min(1.0);
            add((stem, y0 + 0.25 * s * (r(2) < 0.3) as u8 as f64), (stem, y1));
            if r(3) < 0.6 {
                let by = y0 + (y1 - y0) * (0.35 + 0.4 * r(4));
                add((x0, by), (x1, by));
            }
            if r(5) < 0.35 {
                add((x0, y1), (x1, y0 + 0.3 * s));
            }
            if r(6) < 0.45 {
                // A bowl as a 12-sided polygon.
                let (cx, cy, rr) = ((x0 + x1) / 2.0, y1 - 0.22 * s, 0.22 * s);
                for k in 0..12 {
                    let (a0, a1) = (k as f64 * FRAC_PI_6, (k + 1) as f64 * FRAC_PI_6);
                    add((cx + rr * a0.cos(), cy + rr * a0.sin()), (cx + rr * a1.cos(), cy + rr * a1.sin()));
                }
            }
            if r(7) < 0.15 {
                add((x0, y0), (x0 + 0.01, y0));
            }
            x += 0.72 * s;
            i += 1;
        }
        y += s * 1.35 + 2.0;
        row += 1;
    }
    // Line art right of the text: a fan of 1-texel lines, rings, hatching.
    let art = [22.0, 22.0, 28.0];
    let (fx, fy) = (text_right + 15.0, 0.06 * hf);
    for k in 0..48 {
        let a = k as f64 * std::f64::consts::FRAC_PI_2 / 47.0;
        let len = 0.36 * wf;
        strokes.push(Stroke { a: (fx, fy), b: (fx + len * a.cos(), fy + len * a.sin()), width: 1.0, ink: art });
    }
    let (cx, cy) = (text_right + 0.19 * wf, 0.62 * hf);
    for k in 1..40 {
        let rr = k as f64 * 3.3;
        for j in 0..64 {
            let (a0, a1) = (j as f64 * TAU / 64.0, (j + 1) as f64 * TAU / 64.0);
            let ink = if k % 10 == 0 { [170.0, 25.0, 20.0] } else { art };
            strokes.push(Stroke {
                a: (cx + rr * a0.cos(), cy + rr * a0.sin()),
                b: (cx + rr * a1.cos(), cy + rr * a1.sin()),
                width: 1.0,
                ink,
            });
        }
    }
    for k in 0..60 {
        let x0 = text_right + 10.0 + k as f64 * 5.5;
        strokes.push(Stroke { a: (x0, 0.88 * hf), b: (x0 + 40.0, 0.98 * hf), width: 1.2, ink: art });
    }
    // Rasterise: paper, then each stroke blended by its coverage, in order.
    let paper = [250.0, 248.0, 240.0];
    let mut canvas: Vec<[f64; 3]> = vec![paper; w as usize * h as usize];
    for s in &strokes {
        let pad = s.width / 2.0 + 1.0;
        let (xa, xb) = ((s.a.0.min(s.b.0) - pad).max(0.0) as u32, ((s.a.0.max(s.b.0) + pad) as u32).min(w - 1));
        let (ya, yb) = ((s.a.1.min(s.b.1) - pad).max(0.0) as u32, ((s.a.1.max(s.b.1) + pad) as u32).min(h - 1));
        for py in ya..=yb {
            for px in xa..=xb {
                let d = segment_distance(px as f64 + 0.5, py as f64 + 0.5, s.a, s.b);
                let cov = coverage(s.width / 2.0 - d);
                if cov > 0.0 {
                    let c = &mut canvas[py as usize * w as usize + px as usize];
                    *c = mix(*c, s.ink, cov);
                }
            }
        }
    }
    let data = Img::from_fn(w, h, 3, |x, y| rgba(canvas[y as usize * w as usize + x as usize], 255.0));
    Img {
        key: "text",
        title: "Text and line art",
        what: "rows of anti-aliased glyph-like shapes 7-56 texels tall (dark grey, blue, red) on off-white paper; a fan of 48 one-texel lines, 39 thin rings, hatching",
        width: w,
        height: h,
        channels: 3,
        data: Arc::new(data),
    }
}

/// Opaque textured shapes with anti-aliased edges (and one half-transparent disc, and 1-2
/// texel wires) over a fully transparent background whose colour is random garbage (or black,
/// with `clean`).
fn alpha_cutouts(w: u32, h: u32, clean: bool) -> Img {
    let (wf, hf) = (w as f64, h as f64);
    // Shapes: signed distance (positive inside), opacity, colour.
    type Shape = (Box<dyn Fn(f64, f64) -> f64>, f64, [f64; 3]);
    let disc = |cx: f64, cy: f64, r: f64| -> Box<dyn Fn(f64, f64) -> f64> {
        Box::new(move |x, y| r - ((x - cx).powi(2) + (y - cy).powi(2)).sqrt())
    };
    let rounded = |x0: f64, y0: f64, x1: f64, y1: f64, r: f64| -> Box<dyn Fn(f64, f64) -> f64> {
        Box::new(move |x, y| {
            let (cx, cy, hx, hy) = ((x0 + x1) / 2.0, (y0 + y1) / 2.0, (x1 - x0) / 2.0 - r, (y1 - y0) / 2.0 - r);
            let (qx, qy) = ((x - cx).abs() - hx, (y - cy).abs() - hy);
            let outside = (qx.max(0.0).powi(2) + qy.max(0.0).powi(2)).sqrt();
            r - outside - qx.max(qy).min(0.0)
        })
    };
    let ring = |cx: f64, cy: f64, r: f64, t: f64| -> Box<dyn Fn(f64, f64) -> f64> {
        Box::new(move |x, y| t / 2.0 - (((x - cx).powi(2) + (y - cy).powi(2)).sqrt() - r).abs())
    };
    let wire = |a: (f64, f64), b: (f64, f64), t: f64| -> Box<dyn Fn(f64, f64) -> f64> {
        Box::new(move |x, y| t / 2.0 - segment_distance(x, y, a, b))
    };
    let shapes: Vec<Shape> = vec![
        (disc(0.27 * wf, 0.30 * hf, 0.19 * wf), 1.0, [215.0, 60.0, 40.0]),
        (rounded(0.52 * wf, 0.08 * hf, 0.93 * wf, 0.40 * hf, 0.05 * wf), 1.0, [40.0, 150.0, 90.0]),
        (ring(0.70 * wf, 0.70 * hf, 0.17 * wf, 0.045 * wf), 1.0, [235.0, 200.0, 60.0]),
        (rounded(0.08 * wf, 0.60 * hf, 0.45 * wf, 0.93 * hf, 0.012 * wf), 1.0, [60.0, 90.0, 200.0]),
        (disc(0.40 * wf, 0.52 * hf, 0.11 * wf), 0.5, [250.0, 250.0, 250.0]),
        (wire((0.05 * wf, 0.50 * hf), (0.95 * wf, 0.47 * hf), 1.0), 1.0, [20.0, 20.0, 20.0]),
        (wire((0.50 * wf, 0.95 * hf), (0.97 * wf, 0.55 * hf), 2.0), 1.0, [230.0, 230.0, 230.0]),
        (wire((0.03 * wf, 0.05 * hf), (0.45 * wf, 0.57 * hf), 1.5), 1.0, [120.0, 30.0, 160.0]),
    ];
    let data = Img::from_fn(w, h, 4, |x, y| {
        let (xf, yf) = (x as f64 + 0.5, y as f64 + 0.5);
        // Premultiplied "over" of the shapes in order, then straight alpha.
        let (mut pc, mut pa) = ([0.0f64; 3], 0.0f64);
        for (i, (sdf, opacity, colour)) in shapes.iter().enumerate() {
            let a = coverage(sdf(xf, yf)) * opacity;
            if a > 0.0 {
                let tex = 0.75 + 0.5 * fbm(xf / 23.0, yf / 23.0, 31 + i as u64, 5);
                let light = 0.8 + 0.2 * (1.0 - yf / hf);
                for ch in 0..3 {
                    pc[ch] = (colour[ch] * tex * light).min(255.0) * a + pc[ch] * (1.0 - a);
                }
                pa = a + pa * (1.0 - a);
            }
        }
        let alpha = (pa * 255.0).round();
        if alpha == 0.0 && clean {
            return [0.0; 4];
        }
        if alpha == 0.0 {
            let g = hash(x as i64, y as i64, 99);
            return [(g & 255) as f64, ((g >> 8) & 255) as f64, ((g >> 16) & 255) as f64, 0.0];
        }
        let a = alpha / 255.0;
        [pc[0] / a, pc[1] / a, pc[2] / a, alpha]
    });
    Img {
        key: if clean { "alpha-clean" } else { "alpha" },
        title: if clean { "Alpha cut-outs, black under alpha 0" } else { "Alpha cut-outs" },
        what: if clean {
            "the same, with colour 0 (black) wherever alpha is 0"
        } else {
            "RGBA: textured opaque disc, rounded rectangles and ring with anti-aliased edges, a 50%-transparent disc, wires 1-2 texels wide, over a fully transparent background (alpha 0) whose colour is random noise"
        },
        width: w,
        height: h,
        channels: 4,
        data: Arc::new(data),
    }
}

// ---------------------------------------------------------------------------------------------
// Reference pyramid

/// sRGB decode of a code value in [0, 1] (IEC 61966-2-1).
fn to_linear(v: f64) -> f64 {
    if v <= 0.04045 { v / 12.92 } else { ((v + 0.055) / 1.055).powf(2.4) }
}

/// sRGB encode of linear light in [0, 1].
fn to_srgb(l: f64) -> f64 {
    let l = l.clamp(0.0, 1.0);
    if l <= 0.003_130_8 { l * 12.92 } else { 1.055 * l.powf(1.0 / 2.4) - 0.055 }
}

/// Float sums over a texel's footprint of real source pixels: everything each filter's
/// definition and the physical reference need.
#[derive(Clone, Copy, Default)]
struct Sums {
    /// Pixels.
    n: f64,
    /// Alpha, in code values.
    a: f64,
    /// Colour code values.
    code: [f64; 3],
    /// Linear light in [0, 1].
    lin: [f64; 3],
    /// Code x alpha code.
    code_a: [f64; 3],
    /// Linear x alpha code.
    lin_a: [f64; 3],
}

impl Sums {
    fn pixel(px: &[u8], lut: &[f64; 256]) -> Sums {
        let a = if px.len() == 4 { px[3] as f64 } else { 255.0 };
        let mut s = Sums { n: 1.0, a, ..Sums::default() };
        for c in 0..3 {
            let (v, l) = (px[c] as f64, lut[px[c] as usize]);
            s.code[c] = v;
            s.lin[c] = l;
            s.code_a[c] = v * a;
            s.lin_a[c] = l * a;
        }
        s
    }

    fn add(&mut self, o: &Sums) {
        self.n += o.n;
        self.a += o.a;
        for c in 0..3 {
            self.code[c] += o.code[c];
            self.lin[c] += o.lin[c];
            self.code_a[c] += o.code_a[c];
            self.lin_a[c] += o.lin_a[c];
        }
    }

    /// The physical reference: the premultiplied linear-light mean, shown over black, as sRGB
    /// code values (for opaque texels simply the linear-light mean encoded), and mean alpha.
    fn shown(&self) -> ([f64; 3], f64) {
        let c = self.lin_a.map(|v| 255.0 * to_srgb(v / (255.0 * self.n)));
        (c, self.a / self.n)
    }

    /// What an exact filter's own definition gives, unrounded: straight colour and alpha.
    fn own(&self, filter: Filter, has_alpha: bool) -> [f64; 4] {
        let premultiplied = has_alpha && matches!(filter, Filter::Premultiplied | Filter::LinearPremultiplied);
        let linear = matches!(filter, Filter::Linear | Filter::LinearPremultiplied);
        let mut out = [0.0, 0.0, 0.0, self.a / self.n];
        for (c, o) in out.iter_mut().take(3).enumerate() {
            *o = match (premultiplied, linear) {
                (true, _) if self.a == 0.0 => 0.0,
                (true, true) => 255.0 * to_srgb(self.lin_a[c] / self.a),
                (true, false) => self.code_a[c] / self.a,
                (false, true) => 255.0 * to_srgb(self.lin[c] / self.n),
                (false, false) => self.code[c] / self.n,
            };
        }
        out
    }
}

/// One reference level: its sums (LODs 1 and up) and the physical reference, shown over black.
struct RefLevel {
    width: u32,
    height: u32,
    sums: Vec<Sums>,
    shown: Vec<[f64; 3]>,
    alpha: Vec<f64>,
}

/// The float64 reference pyramid of `img`: LOD k's texel sums its whole footprint of real
/// source pixels, built level by level from exact children (as the tiler's cascade does).
fn reference(img: &Img, layout: &Layout, lut: &[f64; 256]) -> Vec<RefLevel> {
    let (w, h, c) = (img.width as usize, img.height as usize, img.channels);
    let level0: Vec<Sums> = img.data.chunks_exact(c).map(|px| Sums::pixel(px, lut)).collect();
    let finish = |width: u32, height: u32, sums: Vec<Sums>| {
        let (shown, alpha) = sums.iter().map(Sums::shown).unzip();
        RefLevel { width, height, sums, shown, alpha }
    };
    let mut levels = vec![finish(w as u32, h as u32, level0)];
    for lod in 1..layout.lod_count {
        let prev = levels.last().expect("LOD 0");
        let (pw, ph) = (prev.width as usize, prev.height as usize);
        let (lw, lh) = layout.level_extent(lod);
        let mut sums = vec![Sums::default(); lw as usize * lh as usize];
        for y in 0..lh as usize {
            for x in 0..lw as usize {
                let s = &mut sums[y * lw as usize + x];
                for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                    let (cx, cy) = (2 * x + dx, 2 * y + dy);
                    if cx < pw && cy < ph {
                        s.add(&prev.sums[cy * pw + cx]);
                    }
                }
            }
        }
        levels.push(finish(lw, lh, sums));
    }
    // LOD 0's sums are the source itself: not needed again.
    levels[0].sums = Vec::new();
    levels
}

// ---------------------------------------------------------------------------------------------
// Choices and measurements

/// One way to build the pyramid: a filter and a codec.
#[derive(Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Debug)]
struct Choice {
    filter: u8,
    codec: CodecKey,
}

/// A sortable stand-in for `Codec`.
#[derive(Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Debug)]
enum CodecKey {
    Jpeg(u8, bool),
    Png(u8),
    Raw,
    Zstd(bool, i32),
    Bc1,
    Bc7(u8),
}

const PNG_LEVELS: [PngLevel; 3] = [PngLevel::Fast, PngLevel::Default, PngLevel::Best];
const BC7_EFFORTS: [Bc7Effort; 5] =
    [Bc7Effort::UltraFast, Bc7Effort::VeryFast, Bc7Effort::Fast, Bc7Effort::Basic, Bc7Effort::Slow];

impl CodecKey {
    fn of(codec: Codec) -> CodecKey {
        match codec {
            Codec::Jpeg { quality, subsampling } => CodecKey::Jpeg(quality, subsampling == Subsampling::S444),
            Codec::Png { level } => CodecKey::Png(PNG_LEVELS.iter().position(|l| *l == level).unwrap_or(0) as u8),
            Codec::Raw => CodecKey::Raw,
            Codec::Zstd { level, delta } => CodecKey::Zstd(delta, level),
            Codec::Bc1 => CodecKey::Bc1,
            Codec::Bc7 { effort } => CodecKey::Bc7(BC7_EFFORTS.iter().position(|e| *e == effort).unwrap_or(0) as u8),
        }
    }

    fn codec(self) -> Codec {
        match self {
            CodecKey::Jpeg(quality, s444) => {
                Codec::Jpeg { quality, subsampling: if s444 { Subsampling::S444 } else { Subsampling::S420 } }
            }
            CodecKey::Png(l) => Codec::Png { level: PNG_LEVELS[l as usize] },
            CodecKey::Raw => Codec::Raw,
            CodecKey::Zstd(delta, level) => Codec::Zstd { level, delta },
            CodecKey::Bc1 => Codec::Bc1,
            CodecKey::Bc7(e) => Codec::Bc7 { effort: BC7_EFFORTS[e as usize] },
        }
    }

    fn label(self) -> String {
        match self {
            CodecKey::Jpeg(q, s444) => format!("jpeg q{q} {}", if s444 { "4:4:4" } else { "4:2:0" }),
            CodecKey::Png(l) => format!("png {}", ["fast", "default", "best"][l as usize]),
            CodecKey::Raw => "raw".into(),
            CodecKey::Zstd(false, l) => format!("zstd {l}"),
            CodecKey::Zstd(true, l) => format!("zstd-delta {l}"),
            CodecKey::Bc1 => "bc1".into(),
            CodecKey::Bc7(e) => format!("bc7 {}", ["ultra-fast", "very-fast", "fast", "basic", "slow"][e as usize]),
        }
    }

    /// Plot family.
    fn family(self) -> usize {
        match self {
            CodecKey::Jpeg(_, false) => 2,
            CodecKey::Jpeg(_, true) => 3,
            CodecKey::Png(_) => 4,
            CodecKey::Raw => 5,
            CodecKey::Zstd(false, _) => 6,
            CodecKey::Zstd(true, _) => 7,
            CodecKey::Bc1 => 8,
            CodecKey::Bc7(_) => 9,
        }
    }
}

impl Choice {
    fn new(filter: Filter, codec: Codec) -> Choice {
        let f = FILTERS.iter().position(|f| *f == filter).expect("a known filter") as u8;
        Choice { filter: f, codec: CodecKey::of(codec) }
    }

    fn filter(self) -> Filter {
        FILTERS[self.filter as usize]
    }

    fn label(self) -> String {
        if self.filter() == Filter::default() {
            self.codec.label()
        } else {
            format!("{} + {}", self.filter().name(), self.codec.label())
        }
    }

    /// Plot family: 0 other filters with PNG fast, 1 with raw, then the codec families (with
    /// the default filter), last other filters with JPEG.
    fn family(self) -> usize {
        match (self.filter(), self.codec) {
            (f, c) if f == Filter::default() => c.family(),
            (_, CodecKey::Raw) => 1,
            (_, CodecKey::Png(0)) => 0,
            _ => 10,
        }
    }
}

const FAMILIES: [&str; 11] = [
    "other filter + png fast",
    "other filter + raw",
    "jpeg 4:2:0",
    "jpeg 4:4:4",
    "png",
    "raw",
    "zstd",
    "zstd-delta",
    "bc1",
    "bc7",
    "other filter + jpeg",
];

/// Error of one LOD against a reference, over colour samples and alpha samples.
#[derive(Clone, Copy, Default)]
struct Err {
    sse: f64,
    samples: f64,
    max: f64,
    sse_a: f64,
    samples_a: f64,
    max_a: f64,
}

impl Err {
    fn add(&mut self, o: &Err) {
        self.sse += o.sse;
        self.samples += o.samples;
        self.max = self.max.max(o.max);
        self.sse_a += o.sse_a;
        self.samples_a += o.samples_a;
        self.max_a = self.max_a.max(o.max_a);
    }

    fn psnr(&self) -> f64 {
        psnr(self.sse, self.samples)
    }

    fn psnr_alpha(&self) -> f64 {
        psnr(self.sse_a, self.samples_a)
    }
}

fn psnr(sse: f64, samples: f64) -> f64 {
    if sse == 0.0 { f64::INFINITY } else { 10.0 * (255.0f64 * 255.0 * samples / sse).log10() }
}

/// What one choice gave on one image.
struct Measured {
    choice: Choice,
    times: Vec<f64>,
    bytes_per_tile: f64,
    /// Per LOD, against the physical reference.
    lods: Vec<Err>,
    /// Exact filters: largest difference from the filter's own float definition over LODs 1
    /// and up, colour and alpha.
    own_max: Option<(f64, f64)>,
}

impl Measured {
    fn median_s(&self) -> f64 {
        let mut t = self.times.clone();
        t.sort_by(f64::total_cmp);
        let n = t.len();
        if n % 2 == 1 { t[n / 2] } else { (t[n / 2 - 1] + t[n / 2]) / 2.0 }
    }

    /// How far the runs spread: (slowest - fastest) / median, leaving out the slowest and the
    /// fastest run when there are five or more.
    fn spread(&self) -> f64 {
        let mut t = self.times.clone();
        t.sort_by(f64::total_cmp);
        let n = t.len();
        let (lo, hi) = if n >= 5 { (t[1], t[n - 2]) } else { (t[0], t[n - 1]) };
        (hi - lo) / self.median_s()
    }

    fn ms_per_mpx(&self, img: &Img) -> f64 {
        1000.0 * self.median_s() / img.megapixels()
    }

    fn total(&self, range: std::ops::Range<usize>) -> Err {
        let mut e = Err::default();
        for l in &self.lods[range] {
            e.add(l);
        }
        e
    }

    fn all(&self) -> Err {
        self.total(0..self.lods.len())
    }

    fn coarse(&self) -> Err {
        self.total(1..self.lods.len())
    }

    /// The single error figure of the plots: colour (shown over black) PSNR over every texel
    /// of every LOD.
    fn plot_psnr(&self) -> f64 {
        self.all().psnr().min(PSNR_CAP)
    }
}

/// Runs one split into a pack at `dest`; returns its wall time in seconds.
fn split_once(img: &Img, layout: &Layout, choice: Choice, dest: &Path) -> Result<f64> {
    let codec = choice.codec.codec();
    let opts = SplitOptions {
        tile_size: TILE_SIZE,
        border: BORDER,
        codec,
        background: Background::Edge,
        flatten: false,
        tile_depth: None,
        filter: choice.filter(),
    };
    let stored = codec.stored_layout(img.layout(), false, None)?;
    let started = Instant::now();
    let sink = PackSink::create(dest, layout, stored, codec, b"{}", WriteOptions::default())?;
    let summary = split::split(Box::new(img.source()), &sink, &opts, &())?;
    sink.finish()?;
    let elapsed = started.elapsed().as_secs_f64();
    if summary.tiles != layout.total_tiles() {
        bail!("{} tiles of {}", summary.tiles, layout.total_tiles());
    }
    Ok(elapsed)
}

/// Decodes every tile of the pack that shows part of the image and compares each LOD with the
/// reference; `time` is the first run's.
fn measure(
    pack_path: &Path,
    img: &Img,
    layout: &Layout,
    refs: &[RefLevel],
    choice: Choice,
    shown_lut: &[[f64; 256]],
    time: f64,
) -> Result<Measured> {
    let pack = Pack::open(pack_path)?;
    let (p, b) = (layout.payload(), layout.border);
    let (mut bytes, mut tiles) = (0u64, 0u64);
    let mut lods = Vec::new();
    let filter = choice.filter();
    let mut own_max = filter.is_exact().then_some((0.0f64, 0.0f64));
    for (lod, r) in refs.iter().enumerate() {
        let (lw, lh) = (r.width, r.height);
        let mut texels = vec![0u8; lw as usize * lh as usize * 4];
        for ty in 0..lh.div_ceil(p) {
            for tx in 0..lw.div_ceil(p) {
                let lod = lod as u32;
                bytes += match pack.tile(lod, tx, ty)? {
                    Tile::Data(_, payload) => payload.len() as u64,
                    _ => 0,
                };
                tiles += 1;
                let rgba = decode_rgba8(&pack, lod, tx, ty)?.context("a tile is absent")?;
                for y in ty * p..((ty + 1) * p).min(lh) {
                    let src = (((y - ty * p + b) * TILE_SIZE + b) * 4) as usize;
                    let x0 = tx * p;
                    let n = (((tx + 1) * p).min(lw) - x0) as usize * 4;
                    let dst = ((y * lw + x0) * 4) as usize;
                    texels[dst..dst + n].copy_from_slice(&rgba[src..src + n]);
                }
            }
        }
        let mut e = Err::default();
        for (i, px) in texels.chunks_exact(4).enumerate() {
            let a = px[3] as usize;
            for ch in 0..3 {
                let d = shown_lut[a][px[ch] as usize] - r.shown[i][ch];
                e.sse += d * d;
                e.max = e.max.max(d.abs());
            }
            e.samples += 3.0;
            if img.has_alpha() {
                let d = px[3] as f64 - r.alpha[i];
                e.sse_a += d * d;
                e.max_a = e.max_a.max(d.abs());
                e.samples_a += 1.0;
            }
            if let (Some((mc, ma)), true) = (own_max.as_mut(), lod > 0) {
                let own = r.sums[i].own(filter, img.has_alpha());
                for ch in 0..3 {
                    *mc = mc.max((px[ch] as f64 - own[ch]).abs());
                }
                *ma = ma.max((px[3] as f64 - own[3]).abs());
            }
        }
        lods.push(e);
    }
    Ok(Measured { choice, times: vec![time], bytes_per_tile: bytes as f64 / tiles as f64, lods, own_max })
}

// ---------------------------------------------------------------------------------------------
// Main

struct Args {
    runs: usize,
    size: (u32, u32),
    out: PathBuf,
}

fn parse_args() -> Result<Args> {
    let mut a = Args {
        runs: DEFAULT_RUNS,
        size: DEFAULT_SIZE,
        out: PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/docs")),
    };
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mut it = args.iter();
    while let Some(flag) = it.next() {
        let mut value = || it.next().with_context(|| format!("{flag} needs a value"));
        match flag.as_str() {
            "--runs" => a.runs = value()?.parse().context("--runs")?,
            "--size" => {
                let v = value()?;
                let (w, h) = v.split_once('x').context("--size WxH")?;
                a.size = (w.parse().context("--size")?, h.parse().context("--size")?);
            }
            "--out" => a.out = PathBuf::from(value()?),
            _ => bail!("usage: accuracy [--runs N] [--size WxH] [--out DIR]"),
        }
    }
    if a.runs == 0 {
        bail!("--runs must be at least 1");
    }
    Ok(a)
}

/// The project's defaults, as `split` resolves them with no flags.
struct Defaults {
    opaque: SplitOptions,
    alpha: SplitOptions,
    zstd_level: i32,
    bc7: Codec,
}

fn defaults() -> Result<Defaults> {
    let rgb = PixelLayout::new(Channels::Rgb, Depth::U8);
    let rgba = PixelLayout::new(Channels::Rgba, Depth::U8);
    let none = Requested::default();
    let with = |codec| Requested { codec: Some(codec), ..Requested::default() };
    let zstd = settings::resolve(&with(CodecChoice::Zstd), None, rgb)?.0.codec;
    let bc7 = settings::resolve(&with(CodecChoice::Bc7), None, rgb)?.0.codec;
    Ok(Defaults {
        opaque: settings::resolve(&none, None, rgb)?.0,
        alpha: settings::resolve(&none, None, rgba)?.0,
        zstd_level: match zstd {
            Codec::Zstd { level, .. } => level,
            _ => bail!("zstd resolved to {}", zstd.name()),
        },
        bc7,
    })
}

/// Every codec setting measured (with the default filter).
fn codec_sweep() -> Vec<Codec> {
    let mut v = Vec::new();
    for quality in [50, 75, 85, 95] {
        for subsampling in [Subsampling::S420, Subsampling::S444] {
            v.push(Codec::Jpeg { quality, subsampling });
        }
    }
    v.extend(PNG_LEVELS.map(|level| Codec::Png { level }));
    v.push(Codec::Raw);
    for delta in [false, true] {
        for level in [1, 3, 9, 19] {
            v.push(Codec::Zstd { level, delta });
        }
    }
    v.push(Codec::Bc1);
    v.extend([Bc7Effort::UltraFast, Bc7Effort::VeryFast, Bc7Effort::Basic].map(|effort| Codec::Bc7 { effort }));
    v
}

struct ImageResult {
    img: Img,
    measured: BTreeMap<Choice, Measured>,
    /// A variant measured with a few choices only, for one table (not plotted).
    extra: bool,
}

/// Whether `choice` is measured on `img`: the codec must store its texels, and without alpha
/// `premultiplied` is `box` and `linear` is `linear-premultiplied` (the same code), so only
/// the latter of each pair runs.
fn applies(img: &Img, extra: bool, choice: Choice) -> bool {
    let codec = choice.codec.codec();
    if codec.stored_layout(img.layout(), false, None).is_err() {
        return false;
    }
    let filter = choice.filter();
    if !img.has_alpha() && matches!(filter, Filter::Premultiplied | Filter::Linear) {
        return false;
    }
    !extra
        || (filter.is_exact() && codec == Codec::Png { level: PngLevel::Fast })
        || (filter == Filter::default() && matches!(codec, Codec::Bc7 { .. }))
}

fn main() -> Result<()> {
    let args = parse_args()?;
    let started = Instant::now();
    let load_start = load_average();
    let defaults = defaults()?;
    let (w, h) = args.size;
    eprintln!("generating 5 images of {w}x{h}");
    let images = vec![
        (photo(w, h), false),
        (high_frequency(w, h), false),
        (text_art(w, h), false),
        (alpha_cutouts(w, h, false), false),
        (alpha_cutouts(w, h, true), true),
    ];
    let layout = Layout::new(w as u64, h as u64, TILE_SIZE, BORDER)?;
    let lut: [f64; 256] = std::array::from_fn(|c| to_linear(c as f64 / 255.0));
    // Shown colour of a stored (code, alpha): over black, as an sRGB code value.
    let shown_lut: Vec<[f64; 256]> =
        (0..256).map(|a| std::array::from_fn(|c| 255.0 * to_srgb(lut[c] * a as f64 / 255.0))).collect();

    let mut choices: Vec<Choice> = Vec::new();
    for codec in [Codec::Png { level: PngLevel::Fast }, Codec::Raw] {
        choices.extend(FILTERS.map(|f| Choice::new(f, codec)));
    }
    choices.extend(codec_sweep().into_iter().map(|c| Choice::new(defaults.opaque.filter, c)));
    // The default JPEG tiles with `box` (as vips averages): what changing only the filter gives.
    choices.push(Choice::new(Filter::Box, defaults.opaque.codec));
    choices.sort();
    choices.dedup();

    let tmp = tempfile::tempdir()?;
    let mut results: Vec<ImageResult> = Vec::new();
    let mut jobs: Vec<(usize, Choice)> = Vec::new();
    let mut refs = Vec::new();
    for (i, (img, extra)) in images.into_iter().enumerate() {
        eprintln!("reference pyramid of {} ({} LODs)", img.key, layout.lod_count);
        refs.push(reference(&img, &layout, &lut));
        jobs.extend(choices.iter().filter(|c| applies(&img, extra, **c)).map(|c| (i, *c)));
        results.push(ImageResult { img, measured: BTreeMap::new(), extra });
    }

    let timing_started = Instant::now();
    let mut rounds_done = 0;
    for round in 0..args.runs {
        if round > 0 && timing_started.elapsed().as_secs_f64() > TIME_BUDGET_S {
            eprintln!("time budget reached: stopping after {round} rounds");
            break;
        }
        let round_started = Instant::now();
        // A different order each round, so that load from elsewhere falls on every choice alike.
        let offset = round * jobs.len() / args.runs.max(1);
        for k in 0..jobs.len() {
            let (i, choice) = jobs[(k + offset) % jobs.len()];
            let r = &mut results[i];
            if let Some(m) = r.measured.get(&choice)
                && m.times.len() >= SLOW_RUNS
                && m.times[0] > SLOW_RUN_S
            {
                continue;
            }
            let dest = tmp.path().join(format!("{}-{round}-{k}.vtpk", r.img.key));
            let t = split_once(&r.img, &layout, choice, &dest).with_context(|| choice.label())?;
            match r.measured.get_mut(&choice) {
                Some(m) => m.times.push(t),
                None => {
                    let m = measure(&dest, &r.img, &layout, &refs[i], choice, &shown_lut, t)
                        .with_context(|| choice.label())?;
                    eprintln!(
                        "  {:<15} {:<34} {:>7.1} ms/Mpx {:>8.0} B/tile  PSNR {:>6.2} dB (LOD 0 {:>6.2}, LODs 1+ {:>6.2})",
                        r.img.key,
                        choice.label(),
                        m.ms_per_mpx(&r.img),
                        m.bytes_per_tile,
                        m.all().psnr(),
                        m.lods[0].psnr(),
                        m.coarse().psnr()
                    );
                    r.measured.insert(choice, m);
                }
            }
            std::fs::remove_file(&dest)?;
        }
        rounds_done = round + 1;
        eprintln!("round {}/{} done in {:.1} s", round + 1, args.runs, round_started.elapsed().as_secs_f64());
    }
    let load_end = load_average();

    std::fs::create_dir_all(&args.out)?;
    let run = RunInfo {
        args: &args,
        layout,
        rounds: rounds_done,
        load_start,
        load_end,
        seconds: started.elapsed().as_secs_f64(),
    };
    let plotted: Vec<&ImageResult> = results.iter().filter(|r| !r.extra).collect();
    for (name, axis) in [("accuracy-time.svg", Axis::Time), ("accuracy-size.svg", Axis::Size)] {
        let svg = plot(&plotted, axis, &defaults)?;
        write_atomically(&args.out.join(name), svg.as_bytes()).with_context(|| name.to_string())?;
    }
    let doc = document(&results, &defaults, &run);
    let path = args.out.join("accuracy.md");
    write_atomically(&path, doc.as_bytes()).with_context(|| path.display().to_string())?;
    eprintln!("wrote {} and its plots in {:.0} s", path.display(), started.elapsed().as_secs_f64());
    Ok(())
}

// ---------------------------------------------------------------------------------------------
// Plots

#[derive(Clone, Copy, PartialEq)]
enum Axis {
    Time,
    Size,
}

impl Axis {
    fn value(self, m: &Measured, img: &Img) -> f64 {
        match self {
            Axis::Time => m.ms_per_mpx(img),
            Axis::Size => m.bytes_per_tile / 1024.0,
        }
    }

    fn describe(self, v: f64) -> String {
        match self {
            Axis::Time => format!("{v:.0} ms/Mpx"),
            Axis::Size => format!("{v:.1} KiB"),
        }
    }
}

/// Indices into `points` (x, y) of the Pareto front, cheapest first: the points that no other
/// point beats on both axes (smaller or equal x with larger y).
fn pareto(points: &[(f64, f64)]) -> Vec<usize> {
    let mut order: Vec<usize> = (0..points.len()).collect();
    order.sort_by(|&a, &b| points[a].0.total_cmp(&points[b].0).then(points[b].1.total_cmp(&points[a].1)));
    let mut front = Vec::new();
    let mut best = f64::NEG_INFINITY;
    for i in order {
        if points[i].1 > best {
            best = points[i].1;
            front.push(i);
        }
    }
    front
}

const PALETTE: [RGBColor; 11] = [
    RGBColor(31, 119, 180),
    RGBColor(23, 190, 207),
    RGBColor(255, 127, 14),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(127, 127, 127),
    RGBColor(148, 103, 189),
    RGBColor(227, 119, 194),
    RGBColor(140, 86, 75),
    RGBColor(188, 189, 34),
    RGBColor(20, 40, 110),
];

fn is_default(m: &Measured, img: &Img, d: &Defaults) -> bool {
    let o = if img.has_alpha() { &d.alpha } else { &d.opaque };
    m.choice == Choice::new(o.filter, o.codec)
}

/// Ticks for a log axis over [lo, hi]: 1-2-5 steps per decade, finer when that gives fewer
/// than four, only powers of ten when it gives more than twelve.
fn log_ticks(lo: f64, hi: f64) -> Vec<f64> {
    let sets: [&[f64]; 4] = [
        &[1.0],
        &[1.0, 2.0, 5.0],
        &[1.0, 1.5, 2.0, 3.0, 5.0, 7.0],
        &[1.0, 1.2, 1.5, 2.0, 2.5, 3.0, 4.0, 5.0, 6.0, 8.0],
    ];
    let ticks = |set: &[f64]| -> Vec<f64> {
        let mut v = Vec::new();
        let mut decade = 10f64.powf(lo.log10().floor());
        while decade <= hi {
            v.extend(set.iter().map(|m| m * decade).filter(|t| *t >= lo && *t <= hi));
            decade *= 10.0;
        }
        v
    };
    let one_two_five = ticks(sets[1]);
    if one_two_five.len() > 12 {
        return ticks(sets[0]);
    }
    sets[1..].iter().map(|s| ticks(s)).find(|t| t.len() >= 4).unwrap_or_else(|| ticks(sets[3]))
}

fn tick_label(v: f64) -> String {
    let s = format!("{v:.2}");
    s.trim_end_matches('0').trim_end_matches('.').to_string()
}

/// Places labels next to points without covering each other (greedy, in pixels).
struct Placer {
    area: (std::ops::Range<i32>, std::ops::Range<i32>),
    labels: Vec<(i32, i32, i32, i32)>,
    points: Vec<(i32, i32)>,
}

impl Placer {
    /// Offset of the label's top-left corner from `at`.
    /// Estimated width of a label in pixels (plotters writes an 11-point label as 8.9-pixel
    /// sans-serif).
    fn width(&self, text: &str) -> i32 {
        (text.chars().count() as f64 * 5.1) as i32 + 2
    }

    fn place(&mut self, at: (i32, i32), text: &str) -> (i32, i32) {
        let (w, h) = (self.width(text), 11);
        let candidates = [
            (8, -6),
            (7, -15),
            (7, 3),
            (-w - 8, -6),
            (-w - 7, -15),
            (-w - 7, 3),
            (-w / 2, -20),
            (-w / 2, 8),
            (7, -28),
            (7, 16),
            (-w - 7, -28),
            (-w - 7, 16),
            (14, -42),
            (14, 30),
            (-w - 14, -42),
            (-w - 14, 30),
        ];
        let cost = |(dx, dy): (i32, i32)| -> i32 {
            let (x0, y0) = (at.0 + dx, at.1 + dy);
            let (x1, y1) = (x0 + w, y0 + h);
            let outside = !(self.area.0.contains(&x0)
                && self.area.0.contains(&x1)
                && self.area.1.contains(&y0)
                && self.area.1.contains(&y1));
            let labels = self.labels.iter().filter(|b| x0 < b.2 && b.0 < x1 && y0 < b.3 && b.1 < y1).count() as i32;
            let points =
                self.points.iter().filter(|p| p.0 + 4 > x0 && p.0 - 4 < x1 && p.1 + 4 > y0 && p.1 - 4 < y1).count()
                    as i32;
            100 * outside as i32 + 10 * labels + points
        };
        let best = candidates.iter().copied().min_by_key(|c| cost(*c)).expect("candidates");
        self.labels.push((at.0 + best.0, at.1 + best.1, at.0 + best.0 + w, at.1 + best.1 + h));
        best
    }
}

fn plot(results: &[&ImageResult], axis: Axis, d: &Defaults) -> Result<String> {
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (1500, 1220)).into_drawing_area();
        root.fill(&WHITE)?;
        let (title, x_desc) = match axis {
            Axis::Time => (
                "Error vs time: PSNR against the float64 reference (all LODs) vs ms per source Mpx (median, 2 cores)",
                "ms per source megapixel, whole split (log scale)",
            ),
            Axis::Size => (
                "Error vs size: PSNR against the float64 reference (all LODs) vs mean payload bytes per 128² tile",
                "KiB per tile (log scale)",
            ),
        };
        let root = root.titled(title, ("sans-serif", 22))?;
        let (legend, rest) = root.split_vertically(40);
        // The legend: families present, the default's ring, the front.
        let present: Vec<usize> = (0..FAMILIES.len())
            .filter(|f| results.iter().any(|r| r.measured.values().any(|m| m.choice.family() == *f)))
            .collect();
        let mut x = 20;
        for &f in &present {
            legend.draw(&Circle::new((x, 20), 5, PALETTE[f].filled()))?;
            legend.draw(&Text::new(FAMILIES[f], (x + 9, 13), ("sans-serif", 13)))?;
            x += 22 + (FAMILIES[f].len() as i32) * 7;
        }
        legend.draw(&Circle::new((x, 20), 8, BLACK.stroke_width(2)))?;
        legend.draw(&Text::new("current default", (x + 12, 13), ("sans-serif", 13)))?;
        x += 130;
        legend.draw(&PathElement::new(vec![(x - 6, 20), (x + 14, 20)], BLACK.stroke_width(1)))?;
        legend.draw(&Text::new("Pareto front (named)", (x + 20, 13), ("sans-serif", 13)))?;

        for (panel, r) in rest.split_evenly((2, 2)).iter().zip(results) {
            let ms: Vec<&Measured> = r.measured.values().collect();
            let pts: Vec<(f64, f64)> = ms.iter().map(|m| (axis.value(m, &r.img), m.plot_psnr())).collect();
            let (xmin, xmax) = pts.iter().fold((f64::MAX, f64::MIN), |(a, b), p| (a.min(p.0), b.max(p.0)));
            let (ymin, ymax) = pts.iter().fold((f64::MAX, f64::MIN), |(a, b), p| (a.min(p.1), b.max(p.1)));
            let (x0, x1) = (xmin / 1.3, xmax * 1.8);
            let caption = format!(
                "{} ({}){}",
                r.img.title,
                r.img.key,
                if r.img.has_alpha() { ": colour shown over black" } else { "" }
            );
            let mut chart = ChartBuilder::on(panel)
                .caption(caption, ("sans-serif", 17))
                .margin(14)
                .x_label_area_size(42)
                .y_label_area_size(52)
                .build_cartesian_2d(
                    (x0..x1).log_scale().with_key_points(log_ticks(x0, x1)),
                    (ymin - 2.0).floor()..(ymax + 2.5).ceil(),
                )?;
            chart
                .configure_mesh()
                .x_desc(x_desc)
                .y_desc("PSNR, dB (all LODs)")
                .x_label_formatter(&|v| tick_label(*v))
                .y_label_formatter(&|v| format!("{v:.0}"))
                .label_style(("sans-serif", 12))
                .axis_desc_style(("sans-serif", 13))
                .light_line_style(TRANSPARENT)
                .bold_line_style(RGBColor(228, 228, 228))
                .draw()?;
            let front = pareto(&pts);
            chart.draw_series(LineSeries::new(front.iter().map(|&i| pts[i]), BLACK.stroke_width(1)))?;
            for (i, p) in pts.iter().enumerate() {
                let colour = PALETTE[ms[i].choice.family()];
                let radius = if front.contains(&i) { 5 } else { 3 };
                chart.draw_series(std::iter::once(Circle::new(*p, radius, colour.filled())))?;
            }
            let (xr, yr) = chart.plotting_area().get_pixel_range();
            let mut placer = Placer {
                area: (xr, yr),
                labels: Vec::new(),
                points: pts.iter().map(|p| chart.backend_coord(p)).collect(),
            };
            let mut named: Vec<(usize, String)> = front.iter().map(|&i| (i, ms[i].choice.label())).collect();
            for (i, m) in ms.iter().enumerate() {
                if is_default(m, &r.img, d) {
                    chart.draw_series(std::iter::once(Circle::new(pts[i], 9, BLACK.stroke_width(2))))?;
                    match named.iter_mut().find(|(j, _)| *j == i) {
                        Some((_, label)) => label.push_str(" (default)"),
                        None => named.push((i, format!("{} (default)", m.choice.label()))),
                    }
                }
            }
            for (i, label) in named {
                let offset = placer.place(chart.backend_coord(&pts[i]), &label);
                if offset.1.abs() > 30 {
                    // A label moved far from its point gets a leader line.
                    let end = (if offset.0 < 0 { offset.0 + placer.width(&label) } else { offset.0 }, offset.1 + 6);
                    chart.draw_series(std::iter::once(
                        EmptyElement::at(pts[i]) + PathElement::new(vec![(0, 0), end], RGBColor(120, 120, 120)),
                    ))?;
                }
                chart.draw_series(std::iter::once(
                    EmptyElement::at(pts[i]) + Text::new(label, offset, ("sans-serif", 11).into_font()),
                ))?;
            }
        }
        root.present()?;
    }
    Ok(svg)
}

// ---------------------------------------------------------------------------------------------
// The document

struct RunInfo<'a> {
    args: &'a Args,
    layout: Layout,
    rounds: usize,
    load_start: Option<f64>,
    load_end: Option<f64>,
    seconds: f64,
}

macro_rules! out {
    ($s:expr) => {
        $s.push('\n')
    };
    ($s:expr, $($t:tt)*) => {
        writeln!($s, $($t)*).expect("writing to a String")
    };
}

fn db(v: f64) -> String {
    if v.is_infinite() {
        "exact".into()
    } else if v.is_nan() {
        "n/a".into()
    } else {
        format!("{v:.2}")
    }
}

/// One decimal, "n/a" for a missing number.
fn f1(v: f64) -> String {
    if v.is_nan() { "n/a".into() } else { format!("{v:.1}") }
}

fn f2(v: f64) -> String {
    if v.is_nan() { "n/a".into() } else { format!("{v:.2}") }
}

fn kib(bytes: f64) -> String {
    format!("{:.1}", bytes / 1024.0)
}

fn get(r: &ImageResult, filter: Filter, codec: Codec) -> Option<&Measured> {
    r.measured.get(&Choice::new(filter, codec))
}

/// What the document reads: the results by image key.
struct Results<'a> {
    all: &'a [ImageResult],
    /// The plotted images (not the extra variant).
    main: Vec<&'a ImageResult>,
}

impl<'a> Results<'a> {
    fn image(&self, key: &str) -> Option<&'a ImageResult> {
        self.all.iter().find(|r| r.img.key == key)
    }

    /// A number from one choice on one image, NaN if it was not measured.
    fn num(&self, key: &str, filter: Filter, codec: Codec, f: impl Fn(&Measured, &Img) -> f64) -> f64 {
        self.image(key).and_then(|r| get(r, filter, codec).map(|m| f(m, &r.img))).unwrap_or(f64::NAN)
    }

    /// Total median time over total megapixels of the main images that have the choice.
    fn ms(&self, filter: Filter, codec: Codec) -> f64 {
        let (mut t, mut mpx) = (0.0, 0.0);
        for r in &self.main {
            if let Some(m) = get(r, filter, codec) {
                t += m.median_s();
                mpx += r.img.megapixels();
            }
        }
        if mpx == 0.0 { f64::NAN } else { 1000.0 * t / mpx }
    }

    /// Time of `a` over time of `b`, summed over the main images that have both.
    fn ratio(&self, a: (Filter, Codec), b: (Filter, Codec)) -> f64 {
        let (mut ta, mut tb) = (0.0, 0.0);
        for r in &self.main {
            if let (Some(x), Some(y)) = (get(r, a.0, a.1), get(r, b.0, b.1)) {
                ta += x.median_s();
                tb += y.median_s();
            }
        }
        if tb == 0.0 { f64::NAN } else { ta / tb }
    }

    /// Mean over the main images that have the choice of its bytes per tile.
    fn bytes(&self, filter: Filter, codec: Codec) -> f64 {
        let v: Vec<f64> = self.main.iter().filter_map(|r| get(r, filter, codec).map(|m| m.bytes_per_tile)).collect();
        if v.is_empty() { f64::NAN } else { v.iter().sum::<f64>() / v.len() as f64 }
    }

    /// Bytes of `a` over bytes of `b`, summed over the main images that have both.
    fn bytes_ratio(&self, a: (Filter, Codec), b: (Filter, Codec)) -> f64 {
        let (mut ba, mut bb) = (0.0, 0.0);
        for r in &self.main {
            if let (Some(x), Some(y)) = (get(r, a.0, a.1), get(r, b.0, b.1)) {
                ba += x.bytes_per_tile;
                bb += y.bytes_per_tile;
            }
        }
        if bb == 0.0 { f64::NAN } else { ba / bb }
    }
}

const PNG_FAST: Codec = Codec::Png { level: PngLevel::Fast };

fn jpeg(quality: u8, s444: bool) -> Codec {
    Codec::Jpeg { quality, subsampling: if s444 { Subsampling::S444 } else { Subsampling::S420 } }
}

/// The filter that is linear-premultiplied on an image: `linear` without alpha (the same code).
fn document(all: &[ImageResult], d: &Defaults, run: &RunInfo) -> String {
    let res = Results { all, main: all.iter().filter(|r| !r.extra).collect() };
    let op = Results { all, main: res.main.iter().copied().filter(|r| !r.img.has_alpha()).collect() };
    let mut s = String::new();
    let (w, h) = run.args.size;
    let layout = &run.layout;

    out!(s, "# What accuracy costs: LOD filters and tile codecs against a float64 reference");
    out!(s);
    out!(
        s,
        "Written by `examples/accuracy.rs` on {} in {:.0} s on {}, Linux; the 1-minute load average was {} at the start and {} at the end{}. Regenerate it, do not edit it:",
        today(),
        run.seconds,
        machine(),
        run.load_start.map_or("?".into(), |l| format!("{l:.2}")),
        run.load_end.map_or("?".into(), |l| format!("{l:.2}")),
        if run.load_start.is_some_and(|l| l >= 1.0) { " (other work shared the machine)" } else { "" }
    );
    out!(s);
    out!(s, "```sh");
    out!(
        s,
        "cargo run --release --example accuracy     # {:.0} s here after the build; --runs N, --size WxH, --out DIR",
        run.seconds
    );
    out!(s, "```");
    out!(s);
    summary(&mut s, &res, d);
    out!(
        s,
        "Every choice builds the whole pyramid of {w}x{h} 8-bit synthetic images through the real pipeline (`split::split` into a pack, as `split --pack` does) in {}-texel tiles with a border of {} ({}-texel payloads: {} tiles per side at LOD 0, {} LODs; neither side is a multiple of 8, so the last texel column and row of LODs 1-{} have partial footprints). The pack's tiles are decoded with `vortex_pack::decode_rgba8` (as `verify --decode` and the runtime's loader do) and every texel of every LOD is compared with a float64 reference pyramid computed from the source. The images are generated, deterministically, by the example:",
        TILE_SIZE,
        BORDER,
        layout.payload(),
        layout.tile_count,
        layout.lod_count,
        layout.lod_count - 1
    );
    out!(s);
    out!(s, "| image | content |");
    out!(s, "|---|---|");
    for r in all {
        out!(s, "| {} (`{}`) | {} |", r.img.title, r.img.key, r.img.what);
    }
    out!(s);
    out!(s, "## What is measured");
    out!(s);
    out!(
        s,
        "- **Reference**: the physically right LOD texel, the mean over the texel's footprint of real source pixels (the `2^k x 2^k` pixels under it, fewer at the right and bottom edges, never padding: as the tiler counts them) of colour decoded to linear light (IEC 61966-2-1) and premultiplied by alpha, in float64. Compared as it is shown over black: `255 * srgb(mean(linear(c) * a))` against `255 * srgb(linear(c') * a')` of the stored texel `(c', a')`, in 8-bit code values, and alpha on its own against `mean(a)`. Without alpha this is the linear-light mean encoded back to sRGB. LOD 0's reference is the source itself."
    );
    out!(
        s,
        "- **PSNR**, `10 log10(255² / MSE)` over the three colour samples of every texel compared (\"exact\": no error at all); **max**: the largest absolute difference, in code values. *All LODs* pools every texel of every LOD (LOD 0 is {:.0}% of them), *LOD 0* is the codec's error alone, *LODs 1+* the coarser levels (filter and codec). The plots use *all LODs*.",
        100.0 / (0..layout.lod_count).map(|k| 0.25f64.powi(k as i32)).sum::<f64>()
    );
    out!(
        s,
        "- **ms/Mpx**: wall time of the whole split (pyramid, encoding on all cores, the pack written to a temporary file) per source megapixel; the median of {} runs ({} for choices slower than {:.2} s a run). The runs are interleaved (each round runs every choice once, in a shifted order) so that load from elsewhere falls on all choices alike. Even so, the runs of one choice, less the slowest and the fastest, span {:.0}% of their median (the median over all choices; each choice's is in the table of every choice): on this small shared machine, read ratios, and take differences under about 20% for noise.",
        run.rounds,
        SLOW_RUNS.min(run.rounds),
        SLOW_RUN_S,
        {
            let mut v: Vec<f64> =
                res.all.iter().flat_map(|r| r.measured.values().map(|m| 100.0 * m.spread())).collect();
            v.sort_by(f64::total_cmp);
            v.get(v.len() / 2).copied().unwrap_or(f64::NAN)
        }
    );
    let shown_tiles: u64 = (0..layout.lod_count)
        .map(|k| {
            let (lw, lh) = layout.level_extent(k);
            (lw.div_ceil(layout.payload()) * lh.div_ceil(layout.payload())) as u64
        })
        .sum();
    out!(
        s,
        "- **KiB/tile**: mean payload bytes of the {shown_tiles} tiles that show part of the image (of the pyramid's {}), identical tiles counted at each place; a one-colour tile costs 0 (a pack stores its colour). **bits/texel**: the same per stored texel.",
        layout.total_tiles()
    );
    out!(
        s,
        "- **Own definition** (exact filters): the largest difference over LODs 1+ between a stored texel (straight colour; alpha) and the filter's own definition in float64 before rounding: `box` the mean of the code values, `linear` sRGB of the linear-light mean, `premultiplied` `sum(c·a) / sum(a)`, `linear-premultiplied` sRGB of `sum(linear(c)·a) / sum(a)`, colour 0 where `sum(a)` is 0. One rounding to the nearest code value allows 0.5."
    );
    out!(s);
    out!(
        s,
        "This page is about the texels stored; what the GPU then does with them (nearest, bilinear and trilinear sampling, borders, their cost per frame) is measured in [gpu-sampling.md](gpu-sampling.md)."
    );
    out!(s);

    filters_section(&mut s, &res, d, layout);
    codecs_section(&mut s, &res, d);
    garbage_section(&mut s, &res, d);

    out!(s, "## Error against time and size");
    out!(s);
    out!(
        s,
        "Every choice on each image: PSNR over all LODs against time per source megapixel and against bytes per tile (log scales). The black line joins the Pareto front, the choices no other beats on both axes, which are named; the current default is ringed."
    );
    out!(s);
    out!(s, "![Error vs time per source megapixel](accuracy-time.svg)");
    out!(s);
    out!(s, "![Error vs bytes per tile](accuracy-size.svg)");
    out!(s);
    for (axis, name) in [(Axis::Time, "time"), (Axis::Size, "size")] {
        out!(s, "Pareto front against {name}, cheapest first:");
        out!(s);
        for r in &res.main {
            let ms: Vec<&Measured> = r.measured.values().collect();
            let pts: Vec<(f64, f64)> = ms.iter().map(|m| (axis.value(m, &r.img), m.plot_psnr())).collect();
            let front: Vec<String> = pareto(&pts)
                .into_iter()
                .map(|i| format!("{} ({}, {:.1} dB)", ms[i].choice.label(), axis.describe(pts[i].0), pts[i].1))
                .collect();
            out!(s, "- `{}`: {}", r.img.key, front.join(" → "));
        }
        out!(s);
    }
    out!(
        s,
        "Against time, the top of every front is the default filter with lossless tiles, since lossless tiles are cheap to make: raw {} ms/Mpx, PNG fast {}, against JPEG q85 {} and BC7 ultra-fast {} (opaque images, default filter). Against size the front climbs through JPEG, BC7 or high zstd levels and ends at lossless tiles. Choices with `box` LODs on a front: {}. They are cheap, but `box`'s error on LODs 1+ caps the PSNR of every codec stored with it (`box` + {}: {} / {} / {} dB on `photo` / `high-frequency` / `text`, against {} / {} / {} with the default filter).",
        f1(op.ms(d.opaque.filter, Codec::Raw)),
        f1(op.ms(d.opaque.filter, PNG_FAST)),
        f1(op.ms(d.opaque.filter, d.opaque.codec)),
        f1(op.ms(d.opaque.filter, Codec::Bc7 { effort: Bc7Effort::UltraFast })),
        box_on_fronts(&res.main),
        CodecKey::of(d.opaque.codec).label(),
        f1(op.num("photo", Filter::Box, d.opaque.codec, |m, _| m.all().psnr())),
        f1(op.num("high-frequency", Filter::Box, d.opaque.codec, |m, _| m.all().psnr())),
        f1(op.num("text", Filter::Box, d.opaque.codec, |m, _| m.all().psnr())),
        f1(op.num("photo", d.opaque.filter, d.opaque.codec, |m, _| m.all().psnr())),
        f1(op.num("high-frequency", d.opaque.filter, d.opaque.codec, |m, _| m.all().psnr())),
        f1(op.num("text", d.opaque.filter, d.opaque.codec, |m, _| m.all().psnr())),
    );
    out!(s);

    defaults_section(&mut s, &res, d);
    s
}

/// Every choice with `box` LODs on a Pareto front: "label against time on `photo`, `text`".
fn box_on_fronts(results: &[&ImageResult]) -> String {
    let mut found: BTreeMap<(String, &str), Vec<String>> = BTreeMap::new();
    for r in results {
        let ms: Vec<&Measured> = r.measured.values().collect();
        for (axis, name) in [(Axis::Time, "time"), (Axis::Size, "size")] {
            let pts: Vec<(f64, f64)> = ms.iter().map(|m| (axis.value(m, &r.img), m.plot_psnr())).collect();
            for i in pareto(&pts).into_iter().filter(|&i| ms[i].choice.filter() == Filter::Box) {
                found.entry((ms[i].choice.label(), name)).or_default().push(format!("`{}`", r.img.key));
            }
        }
    }
    if found.is_empty() {
        return "none".into();
    }
    found
        .iter()
        .map(|((label, axis), keys)| format!("{label} against {axis} on {}", keys.join(", ")))
        .collect::<Vec<_>>()
        .join("; ")
}

/// The opening summary: the headline numbers.
fn summary(s: &mut String, res: &Results, d: &Defaults) {
    let op = Results { all: res.all, main: res.main.iter().copied().filter(|r| !r.img.has_alpha()).collect() };
    let coarse = |key: &str, f: Filter| res.num(key, f, PNG_FAST, |m, _| m.coarse().psnr());
    let gains: Vec<(String, f64, f64)> = res
        .main
        .iter()
        .map(|r| {
            (r.img.key.to_string(), coarse(r.img.key, Filter::Box), coarse(r.img.key, Filter::LinearPremultiplied))
        })
        .collect();
    let list =
        gains.iter().map(|(k, b, l)| format!("{} to {} dB on `{k}`", f1(*b), f1(*l))).collect::<Vec<_>>().join(", ");
    out!(s, "In short:");
    out!(s);
    out!(
        s,
        "- **The LOD filter matters more than the codec.** Going from `box` (the mean of stored sRGB values, as `vips dzsave` averages) to `linear-premultiplied` (the default; `linear` on images without alpha) raises the PSNR of LODs 1+ against the physically right reference from {list}, for {}x the time with raw tiles (the pyramid's own cost) and {}x with PNG fast tiles. `box` is exact to its own definition (within 0.5) but wrong about light: it averages sRGB code values.",
        f2(res.ratio((Filter::LinearPremultiplied, Codec::Raw), (Filter::Box, Codec::Raw))),
        f2(res.ratio((Filter::LinearPremultiplied, PNG_FAST), (Filter::Box, PNG_FAST)))
    );
    let l0 = |key: &str, c: Codec| res.num(key, d.opaque.filter, c, |m, _| m.lods[0].psnr());
    out!(
        s,
        "- **JPEG q85 4:2:0** (the default for opaque images) gives {} dB at LOD 0 on `photo` for {} KiB per tile; 4:4:4 {} dB for {}% more bytes. 4:2:0 cannot hold colour detail of one or two texels at any quality: {} dB at LOD 0 on `high-frequency` (q95: {}), where 4:4:4 reaches {} dB.",
        f1(l0("photo", d.opaque.codec)),
        f1(res.num("photo", d.opaque.filter, d.opaque.codec, |m, _| m.bytes_per_tile / 1024.0)),
        f1(l0("photo", jpeg(85, true))),
        f1(100.0 * (res.bytes_ratio((d.opaque.filter, jpeg(85, true)), (d.opaque.filter, jpeg(85, false))) - 1.0)),
        f1(l0("high-frequency", jpeg(85, false))),
        f1(l0("high-frequency", jpeg(95, false))),
        f1(l0("high-frequency", jpeg(85, true)))
    );
    out!(
        s,
        "- **BC7 ultra-fast** (the BC7 default) is {} dB at LOD 0 on `photo`, 16 KiB per tile; very-fast adds {} dB for {}x the time. Random colour under alpha 0 costs it nothing, as it is cleared before encoding (`alpha`, LOD 0: ultra-fast {} dB, very-fast {} dB; see [below](#colour-under-alpha-0)).",
        f1(l0("photo", Codec::Bc7 { effort: Bc7Effort::UltraFast })),
        f1(l0("photo", Codec::Bc7 { effort: Bc7Effort::VeryFast })
            - l0("photo", Codec::Bc7 { effort: Bc7Effort::UltraFast })),
        f1(op.ratio(
            (d.opaque.filter, Codec::Bc7 { effort: Bc7Effort::VeryFast }),
            (d.opaque.filter, Codec::Bc7 { effort: Bc7Effort::UltraFast })
        )),
        f1(res.num("alpha", d.alpha.filter, Codec::Bc7 { effort: Bc7Effort::UltraFast }, |m, _| m.lods[0].psnr())),
        f1(res.num("alpha", d.alpha.filter, Codec::Bc7 { effort: Bc7Effort::VeryFast }, |m, _| m.lods[0].psnr())),
    );
    let clearly = filter_verdict(res, d).3;
    out!(
        s,
        "- **Defaults**: the numbers {} `linear-premultiplied` over `box` as the default filter (the project's default since these measurements), and support the codec defaults; see [Defaults](#defaults).",
        if clearly { "clearly favour" } else { "do not clearly favour" }
    );
    out!(s);
}

fn filters_section(s: &mut String, res: &Results, d: &Defaults, layout: &Layout) {
    out!(s, "## LOD filters");
    out!(s);
    out!(
        s,
        "Lossless tiles (PNG fast; raw for the pyramid's own cost), so LOD 0 is exact and every error is the filter's: PSNR and max error over LODs 1+. `premultiplied` and `linear` are `box` and `linear-premultiplied` on images without alpha (the same code runs), so they were measured on `alpha` only. `alpha` colour is shown over black; alpha's own error is in the per-LOD tables."
    );
    out!(s);
    let mut head = String::from(
        "| filter | run on | ms/Mpx, png fast | time vs box | ms/Mpx, raw | time vs box | KiB/tile, png fast |",
    );
    let mut rule = String::from("|---|---|---:|---:|---:|---:|---:|");
    for r in &res.main {
        head += &format!(" {} dB | max |", r.img.key);
        rule += "---:|---:|";
    }
    head += " own definition: max colour / alpha |";
    rule += "---:|";
    out!(s, "{head}");
    out!(s, "{rule}");
    for f in FILTERS {
        let ran: Vec<&str> = res.main.iter().filter(|r| get(r, f, PNG_FAST).is_some()).map(|r| r.img.key).collect();
        let mut row = format!(
            "| `{}`{} | {} | {} | {} | {} | {} | {} |",
            f.name(),
            if f == d.opaque.filter { " (default)" } else { "" },
            if ran.len() == res.main.len() { "all".to_string() } else { ran.join(", ") },
            f1(res.ms(f, PNG_FAST)),
            f2(res.ratio((f, PNG_FAST), (Filter::Box, PNG_FAST))),
            f1(res.ms(f, Codec::Raw)),
            f2(res.ratio((f, Codec::Raw), (Filter::Box, Codec::Raw))),
            kib(res.bytes(f, PNG_FAST)),
        );
        let mut own = (0.0f64, 0.0f64);
        for r in &res.main {
            match get(r, f, PNG_FAST) {
                Some(m) => {
                    let c = m.coarse();
                    row += &format!(" {} | {:.1} |", db(c.psnr()), c.max);
                    if let Some((oc, oa)) = m.own_max {
                        own = (own.0.max(oc), own.1.max(oa));
                    }
                }
                None => {
                    let same = if f == Filter::Premultiplied { "box" } else { "linear-premultiplied" };
                    row += &format!(" = {same} | |");
                }
            }
        }
        row += &if f.is_exact() { format!(" {:.3} / {:.3} |", own.0, own.1) } else { " n/a |".into() };
        out!(s, "{row}");
    }
    out!(s);
    out!(
        s,
        "Times and KiB/tile are over the images each filter ran on (total median time over total megapixels; mean of the per-image means), so compare rows by the \"time vs box\" columns, which divide by `box` on the same images."
    );
    out!(s);

    let coarse = |key: &str, f: Filter| res.num(key, f, PNG_FAST, |m, _| m.coarse().psnr());
    let cmax = |key: &str, f: Filter| res.num(key, f, PNG_FAST, |m, _| m.coarse().max);
    let alpha_db = |key: &str, f: Filter| res.num(key, f, PNG_FAST, |m, _| m.coarse().psnr_alpha());
    let alpha_max = |key: &str, f: Filter| res.num(key, f, PNG_FAST, |m, _| m.coarse().max_a);
    let own_colour =
        |f: Filter| res.main.iter().filter_map(|r| get(r, f, PNG_FAST)?.own_max.map(|o| o.0)).fold(f64::NAN, f64::max);
    out!(
        s,
        "- **Linear light is what the reference rewards, by a wide margin.** On LODs 1+ `linear-premultiplied` (`linear` on these opaque images) reaches {} dB on `photo` (`box`: {}), {} on `high-frequency` ({}), {} on `text` ({}), with a largest error of {} code values (its rounding) where `box` is off by up to {}. `box` averages sRGB code values, which darkens every mix of dark and light: a one-texel black/white checker becomes 128 instead of 188, thin dark strokes on paper become heavier and darker, one-texel red/green detail turns to dark olive.",
        db(coarse("photo", Filter::LinearPremultiplied)),
        db(coarse("photo", Filter::Box)),
        db(coarse("high-frequency", Filter::LinearPremultiplied)),
        db(coarse("high-frequency", Filter::Box)),
        db(coarse("text", Filter::LinearPremultiplied)),
        db(coarse("text", Filter::Box)),
        f1(["photo", "high-frequency", "text"]
            .iter()
            .map(|k| cmax(k, Filter::LinearPremultiplied))
            .fold(f64::NAN, f64::max)),
        f1(["photo", "high-frequency", "text"].iter().map(|k| cmax(k, Filter::Box)).fold(f64::NAN, f64::max)),
    );
    out!(
        s,
        "- **Alpha.** With random colour under alpha 0, `box` gets {} dB (max {}): the invisible colour leaks into every texel that mixes visible and transparent pixels, a fringe. `premultiplied` removes it ({} dB, max {}; what remains is sRGB averaging), `linear` alone is worse than `box` ({} dB, max {}: the noise weighs more in linear light), and `linear-premultiplied` gets {} dB with a largest error of {} code values, only where alpha is a few code values: alpha's own rounding (up to 0.5) is magnified by the steep sRGB curve near black when the texel is shown. Alpha is the same exact mean in all four ({} dB, max {}).",
        db(coarse("alpha", Filter::Box)),
        f1(cmax("alpha", Filter::Box)),
        db(coarse("alpha", Filter::Premultiplied)),
        f1(cmax("alpha", Filter::Premultiplied)),
        db(coarse("alpha", Filter::Linear)),
        f1(cmax("alpha", Filter::Linear)),
        db(coarse("alpha", Filter::LinearPremultiplied)),
        f1(cmax("alpha", Filter::LinearPremultiplied)),
        db(alpha_db("alpha", Filter::Box)),
        f1(alpha_max("alpha", Filter::Box)),
    );
    out!(
        s,
        "- **`lanczos3` and `mitchell` are no closer to the reference than `box`** on the opaque images (LODs 1+, `lanczos3` / `mitchell` / `box`: `photo` {} / {} / {} dB, `text` {} / {} / {}, `high-frequency` {} / {} / {}). On `alpha` they premultiply, yet their colour reaches {} / {} dB against `box`'s {} and `premultiplied`'s {}, and alpha itself suffers: {} / {} dB, off by up to {} / {} code values, where every exact filter is within 0.5. They filter stored sRGB values like `box` and are other kernels than the footprint mean (sharper, ringing at edges: errors up to {} code values). They answer another question (less aliasing, more contrast when minified); against the area mean that trilinear filtering between LODs assumes, they are far from the linear-light filters.",
        db(coarse("photo", Filter::Lanczos3)),
        db(coarse("photo", Filter::Mitchell)),
        db(coarse("photo", Filter::Box)),
        db(coarse("text", Filter::Lanczos3)),
        db(coarse("text", Filter::Mitchell)),
        db(coarse("text", Filter::Box)),
        db(coarse("high-frequency", Filter::Lanczos3)),
        db(coarse("high-frequency", Filter::Mitchell)),
        db(coarse("high-frequency", Filter::Box)),
        db(coarse("alpha", Filter::Lanczos3)),
        db(coarse("alpha", Filter::Mitchell)),
        db(coarse("alpha", Filter::Box)),
        db(coarse("alpha", Filter::Premultiplied)),
        db(alpha_db("alpha", Filter::Lanczos3)),
        db(alpha_db("alpha", Filter::Mitchell)),
        f1(alpha_max("alpha", Filter::Lanczos3)),
        f1(alpha_max("alpha", Filter::Mitchell)),
        f1(res.main.iter().map(|r| cmax(r.img.key, Filter::Lanczos3)).fold(f64::NAN, f64::max)),
    );
    out!(
        s,
        "- **Exactness holds.** `box` and `premultiplied` are within {} and {} of their float definitions (one rounding, halves up: exact); `linear` and `linear-premultiplied` within {} and {}: the fixed-point sRGB decode table (65535 steps) and one rounding, inside the one code value `docs/info-json.md` allows. Alpha is within 0.5 everywhere.",
        f2(own_colour(Filter::Box)),
        f2(own_colour(Filter::Premultiplied)),
        f2(own_colour(Filter::Linear)),
        f2(own_colour(Filter::LinearPremultiplied)),
    );
    out!(
        s,
        "- **Cost.** With raw tiles (the pyramid plus a copy), `linear-premultiplied` takes {}x the time of `box`, `lanczos3` {}x, `mitchell` {}x; on `alpha`, `premultiplied` {}x and `linear` {}x. With PNG fast tiles encoding dominates: `linear-premultiplied` {}x. The filters barely change tile sizes ({} KiB per PNG fast tile with `box`, {} with `linear-premultiplied`).",
        f2(res.ratio((Filter::LinearPremultiplied, Codec::Raw), (Filter::Box, Codec::Raw))),
        f2(res.ratio((Filter::Lanczos3, Codec::Raw), (Filter::Box, Codec::Raw))),
        f2(res.ratio((Filter::Mitchell, Codec::Raw), (Filter::Box, Codec::Raw))),
        f2(res.ratio((Filter::Premultiplied, Codec::Raw), (Filter::Box, Codec::Raw))),
        f2(res.ratio((Filter::Linear, Codec::Raw), (Filter::Box, Codec::Raw))),
        f2(res.ratio((Filter::LinearPremultiplied, PNG_FAST), (Filter::Box, PNG_FAST))),
        kib(res.bytes(Filter::Box, PNG_FAST)),
        kib(res.bytes(Filter::LinearPremultiplied, PNG_FAST)),
    );
    out!(s);

    out!(s, "### Per LOD");
    out!(s);
    out!(
        s,
        "PSNR in dB / max error in code values per LOD, lossless tiles (PNG fast). LOD {} is one tile holding the whole image.",
        layout.lod_count - 1
    );
    out!(s);
    for key in ["alpha", "high-frequency", "photo", "text", "alpha-clean"] {
        let Some(r) = res.image(key) else { continue };
        let open = key == "alpha" || key == "high-frequency";
        if open {
            out!(
                s,
                "**{}** (`{}`){}",
                r.img.title,
                r.img.key,
                if r.img.has_alpha() { ", colour shown over black:" } else { ":" }
            );
        } else {
            out!(s, "<details><summary>{} (<code>{}</code>)</summary>", r.img.title, r.img.key);
        }
        out!(s);
        per_lod_table(s, r, layout, false);
        if r.img.has_alpha() {
            out!(s, "Alpha:");
            out!(s);
            per_lod_table(s, r, layout, true);
        }
        if !open {
            out!(s, "</details>");
            out!(s);
        }
    }
}

fn per_lod_table(s: &mut String, r: &ImageResult, layout: &Layout, alpha: bool) {
    let mut head = String::from("| filter |");
    let mut rule = String::from("|---|");
    for k in 0..layout.lod_count {
        let (lw, lh) = layout.level_extent(k);
        head += &format!(" LOD {k} ({lw}x{lh}) |");
        rule += "---:|";
    }
    out!(s, "{head}");
    out!(s, "{rule}");
    for f in FILTERS {
        let Some(m) = get(r, f, PNG_FAST) else { continue };
        let mut row = format!("| `{}` |", f.name());
        for e in &m.lods {
            let (p, max) = if alpha { (e.psnr_alpha(), e.max_a) } else { (e.psnr(), e.max) };
            row += &format!(" {} / {:.1} |", db(p), max);
        }
        out!(s, "{row}");
    }
    out!(s);
}

fn default_mark(codec: Codec, d: &Defaults) -> &'static str {
    if codec == d.opaque.codec {
        " (default)"
    } else if codec == d.alpha.codec {
        " (default with alpha)"
    } else if codec == d.bc7 {
        " (default effort)"
    } else if matches!(codec, Codec::Zstd { level, .. } if level == d.zstd_level) {
        " (default level)"
    } else {
        ""
    }
}

fn codecs_section(s: &mut String, res: &Results, d: &Defaults) {
    let f = d.opaque.filter;
    out!(s, "## Tile codecs");
    out!(s);
    out!(
        s,
        "With the default filter (`{}`). ms/Mpx and KiB/tile over the three opaque images (`alpha`'s are in the table per image below); PSNR over all LODs, LOD 0 alone in parentheses. JPEG and BC1 store no alpha (`--flatten` would composite it away). PNG, raw and zstd are lossless: their PSNR is the filter's.",
        f.name()
    );
    out!(s);
    let opaque: Vec<&ImageResult> = res.main.iter().copied().filter(|r| !r.img.has_alpha()).collect();
    let ms = |codec: Codec| {
        let (mut t, mut mpx) = (0.0, 0.0);
        for r in &opaque {
            if let Some(m) = get(r, f, codec) {
                t += m.median_s();
                mpx += r.img.megapixels();
            }
        }
        1000.0 * t / mpx
    };
    let bytes = |codec: Codec| {
        let v: Vec<f64> = opaque.iter().filter_map(|r| get(r, f, codec).map(|m| m.bytes_per_tile)).collect();
        v.iter().sum::<f64>() / v.len() as f64
    };
    let mut head = String::from("| codec | ms/Mpx | KiB/tile | bits/texel |");
    let mut rule = String::from("|---|---:|---:|---:|");
    for r in &res.main {
        head += &format!(" {} dB |", r.img.key);
        rule += "---:|";
    }
    out!(s, "{head}");
    out!(s, "{rule}");
    for codec in codec_sweep() {
        let b = bytes(codec);
        let mut row = format!(
            "| {}{} | {:.1} | {} | {:.2} |",
            CodecKey::of(codec).label(),
            default_mark(codec, d),
            ms(codec),
            kib(b),
            b * 8.0 / (TILE_SIZE * TILE_SIZE) as f64,
        );
        for r in &res.main {
            match get(r, f, codec) {
                Some(m) => row += &format!(" {} ({}) |", db(m.all().psnr()), db(m.lods[0].psnr())),
                None => row += " - |",
            }
        }
        out!(s, "{row}");
    }
    out!(s);

    let op = Results { all: res.all, main: opaque.clone() };
    let l0 = |key: &str, c: Codec| res.num(key, f, c, |m, _| m.lods[0].psnr());
    let b = |c: Codec| op.bytes(f, c) / 1024.0;
    let t = |c: Codec| op.ms(f, c);
    let bc7 = |e| Codec::Bc7 { effort: e };
    out!(
        s,
        "- **JPEG.** LOD 0 on `photo`: q50 {} dB, q75 {}, q85 {}, q95 {} (4:2:0); 4:4:4 adds {} dB at q85 for {}% more bytes and {}x the time. On `text` 4:4:4 adds {} dB at q85. On `high-frequency`, 4:2:0 stays at {}-{} dB at LOD 0 whatever the quality (1-texel red/green and blue/yellow detail averaged away), 4:4:4 reaches {} at q85 and {} at q95. Over all LODs of `text`, lossless tiles reach {} dB and JPEG q95 4:4:4 {}.",
        f1(l0("photo", jpeg(50, false))),
        f1(l0("photo", jpeg(75, false))),
        f1(l0("photo", jpeg(85, false))),
        f1(l0("photo", jpeg(95, false))),
        f1(l0("photo", jpeg(85, true)) - l0("photo", jpeg(85, false))),
        f1(100.0 * (op.bytes_ratio((f, jpeg(85, true)), (f, jpeg(85, false))) - 1.0)),
        f2(op.ratio((f, jpeg(85, true)), (f, jpeg(85, false)))),
        f1(l0("text", jpeg(85, true)) - l0("text", jpeg(85, false))),
        f1([50, 75, 85, 95].iter().map(|q| l0("high-frequency", jpeg(*q, false))).fold(f64::NAN, f64::min)),
        f1([50, 75, 85, 95].iter().map(|q| l0("high-frequency", jpeg(*q, false))).fold(f64::NAN, f64::max)),
        f1(l0("high-frequency", jpeg(85, true))),
        f1(l0("high-frequency", jpeg(95, true))),
        f1(res.num("text", f, PNG_FAST, |m, _| m.all().psnr())),
        f1(res.num("text", f, jpeg(95, true), |m, _| m.all().psnr())),
    );
    out!(
        s,
        "- **PNG.** `default` and `best` tiles are {}% and {}% smaller than `fast` ones for {}x and {}x the time; `best` buys almost nothing over `default`.",
        f1(100.0 * (1.0 - op.bytes_ratio((f, Codec::Png { level: PngLevel::Default }), (f, PNG_FAST)))),
        f1(100.0 * (1.0 - op.bytes_ratio((f, Codec::Png { level: PngLevel::Best }), (f, PNG_FAST)))),
        f1(op.ratio((f, Codec::Png { level: PngLevel::Default }), (f, PNG_FAST))),
        f1(op.ratio((f, Codec::Png { level: PngLevel::Best }), (f, PNG_FAST))),
    );
    let z = |level, delta| Codec::Zstd { level, delta };
    out!(
        s,
        "- **zstd** (packs only): the row-delta filter makes tiles {}% smaller at level 3, in {}x the time. `zstd-delta` levels 1 / 3 / 9 / 19: {} / {} / {} / {} KiB per tile for {} / {} / {} / {} ms/Mpx; level 19 costs {}x level 3's time for {}% less. `zstd-delta 3` tiles are {}% smaller than PNG fast ones, in {}x the time. Raw: {} ms/Mpx, {} KiB.",
        f1(100.0 * (1.0 - op.bytes_ratio((f, z(3, true)), (f, z(3, false))))),
        f2(op.ratio((f, z(3, true)), (f, z(3, false)))),
        f1(b(z(1, true))),
        f1(b(z(3, true))),
        f1(b(z(9, true))),
        f1(b(z(19, true))),
        f1(t(z(1, true))),
        f1(t(z(3, true))),
        f1(t(z(9, true))),
        f1(t(z(19, true))),
        f1(op.ratio((f, z(19, true)), (f, z(3, true)))),
        f1(100.0 * (1.0 - op.bytes_ratio((f, z(19, true)), (f, z(3, true))))),
        f1(100.0 * (1.0 - op.bytes_ratio((f, z(3, true)), (f, PNG_FAST)))),
        f2(op.ratio((f, z(3, true)), (f, PNG_FAST))),
        f1(t(Codec::Raw)),
        f1(b(Codec::Raw)),
    );
    out!(
        s,
        "- **BC1 and BC7** (packs only, fixed 8 and 16 KiB per tile). LOD 0 on `photo` / `text`: BC1 {} / {} dB, BC7 ultra-fast {} / {}, very-fast {} / {}, basic {} / {}; very-fast takes {}x ultra-fast's time, basic {}x. BC1: {} ms/Mpx{}.",
        f1(l0("photo", Codec::Bc1)),
        f1(l0("text", Codec::Bc1)),
        f1(l0("photo", bc7(Bc7Effort::UltraFast))),
        f1(l0("text", bc7(Bc7Effort::UltraFast))),
        f1(l0("photo", bc7(Bc7Effort::VeryFast))),
        f1(l0("text", bc7(Bc7Effort::VeryFast))),
        f1(l0("photo", bc7(Bc7Effort::Basic))),
        f1(l0("text", bc7(Bc7Effort::Basic))),
        f1(op.ratio((f, bc7(Bc7Effort::VeryFast)), (f, bc7(Bc7Effort::UltraFast)))),
        f1(op.ratio((f, bc7(Bc7Effort::Basic)), (f, bc7(Bc7Effort::UltraFast)))),
        f1(t(Codec::Bc1)),
        if codec_sweep().iter().all(|c| t(*c) >= t(Codec::Bc1)) { ", the fastest codec of all" } else { "" },
    );
    out!(s);

    out!(s, "<details><summary>Every choice on every image</summary>");
    out!(s);
    for r in res.all {
        out!(s, "**{}** (`{}`), {:.2} Mpx:", r.img.title, r.img.key, r.img.megapixels());
        out!(s);
        let alpha = r.img.has_alpha();
        out!(
            s,
            "| choice | ms/Mpx | runs | spread | KiB/tile | all LODs dB | LOD 0 dB | LOD 0 max | LODs 1+ dB | LODs 1+ max |{}",
            if alpha { " alpha dB | alpha max |" } else { "" }
        );
        out!(s, "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|{}", if alpha { "---:|---:|" } else { "" });
        let mut ms: Vec<&Measured> = r.measured.values().collect();
        ms.sort_by(|a, b| a.choice.family().cmp(&b.choice.family()).then(a.choice.cmp(&b.choice)));
        for m in ms {
            let (all, l0, c) = (m.all(), m.lods[0], m.coarse());
            let mut row = format!(
                "| {}{} | {:.1} | {} | {:.0}% | {} | {} | {} | {:.1} | {} | {:.1} |",
                m.choice.label(),
                if is_default(m, &r.img, d) { " (default)" } else { "" },
                m.ms_per_mpx(&r.img),
                m.times.len(),
                100.0 * m.spread(),
                kib(m.bytes_per_tile),
                db(all.psnr()),
                db(l0.psnr()),
                l0.max,
                db(c.psnr()),
                c.max
            );
            if alpha {
                row += &format!(" {} | {:.1} |", db(all.psnr_alpha()), all.max_a);
            }
            out!(s, "{row}");
        }
        out!(s);
    }
    out!(s, "</details>");
    out!(s);
}

fn garbage_section(s: &mut String, res: &Results, d: &Defaults) {
    let (Some(noisy), Some(clean)) = (res.image("alpha"), res.image("alpha-clean")) else { return };
    out!(s, "## Colour under alpha 0");
    out!(s);
    out!(
        s,
        "`{}` holds random colour where alpha is 0, as images cut out of photographs or rendered with straight alpha often do; `{}` is the same image with black there. Nothing under alpha 0 is visible, yet:",
        noisy.img.key,
        clean.img.key
    );
    out!(s);
    out!(
        s,
        "| choice | KiB/tile | KiB/tile, black under 0 | LOD 0 dB | LOD 0 dB, black under 0 | alpha dB / max | alpha dB / max, black under 0 | LODs 1+ dB | LODs 1+ dB, black under 0 |"
    );
    out!(s, "|---|---:|---:|---:|---:|---:|---:|---:|---:|");
    for (choice, m) in &clean.measured {
        let Some(n) = noisy.measured.get(choice) else { continue };
        let (na, ca) = (n.all(), m.all());
        out!(
            s,
            "| {} | {} | {} | {} | {} | {} / {:.0} | {} / {:.0} | {} | {} |",
            choice.label(),
            kib(n.bytes_per_tile),
            kib(m.bytes_per_tile),
            db(n.lods[0].psnr()),
            db(m.lods[0].psnr()),
            db(na.psnr_alpha()),
            na.max_a,
            db(ca.psnr_alpha()),
            ca.max_a,
            db(n.coarse().psnr()),
            db(m.coarse().psnr()),
        );
    }
    out!(s);
    let get2 = |r: &ImageResult, f: Filter, c: Codec, v: &dyn Fn(&Measured) -> f64| get(r, f, c).map_or(f64::NAN, v);
    let bc7 = |e| Codec::Bc7 { effort: e };
    out!(
        s,
        "- **Lossless tiles carry the noise**: PNG fast tiles are {}x larger with it ({} vs {} KiB).",
        f1(get2(noisy, d.alpha.filter, PNG_FAST, &|m| m.bytes_per_tile)
            / get2(clean, d.alpha.filter, PNG_FAST, &|m| m.bytes_per_tile)),
        kib(get2(noisy, d.alpha.filter, PNG_FAST, &|m| m.bytes_per_tile)),
        kib(get2(clean, d.alpha.filter, PNG_FAST, &|m| m.bytes_per_tile)),
    );
    out!(
        s,
        "- **BC7 ignores it.** Intel's encoder weighs the colour of every texel alike and would spend a block's endpoints on the noise (before the tiler cleared it, alpha was off by up to 225 code values and more effort made it worse); the tiler now stores colour under alpha 0 as 0 before BC7 encoding. LOD 0: {} / {} / {} dB (ultra-fast / very-fast / basic) with the noise, {} / {} / {} dB with black; alpha off by at most {} code values.",
        f1(get2(noisy, d.alpha.filter, bc7(Bc7Effort::UltraFast), &|m| m.lods[0].psnr())),
        f1(get2(noisy, d.alpha.filter, bc7(Bc7Effort::VeryFast), &|m| m.lods[0].psnr())),
        f1(get2(noisy, d.alpha.filter, bc7(Bc7Effort::Basic), &|m| m.lods[0].psnr())),
        f1(get2(clean, d.alpha.filter, bc7(Bc7Effort::UltraFast), &|m| m.lods[0].psnr())),
        f1(get2(clean, d.alpha.filter, bc7(Bc7Effort::VeryFast), &|m| m.lods[0].psnr())),
        f1(get2(clean, d.alpha.filter, bc7(Bc7Effort::Basic), &|m| m.lods[0].psnr())),
        f1([Bc7Effort::UltraFast, Bc7Effort::VeryFast, Bc7Effort::Basic]
            .iter()
            .map(|e| get2(noisy, d.alpha.filter, bc7(*e), &|m| m.lods[0].max_a))
            .fold(f64::NAN, f64::max)),
    );
    out!(
        s,
        "- **Black is no cure for `box`**: it trades the noise fringe for a dark one (LODs 1+: {} dB with noise, {} with black). The premultiplied filters ignore the colour under alpha 0 entirely and give the same texels either way ({} dB with `linear-premultiplied`); at LODs 1+ they store colour 0 where a whole footprint is transparent, while LOD 0 keeps the source's colour.",
        db(get2(noisy, Filter::Box, PNG_FAST, &|m| m.coarse().psnr())),
        db(get2(clean, Filter::Box, PNG_FAST, &|m| m.coarse().psnr())),
        db(get2(clean, Filter::LinearPremultiplied, PNG_FAST, &|m| m.coarse().psnr())),
    );
    out!(
        s,
        "- These are per-texel errors of straight-alpha texels shown over black. A GPU that filters straight-alpha texels bilinearly mixes the colour under alpha 0 into visible edges whatever the LOD filter did (noise or black alike); only colour dilated from visible neighbours, or premultiplied storage, avoids that."
    );
    out!(s);
}

/// Whether the numbers clearly favour the linear-light filter over `box`: more than 3 dB on
/// LODs 1+ of every image, for less than twice the split time with the default JPEG tiles.
/// Returns (smallest gain, largest gain, time ratio, verdict).
fn filter_verdict(res: &Results, d: &Defaults) -> (f64, f64, f64, bool) {
    let coarse = |key: &str, f: Filter| res.num(key, f, PNG_FAST, |m, _| m.coarse().psnr());
    let gains: Vec<f64> = res
        .main
        .iter()
        .map(|r| coarse(r.img.key, Filter::LinearPremultiplied) - coarse(r.img.key, Filter::Box))
        .collect();
    let (gmin, gmax) = gains.iter().fold((f64::MAX, f64::MIN), |(a, b), g| (a.min(*g), b.max(*g)));
    let ratio = res.ratio((Filter::LinearPremultiplied, d.opaque.codec), (Filter::Box, d.opaque.codec));
    (gmin, gmax, ratio, gmin > 3.0 && ratio < 2.0)
}

fn defaults_section(s: &mut String, res: &Results, d: &Defaults) {
    out!(s, "## Defaults");
    out!(s);
    out!(
        s,
        "What `split` does with no flags (`settings::resolve`, which `src/cli/split.rs` calls): filter `{}`; codec `auto`, which is `{}` for 8-bit grey or RGB and `{}` for alpha or 16 bits; zstd level {} for `zstd` and `zstd-delta`; BC7 effort `{}`.",
        d.opaque.filter.name(),
        CodecKey::of(d.opaque.codec).label(),
        CodecKey::of(d.alpha.codec).label(),
        d.zstd_level,
        CodecKey::of(d.bc7).label().trim_start_matches("bc7 ")
    );
    out!(s);
    let coarse = |key: &str, f: Filter, c: Codec| res.num(key, f, c, |m, _| m.coarse().psnr());
    let (gmin, gmax, split_ratio, clearly) = filter_verdict(res, d);
    let all_lods = |key: &str, f: Filter| res.num(key, f, d.opaque.codec, |m, _| m.all().psnr());
    let coarse_jpeg = |key: &str, f: Filter| coarse(key, f, d.opaque.codec);
    let own_lp = res
        .main
        .iter()
        .filter_map(|r| get(r, Filter::LinearPremultiplied, PNG_FAST)?.own_max.map(|o| o.0))
        .fold(f64::NAN, f64::max);
    out!(
        s,
        "- **Filter: `{}`{}.** It is {} to {} dB closer to the reference than `box` on LODs 1+ of every image (it is `linear` on images without alpha), within {} of its own definition, and removes the fringes of transparent colour. Its cost: the whole split with the default JPEG tiles took {}x the time of `box` here ({} against {} ms/Mpx: {} s more for a 16384² image on this machine; the linear sums cost more than `box`'s 8-bit pair sums). In exchange, over all LODs of `photo` / `high-frequency` / `text` it gives {} / {} / {} dB instead of {} / {} / {} (LODs 1+: {} / {} / {} instead of {} / {} / {}). It also matches the runtime: the page cache is sampled through an sRGB view, so the GPU filters texels and blends LODs in linear light, and a pyramid averaged in sRGB makes contrasty detail (text, lines, foliage) darker each time the view moves to a coarser LOD. `--filter box` stays for data that is not light, where the pyramid must equal the source's plain mean (normal maps, masks, heights), and for output that matches `vips dzsave`'s.",
        d.opaque.filter.name(),
        if clearly {
            ", chosen from these numbers"
        } else {
            "; this run's numbers do not clearly favour it over `box` (a gain under 3 dB on some image, or twice the time), so the default needs another look"
        },
        f1(gmin),
        f1(gmax),
        f2(own_lp),
        f2(split_ratio),
        f1(res.ms(Filter::LinearPremultiplied, d.opaque.codec)),
        f1(res.ms(Filter::Box, d.opaque.codec)),
        f1((res.ms(Filter::LinearPremultiplied, d.opaque.codec) - res.ms(Filter::Box, d.opaque.codec))
            * 16384.0
            * 16384.0
            / 1e9),
        f1(all_lods("photo", Filter::LinearPremultiplied)),
        f1(all_lods("high-frequency", Filter::LinearPremultiplied)),
        f1(all_lods("text", Filter::LinearPremultiplied)),
        f1(all_lods("photo", Filter::Box)),
        f1(all_lods("high-frequency", Filter::Box)),
        f1(all_lods("text", Filter::Box)),
        f1(coarse_jpeg("photo", Filter::LinearPremultiplied)),
        f1(coarse_jpeg("high-frequency", Filter::LinearPremultiplied)),
        f1(coarse_jpeg("text", Filter::LinearPremultiplied)),
        f1(coarse_jpeg("photo", Filter::Box)),
        f1(coarse_jpeg("high-frequency", Filter::Box)),
        f1(coarse_jpeg("text", Filter::Box)),
    );
    let f = d.opaque.filter;
    let l0 = |key: &str, c: Codec| res.num(key, f, c, |m, _| m.lods[0].psnr());
    let kb = |key: &str, c: Codec| res.num(key, f, c, |m, _| m.bytes_per_tile / 1024.0);
    let fronts: Vec<String> = res
        .main
        .iter()
        .filter(|r| !r.img.has_alpha())
        .filter(|r| {
            let ms: Vec<&Measured> = r.measured.values().filter(|m| m.choice.filter() == f).collect();
            let pts: Vec<(f64, f64)> = ms.iter().map(|m| (Axis::Size.value(m, &r.img), m.plot_psnr())).collect();
            pareto(&pts).iter().any(|&i| is_default(ms[i], &r.img, d))
        })
        .map(|r| format!("`{}`", r.img.key))
        .collect();
    let on_front = if fronts.is_empty() { "none of the opaque images".to_string() } else { fronts.join(" and ") };
    let op = Results { all: res.all, main: res.main.iter().copied().filter(|r| !r.img.has_alpha()).collect() };
    let al = Results { all: res.all, main: res.main.iter().copied().filter(|r| r.img.has_alpha()).collect() };
    let smallest_lossless = codec_sweep()
        .into_iter()
        .filter(|c| matches!(c, Codec::Png { .. } | Codec::Zstd { .. }))
        .min_by(|a, b| kb("text", *a).total_cmp(&kb("text", *b)))
        .unwrap_or(PNG_FAST);
    out!(
        s,
        "- **JPEG q85 4:2:0: supported for photographs, not clearly beaten.** Among the codecs (all with the default filter) it is on the size front of {}, where 4:2:0 and 4:4:4 alternate: q75 4:4:4 ({} / {} KiB on `photo` / `text`) gives {} / {} dB at LOD 0 where q85 4:2:0 ({} / {} KiB) gives {} / {}. What argues for 4:4:4 is the failure mode: 4:2:0 loses all colour detail of one or two texels ({} dB at LOD 0 on `high-frequency` against {} with q85 4:4:4), which maps, coloured line art and text show. A default of q85 4:4:4 would cost {}% more bytes on these images; I would keep q85 4:2:0 and point line-art users to `--subsampling 444`, or to lossless tiles: on `text` the smallest lossless ones ({}, {} KiB) are {}x the size of q85 4:2:0's.",
        on_front,
        f1(kb("photo", jpeg(75, true))),
        f1(kb("text", jpeg(75, true))),
        f1(l0("photo", jpeg(75, true))),
        f1(l0("text", jpeg(75, true))),
        f1(kb("photo", jpeg(85, false))),
        f1(kb("text", jpeg(85, false))),
        f1(l0("photo", jpeg(85, false))),
        f1(l0("text", jpeg(85, false))),
        f1(l0("high-frequency", jpeg(85, false))),
        f1(l0("high-frequency", jpeg(85, true))),
        f1(100.0 * (op.bytes_ratio((f, jpeg(85, true)), (f, jpeg(85, false))) - 1.0)),
        CodecKey::of(smallest_lossless).label(),
        f1(kb("text", smallest_lossless)),
        f2(kb("text", smallest_lossless) / kb("text", jpeg(85, false))),
    );
    let png_default = Codec::Png { level: PngLevel::Default };
    out!(
        s,
        "- **PNG fast for alpha and 16 bits: supported** for a tool whose point is throughput: on `alpha`, `default` saves {}% of the bytes for {}x the time (opaque images: {}% for {}x). In packs, `zstd-delta` at the default level is smaller ({} vs {} KiB on `alpha`) in {}x the time.",
        f1(100.0 * (1.0 - al.bytes_ratio((f, png_default), (f, PNG_FAST)))),
        f1(al.ratio((f, png_default), (f, PNG_FAST))),
        f1(100.0 * (1.0 - op.bytes_ratio((f, png_default), (f, PNG_FAST)))),
        f1(op.ratio((f, png_default), (f, PNG_FAST))),
        f1(al.bytes(f, Codec::Zstd { level: d.zstd_level, delta: true }) / 1024.0),
        f1(al.bytes(f, PNG_FAST) / 1024.0),
        f2(al.ratio((f, Codec::Zstd { level: d.zstd_level, delta: true }), (f, PNG_FAST))),
    );
    let zd = |level| (f, Codec::Zstd { level, delta: true });
    let level = d.zstd_level;
    let delta_wins = [1, 3, 9, 19].iter().all(|l| {
        op.bytes(f, Codec::Zstd { level: *l, delta: true }) < op.bytes(f, Codec::Zstd { level: *l, delta: false })
    });
    out!(
        s,
        "- **zstd level {level}: supported.** Against it (`zstd-delta`), level 1 takes {}x the time for {}% more bytes, level 9 {}x for {}% fewer, level 19 {}x for {}% fewer. {}",
        f2(op.ratio(zd(1), zd(level))),
        f1(100.0 * (op.bytes_ratio(zd(1), zd(level)) - 1.0)),
        f1(op.ratio(zd(9), zd(level))),
        f1(100.0 * (1.0 - op.bytes_ratio(zd(9), zd(level)))),
        f1(op.ratio(zd(19), zd(level))),
        f1(100.0 * (1.0 - op.bytes_ratio(zd(19), zd(level)))),
        if delta_wins {
            "`zstd-delta` is smaller than `zstd` at every level on these images: it is the better choice wherever zstd is."
        } else {
            "`zstd-delta` is not smaller than `zstd` at every level here."
        }
    );
    out!(
        s,
        "- **BC7 ultra-fast: supported** as the fast default (very-fast is {}x slower for {} dB at LOD 0 on `photo`, basic adds almost nothing more). Colour under alpha 0 is cleared before encoding, so cut-outs are safe at every effort (above).",
        f1(op.ratio((f, Codec::Bc7 { effort: Bc7Effort::VeryFast }), (f, Codec::Bc7 { effort: Bc7Effort::UltraFast }))),
        f1(l0("photo", Codec::Bc7 { effort: Bc7Effort::VeryFast })
            - l0("photo", Codec::Bc7 { effort: Bc7Effort::UltraFast })),
    );
    out!(s);
}
