//! Viewer tiles of a pyramid of pages: a Deep Zoom, IIIF or XYZ tile name into the page it
//! comes from and the crop of it (names and crops from [`crate::formats::viewer`]), then the tile
//! itself: the stored bytes when they are it, else the cache, else decoded, cropped and
//! encoded on a blocking thread.

use std::sync::Arc;

use axum::http::HeaderMap;
use bytes::Bytes;

use super::AppState;
use super::catalog::{Source, Tiled, stored_image};
use super::reply::{Reply, TILE_CACHE, etag, internal, not_modified};
use super::routes::{self, Reject, bad, not_found};
use super::tiles::{self, Job};
use crate::formats::viewer::iiif::whole as iiif_whole;
use crate::formats::viewer::{Crop, Viewer, dzi, iiif};
use crate::source::decode_tile;

pub(super) fn dzi_extension(t: &Tiled) -> &'static str {
    t.format.extension(Viewer::Dzi)
}

pub(super) fn iiif_extension(t: &Tiled) -> &'static str {
    t.format.extension(Viewer::Iiif)
}

pub(super) async fn dzi_tile(
    state: &Arc<AppState>,
    index: usize,
    t: &Tiled,
    tile: routes::DziTile,
    headers: &HeaderMap,
) -> Result<Reply, Reject> {
    let ext = dzi_extension(t);
    if tile.extension != ext {
        return Err(not_found(format!("the Deep Zoom tiles of this input are .{ext}")));
    }
    let l = t.layout.down_to_one_texel();
    let max = dzi::max_level(l.width, l.height);
    if tile.level > max {
        return Err(not_found(format!("level {} is past the finest, {max}", tile.level)));
    }
    let lod = max - tile.level;
    let (c, r) = l.grid(lod);
    if tile.col >= c || tile.row >= r {
        return Err(not_found(format!("level {} has {c} x {r} tiles", tile.level)));
    }
    let crop = dzi::crop(&l, lod, tile.col, tile.row);
    let stored = t.layout.lod_count;
    let (page, halvings, extent) = if lod < stored {
        ((lod, tile.col, tile.row), 0, (0, 0))
    } else {
        ((stored - 1, 0, 0), lod - (stored - 1), t.layout.level_extent(stored - 1))
    };
    let key = format!("dzi/{}/{}_{}", tile.level, tile.col, tile.row);
    let job = Job { side: t.layout.tile_size, border: t.layout.border, crop, extent, halvings, codec: t.codec };
    serve_tile(state, index, t, page, job, &key, headers).await
}

pub(super) async fn iiif_tile(
    state: &Arc<AppState>,
    index: usize,
    t: &Tiled,
    rest: &[String],
    headers: &HeaderMap,
) -> Result<Reply, Reject> {
    let (l, ext) = (&t.layout, iiif_extension(t));
    let not_a_tile = || not_found(format!("'{}' is not a IIIF tile of this image", rest.join("/")));
    let (lod, col, row) = match routes::iiif_tile(rest)? {
        routes::IiifTile::Full { path } => {
            // `full/max` and the sizes info.json lists: the whole image at one LOD.
            let max = iiif::max_lod(l);
            let lod = iiif::whole_sizes(l)
                .into_iter()
                .find(|&(lod, w, h)| iiif::full_path(w, h, ext) == path || (lod == max && iiif::max_path(ext) == path))
                .map(|(lod, ..)| lod)
                .ok_or_else(not_a_tile)?;
            if lod + 1 < l.lod_count {
                return whole_image(state, index, t, lod, headers).await;
            }
            (lod, 0, 0)
        }
        routes::IiifTile::Region { x, y, path } => (0..l.lod_count.saturating_sub(1))
            .find_map(|lod| {
                let side = (l.payload() as u64) << lod;
                let (col, row) = (u32::try_from(x / side).ok()?, u32::try_from(y / side).ok()?);
                let (c, r) = l.grid(lod);
                let named = x % side == 0 && y % side == 0 && col < c && row < r;
                (named && iiif::tile_path(l, lod, col, row, ext) == path).then_some((lod, col, row))
            })
            .ok_or_else(not_a_tile)?,
    };
    // IIIF tiles have no overlap: the page's payload, cut at the image's edge.
    let c = iiif::crop(l, lod, col, row);
    let crop = Crop { x: c.x + l.border, y: c.y + l.border, ..c };
    let key = format!("iiif/{lod}/{col}/{row}");
    let job = Job { side: l.tile_size, border: l.border, crop, extent: (0, 0), halvings: 0, codec: t.codec };
    serve_tile(state, index, t, (lod, col, row), job, &key, headers).await
}

