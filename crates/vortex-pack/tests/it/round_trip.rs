//! Packs written with `PackWriter` read back identically through both backends, verify clean,
//! decode to RGBA8; and `verify` finds each kind of problem planted in a pack.

use std::collections::HashMap;
use std::path::Path;

use vortex_pack::fuzzing::at;
use vortex_pack::{
    Limits, NewTile, Pack, PackError, PackWriter, Tile, TileId, TileKind, VerifyOptions, WriteOptions, verify,
};

use crate::common::{self, Written, reseal, write_sample};

const DECODE: VerifyOptions = VerifyOptions { decode: true };

fn as_written(tile: Tile<'_>) -> Written {
    match tile {
        Tile::Absent => Written::Absent,
        Tile::Constant(v) => Written::Constant(v.to_vec()),
        Tile::Data(kind, bytes) => Written::Data(kind, bytes.to_vec()),
    }
}

#[test]
fn every_kind_round_trips_through_both_backends() {
    let dir = tempfile::tempdir().unwrap();
    for (n, (channels, sample_bytes, options)) in common::sample_variants().into_iter().enumerate() {
        let path = dir.path().join(format!("sample{n}.vtpk"));
        let sample = write_sample(&path, channels, sample_bytes, options);
        let mapped = Pack::open(&path).unwrap();
        let read = Pack::open_read(&path).unwrap();
        assert_eq!(mapped.file(), read.file());
        assert_eq!(mapped.file(), std::fs::read(&path).unwrap());
        assert_eq!(mapped.header(), read.header());
        assert_eq!(mapped.levels(), read.levels());
        assert_eq!(mapped.metadata(), read.metadata());
        assert_eq!(mapped.header().payload_alignment, options.payload_alignment);
        assert_eq!(mapped.description(), &sample.description);
        assert_eq!(mapped.ids().count(), sample.tiles.len());

        let mut offsets: HashMap<Vec<u8>, u64> = HashMap::new();
        for (id, written) in &sample.tiles {
            let a = mapped.tile_checked(*id).unwrap();
            let b = read.tile_checked(*id).unwrap();
            assert_eq!(a, b);
            let expected = if *written == Written::Skipped { Written::Absent } else { written.clone() };
            assert_eq!(as_written(a), expected, "{id:?}");
            // Identical payloads are stored once: every copy points at one offset.
            if let Written::Data(_, bytes) = written {
                let offset = mapped.entry(mapped.position(*id).unwrap()).offset_or_value;
                assert_eq!(*offsets.entry(bytes.clone()).or_insert(offset), offset, "{id:?}");
                assert_eq!(offset % options.payload_alignment as u64, 0);
            }
        }
        let payload_tiles = sample.tiles.iter().filter(|(_, w)| matches!(w, Written::Data(..))).count() as u64;
        assert_eq!(sample.summary.stored_payloads, offsets.len() as u64);
        assert_eq!(sample.summary.deduplicated, payload_tiles - offsets.len() as u64);
        assert!(sample.summary.deduplicated >= 2);
        assert_eq!(sample.summary.payload_bytes, offsets.keys().map(|k| k.len() as u64).sum::<u64>());
        assert_eq!(sample.summary.file_bytes, mapped.file().len() as u64);
        assert_eq!(sample.summary.content_hash, mapped.header().content_hash);

        // File order lists every payload tile, offsets ascending.
        let order = mapped.ids_in_file_order();
        assert_eq!(order.len() as u64, payload_tiles);
        assert!(order.windows(2).all(|w| w[0].1.offset_or_value <= w[1].1.offset_or_value));

        for pack in [&mapped, &read] {
            let report = verify(pack, DECODE);
            assert!(report.is_ok(), "{report}");
            assert_eq!(report.tiles, sample.tiles.len() as u64);
            assert_eq!(report.stored_payloads, sample.summary.stored_payloads);
            assert_eq!(report.shared_payloads, sample.summary.deduplicated);
            assert_eq!(report.payload_bytes, sample.summary.payload_bytes);
            assert_eq!(report.count(TileKind::Constant), sample.summary.constant);
            assert_eq!(report.count(TileKind::Absent), sample.summary.absent);
            assert_eq!(report.decoded_payloads, sample.summary.stored_payloads);
            // Every byte is accounted for.
            let h = pack.header();
            let tables = h.levels_offset - 192
                + (h.index_offset - h.levels_offset)
                + (h.meta_offset - h.index_offset)
                + h.meta_len as u64;
            assert_eq!(192 + tables + report.payload_bytes + report.padding_bytes, report.file_bytes);
            assert!(report.to_string().contains("OK: no problem found"));
            assert!(report.to_json().contains("\"ok\":true"));
        }
    }
}

