//! Errors that say where: the file, the byte offset or section, and the tile when known.

use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum PackError {
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },

    /// The file is not a pack, or a structure in it is invalid.
    #[error("{}: {section} at byte {offset}: {message}", path.display())]
    Corrupt { path: PathBuf, section: &'static str, offset: u64, message: String },

    /// A valid pack this reader cannot read (newer version, unknown required feature).
    #[error("{}: {message}", path.display())]
    Unsupported { path: PathBuf, message: String },

    /// The header claims more than the reader's [`Limits`](crate::Limits) allow (a tile side,
    /// a tile count): refused before anything is sized from it. The writer refuses, with this
    /// error, a pack that readers with the default limits would refuse. `field` is the header field or
    /// level-table row, `offset` its byte in the file, `cap` the `Limits` member that raises it.
    #[error(
        "{}: {field} (byte {offset}) is {value}, over the limit of {limit} (Limits::{cap})",
        path.display()
    )]
    LimitExceeded { path: PathBuf, field: String, offset: u64, value: u64, limit: u64, cap: &'static str },

    /// A tile's entry or bytes are invalid.
    #[error("{}: tile (lod {lod}, x {x}, y {y}) at byte {offset}: {message}", path.display())]
    Tile { path: PathBuf, lod: u32, x: u32, y: u32, offset: u64, message: String },

    /// The caller asked for a tile that does not exist.
    #[error("{}: no tile (lod {lod}, x {x}, y {y}): {message}", path.display())]
    OutOfRange { path: PathBuf, lod: u32, x: u32, y: u32, message: String },

    /// A payload given on its own (no pack, no tile) does not decode; the message names the kind.
    #[error("{message}")]
    Payload { kind: &'static str, message: String },

    /// The writer was used wrongly (tile outside the grid, written twice, wrong raw size).
    #[error("{0}")]
    Usage(String),
}

pub type Result<T, E = PackError> = std::result::Result<T, E>;
