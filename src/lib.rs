//! The library behind `vortex-tiler`: cut an image of any size into the pages of a virtual
//! texture, with every power-of-two LOD, in memory bounded by the image's width.
//!
//! The modules follow the data, one folder or file per stage (see `docs/architecture.md`):
//! - [`source`]: images delivered one row at a time (PNG, JPEG, TIFF, PNM, or decoded whole),
//!   and under [`source::tiled`] the already-tiled inputs of `convert`;
//! - [`pyramid`]: the bands, the exact sums and the resampling filters that make every LOD,
//!   the LOD cascade, and the cutting of tiles with their borders;
//! - [`codec`]: tile encoders (JPEG, PNG, raw, zstd, BC1/BC7);
//! - [`sink`]: where encoded tiles go: the [`sink::TileSink`] every format's sink is;
//! - [`split`]: the orchestration that runs source -> pyramid -> codec -> sink, with the
//!   options, progress and summary of a run ([`split::SplitOptions`], [`split::Progress`],
//!   [`split::Summary`]);
//! - [`scale_out`]: one split on many machines (a shard's run, the merge).
//!
//! Beside the stages: [`formats`] holds each file format in a folder of its own: what it names,
//! its sink and its reader (the tile directory's `info.json` and file names, packs, Deep Zoom,
//! IIIF and web-map tiles, PMTiles, OME-Zarr); [`outputs`] plans and writes several of them
//! from one read of a source; [`repack`] moves tiles between a tile
//! directory and a pack (`pack`, `unpack`). Shared types: [`layout`] (the page grid's
//! geometry), [`pixel`] (channels and depth), [`background`] (what fills the padding),
//! [`settings`] (flags and `info.json` into options) and [`error`]. Every command checks
//! [`limits`] before it allocates and claims its destination through [`output`], the one rule
//! that keeps it from destroying anything the user owns. `serve` (feature `serve`) answers
//! the viewer layouts' names ([`formats::viewer`]) over HTTP from packs and directories.
//!
//! # Tiling from Rust
//!
//! Without its default features (`vortex-tiler = { version = "0.1", default-features = false }`)
//! the package is this library alone: none of the command line's, the server's or the GPU's
//! crates (features `cli`, `serve`, `gpu`). A run reports finished tiles to a [`split::Progress`]
//! and stops, with [`error::TilerError::Interrupted`] and nothing left at the destination, once
//! its `cancelled` says so: the command line's Ctrl-C is that flag, set by a signal handler.
//!
//! ```
//! use std::path::Path;
//! use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
//!
//! use vortex_tiler::error::{Result, TilerError};
//! use vortex_tiler::outputs::{Budget, Format, Output, Plan, Settings, Wrote};
//! use vortex_tiler::split::Progress;
//! use vortex_tiler::formats::viewer::Viewer;
//! use vortex_tiler::source;
//!
//! /// Counts finished tiles; stops the run when `stop` is set.
//! #[derive(Default)]
//! struct Watch {
//!     tiles: AtomicU64,
//!     stop: AtomicBool,
//! }
//!
//! impl Progress for Watch {
//!     fn advance(&self, tiles: u64) {
//!         self.tiles.fetch_add(tiles, Ordering::Relaxed);
//!     }
//!     fn cancelled(&self) -> bool {
//!         self.stop.load(Ordering::Relaxed)
//!     }
//! }
//!
//! /// Cuts `input` into 256-texel tiles, once, for two outputs: Deep Zoom for OpenSeadragon
//! /// in `dir/web` and a pack for the GPU in `dir/NAME.vtpk`.
//! fn tile(input: &Path, dir: &Path, name: &str, watch: &Watch) -> Result<Vec<Wrote>> {
//!     let budget = Budget::default(); // 1 GiB, everything the run holds at once
//!     let source = source::open(input, budget)?;
//!     let mut settings = Settings::default();
//!     settings.tiles.tile_size = Some(256);
//!     settings.tiles.border = Some(0); // the pack's; Deep Zoom has --overlap (here its default, 1)
//!     let outputs = vec![
//!         Output::new(Format::Viewer(Viewer::Dzi), dir.join("web")),
//!         Output::new(Format::Pack, dir.join(format!("{name}.vtpk"))),
//!     ];
//!     // Checks every output and claims its path: replaces only an older output of ours.
//!     let plan = Plan::new(outputs, &settings, &source.header(), &[input], budget)?;
//!     // A failed or stopped run leaves no output half-written.
//!     plan.write(source, watch)
//! }
//!
//! # fn main() -> Result<()> {
//! # let temp = tempfile::tempdir().expect("a temporary directory");
//! # let (input, dir) = (temp.path().join("huge.png"), temp.path());
//! # image::RgbImage::from_fn(600, 300, |x, y| image::Rgb([x as u8, y as u8, 128])).save(&input).expect("a PNG");
//! let watch = Watch::default();
//! let wrote = tile(&input, dir, "huge", &watch)?;
//! let total: u64 = wrote.iter().map(|w| w.tiles).sum();
//! assert_eq!(watch.tiles.load(Ordering::Relaxed), total);
//!
//! // Set from anywhere (another thread, a signal handler, a web request's cancellation).
//! watch.stop.store(true, Ordering::Relaxed);
//! let stopped = tile(&input, dir, "stopped", &watch);
//! assert!(matches!(stopped, Err(TilerError::Interrupted)));
//! assert!(!dir.join("stopped.vtpk").exists());
//! # let pack = vortex_tiler::vortex_pack::Pack::open(&dir.join("huge.vtpk")).expect("the pack");
//! # assert_eq!(pack.description().width, 600);
//! # assert!(dir.join("web/huge.dzi").is_file());
//! # assert_eq!(std::fs::read_dir(dir).expect("the directory").count(), 3, "no temporary left");
//! # Ok(())
//! # }
//! ```

#![warn(missing_docs)]

pub mod background;
pub mod codec;
mod decode;
mod encoders;
pub mod error;
mod fnv;
pub mod formats;
pub(crate) mod job;
pub mod layout;
pub mod limits;
pub mod output;
pub mod outputs;
pub mod pixel;
pub mod pyramid;
pub mod repack;
pub mod resume;
pub mod scale_out;
#[cfg(feature = "serve")]
pub mod serve;
pub mod settings;
pub(crate) mod shard;
pub mod sink;
pub mod source;
pub mod split;
pub(crate) mod stages;
pub mod store;

/// The pack format's crate, whose reader ([`vortex_pack::Pack`]) and [`vortex_pack::WriteOptions`]
/// this library's API uses.
pub use vortex_pack;

/// The unit tests' rule for an outside part they lack (a colour profile from a Debian
/// package, `/proc`): outside CI, skip with a note; under `CI=true`, where `.ci/run` installs
/// every part, fail, saying what was missing. (`tests/it/common` has the same rule.)
#[cfg(test)]
pub(crate) fn skip_unless_ci(what: &str, why: &str) {
    assert!(std::env::var("CI").map_or(true, |v| v != "true"), "CI=true and {why}");
    eprintln!("note: skipping {what}: {why}");
}

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