#[test]
fn tiles_decode_to_rgba8() {
    let dir = tempfile::tempdir().unwrap();
    for (channels, sample_bytes) in [(3u8, 1u8), (2, 2)] {
        let path = dir.path().join(format!("decode{channels}.vtpk"));
        let sample = write_sample(&path, channels, sample_bytes, WriteOptions::default());
        let pack = Pack::open(&path).unwrap();
        let d = sample.description;
        let texels = (d.tile_size * d.tile_size) as usize;
        let expand = |raw: &[u8]| -> Vec<u8> {
            let s = |t: &[u8], i: usize| {
                if sample_bytes == 1 {
                    t[i]
                } else {
                    ((u16::from_le_bytes([t[2 * i], t[2 * i + 1]]) as u32 + 128) / 257) as u8
                }
            };
            raw.chunks_exact(channels as usize * sample_bytes as usize)
                .flat_map(|t| match channels {
                    2 => [s(t, 0), s(t, 0), s(t, 0), s(t, 1)],
                    _ => [s(t, 0), s(t, 1), s(t, 2), 255],
                })
                .collect()
        };
        for (i, (id, written)) in sample.tiles.iter().enumerate() {
            let rgba = pack.decode_rgba8(*id).unwrap();
            match written {
                Written::Absent | Written::Skipped => assert_eq!(rgba, None),
                Written::Constant(v) => assert_eq!(rgba.unwrap(), expand(v).repeat(texels)),
                Written::Data(TileKind::Raw, bytes) => assert_eq!(rgba.unwrap(), expand(bytes)),
                Written::Data(TileKind::Zstd, bytes) => {
                    assert_eq!(rgba.unwrap(), expand(&zstd::bulk::decompress(bytes, 1 << 20).unwrap()))
                }
                Written::Data(TileKind::Png, _) => {
                    assert_eq!(rgba.unwrap(), common::png_tile(&d, i as u32, sample_bytes == 2).1)
                }
                Written::Data(TileKind::Jpeg, _) => {
                    let rgba = rgba.unwrap();
                    assert_eq!(rgba.len(), texels * 4);
                    assert!(rgba.chunks_exact(4).all(|p| p[3] == 255));
                }
                other => panic!("unexpected {other:?}"),
            }
        }
        // A limit below one tile is refused before decoding.
        let (id, _) = sample.tiles.iter().find(|(_, w)| matches!(w, Written::Data(TileKind::Png, _))).unwrap();
        let tight = Pack::open_with_limits(&path, Limits { max_decoded_bytes: 100, ..Limits::default() }).unwrap();
        let err = tight.decode_rgba8(*id).unwrap_err();
        assert!(matches!(err, PackError::Tile { .. }), "{err}");
        assert!(pack.decode_rgba8(TileId { lod: 9, x: 0, y: 0 }).is_err());
    }
}

#[test]
fn empty_and_absent_packs_verify() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("empty.vtpk");
    let d = common::description(4, 1);
    let w = PackWriter::create(&path, d, vortex_pack::fuzzing::pyramid_levels(&d, 4), b"", WriteOptions::default())
        .unwrap();
    let summary = w.finish().unwrap();
    assert_eq!(summary.absent, 21);
    let pack = Pack::open(&path).unwrap();
    assert_eq!(pack.header().data_len, 0);
    let report = verify(&pack, DECODE);
    assert!(report.is_ok(), "{report}");
    assert_eq!(report.count(TileKind::Absent), 21);
    assert_eq!(pack.tile(vortex_pack::TileId::new(2, 0, 0)).unwrap(), Tile::Absent);
}

