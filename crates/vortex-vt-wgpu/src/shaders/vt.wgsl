// Vortex virtual texturing, the module an application includes in its own shader
// (`vortex_vt_wgpu::shader`). Everything here is prefixed `vt_` / `Vt` so that it cannot clash
// with the application's names; its bindings sit in bind group VT_GROUP, chosen by the
// application when it asks for the source.
//
// The public functions:
//
//   vt_sample(id, uv, ddx, ddy) -> vec4<f32>       sample texture `id` at image UV `uv` (0..1
//                                                   over the real image), the LOD from the UV's
//                                                   screen derivatives dpdx(uv), dpdy(uv);
//                                                   anisotropic with VT_ANISO > 1
//   vt_sample_level(id, uv, lod) -> vec4<f32>      the same at an explicit LOD
//   vt_feedback(id, uv, ddx, ddy, frag_coord)      ask for the page this fragment wants
//   vt_residency(id, uv, ddx, ddy) -> vec2<u32>    the LOD wanted and the LOD drawn (debug views)
//   vt_sample_layer(id, layer, uv, ddx, ddy)       layer `layer` of a layer stack (`crate::layer`;
//   vt_sample_layer_level(id, layer, uv, lod)      `vt_sample` is layer 0): the same page, slot and
//                                                   address for every layer, so one feedback call
//                                                   serves them all
//
// and, for 2D views deep inside huge images where an f32 UV is not precise enough, the same
// three addressed by a LOD-0 texel position split into an integer and an f32 part
// (`VtTexel`), with the footprint in LOD-0 texels per pixel instead of derivatives:
//
//   vt_sample_texel(id, texel, footprint), vt_sample_texel_level(id, texel, lod),
//   vt_sample_texel_layer(id, layer, texel, footprint), vt_sample_texel_layer_level(id, layer, texel, lod),
//   vt_sample_texel_grad(id, texel, dx, dy), vt_sample_texel_layer_grad(id, layer, texel, dx, dy)
//   (anisotropic with VT_ANISO > 1; the scalar-footprint ones never are),
//   vt_footprint_texels(dx, dy) (the footprint feedback should ask with),
//   vt_feedback_texel(id, texel, footprint, frag_coord), vt_residency_texel(id, texel, footprint),
//   vt_texel_on_image(id, texel) (whether the position lies on the image: the samples clamp to
//   its edges, so a window that shows more than the image must draw its background there)
//
// Samples of colour layers are premultiplied-alpha colour in linear light (the cache is sampled through an sRGB
// view, so filtering happens in linear light on premultiplied texels: no fringes from the
// colour under transparent texels). Blend them with (One, OneMinusSrcAlpha), or divide by alpha.
//
// `vortex_vt::address` mirrors the address translation on the CPU; read its documentation for
// why a texel position is split into an integer and an f32 part.

struct VtTextureInfo {
    // The real image at LOD 0 in texels (UV 0..1 spans it), LODs, payload texels per page side.
    size: vec2<u32>,
    lod_count: u32,
    payload: u32,
    // Pages per row and per column at LOD 0 (`vortex_vt::page::TextureGrid`).
    pages: vec2<u32>,
    pad: vec2<u32>,
}

struct VtParams {
    // Stored tile side, border, payload, cache side: all in texels.
    tile: vec4<f32>,
    // Feedback: block side in pixels, blocks per row, blocks per column, words in the buffer.
    feedback: vec4<u32>,
    // The pixel of each block that writes its feedback this frame (changes every frame).
    elect: vec2<u32>,
    // Added to the LOD a feedback word asks for (the residency's bias when oversubscribed).
    feedback_bias: f32,
    // 0 nearest, 1 bilinear, 2 trilinear (`SampleFilter`).
    sample_filter: u32,
    // Bit k set when layer k's cache holds straight alpha (BC7 blocks as stored): premultiply
    // after filtering.
    straight_alpha: u32,
    // Layers of every texture (1..=4).
    layers: u32,
    pad1: u32,
    pad2: u32,
    textures: array<VtTextureInfo, 16>,
}

