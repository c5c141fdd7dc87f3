// The feedback pass: each fragment writes the feedback word (`vortex_vt::feedback::encode`) of
// the page it wants: the LOD from its footprint plus `frame.bias` (the residency's bias and the
// compensation for the target's reduced size), floored and clamped (`lod_from_footprint`), and
// the page holding its address at that LOD, as its index in the LOD's grid, row by row (the
// word's 24-bit page index). Appended to `virtual.wgsl`.

fn word(is_window: bool, position: vec2<f32>, uv: vec2<f32>, texture: u32) -> u32 {
    let t = frame.textures[texture];
    let f = footprint(is_window, uv, t);
    let lod = u32(clamp(floor(log2(f) + frame.bias), 0.0, f32(t.lod_count - 1u)));
    let page = address(is_window, position, uv, lod, t).page;
    let index = page.y * pages_per_row(t, lod) + page.x;
    return (index & 0xffffffu) | (lod << 24u) | (texture << 28u);
}

@fragment
fn fs_window(v: Varyings) -> @location(0) u32 {
    return word(true, v.position.xy, v.uv, v.texture);
}

@fragment
fn fs_mesh(v: Varyings) -> @location(0) u32 {
    return word(false, v.position.xy, v.uv, v.texture);
}