#[test]
fn writer_refuses_misuse_and_leaves_no_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bad.vtpk");
    let d = common::description(3, 1);
    let levels = vortex_pack::fuzzing::pyramid_levels(&d, 4);
    let mut w = PackWriter::create(&path, d, levels.clone(), b"{}", WriteOptions::default()).unwrap();
    let id = TileId { lod: 0, x: 0, y: 0 };
    assert!(w.add(id, NewTile::Data(TileKind::Raw, &[1, 2, 3])).is_err());
    assert!(w.add(id, NewTile::Data(TileKind::Png, &[])).is_err());
    assert!(w.add(id, NewTile::Constant(&[1, 2])).is_err());
    assert!(w.add(TileId { lod: 3, x: 0, y: 0 }, NewTile::Absent).is_err());
    w.add(id, NewTile::Absent).unwrap();
    assert!(w.add(id, NewTile::Absent).is_err(), "written twice");
    drop(w);
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0, "the temporary file is removed");

    // Texel formats and geometry the reader would refuse.
    for bad in [
        vortex_pack::Description { channels: 5, sample_bytes: 2, sample_format: 0, ..d },
        vortex_pack::Description { sample_bytes: 3, sample_format: 0, ..d },
        vortex_pack::Description { border: 4, ..d },
        vortex_pack::Description { width: 0, ..d },
    ] {
        assert!(PackWriter::create(&path, bad, levels.clone(), b"", WriteOptions::default()).is_err());
    }
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
}

/// A 16000000 x 1 image as a square pyramid used to abort allocating 549 GB of index entries;
/// what a default reader would refuse is refused before anything is allocated or created.
#[test]
fn writer_refuses_what_readers_would_refuse_before_allocating() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("huge.vtpk");
    let d = vortex_pack::Description {
        width: 16_000_000,
        height: 1,
        tile_size: 256,
        border: 0,
        level_count: 17,
        channels: 3,
        sample_bytes: 1,
        sample_format: 0,
    };
    let levels = vortex_pack::fuzzing::pyramid_levels(&d, 1 << 16);
    let e = PackWriter::create(&path, d, levels, b"", WriteOptions::default()).err().unwrap();
    assert!(matches!(&e, PackError::LimitExceeded { cap: "max_tiles", .. }), "{e}");
    assert!(e.to_string().contains("index_count (byte 96) is 5726623061, over the limit of 536870912"), "{e}");

    let d = vortex_pack::Description { tile_size: 1 << 15, level_count: 1, ..common::description(3, 1) };
    let levels = vortex_pack::fuzzing::pyramid_levels(&d, 1);
    let e = PackWriter::create(&path, d, levels, b"", WriteOptions::default()).err().unwrap();
    assert!(
        e.to_string().contains("tile_size (byte 56) is 32768, over the limit of 16384 (Limits::max_tile_size)"),
        "{e}"
    );
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0, "nothing is created");
}

/// Writes `bytes` to a file and opens it.
fn open_bytes(dir: &Path, bytes: &[u8]) -> Pack {
    let path = dir.join("planted.vtpk");
    std::fs::write(&path, bytes).unwrap();
    Pack::open(&path).unwrap()
}

/// The sample pack (page-aligned data, 8-byte payloads) and its tiles.
fn sample_bytes(dir: &Path) -> (Vec<u8>, common::Sample) {
    let path = dir.join("sample.vtpk");
    let sample = write_sample(&path, 3, 1, WriteOptions::default());
    (std::fs::read(&path).unwrap(), sample)
}

