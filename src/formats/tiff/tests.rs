//! The writer read back by a naive reader written here from the TIFF 6.0 and BigTIFF specs,
//! independently of the writer: header, IFD chain, every entry, tile offsets and counts.

use std::collections::BTreeMap;
use std::io::Read;

use super::*;
use crate::layout::Layout;
use crate::pixel::{Channels, Depth, PixelLayout};

/// One entry as read: its type and its values widened to u64 (ASCII as bytes).
#[derive(Debug, Clone)]
struct Entry {
    typ: u16,
    values: Vec<u64>,
}

/// A file's IFD as read: its offset, its tags in file order, the next IFD.
#[derive(Debug)]
struct ReadIfd {
    at: u64,
    order: Vec<u16>,
    tags: BTreeMap<u16, Entry>,
    next: u64,
}

struct Naive<'a> {
    b: &'a [u8],
    big: bool,
}

impl Naive<'_> {
    fn u(&self, at: u64, n: usize) -> u64 {
        let at = at as usize;
        assert!(at + n <= self.b.len(), "read of {n} bytes at {at} past the file's {}", self.b.len());
        self.b[at..at + n].iter().rev().fold(0u64, |v, &x| (v << 8) | x as u64)
    }

    fn ifd(&self, at: u64) -> ReadIfd {
        assert_eq!(at % 2, 0, "IFD at {at}: not word-aligned");
        let (count, mut p, entry_len) =
            if self.big { (self.u(at, 8), at + 8, 20) } else { (self.u(at, 2), at + 2, 12) };
        let mut order = Vec::new();
        let mut tags = BTreeMap::new();
        for _ in 0..count {
            let tag = self.u(p, 2) as u16;
            let typ = self.u(p + 2, 2) as u16;
            let n = if self.big { self.u(p + 4, 8) } else { self.u(p + 4, 4) };
            let size = match typ {
                1 | 2 => 1,
                3 => 2,
                4 | 13 => 4,
                5 => 8,
                16 | 18 => 8,
                t => panic!("tag {tag}: type {t} not written by us"),
            };
            let field = p + if self.big { 12 } else { 8 };
            let inline = if self.big { 8 } else { 4 };
            let data = if n * size <= inline {
                field
            } else if self.big {
                self.u(field, 8)
            } else {
                self.u(field, 4)
            };
            let values = (0..n)
                .map(|i| match typ {
                    5 => self.u(data + i * 8, 4) * 1_000_000 / self.u(data + i * 8 + 4, 4).max(1),
                    _ => self.u(data + i * size, size as usize),
                })
                .collect();
            order.push(tag);
            tags.insert(tag, Entry { typ, values });
            p += entry_len;
        }
        let next = if self.big { self.u(p, 8) } else { self.u(p, 4) };
        ReadIfd { at, order, tags, next }
    }

    fn first(&self) -> u64 {
        if self.big { self.u(8, 8) } else { self.u(4, 4) }
    }
}

fn open(bytes: &[u8]) -> Naive<'_> {
    assert_eq!(&bytes[..2], b"II");
    let big = match bytes[2] {
        42 => false,
        43 => {
            assert_eq!((bytes[4], bytes[6]), (8, 0), "BigTIFF's offset size");
            true
        }
        m => panic!("magic {m}"),
    };
    Naive { b: bytes, big }
}

impl ReadIfd {
    fn one(&self, tag: u16) -> u64 {
        let e = self.tags.get(&tag).unwrap_or_else(|| panic!("IFD at {}: no tag {tag}", self.at));
        assert_eq!(e.values.len(), 1, "tag {tag}");
        e.values[0]
    }
    fn all(&self, tag: u16) -> &[u64] {
        &self.tags.get(&tag).unwrap_or_else(|| panic!("IFD at {}: no tag {tag}", self.at)).values
    }
    fn text(&self, tag: u16) -> String {
        let v: Vec<u8> = self.all(tag).iter().map(|&b| b as u8).collect();
        assert_eq!(v.last(), Some(&0), "tag {tag}: NUL-terminated");
        String::from_utf8(v[..v.len() - 1].to_vec()).unwrap()
    }
}

fn spec(flavour: Flavour, w: u32, h: u32, levels: u32, stored: PixelLayout, compression: Compression) -> Spec {
    // Written field by field (not Layout::new) so that the refusals below can be given
    // sizes Layout itself refuses.
    let tile_size = 16;
    let (columns, rows) = (w.div_ceil(tile_size), h.div_ceil(tile_size));
    let layout = Layout { width: w, height: h, tile_size, border: 0, columns, rows, lod_count: levels };
    Spec {
        flavour,
        layout,
        stored,
        compression,
        bigtiff: BigTiff::Auto,
        name: "tiny <&> \"test\"".into(),
        pixel_size: None,
        geo: Vec::new(),
        icc: None,
        copied: Vec::new(),
        associated: Vec::new(),
        associated_bytes: 0,
        associated_left_out: 0,
        channels: Vec::new(),
        planar: false,
    }
}

