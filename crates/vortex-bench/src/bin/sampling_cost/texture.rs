//! The synthetic texture: one deterministic 2048² RGBA8 image with smooth colour, a fine
//! grating, thin lines and noise, and its box LOD chain. Its packs (one of raw tiles per border)
//! are written by `vortex_vt_wgpu::testing::write_pack`, in the tiler's layout.

use crate::api::{LodChain, Rgba8Image, box_chain};

/// An integer hash of a texel position, for noise that is the same on every run.
pub fn hash(x: u32, y: u32) -> u32 {
    let mut h = x.wrapping_mul(0x2c1b_3c6d) ^ y.wrapping_mul(0x297a_2d39) ^ 0x5bd1_e995;
    h ^= h >> 15;
    h = h.wrapping_mul(0x85eb_ca6b);
    h ^= h >> 13;
    h = h.wrapping_mul(0xc2b2_ae35);
    h ^ (h >> 16)
}

/// LOD 0, texel (`x`, `y`), of a `side`-texel texture: slow colour waves and a diagonal ramp,
/// a diagonal grating of 4.7 texels whose contrast varies slowly, dark lines one texel wide every
/// 37 texels across and 29 down, and a little noise.
pub fn source_texel(x: u32, y: u32, side: u32) -> [u8; 4] {
    let (fx, fy) = (x as f64, y as f64);
    let ramp = (fx + fy) / (2.0 * (side - 1) as f64);
    let base = [
        128.0 + 70.0 * (fx * 0.0041 + fy * 0.0023).sin(),
        120.0 + 70.0 * (fy * 0.0037 - fx * 0.0013 + 1.7).sin(),
        50.0 + 150.0 * ramp,
    ];
    let contrast = 0.5 + 0.5 * (fx * 0.0029 - fy * 0.0051 + 0.4).sin();
    let grating = 38.0 * contrast * ((fx * 0.8 + fy * 0.6) * std::f64::consts::TAU / 4.7).sin();
    let line = if x % 37 == 11 || y % 29 == 5 { -70.0 } else { 0.0 };
    let noise = (hash(x, y) % 17) as f64 - 8.0;
    let code = |v: f64| v.round().clamp(0.0, 255.0) as u8;
    let detail = grating + line + noise;
    [code(base[0] + detail), code(base[1] + detail), code(base[2] + 0.6 * detail), 255]
}

/// The texture's LODs: LOD 0 from [`source_texel`], each further LOD the 2x2 mean of the one
/// before in code values, rounded half up ([`box_chain`]: the tiler's `box` filter on an image
/// that fills its page grid).
pub fn lod_chain(side: u32, lods: u8) -> LodChain {
    box_chain(Rgba8Image::from_fn(side, side, |x, y| source_texel(x, y, side)), lods)
}