fn entry_at(b: &[u8], position: usize) -> usize {
    u64::from_le_bytes(b[at::INDEX_OFFSET..at::INDEX_OFFSET + 8].try_into().unwrap()) as usize + position * 24
}

fn position_of(sample: &common::Sample, pred: impl Fn(&Written) -> bool) -> (usize, TileId) {
    let (i, (id, _)) = sample.tiles.iter().enumerate().find(|(_, (_, w))| pred(w)).unwrap();
    (i, *id)
}

#[test]
fn verify_reports_every_planted_problem_with_offsets_and_tiles() {
    let dir = tempfile::tempdir().unwrap();
    let (clean, sample) = sample_bytes(dir.path());
    let d = sample.description;
    let payloads = common::payload_entries(&clean);
    let data_offset = u64::from_le_bytes(clean[at::DATA_OFFSET..at::DATA_OFFSET + 8].try_into().unwrap());
    let covered = |i: usize| payloads.iter().any(|(_, s, l)| (*s as usize..(*s + *l) as usize).contains(&i));
    let tiles_of = |pred: &dyn Fn(&Written) -> bool| -> Vec<(usize, TileId)> {
        sample.tiles.iter().enumerate().filter(|(_, (_, w))| pred(w)).map(|(i, (id, _))| (i, *id)).collect()
    };

    let mut b = clean.clone();
    // 1. An absent entry with a stray length byte.
    let (absent, absent_id) = position_of(&sample, |w| *w == Written::Absent);
    b[entry_at(&clean, absent) + 9] = 1;
    // 2. A constant entry with a byte past its 3-byte value.
    let (constant, constant_id) = position_of(&sample, |w| matches!(w, Written::Constant(_)));
    b[entry_at(&clean, constant) + 5] = 7;
    // 3. A reserved entry byte, and 4. an unknown kind.
    let skipped = tiles_of(&|w| *w == Written::Skipped);
    b[entry_at(&clean, skipped[0].0) + 20] = 1;
    b[entry_at(&clean, skipped[1].0) + 16] = 99;
    // 5. A byte of the JPEG payload that several tiles share: each of them is reported.
    let jpegs = tiles_of(&|w| matches!(w, Written::Data(TileKind::Jpeg, _)));
    assert!(jpegs.len() >= 2);
    let e = entry_at(&clean, jpegs[0].0);
    let jpeg_start = u64::from_le_bytes(b[e..e + 8].try_into().unwrap());
    b[jpeg_start as usize + 100] ^= 0x40;
    // 6. A byte of padding before the data section, and one between payloads.
    b[data_offset as usize - 1] = 0xEE;
    let gap = (data_offset as usize..b.len()).find(|i| !covered(*i)).expect("a gap between payloads");
    b[gap] = 1;
    // 7. A PNG entry pointing into the middle of a raw payload: a partial overlap, misaligned.
    let (raw, raw_id) = position_of(&sample, |w| matches!(w, Written::Data(TileKind::Raw, _)));
    let e = entry_at(&clean, raw);
    let raw_start = u64::from_le_bytes(b[e..e + 8].try_into().unwrap());
    let (png, png_id) = position_of(&sample, |w| matches!(w, Written::Data(TileKind::Png, _)));
    let e = entry_at(&clean, png);
    b[e..e + 8].copy_from_slice(&(raw_start + 3).to_le_bytes());
    // 8. A zstd entry relabelled raw: the wrong size for a raw tile.
    let (zstd, zstd_id) = position_of(&sample, |w| matches!(w, Written::Data(TileKind::Zstd, _)));
    b[entry_at(&clean, zstd) + 16] = TileKind::Raw as u8;
    reseal(&mut b);

    let pack = open_bytes(dir.path(), &b);
    let report = verify(&pack, DECODE);
    let found = |section: &str, tile: TileId, text: &str| {
        report.problems.iter().any(|p| p.section == section && p.tile == Some(tile) && p.message.contains(text))
    };
    assert!(found("index", absent_id, "absent entry"), "{report}");
    assert!(found("index", constant_id, "constant value"), "{report}");
    assert!(found("index", skipped[0].1, "reserved"), "{report}");
    assert!(found("index", skipped[1].1, "unknown tile kind 99"), "{report}");
    for (_, id) in &jpegs {
        assert!(found("data", *id, "checksum mismatch"), "{id:?}: {report}");
    }
    assert!(report.problems.iter().any(|p| p.section == "padding" && p.offset == Some(data_offset - 1)), "{report}");
    assert!(report.problems.iter().any(|p| p.section == "padding" && p.offset == Some(gap as u64)), "{report}");
    assert!(found("data", png_id, "overlaps"), "{report}");
    assert!(found("index", png_id, "not aligned"), "{report}");
    assert!(found("index", zstd_id, &format!("a raw tile is {} bytes", d.raw_tile_len().unwrap())), "{report}");
    assert!(!report.problems.iter().any(|p| p.tile == Some(raw_id)), "the raw tile itself is fine: {report}");
    // Problems are in file order, each with an offset.
    assert!(report.problems.iter().all(|p| p.offset.is_some()));
    assert!(report.problems.windows(2).all(|w| w[0].offset <= w[1].offset));

    // The same, as JSON.
    let json: serde_json::Value = serde_json::from_str(&report.to_json()).unwrap();
    assert_eq!(json["ok"], false);
    assert_eq!(json["problems"].as_array().unwrap().len(), report.problems.len());
    assert_eq!(json["kinds"]["unknown"], 1);
    assert_eq!(json["path"], pack.path().to_str().unwrap());
    let p = &json["problems"][0];
    assert!(p["offset"].is_u64() && p["section"].is_string() && p["message"].is_string());
    let text = report.to_string();
    assert!(text.contains(&format!("{} problems:", report.problems.len())), "{text}");
    assert!(text.contains(&format!("tile (lod {}, x {}, y {})", png_id.lod, png_id.x, png_id.y)), "{text}");
}

