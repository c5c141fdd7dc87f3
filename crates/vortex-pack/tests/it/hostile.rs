//! Any byte of a pack may be hostile. Every single-byte change is caught (by `Pack::open` or by
//! `verify`), every truncation and extension is refused by `open`, and packs tampered with
//! behind re-computed checksums give clean errors: never a panic, never a large allocation.
//! Headers that claim huge tiles or tile counts are refused by `open` with an error naming the
//! field and the [`Limits`] member, before anything is sized from them.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use proptest::prelude::*;
use vortex_pack::format;
use vortex_pack::fuzzing::at;
use vortex_pack::{Limits, Pack, PackError, Tile, TileId, VerifyOptions, verify};

use crate::common;

/// Records the largest single allocation of each thread, to catch allocations sized by counts
/// or lengths read from a file. Per thread because the other modules' tests run beside these
/// in the same process (each test has a thread of its own).
struct Peak;

thread_local! {
    // A const initialiser and no destructor: reading it never allocates.
    static PEAK: Cell<usize> = const { Cell::new(0) };
}

fn record(size: usize) {
    let _ = PEAK.try_with(|p| p.set(p.get().max(size)));
}

// SAFETY: every method forwards to the system allocator with the caller's arguments; recording
// a size allocates nothing.
#[expect(unsafe_code, reason = "a counting allocator forwarding to the system's")]
unsafe impl GlobalAlloc for Peak {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        record(layout.size());
        // SAFETY: forwarded as given.
        unsafe { System.alloc(layout) }
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        record(layout.size());
        // SAFETY: forwarded as given.
        unsafe { System.alloc_zeroed(layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        record(new_size);
        // SAFETY: forwarded as given.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: forwarded as given.
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static ALLOCATOR: Peak = Peak;

/// No allocation in these tests may come near this (the packs are a few KiB; decoding is
/// limited to `LIMIT`).
const MAX_ALLOCATION: usize = 8 << 20;
const LIMIT: u64 = 1 << 20;
const DECODE: VerifyOptions = VerifyOptions { decode: true };

struct Samples {
    _dir: tempfile::TempDir,
    packs: Vec<Vec<u8>>,
}

fn samples() -> &'static Samples {
    static SAMPLES: OnceLock<Samples> = OnceLock::new();
    SAMPLES.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap();
        let packs = common::sample_variants()
            .into_iter()
            .enumerate()
            .map(|(n, (channels, sample_bytes, options))| {
                let path = dir.path().join(format!("sample{n}.vtpk"));
                common::write_sample(&path, channels, sample_bytes, options);
                std::fs::read(&path).unwrap()
            })
            .collect();
        Samples { _dir: dir, packs }
    })
}

/// A file of its own for each case (tests run in parallel).
fn scratch(bytes: &[u8]) -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("case.vtpk");
    std::fs::write(&path, bytes).unwrap();
    (dir, path)
}

/// Opens `path` mapped, read into memory and from bytes given in memory: all must agree on
/// success (the first two are returned), and give the same bytes.
fn open_both(path: &Path) -> Option<(Pack, Pack)> {
    let limits = Limits { max_decoded_bytes: LIMIT, ..Limits::default() };
    let given = Pack::from_bytes_with_limits(path, std::fs::read(path).unwrap(), limits);
    match (Pack::open_with_limits(path, limits), Pack::open_read_with_limits(path, limits)) {
        (Ok(a), Ok(b)) => {
            assert_eq!(a.file(), b.file());
            assert_eq!(a.file(), given.expect("the file opens, the same bytes in memory do not").file());
            Some((a, b))
        }
        (Err(a), Err(b)) => {
            assert_eq!(a.to_string(), b.to_string());
            assert_eq!(a.to_string(), given.err().expect("the file fails, the same bytes in memory open").to_string());
            None
        }
        (a, b) => panic!("the backends disagree: {:?} / {:?}", a.err(), b.err()),
    }
}

