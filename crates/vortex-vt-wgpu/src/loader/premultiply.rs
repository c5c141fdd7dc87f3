//! Premultiplied alpha for the page cache. The GPU filters the cache's texels as they are
//! (decoded from sRGB to linear light); filtering straight-alpha texels mixes in the colour of
//! transparent ones, which is whatever the image kept under alpha 0 (green and pink fringes
//! around magnified cut-outs). Filtering premultiplied texels weighs every colour by its alpha,
//! so a transparent texel adds nothing. Each texel becomes `srgb(linear(c) * a)`: premultiplied
//! in linear light, as the tiler's default `linear-premultiplied` filter averages, and stored
//! sRGB-encoded so that the dark colours of low alphas keep their precision.

use std::sync::OnceLock;

/// The linear value of each sRGB code value.
fn linear() -> &'static [f32; 256] {
    static TABLE: OnceLock<[f32; 256]> = OnceLock::new();
    TABLE.get_or_init(|| {
        std::array::from_fn(|c| {
            let v = c as f32 / 255.0;
            if v <= 0.04045 { v / 12.92 } else { ((v + 0.055) / 1.055).powf(2.4) }
        })
    })
}

/// The sRGB code value nearest to linear `v` (0..=1).
fn encode(v: f32) -> u8 {
    let s = if v <= 0.003_130_8 { v * 12.92 } else { 1.055 * v.powf(1.0 / 2.4) - 0.055 };
    (s * 255.0 + 0.5).clamp(0.0, 255.0) as u8
}

/// Premultiplies RGBA8 texels (sRGB colour, straight alpha) in place. Opaque texels stay as they
/// are; transparent ones become 0.
pub(super) fn premultiply(texels: &mut [u8]) {
    let linear = linear();
    for t in texels.chunks_exact_mut(4) {
        match t[3] {
            255 => {}
            0 => t[..3].fill(0),
            a => {
                let a = f32::from(a) / 255.0;
                for c in &mut t[..3] {
                    *c = encode(linear[usize::from(*c)] * a);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn opaque_texels_are_unchanged_and_transparent_ones_black() {
        let mut t = vec![10, 200, 30, 255, 0, 255, 0, 0];
        premultiply(&mut t);
        assert_eq!(t, [10, 200, 30, 255, 0, 0, 0, 0]);
    }

    #[test]
    fn half_alpha_halves_linear_light() {
        let mut t = vec![255, 128, 0, 128];
        premultiply(&mut t);
        // linear(255) * 128/255 = 0.502 -> sRGB 188; linear(128) = 0.2159 * 0.502 = 0.1084 -> 93.
        assert_eq!(t, [188, 93, 0, 128]);
    }

    #[test]
    fn every_code_value_round_trips_when_opaque_and_encode_inverts_linear() {
        for c in 0..=255u8 {
            assert_eq!(encode(linear()[usize::from(c)]), c);
        }
    }
}