#[test]
fn verify_decodes_every_payload_when_asked() {
    let dir = tempfile::tempdir().unwrap();
    let (clean, sample) = sample_bytes(dir.path());
    let d = sample.description;

    // A PNG tile relabelled JPEG, a JPEG tile relabelled PNG, and a zstd frame of the wrong
    // size (a valid frame of 10 bytes, its length and checksum fixed up).
    let mut b = clean.clone();
    let (png, png_id) = position_of(&sample, |w| matches!(w, Written::Data(TileKind::Png, _)));
    b[entry_at(&clean, png) + 16] = TileKind::Jpeg as u8;
    let (zstd, zstd_id) = position_of(&sample, |w| matches!(w, Written::Data(TileKind::Zstd, _)));
    let e = entry_at(&clean, zstd);
    let start = u64::from_le_bytes(b[e..e + 8].try_into().unwrap()) as usize;
    let len = u32::from_le_bytes(b[e + 8..e + 12].try_into().unwrap()) as usize;
    let short = zstd::bulk::compress(&[5u8; 10], 3).unwrap();
    assert!(short.len() < len);
    b[start..start + len].fill(0);
    b[start..start + short.len()].copy_from_slice(&short);
    b[e + 8..e + 12].copy_from_slice(&(short.len() as u32).to_le_bytes());
    b[e + 12..e + 16].copy_from_slice(&crc32c::crc32c(&short).to_le_bytes());
    reseal(&mut b);
    let pack = open_bytes(dir.path(), &b);

    // Structure alone: only the zstd frame header gives the size away.
    let report = verify(&pack, VerifyOptions::default());
    assert_eq!(report.problems.len(), 1, "{report}");
    assert_eq!(report.problems[0].tile, Some(zstd_id));
    assert!(report.problems[0].message.contains("zstd frame holds 10 bytes"), "{report}");
    assert_eq!(report.decoded_payloads, 0);

    let report = verify(&pack, DECODE);
    assert!(report.decoded_payloads > 0);
    let bad: Vec<_> = report.problems.iter().filter(|p| p.message.contains("does not decode")).collect();
    assert!(bad.iter().any(|p| p.tile == Some(png_id) && p.message.starts_with("jpeg")), "{report}");
    assert!(bad.iter().any(|p| p.tile == Some(zstd_id) && p.message.starts_with("zstd")), "{report}");
    assert!(report.problems.iter().all(|p| p.tile.is_some()));
    assert!(pack.decode_rgba8(png_id).is_err());
    assert!(pack.decode_rgba8(zstd_id).is_err());

    // A limit below one tile: every decodable payload is refused, none is decoded.
    let limits = Limits { max_decoded_bytes: d.raw_tile_len().unwrap() - 1, ..Limits::default() };
    let pack = Pack::from_bytes_with_limits(pack.path(), pack.file().to_vec(), limits).unwrap();
    let report = verify(&pack, VerifyOptions { decode: true });
    assert!(report.problems.iter().filter(|p| p.message.contains("decoding limit")).count() >= 3, "{report}");
}

