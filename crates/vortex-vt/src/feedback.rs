//! The feedback word, and the math a shader uses to choose the page a sample wants.
//!
//! The feedback pass renders the scene into a small `R32Uint` buffer, writing per pixel the
//! page it would sample. The word is the original library's 32 bits, least significant first:
//!
//! ```text
//!  31    28 27    24 23                  12 11                   0
//! +--------+--------+----------------------+----------------------+
//! | tex id |  LOD   |       page y         |       page x         |
//! +--------+--------+----------------------+----------------------+
//!   4 bits   4 bits        12 bits                12 bits
//! ```
//!
//! so a WGSL shader produces it with shifts alone:
//! `(x & 0xFFFu) | ((y & 0xFFFu) << 12u) | (lod << 24u) | (tex << 28u)`.
//!
//! LOD 15 is "no request": [`decode`] returns `None` for every word whose LOD field is 15,
//! whatever its other bits, so [`NO_REQUEST`] (all ones) can never alias a page. The buffer
//! must be cleared to [`NO_REQUEST`], not to 0: word 0 is page (0, 0) of LOD 0 of texture 0.
//!
//! [`lod_for`], [`page_at`] and [`feedback_bias`] mirror the shader so that tests can compare a
//! CPU prediction with what the GPU wrote. They use f32, like the shader; within about one ulp
//! of a LOD boundary the two may still disagree (WGSL's `log2` is not correctly rounded).

use crate::page::{MAX_LODS, MAX_PAGES_PER_SIDE, MAX_TEXTURES, PageId, TextureGrid};

/// Bit position of page x (12 bits).
pub const X_SHIFT: u32 = 0;
/// Bit position of page y (12 bits).
pub const Y_SHIFT: u32 = 12;
/// Bit position of the LOD (4 bits).
pub const LOD_SHIFT: u32 = 24;
/// Bit position of the texture id (4 bits).
pub const TEXTURE_SHIFT: u32 = 28;
const COORD_MASK: u32 = 0xFFF;
const NIBBLE_MASK: u32 = 0xF;
/// The LOD field value that means "no request".
pub const NO_REQUEST_LOD: u8 = 15;
/// The clear value of the feedback buffer: a pixel that wants no page (LOD field 15).
pub const NO_REQUEST: u32 = 0xFFFF_FFFF;

/// The feedback word of `page`. The page must be within the word's limits (texture < 16,
/// LOD < 15, x and y < 4096); this is checked in debug builds only.
pub fn encode(page: PageId) -> u32 {
    debug_assert!(page.texture < MAX_TEXTURES, "texture id {} out of range", page.texture);
    debug_assert!(page.lod < MAX_LODS, "LOD {} out of range", page.lod);
    debug_assert!(page.x < MAX_PAGES_PER_SIDE && page.y < MAX_PAGES_PER_SIDE, "page {page:?} out of range");
    (page.x as u32 & COORD_MASK) << X_SHIFT
        | (page.y as u32 & COORD_MASK) << Y_SHIFT
        | (page.lod as u32 & NIBBLE_MASK) << LOD_SHIFT
        | (page.texture as u32 & NIBBLE_MASK) << TEXTURE_SHIFT
}

/// The page a feedback word requests, or `None` for "no request" (any word with LOD field 15).
/// The page is not checked against any texture's grid: see `analysis` for that.
pub fn decode(word: u32) -> Option<PageId> {
    let lod = ((word >> LOD_SHIFT) & NIBBLE_MASK) as u8;
    (lod != NO_REQUEST_LOD).then_some(PageId {
        texture: ((word >> TEXTURE_SHIFT) & NIBBLE_MASK) as u8,
        lod,
        x: ((word >> X_SHIFT) & COORD_MASK) as u16,
        y: ((word >> Y_SHIFT) & COORD_MASK) as u16,
    })
}

