//! The GPU runtime of Vortex virtual texturing, on wgpu, made to be embedded: created on the
//! application's own `wgpu::Device` and `Queue`, it streams pages of up to 16 virtual textures
//! (Vortex packs, or any [`PageSource`]) into a physical page cache, while the application draws
//! with its own pipelines and shaders, which include this crate's WGSL module ([`shader`]) and
//! call `vt_sample` and `vt_feedback`. Once per frame the application calls
//! [`Runtime::end_frame`], which never blocks. What to load and where it goes is decided on the
//! CPU by `vortex-vt`; this crate mirrors those decisions into GPU resources.
//!
//! The modules are the nouns of the technique, in the order a frame meets them:
//!
//! - [`shader`]: the WGSL module (`vt_sample`, `vt_feedback`) and its bindings;
//! - [`feedback`]: the buffer `vt_feedback` writes and its non-blocking readback ring;
//! - [`source`]: where pages come from ([`PageSource`]; packs; [`source::Delayed`] for latency);
//! - [`loader`]: the worker pool that reads and decodes pages off the render thread;
//! - [`layer`]: layer stacks, several textures on one page grid (albedo, normal, roughness)
//!   streamed as one;
//! - [`page_cache`] (the physical texture the pages are uploaded into, RGBA8 or [`bc7`]) and
//!   [`page_table`] (the buffer that maps virtual pages to its slots);
//! - [`sample`]: the [`SampleFilter`] and which one a border allows;
//! - [`runtime`]: the frame's end that ties them together;
//! - [`device`]: a headless device (and lavapipe pinning), for tools and tests.
//!
//! The `harness` feature adds the `harness` module: scenes, cameras and an offscreen renderer built on
//! the public API (what `vortex-tiler render` runs). The `testing` feature adds `testing`
//! (synthetic LOD chains, bordered tiles and packs of them) and the harness's address probe.
//!
//! The crate also builds for `wasm32-unknown-unknown` and draws on WebGPU (`docs/web-runtime.md`):
//! there the loader runs on the browser's event loop instead of threads, packs are read with
//! `fetch` (`source::WebPack`, the same protocol code as the native `source::HttpPack`), and
//! the cache holds RGBA8 (or BC7 as stored: no BC transcoder builds for wasm).
//!
//! Everything runs on lavapipe, Mesa's CPU Vulkan driver, so it is tested on machines without a
//! GPU. `examples/embed.rs` draws a pack with its own pipeline in under 200 lines.

// Every public item documented: clippy -D warnings (CI) makes it stick.
#![warn(missing_docs)]

pub mod bc7;
mod bindings;
mod clock;
pub mod device;
pub mod feedback;
#[cfg(feature = "harness")]
pub mod harness;
mod landing;
pub mod layer;
pub mod loader;
pub mod page_cache;
pub mod page_table;
mod params;
mod readback;
pub mod runtime;
pub mod sample;
pub mod shader;
pub mod source;
#[cfg(feature = "testing")]
pub mod testing;
pub mod texture;

pub use device::{DeviceError, Gpu};
pub use feedback::{FeedbackBuffer, FeedbackFrame, FeedbackReadback};
pub use layer::{Layer, LayerKind, MAX_LAYERS};
pub use loader::{
    DEFAULT_MEMORY_TIER_BYTES, LoadCounters, LoadError, LoadedPage, Loader, LoaderError, RetryPolicy, STAND_IN_COLORS,
    TIER_ENTRY_OVERHEAD, TierUsage, stand_in_tile,
};
pub use page_cache::{CacheError, CacheFormat, PageCache};
pub use page_table::{GpuPageTable, PageTableError};
pub use readback::ReadbackError;
pub use runtime::{FrameStats, Pacing, Runtime, RuntimeConfig, RuntimeError};
pub use sample::SampleFilter;
pub use source::{PageSource, ReadError, ReadErrorKind, SourceTile, StoredRead, StoredTile, TileId, TileKind};
pub use texture::VirtualTexture;
// What an embedder names from the crates below (opening packs, pages and slots for the loader),
// and those crates themselves: no direct dependency on them to keep in step with this one.
pub use vortex_pack::{self, Limits, Pack, PackError};
pub use vortex_vt::page::PageId;
pub use vortex_vt::residency::Slot;
pub use vortex_vt::{self};

/// The README's examples, compiled as doc tests.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
pub struct ReadmeDoctests;