/// Level `k`'s size, worked out here as the TIFF readers expect it: `ceil(size / 2^k)`.
fn extent(s: &Spec, k: u32) -> (u32, u32) {
    (s.layout.width.div_ceil(1 << k), s.layout.height.div_ceil(1 << k))
}

/// Level `k`'s tiles across and down.
fn grid(s: &Spec, k: u32) -> (u32, u32) {
    let (w, h) = extent(s, k);
    (w.div_ceil(s.layout.tile_size), h.div_ceil(s.layout.tile_size))
}

fn grey8() -> PixelLayout {
    PixelLayout::new(Channels::Grey, Depth::U8)
}

/// A tile's raw samples, different for every tile and pixel.
fn raw_tile(s: &Spec, level: u32, x: u32, y: u32) -> Vec<u8> {
    let n = s.raw_tile_bytes() as usize;
    (0..n).map(|i| (i as u32 * 7 + level * 31 + x * 13 + y * 5) as u8).collect()
}

/// Writes `s` with its tiles in a scrambled order (last level first, columns reversed), each
/// tile's bytes from `tile`; returns the file's bytes.
fn write(s: &Spec, tile: impl Fn(u32, u32, u32) -> Vec<u8>) -> Vec<u8> {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("t.tif");
    let mut w = TiffWriter::create(&path, std::fs::File::create(&path).unwrap(), s.clone()).unwrap();
    for level in (0..s.layout.lod_count).rev() {
        let (c, r) = grid(s, level);
        for y in 0..r {
            for x in (0..c).rev() {
                w.add_plane_tile(0, level, x, y, &tile(level, x, y)).unwrap();
            }
        }
    }
    let summary = w.finish().unwrap();
    let bytes = std::fs::read(&path).unwrap();
    assert_eq!(summary.file_bytes, bytes.len() as u64);
    bytes
}

/// Checks what every IFD of ours holds: tags ascending, the level's size and tile grid, tile
/// data inside the file where the tile was put, the signature as Software.
fn check_levels(file: &[u8], s: &Spec, ifds: &[ReadIfd], tile: impl Fn(u32, u32, u32) -> Vec<u8>) {
    assert_eq!(ifds.len() as u32, s.layout.lod_count);
    for (k, ifd) in ifds.iter().enumerate() {
        let k = k as u32;
        let mut sorted = ifd.order.clone();
        sorted.sort_unstable();
        sorted.dedup();
        assert_eq!(ifd.order, sorted, "level {k}: tags ascending, each once");
        let (w, h) = extent(s, k);
        assert_eq!((ifd.one(256), ifd.one(257)), (w as u64, h as u64), "level {k}");
        assert_eq!(ifd.one(254), u64::from(k > 0), "NewSubfileType of level {k}");
        assert_eq!((ifd.one(322), ifd.one(323)), (16, 16));
        assert_eq!(ifd.one(277), s.stored.channels.count() as u64);
        assert_eq!(ifd.text(305), SIGNATURE);
        let (c, r) = grid(s, k);
        let (offsets, counts) = (ifd.all(324), ifd.all(325));
        assert_eq!(offsets.len(), (c * r) as usize, "level {k}: one offset a tile");
        assert_eq!(counts.len(), offsets.len());
        for y in 0..r {
            for x in 0..c {
                let i = (y * c + x) as usize;
                let (o, n) = (offsets[i] as usize, counts[i] as usize);
                assert!(o >= 32 && o + n <= file.len(), "tile {i} of level {k} at {o}+{n}");
                assert_eq!(file[o..o + n], tile(k, x, y)[..], "tile ({k}, {x}, {y})");
            }
        }
    }
}

fn chain(n: &Naive, mut at: u64) -> Vec<ReadIfd> {
    let mut out = Vec::new();
    while at != 0 {
        let ifd = n.ifd(at);
        at = ifd.next;
        out.push(ifd);
        assert!(out.len() < 64, "an IFD loop");
    }
    out
}

