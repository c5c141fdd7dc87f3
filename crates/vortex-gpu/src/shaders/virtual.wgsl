// What the sampling and the feedback pass share: the frame's parameters (`params::Frame` on the
// CPU), the two vertex stages (a 2D window onto one texture, or meshes carrying UVs), the LOD a
// fragment wants, and address translation. `vortex_vt::address` mirrors the translation on the
// CPU; read its documentation for why the window's origin is split into an integer and an f32
// part.

struct Texture {
    // Pages per side at LOD 0, LODs, payload texels per page side, padding.
    pages: u32,
    lod_count: u32,
    payload: u32,
    pad0: u32,
    // Image UV (0..1 over the real image) to virtual UV (0..1 over the page grid).
    uv_scale: vec2<f32>,
    // pages * payload: texels per side at LOD 0.
    side_texels: f32,
    pad1: f32,
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

// `vortex_vt::address::uv_at`.
fn uv_at(uv: vec2<f32>, lod: u32, t: Texture) -> At {
    let p = clamp(uv * t.uv_scale, vec2<f32>(0.0), vec2<f32>(BELOW_ONE)) * f32(max(t.pages >> lod, 1u));
    let page = floor(p);
    return At(vec2<u32>(page), (p - page) * f32(t.payload));
}

// `vortex_vt::address::WindowOrigin::at`.
fn window_at(position: vec2<f32>, lod: u32, t: Texture) -> At {
    let side = i32(max(t.pages >> lod, 1u) * t.payload);
    let mask = (1u << lod) - 1u;
    let rel = frame.origin_frac + (position + frame.jitter) * frame.step;
    let r = (vec2<f32>(frame.origin_int & vec2<u32>(mask)) + rel) * (1.0 / f32(1u << lod));
    let fl = floor(r);
    var texel = vec2<i32>(frame.origin_int >> vec2<u32>(lod)) + vec2<i32>(fl);
    var f = r - fl;
    f = select(f, vec2<f32>(0.0), texel < vec2<i32>(0));
    f = select(f, vec2<f32>(BELOW_ONE), texel >= vec2<i32>(side));
    let c = vec2<u32>(clamp(texel, vec2<i32>(0), vec2<i32>(side - 1)));
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
    let s = uv * t.uv_scale * t.side_texels;
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
