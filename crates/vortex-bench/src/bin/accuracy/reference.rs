//! The float64 reference pyramid: for every texel of every LOD, sums over its footprint of real
//! source pixels, from which both the physically right texel (the premultiplied mean in linear
//! light) and each exact filter's own definition follow.

use crate::images::Img;
use crate::tiler::{Filter, Layout};

/// sRGB decode of a code value in [0, 1] (IEC 61966-2-1).
pub fn to_linear(v: f64) -> f64 {
    if v <= 0.04045 { v / 12.92 } else { ((v + 0.055) / 1.055).powf(2.4) }
}

/// sRGB encode of linear light in [0, 1].
pub fn to_srgb(l: f64) -> f64 {
    let l = l.clamp(0.0, 1.0);
    if l <= 0.003_130_8 { l * 12.92 } else { 1.055 * l.powf(1.0 / 2.4) - 0.055 }
}

/// Float sums over a texel's footprint of real source pixels: everything each filter's
/// definition and the physical reference need.
#[derive(Clone, Copy, Default)]
pub struct Sums {
    /// Pixels.
    pub n: f64,
    /// Alpha, in code values.
    pub a: f64,
    /// Colour code values.
    pub code: [f64; 3],
    /// Linear light in [0, 1].
    pub lin: [f64; 3],
    /// Code x alpha code.
    pub code_a: [f64; 3],
    /// Linear x alpha code.
    pub lin_a: [f64; 3],
}

impl Sums {
    pub fn pixel(px: &[u8], lut: &[f64; 256]) -> Sums {
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

    pub fn add(&mut self, o: &Sums) {
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
    pub fn shown(&self) -> ([f64; 3], f64) {
        let c = self.lin_a.map(|v| 255.0 * to_srgb(v / (255.0 * self.n)));
        (c, self.a / self.n)
    }

    /// What an exact filter's own definition gives, unrounded: straight colour and alpha.
    pub fn own(&self, filter: Filter, has_alpha: bool) -> [f64; 4] {
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
pub struct RefLevel {
    pub width: u32,
    pub height: u32,
    pub sums: Vec<Sums>,
    pub shown: Vec<[f64; 3]>,
    pub alpha: Vec<f64>,
}

/// The float64 reference pyramid of `img`: LOD k's texel sums its whole footprint of real
/// source pixels, built level by level from exact children (as the tiler's cascade does).
pub fn reference(img: &Img, layout: &Layout, lut: &[f64; 256]) -> Vec<RefLevel> {
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
