//! Shared by the fuzz targets: fuzzer bytes as a pack file.
//!
//! Random bytes rarely carry valid checksums, so the first input byte chooses how the rest is
//! written: bit 0 recomputes every checksum (index, metadata, content hash, header), bit 1 also
//! makes the header's file and data lengths agree with the input. Those inputs get past
//! `Pack::open`'s checks to the code behind them.

use std::path::PathBuf;

use vortex_pack::format::{HEADER_LEN, at, reseal};

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

fn u64_at(b: &[u8], at: usize) -> u64 {
    u64::from_le_bytes(b[at..at + 8].try_into().unwrap())
}
