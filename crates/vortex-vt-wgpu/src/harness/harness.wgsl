// The harness's own shader, an application shader like any other: it includes the module
// (`vt.wgsl`, bindings in group 1) and draws a 2D window onto one texture, or meshes whose
// vertices carry an image UV and a texture id, asking for feedback from every fragment and
// writing straight alpha (the PNG frames `render` writes).

struct Frame {
    view_proj: mat4x4<f32>,
    // Window: the frame's top-left corner is LOD-0 texel origin_int + origin_frac; step is
    // LOD-0 texels per frame pixel.
    origin_int: vec2<u32>,
    origin_frac: vec2<f32>,
    step: vec2<f32>,
    window_texture: u32,
    // At least 0: sample that LOD everywhere; negative: the LOD from the footprint.
    lod_override: f32,
}

// The residency view (tinted by the LOD drawn, red where it falls back) instead of the picture:
// a pipeline constant, so that the picture's pipelines never compute it.
override RESIDENCY_VIEW: bool = false;
// The layer of the textures' stacks drawn (the scene effect `layer`).
override LAYER: u32 = 0u;

@group(0) @binding(0) var<uniform> frame: Frame;

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
    return Varyings(frame.view_proj * vec4<f32>(position, 1.0), uv, texture);
}

// The window's LOD-0 texel at pixel position `position`.
fn window_texel(position: vec2<f32>) -> VtTexel {
    return VtTexel(frame.origin_int, frame.origin_frac + position * frame.step);
}

fn straight(c: vec4<f32>) -> vec4<f32> {
    if c.a <= 0.0 {
        return vec4<f32>(0.0);
    }
    return vec4<f32>(c.rgb / c.a, c.a);
}

// The residency view of sample `c` whose LODs (wanted, drawn) are `lods`: a hue per LOD drawn,
// over the picture's brightness, turning red by a quarter per LOD it falls back.
fn residency(c: vec4<f32>, lods: vec2<u32>) -> vec4<f32> {
    let hues = array<vec3<f32>, 6>(
        vec3<f32>(0.2, 0.4, 1.0), vec3<f32>(0.1, 0.8, 0.9), vec3<f32>(0.2, 0.9, 0.3),
        vec3<f32>(0.9, 0.9, 0.2), vec3<f32>(0.9, 0.5, 0.1), vec3<f32>(0.8, 0.3, 0.9));
    let grey = dot(straight(c).rgb, vec3<f32>(0.2126, 0.7152, 0.0722));
    var rgb = hues[min(lods.y, 255u) % 6u] * (0.35 + 0.65 * grey);
    if lods.y > lods.x {
        rgb = mix(rgb, vec3<f32>(1.0, 0.0, 0.0), min(0.25 * f32(lods.y - lods.x), 0.75));
    }
    return vec4<f32>(rgb, 1.0);
}

// The LOD to sample: the fixed one if given, else the footprint's. One sample call per fragment
// (lavapipe runs both sides of a branch, even on a uniform, so a branch between two sample calls
// would cost both).
fn lod_for(footprint: f32) -> f32 {
    return select(log2(footprint), frame.lod_override, frame.lod_override >= 0.0);
}

@fragment
fn fs_window(v: Varyings) -> @location(0) vec4<f32> {
    let texel = window_texel(v.position.xy);
    let dx = vec2<f32>(frame.step.x, 0.0);
    let dy = vec2<f32>(0.0, frame.step.y);
    let footprint = vt_footprint_texels(dx, dy);
    vt_feedback_texel(v.texture, texel, footprint, v.position.xy);
    // Anisotropy (a pipeline constant: one side is compiled out) ignores `lod_override`.
    var c: vec4<f32>;
    if VT_ANISO > 1u {
        c = vt_sample_texel_layer_grad(v.texture, LAYER, texel, dx, dy);
    } else {
        c = vt_sample_texel_layer_level(v.texture, LAYER, texel, lod_for(footprint));
    }
    // Beyond the image the samples repeat its edge texels: the background (the target's clear
    // colour) there instead. The feedback above stays: it asks for the edge's pages, which the
    // image's own pixels beside them want anyway.
    if !vt_texel_on_image(v.texture, texel) {
        return vec4<f32>(0.0);
    }
    if RESIDENCY_VIEW {
        return residency(c, vt_residency_texel(v.texture, texel, footprint));
    }
    return straight(c);
}

@fragment
fn fs_mesh(v: Varyings) -> @location(0) vec4<f32> {
    let ddx = dpdx(v.uv);
    let ddy = dpdy(v.uv);
    vt_feedback(v.texture, v.uv, ddx, ddy, v.position.xy);
    var c: vec4<f32>;
    if VT_ANISO > 1u {
        c = vt_sample_layer(v.texture, LAYER, v.uv, ddx, ddy);
    } else {
        c = vt_sample_layer_level(v.texture, LAYER, v.uv, lod_for(vt_footprint(v.texture, ddx, ddy)));
    }
    if RESIDENCY_VIEW {
        return residency(c, vt_residency(v.texture, v.uv, ddx, ddy));
    }
    return straight(c);
}
