// The sampling pass: each fragment finds its LOD (from its footprint, or `frame.lod_override`),
// its address at that LOD, the page-table entry there (the finest resident ancestor-or-self of
// the wanted page), and samples that page's slot of the physical cache through its sRGB view:
// nearest, bilinear, or trilinear (two LODs blended), as the pipeline's `FILTER` constant says.
// Appended to `virtual.wgsl`.

// `page_table::GpuPageTable`: a header of 16 x 16 words, the index of entry (0, 0) of texture t's
// LOD l at t * 16 + l, then every texture's entries, LOD by LOD, row by row.
@group(0) @binding(1) var<storage, read> page_table: array<u32>;
@group(0) @binding(2) var cache: texture_2d<f32>;
@group(0) @binding(3) var cache_sampler: sampler;

// 0 nearest, 1 bilinear, 2 trilinear (`render::Filter`).
override FILTER: u32 = 1u;

const UNMAPPED: u32 = 0xffffffffu;

// The sample at address `at` of LOD `lod` of texture `texture`, from whatever the page table
// maps there.
fn sample_at(texture: u32, lod: u32, at: At) -> vec4<f32> {
    let t = frame.textures[texture];
    let word = page_table[page_table[texture * 16u + lod] + at.page.y * pages_per_row(t, lod) + at.page.x];
    if word == UNMAPPED {
        // Only before the first update pinned the root: magenta, never a real texel.
        return vec4<f32>(1.0, 0.0, 1.0, 1.0);
    }
    let slot = vec2<f32>(f32(word & 0xffu), f32((word >> 8u) & 0xffu));
    let page_lod = (word >> 16u) & 0xffu;
    let a = ancestor(at, page_lod - lod, t.payload);
    // Past the border into the slot; clamped half a texel inside the slot so that a tile
    // without a border never filters in its neighbour's texels.
    let origin = slot * frame.tile.x;
    let texel = clamp(origin + frame.tile.y + a.within, origin + 0.5, origin + frame.tile.x - 0.5);
    return textureSampleLevel(cache, cache_sampler, texel / frame.tile.w, 0.0);
}

fn shade(is_window: bool, position: vec2<f32>, uv: vec2<f32>, texture: u32) -> vec4<f32> {
    let t = frame.textures[texture];
    let wanted = select(log2(footprint(is_window, uv, t)) + frame.bias, frame.lod_override, frame.lod_override >= 0.0);
    let top = f32(t.lod_count - 1u);
    let level = clamp(floor(wanted), 0.0, top);
    let lod = u32(level);
    let at = address(is_window, position, uv, lod, t);
    let fine = sample_at(texture, lod, at);
    let blend = clamp(wanted - level, 0.0, 1.0);
    // Magnified (or at the coarsest LOD) trilinear is bilinear: no second sample.
    if FILTER != 2u || level >= top || blend == 0.0 {
        return fine;
    }
    let coarse = sample_at(texture, lod + 1u, ancestor(at, 1u, t.payload));
    return mix(fine, coarse, blend);
}

@fragment
fn fs_window(v: Varyings) -> @location(0) vec4<f32> {
    return shade(true, v.position.xy, v.uv, v.texture);
}

@fragment
fn fs_mesh(v: Varyings) -> @location(0) vec4<f32> {
    return shade(false, v.position.xy, v.uv, v.texture);
}
