//! How samples are filtered: [`SampleFilter`], and which filter a texture's border allows. The
//! sampling itself is `vt_sample` in `shaders/vt.wgsl`: each fragment finds its LOD (from its
//! footprint, or given), its address at that LOD, the page-table entry there (the finest mapped
//! ancestor-or-self of the wanted page), and samples that page's slot of the physical cache
//! through its sRGB view, in linear light.
//!
//! The filter is a `SampleFilter`, not a `Filter`, so that it is never mistaken for the tiler's
//! LOD filter (how a pyramid level is reduced from the one above), which is another thing.

/// How the cache is filtered. Only trilinear reads two LODs per sample.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum SampleFilter {
    /// The nearest texel of the footprint's LOD.
    Nearest,
    /// The four nearest texels of the footprint's LOD, blended.
    #[default]
    Bilinear,
    /// Bilinear in the LOD below and above the footprint, blended.
    Trilinear,
}

impl SampleFilter {
    /// Every filter, cheapest first.
    pub const ALL: [SampleFilter; 3] = [SampleFilter::Nearest, SampleFilter::Bilinear, SampleFilter::Trilinear];

    /// The name scenes and reports use.
    pub fn name(self) -> &'static str {
        match self {
            SampleFilter::Nearest => "nearest",
            SampleFilter::Bilinear => "bilinear",
            SampleFilter::Trilinear => "trilinear",
        }
    }

    /// The filter `name` names.
    pub fn from_name(name: &str) -> Option<SampleFilter> {
        SampleFilter::ALL.into_iter().find(|f| f.name() == name)
    }

    /// The best filter tiles with `border` texels of border allow without seams. Bilinear and
    /// trilinear read a texel beyond the page at its edges, which only a border of at least one
    /// texel holds: without one they are clamped inside the page, and every page edge shows as a
    /// seam (docs/gpu-sampling.md: up to 44 code values off at page edges with border 0, none
    /// with border 1). So: trilinear (docs/gpu-sampling.md: 18 dB closer to the ideal between
    /// LODs than bilinear, for 1.3x the frame) with a border, nearest without.
    pub fn best_for(border: u32) -> SampleFilter {
        if border == 0 { SampleFilter::Nearest } else { SampleFilter::Trilinear }
    }

    /// Whether this filter shows seams at page edges of tiles with `border` texels of border.
    pub fn seams_with(self, border: u32) -> bool {
        border == 0 && self != SampleFilter::Nearest
    }
}
