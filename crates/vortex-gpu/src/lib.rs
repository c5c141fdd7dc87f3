//! The GPU runtime of Vortex virtual texturing, on wgpu: the physical page cache
//! ([`page_cache`]), the page-table texture ([`page_table`]), the sampling pass ([`render`]),
//! the feedback pass with its readback ([`feedback`]), the loader that reads pages from packs
//! ([`loader`]), scenes ([`scene`]) and the frame loop that ties them together ([`runtime`]).
//! What to load and where it goes is decided on the CPU by `vortex-vt`; this crate mirrors those
//! decisions into GPU resources, draws with them and reads the feedback back.
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
pub mod render;
pub mod runtime;
pub mod scene;
pub mod texture;
pub mod view;

pub use device::{DeviceError, Gpu};
pub use feedback::{FeedbackFrame, FeedbackPass, FeedbackReadback, FeedbackTarget};
pub use loader::{LoadCounters, LoadError, LoadedPage, Loader, LoaderError, STAND_IN_COLORS, stand_in_tile};
pub use mesh::{GpuMesh, Mesh, Vertex};
pub use page_cache::{CacheError, CacheFormat, PageCache};
pub use page_table::GpuPageTable;
pub use render::{Filter, RenderTarget, SamplePass, Sources};
pub use runtime::{FrameReport, Report, Runtime, RuntimeError};
pub use scene::{Effects, Pose, Scene, SceneError, SceneView, Shape};
pub use texture::VirtualTexture;
pub use view::{View, Window};
