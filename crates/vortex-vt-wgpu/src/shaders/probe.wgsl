// The address probe: writes each fragment's window address at `frame.lod_override` (page, and
// the bits of the position within it) so that tests can hold the shader's translation against
// the CPU mirror and against exact arithmetic. Appended to `virtual.wgsl`.

@fragment
fn fs_window(v: Varyings) -> @location(0) vec4<u32> {
    let at = window_at(v.position.xy, u32(frame.lod_override), frame.textures[v.texture]);
    return vec4<u32>(at.page, bitcast<vec2<u32>>(at.within));
}

@fragment
fn fs_mesh(v: Varyings) -> @location(0) vec4<u32> {
    let at = uv_at(v.uv, u32(frame.lod_override), frame.textures[v.texture]);
    return vec4<u32>(at.page, bitcast<vec2<u32>>(at.within));
}
