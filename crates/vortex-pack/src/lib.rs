//! Vortex tile packs: every page of a virtual texture in one file that a runtime maps into
//! memory and reads tiles from with no parsing and no copy. The format is specified in
//! `docs/pack-format.md`.
//!
//! ```no_run
//! let pack = vortex_pack::Pack::open("world.vtpk")?;
//! match pack.tile(0, 3, 5)? {
//!     vortex_pack::Tile::Data(kind, bytes) => println!("{} bytes of {}", bytes.len(), kind.name()),
//!     other => println!("{other:?}"),
//! }
//! # Ok::<(), vortex_pack::PackError>(())
//! ```
//!
//! This crate is a leaf: std, a CRC-32C crate, memmap2, thiserror and zstd. The writer is
//! behind the `write` feature so that readers need none of it; `decode_rgba8` (PNG, JPEG, BC1
//! and BC7 decoding, and `verify` with `VerifyOptions::decode`) is behind `decode`. [`verify()`]
//! checks every byte of a pack and reports every problem it finds. Whatever a header claims is
//! held to [`Limits`] before anything is sized from it.

#[cfg(feature = "decode")]
mod decode;
mod error;
pub mod format;
mod limits;
mod reader;
pub mod verify;
#[cfg(feature = "write")]
mod writer;

#[cfg(feature = "decode")]
pub use decode::{decode_rgba8, decode_rgba8_limited, payload_texels};
pub use error::{PackError, Result};
pub use format::{Description, Entry, Header, Level, TileKind};
pub use limits::{DEFAULT_MAX_DECODED_BYTES, Limits};
pub use reader::{Pack, Tile, TileId};
pub use verify::{Problem, Report, VerifyOptions, verify};
#[cfg(feature = "write")]
pub use writer::{NewTile, PackWriter, WriteOptions, WriteSummary};
