//! The caps a reader holds a pack to, checked before anything is allocated from a value the
//! file claims. A pack's header says how large its tiles are and how many there are; a hostile
//! or damaged one can claim a 2^31-texel tile or billions of tiles in a few bytes. `Pack::open`
//! compares those claims with [`Limits`] and refuses the pack with
//! [`PackError::LimitExceeded`](crate::PackError::LimitExceeded), naming the field and the cap,
//! so that no caller sizes a buffer from them unchecked; decoding charges each tile against
//! [`Limits::max_decoded_bytes`].
//!
//! Its own module, depended on by the reader, the decoder and `verify`, so that none of those
//! depends on another for a constant.

/// The default of [`Limits::max_decoded_bytes`]: 1 GiB, one 16384-texel RGBA8 tile.
pub const DEFAULT_MAX_DECODED_BYTES: u64 = 1 << 30;

/// What a pack may claim before a reader refuses it. Plain data: start from
/// [`Limits::default`] and change the caps you need,
/// `Limits { max_tiles: 1 << 30, ..Limits::default() }`.
///
/// The defaults admit every tile size the tiler writes (8..=16384) and its square pyramids up
/// to 16384 x 16384 tiles at LOD 0 (about 3.6 x 10^8 tiles; an index of 8 GiB, which a writer
/// holds in memory).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Limits {
    /// The largest `tile_size` (stored tile side, borders included) a header may declare.
    /// Default 16384, the largest texture side GPUs commonly support.
    pub max_tile_size: u32,
    /// The most tiles (index entries, every level together) a header's `index_count` and the
    /// level table may declare; the index is 24 bytes per tile. Default 2^29.
    pub max_tiles: u64,
    /// The most bytes one decoded tile, or any buffer decoding it needs, may take (decoding
    /// and `verify` with decoding). Default [`DEFAULT_MAX_DECODED_BYTES`].
    pub max_decoded_bytes: u64,
}

impl Default for Limits {
    fn default() -> Self {
        Limits { max_tile_size: 16384, max_tiles: 1 << 29, max_decoded_bytes: DEFAULT_MAX_DECODED_BYTES }
    }
}
