//! Shared by the fuzz targets: fuzzer bytes as a pack file.
//!
//! Random bytes rarely carry valid checksums, so the first input byte chooses how the rest is
//! written: bit 0 recomputes every checksum (index, metadata, content hash, header), bit 1 also
//! makes the header's file and data lengths agree with the input. Those inputs get past
//! `Pack::open`'s checks to the code behind them.

use std::path::PathBuf;

use vortex_pack::format::{FNV_OFFSET, HEADER_LEN, at, fnv1a};

/// Writes the input to this process's scratch file; `None` for an empty input.
pub fn pack_file(data: &[u8]) -> Option<PathBuf> {
    let (&mode, rest) = data.split_first()?;
    let mut bytes = rest.to_vec();
    if mode & 2 != 0 && bytes.len() >= HEADER_LEN {
        let len = bytes.len() as u64;
        let data_offset = u64_at(&bytes, at::DATA_OFFSET);
        bytes[at::FILE_LEN..at::FILE_LEN + 8].copy_from_slice(&len.to_le_bytes());
        bytes[at::DATA_LEN..at::DATA_LEN + 8].copy_from_slice(&len.saturating_sub(data_offset).to_le_bytes());
    }
    if mode & 3 != 0 {
        reseal(&mut bytes);
    }
    let path = std::env::temp_dir().join(format!("vortex-pack-fuzz-{}.vtpk", std::process::id()));
    std::fs::write(&path, &bytes).ok()?;
    Some(path)
}

fn u32_at(b: &[u8], at: usize) -> u64 {
    u32::from_le_bytes(b[at..at + 4].try_into().unwrap()) as u64
}

fn u64_at(b: &[u8], at: usize) -> u64 {
    u64::from_le_bytes(b[at..at + 8].try_into().unwrap())
}

fn section(b: &[u8], offset: u64, len: Option<u64>) -> Option<&[u8]> {
    let start = usize::try_from(offset).ok()?;
    let end = start.checked_add(usize::try_from(len?).ok()?)?;
    b.get(start..end)
}

/// Recomputes the checksums that the header's offsets let it find.
pub fn reseal(b: &mut [u8]) {
    if b.len() < HEADER_LEN {
        return;
    }
    let levels = section(b, u64_at(b, at::LEVELS_OFFSET), u32_at(b, at::LEVEL_COUNT).checked_mul(32));
    let index = section(b, u64_at(b, at::INDEX_OFFSET), u64_at(b, at::INDEX_COUNT).checked_mul(24));
    let meta = section(b, u64_at(b, at::META_OFFSET), Some(u32_at(b, at::META_LEN)));
    let index_crc = levels.zip(index).map(|(l, i)| crc32c::crc32c_append(crc32c::crc32c(l), i));
    let meta_crc = meta.map(crc32c::crc32c);
    let hash = meta.zip(index).map(|(m, i)| fnv1a(fnv1a(FNV_OFFSET, m), i));
    if let Some(c) = index_crc {
        b[at::INDEX_CRC..at::INDEX_CRC + 4].copy_from_slice(&c.to_le_bytes());
    }
    if let Some(c) = meta_crc {
        b[at::META_CRC..at::META_CRC + 4].copy_from_slice(&c.to_le_bytes());
    }
    if let Some(h) = hash {
        b[at::CONTENT_HASH..at::CONTENT_HASH + 8].copy_from_slice(&h.to_le_bytes());
    }
    let crc = crc32c::crc32c(&b[..at::HEADER_CRC]);
    b[at::HEADER_CRC..at::HEADER_CRC + 4].copy_from_slice(&crc.to_le_bytes());
}