#[test]
fn a_generic_pyramid_chains_every_level() {
    let s = spec(Flavour::Generic, 40, 20, 3, grey8(), Compression::None);
    // The writer's geometry (the pipeline's Layout) agrees with the readers' rule.
    for k in 0..3 {
        assert_eq!((s.layout.level_extent(k), s.layout.grid(k)), (extent(&s, k), grid(&s, k)), "level {k}");
    }
    assert_eq!(grid(&s, 0), (3, 2));
    assert_eq!(grid(&s, 2), (1, 1));
    let file = write(&s, |l, x, y| raw_tile(&s, l, x, y));
    let n = open(&file);
    assert!(!n.big, "a tiny file is classic TIFF");
    let ifds = chain(&n, n.first());
    check_levels(&file, &s, &ifds, |l, x, y| raw_tile(&s, l, x, y));
    let first = &ifds[0];
    assert_eq!(first.one(259), 1, "no compression");
    assert_eq!(first.one(262), 1, "grey is black-is-zero");
    assert!(!first.tags.contains_key(&317) && !first.tags.contains_key(&330) && !first.tags.contains_key(&270));
    assert_eq!(first.all(258), [8]);
    assert_eq!(first.all(339), [1]);
}

#[test]
fn an_ome_tiff_hangs_its_reduced_levels_off_the_first_ifd() {
    let mut s = spec(Flavour::Ome, 40, 20, 3, PixelLayout::new(Channels::Rgb, Depth::U8), Compression::None);
    s.pixel_size = Some(Micrometres(0.25));
    let file = write(&s, |l, x, y| raw_tile(&s, l, x, y));
    let n = open(&file);
    let main = chain(&n, n.first());
    assert_eq!(main.len(), 1, "one IFD in the main chain: one plane");
    let subs = main[0].all(330).to_vec();
    assert_eq!(main[0].tags[&330].typ, 13, "SubIFDs as IFD offsets");
    assert_eq!(subs.len(), 2);
    let mut levels = vec![n.ifd(main[0].at)];
    for &at in &subs {
        let sub = n.ifd(at);
        assert_eq!(sub.next, 0, "a SubIFD chains to nothing");
        levels.push(sub);
    }
    check_levels(&file, &s, &levels, |l, x, y| raw_tile(&s, l, x, y));
    let xml = levels[0].text(270);
    for want in [
        r#"SizeX="40""#,
        r#"SizeY="20""#,
        r#"SizeC="3""#,
        r#"Type="uint8""#,
        r#"SamplesPerPixel="3""#,
        r#"PhysicalSizeX="0.25""#,
        r#"Name="tiny &lt;&amp;&gt; &quot;test&quot;""#,
        r#"<TiffData IFD="0" PlaneCount="1"/>"#,
    ] {
        assert!(xml.contains(want), "{want} in {xml}");
    }
    assert!(!levels[1].tags.contains_key(&270), "OME-XML in the first IFD only");
    // 0.25 µm: 40000 pixels a centimetre, half that a level down.
    assert_eq!((levels[0].one(282), levels[0].one(296)), (40000 * 1_000_000, 3));
    assert_eq!(levels[1].one(283), 20000 * 1_000_000);
    assert_eq!(levels[0].one(262), 2, "RGB");
}

#[test]
fn bigtiff_when_asked() {
    let mut s = spec(Flavour::Ome, 33, 17, 2, PixelLayout::new(Channels::GreyAlpha, Depth::U16), Compression::None);
    s.bigtiff = BigTiff::Always;
    let file = write(&s, |l, x, y| raw_tile(&s, l, x, y));
    let n = open(&file);
    assert!(n.big);
    let main = n.ifd(n.first());
    assert_eq!(main.tags[&324].typ, 16, "LONG8 offsets");
    assert_eq!(main.tags[&330].typ, 18, "IFD8 SubIFDs");
    let levels = vec![n.ifd(main.at), n.ifd(main.all(330)[0])];
    check_levels(&file, &s, &levels, |l, x, y| raw_tile(&s, l, x, y));
    assert_eq!(main.all(338), [2], "unassociated alpha");
    assert_eq!(main.all(258), [16, 16]);
}

#[test]
fn the_size_bound_picks_bigtiff_before_writing() {
    let small = spec(Flavour::Generic, 1000, 700, 3, grey8(), Compression::Deflate { level: 6 });
    assert!(!small.needs_bigtiff());
    let rgb16 = PixelLayout::new(Channels::Rgb, Depth::U16);
    let mut large = spec(Flavour::Generic, 40000, 40000, 1, rgb16, Compression::Zstd { level: 3 });
    large.layout = Layout::new(40000, 40000, 256, 0).unwrap();
    assert!(large.most_file_bytes() > 40000u64 * 40000 * 6, "at least the raw samples");
    assert!(large.needs_bigtiff());
}

