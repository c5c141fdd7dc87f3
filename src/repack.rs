//! Between a directory of tiles (`info.json` + files) and a pack: `pack` and `unpack`.
//!
//! `pack` stores every tile file's bytes unchanged, coarsest level first (see
//! docs/pack-format.md on ordering); `unpack` writes them back, so a round
//! trip gives byte-identical files. Tiles a pack stores as one colour are encoded again with
//! the pack's codec, which gives the bytes `split` would have written. Given another codec,
//! `pack` decodes every tile file and encodes it again (one-colour tiles become constants).

use std::path::Path;

use rayon::prelude::*;
use vortex_pack::{Description, Level, NewTile, Pack, PackWriter, Tile, TileId, TileKind, WriteOptions, WriteSummary};

use crate::codec::{Codec, TileEncoder};
use crate::error::{Result, ShowPath, TilerError};
use crate::formats::pack::tile_kind;
use crate::formats::tiles::filename::DEFAULT_FILENAME_STEM;
use crate::formats::tiles::filename::FilenameFormat;
use crate::formats::tiles::info::InfoFile;
use crate::formats::tiles::{TiledDir, codec_of, layout_of};
use crate::output::Claim;
use crate::pixel::{Depth, PixelLayout, Sample};
use crate::sink::{DirSink, TileSink};
use crate::source::{decode_tile, probe_tile};
use crate::split::Progress;

/// Every tile of `levels`, coarsest level first, each level in raster order (rows top down).
/// Raster beats Morton order for rectangular views (`bench/order-locality.py`,
/// docs/pack-format.md).
pub(crate) fn pack_order(levels: &[Level]) -> impl Iterator<Item = TileId> + '_ {
    levels.iter().enumerate().rev().flat_map(|(lod, l)| {
        (0..l.tiles_h).flat_map(move |y| (0..l.tiles_w).map(move |x| TileId { lod: lod as u32, x, y }))
    })
}

/// Packs the tiled directory `dir` into `dest`: the tile files' bytes as they are, or, with a
/// `codec` other than the directory's, every tile decoded and encoded again with it.
pub fn pack_dir(
    dir: &Path,
    dest: &Path,
    options: WriteOptions,
    codec: Option<Codec>,
    progress: &dyn Progress,
) -> Result<WriteSummary> {
    let t = TiledDir::read(dir)?;
    if let Some(codec) = codec.filter(|c| *c != t.codec) {
        return match t.description.sample_bytes {
            2 => reencode_dir::<u16>(dir, &t, dest, options, codec, progress),
            _ => reencode_dir::<u8>(dir, &t, dest, options, codec, progress),
        };
    }
    let metadata = t.info.to_json_pretty();
    let mut writer = PackWriter::create(dest, t.description, t.levels.clone(), metadata.as_bytes(), options)?;
    let kind = tile_kind(t.codec)?;
    for id in pack_order(&t.levels) {
        if progress.cancelled() {
            return Err(TilerError::Interrupted);
        }
        let (path, bytes) = read_tile(dir, &t, id, kind)?;
        writer.add(id, NewTile::Data(kind, &bytes)).map_err(|e| in_file(&path, e))?;
        progress.advance(1);
    }
    Ok(writer.finish()?)
}

