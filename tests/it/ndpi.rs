//! Hamamatsu NDPI: each level one baseline JPEG in one TIFF strip, cut by restart markers,
//! read a band of restart intervals at a time and checked against OpenSlide 3.4.1.
//!
//! The test slides are made as the scanner makes them: each restart interval (a run of MCUs
//! within one MCU row) encoded with the same tables, their entropy-coded data joined with
//! RST0..RST7 between them under one header with a DRI segment, so the JPEG can be wider than
//! libjpeg can encode (65535); the TIFF around it carries the tags OpenSlide's NDPI reader wants
//! (Software `NDP.scan`, 65420 format flag, 65421 source lens, 65424 focal plane, 65426
//! interval offsets,
//! RowsPerStrip = ImageLength). OpenSlide decodes each interval with libjpeg-turbo as we do, so
//! the texels must be equal (tolerance 0).

use std::io::{Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use crate::common::cli::{self, s};
use crate::common::compare::{Picture, Tolerance, assert_close};
use crate::tiff_slides::{openslide_region, our_texels};
use vortex_tiler::limits::Budget;
use vortex_tiler::source;

/// Chroma subsampling of a test slide: its MCU's width and height.
#[derive(Clone, Copy)]
enum Chroma {
    /// 4:4:4, 8x8 MCUs.
    Full,
    /// 4:2:2, 16x8 MCUs.
    Half,
    /// 4:2:0, 16x16 MCUs.
    Quarter,
}

impl Chroma {
    fn mcu(self) -> (u32, u32) {
        match self {
            Chroma::Full => (8, 8),
            Chroma::Half => (16, 8),
            Chroma::Quarter => (16, 16),
        }
    }

    fn factor(self) -> jpeg_encoder::SamplingFactor {
        match self {
            Chroma::Full => jpeg_encoder::SamplingFactor::F_1_1,
            Chroma::Half => jpeg_encoder::SamplingFactor::F_2_1,
            Chroma::Quarter => jpeg_encoder::SamplingFactor::F_2_2,
        }
    }
}

/// The test picture at (x, y): ramps, a hard diagonal and noisy blocks; defined past the
/// image too (the padding of edge MCUs).
fn texel(x: u32, y: u32) -> [u8; 3] {
    let noise = (x.wrapping_mul(2_654_435_761) ^ y.wrapping_mul(40_503)).rotate_left(7) % 40;
    let noisy = (x / 32 + y / 32).is_multiple_of(3);
    let n = if noisy { noise } else { 0 };
    [((x / 3) % 256) as u8, ((y * 2 + n) % 256) as u8, if x > y { 200 } else { (40 + n) as u8 }]
}

/// How the frame header states the size.
#[derive(Clone, Copy, PartialEq)]
enum Sof {
    /// The image's size.
    Size,
    /// 0 by 0, as NDPI writes it for a JPEG wider or taller than 65535.
    Zero,
}

/// How the TIFF around the strip is laid out.
#[derive(Clone, Copy)]
struct Layout {
    /// NDPI's 64-bit layout (8-byte directory offsets, each entry's high 32 bits after the
    /// directory), as Hamamatsu writes it; otherwise plain classic TIFF.
    wide: bool,
    /// The restart-interval offset table (tag 65426).
    table: bool,
    /// Where the strip lies (after the directory where `None`); the file is written sparse.
    strip_at: Option<u64>,
    /// Two restart intervals (numbered in strip order) whose pictures are exchanged: what a
    /// reader that misplaces intervals would show of a good file, to prove the checks see it.
    swapped: Option<(u32, u32)>,
}

const CLASSIC: Layout = Layout { wide: false, table: true, strip_at: None, swapped: None };

/// An NDPI file of `width` x `height` texels with restart intervals `interval` texels wide.
fn make_ndpi(path: &Path, width: u32, height: u32, interval: u32, chroma: Chroma, sof: Sof) {
    make_ndpi_laid_out(path, (width, height), interval, chroma, sof, CLASSIC);
}

fn make_ndpi_laid_out(
    path: &Path,
    (width, height): (u32, u32),
    interval: u32,
    chroma: Chroma,
    sof: Sof,
    layout: Layout,
) {
    let (mcu_w, mcu_h) = chroma.mcu();
    let across = width.div_ceil(mcu_w).div_ceil(interval / mcu_w);
    let down = height.div_ceil(mcu_h);
    let mut header = Vec::new();
    let mut strip = Vec::new();
    let mut starts = Vec::new();
    for row in 0..down {
        for col in 0..across {
            let n = row * across + col;
            let shown = match layout.swapped {
                Some((a, b)) if n == a => b,
                Some((a, b)) if n == b => a,
                _ => n,
            };
            let (from_row, from_col) = (shown / across, shown % across);
            let mut tile = Vec::with_capacity((interval * mcu_h * 3) as usize);
            for y in 0..mcu_h {
                for x in 0..interval {
                    tile.extend_from_slice(&texel(from_col * interval + x, from_row * mcu_h + y));
                }
            }
            let mut jpeg = Vec::new();
            let mut encoder = jpeg_encoder::Encoder::new(&mut jpeg, 85);
            encoder.set_sampling_factor(chroma.factor());
            encoder.set_restart_interval((interval / mcu_w) as u16);
            encoder.encode(&tile, interval as u16, mcu_h as u16, jpeg_encoder::ColorType::Rgb).unwrap();
            let data_at = scan_data(&jpeg);
            if header.is_empty() {
                header = jpeg[..data_at].to_vec();
                strip.extend_from_slice(&header);
            } else {
                assert_eq!(jpeg[..data_at], header[..], "every interval is encoded with the same tables");
                let n = (row * across + col - 1) % 8;
                strip.extend_from_slice(&[0xFF, 0xD0 + n as u8]);
            }
            starts.push(strip.len() as u32);
            strip.extend_from_slice(&jpeg[data_at..jpeg.len() - 2]);
        }
    }
    strip.extend_from_slice(&[0xFF, 0xD9]);
    // The frame header's size: SOF0's height and width.
    let sof_at = strip.windows(2).position(|w| w == [0xFF, 0xC0]).unwrap();
    let (w, h) = match sof {
        Sof::Size => (width as u16, height as u16),
        Sof::Zero => (0, 0),
    };
    strip[sof_at + 5..sof_at + 7].copy_from_slice(&h.to_be_bytes());
    strip[sof_at + 7..sof_at + 9].copy_from_slice(&w.to_be_bytes());
    let (head, strip_at) = tiff(width, height, &strip, &starts, layout);
    let mut file = std::fs::File::create(path).unwrap();
    file.write_all(&head).unwrap();
    // Seeking past the end leaves a hole: a strip past 4 GiB costs no disk.
    file.seek(SeekFrom::Start(strip_at)).unwrap();
    file.write_all(&strip).unwrap();
}

/// Where the entropy-coded data of a JPEG starts (after its SOS segment).
fn scan_data(jpeg: &[u8]) -> usize {
    let mut at = 2;
    loop {
        let len = u16::from_be_bytes([jpeg[at + 2], jpeg[at + 3]]) as usize;
        if jpeg[at + 1] == 0xDA {
            return at + 2 + len;
        }
        at += 2 + len;
    }
}

/// A little-endian TIFF of one directory holding `strip` as NDPI lays it out: the directory
/// first, then its values, then (where `layout` does not place it) the strip. Returns the bytes
/// before the strip and where the strip goes.
fn tiff(width: u32, height: u32, strip: &[u8], starts: &[u32], layout: Layout) -> (Vec<u8>, u64) {
    const SHORT: u16 = 3;
    const LONG: u16 = 4;
    let le16 = |v: u16| v.to_le_bytes().to_vec();
    let le32 = |v: u32| v.to_le_bytes().to_vec();
    let mut entries: Vec<(u16, u16, u32, Vec<u8>)> = vec![
        (256, LONG, 1, le32(width)),
        (257, LONG, 1, le32(height)),
        (258, SHORT, 3, [le16(8), le16(8), le16(8)].concat()),
        (259, SHORT, 1, le16(7)),
        (262, SHORT, 1, le16(6)),
        (273, LONG, 1, le32(0)), // the strip's offset, known below
        (277, SHORT, 1, le16(3)),
        (278, LONG, 1, le32(height)),
        (279, LONG, 1, le32(strip.len() as u32)),
        (305, 2, 9, b"NDP.scan\0".to_vec()),
        (65420, LONG, 1, le32(1)),
        (65421, 11, 1, 20f32.to_le_bytes().to_vec()),
        (65424, 9, 1, le32(0)), // focal plane 0
        (65426, LONG, starts.len() as u32, starts.iter().flat_map(|s| s.to_le_bytes()).collect()),
    ];
    entries.retain(|e| layout.table || e.0 != 65426);
    entries.sort_by_key(|e| e.0);
    // The wide layout's header offset, next-directory offset and high words are wider.
    let (ifd_at, next_len, highs_len) = if layout.wide { (16, 8, 4 * entries.len()) } else { (8, 4, 0) };
    let mut extra_at = ifd_at + 2 + entries.len() * 12 + next_len + highs_len;
    let extra_len: usize = entries.iter().map(|e| if e.3.len() > 4 { e.3.len() } else { 0 }).sum();
    let strip_at = layout.strip_at.unwrap_or(((extra_at + extra_len + 1) & !1) as u64);
    entries.iter_mut().find(|e| e.0 == 273).unwrap().3 = le32(strip_at as u32);
    let mut out = b"II*\0".to_vec();
    out.extend_from_slice(&le32(ifd_at as u32));
    out.resize(ifd_at, 0);
    let mut extra = Vec::new();
    let mut highs = Vec::new();
    out.extend_from_slice(&le16(entries.len() as u16));
    for (tag, kind, count, value) in &entries {
        // Only the strip's offset has high bits here (the values lie near the directory).
        highs.extend_from_slice(&le32(if *tag == 273 { (strip_at >> 32) as u32 } else { 0 }));
        out.extend_from_slice(&le16(*tag));
        out.extend_from_slice(&le16(*kind));
        out.extend_from_slice(&le32(*count));
        if value.len() <= 4 {
            let mut inline = value.clone();
            inline.resize(4, 0);
            out.extend_from_slice(&inline);
        } else {
            out.extend_from_slice(&le32(extra_at as u32));
            extra.extend_from_slice(value);
            extra_at += value.len();
        }
    }
    out.resize(out.len() + next_len, 0);
    if layout.wide {
        out.extend_from_slice(&highs);
    }
    out.extend_from_slice(&extra);
    assert!(strip_at as usize >= out.len());
    (out, strip_at)
}

/// The largest bias, `|mean(ours - picture)|` of one channel over one 16x16 block (one 4:2:0
/// MCU, aligned; those at the right and bottom edges cut), that JPEG at quality 85 of this
/// picture may leave. JPEG keeps a block's mean well (its DC is quantised finely) even where
/// single samples are far off (the noise wraps green round from 255 to 0, which JPEG smooths:
/// samples off by 44 on average in such a block, with no bias); an interval in the wrong place
/// shows another part of the ramps, whose means differ by tens of levels. Both figures are
/// printed by the test. Only blocks whose picture stays within 16..=239 in every channel are
/// weighed: near 0 and 255 JPEG's ringing is clamped, which biases a block's mean by itself
/// (24 levels in a block where the noise wraps green round, measured).
const WORST_BLOCK: f64 = 12.0;

/// The 16x16 block and channel of RGB `a` and `b` (`width` x `height`) with the largest bias,
/// of the blocks whose test picture stays clear of 0 and 255: (|mean of a - b|, x, y).
fn worst_block(a: &[u8], b: &[u8], width: u32, height: u32) -> (f64, u32, u32) {
    assert_eq!((a.len(), b.len()), ((width * height * 3) as usize, (width * height * 3) as usize));
    let mut worst = (0.0, 0, 0);
    for by in (0..height).step_by(16) {
        for bx in (0..width).step_by(16) {
            let (mut sums, mut n) = ([0i64; 3], 0i64);
            let clear = |x: u32, y: u32| texel(x, y).iter().all(|v| (16..=239).contains(v));
            if !(by..(by + 16).min(height)).all(|y| (bx..(bx + 16).min(width)).all(|x| clear(x, y))) {
                continue;
            }
            for y in by..(by + 16).min(height) {
                for x in bx..(bx + 16).min(width) {
                    let at = ((y * width + x) * 3) as usize;
                    for (ch, sum) in sums.iter_mut().enumerate() {
                        *sum += i64::from(a[at + ch]) - i64::from(b[at + ch]);
                    }
                    n += 1;
                }
            }
            for sum in sums {
                let bias = (sum as f64 / n as f64).abs();
                if bias > worst.0 {
                    worst = (bias, bx, by);
                }
            }
        }
    }
    worst
}

/// The top-left `width` x `height` of an image `stride` texels wide.
fn crop(texels: &[u8], stride: u32, width: u32, height: u32) -> Vec<u8> {
    let row = (stride * 3) as usize;
    texels.chunks_exact(row).take(height as usize).flat_map(|r| &r[..(width * 3) as usize]).copied().collect()
}

fn slide(dir: &Path, name: &str, (width, height): (u32, u32), interval: u32, chroma: Chroma, sof: Sof) -> PathBuf {
    let path = dir.join(name);
    make_ndpi(&path, width, height, interval, chroma, sof);
    path
}

/// An NDPI slide reads as OpenSlide reads it (4:4:4 and 4:2:2; OpenSlide cannot read 4:2:0
/// slides: it decodes an interval with the frame's height, and libjpeg's 4:2:0 upsampling then
/// wants the MCU row below, past the interval's end), ragged edges too (OpenSlide shows only
/// whole intervals: the ragged column and row, and the 4:2:0 slide, are checked against the
/// picture, within JPEG's loss at quality 85); `split` takes it.
#[test]
fn ndpi_reads_as_openslide_does() {
    let dir = tempfile::tempdir().unwrap();
    let mut even_half = Vec::new();
    for (name, chroma, interval, height) in
        [("full.ndpi", Chroma::Full, 128, 480), ("half.ndpi", Chroma::Half, 256, 504)]
    {
        let even = slide(dir.path(), name, (1024, height), interval, chroma, Sof::Size);
        let (source, ours) = our_texels(&even, 1 << 30);
        let describe = source.describe();
        let intervals = format!("restart interval ({interval}x8 intervals, {} to an MCU row", 1024 / interval);
        for needle in ["Hamamatsu NDPI, page 0 of 1", &intervals, "YCbCr"] {
            assert!(describe.contains(needle), "{needle:?} missing from {describe}");
        }
        if let Some(theirs) = openslide_region(&even, "hamamatsu", Some((1024, height))) {
            assert!(ours == theirs, "{name} differs from OpenSlide");
        }
        even_half = ours;
    }
    // 1020 x 500: the last interval of a row reaches 4 texels past the image, the last MCU row
    // 4 rows past it.
    let ragged = slide(dir.path(), "ragged.ndpi", (1020, 500), 256, Chroma::Half, Sof::Size);
    let (_, ours) = our_texels(&ragged, 1 << 30);
    assert_eq!(ours.len(), 1020 * 500 * 3);
    // Its intervals are those of the even 4:2:2 slide (1024 x 504), cropped. (OpenSlide 3.4.1
    // misplaces them: it counts 1020 / 256 = 3 intervals to a row, where the JPEG has 4.)
    assert!(ours == crop(&even_half, 1024, 1020, 500), "the ragged slide differs from the even one, cropped");
    let picture: Vec<u8> = (0..500).flat_map(|y| (0..1020).flat_map(move |x| texel(x, y))).collect();
    // JPEG at quality 85 on this picture (a third of it noise of up to 40 levels) is off by 3.5
    // on average (measured); a misplaced interval or row is off by tens.
    let jpeg = Tolerance::mean(6.0, "JPEG at quality 85 of a picture a third noise is off by 3.5 on average");
    let against_picture = |name: &str, ours: &[u8]| {
        assert_close(name, Picture::new(1020, 500, 3, ours), Picture::new(1020, 500, 3, &picture), jpeg);
        // A mean over the whole picture hides one misplaced interval (256 x 16 texels of
        // 1020 x 500: under 1% of it); the most biased 16x16 block does not. JPEG's loss
        // stays within WORST_BLOCK on every block, a misplaced interval is far past it.
        let (worst, x, y) = worst_block(ours, &picture, 1020, 500);
        eprintln!("{name}: the most biased 16x16 block, at ({x}, {y}), is off by {worst:.2} on average");
        assert!(worst < WORST_BLOCK, "{name}: the 16x16 block at ({x}, {y}) is off by {worst:.1} on average");
    };
    against_picture("ndpi-ragged", &ours);
    let quarter = slide(dir.path(), "quarter.ndpi", (1020, 500), 256, Chroma::Quarter, Sof::Size);
    let (source, quartered) = our_texels(&quarter, 1 << 30);
    assert!(source.describe().contains("256x16 intervals"), "{}", source.describe());
    against_picture("ndpi-4:2:0", &quartered);
    // The same 4:2:0 slide with two intervals of MCU row 5 exchanged, as a reader placing
    // restart intervals wrongly would show it: the whole-picture mean still passes, the worst
    // block does not.
    let misplaced = dir.path().join("misplaced.ndpi");
    let swapped = Layout { swapped: Some((5 * 4, 5 * 4 + 2)), ..CLASSIC };
    make_ndpi_laid_out(&misplaced, (1020, 500), 256, Chroma::Quarter, Sof::Size, swapped);
    let (_, wrong) = our_texels(&misplaced, 1 << 30);
    let (_, mean) = crate::common::compare::differences(&wrong, &picture);
    assert!(mean < 6.0, "the mean alone ({mean:.2}) would have caught it");
    let (worst, x, y) = worst_block(&wrong, &picture, 1020, 500);
    eprintln!("two exchanged intervals: mean {mean:.2}, the worst block, at ({x}, {y}), off by {worst:.2}");
    assert!(worst > 2.0 * WORST_BLOCK, "a misplaced interval is off by only {worst:.1} at ({x}, {y})");
    // Through the tool: split, then convert of a column range (only those intervals decoded).
    let out = dir.path().join("tiles");
    let summary = cli::ok(&["split", s(&ragged), "-o", s(&out), "--tile-size", "256"]);
    assert!(summary.contains("Hamamatsu NDPI"), "{summary}");
    let dzi = dir.path().join("slide.dzi");
    cli::ok(&["split", s(&ragged), "-o", s(&dzi), "--layout", "dzi", "--tile-size", "256", "--overlap", "0"]);
    let mut columns = source::open(&ragged, Budget::new(1 << 30)).unwrap();
    assert!(columns.read_columns(300..700));
    columns.skip_rows(100).unwrap();
    let mut row = vec![0u8; 400 * 3];
    for y in 100..500usize {
        columns.read_row(&mut row).unwrap();
        assert!(row[..] == ours[(y * 1020 + 300) * 3..][..400 * 3], "row {y}");
    }
}

/// Wider than a JPEG header can say: NDPI writes 0 for the frame's size and the TIFF holds
/// it; read as OpenSlide reads it.
#[test]
fn an_ndpi_wider_than_65535_is_read() {
    let dir = tempfile::tempdir().unwrap();
    let wide = slide(dir.path(), "wide.ndpi", (70_144, 32), 512, Chroma::Half, Sof::Zero);
    let (source, ours) = our_texels(&wide, 1 << 30);
    assert_eq!((source.width(), source.height()), (70_144, 32));
    if let Some(theirs) = openslide_region(&wide, "hamamatsu", Some((70_144, 32))) {
        assert!(ours == theirs, "differs from OpenSlide");
    }
}

/// A slide larger than --max-memory is read a band of MCU rows at a time, the same texels as
/// with memory to spare, and split within the bound; below one MCU row it is refused, saying so.
#[test]
fn an_ndpi_larger_than_max_memory_streams() {
    let dir = tempfile::tempdir().unwrap();
    // 131 MiB decoded; one MCU row (8 rows) is 1.6 MiB, its bound with compressed data 8.2 MiB.
    let big = slide(dir.path(), "big.ndpi", (71_680, 640), 1024, Chroma::Half, Sof::Zero);
    let (_, roomy) = our_texels(&big, 1 << 30);
    let (_, tight) = our_texels(&big, 24 << 20);
    assert!(roomy == tight);
    let err = source::open(&big, Budget::new(4 << 20)).err().expect("refused").to_string();
    for needle in ["big.ndpi", "--max-memory", "one MCU row"] {
        assert!(err.contains(needle), "{needle:?} missing from: {err}");
    }
    let out = dir.path().join("out");
    cli::ok(&["split", s(&big), "-o", s(&out), "--max-memory", "100M", "--tile-size", "512"]);
}

/// A truncated slide, a restart marker out of order and one missing are errors naming the
/// file and the interval, whether the intervals are located by the offset table or found by
/// scanning; never a panic or wrong texels.
#[test]
fn damaged_ndpi_names_the_interval() {
    damaged_ndpi(CLASSIC);
    damaged_ndpi(Layout { table: false, ..CLASSIC });
}

fn damaged_ndpi(layout: Layout) {
    let dir = tempfile::tempdir().unwrap();
    let good = dir.path().join("good.ndpi");
    make_ndpi_laid_out(&good, (1024, 48), 256, Chroma::Half, Sof::Size, layout);
    let bytes = std::fs::read(&good).unwrap();
    let read = |name: &str, data: &[u8]| -> String {
        let path = dir.path().join(name);
        std::fs::write(&path, data).unwrap();
        let result = source::open(&path, Budget::new(1 << 30)).and_then(|mut source| {
            let mut row = vec![0u8; source.width() as usize * 3];
            (0..source.height()).try_for_each(|_| source.read_row(&mut row))
        });
        let err = result.err().unwrap_or_else(|| panic!("{name}: no error")).to_string();
        assert!(err.contains(name), "{err}");
        err
    };
    // The strip's markers: RST3 (closing interval 3) becomes RST5.
    let strip_at = bytes.windows(3).position(|w| w == [0xFF, 0xD8, 0xFF]).unwrap();
    let data = strip_at + scan_data(&bytes[strip_at..]);
    let rst3 = data + bytes[data..].windows(2).position(|w| w == [0xFF, 0xD3]).unwrap();
    let mut swapped = bytes.clone();
    swapped[rst3 + 1] = 0xD5;
    let err = read("swapped.ndpi", &swapped);
    for needle in ["restart interval 3 (column 3 of MCU row 0)", "RST5 found where RST3 was due"] {
        assert!(err.contains(needle), "{needle:?} missing from: {err}");
    }
    // The second half of the strip zeroed: no marker comes where one is due.
    let half = strip_at + (bytes.len() - strip_at) / 2;
    let mut zeroed = bytes.clone();
    zeroed[half..].fill(0);
    let err = read("zeroed.ndpi", &zeroed);
    assert!(err.contains("JPEG restart interval"), "{err}");
    // Cut short: in its directory, in the JPEG header, in the strip.
    for keep in [4, 100, strip_at + 100, half] {
        let err = read("truncated.ndpi", &bytes[..keep]);
        assert!(err.contains("truncat"), "{err}");
    }
    // Any byte changed: an error naming the file, or texels (a changed coefficient), never a
    // panic.
    let path = dir.path().join("mutated.ndpi");
    let mut state = 12345u32;
    for at in (0..bytes.len()).step_by(11) {
        state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        let mut mutated = bytes.clone();
        mutated[at] ^= (state >> 24) as u8 | 1;
        std::fs::write(&path, &mutated).unwrap();
        let result = source::open(&path, Budget::new(64 << 20)).and_then(|mut source| {
            let mut row = vec![0u8; source.width() as usize * source.layout().bytes_per_pixel()];
            (0..source.height()).try_for_each(|_| source.read_row(&mut row))
        });
        if let Err(e) = result {
            assert!(e.to_string().contains("mutated.ndpi"), "{e}");
        }
    }
}

/// The offset table (tag 65426) locates the intervals: the same texels as scanning for the
/// markers finds, the summary saying which was done; a table of the wrong length is passed over
/// (scanning instead), and one that puts an interval where its marker is not is an error naming
/// the file and the interval.
#[test]
fn the_offset_table_locates_intervals_and_is_checked() {
    let dir = tempfile::tempdir().unwrap();
    let laid_out = |name: &str, layout: Layout| {
        let path = dir.path().join(name);
        make_ndpi_laid_out(&path, (1024, 48), 256, Chroma::Half, Sof::Size, layout);
        path
    };
    let with_table = laid_out("table.ndpi", CLASSIC);
    let (source, tabled) = our_texels(&with_table, 1 << 30);
    assert!(source.describe().contains("located by its offset table"), "{}", source.describe());
    let without = laid_out("scan.ndpi", Layout { table: false, ..CLASSIC });
    let (source, scanned) = our_texels(&without, 1 << 30);
    assert!(source.describe().contains("found by scanning (no offset table (tag 65426))"), "{}", source.describe());
    assert!(tabled == scanned, "the table and the scan find different intervals");
    // The table's directory entry: tag 65426, LONG, 24 intervals (4 across, 6 MCU rows of 8).
    let bytes = std::fs::read(&with_table).unwrap();
    let entry = bytes.windows(8).position(|w| w[..4] == [0x92, 0xFF, 4, 0] && w[4..] == 24u32.to_le_bytes());
    let entry = entry.expect("the table's directory entry");
    let table_at = u32::from_le_bytes(bytes[entry + 8..entry + 12].try_into().unwrap()) as usize;
    // A count of 23 does not fit the JPEG: the strip is scanned.
    let mut short = bytes.clone();
    short[entry + 4] = 23;
    let path = dir.path().join("short.ndpi");
    std::fs::write(&path, &short).unwrap();
    let (source, texels) = our_texels(&path, 1 << 30);
    assert!(source.describe().contains("not 24 LONGs"), "{}", source.describe());
    assert!(texels == tabled);
    // Interval 5 said to start 3 bytes late: interval 4 then ends where no RST4 is.
    let mut late = bytes.clone();
    let entry = table_at + 5 * 4;
    let start = u32::from_le_bytes(late[entry..entry + 4].try_into().unwrap());
    late[entry..entry + 4].copy_from_slice(&(start + 3).to_le_bytes());
    let path = dir.path().join("late.ndpi");
    std::fs::write(&path, &late).unwrap();
    let err = source::open(&path, Budget::new(1 << 30))
        .and_then(|mut source| {
            let mut row = vec![0u8; 1024 * 3];
            (0..48).try_for_each(|_| source.read_row(&mut row))
        })
        .expect_err("a table that disagrees with the markers is an error")
        .to_string();
    for needle in ["late.ndpi", "restart interval 4 (column 0 of MCU row 1)", "the table disagrees with the markers"] {
        assert!(err.contains(needle), "{needle:?} missing from: {err}");
    }
}

/// An NDPI file past 4 GiB, its strip beyond it, the offset's high 32 bits in the directory's
/// extension (NDPI's 64-bit layout): read as tifffile reads it, and as the same slide laid out
/// small. The file is sparse (a hole up to the strip), so it costs a few KiB of disk.
#[test]
fn an_ndpi_past_4_gib_is_read() {
    let dir = tempfile::tempdir().unwrap();
    let small = dir.path().join("small.ndpi");
    // 4:4:4, so that no chroma is upsampled: tifffile decodes the strip whole, upsampling across
    // the intervals' edges, where OpenSlide and this reader decode each interval alone.
    make_ndpi_laid_out(&small, (1024, 48), 256, Chroma::Full, Sof::Size, Layout { wide: true, ..CLASSIC });
    let big = dir.path().join("big.ndpi");
    let layout = Layout { wide: true, table: true, strip_at: Some((5 << 30) + 4096), swapped: None };
    make_ndpi_laid_out(&big, (1024, 48), 256, Chroma::Full, Sof::Size, layout);
    {
        use std::os::unix::fs::MetadataExt;
        let meta = std::fs::metadata(&big).unwrap();
        assert!(meta.len() > 5 << 30);
        // Where the file system cannot hold holes it holds all of it; the tempdir goes at the end.
        assert!(meta.blocks() * 512 < 1 << 30, "the test file is not sparse here: {} blocks", meta.blocks());
    }
    let (source, ours) = our_texels(&big, 1 << 30);
    assert!(source.describe().contains("located by its offset table"), "{}", source.describe());
    assert!(ours == our_texels(&small, 1 << 30).1, "the slide past 4 GiB differs from the same slide small");
    // tifffile reads NDPI's high words (and its offset table) as OpenSlide 4 does; Debian's
    // OpenSlide 3.4.1 guesses the high bits from the directory's offset instead (the data below
    // the directory), which does not hold for a directory placed first.
    if let Some(py) = crate::tiff_slides::venv_python() {
        let theirs = dir.path().join("theirs.rgb");
        let script = "import sys, tifffile\nopen(sys.argv[2], 'wb').write(tifffile.imread(sys.argv[1]).tobytes())";
        crate::tiff_slides::python(&py, script, &[s(&big), s(&theirs)]);
        assert!(ours == std::fs::read(&theirs).unwrap(), "differs from tifffile's reading");
    }
    let out = dir.path().join("tiles");
    let summary = cli::ok(&["split", s(&big), "-o", s(&out), "--tile-size", "256"]);
    assert!(summary.contains("Hamamatsu NDPI"), "{summary}");
    // The directory moved past 6 GiB (as Hamamatsu may write it, after the data): refused by
    // name, never read from the wrong bytes.
    let mut head = vec![0u8; 4096];
    std::fs::File::open(&big).unwrap().read_exact(&mut head).unwrap();
    let entries = u16::from_le_bytes([head[16], head[17]]) as usize;
    let directory = head[16..16 + 2 + 16 * entries + 8].to_vec();
    head[4..12].copy_from_slice(&(6u64 << 30).to_le_bytes());
    let far = dir.path().join("far.ndpi");
    let mut file = std::fs::File::create(&far).unwrap();
    file.write_all(&head).unwrap();
    file.seek(SeekFrom::Start(6 << 30)).unwrap();
    file.write_all(&directory).unwrap();
    drop(file);
    let err = source::open(&far, Budget::new(1 << 30)).err().expect("a directory past 4 GiB is refused").to_string();
    for needle in ["far.ndpi", "NDPI directory 0 lies at byte 6442450944, past 4 GiB"] {
        assert!(err.contains(needle), "{needle:?} missing from: {err}");
    }
}
