// Samples a virtual texture through the page table and the physical page cache: one full-screen
// triangle, each fragment maps its virtual UV to the page table at the wanted LOD, follows the
// entry to a slot of the cache (the finest resident ancestor of the wanted page) and samples it
// bilinearly through the cache's sRGB view. The layout of `Params` is `render::Params`.

struct Params {
    // Virtual UV of the target's pixel (0, 0) corner (xy) and UV per pixel (zw): a fragment at
    // framebuffer position p (pixel centres at .5) samples window.xy + p * window.zw.
    window: vec4<f32>,
    // Pages per side at LOD 0, the LOD to sample, padding.
    pages: u32,
    lod: u32,
    pad0: u32,
    pad1: u32,
    // Tile side with border, border, payload side, cache side: all in texels.
    tile: vec4<f32>,
}

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var page_table: texture_2d<u32>;
@group(0) @binding(2) var cache: texture_2d<f32>;
@group(0) @binding(3) var cache_sampler: sampler;

const UNMAPPED: u32 = 0xffffffffu;
// The largest f32 below 1: keeps v = 1 inside the last page.
const BELOW_ONE: f32 = 0.99999994;

@fragment
fn fs_main(@builtin(position) frag: vec4<f32>) -> @location(0) vec4<f32> {
    let v = clamp(params.window.xy + frag.xy * params.window.zw, vec2<f32>(0.0), vec2<f32>(BELOW_ONE));
    let lod = params.lod;
    let page = vec2<u32>(v * f32(params.pages)) >> vec2<u32>(lod);
    let word = textureLoad(page_table, page, lod).r;
    if word == UNMAPPED {
        // Only before the first update pinned the root: magenta, never a real texel.
        return vec4<f32>(1.0, 0.0, 1.0, 1.0);
    }
    let slot = vec2<f32>(f32(word & 0xffu), f32((word >> 8u) & 0xffu));
    let page_lod = (word >> 16u) & 0xffu;
    // Position inside the page the entry points at (the wanted page or a coarser ancestor), then
    // inside its payload, past the border, in the slot, in the cache.
    let within = fract(v * f32(params.pages >> page_lod));
    let texel = slot * params.tile.x + within * params.tile.z + params.tile.y;
    // Explicit level: the cache has one mip, and the UV jumps between slots at page edges, so
    // derivatives would be meaningless.
    return textureSampleLevel(cache, cache_sampler, texel / params.tile.w, 0.0);
}
