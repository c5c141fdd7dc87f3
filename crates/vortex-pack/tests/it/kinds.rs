//! The kinds format 1.1 adds or specifies: zstd-delta and JPEG XL (each with its
//! required-feature bit), BC1 and BC7 blocks. Blocks here are written by hand, bit by bit, from the Direct3D definitions, so
//! that the decoder is checked against the format rather than against an encoder.

use vortex_pack::format::{self, delta_decode_rows, delta_encode_rows};
use vortex_pack::fuzzing::{at, pyramid_levels};
use vortex_pack::{
    Description, NewTile, Pack, PackError, PackWriter, Tile, TileId, TileKind, VerifyOptions, WriteOptions, verify,
};

use crate::common::{self, reseal};

const DECODE: VerifyOptions = VerifyOptions { decode: true };
const LIMIT: u64 = 1 << 20;

/// Reproducible bytes.
fn noise(len: usize, seed: u32) -> Vec<u8> {
    let mut s = seed.wrapping_mul(2_654_435_761).wrapping_add(1);
    (0..len)
        .map(|_| {
            s ^= s << 13;
            s ^= s >> 17;
            s ^= s << 5;
            s as u8
        })
        .collect()
}

/// Writes one pack of `d` whose every LOD-0 tile is `tile(x, y)`; the other levels are absent.
fn write(path: &std::path::Path, d: Description, tile: impl Fn(u32, u32) -> (TileKind, Vec<u8>)) {
    let levels = pyramid_levels(&d, 4);
    let mut w = PackWriter::create(path, d, levels.clone(), b"{}", WriteOptions::default()).unwrap();
    for y in 0..levels[0].tiles_h {
        for x in 0..levels[0].tiles_w {
            let (kind, bytes) = tile(x, y);
            w.add(TileId { lod: 0, x, y }, NewTile::Data(kind, &bytes)).unwrap();
        }
    }
    w.finish().unwrap();
}

#[test]
fn the_row_filter_is_the_spec_formula_and_undoes_itself() {
    // Two rows of two RGB texels: the first texel of each row stays, the second becomes the
    // difference, modulo 256.
    let mut b = vec![10, 20, 30, 15, 25, 5, 200, 0, 1, 100, 255, 0];
    delta_encode_rows(&mut b, 2, 3, 1);
    assert_eq!(b, [10, 20, 30, 5, 5, 231, 200, 0, 1, 156, 255, 255]);
    delta_decode_rows(&mut b, 2, 3, 1);
    assert_eq!(b, [10, 20, 30, 15, 25, 5, 200, 0, 1, 100, 255, 0]);
    // 16-bit samples are little-endian and wrap modulo 65536.
    let mut b = [1u16, 0, 0x1234, 0x1334].iter().flat_map(|v| v.to_le_bytes()).collect::<Vec<u8>>();
    delta_encode_rows(&mut b, 4, 1, 2);
    assert_eq!(b, [1u16, 0xffff, 0x1234, 0x0100].iter().flat_map(|v| v.to_le_bytes()).collect::<Vec<u8>>());
    for (channels, sample_bytes, width) in [(1, 1, 7), (3, 1, 16), (4, 1, 5), (2, 2, 9), (4, 2, 3)] {
        let raw = noise(width * channels * sample_bytes * 6, width as u32);
        let mut b = raw.clone();
        delta_encode_rows(&mut b, width, channels, sample_bytes);
        assert_ne!(b, raw);
        delta_decode_rows(&mut b, width, channels, sample_bytes);
        assert_eq!(b, raw, "{channels} x {sample_bytes}");
    }
}