/// The LOD a sample wants, from its UV derivatives per pixel (`dpdx = (dudx, dvdx)`,
/// `dpdy = (dudy, dvdy)`), isotropically as GPUs do: the footprint is the longer of the two
/// derivative vectors in texels, and the LOD is `floor(log2(footprint) + bias)` clamped to
/// `[0, lod_count - 1]`. A footprint of exactly 2^k texels gives LOD k (with bias 0); anything
/// below 1 texel, zero or NaN gives LOD 0; infinity gives the coarsest LOD.
///
/// The thesis took the smaller derivative instead; the larger is what the GPU's own isotropic
/// LOD selection does, so the page asked for is the one the filtered sample will read.
///
/// In WGSL: `let f = max(length(dpdx(uv)), length(dpdy(uv))) * side;`
/// `let lod = clamp(floor(log2(f) + bias), 0.0, f32(lod_count - 1u));`.
pub fn lod_for(dudx: f32, dvdx: f32, dudy: f32, dvdy: f32, texture_side_texels: f32, bias: f32, lod_count: u8) -> u8 {
    let length = |a: f32, b: f32| {
        let (a, b) = (a * texture_side_texels, b * texture_side_texels);
        (a * a + b * b).sqrt()
    };
    lod_from_footprint(length(dudx, dvdx).max(length(dudy, dvdy)), bias, lod_count)
}

/// `floor(log2(footprint) + bias)` clamped to `[0, lod_count - 1]`, for a footprint in LOD-0
/// texels per pixel (what [`lod_for`] computes from derivatives, and a 2D window from its step).
pub fn lod_from_footprint(footprint: f32, bias: f32, lod_count: u8) -> u8 {
    let max_lod = lod_count.saturating_sub(1);
    let lod = (footprint.log2() + bias).floor();
    // NaN (e.g. a zero footprint with an infinite bias) counts as magnified.
    if lod.is_nan() || lod < 0.0 {
        0
    } else if lod >= max_lod as f32 {
        max_lod
    } else {
        lod as u8
    }
}

/// The page of LOD `lod` that holds the sample at (u, v): `floor(u * pages_at_lod)`, clamped to
/// the grid (so u = 1.0, negative u and NaN stay in range). Exact in f32: the page count is a
/// power of two.
pub fn page_at(u: f32, v: f32, lod: u8, grid: &TextureGrid) -> (u16, u16) {
    let lod = lod.min(grid.lod_count - 1);
    let n = grid.pages_per_side(lod);
    let side = n as f32;
    // `as` saturates: negative and NaN give 0, too-large values give u16::MAX, then clamped.
    let at = |t: f32| ((t * side).floor() as u16).min(n - 1);
    (at(u), at(v))
}

