//! The CPU reference sampler that images rendered on the GPU are compared against.
//!
//! It samples a virtual texture's LOD images (RGBA8, colour sRGB-encoded, each LOD at its real
//! size) the way an `Rgba8UnormSrgb` texture is sampled: filtering happens in linear light, so
//! colour is decoded with the exact sRGB curve, weighted, and encoded back; alpha is linear
//! and only scaled. Filtering the sRGB values directly is badly off (31 dB on a real image).
//!
//! UV 0..1 spans LOD 0's image, and LOD k is anchored at its top-left corner with texel `c`
//! covering LOD-0 texels `[c 2^k, (c + 1) 2^k)` (as the runtime addresses it, `address`): the
//! texel position of `u` at LOD k is `u * width_0 / 2^k`, not `u * width_k`, which differ when
//! the width is not a multiple of 2^k (the last texel of such a level is partly outside the
//! image). Addressing is clamp-to-edge with texel centres at `i + 0.5` in those positions;
//! trilinear blends the bilinear samples of `floor(lod)` and `floor(lod) + 1`. Weights are exact f32 here, whereas
//! GPUs quantise them (typically to 8 bits), so compare with a tolerance of a code value or so.

/// The LOD images of one virtual texture: LOD 0 is the finest.
pub trait LodImages {
    /// At least 1.
    fn lod_count(&self) -> u8;
    /// Width and height of LOD `lod` in texels (at least 1 each): `ceil(size(0) / 2^lod)`.
    fn size(&self, lod: u8) -> (u32, u32);
    /// Texel (x, y) of LOD `lod`, RGBA8 with sRGB-encoded colour; x and y are within `size`.
    fn texel(&self, lod: u8, x: u32, y: u32) -> [u8; 4];
}

/// One RGBA8 image, row-major.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Rgba8Image {
    /// Width in texels.
    pub width: u32,
    /// Height in texels.
    pub height: u32,
    /// The texels, row by row, top down.
    pub texels: Vec<[u8; 4]>,
}

impl Rgba8Image {
    /// An image whose texel `(x, y)` is `f(x, y)`.
    pub fn from_fn(width: u32, height: u32, mut f: impl FnMut(u32, u32) -> [u8; 4]) -> Rgba8Image {
        assert!(width > 0 && height > 0, "an empty {width}x{height} image");
        let texels = (0..height).flat_map(|y| (0..width).map(move |x| (x, y))).map(|(x, y)| f(x, y)).collect();
        Rgba8Image { width, height, texels }
    }
}

/// LOD images held in memory, finest first (at least one).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct LodChain(pub Vec<Rgba8Image>);

impl LodImages for LodChain {
    fn lod_count(&self) -> u8 {
        self.0.len() as u8
    }
    fn size(&self, lod: u8) -> (u32, u32) {
        let i = &self.0[lod as usize];
        (i.width, i.height)
    }
    fn texel(&self, lod: u8, x: u32, y: u32) -> [u8; 4] {
        let i = &self.0[lod as usize];
        i.texels[y as usize * i.width as usize + x as usize]
    }
}

/// The exact sRGB decode of an 8-bit code value, in [0, 1].
pub fn srgb_to_linear(c: u8) -> f32 {
    let s = c as f64 / 255.0;
    let l = if s <= 0.04045 { s / 12.92 } else { ((s + 0.055) / 1.055).powf(2.4) };
    l as f32
}

/// The exact sRGB encode of a linear value, rounded to the nearest code value; the input is
/// clamped to [0, 1] and NaN gives 0.
pub fn linear_to_srgb(l: f32) -> u8 {
    let l = (l as f64).clamp(0.0, 1.0);
    let s = if l <= 0.003_130_8 { l * 12.92 } else { 1.055 * l.powf(1.0 / 2.4) - 0.055 };
    // `as` saturates and maps NaN to 0.
    (s * 255.0).round() as u8
}

/// A filtered sample in linear light: RGB linear, alpha as stored, all in [0, 1].
pub type Linear = [f32; 4];

fn to_linear(t: [u8; 4]) -> Linear {
    [srgb_to_linear(t[0]), srgb_to_linear(t[1]), srgb_to_linear(t[2]), t[3] as f32 / 255.0]
}