#[test]
fn zstd_delta_tiles_read_back_exactly_and_need_their_feature_bit() {
    let dir = tempfile::tempdir().unwrap();
    for (channels, sample_bytes) in [(3, 1), (2, 2), (4, 1)] {
        let d = common::description(channels, sample_bytes);
        let texel = channels as usize * sample_bytes as usize;
        let raw = |x: u32, y: u32| noise(d.raw_tile_len().unwrap() as usize, x * 7 + y + channels as u32);
        let path = dir.path().join(format!("delta{channels}{sample_bytes}.vtpk"));
        write(&path, d, |x, y| {
            let mut filtered = raw(x, y);
            delta_encode_rows(&mut filtered, d.tile_size as usize, channels as usize, sample_bytes as usize);
            (TileKind::ZstdDelta, zstd::bulk::compress(&filtered, 3).unwrap())
        });
        let pack = Pack::open(&path).unwrap();
        assert_eq!((pack.header().minor, pack.header().required_features), (1, format::REQUIRED_ZSTD_DELTA));
        let report = verify(&pack, DECODE);
        assert!(report.is_ok() && report.count(TileKind::ZstdDelta) == 16, "{report}");
        assert!(report.to_json().contains("\"zstd-delta\":16"), "{}", report.to_json());
        let vortex_pack::Tile::Data(TileKind::ZstdDelta, bytes) = pack.tile(vortex_pack::TileId::new(0, 2, 1)).unwrap()
        else {
            panic!()
        };
        assert_eq!(Tile::Data(TileKind::ZstdDelta, bytes).decode_texels(&d, LIMIT).unwrap(), raw(2, 1));
        let rgba = pack.decode_rgba8(TileId { lod: 0, x: 2, y: 1 }).unwrap().unwrap();
        let first = &raw(2, 1)[..texel];
        let expected_first = match (channels, sample_bytes) {
            (3, 1) => vec![first[0], first[1], first[2], 255],
            (4, 1) => first.to_vec(),
            _ => {
                let s = |i: usize| ((u16::from_le_bytes([first[i], first[i + 1]]) as u32 + 128) / 257) as u8;
                vec![s(0), s(0), s(0), s(2)]
            }
        };
        assert_eq!(rgba[..4], expected_first[..]);

        // Without the bit, a reader refuses the tile and verify says why.
        let mut b = std::fs::read(&path).unwrap();
        b[at::REQUIRED] = 0;
        reseal(&mut b);
        let bad = dir.path().join(format!("nobit{channels}{sample_bytes}.vtpk"));
        std::fs::write(&bad, &b).unwrap();
        let pack = Pack::open(&bad).unwrap();
        let e = pack.tile(vortex_pack::TileId::new(0, 0, 0)).unwrap_err().to_string();
        assert!(e.contains("zstd-delta") && e.contains("required-feature bit 0x1"), "{e}");
        let report = verify(&pack, VerifyOptions::default());
        assert!(
            report.problems.iter().any(|p| p.offset == Some(at::REQUIRED as u64)
                && p.message.contains("16 zstd-delta tile(s), but required-feature bit 0x1 is not set")),
            "{report}"
        );
    }
    // A pack without zstd-delta tiles sets no bit; a newer bit is refused at open.
    let d = common::description(3, 1);
    let path = dir.path().join("plain.vtpk");
    write(&path, d, |x, y| (TileKind::Zstd, zstd::bulk::compress(&noise(192, x + y), 1).unwrap()));
    let mut b = std::fs::read(&path).unwrap();
    assert_eq!(b[at::REQUIRED], 0);
    // (Bit 1 marks 32-bit and float samples, bit 2 JPEG XL tiles: bit 3 is the first one not
    // defined.)
    b[at::REQUIRED] = 8;
    reseal(&mut b);
    std::fs::write(&path, &b).unwrap();
    let e = Pack::open(&path).err().unwrap().to_string();
    assert!(e.contains("required features 0x8 unknown"), "{e}");
}

