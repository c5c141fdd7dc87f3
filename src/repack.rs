//! Between a directory of tiles (`info.json` + files) and a pack: `pack` and `unpack`.
//!
//! `pack` stores every tile file's bytes unchanged, coarsest level first (see
//! docs/pack-format.md on ordering); `unpack` writes them back, so a round
//! trip gives byte-identical files. Tiles a pack stores as one colour are encoded again with
//! the pack's codec, which gives the bytes `split` would have written.

use std::path::Path;

use vortex_pack::format::pyramid_levels;
use vortex_pack::{Description, NewTile, Pack, PackWriter, Tile, TileId, TileKind, WriteOptions, WriteSummary};

use crate::codec::{Codec, PngLevel, Subsampling, TileEncoder};
use crate::error::{Result, TilerError};
use crate::filename::FilenameFormat;
use crate::info::{FORMAT_VERSION, InfoFile};
use crate::pack_sink::tile_kind;
use crate::pixel::{Channels, Depth, PixelLayout, Sample};
use crate::settings::DEFAULT_FILENAME_STEM;
use crate::sink::{DirSink, TileSink};
use crate::split::Progress;

/// A tiled directory's `info.json`, completed with defaults for the thesis's version-0 files.
pub struct TiledDir {
    pub info: InfoFile,
    pub description: Description,
    pub tile_count: u32,
    pub names: FilenameFormat,
    pub codec: Codec,
}

impl TiledDir {
    pub fn read(dir: &Path) -> Result<TiledDir> {
        let path = dir.join("info.json");
        let mut info = InfoFile::read(&path)?;
        let missing =
            |field: &str| TilerError::Info { path: path.clone(), field: field.into(), message: "is required".into() };
        let tile_size = info.tile_size.ok_or_else(|| missing("tileSize"))?;
        let tile_count = info.tile_count.ok_or_else(|| missing("tileCount"))?;
        let border = info.border.unwrap_or(0);
        let payload = tile_size.checked_sub(2 * border).filter(|p| *p > 0).ok_or_else(|| TilerError::Info {
            path: path.clone(),
            field: "border".into(),
            message: format!("{border} leaves no payload in {tile_size}-texel tiles"),
        })?;
        let side = u32::try_from(tile_count as u64 * payload as u64).map_err(|_| missing("width"))?;
        let names = info.filename_format.clone().ok_or_else(|| missing("filenameFormat"))?;
        let names = FilenameFormat::parse(&names, 3).map_err(|m| TilerError::Info {
            path: path.clone(),
            field: "filenameFormat".into(),
            message: m,
        })?;
        let codec = codec_of(&info, names.extension()).ok_or_else(|| TilerError::Info {
            path: path.clone(),
            field: "codec".into(),
            message: "neither codec nor the file extension says jpeg or png".into(),
        })?;
        let channels = Channels::from_tile_format(info.tile_format.as_deref().unwrap_or("rgb")).ok_or_else(|| {
            TilerError::Info { path: path.clone(), field: "tileFormat".into(), message: "not supported".into() }
        })?;
        let depth = Depth::from_tile_type(info.tile_type.as_deref().unwrap_or("unsignedByte")).ok_or_else(|| {
            TilerError::Info { path: path.clone(), field: "tileType".into(), message: "not supported".into() }
        })?;
        let lod_count = tile_count.trailing_zeros() + 1;
        let description = Description {
            width: info.width.unwrap_or(side),
            height: info.height.unwrap_or(side),
            tile_size,
            border,
            level_count: lod_count,
            channels: channels.count() as u8,
            sample_bytes: depth.bytes() as u8,
        };
        // The pack's metadata is the completed description.
        info.format_version = Some(FORMAT_VERSION);
        info.lod_count = Some(lod_count);
        info.border = Some(border);
        info.width = Some(description.width);
        info.height = Some(description.height);
        info.tile_format = Some(channels.tile_format().into());
        info.tile_type = Some(depth.tile_type().into());
        info.codec = Some(codec.name().into());
        Ok(TiledDir { info, description, tile_count, names, codec })
    }
}

/// The codec `info.json` names, or else the one the tile files' extension implies.
fn codec_of(info: &InfoFile, extension: Option<String>) -> Option<Codec> {
    let name = info.codec.clone().or(extension).unwrap_or_default();
    let subsampling = if info.subsampling.as_deref() == Some("444") { Subsampling::S444 } else { Subsampling::S420 };
    let level = match info.png_compression.as_deref() {
        Some("default") => PngLevel::Default,
        Some("best") => PngLevel::Best,
        _ => PngLevel::Fast,
    };
    match name.as_str() {
        "jpeg" | "jpg" => Some(Codec::Jpeg { quality: info.quality.unwrap_or(85), subsampling }),
        "png" => Some(Codec::Png { level }),
        _ => None,
    }
}

/// Every tile, coarsest level first, each level in raster order (rows top down). Raster
/// beats Morton order for rectangular views (`bench/order-locality.py`, docs/pack-format.md).
pub fn pack_order(tile_count: u32, lod_count: u32) -> impl Iterator<Item = TileId> {
    (0..lod_count).rev().flat_map(move |lod| {
        let n = tile_count >> lod;
        (0..n).flat_map(move |y| (0..n).map(move |x| TileId { lod, x, y }))
    })
}

