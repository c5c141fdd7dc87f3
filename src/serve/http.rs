//! The one request handler: method, route, input, then the answer with its headers
//! (`Content-Type`, `ETag` / `If-None-Match`, `Cache-Control`, CORS, `Range` for packs); the
//! tiles themselves are `tile_routes`'.
//!
//! Every request holds a permit of `--max-concurrent` while it is answered; decoding and
//! encoding run on tokio's blocking threads, at most one per core at a time. No request can
//! panic the server: each path returns a status and a short text.

use std::path::Path;
use std::sync::Arc;
use std::time::UNIX_EPOCH;

use axum::body::Body;
use axum::extract::{Request, State};
use axum::http::{HeaderMap, Method, StatusCode, header};
use axum::response::{IntoResponse, Response};
use bytes::Bytes;

use super::AppState;
use super::catalog::{Input, Source, StaticDir, StaticLayout, Tiled, map_slice};
use super::files::{self, Refused};
use super::html;
use super::range::{self, RangeError};
use super::reply::{FileBody, Payload, Reply, TILE_CACHE, conditional, etag, not_modified};
use super::routes::{self, Reject, Route, bad, not_found};
use super::tile_routes::{dzi_extension, dzi_tile, iiif_extension, iiif_tile, xyz_tile};
use crate::formats::viewer::{dzi, iiif, xyz};

/// `Cache-Control` of manifests and pages.
const MANIFEST_CACHE: &str = "public, max-age=60";
const PAGE_CACHE: &str = "no-cache";

pub async fn handle(State(state): State<Arc<AppState>>, request: Request) -> Response {
    let Ok(_permit) = state.requests.acquire().await else {
        return respond(Reply::text(StatusCode::SERVICE_UNAVAILABLE, "shutting down"), false);
    };
    let method = request.method().clone();
    // RFC 9112, 3.2: a request with more than one Host is answered 400 (which one the IIIF id
    // would name is ambiguous).
    let reply = if request.headers().get_all(header::HOST).iter().nth(1).is_some() {
        Reply::from(bad("more than one Host header"))
    } else if method == Method::GET || method == Method::HEAD {
        answer(&state, request.uri().path(), request.headers()).await.unwrap_or_else(Reply::from)
    } else if method == Method::OPTIONS {
        Reply { status: StatusCode::NO_CONTENT, ..Reply::new("text/plain", Bytes::new()) }
            .with(header::ACCESS_CONTROL_ALLOW_METHODS, "GET, HEAD, OPTIONS")
            .with(header::ACCESS_CONTROL_ALLOW_HEADERS, "Range, If-None-Match")
            .with(header::ACCESS_CONTROL_MAX_AGE, "86400")
    } else {
        Reply::text(StatusCode::METHOD_NOT_ALLOWED, format!("{method} is not served; use GET or HEAD"))
            .with(header::ALLOW, "GET, HEAD, OPTIONS")
    };
    respond(reply, method == Method::HEAD)
}

/// The reply as an HTTP response; a HEAD request's has the same headers and no body.
fn respond(reply: Reply, head: bool) -> Response {
    let mut response = reply.into_response();
    if head {
        *response.body_mut() = Body::empty();
    }
    response
}