@group(VT_GROUP) @binding(0) var<uniform> vt_params: VtParams;
// `page_table::GpuPageTable`: a header of 16 x 16 words, the index of entry (0, 0) of texture
// t's LOD l at t * 16 + l, then every texture's entries, LOD by LOD, row by row.
@group(VT_GROUP) @binding(1) var<storage, read> vt_page_table: array<u32>;
@group(VT_GROUP) @binding(2) var vt_cache: texture_2d<f32>;
@group(VT_GROUP) @binding(3) var vt_cache_sampler: sampler;
// One word per feedback block (`vortex_vt::feedback::encode`), all ones where nothing asked.
@group(VT_GROUP) @binding(4) var<storage, read_write> vt_feedback_words: array<u32>;
// Layers 1-3's caches (layer 0's where the runtime has fewer layers): the same slots as vt_cache,
// each in its layer's format.
@group(VT_GROUP) @binding(5) var vt_cache_1: texture_2d<f32>;
@group(VT_GROUP) @binding(6) var vt_cache_2: texture_2d<f32>;
@group(VT_GROUP) @binding(7) var vt_cache_3: texture_2d<f32>;

// The filter: 3 (the default) takes it from the uniform block (`Runtime::set_filter`, no pipeline
// change); 0 nearest, 1 bilinear, 2 trilinear fix it when the pipeline is made
// (`shader::filter_constant`), so that the others' code is compiled out. CPU drivers such as
// lavapipe run both sides of a branch, so there a fixed filter makes nearest and bilinear cheaper.
override VT_FILTER: u32 = 3u;

// Anisotropic filtering: the most probes per sample of `vt_sample` (`shader::anisotropy_constant`,
// `vortex_vt::anisotropy`). 1, the default, is isotropic and compiles the probes' loop out; 2 to
// 16 spread up to that many probes along the longer UV derivative, at the LOD of the shorter one.
override VT_ANISO: u32 = 1u;

const VT_BELOW_ONE: f32 = 0.99999994;
const VT_UNMAPPED: u32 = 0xffffffffu;

// A LOD-0 texel position: `origin + offset`, the integer part exact at any size.
struct VtTexel {
    origin: vec2<u32>,
    offset: vec2<f32>,
}

// A sample's address at one LOD: its page and its position in the page's payload, in texels.
struct VtAt {
    page: vec2<u32>,
    within: vec2<f32>,
}

// Where a sample is: image UV (`is_uv`, in `texel.offset`), or a LOD-0 texel position.
struct VtCoord {
    is_uv: bool,
    texel: VtTexel,
}

// Pages per row of LOD `lod`: LOD 0's halved `lod` times, rounded up.
fn vt_pages_per_row(t: VtTextureInfo, lod: u32) -> u32 {
    return ((t.pages.x - 1u) >> lod) + 1u;
}

// `vortex_vt::address::split`: a texel position into page and position in the page, the
// rounded quotient's page corrected by the exact remainder.
fn vt_split(p: vec2<f32>, payload: f32) -> VtAt {
    var page = floor(p / payload);
    var within = p - page * payload;
    let under = within < vec2<f32>(0.0);
    page = select(page, page - 1.0, under);
    within = select(within, within + payload, under);
    let over = within >= vec2<f32>(payload);
    page = select(page, page + 1.0, over);
    within = select(within, within - payload, over);
    return VtAt(vec2<u32>(page), within);
}

// `vortex_vt::address::uv_at`.
fn vt_uv_at(uv: vec2<f32>, lod: u32, t: VtTextureInfo) -> VtAt {
    let scale = vec2<f32>(t.size) * (1.0 / f32(1u << lod));
    return vt_split(clamp(uv, vec2<f32>(0.0), vec2<f32>(VT_BELOW_ONE)) * scale, f32(t.payload));
}