/// Deflate and zstd of 16-bit RGB with the predictor, as the encoders make them from the
/// codec the spec names: the naive reader inflates each tile and sums the differences back,
/// and gets the samples given.
#[test]
fn compressed_tiles_decode_to_the_samples() {
    let rgb16 = PixelLayout::new(Channels::Rgb, Depth::U16);
    for compression in [Compression::Deflate { level: 6 }, Compression::Zstd { level: 3 }] {
        let s = spec(Flavour::Generic, 20, 18, 2, rgb16, compression);
        let codec = s.codec().unwrap();
        assert!(
            matches!(
                codec,
                Codec::Deflate { filter: RowFilter::Delta, .. } | Codec::Zstd { filter: RowFilter::Delta, .. }
            ),
            "{codec:?}"
        );
        let encoder = crate::codec::TileEncoder::<u16>::new(codec, rgb16, false, None, 16, vec![]).unwrap();
        let stored = |l, x, y| {
            let texels: Vec<u16> =
                raw_tile(&s, l, x, y).chunks_exact(2).map(|b| u16::from_le_bytes([b[0], b[1]])).collect();
            let mut out = Vec::new();
            encoder.encode(&texels, &mut out).unwrap();
            out
        };
        let file = write(&s, stored);
        let n = open(&file);
        let ifds = chain(&n, n.first());
        assert_eq!(ifds[0].one(317), 2, "{compression:?}: horizontal predictor");
        assert_eq!(ifds[0].one(259), compression.code() as u64);
        let (offsets, counts) = (ifds[1].all(324), ifds[1].all(325));
        let (o, c) = (offsets[0] as usize, counts[0] as usize);
        let mut out = Vec::new();
        match compression {
            Compression::Deflate { .. } => {
                flate2::read::ZlibDecoder::new(&file[o..o + c]).read_to_end(&mut out).unwrap();
            }
            _ => out = zstd::bulk::decompress(&file[o..o + c], 1 << 20).unwrap(),
        }
        // Undo the predictor: 16-bit samples, 3 a pixel, rows of 16 pixels.
        for row in out.chunks_exact_mut(16 * 6) {
            for i in 3..row.len() / 2 {
                let v = u16::from_le_bytes([row[2 * i], row[2 * i + 1]])
                    .wrapping_add(u16::from_le_bytes([row[2 * i - 6], row[2 * i - 5]]));
                row[2 * i..2 * i + 2].copy_from_slice(&v.to_le_bytes());
            }
        }
        assert_eq!(out, raw_tile(&s, 1, 0, 0), "{compression:?}");
    }
}

/// Float samples take the floating-point predictor (3) before Deflate and LZW: the `tiff`
/// crate, a reader of its own that undoes predictor 3, gives back every sample bit for bit,
/// negative, fractional and subnormal ones included, across the tiles' joins.
#[test]
fn float_tiles_take_the_floating_point_predictor() {
    let rgbf = PixelLayout::new(Channels::Rgb, Depth::F32);
    let value = |x: u32, y: u32, c: u32| match (x + y + c) % 5 {
        0 => -(x as f32) * 0.37 - y as f32,
        1 => f32::from_bits(0x0000_0401 + x),
        2 => 1.0e30 / (1 + y) as f32,
        _ => (x * 1000 + y * 10 + c) as f32 / 7.0,
    };
    for compression in [Compression::Deflate { level: 6 }, Compression::Lzw] {
        let s = spec(Flavour::Generic, 20, 18, 1, rgbf, compression);
        let codec = s.codec().unwrap();
        let encoder = crate::codec::TileEncoder::<f32>::new(codec, rgbf, false, None, 16, vec![]).unwrap();
        let file = write(&s, |_, tx, ty| {
            let texels: Vec<f32> =
                (0..16 * 16 * 3).map(|i| value(tx * 16 + (i / 3) % 16, ty * 16 + i / 48, i % 3)).collect();
            let mut out = Vec::new();
            encoder.encode(&texels, &mut out).unwrap();
            out
        });
        let n = open(&file);
        assert_eq!(chain(&n, n.first())[0].one(317), 3, "{compression:?}: floating-point predictor");
        let mut decoder = tiff::decoder::Decoder::new(std::io::Cursor::new(&file)).unwrap();
        let tiff::decoder::DecodingResult::F32(samples) = decoder.read_image().unwrap() else {
            panic!("{compression:?}: not read as float samples");
        };
        assert_eq!(samples.len(), 20 * 18 * 3);
        for (i, got) in samples.iter().enumerate() {
            let (x, y, c) = ((i / 3) as u32 % 20, (i / 3) as u32 / 20, i as u32 % 3);
            assert_eq!(got.to_bits(), value(x, y, c).to_bits(), "{compression:?}: ({x}, {y}) sample {c}");
        }
    }
}