/// The whole image at `lod` (more than one page), assembled from its pages on a blocking
/// thread and cached.
async fn whole_image(
    state: &Arc<AppState>,
    index: usize,
    t: &Tiled,
    lod: u32,
    headers: &HeaderMap,
) -> Result<Reply, Reject> {
    let key = format!("iiif/full/{lod}");
    let etag = etag(t.etag, &key);
    let reply = |bytes: Bytes| Reply::new(t.format.content_type(), bytes).cached(TILE_CACHE, &etag);
    if let Some(r) = not_modified(headers, &etag) {
        return Ok(r);
    }
    let cache_key = format!("{index}/{key}");
    if let Some(bytes) = state.cache.get(&cache_key) {
        return Ok(reply(bytes));
    }
    let permit = state.blocking.clone().acquire_owned().await.map_err(|_| bad("shutting down"))?;
    let shared = state.clone();
    let work = tokio::task::spawn_blocking(move || -> Result<Bytes, String> {
        let _permit = permit;
        let Some(Source::Tiled(t)) = shared.catalog.inputs.get(index).map(|i| &i.source) else {
            return Err("the input is gone".into());
        };
        let l = &t.layout;
        let bytes = iiif_whole::assemble(l, lod, t.codec, |col, row| {
            let page = t.page(lod, col, row)?.ok_or_else(|| format!("page (lod {lod}, x {col}, y {row}) is absent"))?;
            let decoded = match page {
                tiles::Page::Image(_, bytes) => {
                    decode_tile(std::path::Path::new("page"), &bytes).map_err(|e| e.to_string())?
                }
                tiles::Page::Texels(decoded) => decoded,
            };
            // IIIF tiles have no overlap: the page's payload, cut at the image's edge.
            let c = iiif::crop(l, lod, col, row);
            Ok((decoded, Crop { x: c.x + l.border, y: c.y + l.border, ..c }))
        })?;
        Ok(Bytes::from(bytes))
    });
    match work.await {
        Ok(Ok(bytes)) => {
            state.cache.insert(cache_key, bytes.clone());
            Ok(reply(bytes))
        }
        Ok(Err(message)) => Ok(internal(format!("the whole image at LOD {lod}: {message}"))),
        Err(e) => Ok(internal(format!("the whole image at LOD {lod}: {e}"))),
    }
}

pub(super) async fn xyz_tile(
    state: &Arc<AppState>,
    index: usize,
    t: &Tiled,
    rest: &[String],
    headers: &HeaderMap,
) -> Result<Reply, Reject> {
    let tile = routes::xyz_tile(rest)?;
    let l = &t.layout;
    let ext = t.format.extension(Viewer::Xyz);
    if tile.extension != ext {
        return Err(not_found(format!("the XYZ tiles of this input are .{ext}")));
    }
    if tile.zoom >= l.lod_count {
        return Err(not_found(format!("zoom {} is past the finest, {}", tile.zoom, l.lod_count - 1)));
    }
    let lod = l.lod_count - 1 - tile.zoom;
    let (c, r) = l.grid(lod);
    if tile.x >= c || tile.y >= r {
        return Err(not_found(format!("zoom {} has {c} x {r} tiles holding the image", tile.zoom)));
    }
    // The payload, whole: edge tiles hold the pack's own padding past the image.
    let p = l.payload();
    let crop = Crop { x: l.border, y: l.border, width: p, height: p };
    let key = format!("xyz/{lod}/{}/{}", tile.x, tile.y);
    let job = Job { side: l.tile_size, border: l.border, crop, extent: (0, 0), halvings: 0, codec: t.codec };
    serve_tile(state, index, t, (lod, tile.x, tile.y), job, &key, headers).await
}

/// One viewer tile: the stored bytes when they are it, else from the cache, else decoded,
/// cropped and encoded on a blocking thread (and cached).
async fn serve_tile(
    state: &Arc<AppState>,
    index: usize,
    t: &Tiled,
    (lod, x, y): (u32, u32, u32),
    job: Job,
    key: &str,
    headers: &HeaderMap,
) -> Result<Reply, Reject> {
    let etag = etag(t.etag, key);
    let reply = |bytes: Bytes| Reply::new(t.format.content_type(), bytes).cached(TILE_CACHE, &etag);
    if let Some(r) = not_modified(headers, &etag) {
        return Ok(r);
    }
    if let Some(pack) = t.pack()
        && job.halvings == 0
        && job.crop == Crop::whole(job.side)
        && let Some((format, bytes)) = stored_image(pack, lod, x, y)
        && format == t.format
    {
        return Ok(reply(bytes));
    }
    let cache_key = format!("{index}/{key}");
    if let Some(bytes) = state.cache.get(&cache_key) {
        return Ok(reply(bytes));
    }
    let permit = state.blocking.clone().acquire_owned().await.map_err(|_| bad("shutting down"))?;
    let shared = state.clone();
    let work = tokio::task::spawn_blocking(move || -> Result<Option<(Bytes, bool)>, String> {
        let _permit = permit;
        let Some(Source::Tiled(t)) = shared.catalog.inputs.get(index).map(|i| &i.source) else {
            return Ok(None);
        };
        let Some(page) = t.page(lod, x, y)? else { return Ok(None) };
        if let Some(bytes) = tiles::as_stored(&page, &job, t.format) {
            return Ok(Some((bytes, false)));
        }
        tiles::render(page, &job).map(|b| Some((b, true)))
    });
    match work.await {
        Ok(Ok(Some((bytes, rendered)))) => {
            if rendered {
                state.cache.insert(cache_key, bytes.clone());
            }
            Ok(reply(bytes))
        }
        Ok(Ok(None)) => Err(not_found(format!("page (lod {lod}, x {x}, y {y}) is absent"))),
        Ok(Err(message)) => Ok(internal(format!("page (lod {lod}, x {x}, y {y}): {message}"))),
        Err(e) => Ok(internal(format!("page (lod {lod}, x {x}, y {y}): {e}"))),
    }
}