// `vortex_vt::address::WindowOrigin::at`: the LOD-0 texel `origin + offset` at `lod`, clamped to
// the image.
fn vt_texel_at(texel: VtTexel, lod: u32, t: VtTextureInfo) -> VtAt {
    let mask = (1u << lod) - 1u;
    let scale = 1.0 / f32(1u << lod);
    let r = (vec2<f32>(texel.origin & vec2<u32>(mask)) + texel.offset) * scale;
    let fl = floor(r);
    var at = vec2<i32>(texel.origin >> vec2<u32>(lod)) + vec2<i32>(fl);
    var f = r - fl;
    // The texel holding the image's last LOD-0 texel, and how far into it the image goes.
    let size = max(t.size, vec2<u32>(1u));
    let last = vec2<i32>((size - 1u) >> vec2<u32>(lod));
    let end = vec2<f32>(((size - 1u) & vec2<u32>(mask)) + 1u) * scale * VT_BELOW_ONE;
    let beyond = (at > last) | ((at == last) & (f > end));
    f = select(f, vec2<f32>(0.0), at < vec2<i32>(0));
    f = select(f, end, beyond);
    let c = vec2<u32>(clamp(at, vec2<i32>(0), last));
    return VtAt(c / t.payload, vec2<f32>(c % t.payload) + f);
}

// The address of `c` at `lod`.
fn vt_address(c: VtCoord, lod: u32, t: VtTextureInfo) -> VtAt {
    if c.is_uv {
        return vt_uv_at(c.texel.offset, lod, t);
    }
    return vt_texel_at(c.texel, lod, t);
}

// `vortex_vt::address::At::ancestor`.
fn vt_ancestor(at: VtAt, levels: u32, payload: u32) -> VtAt {
    let mask = (1u << levels) - 1u;
    let within = (vec2<f32>(at.page & vec2<u32>(mask)) * f32(payload) + at.within) * (1.0 / f32(1u << levels));
    return VtAt(at.page >> vec2<u32>(levels), within);
}

// LOD-0 texels per pixel of UV derivatives, whose log2 is the LOD sampled (`vt_footprint_texels`).
fn vt_footprint(id: u32, ddx: vec2<f32>, ddy: vec2<f32>) -> f32 {
    let size = vec2<f32>(vt_params.textures[id].size);
    return vt_footprint_texels(ddx * size, ddy * size);
}

// The same for derivatives in LOD-0 texels: the longer derivative vector
// (`vortex_vt::feedback::lod_for`), or with anisotropy each probe's share of it
// (`vortex_vt::feedback::lod_for_anisotropic`), so that feedback asks for the LOD the probes read.
fn vt_footprint_texels(dx: vec2<f32>, dy: vec2<f32>) -> f32 {
    if VT_ANISO <= 1u {
        return max(length(dx), length(dy));
    }
    return vt_probes(dx, dy, dx, dy).footprint;
}

// `vortex_vt::anisotropy::Probes`: `count` probes spaced along `axis` (the longer derivative, in
// the coordinate's units: UV or texels), each filtered at the LOD of `footprint` LOD-0 texels.
struct VtProbes {
    count: u32,
    axis: vec2<f32>,
    footprint: f32,
}

// The probes of derivatives `dx`, `dy` in LOD-0 texels, which are `ax`, `ay` in the coordinate's
// units.
fn vt_probes(dx: vec2<f32>, dy: vec2<f32>, ax: vec2<f32>, ay: vec2<f32>) -> VtProbes {
    let lx = length(dx);
    let ly = length(dy);
    let major = max(lx, ly);
    let minor = min(lx, ly);
    // The smallest normal f32 keeps 0 / 0 out (one probe) and sends a line's ratio to the cap.
    let count = clamp(ceil(major / max(minor, 1.17549435e-38)), 1.0, f32(VT_ANISO));
    return VtProbes(u32(count), select(ay, ax, lx >= ly), max(major / count, minor));
}

