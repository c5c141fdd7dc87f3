//! A Vortex pack as input: its LOD 0 is the image, each tile's payload the cell, its border
//! skipped. PNG and JPEG payloads are decoded like tile files; raw, zstd and zstd-delta
//! payloads and constant tiles hold little-endian samples in the pack's texel format, and BC1
//! and BC7 blocks decode to it (RGB or RGBA).

use std::path::{Path, PathBuf};

use vortex_pack::{Pack, Tile, TileKind};

use crate::error::{Result, ShowPath, TilerError};
use crate::pixel::{Channels, Depth, PixelLayout};
use crate::source::ImageHeader;
use crate::source::tiled::{CellData, TileGrid, info_icc_profile};

/// A pack's LOD 0 as a grid of tiles, for `convert` to read as an image: each tile decoded
/// and its border cut off.
pub struct PackInput {
    pack: Pack,
    header: ImageHeader,
    tile_size: u32,
    payload: u32,
    border: u32,
    /// Bytes of one raw tile.
    raw_len: usize,
}

impl PackInput {
    /// Opens the pack at `path` (checking its structure, not yet its tiles).
    pub fn open(path: &Path) -> Result<PackInput> {
        let pack = Pack::open(path)?;
        crate::shard::manifest::refuse_shard(path, pack.metadata())?;
        let d = *pack.description();
        // The reader has checked channels (1-4), the sample format and 2 * border < tile size.
        let channels = [Channels::Grey, Channels::GreyAlpha, Channels::Rgb, Channels::Rgba][d.channels as usize - 1];
        let depth = Depth::from_pack(d.sample_bytes, d.sample_format).unwrap_or(Depth::U8);
        let header = ImageHeader { width: d.width, height: d.height, layout: PixelLayout::new(channels, depth) };
        let payload = d.tile_size - 2 * d.border;
        let raw_len = d
            .raw_tile_len()
            .filter(|n| *n <= vortex_pack::DEFAULT_MAX_DECODED_BYTES)
            .and_then(|n| usize::try_from(n).ok())
            .ok_or_else(|| {
                TilerError::unsupported(
                    path,
                    format!(
                        "a {side}x{side} {} tile is over {} bytes, the most this tool decodes",
                        header.layout,
                        vortex_pack::DEFAULT_MAX_DECODED_BYTES,
                        side = d.tile_size,
                    ),
                )
            })?;
        let (cols, rows) = (d.width.div_ceil(payload), d.height.div_ceil(payload));
        let lod0 = pack.levels()[0];
        if lod0.tiles_w < cols || lod0.tiles_h < rows {
            return Err(TilerError::decode(
                path,
                format!(
                    "LOD 0 has {}x{} tiles, but its {}x{} image needs {cols}x{rows} tiles of {payload} texels",
                    lod0.tiles_w, lod0.tiles_h, d.width, d.height
                ),
            ));
        }
        Ok(PackInput { pack, header, tile_size: d.tile_size, payload, border: d.border, raw_len })
    }

    /// The pack's metadata (the `info.json` members of the run that wrote it, as JSON text).
    pub fn metadata(&self) -> &[u8] {
        self.pack.metadata()
    }

    /// A name for tile (col, row) of LOD 0 in errors: `world.vtpk:(lod 0, x 3, y 5)`.
    fn name(&self, col: u32, row: u32) -> PathBuf {
        PathBuf::from(format!("{}:(lod 0, x {col}, y {row})", self.pack.path().display()))
    }

    /// `bytes` (little-endian samples) as native-endian samples of a whole tile.
    fn samples(&self, name: PathBuf, mut bytes: Vec<u8>) -> CellData {
        // A pack stores samples little-endian; cells hold them in the host's order.
        let width = self.header.layout.depth.bytes();
        if width > 1 && cfg!(target_endian = "big") {
            for sample in bytes.chunks_exact_mut(width) {
                sample.reverse();
            }
        }
        CellData::Samples { name, width: self.tile_size, height: self.tile_size, bytes }
    }
}

