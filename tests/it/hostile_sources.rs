//! Hostile and damaged inputs to the source readers (issue 41): embedded profiles, OME-XML,
//! tiles in a zip, TIFF directories and tags that lie. Every input is built here; each case
//! says what it is refused with, or what the summary says, and where memory is the point, the
//! peak resident memory of the run as the kernel counts it.

use std::io::Write;
use std::path::{Path, PathBuf};

use tiff::encoder::{TiffEncoder, TiffKind, TiffKindBig, TiffKindStandard, colortype};
use tiff::tags::Tag;
use vortex_tiler::source::channels::ChannelSet;
use vortex_tiler::source::{self, OpenOptions, Pick};

use crate::common::cli::{fails_with, run, s};
use vortex_tiler::limits::Budget;

/// Runs the binary with `args`; its output and its peak resident memory in MiB (see
/// [`crate::common::cli::run_measuring_rss`]).
fn run_measured(args: &[&str]) -> (std::process::Output, f64) {
    let (out, bytes) = crate::common::cli::run_measuring_rss(args);
    (out, bytes as f64 / (1 << 20) as f64)
}

/// A PNG of `w x h` grey texels with `chunk` (type and data) spliced in after IHDR.
fn png_with_chunk(path: &Path, w: u32, h: u32, kind: &[u8; 4], data: &[u8]) {
    let mut plain = Vec::new();
    let mut encoder = png::Encoder::new(&mut plain, w, h);
    encoder.set_color(png::ColorType::Rgb);
    let mut writer = encoder.write_header().unwrap();
    writer.write_image_data(&vec![100u8; (w * h * 3) as usize]).unwrap();
    writer.finish().unwrap();
    // Signature (8) and IHDR (4 + 4 + 13 + 4).
    let mut bytes = plain[..33].to_vec();
    bytes.extend_from_slice(&(data.len() as u32).to_be_bytes());
    let mut crc = crc32fast::Hasher::new();
    crc.update(kind);
    crc.update(data);
    bytes.extend_from_slice(kind);
    bytes.extend_from_slice(data);
    bytes.extend_from_slice(&crc.finalize().to_be_bytes());
    bytes.extend_from_slice(&plain[33..]);
    std::fs::write(path, bytes).unwrap();
}

/// An iCCP chunk's data: a profile name, compression method `method`, then `stream`.
fn iccp(method: u8, stream: &[u8]) -> Vec<u8> {
    let mut data = b"profile\0".to_vec();
    data.push(method);
    data.extend_from_slice(stream);
    data
}

fn zlib(bytes: &[u8]) -> Vec<u8> {
    let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::fast());
    z.write_all(bytes).unwrap();
    z.finish().unwrap()
}

/// A PNG's iCCP profile inflating to 100 MiB is refused at the fixed cap (16 MiB) whatever
/// `--max-memory` is, and never inflated past it. Before, the png crate inflated it within
/// `--max-memory` (1 GiB here: RSS over 100 MiB) and, under a smaller budget, dropped it
/// without a word (exit 0, the texels taken as sRGB).
#[test]
fn a_png_profile_past_the_cap_is_refused_unread_whatever_the_budget() {
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("bomb.png");
    png_with_chunk(&png, 8, 8, b"iCCP", &iccp(0, &zlib(&vec![0u8; 100 << 20])));
    assert!(std::fs::metadata(&png).unwrap().len() < 1 << 20, "a small file");
    let out = dir.path().join("out");
    for budget in ["64M", "1G"] {
        let (output, peak) = run_measured(&["split", s(&png), "-o", s(&out), "--max-memory", budget]);
        fails_with(&output, &["bomb.png", "ICC profile (PNG iCCP chunk, inflated) holds more than the 16 MiB"]);
        // The binary alone (its libraries mapped, a thread pool) stays under 64 MiB here; the
        // profile is cut at 16 MiB; a 100 MiB inflation would be over the bound by itself.
        assert!(peak < 96.0, "--max-memory {budget}: peak RSS {peak:.1} MiB");
        assert!(!out.exists());
    }
}