// The mean of the probes `p` around `c`, each an ordinary filtered sample (`vt_shade`) with its
// own page-table lookup: a probe past a page edge reads the neighbouring page, so anisotropy
// needs no wider border than the filter of one probe.
fn vt_aniso(id: u32, layer: u32, c: VtCoord, p: VtProbes) -> vec4<f32> {
    let lod = log2(p.footprint);
    let n = f32(p.count);
    var sum = vec4<f32>(0.0);
    for (var i = 0u; i < p.count; i++) {
        var probe = c;
        probe.texel.offset += p.axis * ((f32(i) + 0.5) / n - 0.5);
        sum += vt_shade(id, layer, probe, lod);
    }
    return sum / n;
}

// The page-table word of address `at` of LOD `lod` of texture `id` (`vortex_vt::page_table`).
fn vt_entry(id: u32, lod: u32, at: VtAt) -> u32 {
    let t = vt_params.textures[id];
    return vt_page_table[vt_page_table[id * 16u + lod] + at.page.y * vt_pages_per_row(t, lod) + at.page.x];
}

// Layer `layer`'s cache at cache UV `uv`. A switch, since the caches' formats differ; a shader
// that passes a constant layer has the others compiled out.
fn vt_cache_sample(layer: u32, uv: vec2<f32>) -> vec4<f32> {
    switch layer {
        case 1u: { return textureSampleLevel(vt_cache_1, vt_cache_sampler, uv, 0.0); }
        case 2u: { return textureSampleLevel(vt_cache_2, vt_cache_sampler, uv, 0.0); }
        case 3u: { return textureSampleLevel(vt_cache_3, vt_cache_sampler, uv, 0.0); }
        default: { return textureSampleLevel(vt_cache, vt_cache_sampler, uv, 0.0); }
    }
}

// The sample at address `at` of LOD `lod` of layer `layer` of texture `id`, from whatever the
// page table maps there.
fn vt_fetch(id: u32, layer: u32, lod: u32, at: VtAt) -> vec4<f32> {
    let t = vt_params.textures[id];
    let word = vt_entry(id, lod, at);
    if word == VT_UNMAPPED {
        // Only before the first update pinned the root: magenta, never a real texel.
        return vec4<f32>(1.0, 0.0, 1.0, 1.0);
    }
    let slot = vec2<f32>(f32(word & 0xffu), f32((word >> 8u) & 0xffu));
    let page_lod = (word >> 16u) & 0xffu;
    let a = vt_ancestor(at, page_lod - lod, t.payload);
    // Past the border into the slot; clamped half a texel inside the slot so that a tile
    // without a border never filters in its neighbour's texels.
    let tile = vt_params.tile;
    let origin = slot * tile.x;
    let texel = clamp(origin + tile.y + a.within, origin + 0.5, origin + tile.x - 0.5);
    let s = vt_cache_sample(layer, texel / tile.w);
    // Without a branch: a straight-alpha cache (BC7) is premultiplied here.
    let straight = (vt_params.straight_alpha & (1u << layer)) != 0u;
    return vec4<f32>(s.rgb * select(1.0, s.a, straight), s.a);
}

// The filtered sample of layer `layer` of `c` at the (fractional) LOD `wanted`.
fn vt_shade(id: u32, layer: u32, c: VtCoord, wanted: f32) -> vec4<f32> {
    let t = vt_params.textures[id];
    let top = f32(t.lod_count - 1u);
    let level = clamp(floor(wanted), 0.0, top);
    let lod = u32(level);
    let at = vt_address(c, lod, t);
    let fine = vt_fetch(id, layer, lod, at);
    let blend = clamp(wanted - level, 0.0, 1.0);
    // Magnified (or at the coarsest LOD) trilinear is bilinear: no second sample.
    let mode = select(VT_FILTER, vt_params.sample_filter, VT_FILTER > 2u);
    if mode != 2u || level >= top || blend == 0.0 {
        return fine;
    }
    let coarse = vt_fetch(id, layer, lod + 1u, vt_ancestor(at, 1u, t.payload));
    return mix(fine, coarse, blend);
}

