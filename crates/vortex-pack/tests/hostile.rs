//! Any byte of a pack may be hostile. Every single-byte change is caught (by `Pack::open` or by
//! `verify`), every truncation and extension is refused by `open`, and packs tampered with
//! behind re-computed checksums give clean errors: never a panic, never a large allocation.

mod common;

use std::alloc::{GlobalAlloc, Layout, System};
use std::path::{Path, PathBuf};
use std::sync::OnceLock;
use std::sync::atomic::{AtomicUsize, Ordering};

use proptest::prelude::*;
use vortex_pack::{Pack, Tile, VerifyOptions, decode_rgba8_limited, verify};

/// Records the largest single allocation of the process, to catch allocations sized by counts
/// or lengths read from a file.
struct Peak;

static PEAK: AtomicUsize = AtomicUsize::new(0);

unsafe impl GlobalAlloc for Peak {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        PEAK.fetch_max(layout.size(), Ordering::Relaxed);
        // SAFETY: forwarded as given.
        unsafe { System.alloc(layout) }
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        PEAK.fetch_max(layout.size(), Ordering::Relaxed);
        // SAFETY: forwarded as given.
        unsafe { System.alloc_zeroed(layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        PEAK.fetch_max(new_size, Ordering::Relaxed);
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
const DECODE: VerifyOptions = VerifyOptions { decode: true, max_decoded_bytes: LIMIT };

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

/// Opens `path` both ways: both must agree on success, and give the same bytes.
fn open_both(path: &Path) -> Option<(Pack, Pack)> {
    match (Pack::open(path), Pack::open_read(path)) {
        (Ok(a), Ok(b)) => {
            assert_eq!(a.file(), b.file());
            Some((a, b))
        }
        (Err(a), Err(b)) => {
            assert_eq!(a.to_string(), b.to_string());
            None
        }
        (a, b) => panic!("the backends disagree: {:?} / {:?}", a.err(), b.err()),
    }
}

/// Everything a reader can ask of a pack, on both backends; returns whether `verify` found a
/// problem.
fn exercise(mapped: &Pack, read: &Pack) -> bool {
    for id in mapped.ids().collect::<Vec<_>>() {
        let a = mapped.tile(id.lod, id.x, id.y).map_err(|e| e.to_string());
        let b = read.tile(id.lod, id.x, id.y).map_err(|e| e.to_string());
        assert_eq!(a, b);
        let checked = mapped.tile_checked(id.lod, id.x, id.y);
        if let Ok(Tile::Data(_, bytes)) = a {
            assert!(bytes.len() as u64 <= mapped.header().data_len);
        }
        let decoded = decode_rgba8_limited(mapped, id.lod, id.x, id.y, LIMIT);
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
    let peak = PEAK.load(Ordering::Relaxed);
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