/// Encodes a linear-light sample back to RGBA8 sRGB.
pub fn encode(l: Linear) -> [u8; 4] {
    let alpha = (l[3].clamp(0.0, 1.0) * 255.0).round() as u8;
    [linear_to_srgb(l[0]), linear_to_srgb(l[1]), linear_to_srgb(l[2]), alpha]
}

/// `a + (b - a) * t`: exactly `a` when `a == b` or `t == 0`.
fn lerp(a: Linear, b: Linear, t: f32) -> Linear {
    std::array::from_fn(|i| a[i] + (b[i] - a[i]) * t)
}

/// The texel position at LOD `lod` of `t` along an axis of `n0` texels at LOD 0: `t * n0 / 2^lod`,
/// one rounding (the scale is exact), as the runtime's mesh path computes it.
fn position(t: f32, n0: u32, lod: u8) -> f32 {
    t * (n0 as f32 * (1.0 / (1u32 << lod) as f32))
}

/// The texel under (u, v) at LOD `lod` (clamped to the chain), unfiltered.
pub fn nearest(img: &impl LodImages, lod: u8, u: f32, v: f32) -> [u8; 4] {
    let lod = lod.min(img.lod_count() - 1);
    let ((w0, h0), (w, h)) = (img.size(0), img.size(lod));
    // `as` saturates: negative and NaN give 0.
    let at = |t: f32, n0: u32, n: u32| (position(t, n0, lod).floor() as u32).min(n - 1);
    img.texel(lod, at(u, w0, w), at(v, h0, h))
}

/// Bilinear sample at LOD `lod` (clamped to the chain), in linear light.
pub fn bilinear_linear(img: &impl LodImages, lod: u8, u: f32, v: f32) -> Linear {
    let lod = lod.min(img.lod_count() - 1);
    let ((w0, h0), (w, h)) = (img.size(0), img.size(lod));
    // The two texels around the position - 0.5 and the weight of the second, clamped to the edge.
    let axis = |t: f32, n0: u32, n: u32| {
        let p = position(t, n0, lod) - 0.5;
        let p = if p.is_nan() { 0.0 } else { p };
        let f = p.floor();
        let i0 = (f as i64).clamp(0, n as i64 - 1) as u32;
        let i1 = (f as i64 + 1).clamp(0, n as i64 - 1) as u32;
        (i0, i1, p - f)
    };
    let (x0, x1, fx) = axis(u, w0, w);
    let (y0, y1, fy) = axis(v, h0, h);
    let t = |x, y| to_linear(img.texel(lod, x, y));
    let top = lerp(t(x0, y0), t(x1, y0), fx);
    let bottom = lerp(t(x0, y1), t(x1, y1), fx);
    lerp(top, bottom, fy)
}

/// Bilinear sample at LOD `lod`, filtered in linear light, as RGBA8 sRGB.
pub fn bilinear(img: &impl LodImages, lod: u8, u: f32, v: f32) -> [u8; 4] {
    encode(bilinear_linear(img, lod, u, v))
}

/// Trilinear sample at fractional `lod`, in linear light: the bilinear samples of `floor(lod)`
/// and `floor(lod) + 1` blended by the fraction. LODs below 0 sample LOD 0, LODs at or beyond
/// the coarsest sample the coarsest.
pub fn trilinear_linear(img: &impl LodImages, lod: f32, u: f32, v: f32) -> Linear {
    let max = (img.lod_count() - 1) as f32;
    let lod = if lod.is_nan() { 0.0 } else { lod.clamp(0.0, max) };
    let l0 = lod.floor();
    let t = lod - l0;
    let a = bilinear_linear(img, l0 as u8, u, v);
    if t == 0.0 { a } else { lerp(a, bilinear_linear(img, l0 as u8 + 1, u, v), t) }
}

/// Trilinear sample at fractional `lod`, filtered in linear light, as RGBA8 sRGB.
pub fn trilinear(img: &impl LodImages, lod: f32, u: f32, v: f32) -> [u8; 4] {
    encode(trilinear_linear(img, lod, u, v))
}