impl TileGrid for PackInput {
    fn describe(&self) -> String {
        format!(
            "LOD 0 of the pack {} ({}-texel payload, border {})",
            self.pack.path().shown(),
            self.payload,
            self.border
        )
    }
    fn header(&self) -> ImageHeader {
        self.header
    }
    fn cell(&self) -> (u32, u32) {
        (self.payload, self.payload)
    }
    fn icc_profile(&self) -> Result<Option<Vec<u8>>> {
        info_icc_profile(self.pack.path(), self.metadata())
    }
    /// Tiles come out of the pack, whose index bounds them: `_cap` is for files.
    fn read(&self, col: u32, row: u32, _cap: u64) -> Result<Option<CellData>> {
        let name = || self.name(col, row);
        Ok(Some(match self.pack.tile_checked(vortex_pack::TileId::new(0, col, row))? {
            Tile::Absent => return Ok(None),
            Tile::Constant(texel) => {
                let mut bytes = Vec::with_capacity(self.raw_len);
                for _ in 0..self.raw_len / texel.len() {
                    bytes.extend_from_slice(texel);
                }
                self.samples(name(), bytes)
            }
            Tile::Data(TileKind::Png | TileKind::Jpeg | TileKind::Jxl, bytes) => CellData::File(name(), bytes.to_vec()),
            Tile::Data(kind, bytes) => {
                let limit = vortex_pack::DEFAULT_MAX_DECODED_BYTES;
                let raw = Tile::Data(kind, bytes)
                    .decode_texels(self.pack.description(), limit)
                    .map_err(|e| TilerError::decode(name(), e))?;
                self.samples(name(), raw)
            }
        }))
    }
    fn crop(&self, _: u32, _: u32) -> (u32, u32) {
        (self.border, self.border)
    }
    fn stored_size(&self, _: u32, _: u32) -> Option<(u32, u32)> {
        Some((self.tile_size, self.tile_size))
    }
}

#[cfg(test)]
mod tests {
    use std::io::Cursor;

    use image::ImageEncoder;
    use vortex_pack::{Description, Level, NewTile, PackWriter, TileId, WriteOptions};

    use super::*;
    use crate::formats::tiles::square_levels;
    use crate::source::read_all;
    use crate::source::tiled::TiledSource;

    const TILE: u32 = 16;
    const BORDER: u32 = 2;
    const PAYLOAD: u32 = TILE - 2 * BORDER;

    /// Reproducible bytes.
    fn noise(len: usize, seed: u32) -> Vec<u8> {
        crate::source::tiled::noise(len, seed)
    }

    /// An image of `bpp`-byte texels, `width` wide.
    struct Image {
        width: u32,
        height: u32,
        bpp: usize,
        bytes: Vec<u8>,
    }

    impl Image {
        /// The stored tile (x, y) at LOD 0: payload plus border, edge texels repeated outside.
        fn tile(&self, x: u32, y: u32) -> Vec<u8> {
            let mut out = Vec::new();
            for ty in 0..TILE {
                let iy = (y * PAYLOAD + ty).saturating_sub(BORDER).min(self.height - 1);
                for tx in 0..TILE {
                    let ix = (x * PAYLOAD + tx).saturating_sub(BORDER).min(self.width - 1);
                    out.extend_from_slice(&self.bytes[(iy * self.width + ix) as usize * self.bpp..][..self.bpp]);
                }
            }
            out
        }

        /// Sets the texels a stored tile (x, y) covers, border included, to `texel`.
        fn paint_tile(&mut self, x: u32, y: u32, texel: &[u8]) {
            for ty in 0..TILE {
                let iy = (y * PAYLOAD + ty).saturating_sub(BORDER).min(self.height - 1);
                for tx in 0..TILE {
                    let ix = (x * PAYLOAD + tx).saturating_sub(BORDER).min(self.width - 1);
                    self.bytes[(iy * self.width + ix) as usize * self.bpp..][..self.bpp].copy_from_slice(texel);
                }
            }
        }
    }

    fn description(image: &Image, channels: u8, sample_bytes: u8, levels: u32) -> Description {
        Description {
            width: image.width,
            height: image.height,
            tile_size: TILE,
            border: BORDER,
            level_count: levels,
            channels,
            sample_bytes,
            sample_format: 0,
        }
    }

    /// Writes `tiles` (LOD 0 coordinates, what to store) into `path`.
    fn write_pack(path: &Path, d: Description, levels: Vec<Level>, tiles: &[((u32, u32), NewTile)]) {
        let mut w = PackWriter::create(path, d, levels, b"{}", WriteOptions::default()).unwrap();
        for ((x, y), tile) in tiles {
            w.add(TileId { lod: 0, x: *x, y: *y }, *tile).unwrap();
        }
        w.finish().unwrap();
    }

    fn png(bytes: &[u8], colour: image::ExtendedColorType) -> Vec<u8> {
        let mut out = Cursor::new(Vec::new());
        image::codecs::png::PngEncoder::new(&mut out).write_image(bytes, TILE, TILE, colour).unwrap();
        out.into_inner()
    }