#[test]
fn jxl_tiles_decode_as_libjxl_coded_them_and_need_their_feature_bit() {
    let dir = tempfile::tempdir().unwrap();
    // Lossless tiles of every layout, 8 and 16 bits: libjxl encodes, jxl-oxide decodes, and the
    // RGBA8 tile is exactly the texels' (16 bits as raw ones, (v + 128) / 257).
    for (channels, sample_bytes) in [(1u8, 1u8), (2, 1), (3, 1), (4, 1), (3, 2), (2, 2)] {
        let d = common::description(channels, sample_bytes);
        let side = d.tile_size;
        let raw = |x: u32, y: u32| noise(d.raw_tile_len().unwrap() as usize, x * 5 + y + 16 * channels as u32);
        let encode = |texels: &[u8]| {
            let words: Vec<u16> = texels.chunks_exact(2).map(|p| u16::from_le_bytes([p[0], p[1]])).collect();
            let pixels =
                if sample_bytes == 1 { vortex_jxl::Pixels::U8(texels) } else { vortex_jxl::Pixels::U16(&words) };
            let image = vortex_jxl::Image { width: side, height: side, channels: channels as u32, pixels };
            vortex_jxl::encode(&image, vortex_jxl::Quality::Lossless, vortex_jxl::Effort::new(1).unwrap()).unwrap()
        };
        let path = dir.path().join(format!("jxl{channels}{sample_bytes}.vtpk"));
        write(&path, d, |x, y| (TileKind::Jxl, encode(&raw(x, y))));
        let pack = Pack::open(&path).unwrap();
        assert_eq!(pack.header().required_features, format::REQUIRED_JXL);
        let report = verify(&pack, DECODE);
        assert!(report.is_ok() && report.count(TileKind::Jxl) == 16, "{report}");
        assert!(report.to_json().contains("\"jxl\":16"), "{}", report.to_json());
        let expected = Tile::Data(TileKind::Raw, &raw(3, 2)).decode_rgba8(&d, LIMIT).unwrap().unwrap();
        let rgba = pack.decode_rgba8(TileId { lod: 0, x: 3, y: 2 }).unwrap().unwrap();
        assert!(rgba == expected, "{channels} channel(s) of {sample_bytes} byte(s)");
        // A JPEG XL payload is an image file, like PNG's: no texels of the pack's own format.
        let Tile::Data(_, bytes) = pack.tile(TileId::new(0, 3, 2)).unwrap() else { panic!() };
        assert!(Tile::Data(TileKind::Jxl, bytes).decode_texels(&d, LIMIT).is_err());

        // Without the bit, a reader refuses the tile.
        let mut b = std::fs::read(&path).unwrap();
        b[at::REQUIRED] = 0;
        reseal(&mut b);
        let bad = dir.path().join(format!("jxl-nobit{channels}{sample_bytes}.vtpk"));
        std::fs::write(&bad, &b).unwrap();
        let e = Pack::open(&bad).unwrap().tile(TileId::new(0, 0, 0)).unwrap_err().to_string();
        assert!(e.contains("jxl") && e.contains("required-feature bit 0x4"), "{e}");
    }

    // A lossy tile decodes within what its distance allows, and a tile of another size, a
    // recompressed JPEG of the right size, and garbage are told apart.
    let d = common::description(3, 1);
    let side = d.tile_size;
    let smooth: Vec<u8> = (0..side * side * 3).map(|i| ((i / 3 % side) * 255 / side) as u8).collect();
    let image = vortex_jxl::Image { width: side, height: side, channels: 3, pixels: vortex_jxl::Pixels::U8(&smooth) };
    let lossy =
        vortex_jxl::encode(&image, vortex_jxl::Quality::Distance(1.0), vortex_jxl::Effort::new(3).unwrap()).unwrap();
    let rgba = Tile::Data(TileKind::Jxl, &lossy).decode_rgba8(&d, LIMIT).unwrap().unwrap();
    let worst = rgba
        .chunks_exact(4)
        .zip(smooth.chunks_exact(3))
        .flat_map(|(a, b)| (0..3).map(move |c| a[c].abs_diff(b[c])))
        .max();
    // Distance 1.0 on a smooth ramp: a few levels at most (libjxl's own decoder differs by as
    // much); a wrong colour space or channel order would be off by tens.
    assert!(worst.unwrap() <= 6, "worst error {worst:?}");
    let mut wide = vec![0u8; (side as usize * 2) * (side as usize * 2) * 3];
    wide[0] = 1;
    let image =
        vortex_jxl::Image { width: side * 2, height: side * 2, channels: 3, pixels: vortex_jxl::Pixels::U8(&wide) };
    let big = vortex_jxl::encode(&image, vortex_jxl::Quality::Lossless, vortex_jxl::Effort::new(1).unwrap()).unwrap();
    let e = Tile::Data(TileKind::Jxl, &big).decode_rgba8(&d, LIMIT).unwrap_err().to_string();
    assert!(e.contains(&format!("jxl image is {0}x{0}, the tile is {1}x{1}", side * 2, side)), "{e}");
    for garbage in [&b"\xff\x0a"[..], b"not a jxl", &lossy[..lossy.len() / 2]] {
        let e = Tile::Data(TileKind::Jxl, garbage).decode_rgba8(&d, LIMIT).unwrap_err().to_string();
        assert!(e.contains("jxl"), "{e}");
    }
}

