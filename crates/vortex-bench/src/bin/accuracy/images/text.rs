//! `text`: glyph-like strokes from 7 to 56 texels tall and line art, anti-aliased on paper:
//! thin dark detail on a light ground, which averaging in sRGB darkens.

use std::f64::consts::{FRAC_PI_6, TAU};
use std::sync::Arc;

use super::Img;
use super::noise::{coverage, hash, mix, rgba, segment_distance, unit};

/// A stroke: segment from `a` to `b`, `width` texels wide.
struct Stroke {
    a: (f64, f64),
    b: (f64, f64),
    width: f64,
    ink: [f64; 3],
}

/// Rows of glyph-like shapes (stems, bars, diagonals, bowls, dots) from 7 to 56 texels tall,
/// and line art (a fan of 1-texel lines, concentric rings, hatching), anti-aliased, on paper.
pub fn text_art(w: u32, h: u32) -> Img {
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