    /// Little-endian samples of native-endian 16-bit samples.
    fn le16(native: &[u8]) -> Vec<u8> {
        native.chunks_exact(2).flat_map(|s| u16::from_ne_bytes([s[0], s[1]]).to_le_bytes()).collect()
    }

    fn read_image(path: &Path, fill: Vec<u8>, strict: bool) -> Result<Vec<u8>> {
        let grid = PackInput::open(path)?;
        let mut source = TiledSource::new(Box::new(grid), fill, strict);
        read_all(&mut source)
    }

    #[test]
    fn rgb_png_raw_zstd_and_constant_tiles_read_back_bit_exactly() {
        let tmp = tempfile::tempdir().unwrap();
        // 4x3 cells of 12 texels, the last column 9 wide, the last row 6 high.
        let mut image = Image { width: 45, height: 30, bpp: 3, bytes: noise(45 * 30 * 3, 1) };
        image.paint_tile(1, 1, &[10, 20, 30]);
        let d = description(&image, 3, 1, 3);
        let stored: Vec<((u32, u32), Vec<u8>)> =
            (0..3).flat_map(|y| (0..4).map(move |x| (x, y))).map(|(x, y)| ((x, y), image.tile(x, y))).collect();
        let pngs: Vec<Vec<u8>> = stored.iter().map(|(_, t)| png(t, image::ExtendedColorType::Rgb8)).collect();
        let zstds: Vec<Vec<u8>> = stored.iter().map(|(_, t)| zstd::bulk::compress(t, 3).unwrap()).collect();
        let tiles: Vec<((u32, u32), NewTile)> = stored
            .iter()
            .enumerate()
            .map(|(i, ((x, y), raw))| {
                let tile = match (x, y) {
                    (1, 1) => NewTile::Constant(&[10, 20, 30]),
                    _ if i % 3 == 0 => NewTile::Data(TileKind::Png, &pngs[i]),
                    _ if i % 3 == 1 => NewTile::Data(TileKind::Raw, raw),
                    _ => NewTile::Data(TileKind::Zstd, &zstds[i]),
                };
                ((*x, *y), tile)
            })
            .collect();
        let path = tmp.path().join("world.vtpk");
        write_pack(&path, d, square_levels(&d, 4), &tiles);
        let grid = PackInput::open(&path).unwrap();
        assert_eq!(
            grid.header(),
            ImageHeader { width: 45, height: 30, layout: PixelLayout::new(Channels::Rgb, Depth::U8) }
        );
        assert_eq!((grid.cell(), grid.crop(3, 2)), ((PAYLOAD, PAYLOAD), (BORDER, BORDER)));
        assert_eq!(grid.metadata(), b"{}");
        assert!(grid.describe().contains("world.vtpk"), "{}", grid.describe());
        assert!(read_image(&path, vec![0; 3], true).unwrap() == image.bytes);
    }

    #[test]
    fn sixteen_bit_samples_become_native_endian() {
        let tmp = tempfile::tempdir().unwrap();
        // Native-endian grey+alpha 16-bit samples; 3x2 cells.
        let mut image = Image { width: 30, height: 20, bpp: 4, bytes: noise(30 * 20 * 4, 2) };
        let constant = [0x1234u16.to_ne_bytes(), 0xfedcu16.to_ne_bytes()].concat();
        image.paint_tile(2, 1, &constant);
        let d = description(&image, 2, 2, 3);
        let stored: Vec<((u32, u32), Vec<u8>)> =
            (0..2).flat_map(|y| (0..3).map(move |x| (x, y))).map(|(x, y)| ((x, y), image.tile(x, y))).collect();
        let les: Vec<Vec<u8>> = stored.iter().map(|(_, t)| le16(t)).collect();
        let zstds: Vec<Vec<u8>> = les.iter().map(|t| zstd::bulk::compress(t, 1).unwrap()).collect();
        let pngs: Vec<Vec<u8>> = stored.iter().map(|(_, t)| png(t, image::ExtendedColorType::La16)).collect();
        let constant_le = le16(&constant);
        let tiles: Vec<((u32, u32), NewTile)> = stored
            .iter()
            .enumerate()
            .map(|(i, ((x, y), _))| {
                let tile = match (x, y) {
                    (2, 1) => NewTile::Constant(&constant_le),
                    (0, _) => NewTile::Data(TileKind::Raw, &les[i]),
                    (1, _) => NewTile::Data(TileKind::Zstd, &zstds[i]),
                    _ => NewTile::Data(TileKind::Png, &pngs[i]),
                };
                ((*x, *y), tile)
            })
            .collect();
        let path = tmp.path().join("deep.vtpk");
        write_pack(&path, d, square_levels(&d, 4), &tiles);
        assert_eq!(PackInput::open(&path).unwrap().header().layout.to_string(), "luminanceAlpha 16-bit");
        assert!(read_image(&path, vec![0; 4], true).unwrap() == image.bytes);
    }