/// A damaged iCCP chunk (not zlib data, an unknown method, no name, a CRC that fails) is an
/// error naming it, where the png crate dropped it and the texels went out as sRGB; a good one
/// is read.
#[test]
fn a_damaged_png_profile_is_an_error_not_srgb() {
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("damaged.png");
    let out = dir.path().join("out");
    for (data, says) in [
        (iccp(0, b"this is no zlib stream"), "is damaged: not zlib data"),
        (iccp(1, &zlib(b"x")), "is damaged: compression method 1"),
        (b"\0\0rest".to_vec(), "is damaged: no profile name"),
    ] {
        png_with_chunk(&png, 8, 8, b"iCCP", &data);
        fails_with(&run(&["split", s(&png), "-o", s(&out)]), &["damaged.png", "PNG iCCP chunk", says]);
    }
    // sRGB itself, as iCCP: read, found to be sRGB, left alone.
    let srgb = lcms2::Profile::new_srgb().icc().unwrap();
    let data = iccp(0, &zlib(&srgb));
    png_with_chunk(&png, 8, 8, b"iCCP", &data);
    let source = source::open_with(&png, OpenOptions::shown(Budget::new(1 << 30))).unwrap().source;
    assert!(source.describe().contains("is sRGB: left as is"), "{}", source.describe());
    let keep = OpenOptions { keep_icc: true, ..OpenOptions::shown(Budget::new(1 << 30)) };
    assert_eq!(source::open_with(&png, keep).unwrap().icc, Some(srgb));
    // The same chunk with its CRC's last byte changed: damaged, not read as if whole (libvips
    // warns and keeps it; the png crate drops it).
    let mut bytes = std::fs::read(&png).unwrap();
    bytes[33 + 8 + data.len() + 3] ^= 1;
    std::fs::write(&png, bytes).unwrap();
    fails_with(&run(&["split", s(&png), "-o", s(&out)]), &["damaged.png", "PNG iCCP chunk) is damaged: its CRC is"]);
    assert!(!out.exists());
}

/// A TIFF's ICC tag (34675) over the cap is refused from its count, before it is read, with
/// the same message whatever `--max-memory` is (it said "raise --max-memory" under a small
/// budget, and was read whole under a large one).
#[test]
fn a_tiff_profile_past_the_cap_is_refused_from_its_count() {
    let dir = tempfile::tempdir().unwrap();
    let tif = dir.path().join("icc.tif");
    let mut encoder = TiffEncoder::new(std::fs::File::create(&tif).unwrap()).unwrap();
    let mut image = encoder.new_image::<colortype::RGB8>(4, 4).unwrap();
    image.encoder().write_tag(Tag::IccProfile, &vec![7u8; (16 << 20) + 1][..]).unwrap();
    image.write_data(&[9u8; 48]).unwrap();
    for budget in [8u64 << 20, 1 << 30] {
        let e = source::open_with(&tif, OpenOptions::shown(Budget::new(budget))).err().expect("refused").to_string();
        assert!(
            e.contains("icc.tif") && e.contains("(TIFF tag 34675) holds 16777217 bytes, more than the 16 MiB"),
            "{budget}: {e}"
        );
    }
}

/// `pages` grey 16x16 pages, page 0 described by `xml`.
fn ome_tiff(path: &Path, xml: &str, pages: u8) {
    let mut encoder = TiffEncoder::new(std::fs::File::create(path).unwrap()).unwrap();
    for page in 0..pages {
        let mut image = encoder.new_image::<colortype::Gray8>(16, 16).unwrap();
        if page == 0 {
            image.encoder().write_tag(Tag::ImageDescription, xml).unwrap();
        }
        image.write_data(&[page * 10; 256]).unwrap();
    }
}

fn ome(pixels: &str, inner: &str) -> String {
    format!(
        r#"<?xml version="1.0" encoding="UTF-8"?><OME xmlns="http://www.openmicroscopy.org/Schemas/OME/2016-06" UUID="urn:uuid:self"><Image ID="Image:0"><Pixels ID="Pixels:0" Type="uint8" SizeX="16" SizeY="16" SizeZ="1" SizeT="1" {pixels}>{inner}</Pixels></Image></OME>"#
    )
}