/// Anisotropic sample at `uv` with UV derivatives `ddx`, `ddy` per pixel and at most
/// `max_anisotropy` probes, in linear light: the mean of the probes of
/// [`Probes`](crate::anisotropy::Probes), each trilinear (or, with `trilinear` false, bilinear at
/// the LOD below), as the runtime's shader samples.
pub fn anisotropic_linear(
    img: &impl LodImages,
    uv: [f32; 2],
    ddx: [f32; 2],
    ddy: [f32; 2],
    max_anisotropy: u32,
    trilinear: bool,
) -> Linear {
    let (w, h) = img.size(0);
    let probes = crate::anisotropy::Probes::new(ddx, ddy, [w as f32, h as f32], max_anisotropy);
    let lod = probes.lod();
    let mut sum = [0.0f32; 4];
    for i in 0..probes.count {
        let [u, v] = probes.at(uv, i);
        let s = if trilinear {
            trilinear_linear(img, lod, u, v)
        } else {
            // `as` saturates: below 0 (and NaN) is LOD 0.
            bilinear_linear(img, lod.floor() as u8, u, v)
        };
        sum = std::array::from_fn(|c| sum[c] + s[c]);
    }
    sum.map(|c| c / probes.count as f32)
}

/// The ground truth the filters are measured against: the mean of LOD 0 over the pixel's whole
/// footprint, the parallelogram `uv + a ddx + b ddy` for `a`, `b` in [-1/2, 1/2], in linear
/// light. It is integrated by a regular grid of LOD-0 bilinear samples, two per texel along
/// each derivative (at most `max_per_axis`, at least one), so it does not alias where the LODs
/// would: no LOD, no pyramid, just the image. A footprint longer than `max_per_axis / 2` texels
/// is undersampled; choose the cap for the footprints measured.
pub fn supersampled_linear(
    img: &impl LodImages,
    uv: [f32; 2],
    ddx: [f32; 2],
    ddy: [f32; 2],
    max_per_axis: u32,
) -> Linear {
    let (w, h) = img.size(0);
    let count = |d: [f32; 2]| {
        let texels = ((d[0] * w as f32).powi(2) + (d[1] * h as f32).powi(2)).sqrt();
        // `as` saturates: NaN gives 0, raised to 1.
        ((2.0 * texels).ceil() as u32).clamp(1, max_per_axis.max(1))
    };
    let (nx, ny) = (count(ddx), count(ddy));
    let mut sum = [0.0f64; 4];
    for j in 0..ny {
        let b = (j as f32 + 0.5) / ny as f32 - 0.5;
        for i in 0..nx {
            let a = (i as f32 + 0.5) / nx as f32 - 0.5;
            let s = bilinear_linear(img, 0, uv[0] + a * ddx[0] + b * ddy[0], uv[1] + a * ddx[1] + b * ddy[1]);
            sum = std::array::from_fn(|c| sum[c] + s[c] as f64);
        }
    }
    sum.map(|c| (c / (nx * ny) as f64) as f32)
}

#[cfg(test)]
mod tests {
    use proptest::prelude::*;

    use super::*;

    #[test]
    fn srgb_round_trip_is_the_identity() {
        for c in 0..=255u8 {
            assert_eq!(linear_to_srgb(srgb_to_linear(c)), c, "{c}");
        }
        // Golden values of the curve.
        assert_eq!(srgb_to_linear(0), 0.0);
        assert_eq!(srgb_to_linear(255), 1.0);
        assert!((srgb_to_linear(10) - 10.0 / 255.0 / 12.92).abs() < 1e-9, "linear segment");
        assert!((srgb_to_linear(128) - 0.215_860_5).abs() < 1e-6);
        assert_eq!(linear_to_srgb(0.5), 188);
        assert_eq!(linear_to_srgb(-1.0), 0);
        assert_eq!(linear_to_srgb(2.0), 255);
        assert_eq!(linear_to_srgb(f32::NAN), 0);
        let increasing = (0..255u8).all(|c| srgb_to_linear(c) < srgb_to_linear(c + 1));
        assert!(increasing);
    }