/// Everything a reader can ask of a pack, on both backends; returns whether `verify` found a
/// problem.
fn exercise(mapped: &Pack, read: &Pack) -> bool {
    for id in mapped.ids().collect::<Vec<_>>() {
        let a = mapped.tile(id).map_err(|e| e.to_string());
        let b = read.tile(id).map_err(|e| e.to_string());
        assert_eq!(a, b);
        let checked = mapped.tile_checked(id);
        if let Ok(Tile::Data(_, bytes)) = a {
            assert!(bytes.len() as u64 <= mapped.header().data_len);
        }
        let decoded = mapped.decode_rgba8(id);
        if let Ok(Some(rgba)) = &decoded {
            let side = mapped.description().tile_size as usize;
            assert_eq!(rgba.len(), side * side * 4);
        }
        if checked.is_err() {
            assert!(decoded.is_err());
        }
    }
    let _ = mapped.ids_in_file_order();
    let report = verify(mapped, DECODE);
    assert_eq!(report, verify(read, DECODE));
    let _ = (report.to_string(), report.to_json());
    !report.is_ok()
}

fn check_allocations() {
    let peak = PEAK.with(Cell::get);
    assert!(peak < MAX_ALLOCATION, "an allocation of {peak} bytes");
}

#[test]
fn the_samples_are_clean() {
    for bytes in &samples().packs {
        let (_dir, path) = scratch(bytes);
        let (a, b) = open_both(&path).unwrap();
        assert!(!exercise(&a, &b));
    }
}

#[test]
fn every_truncation_is_refused() {
    for bytes in &samples().packs {
        let (_dir, path) = scratch(bytes);
        let file = std::fs::OpenOptions::new().write(true).open(&path).unwrap();
        for len in (0..bytes.len() as u64).rev() {
            file.set_len(len).unwrap();
            assert!(open_both(&path).is_none(), "a pack cut to {len} of {} bytes opens", bytes.len());
        }
    }
    check_allocations();
}

/// Exhaustively: each byte of each sample, changed, is caught by `open` or by `verify`
/// (structure and checksums alone, no decoding needed).
#[test]
fn every_byte_position_is_covered() {
    use std::os::unix::fs::FileExt;
    for (n, bytes) in samples().packs.iter().enumerate() {
        let (_dir, path) = scratch(bytes);
        let file = std::fs::OpenOptions::new().write(true).open(&path).unwrap();
        for at in 0..bytes.len() {
            file.write_all_at(&[bytes[at] ^ 0x80], at as u64).unwrap();
            if let Ok(pack) = Pack::open(&path) {
                assert!(!verify(&pack, VerifyOptions::default()).is_ok(), "byte {at} of pack {n} went unnoticed");
            }
            file.write_all_at(&bytes[at..at + 1], at as u64).unwrap();
        }
    }
    check_allocations();
}

/// 256 cases each unless `PROPTEST_CASES` says otherwise (for longer hunts).
fn config() -> ProptestConfig {
    let mut config = ProptestConfig { failure_persistence: None, ..ProptestConfig::default() };
    if std::env::var_os("PROPTEST_CASES").is_none() {
        config.cases = 256;
    }
    config
}

