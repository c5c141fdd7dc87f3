//! Address translation: where a sample of a virtual texture lands, as a page and a position in
//! that page's payload at one LOD, computed exactly as the shaders do (`vortex-gpu`'s
//! `shaders/virtual.wgsl`) so that tests can mirror them. Runs on any thread.
//!
//! A single f32 UV cannot address a large texture finely: its resolution is 2^-24 of the
//! texture near u = 1, a sixteenth of a texel at 2^20 texels and a quarter at 2^22. So:
//!
//! - the **2D window** (a viewer's pan and zoom) carries its origin as an integer LOD-0 texel
//!   plus an f32 remainder, and per pixel only adds a small f32 offset; the integer part is
//!   shifted down to the LOD exactly. The error stays a small fraction of a texel at every
//!   virtual size the feedback word can address (4096 pages of any payload);
//! - **meshes** carry f32 UVs in their vertices, which sets their precision (2^-24 of the
//!   texture); translating such a UV adds no further error: `uv * pages` is exact (a power of
//!   two), the page is its floor, and only the fraction is multiplied by the payload.

use crate::page::MAX_LODS;

/// The largest f32 below 1: keeps u = 1 inside the last page.
pub const BELOW_ONE: f32 = 1.0 - f32::EPSILON / 2.0;

/// A sample's address at one LOD: its page and its position in the page's payload, in texels
/// of that LOD (`0 <= within < payload`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct At {
    pub page: [u32; 2],
    pub within: [f32; 2],
}

impl At {
    /// The same sample `levels` LODs coarser: in the ancestor page, at half the position per LOD.
    /// Exact for the page; the position loses nothing but the f32 rounding of one division.
    pub fn ancestor(self, levels: u8, payload: u32) -> At {
        let scale = 1.0 / (1u32 << levels) as f32;
        let mask = (1u32 << levels) - 1;
        let axis = |i: usize| ((self.page[i] & mask) as f32 * payload as f32 + self.within[i]) * scale;
        At { page: [self.page[0] >> levels, self.page[1] >> levels], within: [axis(0), axis(1)] }
    }
}

/// The address of image UV (`u`, `v`) at `lod` in a texture of `pages` pages per side at LOD 0:
/// the mesh path. `u` and `v` are clamped to `[0, BELOW_ONE]` first.
pub fn uv_at(u: f32, v: f32, lod: u8, pages: u32, payload: u32) -> At {
    let n = (pages >> lod).max(1) as f32;
    let axis = |t: f32| {
        let p = t.clamp(0.0, BELOW_ONE) * n;
        let page = p.floor();
        (page as u32, (p - page) * payload as f32)
    };
    let ((px, wx), (py, wy)) = (axis(u), axis(v));
    At { page: [px, py], within: [wx, wy] }
}

/// A 2D window onto one virtual texture as the shaders receive it: the LOD-0 texel position of
/// the frame's top-left corner, split into an integer and an f32 part, and the LOD-0 texels per
/// frame pixel.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WindowOrigin {
    pub int: [u32; 2],
    pub frac: [f32; 2],
    pub step: [f32; 2],
}

impl WindowOrigin {
    /// The window whose top-left corner is at LOD-0 texel `origin` and that advances `step`
    /// texels per pixel. A negative origin (a view hanging over the texture's top or left edge)
    /// is kept in the f32 part, where it is small.
    pub fn new(origin: [f64; 2], step: [f64; 2]) -> WindowOrigin {
        let split = |o: f64| {
            let int = o.floor().clamp(0.0, u32::MAX as f64);
            (int as u32, (o - int) as f32)
        };
        let ((ix, fx), (iy, fy)) = (split(origin[0]), split(origin[1]));
        WindowOrigin { int: [ix, iy], frac: [fx, fy], step: [step[0] as f32, step[1] as f32] }
    }

    /// The LOD of a window sample: `floor(log2(max(step)) + bias)`, clamped to `[0, lod_count - 1]`
    /// (what `feedback::lod_for` gives for a window's derivatives).
    pub fn lod(&self, bias: f32, lod_count: u8) -> u8 {
        crate::feedback::lod_from_footprint(self.step[0].abs().max(self.step[1].abs()), bias, lod_count)
    }

