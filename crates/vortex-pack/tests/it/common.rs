//! Small packs with every kind of tile, and the means to tamper with them.

use std::path::Path;

use vortex_pack::fuzzing::{self, at};
use vortex_pack::{Description, NewTile, PackWriter, TileId, TileKind, WriteOptions, WriteSummary};

/// A tile as written, to compare with what is read back.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Written {
    Absent,
    Constant(Vec<u8>),
    Data(TileKind, Vec<u8>),
    /// Never given to the writer (absent).
    Skipped,
}

pub struct Sample {
    pub description: Description,
    pub tiles: Vec<(TileId, Written)>,
    pub summary: WriteSummary,
}

/// 20x12 texels in 8-texel tiles with a 1-texel border: 4x4, 2x2 and 1x1 tiles.
pub fn description(channels: u8, sample_bytes: u8) -> Description {
    Description {
        width: 20,
        height: 12,
        tile_size: 8,
        border: 1,
        level_count: 3,
        channels,
        sample_bytes,
        sample_format: 0,
    }
}

/// A raw tile whose bytes depend on `seed`.
pub fn raw_tile(d: &Description, seed: u32) -> Vec<u8> {
    let n = d.raw_tile_len().unwrap() as usize;
    (0..n).map(|i| (i as u32).wrapping_mul(31).wrapping_add(seed.wrapping_mul(97)) as u8).collect()
}

/// An 8-bit RGB PNG (or 16-bit grey-alpha when `sixteen`) of the tile's size.
pub fn png_tile(d: &Description, seed: u32, sixteen: bool) -> (Vec<u8>, Vec<u8>) {
    let side = d.tile_size;
    let n = (side * side) as usize;
    let (color, depth, samples) = if sixteen {
        (png::ColorType::GrayscaleAlpha, png::BitDepth::Sixteen, 4)
    } else {
        (png::ColorType::Rgb, png::BitDepth::Eight, 3)
    };
    let data: Vec<u8> = (0..n * samples).map(|i| (i as u32 * 7 + seed * 13) as u8).collect();
    let mut out = Vec::new();
    {
        let mut enc = png::Encoder::new(&mut out, side, side);
        enc.set_color(color);
        enc.set_depth(depth);
        let mut w = enc.write_header().unwrap();
        w.write_image_data(&data).unwrap();
        w.finish().unwrap();
    }
    // The RGBA8 the decoder must give.
    let rgba = if sixteen {
        data.chunks_exact(4)
            .flat_map(|t| {
                let s = |i: usize| ((u16::from_be_bytes([t[i], t[i + 1]]) as u32 + 128) / 257) as u8;
                [s(0), s(0), s(0), s(2)]
            })
            .collect()
    } else {
        data.chunks_exact(3).flat_map(|t| [t[0], t[1], t[2], 255]).collect()
    };
    (out, rgba)
}

pub fn jpeg_tile(d: &Description, seed: u32) -> Vec<u8> {
    let side = d.tile_size as usize;
    let data: Vec<u8> = (0..side * side * 3).map(|i| ((i / 3) as u32 * 5 + seed * 40) as u8).collect();
    let mut out = Vec::new();
    jpeg_encoder::Encoder::new(&mut out, 90)
        .encode(&data, side as u16, side as u16, jpeg_encoder::ColorType::Rgb)
        .unwrap();
    out
}

/// Writes a pack with every kind of tile: absent (written and skipped), constant, raw, zstd,
/// PNG, JPEG, and payloads shared by several tiles.
pub fn write_sample(path: &Path, channels: u8, sample_bytes: u8, options: WriteOptions) -> Sample {
    let d = description(channels, sample_bytes);
    let levels = fuzzing::pyramid_levels(&d, 4);
    let metadata = br#"{"generator":"vortex-pack tests","note":"caf\u00e9 \"quoted\""}"#;
    let mut w = PackWriter::create(path, d, levels.clone(), metadata, options).unwrap();
    let texel = channels as usize * sample_bytes as usize;
    let shared_raw = raw_tile(&d, 1000);
    let shared_jpeg = jpeg_tile(&d, 3);
    let mut tiles = Vec::new();
    let mut i = 0u32;
    for (lod, l) in levels.iter().enumerate() {
        for y in 0..l.tiles_h {
            for x in 0..l.tiles_w {
                let id = TileId { lod: lod as u32, x, y };
                let written = match i % 8 {
                    0 => Written::Absent,
                    1 => Written::Constant((0..texel).map(|k| (i as usize * 3 + k) as u8).collect()),
                    2 => Written::Data(TileKind::Raw, raw_tile(&d, i)),
                    3 => Written::Data(TileKind::Zstd, zstd::bulk::compress(&raw_tile(&d, i), 3).unwrap()),
                    4 => Written::Data(TileKind::Png, png_tile(&d, i, sample_bytes == 2).0),
                    5 => Written::Data(TileKind::Jpeg, shared_jpeg.clone()),
                    6 => Written::Data(TileKind::Raw, shared_raw.clone()),
                    _ => Written::Skipped,
                };
                match &written {
                    Written::Absent => w.add(id, NewTile::Absent).unwrap(),
                    Written::Constant(v) => w.add(id, NewTile::Constant(v)).unwrap(),
                    Written::Data(kind, bytes) => w.add(id, NewTile::Data(*kind, bytes)).unwrap(),
                    Written::Skipped => {}
                }
                tiles.push((id, written));
                i += 1;
            }
        }
    }
    let summary = w.finish().unwrap();
    Sample { description: d, tiles, summary }
}

/// The three sample packs the tests tamper with: page-aligned data and 8-byte payloads,
/// 64-byte everything, and 16-bit grey-alpha texels.
pub fn sample_variants() -> [(u8, u8, WriteOptions); 3] {
    [
        (3, 1, WriteOptions { alignment: 4096, payload_alignment: 8 }),
        (3, 1, WriteOptions { alignment: 64, payload_alignment: 64 }),
        (2, 2, WriteOptions { alignment: 8, payload_alignment: 16 }),
    ]
}

fn get_u32(b: &[u8], at: usize) -> u64 {
    u32::from_le_bytes(b[at..at + 4].try_into().unwrap()) as u64
}

fn get_u64(b: &[u8], at: usize) -> u64 {
    u64::from_le_bytes(b[at..at + 8].try_into().unwrap())
}

pub use vortex_pack::fuzzing::reseal;

/// Index entries of a (well-formed) pack's bytes: (entry offset, payload offset, length).
pub fn payload_entries(b: &[u8]) -> Vec<(usize, u64, u64)> {
    let index_at = get_u64(b, at::INDEX_OFFSET) as usize;
    let count = get_u64(b, at::INDEX_COUNT) as usize;
    (0..count)
        .map(|i| index_at + i * 24)
        .filter(|e| TileKind::from_u8(b[e + 16]).is_some_and(TileKind::has_payload))
        .map(|e| (e, get_u64(b, e), get_u32(b, e + 8)))
        .collect()
}

/// Sets the CRC of every entry pointing at `offset` to `crc`.
pub fn set_payload_crc(b: &mut [u8], offset: u64, crc: u32) {
    for (e, start, _) in payload_entries(b) {
        if start == offset {
            b[e + 12..e + 16].copy_from_slice(&crc.to_le_bytes());
        }
    }
}