proptest! {
    #![proptest_config(config())]

    /// Any one byte changed, anywhere: `open` refuses the file or `verify` reports it.
    #[test]
    fn every_changed_byte_is_caught(pack in 0usize..3, at in any::<prop::sample::Index>(), flip in 1u8..=255) {
        let mut bytes = samples().packs[pack].clone();
        let at = at.index(bytes.len());
        bytes[at] ^= flip;
        let (_dir, path) = scratch(&bytes);
        if let Some((a, b)) = open_both(&path) {
            prop_assert!(exercise(&a, &b), "byte {at} ^ {flip:#x} of pack {pack} went unnoticed");
        }
        check_allocations();
    }

    /// Cut anywhere, or with bytes appended: `open` refuses it, even with the header's length
    /// fields made to agree (then `verify` or `open` still finds tiles or sections missing).
    #[test]
    fn truncated_or_extended_packs_are_refused(
        pack in 0usize..3,
        cut in any::<prop::sample::Index>(),
        extra in prop::collection::vec(any::<u8>(), 1..200),
        fix_lengths in any::<bool>(),
    ) {
        let full = &samples().packs[pack];
        let mut cut_bytes = full[..cut.index(full.len())].to_vec();
        let mut longer = [full.as_slice(), &extra].concat();
        if fix_lengths {
            for b in [&mut cut_bytes, &mut longer] {
                set_lengths(b);
            }
        }
        for (what, bytes) in [("cut", &cut_bytes), ("extended", &longer)] {
            let (_dir, path) = scratch(bytes);
            let opened = open_both(&path);
            if !fix_lengths {
                prop_assert!(opened.is_none(), "{what} to {} bytes, the pack opens", bytes.len());
            } else if let Some((a, b)) = opened {
                // Lengths that agree with the file make a pack that claims less data (payloads
                // cut off) or more padding (which must be zero).
                let noticed = exercise(&a, &b);
                if what == "cut" || extra.iter().any(|b| *b != 0) {
                    prop_assert!(noticed, "{what} to {} bytes with lengths fixed, nothing noticed", bytes.len());
                }
            }
        }
        check_allocations();
    }

    /// Header, level table, index or metadata changed and every checksum recomputed: whatever
    /// the fields say, reading and verifying fail cleanly.
    #[test]
    fn resealed_structure_changes_fail_cleanly(
        pack in 0usize..3,
        changes in prop::collection::vec((any::<bool>(), any::<prop::sample::Index>(), any::<u8>(), 0u8..4), 1..4),
    ) {
        let mut bytes = samples().packs[pack].clone();
        let meta_end = u64::from_le_bytes(bytes[112..120].try_into().unwrap()) as usize
            + u32::from_le_bytes(bytes[120..124].try_into().unwrap()) as usize;
        for (in_header, at, value, how) in changes {
            // Half in the header's fields, half in the level table, index and metadata.
            let at = if in_header { at.index(188) } else { 192 + at.index(meta_end - 192) };
            bytes[at] = match how {
                0 => value,
                1 => bytes[at] ^ (1 << (value % 8)),
                2 => 0xFF,
                _ => bytes[at].wrapping_add(1),
            };
        }
        common::reseal(&mut bytes);
        let (_dir, path) = scratch(&bytes);
        if let Some((a, b)) = open_both(&path) {
            exercise(&a, &b);
        }
        check_allocations();
    }

    /// Payload bytes changed with checksums fixed: the decoders see hostile input.
    #[test]
    fn resealed_payload_changes_fail_cleanly(
        pack in 0usize..3,
        which in any::<prop::sample::Index>(),
        changes in prop::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..8),
    ) {
        let mut bytes = samples().packs[pack].clone();
        let payloads = common::payload_entries(&bytes);
        let (_, start, len) = payloads[which.index(payloads.len())];
        let (start, len) = (start as usize, len as usize);
        for (at, value) in changes {
            bytes[start + at.index(len)] = value;
        }
        let crc = crc32c::crc32c(&bytes[start..start + len]);
        common::set_payload_crc(&mut bytes, start as u64, crc);
        common::reseal(&mut bytes);
        let (_dir, path) = scratch(&bytes);
        let (a, b) = open_both(&path).expect("only payload bytes changed");
        exercise(&a, &b);
        check_allocations();
    }
}

/// Makes the header's file and data lengths agree with `b`'s length (where they can).
fn set_lengths(b: &mut [u8]) {
    if b.len() < 192 {
        return;
    }
    let len = b.len() as u64;
    let data_offset = u64::from_le_bytes(b[128..136].try_into().unwrap());
    b[32..40].copy_from_slice(&len.to_le_bytes());
    b[136..144].copy_from_slice(&len.saturating_sub(data_offset).to_le_bytes());
    common::reseal(b);
}

/// A sample pack with `change` applied to its bytes and every checksum recomputed.
fn tampered(change: impl FnOnce(&mut Vec<u8>)) -> Vec<u8> {
    let mut bytes = samples().packs[0].clone();
    change(&mut bytes);
    common::reseal(&mut bytes);
    bytes
}

