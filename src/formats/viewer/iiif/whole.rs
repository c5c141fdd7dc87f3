//! IIIF's whole-image files, `full/max` and the `sizes` (`full/{w},{h}`): one LOD of the
//! pyramid in one image, assembled from that LOD's tiles and encoded again.
//!
//! The split pipeline streams and never holds a whole level, and `serve` keeps only pages, so
//! both build these from tiles after the fact: `split` from the tile files it has just written
//! (decoded, so a JPEG whole image is a second generation at the tiles' quality), `serve` from
//! a pack's pages. Only LODs within [`MAX_WHOLE_SIDE`] are assembled, so the memory is bounded
//! whatever the image: at most a square of that side (the encoder takes square tiles).

use super::{MAX_WHOLE_SIDE, crop};
use crate::codec::{Codec, TileEncoder};
use crate::decode::Decoded;
use crate::layout::Crop;
use crate::layout::Layout;
use crate::pixel::{Depth, PixelLayout};

/// The whole image at `lod`, encoded with `codec`, from its tiles: `tile(col, row)` gives the
/// decoded page or tile and the part of it that is IIIF's tile of (col, row) (the part
/// [`crop`] names, moved by a stored border).
pub(crate) fn assemble(
    layout: &Layout,
    lod: u32,
    codec: Codec,
    mut tile: impl FnMut(u32, u32) -> Result<(Decoded, Crop), String>,
) -> Result<Vec<u8>, String> {
    let (width, height) = layout.level_extent(lod);
    let side = width.max(height);
    if side > MAX_WHOLE_SIDE.max(layout.payload()) {
        return Err(format!("LOD {lod} is {width}x{height}, larger than a whole-image file may be"));
    }
    let (cols, rows) = layout.grid(lod);
    let p = layout.payload();
    let mut canvas: Option<(PixelLayout, Vec<u8>)> = None;
    for row in 0..rows {
        for col in 0..cols {
            let (decoded, part) = tile(col, row)?;
            let want = crop(layout, lod, col, row);
            let at = format!("tile (lod {lod}, x {col}, y {row})");
            if (part.width, part.height) != (want.width, want.height)
                || part.x + part.width > decoded.width
                || part.y + part.height > decoded.height
            {
                return Err(format!(
                    "{at}: {}x{} texels at ({}, {}) of a {}x{} image, not the {}x{} the level needs",
                    part.width, part.height, part.x, part.y, decoded.width, decoded.height, want.width, want.height
                ));
            }
            let (l, bytes) = canvas.get_or_insert_with(|| {
                let bpp = decoded.layout.bytes_per_pixel();
                (decoded.layout, vec![0u8; side as usize * side as usize * bpp])
            });
            if *l != decoded.layout {
                return Err(format!("{at} is {}, the tiles before it {l}", decoded.layout));
            }
            let bpp = l.bytes_per_pixel();
            let row_bytes = part.width as usize * bpp;
            for y in 0..part.height as usize {
                let from = ((part.y as usize + y) * decoded.width as usize + part.x as usize) * bpp;
                let to = ((row * p) as usize + y) * side as usize * bpp + (col * p) as usize * bpp;
                bytes[to..to + row_bytes].copy_from_slice(&decoded.bytes[from..from + row_bytes]);
            }
        }
    }
    let (pixels, bytes) = canvas.ok_or_else(|| format!("LOD {lod} has no tiles"))?;
    let whole = Crop { x: 0, y: 0, width, height };
    let mut out = Vec::new();
    match pixels.depth {
        Depth::U8 => {
            encoder::<u8>(codec, pixels, side)?.encode_crop(&bytes, whole, &mut out).map_err(|e| e.to_string())?
        }
        Depth::U16 => {
            let samples: Vec<u16> = bytemuck::pod_collect_to_vec(&bytes);
            encoder::<u16>(codec, pixels, side)?.encode_crop(&samples, whole, &mut out).map_err(|e| e.to_string())?
        }
        // Split refuses JPEG and PNG tiles for 32-bit and float images before any is written.
        other => return Err(format!("{other:?} samples have no JPEG or PNG tiles")),
    }
    Ok(out)
}

fn encoder<T: crate::pixel::Sample>(codec: Codec, layout: PixelLayout, side: u32) -> Result<TileEncoder<T>, String> {
    TileEncoder::new(codec, layout, false, None, side, Vec::new()).map_err(|e| e.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::codec::PngLevel;
    use crate::decode::decode_tile;
    use crate::formats::viewer::Viewer;
    use crate::pixel::Channels;

    #[test]
    fn tiles_land_where_the_level_has_them() {
        // 20 x 9 in 8-texel tiles: 3 x 2 tiles at LOD 0, the last column 4 wide, the last row 1.
        let l = Viewer::Iiif.page_grid(20, 9, 8, 0).unwrap();
        let grey = PixelLayout::new(Channels::Grey, Depth::U8);
        let png = Codec::Png { level: PngLevel::Fast };
        let out = assemble(&l, 0, png, |col, row| {
            let c = crop(&l, 0, col, row);
            let bytes = (0..c.width * c.height)
                .map(|i| (col * 8 + i % c.width + 100 * (row * 8 + i / c.width)) as u8)
                .collect();
            Ok((Decoded { width: c.width, height: c.height, layout: grey, bytes }, Crop { x: 0, y: 0, ..c }))
        })
        .unwrap();
        let d = decode_tile(std::path::Path::new("whole"), &out).unwrap();
        assert_eq!((d.width, d.height), (20, 9));
        for (i, v) in d.bytes.iter().enumerate() {
            let (x, y) = (i as u32 % 20, i as u32 / 20);
            assert_eq!(*v as u32, (x + 100 * y) % 256, "texel ({x}, {y})");
        }
        let wrong = assemble(&l, 0, png, |_, _| {
            Ok((Decoded { width: 8, height: 8, layout: grey, bytes: vec![0; 64] }, Crop::whole(8)))
        });
        assert!(wrong.unwrap_err().contains("tile (lod 0, x 2, y 0): 8x8 texels"));
    }
}
