//! The viewer page's Rust half (`web/viewer/`, built by `scripts/build-web.sh`): a canvas's
//! WebGPU device, a pack opened by URL ([`WebPack`]) and drawn by `vortex-vt-wgpu`'s scene
//! renderer in a 2D pan and zoom, as `vortex-tiler view` draws it. The page's JavaScript owns the
//! frame loop (`requestAnimationFrame`) and the input, and calls [`Viewer::frame`] once per
//! frame, which never waits. A crate of its own so that `vortex-vt-wgpu` keeps a plain Rust API
//! with no JavaScript bindings in it. Natively it is empty.

#[cfg(target_arch = "wasm32")]
mod viewer;

#[cfg(target_arch = "wasm32")]
pub use viewer::Viewer;