/// Channel names are the OME-XML's, unescaped (`A&amp;B` is `A&B`; `&#65;` is `A`).
#[test]
fn ome_channel_names_are_unescaped() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("names.ome.tif");
    let channels = r#"<Channel ID="Channel:0:0" Name="A&amp;B"/><Channel ID="Channel:0:1" Name="&#65;&lt;&#x42;&gt;"/><Channel ID="Channel:0:2" Name="&bogus; &amp"/>"#;
    let xml = ome(r#"DimensionOrder="XYCZT" SizeC="3""#, &format!(r#"{channels}<TiffData IFD="0" PlaneCount="3"/>"#));
    ome_tiff(&path, &xml, 3);
    let set = ChannelSet::open(&path, Pick::default(), Budget::new(1 << 30)).unwrap();
    // A malformed reference is kept as written.
    assert_eq!(set.names, ["A&B", "A<B>", "&bogus; &amp"]);
}

/// OME-XML that does not map onto the file's pages is refused naming the field, where page 0
/// was read as one channel with exit 0; so is a plane another file of a multi-file OME-TIFF
/// holds (its TiffData's UUID FileName), where this file's page was read in its place.
#[test]
fn ome_xml_that_does_not_map_is_refused_naming_the_field() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bad.ome.tif");
    let planes = r#"<TiffData IFD="0" PlaneCount="3"/>"#;
    let other = r#"<TiffData IFD="0" PlaneCount="3"><UUID FileName="other.ome.tif">urn:uuid:other</UUID></TiffData>"#;
    let renamed =
        r#"<TiffData IFD="0" PlaneCount="3"><UUID FileName="old-name.ome.tif">urn:uuid:self</UUID></TiffData>"#;
    for (xml, says) in [
        (ome(r#"SizeC="1000000000""#, planes), "Pixels SizeC is 1000000000: at most 4096 channels"),
        (ome(r#"SizeC="3" DimensionOrder="XYQQQ""#, planes), r#"DimensionOrder "XYQQQ""#),
        (ome(r#"SizeC="3""#, r#"<TiffData FirstC="7" IFD="0"/>"#), "TiffData FirstC 7 is past Pixels SizeC 3"),
        (ome(r#"SizeC="3""#, other), r#"channel 0 is stored in another file (FileName "other.ome.tif")"#),
        ("<OME><Image ID=\"Image:0\"></OME>".into(), "Image 0 has no Pixels element"),
    ] {
        ome_tiff(&path, &xml, 3);
        let e = ChannelSet::open(&path, Pick::default(), Budget::new(1 << 30)).err().expect("refused").to_string();
        assert!(e.contains("bad.ome.tif") && e.contains("OME-XML") && e.contains(says), "{xml}: {e}");
    }
    // Through the command line too: no OME-Zarr of page 0.
    ome_tiff(&path, &ome(r#"SizeC="1000000000""#, planes), 3);
    let out = dir.path().join("out.zarr");
    fails_with(&run(&["split", s(&path), "--layout", "ome-zarr", "-o", s(&out)]), &["bad.ome.tif", "SizeC"]);
    assert!(!out.exists());
    // The main reader: series 0 is in another file.
    ome_tiff(&path, &ome(r#"SizeC="3""#, other), 3);
    let e = source::open(&path, Budget::new(1 << 30)).err().expect("refused").to_string();
    assert!(e.contains("series 0 is stored in another file (FileName \"other.ome.tif\")"), "{e}");
    // A renamed file whose TiffData names its own UUID is this file.
    ome_tiff(&path, &ome(r#"SizeC="3""#, renamed), 3);
    assert_eq!(ChannelSet::open(&path, Pick::default(), Budget::new(1 << 30)).unwrap().count(), 3);
}

/// An ImageDescription larger than `--max-memory` is an error naming the tag, and nothing but
/// our message reaches stderr (the `tiff` crate printed a `dbg!` line, and the OME-XML in it
/// vanished: the file was read as a plain TIFF).
#[test]
fn an_oversized_description_is_named_and_stderr_holds_only_our_message() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("huge-xml.ome.tif");
    let xml = ome(r#"SizeC="1""#, &format!(r#"<TiffData IFD="0"/><!-- {} -->"#, "x".repeat(20 << 20)));
    ome_tiff(&path, &xml, 1);
    let out = run(&["split", s(&path), "-o", s(&dir.path().join("out")), "--max-memory", "16M"]);
    fails_with(&out, &["huge-xml.ome.tif", "ImageDescription (tag 270", "more than --max-memory"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(err.lines().count(), 1, "{err}");
}

/// Offsets of the directories of a classic little-endian TIFF, in chain order (no loop).
fn ifd_offsets(bytes: &[u8]) -> Vec<usize> {
    let u32_at = |at: usize| u32::from_le_bytes(bytes[at..at + 4].try_into().unwrap()) as usize;
    let mut at = u32_at(4);
    let mut all = Vec::new();
    while at != 0 {
        all.push(at);
        let entries = u16::from_le_bytes([bytes[at], bytes[at + 1]]) as usize;
        at = u32_at(at + 2 + 12 * entries);
    }
    all
}

/// A TIFF (`K`: classic or BigTIFF) of `pages` 4x4 grey pages at `path`; its bytes.
fn grey_tiff<K: TiffKind>(path: &Path, pages: usize) -> Vec<u8> {
    let mut encoder = TiffEncoder::<_, K>::new_generic(std::fs::File::create(path).unwrap()).unwrap();
    for _ in 0..pages {
        encoder.new_image::<colortype::Gray8>(4, 4).unwrap().write_data(&[1u8; 16]).unwrap();
    }
    drop(encoder);
    std::fs::read(path).unwrap()
}

/// A directory chain that loops (page 1 points back at page 0) is said in the summary, where
/// the file was read as one page without a word; so is a page picked past where it stops.
#[test]
fn a_directory_loop_is_said_in_the_summary() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("loop.tif");
    let mut bytes = grey_tiff::<TiffKindStandard>(&path, 2);
    let ifds = ifd_offsets(&bytes);
    assert_eq!(ifds.len(), 2);
    let entries = u16::from_le_bytes([bytes[ifds[1]], bytes[ifds[1] + 1]]) as usize;
    let next = ifds[1] + 2 + 12 * entries;
    bytes[next..next + 4].copy_from_slice(&(ifds[0] as u32).to_le_bytes());
    std::fs::write(&path, &bytes).unwrap();
    // The tiff crate will not step onto page 1, whose next offset closes the loop, so page 1
    // is lost with the loop (libtiff and tifffile read both pages and warn).
    let said = "the directory chain stops after page 0 (format error: file contained a cycle in the list of IFDs)";
    let described = source::open(&path, Budget::new(1 << 30)).unwrap().describe();
    assert!(described.contains(&format!("{said}: later pages not read")), "{described}");
    let e = source::open_picked(&path, Budget::new(1 << 30), Pick { page: Some(1), series: None })
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("--page 1: the TIFF has 1 page(s), 0 to 0") && e.contains(said), "{e}");
}

/// A BigTIFF whose first directory lies past 2^63 bytes: the message names the offset, not
/// "Invalid argument (os error 22)".
#[test]
fn a_first_directory_past_any_file_is_named() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("far.tif");
    let mut bytes = grey_tiff::<TiffKindBig>(&path, 1);
    let far = (1u64 << 63) + 8;
    bytes[8..16].copy_from_slice(&far.to_le_bytes());
    std::fs::write(&path, &bytes).unwrap();
    let e = source::open(&path, Budget::new(1 << 30)).err().unwrap().to_string();
    assert!(e.contains(&format!("first directory offset ({far}) lies past any file")), "{e}");
    assert!(!e.contains("os error"), "{e}");
}

/// An unknown compression is refused with the list of every compression read, made from the
/// table that decides (it stopped at PackBits while JPEG, JPEG 2000 and fax were read).
#[test]
fn an_unknown_compression_lists_every_one_read() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("odd.tif");
    let mut bytes = grey_tiff::<TiffKindStandard>(&path, 1);
    // Tag 259, type SHORT, count 1, value 1 (none).
    let entry = [3u8, 1, 3, 0, 1, 0, 0, 0, 1, 0];
    let at = bytes.windows(entry.len()).position(|w| w == entry).expect("a Compression entry");
    bytes[at + 8..at + 10].copy_from_slice(&52479u16.to_le_bytes());
    std::fs::write(&path, &bytes).unwrap();
    let e = source::open(&path, Budget::new(1 << 30)).err().unwrap().to_string();
    for read in ["code 52479", "PackBits (32773)", "JPEG (7)", "Aperio JPEG 2000 RGB (33005)", "CCITT Group 4 fax (4)"]
    {
        assert!(e.contains(read), "{read}: {e}");
    }
}

/// A Deep Zoom pyramid in a zip whose first tile's entry declares 200 MiB (a 200x100 PNG with
/// zeros after it, deflated to a few hundred KiB) is refused from the tile's header and the
/// entry's declared size, unread. Before, the tile was read whole to learn its size: 200+ MiB
/// resident under `--max-memory 64M`.
#[test]
fn a_zip_tile_past_its_size_is_refused_unread() {
    let dir = tempfile::tempdir().unwrap();
    let zip_path: PathBuf = dir.path().join("big.zip");
    let mut tile = Vec::new();
    let mut encoder = png::Encoder::new(&mut tile, 200, 100);
    encoder.set_color(png::ColorType::Rgb);
    let mut writer = encoder.write_header().unwrap();
    writer.write_image_data(&vec![50u8; 200 * 100 * 3]).unwrap();
    writer.finish().unwrap();
    tile.resize(200 << 20, 0);
    let mut zip = zip::ZipWriter::new(std::fs::File::create(&zip_path).unwrap());
    let options = zip::write::SimpleFileOptions::default()
        .compression_method(zip::CompressionMethod::Deflated)
        .compression_level(Some(1));
    let dzi = r#"<?xml version="1.0"?><Image xmlns="http://schemas.microsoft.com/deepzoom/2008" TileSize="254" Overlap="1" Format="png"><Size Width="200" Height="100"/></Image>"#;
    zip.start_file("big.dzi", options).unwrap();
    zip.write_all(dzi.as_bytes()).unwrap();
    zip.start_file("big_files/8/0_0.png", options).unwrap();
    zip.write_all(&tile).unwrap();
    zip.finish().unwrap();
    drop(tile);
    let out = dir.path().join("out");
    let (output, peak) = run_measured(&["convert", s(&zip_path), "-o", s(&out), "--max-memory", "64M"]);
    fails_with(
        &output,
        &["big.zip:big_files/8/0_0.png", "is 200.0 MiB, more than a 200x100 rgb 8-bit tile file can be"],
    );
    // The binary alone stays under 64 MiB; the tile's first MiB is what is read of it.
    assert!(peak < 96.0, "peak RSS {peak:.1} MiB");
}

/// A damaged strip of a JPEG TIFF is named with its own first row, not the first row of the
/// group of strips decoded with it (issue 41: strip 5 of 32 rows was reported at row 0).
#[test]
fn a_damaged_jpeg_strip_is_named_at_its_own_row() {
    let Some(python) = crate::tiff_slides::venv_python() else { return };
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("bad.tif");
    let script = r#"
import sys
import numpy as np, tifffile
a = (np.random.RandomState(1).rand(256, 64, 3) * 255).astype("uint8")
tifffile.imwrite(sys.argv[1], a, photometric="rgb", compression="jpeg", rowsperstrip=32)
page = tifffile.TiffFile(sys.argv[1]).pages[0]
o, n = page.dataoffsets[5], page.databytecounts[5]
b = bytearray(open(sys.argv[1], "rb").read())
for i in range(o + n // 2, o + n - 2):
    b[i] = 0xFF if i % 2 == 0 else 0xD9
open(sys.argv[1], "wb").write(bytes(b))
"#;
    crate::tiff_slides::python(&python, script, &[s(&input)]);
    let out = run(&["split", s(&input), "-o", s(&dir.path().join("out")), "--tile-size", "64"]);
    fails_with(&out, &["bad.tif", "row 160: JPEG strip 5"]);
}
