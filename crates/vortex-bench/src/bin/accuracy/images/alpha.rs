//! `alpha` and `alpha-clean`: textured cut-outs with anti-aliased edges over a transparent
//! background whose hidden colour is random noise (or black): what leaks from under alpha 0.

use std::sync::Arc;

use super::Img;
use super::noise::{coverage, fbm, hash, segment_distance};

/// with `clean`).
pub fn alpha_cutouts(w: u32, h: u32, clean: bool) -> Img {
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
