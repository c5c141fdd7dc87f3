//! `photo`: a photograph-like scene (sky, textured ground, a lit sphere, a building's window
//! grid, sensor grain): smooth areas, texture and hard edges together.

use std::sync::Arc;

use super::Img;
use super::noise::{coverage, fbm, hash, mix, rgba, unit, value_noise};

/// sensor grain: smooth areas, texture and hard edges.
pub fn photo(w: u32, h: u32) -> Img {
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