#[test]
fn verify_reports_a_gap_between_sections() {
    let dir = tempfile::tempdir().unwrap();
    let (clean, _) = sample_bytes(dir.path());
    let field = |b: &[u8], at: usize| u64::from_le_bytes(b[at..at + 8].try_into().unwrap()) as usize;
    let (meta_at, meta_len) = (field(&clean, at::META_OFFSET), field(&clean, at::META_LEN) & 0xFFFF_FFFF);
    // The metadata moved 8 bytes on into the zero padding before the data section.
    let mut b = clean.clone();
    b[meta_at..meta_at + 8 + meta_len].fill(0);
    b[meta_at + 8..meta_at + 8 + meta_len].copy_from_slice(&clean[meta_at..meta_at + meta_len]);
    b[at::META_OFFSET..at::META_OFFSET + 8].copy_from_slice(&(meta_at as u64 + 8).to_le_bytes());
    reseal(&mut b);
    let pack = open_bytes(dir.path(), &b);
    assert_eq!(pack.metadata(), &clean[meta_at..meta_at + meta_len]);
    let report = verify(&pack, VerifyOptions::default());
    assert_eq!(report.problems.len(), 1, "{report}");
    assert_eq!(report.problems[0].offset, Some(at::META_OFFSET as u64));
    assert!(report.problems[0].message.contains("must follow"), "{report}");
    // The gap itself is zero padding, and counted.
    let clean_report = verify(&Pack::open(dir.path().join("sample.vtpk")).unwrap(), VerifyOptions::default());
    assert_eq!(report.padding_bytes, clean_report.padding_bytes);
}