#[test]
fn jpeg_rgb_is_ycbcr_at_the_encoder_s_subsampling_or_rgb() {
    use crate::codec::Subsampling;
    for subsampling in Subsampling::ALL {
        let s = spec(
            Flavour::Generic,
            16,
            16,
            1,
            PixelLayout::new(Channels::Rgb, Depth::U8),
            Compression::Jpeg { subsampling },
        );
        let file = write(&s, |_, _, _| b"\xff\xd8 not really a JPEG \xff\xd9".to_vec());
        let n = open(&file);
        let ifd = n.ifd(n.first());
        assert!(!ifd.tags.contains_key(&317), "no predictor before JPEG");
        if subsampling == Subsampling::Rgb {
            assert_eq!((ifd.one(259), ifd.one(262)), (7, 2));
            assert!(!ifd.tags.contains_key(&530) && !ifd.tags.contains_key(&532), "no YCbCr tags for RGB");
            continue;
        }
        let factor = u64::from(subsampling.factor());
        assert_eq!((ifd.one(259), ifd.one(262)), (7, 6));
        assert_eq!(ifd.all(530), [factor, factor]);
        assert_eq!(ifd.all(532).len(), 6);
    }
}

#[test]
fn a_missing_or_repeated_or_stray_tile_is_an_error() {
    let s = spec(Flavour::Generic, 40, 20, 2, grey8(), Compression::None);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("t.tif");
    let mut w = TiffWriter::create(&path, std::fs::File::create(&path).unwrap(), s.clone()).unwrap();
    let t = raw_tile(&s, 0, 0, 0);
    w.add_plane_tile(0, 0, 0, 0, &t).unwrap();
    assert!(w.add_plane_tile(0, 0, 0, 0, &t).unwrap_err().to_string().contains("twice"));
    assert!(w.add_plane_tile(0, 0, 3, 0, &t).unwrap_err().to_string().contains("3x2 tiles"));
    assert!(w.add_plane_tile(0, 2, 0, 0, &t).unwrap_err().to_string().contains("2 levels"));
    assert!(w.add_plane_tile(0, 0, 1, 0, &[]).unwrap_err().to_string().contains("empty"));
    let e = w.finish().unwrap_err().to_string();
    assert!(e.contains("tile (level 0, x 1, y 0) was never written"), "{e}");
}

#[test]
fn what_no_tiff_holds_is_refused_before_writing() {
    let rgb = PixelLayout::new(Channels::Rgb, Depth::U8);
    let jpeg = Compression::Jpeg { subsampling: crate::codec::Subsampling::S420 };
    let cases = [
        (
            {
                let mut s = spec(Flavour::Generic, 40, 20, 1, rgb, Compression::None);
                s.layout.tile_size = 100;
                s
            },
            "multiple of 16",
        ),
        (spec(Flavour::Generic, 40, 20, 1, PixelLayout::new(Channels::Rgb, Depth::U16), jpeg), "8-bit grey or RGB"),
        (spec(Flavour::Generic, 40, 20, 1, PixelLayout::new(Channels::Rgba, Depth::U8), jpeg), "8-bit grey or RGB"),
        (spec(Flavour::Generic, 0, 20, 1, rgb, Compression::None), "no pixels"),
        (spec(Flavour::Generic, 40, 20, 0, rgb, Compression::None), "0 levels"),
    ];
    for (s, want) in cases {
        let e = s.check().unwrap_err().to_string();
        assert!(e.contains(want), "{e:?} lacks {want:?}");
    }
}

#[test]
fn the_sink_leaves_nothing_unless_finished_and_a_later_run_may_replace_its_file() {
    let dir = tempfile::tempdir().unwrap();
    let dest = dir.path().join("a.tif");
    let s = spec(Flavour::Generic, 20, 20, 2, grey8(), Compression::None);
    drop(TiffSink::create(&dest, s.clone()).unwrap());
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0, "a dropped sink leaves no temporary");

    let sink = TiffSink::create(&dest, s.clone()).unwrap();
    use crate::sink::TileSink;
    for level in 0..2 {
        let (c, r) = grid(&s, level);
        for y in 0..r {
            for x in 0..c {
                sink.write_tile(level, x, y, &raw_tile(&s, level, x, y)).unwrap();
            }
        }
    }
    assert!(sink.write_tile(0, 0, 0, &[1, 2, 3]).is_err(), "raw tiles are whole tiles");
    let summary = sink.finish().unwrap();
    assert_eq!((summary.levels, summary.tiles, summary.compression), (2, 5, "none"));
    let names: Vec<_> = std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert_eq!(names, ["a.tif"]);
    let claim = crate::output::claim(&dest, crate::output::Product::Tiff, &[], false).unwrap();
    assert_eq!(claim.replaces, Some(crate::output::Existing::Ours));
    // Somebody else's TIFF is not ours.
    let theirs = dir.path().join("b.tif");
    std::fs::write(&theirs, b"II*\0\x08\0\0\0\0\0").unwrap();
    assert!(crate::output::claim(&theirs, crate::output::Product::Tiff, &[], false).is_err());
}

