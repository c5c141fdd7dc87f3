//! The GPU runtime of Vortex virtual texturing, on wgpu: the physical page cache
//! ([`page_cache`]), the page-table texture ([`page_table`]), the pass that samples a virtual
//! texture through them ([`render`]) and the feedback pass with its readback ([`feedback`]).
//! What to load and where it goes is decided on the CPU by `vortex-vt`; this crate only mirrors
//! those decisions into GPU resources, draws with them and reads the feedback back.
//!
//! Everything here is headless (no window or surface) and runs on lavapipe, Mesa's CPU Vulkan
//! driver, so it is tested on machines without a GPU.

pub mod device;
pub mod feedback;
mod fullscreen;
pub mod page_cache;
pub mod page_table;
pub mod render;

pub use device::{DeviceError, Gpu};
pub use feedback::{FeedbackFrame, FeedbackPass, FeedbackReadback, FeedbackTarget, FeedbackView};
pub use page_cache::{CacheError, PageCache};
pub use page_table::GpuPageTable;
pub use render::{RenderTarget, SamplePass, ViewParams};
