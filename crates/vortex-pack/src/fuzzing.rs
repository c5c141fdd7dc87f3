//! Not part of the API: what this crate's tests and fuzzers (and the tests of the crates built
//! on it) use to build packs and to edit their bytes behind the checksums, behind the hidden
//! `fuzzing` feature. It may change in any release; a reader or writer of packs needs none of it.

use crate::format::{
    Description, ENTRY_LEN, FNV_OFFSET, HEADER_LEN, LEVEL_LEN, Level, fnv1a, put_u32, put_u64, u32_at, u64_at,
};

/// Byte offsets of the header's fields (see the spec's diagram).
pub mod at {
    pub use crate::format::at::*;
}

/// The levels of a square power-of-two pyramid of `description` (the tiler's older layout),
/// their `first_entry` as the writer places them.
pub fn pyramid_levels(d: &Description, tiles_at_lod0: u32) -> Vec<Level> {
    let mut first = 0u64;
    (0..d.level_count)
        .map(|lod| {
            let n = tiles_at_lod0 >> lod;
            let shrink = |v: u32| ((v as u64 + (1u64 << lod) - 1) >> lod) as u32;
            let level =
                Level { tiles_w: n, tiles_h: n, first_entry: first, width: shrink(d.width), height: shrink(d.height) };
            first += n as u64 * n as u64;
            level
        })
        .collect()
}

/// Recomputes every checksum the header's offsets let it find (index,
/// metadata, content hash, header), so that a deliberate change to a pack's bytes gets past the
/// checksums to the checks behind them. Sections the header places outside `b` keep their old
/// checksums.
pub fn reseal(b: &mut [u8]) {
    fn section(b: &[u8], offset: u64, len: Option<u64>) -> Option<&[u8]> {
        let start = usize::try_from(offset).ok()?;
        let end = start.checked_add(usize::try_from(len?).ok()?)?;
        b.get(start..end)
    }
    if b.len() < HEADER_LEN {
        return;
    }
    let count = |field| u32_at(b, field) as u64;
    let levels = section(b, u64_at(b, at::LEVELS_OFFSET), count(at::LEVEL_COUNT).checked_mul(LEVEL_LEN as u64));
    let index = section(b, u64_at(b, at::INDEX_OFFSET), u64_at(b, at::INDEX_COUNT).checked_mul(ENTRY_LEN as u64));
    let meta = section(b, u64_at(b, at::META_OFFSET), Some(count(at::META_LEN)));
    let index_crc = levels.zip(index).map(|(l, i)| crc32c::crc32c_append(crc32c::crc32c(l), i));
    let meta_crc = meta.map(crc32c::crc32c);
    let hash = meta.zip(index).map(|(m, i)| fnv1a(fnv1a(FNV_OFFSET, m), i));
    if let Some(c) = index_crc {
        put_u32(b, at::INDEX_CRC, c);
    }
    if let Some(c) = meta_crc {
        put_u32(b, at::META_CRC, c);
    }
    if let Some(h) = hash {
        put_u64(b, at::CONTENT_HASH, h);
    }
    let crc = crc32c::crc32c(&b[..at::HEADER_CRC]);
    put_u32(b, at::HEADER_CRC, crc);
}