/// Appends `value`'s low `bits` bits to a little-endian bit stream (as BC7 reads it).
struct Bits {
    block: u128,
    at: u32,
}

impl Bits {
    fn put(&mut self, value: u32, bits: u32) -> &mut Self {
        self.block |= ((value as u128) & ((1u128 << bits) - 1)) << self.at;
        self.at += bits;
        self
    }
}

/// A BC7 mode-6 block (one subset, RGBA endpoints of 7 bits plus a p-bit each, 4-bit indices)
/// whose texel 0 takes endpoint 0 and texel 15 endpoint 1: (255, 129, 1, 255) and
/// (0, 128, 254, 254): each 8-bit endpoint is its 7 bits and the p-bit.
fn bc7_mode6() -> [u8; 16] {
    let mut b = Bits { block: 0, at: 0 };
    b.put(1 << 6, 7);
    for (e0, e1) in [(0x7f, 0), (0x40, 0x40), (0, 0x7f), (0x7f, 0x7f)] {
        b.put(e0, 7).put(e1, 7);
    }
    b.put(1, 1).put(0, 1); // p-bits: endpoint 0 gets 1, endpoint 1 gets 0
    b.put(0, 3); // texel 0, the anchor: 3 bits
    for _ in 1..15 {
        b.put(0, 4);
    }
    b.put(15, 4);
    assert_eq!(b.at, 128);
    b.block.to_le_bytes()
}

/// BC1 blocks: red/blue in four-colour mode (indices 0, 1, 2, 3 on the first row), and in
/// three-colour mode (colour 0 <= colour 1), whose index 3 is transparent black.
fn bc1_blocks() -> ([u8; 8], [u8; 8]) {
    let four = [0x00, 0xf8, 0x1f, 0x00, 0b1110_0100, 0, 0, 0];
    let three = [0x1f, 0x00, 0x00, 0xf8, 0b1110_0100, 0, 0, 0];
    (four, three)
}

fn texel(rgba: &[u8], side: usize, x: usize, y: usize) -> [u8; 4] {
    rgba[(y * side + x) * 4..][..4].try_into().unwrap()
}

