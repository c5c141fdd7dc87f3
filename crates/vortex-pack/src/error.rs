//! Errors that say where: the file, the byte offset or section, and the tile when known.

use std::path::PathBuf;

/// Why a pack could not be opened, read, decoded or written. Every variant names the file (a
/// payload decoded on its own aside) and, where it has one, the byte and the tile.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum PackError {
    /// Reading or writing the file failed.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// What the system said.
        #[source]
        source: std::io::Error,
    },

    /// The file is not a pack, or a structure in it is invalid.
    #[error("{}: {section} at byte {offset}: {message}", path.display())]
    Corrupt {
        /// The file.
        path: PathBuf,
        /// The part of the file: `header`, `levels`, `index`, `metadata`, `data`.
        section: &'static str,
        /// The byte of the file where the fault is.
        offset: u64,
        /// What is wrong.
        message: String,
    },

    /// A valid pack this reader cannot read (newer version, unknown required feature).
    #[error("{}: {message}", path.display())]
    Unsupported {
        /// The file.
        path: PathBuf,
        /// What this reader does not support.
        message: String,
    },

    /// The header claims more than the reader's [`Limits`](crate::Limits) allow (a tile side,
    /// a tile count): refused before anything is sized from it. The writer refuses, with this
    /// error, a pack that readers with the default limits would refuse.
    #[error(
        "{}: {field} (byte {offset}) is {value}, over the limit of {limit} (Limits::{cap})",
        path.display()
    )]
    LimitExceeded {
        /// The file.
        path: PathBuf,
        /// The header field or level-table row.
        field: String,
        /// Its byte in the file.
        offset: u64,
        /// What it claims.
        value: u64,
        /// The most the limits allow.
        limit: u64,
        /// The [`Limits`](crate::Limits) member that raises it.
        cap: &'static str,
    },

    /// A tile's entry or bytes are invalid.
    #[error("{}: tile (lod {lod}, x {x}, y {y}) at byte {offset}: {message}", path.display())]
    Tile {
        /// The file.
        path: PathBuf,
        /// The tile's level.
        lod: u32,
        /// Its column.
        x: u32,
        /// Its row.
        y: u32,
        /// The byte of the file where the fault is (its entry's, or its payload's).
        offset: u64,
        /// What is wrong.
        message: String,
    },

    /// The caller asked for a tile that does not exist.
    #[error("{}: no tile (lod {lod}, x {x}, y {y}): {message}", path.display())]
    OutOfRange {
        /// The file.
        path: PathBuf,
        /// The level asked for.
        lod: u32,
        /// The column asked for.
        x: u32,
        /// The row asked for.
        y: u32,
        /// The pack's extent there.
        message: String,
    },

    /// A payload given on its own (no pack, no tile) does not decode; the message names the kind.
    #[error("{message}")]
    Payload {
        /// The payload's tile kind ([`TileKind::name`](crate::TileKind::name)).
        kind: &'static str,
        /// What is wrong.
        message: String,
    },

    /// The writer was used wrongly (tile outside the grid, written twice, wrong raw size).
    #[error("{0}")]
    Usage(String),
}

/// A result whose error is a [`PackError`].
pub type Result<T, E = PackError> = std::result::Result<T, E>;
