//! Everything `sampling_cost` takes from the GPU runtime, the page model and the pack format,
//! in one place: when those crates rename or move an item (the sampling filter, the harness),
//! only these paths change.

pub use vortex_pack::{Pack, TileKind};
pub use vortex_vt::page::{PageId, TextureGrid};
pub use vortex_vt::sampler::{LodChain, Rgba8Image, bilinear, nearest, trilinear};
pub use vortex_vt_wgpu::device::prefer_lavapipe;
pub use vortex_vt_wgpu::harness::camera::Keyframe;
pub use vortex_vt_wgpu::harness::{
    Effects, Pose, Scene, SceneRenderer, SceneView, Shape, TARGET_FORMAT, Window, WindowKey,
};
pub use vortex_vt_wgpu::testing::{box_chain, write_pack};
pub use vortex_vt_wgpu::{Gpu, Pacing, PageSource, Runtime, SampleFilter, VirtualTexture};