#[test]
fn bc1_and_bc7_blocks_decode_as_direct3d_defines_them() {
    let dir = tempfile::tempdir().unwrap();
    // 8-texel tiles: 2 x 2 blocks, in rows of blocks.
    let (four, three) = bc1_blocks();
    let d = common::description(3, 1);
    let path = dir.path().join("bc1.vtpk");
    write(&path, d, |_, _| (TileKind::Bc1, [four, three, three, four].concat()));
    let pack = Pack::open(&path).unwrap();
    let report = verify(&pack, DECODE);
    assert!(report.is_ok() && report.decoded_payloads == 1 && report.count(TileKind::Bc1) == 16, "{report}");
    let rgba = pack.decode_rgba8(TileId { lod: 0, x: 1, y: 1 }).unwrap().unwrap();
    let row: Vec<[u8; 4]> = (0..8).map(|x| texel(&rgba, 8, x, 0)).collect();
    assert_eq!(row[..4], [[255, 0, 0, 255], [0, 0, 255, 255], [170, 0, 85, 255], [85, 0, 170, 255]]);
    // Three-colour mode: index 2 is the mean, index 3 black, opaque in an RGB pack.
    assert_eq!(row[4..], [[0, 0, 255, 255], [255, 0, 0, 255], [128, 0, 128, 255], [0, 0, 0, 255]]);
    assert_eq!(texel(&rgba, 8, 5, 3), [0, 0, 255, 255]);
    assert_eq!(texel(&rgba, 8, 0, 4), [0, 0, 255, 255]);
    let vortex_pack::Tile::Data(_, bytes) = pack.tile(vortex_pack::TileId::new(0, 0, 0)).unwrap() else { panic!() };
    let rgb = Tile::Data(TileKind::Bc1, bytes).decode_texels(&d, LIMIT).unwrap();
    assert_eq!((rgb.len(), &rgb[..6]), (192, &[255, 0, 0, 0, 0, 255][..]));

    for channels in [3, 4] {
        let d = common::description(channels, 1);
        let path = dir.path().join(format!("bc7-{channels}.vtpk"));
        write(&path, d, |_, _| (TileKind::Bc7, bc7_mode6().repeat(4)));
        let pack = Pack::open(&path).unwrap();
        let report = verify(&pack, DECODE);
        assert!(report.is_ok() && report.count(TileKind::Bc7) == 16, "{report}");
        let rgba = pack.decode_rgba8(TileId { lod: 0, x: 3, y: 0 }).unwrap().unwrap();
        let alpha = if channels == 4 { 254 } else { 255 };
        for (bx, by) in [(0, 0), (4, 0), (0, 4), (4, 4)] {
            assert_eq!(texel(&rgba, 8, bx, by), [255, 129, 1, 255]);
            assert_eq!(texel(&rgba, 8, bx + 3, by + 3), [0, 128, 254, alpha]);
            assert_eq!(texel(&rgba, 8, bx + 1, by + 2), [255, 129, 1, 255]);
        }
        let vortex_pack::Tile::Data(_, bytes) = pack.tile(vortex_pack::TileId::new(0, 0, 0)).unwrap() else { panic!() };
        let texels = Tile::Data(TileKind::Bc7, bytes).decode_texels(&d, LIMIT).unwrap();
        assert_eq!(texels.len(), 64 * channels as usize);
    }
}

#[test]
fn block_tiles_need_a_texture_they_can_describe() {
    let dir = tempfile::tempdir().unwrap();
    let (four, _) = bc1_blocks();
    let bc1 = four.repeat(4);
    let bc7 = bc7_mode6().repeat(4);
    let cases: [(Description, TileKind, &[u8], &str); 6] = [
        (common::description(4, 1), TileKind::Bc1, &bc1, "bc1 tiles need 3 channels of 1 byte, not 4 channel(s)"),
        (common::description(3, 2), TileKind::Bc1, &bc1, "not 3 channel(s) of 2 byte(s)"),
        (common::description(1, 1), TileKind::Bc7, &bc7, "bc7 tiles need 3 or 4 channels of 1 byte"),
        (
            Description { tile_size: 6, ..common::description(3, 1) },
            TileKind::Bc7,
            &bc7,
            "a tile size that is a multiple of 4, not 6",
        ),
        (common::description(3, 1), TileKind::Bc1, &bc1[..24], "a bc1 tile has 32 bytes, not 24"),
        (common::description(4, 1), TileKind::Bc7, &bc1, "a bc7 tile has 64 bytes, not 32"),
    ];
    for (i, (d, kind, bytes, expected)) in cases.into_iter().enumerate() {
        let path = dir.path().join(format!("refused{i}.vtpk"));
        let levels = pyramid_levels(&d, 4);
        let mut w = PackWriter::create(&path, d, levels, b"{}", WriteOptions::default()).unwrap();
        let e = w.add(TileId { lod: 0, x: 0, y: 0 }, NewTile::Data(kind, bytes)).unwrap_err().to_string();
        assert!(e.contains(expected), "{expected}: {e}");
        let e = Tile::Data(kind, bytes).decode_texels(&d, LIMIT).unwrap_err().to_string();
        assert!(e.contains(expected), "{expected}: {e}");
    }

    // A BC1 pack whose header is changed to say RGBA: verify reports it once, at the header,
    // and decoding refuses the tiles.
    let path = dir.path().join("bc1.vtpk");
    write(&path, common::description(3, 1), |_, _| (TileKind::Bc1, bc1.clone()));
    let mut b = std::fs::read(&path).unwrap();
    b[at::CHANNELS] = 4;
    reseal(&mut b);
    std::fs::write(&path, &b).unwrap();
    let pack = Pack::open(&path).unwrap();
    let report = verify(&pack, DECODE);
    assert_eq!(report.problems.len(), 1, "{report}");
    assert!(report.problems[0].message.contains("16 bc1 tile(s), but bc1 tiles need 3 channels"), "{report}");
    let e = pack.decode_rgba8(TileId { lod: 0, x: 0, y: 0 }).unwrap_err().to_string();
    assert!(e.contains("tile (lod 0, x 0, y 0)") && e.contains("bc1 tiles need 3 channels"), "{e}");
}

