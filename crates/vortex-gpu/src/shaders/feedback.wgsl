// The feedback pass: one full-screen triangle into a small R32Uint target; each fragment writes
// the feedback word (`vortex_vt::feedback::encode`) of the page its virtual UV wants. The LOD
// comes from the UV's screen-space derivatives exactly as `vortex_vt::feedback::lod_for` computes
// it, with `bias` already holding `feedback_bias` for the target's reduced size. The layout of
// `Params` is `feedback::Params`.

struct Params {
    // Virtual UV of the target's pixel (0, 0) corner (xy) and UV per pixel (zw): a fragment at
    // framebuffer position p (pixel centres at .5) wants window.xy + p * window.zw.
    window: vec4<f32>,
    // Pages per side at LOD 0, LODs of the texture, texture id, padding.
    pages: u32,
    lod_count: u32,
    texture: u32,
    pad0: u32,
    // Texels per side of the texture at LOD 0, LOD bias, padding.
    side_texels: f32,
    bias: f32,
    pad1: f32,
    pad2: f32,
}

@group(0) @binding(0) var<uniform> params: Params;

@fragment
fn fs_main(@builtin(position) frag: vec4<f32>) -> @location(0) u32 {
    // Unclamped, so that the derivatives stay those of the view beyond the texture's edges.
    let uv = params.window.xy + frag.xy * params.window.zw;
    // `lod_for`: the longer derivative vector in texels, log2, bias, floor, clamp.
    let f = max(length(dpdx(uv) * params.side_texels), length(dpdy(uv) * params.side_texels));
    let lod = u32(clamp(floor(log2(f) + params.bias), 0.0, f32(params.lod_count - 1u)));
    // `page_at`: floor(uv * pages at the LOD), clamped to the grid (exact: a power of two).
    let n = f32(params.pages >> lod);
    let page = vec2<u32>(clamp(floor(uv * n), vec2<f32>(0.0), vec2<f32>(n - 1.0)));
    return (page.x & 0xfffu) | ((page.y & 0xfffu) << 12u) | (lod << 24u) | (params.texture << 28u);
}
