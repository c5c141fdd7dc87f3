//! The pack (docs/pack-format.md, `crates/vortex-pack`) as an output and an input: [`PackSink`]
//! writes one pack file from the pipeline's tiles, [`PackInput`] reads a pack's LOD 0 back as
//! an image for `convert`.

mod read;
mod sink;

pub use read::PackInput;
pub use sink::{PackSink, tile_kind};
pub(crate) use sink::{pack_description, size_bound};