/// `bytes` must be refused by every backend with `LimitExceeded` naming `field` and `cap`.
fn assert_over_limit(bytes: Vec<u8>, field: &str, cap: &str) {
    let (_dir, path) = scratch(&bytes);
    assert!(open_both(&path).is_none());
    for e in [Pack::open(&path).err(), Pack::from_bytes("hostile.vtpk", bytes).err()] {
        let e = e.expect("a pack claiming too much opens");
        let text = e.to_string();
        match &e {
            PackError::LimitExceeded { field: f, cap: c, .. } => {
                assert!(f.contains(field), "{text}");
                assert_eq!(*c, cap, "{text}");
            }
            other => panic!("not a limit error: {other}"),
        }
        assert!(text.contains(field) && text.contains(&format!("Limits::{cap}")), "{text}");
    }
    check_allocations();
}

fn put_u32(b: &mut [u8], at: usize, v: u32) {
    b[at..at + 4].copy_from_slice(&v.to_le_bytes());
}

fn put_u64(b: &mut [u8], at: usize, v: u64) {
    b[at..at + 8].copy_from_slice(&v.to_le_bytes());
}

/// `unpack` of a pack whose header said `tile_size` 2^31 died of `capacity overflow`.
#[test]
fn a_huge_tile_size_is_refused_naming_the_field() {
    for side in [1u32 << 31, u32::MAX, 16385] {
        let bytes = tampered(|b| put_u32(b, at::TILE_SIZE, side));
        assert_over_limit(bytes, "tile_size", "max_tile_size");
    }
    // The cap can be raised; then the claim is checked against the rest of the file as before.
    let bytes = tampered(|b| put_u32(b, at::TILE_SIZE, 1 << 31));
    let raised = Limits { max_tile_size: u32::MAX, ..Limits::default() };
    if let Ok(pack) = Pack::from_bytes_with_limits("raised.vtpk", bytes, raised) {
        assert!(!verify(&pack, VerifyOptions::default()).is_ok());
        assert!(pack.decode_rgba8(TileId { lod: 0, x: 1, y: 0 }).is_err());
    }
    check_allocations();
}

/// An index of 2^40 entries (24 TiB) claimed in the header.
#[test]
fn a_huge_index_count_is_refused_naming_the_field() {
    for count in [1u64 << 40, u64::MAX, Limits::default().max_tiles + 1] {
        let bytes = tampered(|b| put_u64(b, at::INDEX_COUNT, count));
        assert_over_limit(bytes, "index_count", "max_tiles");
    }
}

/// A level table whose levels hold 2^32 x 2^32 tiles, the index count left alone.
#[test]
fn a_huge_level_table_is_refused_naming_the_level() {
    for (lod, w, h) in [(0usize, u32::MAX, u32::MAX), (1, 1 << 20, 1 << 20), (2, 1 << 15, 1 << 15)] {
        let bytes = tampered(|b| {
            let row = u64::from_le_bytes(b[at::LEVELS_OFFSET..at::LEVELS_OFFSET + 8].try_into().unwrap()) as usize
                + lod * format::LEVEL_LEN;
            put_u32(b, row, w);
            put_u32(b, row + 4, h);
        });
        assert_over_limit(bytes, &format!("level {lod}: {w}x{h}"), "max_tiles");
    }
}

/// Tighter caps refuse a pack that the defaults accept; the sample has 21 tiles of 8 texels.
#[test]
fn limits_below_the_pack_refuse_it() {
    let bytes = samples().packs[0].clone();
    let tight = |limits: Limits| Pack::from_bytes_with_limits("tight.vtpk", bytes.clone(), limits).err();
    let e = tight(Limits { max_tiles: 20, ..Limits::default() }).expect("21 tiles opened under a cap of 20");
    assert!(e.to_string().contains("index_count (byte 96) is 21, over the limit of 20"), "{e}");
    let e = tight(Limits { max_tile_size: 7, ..Limits::default() }).expect("8-texel tiles opened under a cap of 7");
    assert!(e.to_string().contains("tile_size (byte 56) is 8"), "{e}");
    assert!(tight(Limits { max_tiles: 21, max_tile_size: 8, ..Limits::default() }).is_none());
    // A decoding cap below one tile refuses each tile, not the pack.
    let small = Limits { max_decoded_bytes: 255, ..Limits::default() };
    let pack = Pack::from_bytes_with_limits("small.vtpk", bytes.clone(), small).unwrap();
    let report = verify(&pack, DECODE);
    assert!(report.problems.iter().any(|p| p.message.contains("decoding limit of 255 bytes")), "{report}");
}