/// The file of tile `id` and its bytes, checked against `info.json` before they are stored:
/// a regular file no larger than a tile can be, a complete `kind` (PNG, JPEG or JPEG XL) file whose
/// header says the directory's tile size and pixel layout.
fn read_tile(dir: &Path, t: &TiledDir, id: TileId, kind: TileKind) -> Result<(std::path::PathBuf, Vec<u8>)> {
    use std::io::Read;
    let path = dir.join(t.names.format(&[id.lod, id.x, id.y]));
    let meta = std::fs::metadata(&path).map_err(|e| TilerError::io(&path, e))?;
    if !meta.is_file() {
        return Err(TilerError::decode(&path, "is not a regular file (a device, FIFO or directory)"));
    }
    let side = t.description.tile_size;
    let layout = t.layout();
    // A tile file is at most its raw texels twice over (JPEG of noise at quality 100 stays
    // well below) plus its headers.
    let most = 2 * (side as u64).pow(2) * layout.bytes_per_pixel() as u64 + (64 << 10);
    if meta.len() > most {
        return Err(TilerError::decode(
            &path,
            format!("is {} bytes, more than a {side}x{side} {layout} tile can need ({most})", meta.len()),
        ));
    }
    let mut bytes = Vec::with_capacity(meta.len() as usize);
    let file = std::fs::File::open(&path).map_err(|e| TilerError::io(&path, e))?;
    file.take(most + 1).read_to_end(&mut bytes).map_err(|e| TilerError::io(&path, e))?;
    let (looks_right, complete) = match kind {
        TileKind::Jpeg => (bytes.starts_with(&[0xff, 0xd8, 0xff]), bytes.ends_with(&[0xff, 0xd9])),
        // A JPEG XL codestream has no end marker: it is complete if it decodes.
        TileKind::Jxl => (vortex_jxl::is_jxl(&bytes), vortex_jxl::decode(&bytes, (side, side)).is_ok()),
        _ => (bytes.starts_with(b"\x89PNG\r\n\x1a\n"), bytes.ends_with(&PNG_END)),
    };
    if !looks_right {
        return Err(TilerError::decode(&path, format!("is not a {} file, as info.json's codec says", kind.name())));
    }
    if !complete || bytes.len() as u64 > most {
        return Err(TilerError::decode(
            &path,
            format!("is a truncated or damaged {} file (no end marker)", kind.name()),
        ));
    }
    let (w, h, found) = probe_tile(&path, &bytes)?;
    if (w, h, found) != (side, side, layout) {
        return Err(TilerError::decode(
            &path,
            format!("is a {w}x{h} {found} image; info.json says tiles are {side}x{side} {layout}"),
        ));
    }
    Ok((path, bytes))
}

/// The last 12 bytes of every PNG file: the empty IEND chunk with its CRC.
const PNG_END: [u8; 12] = [0, 0, 0, 0, b'I', b'E', b'N', b'D', 0xae, 0x42, 0x60, 0x82];

fn in_file(path: &Path, e: vortex_pack::PackError) -> TilerError {
    TilerError::decode(path, e)
}

/// Tiles decoded and encoded in parallel this many at a time, then stored in order.
const REENCODE_CHUNK: usize = 64;

/// `pack_dir` with another codec: each tile file decoded (it must have the directory's size
/// and layout) and encoded with `codec`; one-colour tiles are stored as their colour.
fn reencode_dir<T: Sample>(
    dir: &Path,
    t: &TiledDir,
    dest: &Path,
    options: WriteOptions,
    codec: Codec,
    progress: &dyn Progress,
) -> Result<WriteSummary> {
    let side = t.description.tile_size;
    let layout = t.layout();
    let encoder = TileEncoder::<T>::new(codec, layout, false, None, side, Vec::new())?;
    let stored = encoder.stored_layout();
    let description = Description {
        channels: stored.channels.count() as u8,
        sample_bytes: stored.depth.bytes() as u8,
        sample_format: stored.depth.pack_sample_format(),
        ..t.description
    };
    let mut info = t.info.clone();
    let names = t.names.as_str();
    let stem = match t.names.extension() {
        Some(ext) => &names[..names.len() - ext.len() - 1],
        None => names,
    };
    info.filename_format = Some(format!("{stem}.{}", codec.extension()));
    info.tile_format = Some(stored.channels.tile_format().into());
    info.tile_type = Some(stored.depth.tile_type().into());
    let described = crate::settings::describe_codec(codec);
    info.codec = described.codec;
    info.quality = described.quality;
    info.subsampling = described.subsampling;
    info.png_compression = described.png_compression;
    info.zstd_level = described.zstd_level;
    info.bc7_effort = described.bc7_effort;
    let mut writer =
        PackWriter::create(dest, description, t.levels.clone(), info.to_json_pretty().as_bytes(), options)?;
    let (from, to) = (tile_kind(t.codec)?, tile_kind(codec)?);
    let channels = layout.channels.count();
    let ids: Vec<TileId> = pack_order(&t.levels).collect();
    for chunk in ids.chunks(REENCODE_CHUNK) {
        if progress.cancelled() {
            return Err(TilerError::Interrupted);
        }
        let done: Vec<Result<(TileId, std::path::PathBuf, Stored)>> = chunk
            .par_iter()
            .map(|&id| {
                let (path, bytes) = read_tile(dir, t, id, from)?;
                let decoded = decode_tile(&path, &bytes)?;
                if (decoded.width, decoded.height, decoded.layout) != (side, side, layout) {
                    return Err(TilerError::decode(
                        &path,
                        format!(
                            "is a {}x{} {} image; info.json says tiles are {side}x{side} {layout}",
                            decoded.width, decoded.height, decoded.layout
                        ),
                    ));
                }
                let texels: Vec<T> = bytemuck::pod_collect_to_vec(&decoded.bytes);
                let first = &texels[..channels];
                if texels.chunks_exact(channels).all(|px| px == first) {
                    return Ok((id, path, Stored::Constant(encoder.stored_texel(first))));
                }
                let mut out = Vec::new();
                encoder.encode(&texels, &mut out).map_err(|e| TilerError::Encode {
                    lod: id.lod,
                    x: id.x,
                    y: id.y,
                    message: e.to_string(),
                })?;
                Ok((id, path, Stored::Data(out)))
            })
            .collect();
        for tile in done {
            let (id, path, stored) = tile?;
            let tile = match &stored {
                Stored::Constant(texel) => NewTile::Constant(texel),
                Stored::Data(bytes) => NewTile::Data(to, bytes),
            };
            writer.add(id, tile).map_err(|e| in_file(&path, e))?;
        }
        progress.advance(chunk.len() as u64);
    }
    Ok(writer.finish()?)
}

