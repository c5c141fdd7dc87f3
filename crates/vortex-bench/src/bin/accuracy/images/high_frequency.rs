//! `high-frequency`: detail at and beyond what a LOD can hold (zone plate, one-texel checkers,
//! stripes and lines, a near-Nyquist grating, a Siemens star), where averaging in the wrong
//! space shows most.

use std::sync::Arc;

use super::Img;
use super::noise::{mix, rgba};

/// near-Nyquist grating and a Siemens star: detail at and beyond what a LOD can hold.
pub fn high_frequency(w: u32, h: u32) -> Img {
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
