// The README is the crate documentation; its example writes a pack, so it is compiled (and run
// as a doc test) only with the `write` feature, which this crate's own tests always have (the
// dev-dependency on itself). Without it the docs are this summary.
#![cfg_attr(feature = "write", doc = include_str!("../README.md"))]
#![cfg_attr(
    not(feature = "write"),
    doc = "Reader (and, behind the `write` feature, writer) of Vortex tile packs: every tile of a \
           virtual-texture pyramid in one file that a runtime maps into memory and reads tiles \
           from with no parsing and no copy. [`Pack`] opens a pack and finds tiles, [`verify()`] \
           checks every byte of one. The README, with an example that writes a pack and reads \
           it back, is the crate documentation with the `write` feature (as on \
           <https://docs.rs/vortex-pack>)."
)]
// Every public item documented: clippy -D warnings (CI) makes it stick.
#![warn(missing_docs)]

#[cfg(feature = "decode")]
mod decode;
mod error;
pub mod format;
#[cfg(feature = "fuzzing")]
#[doc(hidden)]
pub mod fuzzing;
mod limits;
#[cfg(feature = "write")]
mod output;
mod reader;
pub mod verify;
#[cfg(feature = "write")]
mod writeback;
#[cfg(feature = "write")]
mod writer;

pub use error::{PackError, Result};
pub use format::{Description, Entry, Header, Level, TileKind};
pub use limits::{DEFAULT_MAX_DECODED_BYTES, Limits};
#[cfg(feature = "write")]
pub use output::{PackFile, PackOutput};
pub use reader::{Pack, PackLayout, Place, Tile, TileId};
pub use verify::{Problem, Report, VerifyOptions, verify};
#[cfg(feature = "write")]
pub use writer::{NewTile, PackWriter, WriteOptions, WriteSummary, temporary_path, temporary_pid};