// The LOD `vt_shade` samples first at `c` for the LOD `wanted`, and the LOD of the page the page
// table maps there (greater when the page has not landed and a coarser one stands in; 255 when
// nothing is mapped).
fn vt_lods(id: u32, c: VtCoord, wanted: f32) -> vec2<u32> {
    let t = vt_params.textures[id];
    let lod = u32(clamp(floor(wanted), 0.0, f32(t.lod_count - 1u)));
    let word = vt_entry(id, lod, vt_address(c, lod, t));
    return vec2<u32>(lod, select((word >> 16u) & 0xffu, 255u, word == VT_UNMAPPED));
}

// The feedback word of `c` with a footprint of `footprint` LOD-0 texels per pixel, written if
// `frag_coord` is its block's elected pixel this frame.
fn vt_write_feedback(id: u32, c: VtCoord, footprint: f32, frag_coord: vec2<f32>) {
    let fb = vt_params.feedback;
    let pixel = vec2<u32>(max(frag_coord, vec2<f32>(0.0)));
    let block = pixel / fb.x;
    if any(pixel - block * fb.x != vt_params.elect) || block.x >= fb.y || block.y >= fb.z {
        return;
    }
    let t = vt_params.textures[id];
    let lod = u32(clamp(floor(log2(footprint) + vt_params.feedback_bias), 0.0, f32(t.lod_count - 1u)));
    let page = vt_address(c, lod, t).page;
    let index = page.y * vt_pages_per_row(t, lod) + page.x;
    let i = block.y * fb.y + block.x;
    if i < fb.w {
        vt_feedback_words[i] = (index & 0xffffffu) | (lod << 24u) | (id << 28u);
    }
}

fn vt_uv(uv: vec2<f32>) -> VtCoord {
    return VtCoord(true, VtTexel(vec2<u32>(0u), uv));
}

fn vt_texel(texel: VtTexel) -> VtCoord {
    return VtCoord(false, texel);
}

// Texture `id` at image UV `uv`, filtered at the LOD of the UV's screen derivatives
// (`dpdx(uv)`, `dpdy(uv)`, taken by the caller in uniform control flow). Premultiplied linear RGBA.
fn vt_sample(id: u32, uv: vec2<f32>, ddx: vec2<f32>, ddy: vec2<f32>) -> vec4<f32> {
    return vt_sample_layer(id, 0u, uv, ddx, ddy);
}

// Layer `layer` (clamped to the layers there are) of texture `id`, as `vt_sample` samples layer 0.
// Colour layers give premultiplied linear RGBA; data layers their values as stored.
fn vt_sample_layer(id: u32, layer: u32, uv: vec2<f32>, ddx: vec2<f32>, ddy: vec2<f32>) -> vec4<f32> {
    let l = min(layer, vt_params.layers - 1u);
    if VT_ANISO > 1u {
        let size = vec2<f32>(vt_params.textures[id].size);
        return vt_aniso(id, l, vt_uv(uv), vt_probes(ddx * size, ddy * size, ddx, ddy));
    }
    return vt_shade(id, l, vt_uv(uv), log2(vt_footprint(id, ddx, ddy)));
}

fn vt_sample_layer_level(id: u32, layer: u32, uv: vec2<f32>, lod: f32) -> vec4<f32> {
    return vt_shade(id, min(layer, vt_params.layers - 1u), vt_uv(uv), lod);
}

// Texture `id` at image UV `uv` at LOD `lod` (0 is the full resolution; fractions blend two
// LODs under trilinear filtering).
fn vt_sample_level(id: u32, uv: vec2<f32>, lod: f32) -> vec4<f32> {
    return vt_shade(id, 0u, vt_uv(uv), lod);
}