/// A re-encoded tile.
enum Stored {
    Constant(Vec<u8>),
    Data(Vec<u8>),
}

/// Writes every tile of `pack` as files plus `info.json` into the directory `dir` claims;
/// returns the tile count.
pub fn unpack(pack: &Pack, dir: &Claim, progress: &dyn Progress) -> Result<u64> {
    let meta = pack.metadata();
    crate::shard::manifest::refuse_shard(pack.path(), meta)?;
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
    let names = FilenameFormat::parse(&names, 3).map_err(|e| TilerError::Options(format!("filename format: {e}")))?;
    let codec = codec_of(&info, names.extension());
    let layout = layout_of(&d);
    let no_files = |kind: &str| {
        TilerError::unsupported(
            pack.path(),
            format!(
                "its tiles are {kind} payloads, which are not image files; `vortex-tiler convert {} -o DIR --codec png` writes them as files",
                pack.path().shown()
            ),
        )
    };
    if let Some(c) = codec.filter(|c| !c.writes_files()) {
        return Err(no_files(c.name()));
    }
    check_metadata(pack, &info, codec, names.extension())?;
    let sink = DirSink::create(dir, names)?;
    let result = (|| {
        let mut count = 0;
        for id in pack.ids() {
            if progress.cancelled() {
                return Err(TilerError::Interrupted);
            }
            match pack.tile_checked(id)? {
                Tile::Absent => continue,
                Tile::Data(kind @ (TileKind::Png | TileKind::Jpeg | TileKind::Jxl), bytes) => {
                    if let Some(c) = codec.filter(|c| tile_kind(*c).ok() != Some(kind)) {
                        return Err(TilerError::Info {
                            path: pack.path().to_path_buf(),
                            field: "metadata: codec".into(),
                            message: format!(
                                "says {} but tile (lod {}, x {}, y {}) is {}",
                                c.name(),
                                id.lod,
                                id.x,
                                id.y,
                                kind.name()
                            ),
                        });
                    }
                    sink.write_tile(id.lod, id.x, id.y, bytes)?
                }
                Tile::Data(kind, _) => return Err(no_files(kind.name())),
                Tile::Constant(texel) => {
                    let codec = codec.ok_or_else(|| {
                        TilerError::Options("the pack's metadata names no codec to encode one-colour tiles with".into())
                    })?;
                    let bytes = match layout.depth {
                        Depth::U8 => encode_constant::<u8>(codec, layout, d.tile_size, texel)?,
                        Depth::U16 => encode_constant::<u16>(codec, layout, d.tile_size, texel)?,
                        // Raw and zstd packs are refused above: nothing holds these as files.
                        other => return Err(no_files(other.tile_type())),
                    };
                    sink.write_tile(id.lod, id.x, id.y, &bytes)?
                }
            }
            count += 1;
            progress.advance(1);
        }
        Ok(count)
    })();
    // On error the sink is dropped, which removes what it wrote.
    let count = result?;
    sink.finish(&info)?;
    Ok(count)
}