/// Packs the tiled directory `dir` into `dest`.
pub fn pack_dir(dir: &Path, dest: &Path, options: WriteOptions, progress: &dyn Progress) -> Result<WriteSummary> {
    let t = TiledDir::read(dir)?;
    let levels = pyramid_levels(&t.description, t.tile_count);
    let metadata = t.info.to_json_pretty();
    let mut writer = PackWriter::create(dest, t.description, levels, metadata.as_bytes(), options)?;
    let kind = tile_kind(t.codec);
    for id in pack_order(t.tile_count, t.description.level_count) {
        if progress.cancelled() {
            return Err(TilerError::Interrupted);
        }
        let path = dir.join(t.names.format(&[id.lod, id.x, id.y]));
        let bytes = std::fs::read(&path).map_err(|e| TilerError::io(&path, e))?;
        let looks_right = match kind {
            TileKind::Jpeg => bytes.starts_with(&[0xff, 0xd8, 0xff]),
            _ => bytes.starts_with(b"\x89PNG\r\n\x1a\n"),
        };
        if !looks_right {
            return Err(TilerError::decode(&path, format!("is not a {} file, as info.json's codec says", kind.name())));
        }
        writer.add(id, NewTile::Data(kind, &bytes))?;
        progress.advance(1);
    }
    Ok(writer.finish()?)
}

/// Writes every tile of `pack` as files plus `info.json` into `dir`; returns the tile count.
pub fn unpack(pack: &Pack, dir: &Path, progress: &dyn Progress) -> Result<u64> {
    let meta = pack.metadata();
    let info: InfoFile = serde_json::from_slice(meta).map_err(|e| TilerError::Info {
        path: pack.path().to_path_buf(),
        field: "metadata".into(),
        message: e.to_string(),
    })?;
    let d = *pack.description();
    let names = match &info.filename_format {
        Some(f) => f.clone(),
        None => format!("{DEFAULT_FILENAME_STEM}.{}", codec_of(&info, None).map_or("png", |c| c.extension())),
    };
    let names = FilenameFormat::parse(&names, 3).map_err(TilerError::Options)?;
    let codec = codec_of(&info, names.extension());
    let layout = PixelLayout::new(
        [Channels::Grey, Channels::GreyAlpha, Channels::Rgb, Channels::Rgba][d.channels as usize - 1],
        if d.sample_bytes == 2 { Depth::U16 } else { Depth::U8 },
    );
    let sink = DirSink::create(dir, names)?;
    let result = (|| {
        let mut count = 0;
        for id in pack.ids() {
            if progress.cancelled() {
                return Err(TilerError::Interrupted);
            }
            match pack.tile_checked(id.lod, id.x, id.y)? {
                Tile::Absent => continue,
                Tile::Data(_, bytes) => sink.write_tile(id.lod, id.x, id.y, bytes)?,
                Tile::Constant(texel) => {
                    let codec = codec.ok_or_else(|| {
                        TilerError::Options("the pack's metadata names no codec to encode one-colour tiles with".into())
                    })?;
                    let bytes = match layout.depth {
                        Depth::U8 => encode_constant::<u8>(codec, layout, d.tile_size, texel)?,
                        Depth::U16 => encode_constant::<u16>(codec, layout, d.tile_size, texel)?,
                    };
                    sink.write_tile(id.lod, id.x, id.y, &bytes)?
                }
            }
            count += 1;
            progress.advance(1);
        }
        Ok(count)
    })();
    match result {
        Ok(count) => {
            sink.finish(&info)?;
            Ok(count)
        }
        Err(e) => {
            sink.abandon();
            Err(e)
        }
    }
}

fn encode_constant<T: Sample>(codec: Codec, layout: PixelLayout, side: u32, texel: &[u8]) -> Result<Vec<u8>> {
    let samples: Vec<T> = texel
        .chunks_exact(layout.depth.bytes())
        .map(|b| T::from_u16(if b.len() == 2 { u16::from_le_bytes([b[0], b[1]]) } else { b[0] as u16 }))
        .collect();
    let texels: Vec<T> = samples.iter().copied().cycle().take(samples.len() * (side as usize).pow(2)).collect();
    let encoder = TileEncoder::<T>::new(codec, layout, false, None, side, Vec::new())?;
    let mut out = Vec::new();
    encoder.encode(&texels, &mut out).map_err(|message| TilerError::Encode { lod: 0, x: 0, y: 0, message })?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn coarse_levels_come_first() {
        let ids: Vec<TileId> = pack_order(4, 3).collect();
        assert_eq!(ids.len(), 1 + 4 + 16);
        assert_eq!(ids[0], TileId { lod: 2, x: 0, y: 0 });
        assert_eq!(
            ids[1..5].iter().map(|i| (i.lod, i.x, i.y)).collect::<Vec<_>>(),
            vec![(1, 0, 0), (1, 1, 0), (1, 0, 1), (1, 1, 1)]
        );
        assert_eq!(ids[20], TileId { lod: 0, x: 3, y: 3 });
    }
}
