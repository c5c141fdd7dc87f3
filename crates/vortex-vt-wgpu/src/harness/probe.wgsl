// The address probe: writes each fragment's address at `frame.lod_override` (page, and the bits
// of the position within it) so that tests can hold the module's translation against the CPU
// mirror and against exact arithmetic. Appended to `harness.wgsl`, replacing its fragment stages.

@fragment
fn fs_probe_window(v: Varyings) -> @location(0) vec4<u32> {
    let t = vt_params.textures[v.texture];
    let at = vt_texel_at(window_texel(v.position.xy), u32(frame.lod_override), t);
    return vec4<u32>(at.page, bitcast<vec2<u32>>(at.within));
}

@fragment
fn fs_probe_mesh(v: Varyings) -> @location(0) vec4<u32> {
    let at = vt_uv_at(v.uv, u32(frame.lod_override), vt_params.textures[v.texture]);
    return vec4<u32>(at.page, bitcast<vec2<u32>>(at.within));
}