async fn answer(state: &Arc<AppState>, path: &str, headers: &HeaderMap) -> Result<Reply, Reject> {
    let route = routes::parse(path)?;
    let input_named = |name: &str| -> Result<(usize, &Input), Reject> {
        state
            .catalog
            .inputs
            .iter()
            .enumerate()
            .find(|(_, i)| i.name == name)
            .ok_or_else(|| not_found(format!("no input is named '{name}'")))
    };
    match route {
        Route::Index => {
            Ok(Reply::new("text/html; charset=utf-8", html::index(&state.catalog))
                .with(header::CACHE_CONTROL, PAGE_CACHE))
        }
        Route::View(name) => {
            let (_, input) = input_named(&name)?;
            let source =
                html::tile_source(input).ok_or_else(|| not_found(format!("'{name}' has no Deep Zoom or IIIF view")))?;
            let page = html::view(input, &source, state.openseadragon.is_some());
            Ok(Reply::new("text/html; charset=utf-8", page).with(header::CACHE_CONTROL, PAGE_CACHE))
        }
        Route::OpenSeadragon(rest) => {
            let root = state.openseadragon.as_deref().ok_or_else(|| not_found("no --openseadragon directory"))?;
            static_file(root, &rest, 0, headers).await
        }
        Route::DziDescriptor(name) => match &input_named(&name)?.1.source {
            Source::Tiled(t) => {
                let l = t.layout.down_to_one_texel();
                let body = dzi::descriptor(&l, dzi_extension(t));
                let etag = etag(t.etag, "dzi");
                Ok(conditional(headers, &etag, || Reply::new("application/xml", body).cached(MANIFEST_CACHE, &etag)))
            }
            Source::Static(s @ StaticDir { layout: StaticLayout::Dzi { stem }, .. }) => {
                static_file(&s.root, &[format!("{stem}.dzi")], s.etag, headers).await
            }
            Source::Static(_) => Err(not_found(format!("'{name}' is not a Deep Zoom pyramid"))),
        },
        Route::DziFiles { name, rest } => match input_named(&name)? {
            (index, Input { source: Source::Tiled(t), .. }) => {
                dzi_tile(state, index, t, routes::dzi_tile(&rest)?, headers).await
            }
            (_, Input { source: Source::Static(s @ StaticDir { layout: StaticLayout::Dzi { stem }, .. }), .. }) => {
                image_name(&routes::dzi_tile(&rest)?.extension)?;
                let rel: Vec<String> = std::iter::once(format!("{stem}_files")).chain(rest).collect();
                static_file(&s.root, &rel, s.etag, headers).await
            }
            _ => Err(not_found(format!("'{name}' is not a Deep Zoom pyramid"))),
        },
        Route::PackFile(name) => match &input_named(&name)?.1.source {
            Source::Tiled(t) if t.pack().is_some() => pack_file(t, headers),
            _ => Err(not_found(format!("'{name}' is not a pack"))),
        },
        Route::IiifBase(name) => {
            input_named(&name)?;
            Ok(Reply::text(StatusCode::SEE_OTHER, "see info.json")
                .with(header::LOCATION, format!("/{}/iiif/info.json", html::url_segment(&name))))
        }
        Route::Iiif { name, rest } => {
            let (index, input) = input_named(&name)?;
            let id = format!("http://{}/{}/iiif", host(state, headers), html::url_segment(&name));
            let is_info = rest.len() == 1 && rest[0] == "info.json";
            match &input.source {
                Source::Tiled(t) if is_info => {
                    let body = iiif::info_json(&t.layout, &id, iiif_extension(t), true);
                    Ok(iiif_info(body))
                }
                Source::Tiled(t) => iiif_tile(state, index, t, &rest, headers).await,
                Source::Static(StaticDir { layout: StaticLayout::Iiif { info }, .. }) if is_info => {
                    let mut info = info.clone();
                    if info.get("@id").is_some() {
                        info["@id"] = id.clone().into();
                    }
                    info["id"] = id.into();
                    let body = serde_json::to_string_pretty(&info).map_err(|e| bad(e.to_string()))?;
                    Ok(iiif_info(body))
                }
                Source::Static(s @ StaticDir { layout: StaticLayout::Iiif { .. }, .. }) => {
                    image_name(routes::iiif_tile(&rest)?.extension())?;
                    static_file(&s.root, &rest, s.etag, headers).await
                }
                Source::Static(_) => Err(not_found(format!("'{name}' is not a IIIF image"))),
            }
        }
        Route::Xyz { name, rest } => {
            let (index, input) = input_named(&name)?;
            match &input.source {
                Source::Tiled(t) => xyz_tile(state, index, t, &rest, headers).await,
                Source::Static(s @ StaticDir { layout: StaticLayout::Xyz, .. }) => {
                    if rest != [xyz::TILEJSON] {
                        image_name(&routes::xyz_tile(&rest)?.extension)?;
                    }
                    static_file(&s.root, &rest, s.etag, headers).await
                }
                Source::Static(_) => Err(not_found(format!("'{name}' has no XYZ tiles"))),
            }
        }
    }
}

/// An `info.json`: its `id` names the Host the request named, so a shared cache must keep one
/// per Host.
fn iiif_info(body: String) -> Reply {
    Reply::new("application/json", body).with(header::CACHE_CONTROL, MANIFEST_CACHE).with(header::VARY, "Host")
}

/// Only tile images are served from a viewer-layout directory, with the manifest: no other
/// file a directory may hold (`.git/`, notes, a key).
fn image_name(extension: &str) -> Result<(), Reject> {
    match extension {
        "jpg" | "jpeg" | "png" | "webp" => Ok(()),
        _ => Err(not_found(format!("'.{extension}' files are not tiles of this directory"))),
    }
}

