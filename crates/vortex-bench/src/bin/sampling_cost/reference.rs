//! What a picture should be, computed on the CPU with the reference sampler
//! (`vortex_vt::sampler`): the runtime's own model (each pixel at its page-table entry's LOD)
//! and the ideal (trilinear at the exact footprint LOD, no pages in between).

use crate::SIZE;
use crate::api::{
    LodChain, PageId, Rgba8Image, Runtime, SampleFilter as Filter, VirtualTexture, Window, bilinear, nearest, trilinear,
};
use crate::compare::Fallback;

/// What the runtime's picture of `window` must be, as `tests/runtime.rs` computes it: at each
/// pixel the reference sample at the LOD of the page-table entry of the pixel's wanted page
/// (trilinear at the footprint LOD when that entry is the wanted page itself). Also returns the
/// pixels drawn from a coarser fallback page.
pub fn model(
    rt: &Runtime,
    chain: &LodChain,
    tex: &VirtualTexture,
    window: &Window,
    filter: Filter,
) -> (Rgba8Image, Fallback) {
    let size = (SIZE[0], SIZE[1]);
    let origin = window.origin_texels(tex, size);
    let lod = origin.lod(0.0, tex.grid.lod_count());
    let footprint = origin.step[0].max(origin.step[1]).log2().max(0.0);
    let table = rt.page_table();
    let mut fallback = Fallback::default();
    let image = Rgba8Image::from_fn(size.0, size.1, |x, y| {
        let [u, v] = window.uv(x, y, size).map(|t| t as f32);
        let at = origin.at(x as f32 + 0.5, y as f32 + 0.5, lod, tex.size(), tex.payload());
        let entry = table.entry(0, lod, at.page[0] as u16, at.page[1] as u16);
        if entry.lod != lod {
            fallback.add(x, y, PageId::new(0, lod, at.page[0] as u16, at.page[1] as u16), entry.lod);
        }
        match filter {
            Filter::Nearest => nearest(chain, entry.lod, u, v),
            Filter::Trilinear if entry.lod == lod => trilinear(chain, footprint, u, v),
            _ => bilinear(chain, entry.lod, u, v),
        }
    });
    (image, fallback)
}

/// The ideal picture of `window`: trilinear at the exact footprint LOD from the whole LOD chain.
pub fn ideal(chain: &LodChain, window: &Window, side: u32) -> Rgba8Image {
    let size = (SIZE[0], SIZE[1]);
    let step = (window.extent[0] * side as f64 / size.0 as f64).max(window.extent[1] * side as f64 / size.1 as f64);
    let footprint = (step as f32).log2().max(0.0);
    Rgba8Image::from_fn(size.0, size.1, |x, y| {
        let [u, v] = window.uv(x, y, size).map(|t| t as f32);
        trilinear(chain, footprint, u, v)
    })
}
