//! The properties the fuzz targets check, kept apart from libFuzzer so that the crate's
//! ordinary tests (`tests/it/fuzz_regressions.rs` includes this file) run every committed
//! regression input through exactly the same checks on stable.
//!
//! Random bytes rarely carry valid checksums, so the first input byte chooses how the rest is
//! read: bit 0 recomputes every checksum (index, metadata, content hash, header), bit 1 also
//! makes the header's file and data lengths agree with the input. Those inputs get past
//! `Pack::open`'s checks to the code behind them.

use std::path::Path;

use vortex_pack::format::HEADER_LEN;
use vortex_pack::fuzzing::{at, reseal};
use vortex_pack::{Limits, Pack, VerifyOptions, verify};

/// The decoding limit of the checks: small, so that a payload claiming a large image is
/// refused rather than allocated.
pub const MAX_DECODED_BYTES: u64 = 1 << 22;

/// Fuzzer bytes as the bytes of a pack (see the module documentation); `None` for an empty
/// input.
pub fn pack_bytes(data: &[u8]) -> Option<Vec<u8>> {
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
    Some(bytes)
}

fn limits() -> Limits {
    Limits { max_decoded_bytes: MAX_DECODED_BYTES, ..Limits::default() }
}

/// Whatever the bytes, opening a pack in memory, reading and decoding every tile and verifying
/// it return errors, never panic, and decode within the limit.
pub fn open_and_read(data: &[u8]) {
    let Some(bytes) = pack_bytes(data) else { return };
    let Ok(pack) = Pack::from_bytes_with_limits("fuzz.vtpk", bytes, limits()) else { return };
    let ids: Vec<_> = pack.ids().collect();
    for id in ids {
        let _ = pack.tile(id);
        let checked = pack.tile_checked(id);
        let decoded = pack.decode_rgba8(id);
        if let Ok(Some(rgba)) = &decoded {
            let side = pack.description().tile_size as usize;
            assert_eq!(rgba.len(), side * side * 4);
        }
        if checked.is_err() {
            assert!(decoded.is_err(), "tile {id:?} fails its check but decodes");
        }
    }
    let _ = pack.ids_in_file_order();
    let report = verify(&pack, VerifyOptions { decode: true });
    let _ = (report.to_string(), report.to_json());
}

/// The same bytes give the same answers in memory and memory-mapped from `scratch` (a file
/// this function overwrites): the same error, or the same header, levels, metadata, tiles and
/// report.
pub fn backends_agree(data: &[u8], scratch: &Path) {
    let Some(bytes) = pack_bytes(data) else { return };
    if std::fs::write(scratch, &bytes).is_err() {
        return;
    }
    let limits = limits();
    match (Pack::from_bytes_with_limits(scratch, bytes, limits), Pack::open_with_limits(scratch, limits)) {
        (Ok(a), Ok(b)) => {
            assert_eq!(a.file(), b.file());
            assert_eq!(a.header(), b.header());
            assert_eq!(a.levels(), b.levels());
            assert_eq!(a.metadata(), b.metadata());
            let ids: Vec<_> = a.ids().collect();
            assert!(ids.iter().copied().eq(b.ids()));
            for id in ids {
                let ta = a.tile_checked(id).map_err(|e| e.to_string());
                let tb = b.tile_checked(id).map_err(|e| e.to_string());
                assert_eq!(ta, tb);
            }
            assert_eq!(a.ids_in_file_order(), b.ids_in_file_order());
            let opts = VerifyOptions::default();
            assert_eq!(verify(&a, opts), verify(&b, opts));
        }
        (Err(a), Err(b)) => assert_eq!(a.to_string(), b.to_string()),
        (a, b) => panic!("the backends disagree: {:?} / {:?}", a.err(), b.err()),
    }
}

fn u64_at(b: &[u8], at: usize) -> u64 {
    let mut v = [0u8; 8];
    v.copy_from_slice(&b[at..at + 8]);
    u64::from_le_bytes(v)
}