    /// A chain of `levels` LODs halving (rounded up) from `w` x `h`, texels from `f(lod, x, y)`.
    fn chain(w: u32, h: u32, levels: u8, f: impl Fn(u8, u32, u32) -> [u8; 4]) -> LodChain {
        LodChain(
            (0..levels)
                .map(|l| Rgba8Image::from_fn(w.div_ceil(1 << l), h.div_ceil(1 << l), |x, y| f(l, x, y)))
                .collect(),
        )
    }

    fn noise(l: u8, x: u32, y: u32) -> [u8; 4] {
        let h = (x.wrapping_mul(0x9E37_79B9) ^ y.wrapping_mul(0x85EB_CA6B) ^ (l as u32) << 7).wrapping_mul(0xC2B2_AE35);
        h.to_le_bytes()
    }

    #[test]
    fn bilinear_at_texel_centres_is_the_texel() {
        for (w, h) in [(1, 1), (3, 5), (16, 16), (7, 2)] {
            let img = chain(w, h, 1, noise);
            for y in 0..h {
                for x in 0..w {
                    let (u, v) = ((x as f32 + 0.5) / w as f32, (y as f32 + 0.5) / h as f32);
                    assert_eq!(bilinear(&img, 0, u, v), img.texel(0, x, y), "{w}x{h} ({x}, {y})");
                    assert_eq!(nearest(&img, 0, u, v), img.texel(0, x, y));
                    assert_eq!(trilinear(&img, 0.0, u, v), img.texel(0, x, y));
                }
            }
        }
    }

    #[test]
    fn black_and_white_mix_in_linear_light() {
        let img = LodChain(vec![Rgba8Image { width: 2, height: 1, texels: vec![[0, 0, 0, 0], [255, 255, 255, 255]] }]);
        // Halfway between the two centres (u = 0.25 and 0.75).
        assert_eq!(bilinear(&img, 0, 0.5, 0.5), [188, 188, 188, 128], "alpha is linear: 127.5 rounds to 128");
        assert_eq!(bilinear_linear(&img, 0, 0.5, 0.5), [0.5; 4]);
        // A quarter of the way: linear 0.25 is sRGB 137.
        assert_eq!(bilinear(&img, 0, 0.375, 0.5), [137, 137, 137, 64]);
        // Clamp to edge: outside the centres each texel is alone.
        assert_eq!(bilinear(&img, 0, 0.0, 0.0), [0, 0, 0, 0]);
        assert_eq!(bilinear(&img, 0, 0.999, 0.999), [255; 4]);
    }

    #[test]
    fn trilinear_blends_lods_in_linear_light() {
        let img = chain(4, 4, 3, |l, _, _| if l == 0 { [0, 0, 0, 0] } else { [255; 4] });
        assert_eq!(trilinear(&img, 0.5, 0.3, 0.6), [188, 188, 188, 128]);
        assert_eq!(trilinear(&img, 0.25, 0.3, 0.6), [137, 137, 137, 64]);
        assert_eq!(trilinear(&img, -3.0, 0.3, 0.6), [0; 4], "below LOD 0");
        assert_eq!(trilinear(&img, 9.5, 0.3, 0.6), [255; 4], "beyond the coarsest");
        assert_eq!(nearest(&img, 9, 0.3, 0.6), [255; 4]);
    }

    #[test]
    fn coarse_lods_of_odd_sizes_are_anchored_at_the_top_left() {
        // 5 texels wide: LOD 1 has 3, the last covering LOD-0 texel 4 only, so the image ends
        // halfway into it (u = 1 is LOD-1 position 2.5, not 3).
        let img = chain(5, 1, 2, |l, x, _| [(10 * l as u32 + x) as u8, 0, 0, 255]);
        assert_eq!(nearest(&img, 1, 0.999, 0.5), [12, 0, 0, 255]);
        assert_eq!(nearest(&img, 1, 0.79, 0.5), [11, 0, 0, 255], "LOD-0 texel 3 is in LOD-1 texel 1");
        assert_eq!(nearest(&img, 1, 0.81, 0.5), [12, 0, 0, 255], "LOD-0 texel 4 is in LOD-1 texel 2");
        // LOD-1 texel 1's centre is LOD-0 position 3, u = 0.6.
        assert_eq!(bilinear(&img, 1, 0.6, 0.5), [11, 0, 0, 255]);
        // Between the centres of texels 1 and 2 (u = 0.7 is LOD-1 position 1.75): a quarter of
        // the way, in linear light.
        let mix = bilinear_linear(&img, 1, 0.7, 0.5)[0];
        let want = srgb_to_linear(11) * 0.75 + srgb_to_linear(12) * 0.25;
        assert!((mix - want).abs() < 1e-6, "{mix} {want}");
    }

