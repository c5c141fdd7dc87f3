//! Anisotropic filtering's plan for one pixel: how many probes, where, and at which LOD. The
//! shader (`vt_aniso` in `vortex-vt-wgpu`'s `vt.wgsl`) and the reference sampler
//! ([`crate::sampler::anisotropic_linear`]) both follow it, so that they can be compared.
//!
//! A pixel seen at a grazing angle covers a long thin footprint on the texture: its UV
//! derivatives `ddx`, `ddy` (per pixel, scaled to LOD-0 texels) differ in length. Isotropic
//! filtering takes its LOD from the longer one, which blurs the short direction as much as the
//! long one (the mush toward the horizon). Here the LOD comes from the shorter one instead, and
//! the long direction is covered by `count` probes spaced evenly along the longer derivative,
//! each an ordinary (bilinear or trilinear) sample, averaged:
//!
//! - `major`, `minor`: the longer and shorter derivative lengths in texels;
//! - `count = clamp(ceil(major / minor), 1, max)`: enough probes that each covers about a
//!   `minor`-sized step, at most the anisotropy asked for;
//! - LOD footprint `max(major / count, minor)`: the long axis split among the probes, never finer
//!   than the short axis (so at most `max` times finer than isotropic);
//! - probe `i` at `uv + axis * ((i + 0.5) / count - 0.5)`, `axis` the longer derivative in UV.
//!
//! Each probe is addressed on its own (its own page-table lookup on the GPU), so probes that
//! cross a page edge read the neighbouring page: anisotropy needs no more border than the
//! filter each probe uses. The "longer of ddx and ddy" is an approximation of the footprint
//! ellipse's major axis (the one the GPU's own isotropic LOD uses too); it is exact when the
//! two derivatives are perpendicular, as on a plane seen straight toward the horizon.

/// The largest anisotropy a scene or the shader accepts (probes per sample).
pub const MAX_ANISOTROPY: u32 = 16;

/// One pixel's probes: `count` of them, spaced along `axis` (in UV), filtered at the LOD of
/// `footprint` LOD-0 texels.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Probes {
    /// How many probes: 1 for an isotropic footprint, up to the filter's maximum along its longer
    /// axis.
    pub count: u32,
    /// The longer derivative, in UV: probes span it, centred on the sample.
    pub axis: [f32; 2],
    /// LOD-0 texels per probe; `log2` of it is the LOD the probes sample (and feedback asks for).
    pub footprint: f32,
}

impl Probes {
    /// The plan for UV derivatives `ddx`, `ddy` on a texture of `texels` (width, height) at LOD 0,
    /// with at most `max_anisotropy` probes (1 is isotropic: one probe at the longer axis's LOD,
    /// what [`crate::feedback::lod_for`] assumes). Computed in f32 in the order the shader does.
    pub fn new(ddx: [f32; 2], ddy: [f32; 2], texels: [f32; 2], max_anisotropy: u32) -> Probes {
        let length = |d: [f32; 2]| {
            let (a, b) = (d[0] * texels[0], d[1] * texels[1]);
            (a * a + b * b).sqrt()
        };
        let (lx, ly) = (length(ddx), length(ddy));
        let (major, minor, axis) = if lx >= ly { (lx, ly, ddx) } else { (ly, lx, ddy) };
        let max = max_anisotropy.clamp(1, MAX_ANISOTROPY) as f32;
        // A zero minor axis (a line) gives infinity, clamped to `max`; 0 / 0 (no footprint) NaN,
        // which `clamp` would keep, so it is tested first.
        let ratio = (major / minor).ceil();
        let count = if ratio.is_nan() { 1.0 } else { ratio.clamp(1.0, max) };
        Probes { count: count as u32, axis, footprint: (major / count).max(minor) }
    }

    /// The UV of probe `i` (of `count`) around the sample at `uv`.
    pub fn at(&self, uv: [f32; 2], i: u32) -> [f32; 2] {
        let t = (i as f32 + 0.5) / self.count as f32 - 0.5;
        [uv[0] + self.axis[0] * t, uv[1] + self.axis[1] * t]
    }

    /// The LOD the probes sample (fractional; trilinear blends the two around it).
    pub fn lod(&self) -> f32 {
        self.footprint.log2()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const SQUARE: [f32; 2] = [256.0, 256.0];

    #[test]
    fn isotropic_footprints_take_one_probe() {
        let p = Probes::new([4.0 / 256.0, 0.0], [0.0, 4.0 / 256.0], SQUARE, 8);
        assert_eq!((p.count, p.footprint, p.lod()), (1, 4.0, 2.0));
        assert_eq!(p.at([0.5, 0.5], 0), [0.5, 0.5], "one probe sits on the sample");
    }

    #[test]
    fn the_count_follows_the_ratio_up_to_the_maximum() {
        // 16 texels along x per pixel, 2 along y: ratio 8.
        let (ddx, ddy) = ([16.0 / 256.0, 0.0], [0.0, 2.0 / 256.0]);
        for (max, count, footprint) in [(1, 1, 16.0), (2, 2, 8.0), (4, 4, 4.0), (8, 8, 2.0), (16, 8, 2.0)] {
            let p = Probes::new(ddx, ddy, SQUARE, max);
            assert_eq!((p.count, p.footprint), (count, footprint), "max {max}");
        }
        // The longer axis is whichever it is: here ddy.
        let p = Probes::new(ddy, ddx, SQUARE, 4);
        assert_eq!((p.count, p.axis), (4, ddx));
    }

    #[test]
    fn the_lod_is_never_finer_than_the_minor_axis() {
        // Ratio 2.5: 3 probes would each cover 10 / 3 < 4 texels; the minor axis (4) wins.
        let p = Probes::new([10.0 / 256.0, 0.0], [0.0, 4.0 / 256.0], SQUARE, 8);
        assert_eq!((p.count, p.footprint), (3, 4.0));
    }

    #[test]
    fn probes_span_the_major_axis_evenly() {
        let p = Probes::new([0.0, 8.0 / 256.0], [2.0 / 256.0, 0.0], SQUARE, 4);
        let v: Vec<f32> = (0..4).map(|i| p.at([0.5, 0.5], i)[1] * 256.0 - 128.0).collect();
        assert_eq!(v, [-3.0, -1.0, 1.0, 3.0], "in texels around the sample");
    }

    #[test]
    fn degenerate_footprints_are_finite() {
        let zero = Probes::new([0.0; 2], [0.0; 2], SQUARE, 8);
        assert_eq!((zero.count, zero.footprint), (1, 0.0));
        let line = Probes::new([1.0 / 256.0, 0.0], [0.0; 2], SQUARE, 8);
        assert_eq!((line.count, line.footprint), (8, 0.125));
        let over = Probes::new([1.0, 0.0], [0.0, 0.001], SQUARE, 99);
        assert_eq!(over.count, MAX_ANISOTROPY);
        let zero_max = Probes::new([1.0, 0.0], [0.0, 0.001], SQUARE, 0);
        assert_eq!(zero_max.count, 1, "0 means isotropic");
    }
}