    /// The address at `lod` of frame position (`x`, `y`) (pixel centres at .5) in a texture of
    /// `pages` pages per side at LOD 0; positions beyond the texture clamp to its edge texels.
    pub fn at(&self, x: f32, y: f32, lod: u8, pages: u32, payload: u32) -> At {
        debug_assert!(lod < MAX_LODS);
        let side = (pages >> lod).max(1) as i64 * payload as i64;
        let scale = 1.0 / (1u32 << lod) as f32;
        let mask = (1u32 << lod) - 1;
        let axis = |i: usize, p: f32| {
            let rel = self.frac[i] + p * self.step[i];
            let r = ((self.int[i] & mask) as f32 + rel) * scale;
            let fl = r.floor();
            let t = (self.int[i] >> lod) as i64 + fl as i64;
            let (t, f) = if t < 0 {
                (0, 0.0)
            } else if t >= side {
                (side - 1, BELOW_ONE)
            } else {
                (t, r - fl)
            };
            ((t / payload as i64) as u32, (t % payload as i64) as f32 + f)
        };
        let ((px, wx), (py, wy)) = (axis(0, x), axis(1, y));
        At { page: [px, py], within: [wx, wy] }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// The exact LOD-`lod` texel position of a window sample, in f64.
    fn exact(o: [f64; 2], step: [f64; 2], x: f64, lod: u8) -> f64 {
        (o[0] + x * step[0]) / (1u64 << lod) as f64
    }

    fn texel_of(at: At, payload: u32) -> f64 {
        at.page[0] as f64 * payload as f64 + at.within[0] as f64
    }

    #[test]
    fn window_translation_stays_within_a_sixteenth_of_a_texel_at_the_largest_size() {
        // 4096 pages of 1016-texel payloads: about 2^22 texels per side, the largest the
        // feedback word can address with 1024-texel tiles. Non-dyadic origins and steps.
        let (pages, payload) = (4096u32, 1016u32);
        let side = pages as f64 * payload as f64;
        let mut worst: f64 = 0.0;
        for (k, &(ox, step, lod)) in [
            (side * 0.7316514, 0.371, 0u8),
            (side * 0.9999137, 0.913, 0),
            (side * 0.5123417, 1.37, 0),
            (side * 0.3331, 3.1, 1),
            (side * 0.8711, 27.3, 4),
        ]
        .iter()
        .enumerate()
        {
            let w = WindowOrigin::new([ox, 1000.25 + k as f64], [step, step]);
            for x in 0..256 {
                let x = x as f32 + 0.5;
                let at = w.at(x, 0.5, lod, pages, payload);
                let err = (texel_of(at, payload) - exact([ox, 0.0], [step, step], x as f64, lod)).abs();
                worst = worst.max(err);
            }
        }
        assert!(worst < 1.0 / 64.0, "worst error {worst} texels");
    }

    #[test]
    fn one_f32_uv_would_not_be_precise_enough() {
        // Why the window is split: a plain f32 UV at 2^22 texels is off by far more.
        let side = 4096.0 * 1016.0;
        let (o, step) = (side * 0.7316514, 0.371);
        let mut worst: f64 = 0.0;
        for x in 0..256 {
            let u = (o / side) as f32 + (x as f32 + 0.5) * (step / side) as f32;
            let texel = u as f64 * side;
            worst = worst.max((texel - (o + (x as f64 + 0.5) * step)).abs());
        }
        assert!(worst > 1.0 / 16.0, "f32 UVs were precise ({worst})");
    }

    #[test]
    fn windows_clamp_to_the_texture_edges() {
        let w = WindowOrigin::new([-50.0, 10.0], [1.0, 1.0]);
        assert_eq!(w.at(0.5, 0.5, 0, 4, 100), At { page: [0, 0], within: [0.0, 10.5] });
        let far = WindowOrigin::new([1e9, 399.0], [1.0, 1.0]);
        assert_eq!(far.at(0.5, 0.5, 0, 4, 100), At { page: [3, 3], within: [99.0 + BELOW_ONE, 99.5] });
    }

    #[test]
    fn uv_translation_matches_f64() {
        for &(u, lod) in &[(0.0f32, 0u8), (0.3, 0), (0.999, 2), (1.0, 0), (0.5, 3)] {
            let at = uv_at(u, u, lod, 16, 120);
            let want = (u.min(BELOW_ONE) as f64) * (16u32 >> lod) as f64 * 120.0;
            assert!((texel_of(at, 120) - want).abs() < 1e-4, "{u} at LOD {lod}: {at:?}");
        }
    }

    proptest! {
        #[test]
        fn ancestors_address_the_same_point(
            page in (0u32..4096, 0u32..4096),
            within in (0.0f32..119.99, 0.0f32..119.99),
            levels in 0u8..12,
        ) {
            let at = At { page: [page.0, page.1], within: [within.0, within.1] };
            let up = at.ancestor(levels, 120);
            let scale = (1u32 << levels) as f64;
            for i in 0..2 {
                let fine = at.page[i] as f64 * 120.0 + at.within[i] as f64;
                let coarse = up.page[i] as f64 * 120.0 + up.within[i] as f64;
                prop_assert!((fine / scale - coarse).abs() < 1e-3);
                prop_assert!(up.within[i] < 120.0);
            }
        }

        #[test]
        fn window_and_mesh_paths_agree_where_uvs_are_exact(
            px in 0u32..64, lod in 0u8..4, x in 0u32..32,
        ) {
            // A window on whole texels with a dyadic step: both paths are exact.
            let (pages, payload) = (16u32, 128u32);
            let side = (pages * payload) as f64;
            let w = WindowOrigin::new([px as f64 * 16.0, 0.0], [0.25, 0.25]);
            let at = w.at(x as f32 + 0.5, 0.5, lod, pages, payload);
            let u = ((px as f64 * 16.0 + (x as f64 + 0.5) * 0.25) / side) as f32;
            let by_uv = uv_at(u, 0.5 * 0.25 / side as f32, lod, pages, payload);
            prop_assert_eq!(at.page[0], by_uv.page[0]);
            prop_assert!((at.within[0] - by_uv.within[0]).abs() < 1e-4);
        }
    }
}
