//! The WGSL module an application includes in its own shaders (`shaders/vt.wgsl`): its
//! bindings, `vt_sample` / `vt_sample_level` / `vt_feedback` and their texel-addressed variants.
//! The module is plain WGSL text, prepended to the application's own source, with its bindings
//! in the bind group the application chooses (so it never collides with the application's
//! groups); [`Runtime::bind_group_layout`](crate::Runtime::bind_group_layout) and
//! [`Runtime::bind_group`](crate::Runtime::bind_group) are that group's layout and contents.
//!
//! ```
//! let fragment = "
//! @fragment
//! fn fs_main(@builtin(position) p: vec4<f32>, @location(0) uv: vec2<f32>) -> @location(0) vec4<f32> {
//!     let ddx = dpdx(uv);
//!     let ddy = dpdy(uv);
//!     vt_feedback(0u, uv, ddx, ddy, p.xy);
//!     return vt_sample(0u, uv, ddx, ddy);
//! }";
//! let source = vortex_vt_wgpu::shader::with_module(fragment, 1);
//! assert!(source.contains("@group(1) @binding(0) var<uniform> vt_params"));
//! ```

use std::borrow::Cow;

/// The module's source as stored, its group written `VT_GROUP`.
const MODULE: &str = include_str!("shaders/vt.wgsl");

/// The module's source with its bindings in bind group `group`.
pub fn module(group: u32) -> String {
    MODULE.replace("VT_GROUP", &group.to_string())
}

/// `application`'s WGSL after the module (bindings in `group`): one source that can call the
/// module's functions.
pub fn with_module(application: &str, group: u32) -> String {
    format!("{}\n{application}", module(group))
}

/// The pipeline constant that fixes the module's filter when a pipeline is made (pass it in
/// `PipelineCompilationOptions::constants`): the other filters' code is compiled out. Without
/// it the filter comes from the uniform block and [`Runtime::set_filter`](crate::Runtime::set_filter)
/// changes it without a new pipeline; pass the runtime's filter, and make the pipeline anew when
/// it changes. Worth it on CPU drivers (lavapipe), which run both sides of a branch.
pub fn filter_constant(filter: crate::SampleFilter) -> (&'static str, f64) {
    ("VT_FILTER", f64::from(filter as u32))
}

/// The pipeline constant that turns on anisotropic filtering in `vt_sample` and `vt_feedback`:
/// up to `max_probes` probes per sample along the pixel's footprint (clamped to
/// 1..=[`MAX_ANISOTROPY`](vortex_vt::anisotropy::MAX_ANISOTROPY); 1, the default without it, is
/// isotropic). A constant rather than a uniform so that the probes' loop costs nothing when off.
/// Feedback asks for the finer LOD the probes read, so pass the same constant to the pipelines
/// that write feedback.
pub fn anisotropy_constant(max_probes: u32) -> (&'static str, f64) {
    ("VT_ANISO", f64::from(max_probes.clamp(1, vortex_vt::anisotropy::MAX_ANISOTROPY)))
}

/// A shader module descriptor of [`with_module`], for `Device::create_shader_module`.
pub fn descriptor<'a>(label: Option<&'a str>, application: &str, group: u32) -> wgpu::ShaderModuleDescriptor<'a> {
    wgpu::ShaderModuleDescriptor {
        label,
        source: wgpu::ShaderSource::Wgsl(Cow::Owned(with_module(application, group))),
    }
}