/// A COG as GDAL lays it out (`cog.rs`): the ghost area right after the header, the first IFD
/// right after it at an even offset, every IFD before any tile, the tile data coarsest level
/// first and row by row, each tile framed by its length and its last 4 bytes repeated.
#[test]
fn a_cog_has_gdal_s_ghost_area_its_ifds_first_and_its_data_coarse_to_fine() {
    for bigtiff in [BigTiff::Auto, BigTiff::Always] {
        let s = Spec { bigtiff, ..spec(Flavour::Cog, 40, 36, 3, grey8(), Compression::None) };
        let file = write(&s, |l, x, y| raw_tile(&s, l, x, y));
        let n = open(&file);
        assert_eq!(n.big, bigtiff == BigTiff::Always);
        let head = if n.big { 16 } else { 8 };
        let line = b"GDAL_STRUCTURAL_METADATA_SIZE=000140 bytes\n";
        assert_eq!(&file[head..head + line.len()], line);
        let meta = std::str::from_utf8(&file[head + line.len()..][..140]).unwrap();
        let want = "LAYOUT=IFDS_BEFORE_DATA\nBLOCK_ORDER=ROW_MAJOR\nBLOCK_LEADER=SIZE_AS_UINT4\n\
                    BLOCK_TRAILER=LAST_4_BYTES_REPEATED\nKNOWN_INCOMPATIBLE_EDITION=NO\n ";
        assert_eq!(meta, want);
        assert_eq!(n.first(), ((head + line.len() + 140) as u64).next_multiple_of(2));
        let ifds = chain(&n, n.first());
        check_levels(&file, &s, &ifds, |l, x, y| raw_tile(&s, l, x, y));
        let last_ifd = ifds.last().unwrap().at;
        let mut previous = last_ifd;
        for k in (0..s.layout.lod_count as usize).rev() {
            assert!(k == 0 || ifds[k].at > ifds[k - 1].at, "IFDs in level order");
            for (&o, &c) in ifds[k].all(324).iter().zip(ifds[k].all(325)) {
                assert!(o > previous, "level {k}: tile at {o}, not after the one before at {previous}");
                let (o, c) = (o as usize, c as usize);
                assert_eq!(u32::from_le_bytes(file[o - 4..o].try_into().unwrap()) as usize, c, "leader");
                assert_eq!(file[o + c..o + c + 4], file[o + c - 4..o + c], "trailer");
                previous = o as u64;
            }
        }
        let (o, c) = (ifds[0].all(324), ifds[0].all(325));
        assert_eq!(o.last().unwrap() + c.last().unwrap() + 4, file.len() as u64, "level 0's last tile ends the file");
    }
}

/// A COG through the sink: nothing left beside it (the staging file is gone), and a later run
/// knows it for ours by its first IFD's Software tag (its byte 16 is GDAL's ghost area).
#[test]
fn a_cog_leaves_no_staging_file_and_is_recognised_as_ours() {
    use crate::sink::TileSink;
    let dir = tempfile::tempdir().unwrap();
    let dest = dir.path().join("a.cog.tif");
    let s = spec(Flavour::Cog, 40, 20, 2, grey8(), Compression::None);
    drop(TiffSink::create(&dest, s.clone()).unwrap());
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0, "a dropped COG sink leaves nothing");
    let sink = TiffSink::create(&dest, s.clone()).unwrap();
    for level in (0..2).rev() {
        let (c, r) = grid(&s, level);
        for y in 0..r {
            for x in 0..c {
                sink.write_tile(level, x, y, &raw_tile(&s, level, x, y)).unwrap();
            }
        }
    }
    let summary = sink.finish().unwrap();
    assert_eq!(summary.file_bytes, std::fs::metadata(&dest).unwrap().len());
    let names: Vec<_> = std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert_eq!(names, ["a.cog.tif"]);
    let claim = crate::output::claim(&dest, crate::output::Product::Tiff, &[], false).unwrap();
    assert_eq!(claim.replaces, Some(crate::output::Existing::Ours));
}

/// `s` with `names` as grey planes, colours where given.
fn planar(mut s: Spec, channels: &[(&str, Option<u32>)]) -> Spec {
    s.channels = (channels.iter()).map(|(n, c)| OmeChannel { name: Some(n.to_string()), colour: *c }).collect();
    s.planar = true;
    s
}