// Asks for the page that `vt_sample` with the same arguments reads, from pixel `frag_coord`
// (`@builtin(position).xy`). Call it once per fragment of the surfaces that show the texture;
// only one pixel per feedback block writes each frame, a different one every frame.
fn vt_feedback(id: u32, uv: vec2<f32>, ddx: vec2<f32>, ddy: vec2<f32>, frag_coord: vec2<f32>) {
    vt_write_feedback(id, vt_uv(uv), vt_footprint(id, ddx, ddy), frag_coord);
}

// Texture `id` at LOD-0 texel position `texel`, at the LOD of `footprint` LOD-0 texels per pixel.
fn vt_sample_texel(id: u32, texel: VtTexel, footprint: f32) -> vec4<f32> {
    return vt_shade(id, 0u, vt_texel(texel), log2(footprint));
}

// Texture `id` at LOD-0 texel position `texel`, a pixel stepping `dx` texels across and `dy`
// down: anisotropic with VT_ANISO > 1 (a window stretched more one way than the other), else
// `vt_sample_texel` with their footprint.
fn vt_sample_texel_grad(id: u32, texel: VtTexel, dx: vec2<f32>, dy: vec2<f32>) -> vec4<f32> {
    return vt_sample_texel_layer_grad(id, 0u, texel, dx, dy);
}

fn vt_sample_texel_layer_grad(id: u32, layer: u32, texel: VtTexel, dx: vec2<f32>, dy: vec2<f32>) -> vec4<f32> {
    let l = min(layer, vt_params.layers - 1u);
    if VT_ANISO > 1u {
        return vt_aniso(id, l, vt_texel(texel), vt_probes(dx, dy, dx, dy));
    }
    return vt_shade(id, l, vt_texel(texel), log2(vt_footprint_texels(dx, dy)));
}

fn vt_sample_texel_level(id: u32, texel: VtTexel, lod: f32) -> vec4<f32> {
    return vt_shade(id, 0u, vt_texel(texel), lod);
}

fn vt_sample_texel_layer(id: u32, layer: u32, texel: VtTexel, footprint: f32) -> vec4<f32> {
    return vt_shade(id, min(layer, vt_params.layers - 1u), vt_texel(texel), log2(footprint));
}

fn vt_sample_texel_layer_level(id: u32, layer: u32, texel: VtTexel, lod: f32) -> vec4<f32> {
    return vt_shade(id, min(layer, vt_params.layers - 1u), vt_texel(texel), lod);
}

fn vt_feedback_texel(id: u32, texel: VtTexel, footprint: f32, frag_coord: vec2<f32>) {
    vt_write_feedback(id, vt_texel(texel), footprint, frag_coord);
}

// Whether LOD-0 texel position `texel` lies on texture `id`'s image, `[0, size)` on each axis
// (`vortex_vt::address::WindowOrigin::on_image`). Sampling clamps to the image's edges, which
// beyond them repeats the edge texels: a window larger than the image tests this first.
fn vt_texel_on_image(id: u32, texel: VtTexel) -> bool {
    let at = vec2<i32>(texel.origin) + vec2<i32>(floor(texel.offset));
    return all(at >= vec2<i32>(0)) && all(at < vec2<i32>(vt_params.textures[id].size));
}

// For residency views: the LOD `vt_sample` wants at `uv` and the LOD of the page it draws from
// (greater while it falls back to a coarser page).
fn vt_residency(id: u32, uv: vec2<f32>, ddx: vec2<f32>, ddy: vec2<f32>) -> vec2<u32> {
    return vt_lods(id, vt_uv(uv), log2(vt_footprint(id, ddx, ddy)));
}

fn vt_residency_texel(id: u32, texel: VtTexel, footprint: f32) -> vec2<u32> {
    return vt_lods(id, vt_texel(texel), log2(footprint));
}