    #[test]
    fn an_absent_tile_is_filled_or_an_error_with_strict() {
        let tmp = tempfile::tempdir().unwrap();
        let mut image = Image { width: 20, height: 10, bpp: 1, bytes: noise(20 * 10, 3) };
        let d = description(&image, 1, 1, 2);
        let raw = image.tile(0, 0);
        // Tile (1, 0) is never added: absent.
        let path = tmp.path().join("holes.vtpk");
        write_pack(&path, d, square_levels(&d, 2), &[((0, 0), NewTile::Data(TileKind::Raw, &raw))]);
        for y in 0..10 {
            for x in 12..20 {
                image.bytes[y * 20 + x] = 77;
            }
        }
        assert!(read_image(&path, vec![77], false).unwrap() == image.bytes);
        let e = read_image(&path, vec![77], true).unwrap_err().to_string();
        assert!(e.contains("missing") && e.contains("x 1, y 0"), "{e}");
    }

    #[test]
    fn bad_payloads_are_errors_naming_the_tile() {
        let tmp = tempfile::tempdir().unwrap();
        let image = Image { width: 12, height: 12, bpp: 1, bytes: noise(144, 4) };
        let d = description(&image, 1, 1, 1);
        let levels = square_levels(&d, 1);
        let raw_len = (TILE * TILE) as usize;
        let too_long = zstd::bulk::compress(&vec![5u8; raw_len + 1], 1).unwrap();
        let too_short = zstd::bulk::compress(&vec![5u8; raw_len - 1], 1).unwrap();
        let small_png = {
            let mut out = Cursor::new(Vec::new());
            let encoder = image::codecs::png::PngEncoder::new(&mut out);
            encoder.write_image(&[0; 12 * 12], 12, 12, image::ExtendedColorType::L8).unwrap();
            out.into_inner()
        };
        let cases: [(NewTile, &str); 6] = [
            (NewTile::Data(TileKind::Png, &small_png), "is 12x12, but the tiles of this input are 16x16"),
            (NewTile::Data(TileKind::Zstd, b"not zstd"), "does not decompress to one 256-byte raw tile"),
            (NewTile::Data(TileKind::Zstd, &too_long), "does not decompress to one 256-byte raw tile"),
            (NewTile::Data(TileKind::Zstd, &too_short), "decompresses to 255 bytes; a raw tile is 256"),
            (NewTile::Data(TileKind::Png, b"not a png"), "format could not be determined"),
            (NewTile::Data(TileKind::ZstdDelta, b"not zstd"), "does not decompress to one 256-byte raw tile"),
        ];
        for (i, (tile, expected)) in cases.into_iter().enumerate() {
            let path = tmp.path().join(format!("bad{i}.vtpk"));
            write_pack(&path, d, levels.clone(), &[((0, 0), tile)]);
            let e = read_image(&path, vec![0], false).unwrap_err().to_string();
            let name = format!("{}:(lod 0, x 0, y 0): ", path.shown());
            assert!(e.starts_with(&name) && e.contains(expected), "{expected}: {e}");
        }
    }

    #[test]
    fn a_pack_whose_lod0_does_not_cover_the_image_is_refused() {
        let tmp = tempfile::tempdir().unwrap();
        let image = Image { width: 30, height: 12, bpp: 1, bytes: Vec::new() };
        let d = description(&image, 1, 1, 1);
        let levels = vec![Level { tiles_w: 2, tiles_h: 1, first_entry: 0, width: 30, height: 12 }];
        let path = tmp.path().join("short.vtpk");
        write_pack(&path, d, levels, &[]);
        let e = PackInput::open(&path).err().unwrap().to_string();
        assert!(e.contains("short.vtpk") && e.contains("LOD 0 has 2x1 tiles") && e.contains("needs 3x1"), "{e}");
        let e = PackInput::open(&tmp.path().join("none.vtpk")).err().unwrap().to_string();
        assert!(e.contains("none.vtpk"), "{e}");
    }
}