/// A plane's tile: `raw_tile`'s, told apart by its plane.
fn plane_tile(s: &Spec, p: u32, level: u32, x: u32, y: u32) -> Vec<u8> {
    raw_tile(s, level, x, y).into_iter().map(|b| b.wrapping_add(p as u8 * 101)).collect()
}

/// An OME-TIFF of planes, as bioformats and raw2ometiff write more channels than a pixel
/// holds: plane `c` is the `c`th main IFD, its reduced levels its SubIFDs; the OME-XML (first
/// IFD only) says one channel of one sample a plane, with its name and colour, and a
/// `TiffData` mapping IFD `c` to channel `c`. Tiles come plane after plane, as the passes run.
#[test]
fn an_ome_tiff_of_planes_chains_a_main_ifd_a_channel() {
    for big in [BigTiff::Auto, BigTiff::Always] {
        let grey16 = PixelLayout::new(Channels::Grey, Depth::U16);
        let base = Spec { bigtiff: big, ..spec(Flavour::Ome, 40, 20, 3, grey16, Compression::None) };
        let s = planar(base, &[("DAPI", Some(0x0000_FFFF)), ("G&FP", None), ("c2", Some(0xFF00_00FF))]);
        assert_eq!((s.planes(), s.total_tiles()), (3, 3 * s.plane_tiles()));
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.ome.tif");
        let mut w = TiffWriter::create(&path, std::fs::File::create(&path).unwrap(), s.clone()).unwrap();
        for p in 0..3 {
            for level in 0..3 {
                let (c, r) = grid(&s, level);
                for y in 0..r {
                    for x in 0..c {
                        w.add_plane_tile(p, level, x, y, &plane_tile(&s, p, level, x, y)).unwrap();
                    }
                }
            }
        }
        let e = w.add_plane_tile(3, 0, 0, 0, &[1]).unwrap_err().to_string();
        assert!(e.contains("plane 3: the TIFF has 3 plane(s)"), "{e}");
        let summary = w.finish().unwrap();
        assert_eq!((summary.planes, summary.tiles), (3, s.total_tiles()));
        let file = std::fs::read(&path).unwrap();
        let n = open(&file);
        assert_eq!(n.big, big == BigTiff::Always);
        let main = chain(&n, n.first());
        assert_eq!(main.len(), 3, "one main IFD a plane");
        for (p, ifd) in main.iter().enumerate() {
            let mut levels = vec![n.ifd(ifd.at)];
            levels.extend(ifd.all(330).iter().map(|&at| n.ifd(at)));
            check_levels(&file, &s, &levels, |l, x, y| plane_tile(&s, p as u32, l, x, y));
            assert!(levels.iter().all(|l| l.one(277) == 1 && l.all(258) == [16] && l.one(262) == 1));
            assert_eq!(ifd.tags.contains_key(&270), p == 0, "OME-XML in the first IFD only");
        }
        let xml = main[0].text(270);
        for want in [
            r#"SizeC="3""#,
            r#"Type="uint16""#,
            r#"Interleaved="false""#,
            r#"<Channel ID="Channel:0:0" Name="DAPI" Color="65535" SamplesPerPixel="1">"#,
            r#"<Channel ID="Channel:0:1" Name="G&amp;FP" SamplesPerPixel="1">"#,
            r#"<Channel ID="Channel:0:2" Name="c2" Color="-16776961" SamplesPerPixel="1">"#,
            r#"<TiffData IFD="0" FirstC="0" FirstZ="0" FirstT="0" PlaneCount="1"/>"#,
            r#"<TiffData IFD="2" FirstC="2" FirstZ="0" FirstT="0" PlaneCount="1"/></Pixels>"#,
        ] {
            assert!(xml.contains(want), "{want} in {xml}");
        }
    }
}