    #[test]
    fn anisotropy_keeps_detail_along_the_minor_axis() {
        // Stripes across v, one texel each: a footprint 8 texels long in u and 1 in v sees them.
        let img = chain(64, 64, 7, |l, _, y| {
            if l == 0 && y % 2 == 0 {
                [255; 4]
            } else if l == 0 {
                [0, 0, 0, 255]
            } else {
                [188, 188, 188, 255]
            }
        });
        let (ddx, ddy) = ([8.0 / 64.0, 0.0], [0.0, 1.0 / 64.0]);
        let uv = [0.5, 20.5 / 64.0];
        let iso = anisotropic_linear(&img, uv, ddx, ddy, 1, true);
        let aniso = anisotropic_linear(&img, uv, ddx, ddy, 8, true);
        assert_eq!(iso, trilinear_linear(&img, 3.0, uv[0], uv[1]), "one probe is trilinear");
        assert_eq!(encode(iso), [188, 188, 188, 255], "LOD 3: grey");
        assert_eq!(encode(aniso), [255; 4], "eight LOD-0 probes along the white row");
        // The ground truth over the 8 x 1 footprint: LOD 0's bilinear samples a quarter texel
        // either side of the row's centre, each three quarters white.
        let truth = supersampled_linear(&img, uv, ddx, ddy, 64);
        assert!((truth[0] - 0.75).abs() < 1e-6, "{truth:?}");
    }

    #[test]
    fn supersampling_a_constant_is_the_constant() {
        let img = chain(16, 16, 1, |_, _, _| [10, 20, 30, 255]);
        let s = supersampled_linear(&img, [0.3, 0.7], [0.5, 0.1], [-0.2, 0.3], 64);
        assert_eq!(encode(s), [10, 20, 30, 255]);
        assert_eq!(encode(supersampled_linear(&img, [0.3, 0.7], [0.0; 2], [f32::NAN; 2], 0)), [10, 20, 30, 255]);
    }

    proptest! {
        #[test]
        fn a_constant_texture_samples_its_constant(
            c in any::<[u8; 4]>(), u in 0f32..1.0, v in 0f32..1.0, lod in 0f32..6.0,
            w in 1u32..40, h in 1u32..40,
        ) {
            let img = chain(w, h, 5, |_, _, _| c);
            prop_assert_eq!(trilinear(&img, lod, u, v), c);
            prop_assert_eq!(bilinear(&img, lod as u8, u, v), c);
            prop_assert_eq!(nearest(&img, lod as u8, u, v), c);
        }

        #[test]
        fn trilinear_at_an_integer_lod_is_bilinear(u in 0f32..1.0, v in 0f32..1.0, lod in 0u8..4) {
            let img = chain(19, 12, 4, noise);
            prop_assert_eq!(trilinear(&img, lod as f32, u, v), bilinear(&img, lod, u, v));
        }

        #[test]
        fn bilinear_stays_within_its_four_texels(u in 0f32..1.0, v in 0f32..1.0) {
            let img = chain(9, 6, 1, noise);
            let got = bilinear(&img, 0, u, v);
            let (x, y) = ((u * 9.0 - 0.5).floor(), (v * 6.0 - 0.5).floor());
            let around: Vec<[u8; 4]> = [(0., 0.), (1., 0.), (0., 1.), (1., 1.)]
                .iter()
                .map(|(dx, dy)| img.texel(0, (x + dx).clamp(0.0, 8.0) as u32, (y + dy).clamp(0.0, 5.0) as u32))
                .collect();
            for ch in 0..4 {
                let lo = around.iter().map(|t| t[ch]).min().unwrap();
                let hi = around.iter().map(|t| t[ch]).max().unwrap();
                prop_assert!(lo <= got[ch] && got[ch] <= hi);
            }
        }
    }
}
