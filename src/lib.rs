//! The library behind `vortex-tiler`: cut an image of any size into the pages of a virtual
//! texture, with every power-of-two LOD, in memory bounded by the image's width.
//!
//! The modules follow the data, one folder or file per stage (see `docs/architecture.md`):
//! - [`source`]: images delivered one row at a time (PNG, JPEG, TIFF, PNM, or decoded whole),
//!   and under [`source::tiled`] the already-tiled inputs of `convert`;
//! - [`pyramid`]: the bands, the exact sums and the resampling filters that make every LOD,
//!   the LOD cascade, and the cutting of tiles with their borders;
//! - [`codec`]: tile encoders (JPEG, PNG, raw, zstd, BC1/BC7);
//! - [`sink`]: where encoded tiles go (a tile directory or a pack);
//! - [`split`]: the orchestration that runs source -> pyramid -> codec -> sink.
//!
//! Beside the stages: [`tile_dir`] is the tile-directory format (`info.json`, file names) that
//! the directory sink writes and the tiled sources read; [`repack`] moves tiles between a tile
//! directory and a pack (`pack`, `unpack`). Shared types: [`layout`] (the page grid's
//! geometry), [`pixel`] (channels and depth), [`background`] (what fills the padding),
//! [`settings`] (flags and `info.json` into options) and [`error`]. Every command checks
//! [`limits`] before it allocates and claims its destination through [`output`], the one rule
//! that keeps it from destroying anything the user owns. [`viewer`] names pages as Deep Zoom,
//! IIIF and web-map tiles; [`serve`] answers those names over HTTP from packs and directories.

pub mod background;
pub mod codec;
mod encoders;
pub mod error;
pub mod layout;
pub mod limits;
pub mod output;
pub mod pixel;
pub mod pyramid;
pub mod repack;
pub mod serve;
pub mod settings;
pub mod shard;
pub mod sink;
pub mod source;
pub mod split;
pub mod stages;
pub mod tile_dir;
pub mod viewer;

/// Internals the integration tests check directly (the exact sums, the sRGB tables, the
/// resamplers, the cutting arithmetic). Not an API: only built with the `testing` feature,
/// which the crate's own dev-dependency on itself turns on for `cargo test`.
#[cfg(feature = "testing")]
pub mod testing {
    pub use crate::pyramid::cut::{first_row_read, last_row_needed};
    pub use crate::pyramid::filter::{ExactFilter, SrgbTable, linear_to_srgb, srgb_to_linear, sums_need_u128};
    pub use crate::pyramid::reduce::{Acc, ExactRow, Reducer};
    pub use crate::pyramid::resample::{Resampler, resample_level};
    pub use crate::pyramid::stripes::one_band_bytes;
}
