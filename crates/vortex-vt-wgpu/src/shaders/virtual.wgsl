// What the sampling and the feedback pass share: the frame's parameters (`params::Frame` on the
// CPU), the two vertex stages (a 2D window onto one texture, or meshes carrying UVs), the LOD a
// fragment wants, and address translation. `vortex_vt::address` mirrors the translation on the
// CPU; read its documentation for why the window's origin is split into an integer and an f32
// part.

struct Texture {
    // The real image at LOD 0 in texels (UV 0..1 spans it), LODs, payload texels per page side.
    size: vec2<u32>,
    lod_count: u32,
    payload: u32,
    // Pages per row and per column at LOD 0 (`vortex_vt::page::TextureGrid`).
    pages: vec2<u32>,
    pad: vec2<u32>,
}

struct Frame {
    view_proj: mat4x4<f32>,
    // Window: the frame's top-left corner is LOD-0 texel origin_int + origin_frac; step is
    // LOD-0 texels per frame pixel.
    origin_int: vec2<u32>,
    origin_frac: vec2<f32>,
    step: vec2<f32>,
    window_texture: u32,
    // At least 0: sample that LOD everywhere; negative: the LOD from derivatives.
    lod_override: f32,
    // Stored tile side, border, payload, cache side: all in texels.
    tile: vec4<f32>,
    // Added to every LOD (feedback: the residency's bias plus the reduced size's compensation).
    bias: f32,
    pad0: f32,
    // Where in its pixel a fragment samples, relative to the centre (feedback: a different
    // point each frame, so that over a few frames every frame pixel's page is asked for): in
    // pixels for windows, and as the clip-space shift that moves meshes by as much.
    jitter: vec2<f32>,
    jitter_ndc: vec2<f32>,
    pad1: vec2<f32>,
    textures: array<Texture, 16>,
}

@group(0) @binding(0) var<uniform> frame: Frame;

const BELOW_ONE: f32 = 0.99999994;

struct Varyings {
    @builtin(position) position: vec4<f32>,
    // Image UV (meshes only).
    @location(0) uv: vec2<f32>,
    @location(1) @interpolate(flat) texture: u32,
}

// One triangle covering the target: (-1, -1), (3, -1), (-1, 3), at the far plane so meshes are
// never hidden by it.
@vertex
fn vs_window(@builtin(vertex_index) i: u32) -> Varyings {
    let xy = vec2<f32>(f32((i << 1u) & 2u), f32(i & 2u)) * 2.0 - 1.0;
    return Varyings(vec4<f32>(xy, 1.0, 1.0), vec2<f32>(0.0), frame.window_texture);
}

@vertex
fn vs_mesh(@location(0) position: vec3<f32>, @location(1) uv: vec2<f32>, @location(2) texture: u32) -> Varyings {
    let clip = frame.view_proj * vec4<f32>(position, 1.0);
    return Varyings(vec4<f32>(clip.xy + frame.jitter_ndc * clip.w, clip.zw), uv, texture);
}

// A sample's address at one LOD: its page and its position in the page's payload, in texels.
struct At {
    page: vec2<u32>,
    within: vec2<f32>,
}

// Pages per row of LOD `lod`: LOD 0's halved `lod` times, rounded up.
fn pages_per_row(t: Texture, lod: u32) -> u32 {
    return ((t.pages.x - 1u) >> lod) + 1u;
}

// `vortex_vt::address::split`: a texel position into page and position in the page, the
// rounded quotient's page corrected by the exact remainder.
fn split(p: vec2<f32>, payload: f32) -> At {
    var page = floor(p / payload);
    var within = p - page * payload;
    let under = within < vec2<f32>(0.0);
    page = select(page, page - 1.0, under);
    within = select(within, within + payload, under);
    let over = within >= vec2<f32>(payload);
    page = select(page, page + 1.0, over);
    within = select(within, within - payload, over);
    return At(vec2<u32>(page), within);
}

// `vortex_vt::address::uv_at`.
fn uv_at(uv: vec2<f32>, lod: u32, t: Texture) -> At {
    let scale = vec2<f32>(t.size) * (1.0 / f32(1u << lod));
    return split(clamp(uv, vec2<f32>(0.0), vec2<f32>(BELOW_ONE)) * scale, f32(t.payload));
}

// `vortex_vt::address::WindowOrigin::at`.
fn window_at(position: vec2<f32>, lod: u32, t: Texture) -> At {
    let mask = (1u << lod) - 1u;
    let scale = 1.0 / f32(1u << lod);
    let rel = frame.origin_frac + (position + frame.jitter) * frame.step;
    let r = (vec2<f32>(frame.origin_int & vec2<u32>(mask)) + rel) * scale;
    let fl = floor(r);
    var texel = vec2<i32>(frame.origin_int >> vec2<u32>(lod)) + vec2<i32>(fl);
    var f = r - fl;
    // The texel holding the image's last LOD-0 texel, and how far into it the image goes.
    let size = max(t.size, vec2<u32>(1u));
    let last = vec2<i32>((size - 1u) >> vec2<u32>(lod));
    let end = vec2<f32>(((size - 1u) & vec2<u32>(mask)) + 1u) * scale * BELOW_ONE;
    let beyond = texel > last | (texel == last & f > end);
    f = select(f, vec2<f32>(0.0), texel < vec2<i32>(0));
    f = select(f, end, beyond);
    let c = vec2<u32>(clamp(texel, vec2<i32>(0), last));
    return At(c / t.payload, vec2<f32>(c % t.payload) + f);
}

// `vortex_vt::address::At::ancestor`.
fn ancestor(at: At, levels: u32, payload: u32) -> At {
    let mask = (1u << levels) - 1u;
    let within = (vec2<f32>(at.page & vec2<u32>(mask)) * f32(payload) + at.within) * (1.0 / f32(1u << levels));
    return At(at.page >> vec2<u32>(levels), within);
}

// LOD-0 texels per pixel: the longer derivative vector (`vortex_vt::feedback::lod_for`), or a
// window's step. Must be called in uniform control flow.
fn footprint(is_window: bool, uv: vec2<f32>, t: Texture) -> f32 {
    let s = uv * vec2<f32>(t.size);
    let derivatives = max(length(dpdx(s)), length(dpdy(s)));
    return select(derivatives, max(abs(frame.step.x), abs(frame.step.y)), is_window);
}

// The address at `lod`, by whichever path the fragment came.
fn address(is_window: bool, position: vec2<f32>, uv: vec2<f32>, lod: u32, t: Texture) -> At {
    if is_window {
        return window_at(position, lod, t);
    }
    return uv_at(uv, lod, t);
}