/// The LOD bias that makes a feedback buffer smaller than the frame ask for the LODs the frame
/// needs: `log2(min(fw / FW, fh / FH))`, to be added to any bias of the frame itself.
///
/// The sign is negative (zero at full resolution): at 1/8 of the frame's size each feedback
/// pixel spans 8 frame pixels, so its UV derivatives are 8 times larger and `lod_for` would
/// answer 3 LODs too coarse; -3 brings it back. With unequal ratios the smaller one (the axis
/// scaled down most) sets the bias, so the feedback never asks coarser than the frame needs.
pub fn feedback_bias(feedback_w: u32, feedback_h: u32, frame_w: u32, frame_h: u32) -> f32 {
    let rx = feedback_w as f32 / frame_w as f32;
    let ry = feedback_h as f32 / frame_h as f32;
    rx.min(ry).log2()
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn golden_bit_layout() {
        assert_eq!(encode(PageId::new(0, 0, 0, 0)), 0);
        assert_eq!(encode(PageId::new(0, 0, 1, 0)), 0x0000_0001);
        assert_eq!(encode(PageId::new(0, 0, 0, 1)), 0x0000_1000);
        assert_eq!(encode(PageId::new(0, 1, 0, 0)), 0x0100_0000);
        assert_eq!(encode(PageId::new(1, 0, 0, 0)), 0x1000_0000);
        assert_eq!(encode(PageId::new(0xA, 0x3, 0x123, 0x456)), 0xA345_6123);
        assert_eq!(encode(PageId::new(15, 14, 4095, 4095)), 0xFEFF_FFFF);
        assert_eq!(decode(0xA345_6123), Some(PageId::new(0xA, 0x3, 0x123, 0x456)));
        // The WGSL expression in the module doc, written out.
        let (x, y, lod, tex) = (0x123u32, 0x456u32, 3u32, 0xAu32);
        assert_eq!((x & 0xFFF) | ((y & 0xFFF) << 12) | (lod << 24) | (tex << 28), 0xA345_6123);
    }

    #[test]
    fn lod_15_is_never_a_page() {
        assert_eq!(decode(NO_REQUEST), None);
        assert_eq!(NO_REQUEST >> LOD_SHIFT & 0xF, NO_REQUEST_LOD as u32);
        // Every word with LOD field 15: 4 texture bits x 24 coordinate bits, sampled densely.
        for tex in 0..16u32 {
            for xy in (0..1u32 << 24).step_by(4093).chain([0xFF_FFFF]) {
                assert_eq!(decode(tex << 28 | 15 << 24 | xy), None);
            }
        }
    }

    #[test]
    fn every_lod_below_15_decodes() {
        for lod in 0..15u32 {
            assert_eq!(decode(lod << 24).map(|p| p.lod), Some(lod as u8));
        }
    }

    proptest! {
        #[test]
        fn round_trip_of_valid_pages(tex in 0u8..16, lod in 0u8..15, x in 0u16..4096, y in 0u16..4096) {
            let p = PageId::new(tex, lod, x, y);
            prop_assert_eq!(decode(encode(p)), Some(p));
        }

        #[test]
        fn words_with_lod_15_decode_to_none(word in any::<u32>()) {
            let w = word | 15 << LOD_SHIFT;
            prop_assert_eq!(decode(w), None);
        }

        #[test]
        fn decode_then_encode_is_identity(word in any::<u32>()) {
            if let Some(p) = decode(word) {
                prop_assert_eq!(encode(p), word);
            }
        }

        #[test]
        fn lod_is_monotonic_in_the_footprint(a in 1e-9f32..10.0, b in 1e-9f32..10.0) {
            let (lo, hi) = if a <= b { (a, b) } else { (b, a) };
            let l = |f: f32| lod_for(f / 65536.0, 0.0, 0.0, 0.0, 65536.0, 0.0, 17);
            prop_assert!(l(lo) <= l(hi));
        }

        #[test]
        fn the_page_holds_the_sample(u in 0f32..1.0, v in 0f32..1.0, lod in 0u8..10) {
            let g = TextureGrid::new(512).unwrap();
            let (x, y) = page_at(u, v, lod, &g);
            let n = g.pages_per_side(lod) as f32;
            prop_assert!(g.contains(PageId::new(0, lod, x, y)));
            prop_assert!(x as f32 / n <= u && u < (x + 1) as f32 / n);
            prop_assert!(y as f32 / n <= v && v < (y + 1) as f32 / n);
        }
    }

    /// The LOD of a footprint of `texels` along u, on a 65536-texel texture with 17 LODs.
    fn lod_of(texels: f32) -> u8 {
        lod_for(texels / 65536.0, 0.0, 0.0, 0.0, 65536.0, 0.0, 17)
    }

    #[test]
    fn powers_of_two_are_exact() {
        for k in 0..17 {
            let f = (k as f32).exp2();
            assert_eq!(lod_of(f), k as u8, "2^{k}");
            // The same footprint along v, along a diagonal of the y derivative, or split
            // between x and y derivatives (the larger one counts).
            assert_eq!(lod_for(0.0, f / 65536.0, 0.0, 0.0, 65536.0, 0.0, 17), k as u8);
            assert_eq!(lod_for(0.0, 0.0, 0.0, f / 65536.0, 65536.0, 0.0, 17), k as u8);
            assert_eq!(lod_for(f / 131072.0, 0.0, 0.0, f / 65536.0, 65536.0, 0.0, 17), k as u8);
            if k > 0 {
                assert_eq!(lod_of(f * 0.999), k as u8 - 1, "just below 2^{k}");
            }
            assert_eq!(lod_of(f * 1.001), k as u8, "just above 2^{k}");
            assert_eq!(lod_of(f * 1.999), k.min(16) as u8, "just below 2^{}", k + 1);
        }
        // A 3-4-5 triangle: footprint 5 texels, LOD 2.
        assert_eq!(lod_for(3.0, 4.0, 0.0, 0.0, 1.0, 0.0, 10), 2);
        // Bias moves by whole LODs, and half a LOD of bias rounds by the usual floor.
        assert_eq!(lod_for(4.0, 0.0, 0.0, 0.0, 1.0, 1.0, 10), 3);
        assert_eq!(lod_for(4.0, 0.0, 0.0, 0.0, 1.0, -1.0, 10), 1);
        assert_eq!(lod_for(4.0, 0.0, 0.0, 0.0, 1.0, 0.5, 10), 2);
        assert_eq!(lod_for(4.0, 0.0, 0.0, 0.0, 1.0, -0.5, 10), 1);
    }

    #[test]
    fn lod_is_clamped() {
        assert_eq!(lod_of(0.5), 0, "magnified");
        assert_eq!(lod_of(1e-30), 0);
        assert_eq!(lod_for(0.0, 0.0, 0.0, 0.0, 65536.0, 0.0, 17), 0, "zero footprint");
        assert_eq!(lod_for(f32::NAN, 0.0, 0.0, 0.0, 65536.0, 0.0, 17), 0, "NaN");
        assert_eq!(lod_for(0.0, 0.0, 0.0, 0.0, 65536.0, f32::INFINITY, 17), 0, "-inf + inf");
        assert_eq!(lod_of(65536.0 * 4.0), 16, "beyond the coarsest");
        assert_eq!(lod_for(f32::INFINITY, 0.0, 0.0, 0.0, 65536.0, 0.0, 17), 16);
        assert_eq!(lod_for(1.0, 0.0, 0.0, 0.0, 8.0, 0.0, 3), 2, "8 texels, 3 LODs");
        assert_eq!(lod_for(1.0, 0.0, 0.0, 0.0, 8.0, 0.0, 1), 0, "one LOD");
        assert_eq!(lod_for(1.0, 0.0, 0.0, 0.0, 8.0, -100.0, 4), 0, "big negative bias");
    }

    #[test]
    fn pages_of_samples() {
        let g = TextureGrid::new(512).unwrap();
        assert_eq!(page_at(0.0, 0.0, 0, &g), (0, 0));
        assert_eq!(page_at(0.5, 0.25, 0, &g), (256, 128));
        assert_eq!(page_at(0.5, 0.25, 3, &g), (32, 16));
        assert_eq!(page_at(0.999_999, 0.999_999, 0, &g), (511, 511));
        assert_eq!(page_at(0.5, 0.5, 9, &g), (0, 0), "root");
        assert_eq!(page_at(1.0, 1.5, 0, &g), (511, 511), "clamped high");
        assert_eq!(page_at(-0.25, f32::NAN, 1, &g), (0, 0), "clamped low, NaN");
        assert_eq!(page_at(0.75, 0.75, 200, &g), (0, 0), "LOD clamped to the root");
        // A page boundary belongs to the page after it.
        assert_eq!(page_at(1.0 / 512.0, 0.0, 0, &g), (1, 0));
        assert_eq!(page_at(1.0 / 512.0 - f32::EPSILON / 512.0, 0.0, 0, &g), (0, 0));
    }

    #[test]
    fn feedback_bias_is_negative_for_a_smaller_buffer() {
        assert_eq!(feedback_bias(1280, 720, 1280, 720), 0.0);
        assert_eq!(feedback_bias(160, 90, 1280, 720), -3.0);
        assert_eq!(feedback_bias(320, 180, 1280, 720), -2.0);
        // Unequal ratios: the axis scaled down most sets the bias.
        assert_eq!(feedback_bias(160, 180, 1280, 720), -3.0);
        assert!((feedback_bias(128, 72, 1280, 720) - (0.1f32).log2()).abs() < 1e-6);
        // The point of it: a feedback pixel at 1/8 size has 8x the derivatives, and with the
        // bias it asks for the same LOD as the frame pixel.
        for k in 0..14 {
            let d = (k as f32).exp2() / 65536.0 * 1.3;
            let frame = lod_for(d, 0.0, 0.0, d, 65536.0, 0.0, 17);
            let fb = lod_for(8.0 * d, 0.0, 0.0, 8.0 * d, 65536.0, feedback_bias(160, 90, 1280, 720), 17);
            assert_eq!(fb, frame, "2^{k} * 1.3 texels");
            assert_eq!(lod_for(8.0 * d, 0.0, 0.0, 8.0 * d, 65536.0, 0.0, 17), (frame + 3).min(16));
        }
    }
}