/// JPEG as encoders write it: progressive, restart markers, 4:2:0, greyscale; a 16x16 tile.
#[test]
fn jpeg_variants_decode() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("jpeg.vtpk");
    let d = vortex_pack::Description {
        width: 16,
        height: 16,
        tile_size: 16,
        border: 0,
        level_count: 1,
        channels: 3,
        sample_bytes: 1,
        sample_format: 0,
    };
    let rgb: Vec<u8> = (0..16 * 16).flat_map(|i| [200u8, 100, (i % 16 * 10) as u8]).collect();
    let grey: Vec<u8> = vec![77; 16 * 16];
    let encode = |progressive: bool, restart: u16, subsample: bool, luma: bool| {
        let mut out = Vec::new();
        let mut enc = jpeg_encoder::Encoder::new(&mut out, 95);
        enc.set_progressive(progressive);
        enc.set_restart_interval(restart);
        if subsample {
            enc.set_sampling_factor(jpeg_encoder::SamplingFactor::F_2_2);
        }
        let (data, color) =
            if luma { (&grey, jpeg_encoder::ColorType::Luma) } else { (&rgb, jpeg_encoder::ColorType::Rgb) };
        enc.encode(data, 16, 16, color).unwrap();
        out
    };
    let variants = [
        (false, 0, false, false),
        (true, 0, false, false),
        (false, 1, true, false),
        (true, 2, true, false),
        (false, 0, false, true),
        (true, 1, false, true),
    ];
    let tiles: Vec<Vec<u8>> = variants.iter().map(|v| encode(v.0, v.1, v.2, v.3)).collect();
    let levels = vec![vortex_pack::Level { tiles_w: 3, tiles_h: 2, first_entry: 0, width: 16, height: 16 }];
    let mut w = PackWriter::create(&path, d, levels, b"{}", WriteOptions::default()).unwrap();
    for (i, t) in tiles.iter().enumerate() {
        w.add(TileId { lod: 0, x: i as u32 % 3, y: i as u32 / 3 }, NewTile::Data(TileKind::Jpeg, t)).unwrap();
    }
    w.finish().unwrap();
    let pack = Pack::open(&path).unwrap();
    let report = verify(&pack, DECODE);
    assert!(report.is_ok(), "{report}");
    assert_eq!(report.decoded_payloads, 6);
    for (i, v) in variants.iter().enumerate() {
        let rgba = pack.decode_rgba8(TileId { lod: 0, x: i as u32 % 3, y: i as u32 / 3 }).unwrap().unwrap();
        assert_eq!(rgba.len(), 16 * 16 * 4);
        let expected: Vec<u8> = if v.3 {
            (0..256).flat_map(|_| [77, 77, 77, 255]).collect()
        } else {
            rgb.chunks_exact(3).flat_map(|p| [p[0], p[1], p[2], 255]).collect()
        };
        let worst = rgba.iter().zip(&expected).map(|(a, b)| a.abs_diff(*b)).max().unwrap();
        assert!(worst <= 24, "variant {v:?}: off by {worst}");
    }
}

/// Metadata learnt while writing (a shard's sums) replaces a longer placeholder: the data
/// section moves down over the unused room, offsets stay aligned, and the pack verifies.
#[test]
fn shorter_metadata_set_at_the_end_gives_back_its_room() {
    let dir = tempfile::tempdir().unwrap();
    let d = common::description(4, 1);
    let levels = vortex_pack::fuzzing::pyramid_levels(&d, 4);
    let write = |name: &str, room: usize, meta: &[u8], options: WriteOptions| {
        let path = dir.path().join(name);
        let mut w = PackWriter::create(&path, d, levels.clone(), &vec![b' '; room], options).unwrap();
        for x in 0..4u32 {
            w.add(TileId { lod: 0, x, y: 0 }, NewTile::Data(TileKind::Raw, &common::raw_tile(&d, x))).unwrap();
        }
        w.add(TileId { lod: 0, x: 0, y: 1 }, NewTile::Data(TileKind::Raw, &common::raw_tile(&d, 0))).unwrap();
        w.set_metadata(meta.to_vec()).unwrap();
        w.finish().unwrap();
        std::fs::read(path).unwrap()
    };
    let tight = write("tight.vtpk", 7, b"{\"a\":1}", WriteOptions::default());
    let roomy = write("roomy.vtpk", 3 << 20, b"{\"a\":1}", WriteOptions::default());
    assert!(tight == roomy, "the room is given back whole");
    let sparse = WriteOptions { alignment: 4096, payload_alignment: 65536 };
    // Moved in whole units of the larger alignment: at most one unit more than a tight pack.
    let (roomy, tight) = (write("aligned.vtpk", 200_000, b"{}", sparse), write("aligned-tight.vtpk", 2, b"{}", sparse));
    assert!(roomy.len() < tight.len() + 65536, "{} against {}", roomy.len(), tight.len());
    let pack = Pack::open(dir.path().join("aligned.vtpk")).unwrap();
    for (_, e) in pack.ids_in_file_order() {
        assert!(e.len == 0 || e.offset_or_value.is_multiple_of(65536), "{e:?}");
    }
    assert!(verify(&pack, DECODE).is_ok());
    assert_eq!(pack.metadata(), b"{}");
    assert_eq!(
        pack.tile(vortex_pack::TileId::new(0, 3, 0)).unwrap(),
        Tile::Data(TileKind::Raw, &common::raw_tile(&d, 3))
    );

    let mut w =
        PackWriter::create(dir.path().join("x.vtpk"), d, levels.clone(), b"{}", WriteOptions::default()).unwrap();
    assert!(matches!(w.set_metadata(b"{\"longer\":1}".to_vec()), Err(PackError::Usage(_))));
}

