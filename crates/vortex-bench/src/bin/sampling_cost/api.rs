//! Everything `sampling_cost` takes from the GPU runtime, the page model and the pack format,
//! in one place: when those crates rename or move an item (the sampling filter, the sampling
//! pass), only these paths change.

pub use vortex_gpu::camera::Keyframe;
pub use vortex_gpu::scene::WindowKey;
pub use vortex_gpu::{
    Effects, Gpu, GpuPageTable, Loader, Pose, RenderTarget, Runtime, SampleFilter, SamplePass, Scene, SceneView,
    Sources, View, VirtualTexture, Window,
};
pub use vortex_pack::format::pyramid_levels;
pub use vortex_pack::{Description, NewTile, Pack, PackWriter, TileId, TileKind, WriteOptions};
pub use vortex_vt::page::{PageId, TextureGrid};
pub use vortex_vt::sampler::{LodChain, LodImages, Rgba8Image, bilinear, nearest, trilinear};
