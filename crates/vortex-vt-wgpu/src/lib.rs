//! The GPU runtime of Vortex virtual texturing, on wgpu. What to load and where it goes is decided
//! on the CPU by `vortex-vt`; this crate mirrors those decisions into GPU resources, draws with
//! them and reads the feedback back. The modules are the nouns of the technique, in the order a
//! frame meets them:
//!
//! - [`scene`], [`camera`], [`view`], [`mesh`]: what is drawn, from where;
//! - [`feedback`]: the feedback pass and its non-blocking readback ring (which pages are wanted);
//! - [`loader`]: the worker pool that reads those pages from packs ([`loader`]'s `pool`, `decode`
//!   and `magnify` for absent tiles);
//! - [`page_cache`] (the physical texture the pages are uploaded into, RGBA8 or [`bc7`]) and
//!   [`page_table`] (the texture that maps virtual pages to its slots);
//! - [`sample`]: the sampling pass through page table and cache, and its [`SampleFilter`];
//! - [`runtime`]: the frame loop that ties them together; [`device`]: the headless device (and
//!   lavapipe pinning); [`probe`]: the address probe for tests.
//!
//! The passes share their pipelines, targets and shader prelude (`draw`), their uniform block
//! (`params`) and their readback (`readback`, whose failures are [`ReadbackError`]s, never
//! panics). The `testing` feature adds a `testing` module: synthetic LOD chains, bordered tiles
//! and packs of them, for tests and measurement programs.
//!
//! Everything here is headless (no window or surface) and runs on lavapipe, Mesa's CPU Vulkan
//! driver, so it is tested on machines without a GPU.

pub mod bc7;
pub mod camera;
pub mod device;
mod draw;
pub mod feedback;
pub mod loader;
pub mod mesh;
pub mod page_cache;
pub mod page_table;
mod params;
pub mod probe;
mod readback;
pub mod runtime;
pub mod sample;
pub mod scene;
#[cfg(feature = "testing")]
pub mod testing;
pub mod texture;
pub mod view;

pub use device::{DeviceError, Gpu};
pub use feedback::{FeedbackFrame, FeedbackPass, FeedbackReadback, FeedbackTarget};
pub use loader::{LoadCounters, LoadError, LoadedPage, Loader, LoaderError, STAND_IN_COLORS, stand_in_tile};
pub use mesh::{GpuMesh, Mesh, Vertex};
pub use page_cache::{CacheError, CacheFormat, PageCache};
pub use page_table::{GpuPageTable, PageTableError};
pub use readback::ReadbackError;
pub use runtime::{FrameReport, Report, Runtime, RuntimeError};
pub use sample::{RenderTarget, SampleFilter, SamplePass, Sources};
pub use scene::{Effects, Pose, Scene, SceneError, SceneView, Shape};
pub use texture::VirtualTexture;
pub use view::{View, Window};
