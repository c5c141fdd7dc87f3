//! What a shard pack says about itself: its place among the shards, what it was made from
//! and with which options, and the exact sums of its subtree roots. It is the pack's JSON
//! metadata (a shard pack is a pack: `info` and `verify` read it); `merge` checks that the
//! shards belong together from it and makes the levels above the cut from its sums.

use std::path::Path;

use base64::Engine;
use base64::engine::general_purpose::STANDARD;
use serde::{Deserialize, Serialize};

use crate::error::{Result, TilerError};
use crate::pixel::{Channels, Depth, PixelLayout};

/// The manifest's version: `merge` refuses others.
pub const FORMAT: u32 = 1;

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase", deny_unknown_fields)]
pub struct Manifest {
    /// [`FORMAT`]; also how a shard pack is told from a pack.
    pub vortex_shard: u32,
    pub index: u32,
    pub count: u32,
    /// The cut level: this shard holds LODs `0..=cut_level` of its subtrees.
    pub cut_level: u32,
    pub source: SourceId,
    /// Everything else the shards must agree on.
    pub options: ShardOptions,
    /// The shard's rectangles of roots, with their sums.
    pub roots: Vec<StoredRoots>,
}

/// Which input the shard was cut from.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase", deny_unknown_fields)]
pub struct SourceId {
    /// The input as named on the shard's command line (for messages only).
    pub name: String,
    /// [`crate::shard::fingerprint()`] of the input.
    pub fingerprint: String,
    pub width: u32,
    pub height: u32,
    /// The source's texels, before any conversion: `luminance`, `luminanceAlpha`, `rgb` or
    /// `rgba`, of 1 or 2 bytes a sample.
    pub tile_format: String,
    pub sample_bytes: u8,
}

impl SourceId {
    /// Whether two shards were cut from the same input: everything but the name, which is the
    /// input as each command line spelled it (`src.tif`, `./src.tif`, an absolute path on
    /// another machine) and serves only to name it in messages.
    pub fn same_input(&self, other: &SourceId) -> bool {
        // Every other member by name, so that one added later is not left out.
        let SourceId { name: _, fingerprint, width, height, tile_format, sample_bytes } = self;
        (fingerprint, width, height, tile_format, sample_bytes)
            == (&other.fingerprint, &other.width, &other.height, &other.tile_format, &other.sample_bytes)
    }

    pub fn pixels(&self, path: &Path) -> Result<PixelLayout> {
        let channels = Channels::from_tile_format(&self.tile_format);
        let depth = match self.sample_bytes {
            1 => Some(Depth::U8),
            2 => Some(Depth::U16),
            _ => None,
        };
        match (channels, depth) {
            (Some(channels), Some(depth)) => Ok(PixelLayout { channels, depth }),
            _ => Err(shard_error(
                path,
                format!(
                    "its source texels '{}' of {} bytes are not a texel format",
                    self.tile_format, self.sample_bytes
                ),
            )),
        }
    }
}

#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase", deny_unknown_fields)]
pub struct ShardOptions {
    /// The metadata (`info.json` members) of the pack the shards merge into, as `split
    /// --pack` writes it: every tiling option is in it.
    pub info: String,
    /// `--flatten`, which `info.json` does not record.
    pub flatten: bool,
    /// `--max-memory`: the one-machine run's passes, hence its pack's order, depend on it.
    pub max_memory: u64,
    /// `--align` and `--tile-align`.
    pub alignment: u32,
    pub payload_alignment: u32,
    /// Bytes per stored sum: 8, or 16 where the sums could overflow 64 bits.
    pub sum_bytes: u32,
}

/// One rectangle of the cut level: texel columns and rows, and its sums ([`super::sums`]).
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase", deny_unknown_fields)]
pub struct StoredRoots {
    pub columns: [u64; 2],
    pub rows: [u64; 2],
    /// Base64 of the compressed sums.
    pub sums: String,
}

impl StoredRoots {
    pub fn new(columns: std::ops::Range<u64>, rows: std::ops::Range<u64>, sums: &[u8]) -> StoredRoots {
        StoredRoots { columns: [columns.start, columns.end], rows: [rows.start, rows.end], sums: STANDARD.encode(sums) }
    }

    pub fn sums(&self, path: &Path) -> Result<Vec<u8>> {
        STANDARD.decode(&self.sums).map_err(|e| shard_error(path, format!("its root sums are damaged: {e}")))
    }
}

impl Manifest {
    /// The manifest of the shard pack at `path` (whose metadata is `metadata`), or an error
    /// saying what the file is instead.
    pub fn parse(path: &Path, metadata: &[u8]) -> Result<Manifest> {
        #[derive(Deserialize)]
        #[serde(rename_all = "camelCase")]
        struct Probe {
            vortex_shard: Option<u32>,
        }
        let probe: Probe = serde_json::from_slice(metadata).unwrap_or(Probe { vortex_shard: None });
        match probe.vortex_shard {
            None => {
                Err(shard_error(path, "is a pack, not a shard: `split --shard I/N --pack FILE` writes shards".into()))
            }
            Some(v) if v != FORMAT => Err(shard_error(
                path,
                format!(
                    "is a shard of format {v}; this vortex-tiler merges format {FORMAT} (made by another version?)"
                ),
            )),
            Some(_) => serde_json::from_slice(metadata)
                .map_err(|e| shard_error(path, format!("its shard metadata is damaged: {e}"))),
        }
    }

    pub fn to_json(&self) -> Vec<u8> {
        #[expect(clippy::expect_used, reason = "a struct of strings and numbers always serialises")]
        serde_json::to_vec(self).expect("serialisable")
    }
}

/// What a shard pack is, in one line, if `metadata` is a shard's (for `info`).
pub fn describe(metadata: &[u8]) -> Option<String> {
    #[derive(Deserialize)]
    #[serde(rename_all = "camelCase")]
    struct Head {
        vortex_shard: u32,
        index: u32,
        count: u32,
        cut_level: u32,
        source: SourceId,
    }
    let h: Head = serde_json::from_slice(metadata).ok()?;
    Some(format!(
        "shard {} of {} (format {}) of a split of {}: its subtrees at LODs 0 to {}; `vortex-tiler merge` joins all {} into the pack",
        h.index, h.count, h.vortex_shard, h.source.name, h.cut_level, h.count
    ))
}

/// Refuses a shard pack where a whole pyramid is needed (`unpack`, `convert`, `serve`,
/// `render`): it holds only some pages and no levels above its cut.
pub fn refuse_shard(path: &Path, metadata: &[u8]) -> Result<()> {
    match describe(metadata) {
        Some(what) => Err(shard_error(path, format!("is {what} first"))),
        None => Ok(()),
    }
}

pub(crate) fn shard_error(path: &Path, message: String) -> TilerError {
    TilerError::Shard { path: path.to_path_buf(), message }
}