/// A writer killed half-way (its file kept, as after SIGKILL) is resumed from the entries it
/// gave: the pack is the one an uninterrupted writer makes, byte for byte; a damaged payload
/// ends what is kept, and what follows it is written again.
#[test]
fn a_resumed_writer_makes_the_same_file() {
    let dir = tempfile::tempdir().unwrap();
    let d = common::description(3, 1);
    let levels = vortex_pack::fuzzing::pyramid_levels(&d, 4);
    let options = WriteOptions { alignment: 4096, payload_alignment: 16 };
    // Every tile of the pyramid, some repeated (shared payloads) and some constant.
    let tiles: Vec<(TileId, Option<Vec<u8>>)> = levels
        .iter()
        .enumerate()
        .flat_map(|(lod, l)| {
            (0..l.tiles_h).flat_map(move |y| (0..l.tiles_w).map(move |x| TileId { lod: lod as u32, x, y }))
        })
        .enumerate()
        .map(|(k, id)| (id, (k % 5 != 4).then(|| common::raw_tile(&d, (k % 7) as u32))))
        .collect();
    let add = |w: &mut PackWriter, (id, tile): &(TileId, Option<Vec<u8>>)| match tile {
        Some(bytes) => w.add(*id, NewTile::Data(TileKind::Raw, bytes)).unwrap(),
        None => w.add(*id, NewTile::Constant(&[9, 8, 7])).unwrap(),
    };
    let whole = dir.path().join("whole.vtpk");
    let mut w = PackWriter::create(&whole, d, levels.clone(), b"{}", options).unwrap();
    tiles.iter().for_each(|t| add(&mut w, t));
    w.finish().unwrap();
    let expected = std::fs::read(&whole).unwrap();

    for damage in [false, true] {
        let path = dir.path().join("resumed.vtpk");
        let mut w = PackWriter::create(&path, d, levels.clone(), b"{}", options).unwrap();
        let half = tiles.len() / 2;
        let mut journal = Vec::new();
        for t in &tiles[..half] {
            add(&mut w, t);
            journal.push((t.0, w.entry(t.0).unwrap()));
        }
        // One more payload written but not journaled, as a kill between the two leaves it.
        add(&mut w, &tiles[half]);
        w.keep_on_drop();
        drop(w);
        // A killed run's name: another PID's.
        let left = dir.path().join(".resumed.vtpk.tmp-4000000000");
        std::fs::rename(vortex_pack::temporary_path(&path), &left).unwrap();
        let mut first_damaged = half;
        if damage {
            // The 4th payload stored, one byte changed: the tiles from the first that stored it on go.
            let mut seen = std::collections::HashSet::new();
            let (k, e) = (journal.iter().enumerate())
                .filter(|(_, (_, e))| e.len > 0 && seen.insert(e.offset_or_value))
                .map(|(k, (_, e))| (k, *e))
                .nth(3)
                .unwrap();
            let mut bytes = std::fs::read(&left).unwrap();
            bytes[e.offset_or_value as usize] ^= 1;
            std::fs::write(&left, bytes).unwrap();
            first_damaged = k;
        }
        let (mut w, held) = PackWriter::resume(&path, d, levels.clone(), b"{}", options, &left, &journal).unwrap();
        assert_eq!(held, first_damaged, "damaged: {damage}");
        assert!(!left.exists());
        for t in &tiles[held..] {
            add(&mut w, t);
        }
        w.finish().unwrap();
        assert!(std::fs::read(&path).unwrap() == expected, "damaged: {damage}");
    }
}