/// A plane never written is named with its plane; planes only in an OME-TIFF, of grey
/// samples; an interleaved image is one OME channel, named where the source names it.
#[test]
fn planes_are_checked_and_one_interleaved_channel_is_named_only_where_known() {
    let s = planar(spec(Flavour::Ome, 40, 20, 2, grey8(), Compression::None), &[("a", None), ("b", None)]);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("t.ome.tif");
    let mut w = TiffWriter::create(&path, std::fs::File::create(&path).unwrap(), s.clone()).unwrap();
    for level in 0..2 {
        let (c, r) = grid(&s, level);
        for (x, y) in (0..r).flat_map(|y| (0..c).map(move |x| (x, y))) {
            w.add_plane_tile(0, level, x, y, &raw_tile(&s, level, x, y)).unwrap();
        }
    }
    let e = w.finish().unwrap_err().to_string();
    assert!(e.contains("tile (plane 1, level 0, x 0, y 0) was never written"), "{e}");
    let rgb = PixelLayout::new(Channels::Rgb, Depth::U8);
    for (s, want) in [
        (planar(spec(Flavour::Generic, 40, 20, 1, grey8(), Compression::None), &[("a", None)]), "only an OME-TIFF"),
        (planar(spec(Flavour::Cog, 40, 20, 1, grey8(), Compression::None), &[("a", None)]), "--channels"),
        (planar(spec(Flavour::Ome, 40, 20, 1, rgb, Compression::None), &[("a", None)]), "grey pyramids"),
        (planar(spec(Flavour::Ome, 40, 20, 1, grey8(), Compression::None), &[("a\0", None)]), "NUL"),
        (planar(spec(Flavour::Ome, 40, 20, 1, grey8(), Compression::None), &[]), "0 planes"),
    ] {
        let e = s.check().unwrap_err().to_string();
        assert!(e.contains(want), "{e:?} lacks {want:?}");
    }
    // Interleaved RGB: one channel of three samples; unnamed as before, or named.
    let mut s = spec(Flavour::Ome, 40, 20, 1, rgb, Compression::None);
    let unnamed = ome::xml(&s, &[]);
    assert!(unnamed.contains(r#"<Channel ID="Channel:0:0" SamplesPerPixel="3"><LightPath/></Channel>"#), "{unnamed}");
    assert!(!unnamed.contains("Color="));
    s.channels = vec![OmeChannel { name: Some("H&E".into()), colour: None }];
    let named = ome::xml(&s, &[]);
    assert!(named.contains(r#"<Channel ID="Channel:0:0" Name="H&amp;E" SamplesPerPixel="3">"#), "{named}");
    s.channels.push(OmeChannel::default());
    assert!(s.check().unwrap_err().to_string().contains("one OME channel"));
}

/// A generic pyramid's associated images follow its levels in the chain, one deflated strip
/// each, grey or RGB, of odd sizes: the `tiff` crate (a decoder of its own, not ours) reads
/// each page's samples back exactly, with its one-word description and `NewSubfileType` 1.
#[test]
fn associated_images_follow_the_levels_and_decode_to_their_samples() {
    use crate::source::associated::{Kind, Pixels};
    let s = spec(Flavour::Generic, 20, 18, 2, grey8(), Compression::Deflate { level: 6 });
    let samples = |w: u32, h: u32, c: usize| -> Vec<u8> {
        (0..w as usize * h as usize * c).map(|i| (i * 37 % 251) as u8).collect()
    };
    let images = [
        (
            Kind::Label,
            Pixels { width: 37, height: 23, channels: Channels::Grey, samples: samples(37, 23, 1), lossy: Vec::new() },
        ),
        (
            Kind::Overview,
            Pixels { width: 50, height: 11, channels: Channels::Rgb, samples: samples(50, 11, 3), lossy: Vec::new() },
        ),
    ];
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("t.tif");
    let mut w = TiffWriter::create(&path, std::fs::File::create(&path).unwrap(), s.clone()).unwrap();
    for level in 0..2 {
        let (c, r) = grid(&s, level);
        for (x, y) in (0..r).flat_map(|y| (0..c).map(move |x| (x, y))) {
            let tile = raw_tile(&s, level, x, y);
            let encoder = crate::codec::TileEncoder::<u8>::new(s.codec().unwrap(), grey8(), false, None, 16, vec![]);
            let mut out = Vec::new();
            encoder.unwrap().encode(&tile, &mut out).unwrap();
            w.add_plane_tile(0, level, x, y, &out).unwrap();
        }
    }
    for (kind, pixels) in images.iter().cloned() {
        w.add_associated(kind, pixels).unwrap();
    }
    w.finish().unwrap();

    let mut decoder = tiff::decoder::Decoder::new(std::fs::File::open(&path).unwrap()).unwrap();
    for (page, (kind, pixels)) in images.iter().enumerate().map(|(k, i)| (k + 2, i)) {
        decoder.seek_to_image(page).unwrap();
        assert_eq!(decoder.dimensions().unwrap(), (pixels.width, pixels.height), "page {page}");
        let description = decoder.get_tag_ascii_string(tiff::tags::Tag::ImageDescription).unwrap();
        assert_eq!(description, associated::word(*kind));
        assert_eq!(decoder.get_tag_u32(tiff::tags::Tag::NewSubfileType).unwrap(), 1);
        let tiff::decoder::DecodingResult::U8(got) = decoder.read_image().unwrap() else { panic!("8-bit samples") };
        assert_eq!(got, pixels.samples, "page {page}: the {kind:?}'s samples");
    }
    assert!(!decoder.more_images(), "nothing after the associated images");
}
