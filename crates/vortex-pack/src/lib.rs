#![doc = include_str!("../README.md")]

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