/// The Host header if it looks like one, else the address the server listens on (the IIIF
/// `id` must be an absolute URL a viewer can fetch).
fn host(state: &AppState, headers: &HeaderMap) -> String {
    headers
        .get(header::HOST)
        .and_then(|h| h.to_str().ok())
        .filter(|h| {
            !h.is_empty() && h.len() < 256 && h.bytes().all(|b| b.is_ascii_alphanumeric() || b".-:[]_".contains(&b))
        })
        .map_or_else(|| state.local_addr.to_string(), str::to_string)
}

/// The pack file, whole or one byte range of it, straight from its memory map.
fn pack_file(t: &Tiled, headers: &HeaderMap) -> Result<Reply, Reject> {
    let Some(pack) = t.pack() else { return Err(not_found("not a pack")) };
    let etag = format!("\"{:016x}\"", t.etag);
    let len = pack.file().len() as u64;
    // RFC 9110, 13.2.2: If-None-Match is evaluated before Range.
    if let Some(r) = not_modified(headers, &etag) {
        return Ok(r);
    }
    let ranged = headers
        .get(header::RANGE)
        .map(|v| v.to_str().map_err(|_| RangeError::Malformed).and_then(|v| range::parse(v, len)));
    let base = |status, body: Bytes| {
        Reply { status, ..Reply::new("application/octet-stream", body) }
            .cached(TILE_CACHE, &etag)
            .with(header::ACCEPT_RANGES, "bytes")
    };
    match ranged {
        // No Range, or one in a unit other than bytes (ignored, RFC 9110 14.2).
        None | Some(Ok(None)) => Ok(base(StatusCode::OK, map_slice(pack, 0, len as usize))),
        Some(Ok(Some((first, last)))) => {
            let body = map_slice(pack, first as usize, (last - first + 1) as usize);
            Ok(base(StatusCode::PARTIAL_CONTENT, body)
                .with(header::CONTENT_RANGE, format!("bytes {first}-{last}/{len}")))
        }
        Some(Err(RangeError::Malformed)) => Err(bad("malformed Range header (one range: bytes=A-B, A- or -N)")),
        Some(Err(e)) => {
            let why = if e == RangeError::Multiple {
                "only one range per request is served"
            } else {
                "the range is past the end"
            };
            Ok(Reply::text(StatusCode::RANGE_NOT_SATISFIABLE, why)
                .with(header::CONTENT_RANGE, format!("bytes */{len}")))
        }
    }
}

/// A file under `root` (a viewer-layout directory, OpenSeadragon's build), streamed from
/// disk: the segments were checked by `routes`; it is opened only as a regular file whose
/// canonical path lies under `root` (no link out of it, no FIFO or device).
async fn static_file(root: &Path, rel: &[String], base: u64, headers: &HeaderMap) -> Result<Reply, Reject> {
    let mut path = root.to_path_buf();
    path.extend(rel);
    let root = root.to_path_buf();
    let opened = tokio::task::spawn_blocking(move || files::open_under(&root, &path).map(|f| (path, f)));
    let (path, (file, meta)) = match opened.await {
        Ok(Ok(opened)) => opened,
        Ok(Err(Refused::Refused(why))) => {
            eprintln!("serve: {why}");
            return Err(not_found(format!("/{}", rel.join("/"))));
        }
        Ok(Err(Refused::Missing)) | Err(_) => return Err(not_found(format!("/{}", rel.join("/")))),
    };
    let (len, mtime) = (meta.len(), meta.modified().ok().and_then(|t| t.duration_since(UNIX_EPOCH).ok()));
    let etag = etag(base, &format!("{}:{len}:{}", rel.join("/"), mtime.map_or(0, |d| d.as_nanos())));
    if let Some(r) = not_modified(headers, &etag) {
        return Ok(r);
    }
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
    let (content_type, cache) = match ext.as_str() {
        "jpg" | "jpeg" => ("image/jpeg", TILE_CACHE),
        "png" => ("image/png", TILE_CACHE),
        "webp" => ("image/webp", TILE_CACHE),
        "json" => ("application/json", MANIFEST_CACHE),
        "dzi" | "xml" => ("application/xml", MANIFEST_CACHE),
        "js" => ("text/javascript", MANIFEST_CACHE),
        "css" => ("text/css", MANIFEST_CACHE),
        "html" => ("text/html; charset=utf-8", PAGE_CACHE),
        _ => ("application/octet-stream", MANIFEST_CACHE),
    };
    let body = Payload::File(FileBody { file: tokio::fs::File::from_std(file), left: len, chunk: Vec::new() });
    Ok(Reply { body, ..Reply::new(content_type, Bytes::new()) }.cached(cache, &etag))
}