/// A square grid's side as `tileCount` gives it, or what the grid is when it is not square.
fn square_side(lod0: Level) -> String {
    match lod0.tiles_w == lod0.tiles_h {
        true => lod0.tiles_w.to_string(),
        false => format!("a grid of {} x {} tiles", lod0.tiles_w, lod0.tiles_h),
    }
}

/// Refuses a pack whose metadata (the `info.json` that `unpack` writes) contradicts its
/// header: the files must be described by what they are, not by what the metadata claims.
fn check_metadata(pack: &Pack, info: &InfoFile, codec: Option<Codec>, extension: Option<String>) -> Result<()> {
    let d = pack.description();
    let lie = |field: &str, claimed: String, actual: String| TilerError::Info {
        path: pack.path().to_path_buf(),
        field: format!("metadata: {field}"),
        message: format!(
            "says {claimed} but the pack's header says {actual}; the pack was altered or written by another tool"
        ),
    };
    let lod0 = pack.levels()[0];
    let stored = layout_of(d);
    let members: [(&str, Option<String>, String); 10] = [
        ("tileSize", info.tile_size.map(|v| v.to_string()), d.tile_size.to_string()),
        ("border", info.border.map(|v| v.to_string()), d.border.to_string()),
        ("width", info.width.map(|v| v.to_string()), d.width.to_string()),
        ("height", info.height.map(|v| v.to_string()), d.height.to_string()),
        ("tileColumns", info.tile_columns.map(|v| v.to_string()), lod0.tiles_w.to_string()),
        ("tileRows", info.tile_rows.map(|v| v.to_string()), lod0.tiles_h.to_string()),
        ("tileCount", info.tile_count.map(|v| v.to_string()), square_side(lod0)),
        ("lodCount", info.lod_count.map(|v| v.to_string()), d.level_count.to_string()),
        ("tileFormat", info.tile_format.clone(), stored.channels.tile_format().to_string()),
        ("tileType", info.tile_type.clone(), stored.depth.tile_type().to_string()),
    ];
    for (field, claimed, actual) in members {
        if let Some(claimed) = claimed.filter(|c| *c != actual) {
            return Err(lie(field, claimed, actual));
        }
    }
    if let (Some(c), Some(ext)) = (codec, extension) {
        let matches = match c {
            Codec::Jpeg { .. } => ext == "jpg" || ext == "jpeg",
            _ => ext == c.extension(),
        };
        if !matches {
            return Err(lie("filenameFormat", format!("files ending .{ext}"), format!("{} tiles", c.name())));
        }
    }
    Ok(())
}

fn encode_constant<T: Sample>(codec: Codec, layout: PixelLayout, side: u32, texel: &[u8]) -> Result<Vec<u8>> {
    let samples: Vec<T> = texel
        .chunks_exact(layout.depth.bytes())
        .map(|b| T::from_u16(if b.len() == 2 { u16::from_le_bytes([b[0], b[1]]) } else { b[0] as u16 }))
        .collect();
    let texels: Vec<T> = samples.iter().copied().cycle().take(samples.len() * (side as usize).pow(2)).collect();
    let encoder = TileEncoder::<T>::new(codec, layout, false, None, side, Vec::new())?;
    let mut out = Vec::new();
    encoder.encode(&texels, &mut out).map_err(|e| TilerError::Encode { lod: 0, x: 0, y: 0, message: e.to_string() })?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::layout::Layout;

    #[test]
    fn coarse_levels_come_first() {
        // A 5 x 3 page grid: 5 x 3, 3 x 2, 2 x 1, 1 x 1.
        let levels = Layout::new(50, 30, 14, 2).unwrap().pack_levels();
        let ids: Vec<TileId> = pack_order(&levels).collect();
        assert_eq!(ids.len(), 1 + 2 + 6 + 15);
        assert_eq!(ids[0], TileId { lod: 3, x: 0, y: 0 });
        assert_eq!(ids[1..3].iter().map(|i| (i.lod, i.x, i.y)).collect::<Vec<_>>(), vec![(2, 0, 0), (2, 1, 0)]);
        assert_eq!(
            ids[3..6].iter().map(|i| (i.lod, i.x, i.y)).collect::<Vec<_>>(),
            vec![(1, 0, 0), (1, 1, 0), (1, 2, 0)]
        );
        assert_eq!(ids[23], TileId { lod: 0, x: 4, y: 2 });
    }
}