#[test]
fn hostile_payloads_are_errors_not_panics() {
    let d = common::description(4, 1);
    for seed in 0..200u32 {
        let len = (seed as usize * 7) % 300;
        let bytes = noise(len, seed);
        for kind in [TileKind::Raw, TileKind::Zstd, TileKind::ZstdDelta, TileKind::Bc1, TileKind::Bc7] {
            let _ = Tile::Data(kind, &bytes).decode_texels(&d, LIMIT);
        }
    }
    // Right-sized random blocks decode to something (every bit pattern is a block).
    assert_eq!(Tile::Data(TileKind::Bc7, &noise(64, 1)).decode_texels(&d, LIMIT).unwrap().len(), 256);
    let e = Tile::Data(TileKind::Png, b"\x89PNG").decode_texels(&d, LIMIT).unwrap_err().to_string();
    assert!(e.contains("png payloads are image files, not texels"), "{e}");
    let e =
        Tile::Data(TileKind::Raw, &[0; 256]).decode_texels(&common::description(4, 1), 100).unwrap_err().to_string();
    assert!(e.contains("exceeds the decoding limit of 100 bytes"), "{e}");
}

#[test]
fn a_tile_decoded_away_from_its_pack_is_the_tile_decoded_in_place() {
    let dir = tempfile::tempdir().unwrap();
    for (i, (channels, sample_bytes, options)) in common::sample_variants().into_iter().enumerate() {
        let path = dir.path().join(format!("sample{i}.vtpk"));
        common::write_sample(&path, channels, sample_bytes, options);
        let pack = Pack::open(&path).unwrap();
        let d = pack.description();
        for id in pack.ids() {
            // A copy of the stored bytes, as a cache keeps them once the map is gone.
            let (kept, stored) = match pack.tile_checked(id).unwrap() {
                Tile::Absent => (vec![], None),
                Tile::Constant(value) => (value.to_vec(), Some(TileKind::Constant)),
                Tile::Data(kind, bytes) => (bytes.to_vec(), Some(kind)),
            };
            let copy = match stored {
                None => Tile::Absent,
                Some(TileKind::Constant) => Tile::Constant(&kept),
                Some(kind) => Tile::Data(kind, &kept),
            };
            let in_place = pack.decode_rgba8(id).unwrap();
            assert_eq!(copy.decode_rgba8(d, LIMIT).unwrap(), in_place, "{id:?}");
        }
    }
    let d = common::description(3, 1);
    let e = Tile::Data(TileKind::Raw, &[1, 2, 3]).decode_rgba8(&d, LIMIT).unwrap_err();
    assert!(matches!(&e, PackError::Payload { kind: "raw", .. }), "{e}");
}
