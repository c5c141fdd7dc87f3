//! The one request handler: method, route, input, then the answer with its headers
//! (`Content-Type`, `ETag` / `If-None-Match`, `Cache-Control`, CORS, `Range` for packs); the
//! tiles themselves are `tile_routes`'.
//!
//! Every request holds a permit of `--max-concurrent` while it is answered; decoding and
//! encoding run on tokio's blocking threads, at most one per core at a time. No request can
//! panic the server: each path returns a status and a short text.

use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use axum::body::Body;
use axum::extract::{Request, State};
use axum::http::{HeaderMap, HeaderName, HeaderValue, Method, StatusCode, header};
use axum::response::Response;
use bytes::Bytes;
use tokio::sync::Semaphore;

use super::cache::TileCache;
use super::catalog::{Catalog, Input, Source, StaticDir, StaticLayout, Tiled, map_slice};
use super::html;
use super::range::{self, RangeError};
use super::routes::{self, Reject, Route, bad, not_found};
use super::tile_routes::{dzi_extension, dzi_tile, iiif_extension, iiif_tile, xyz_tile};
use crate::viewer::{dzi, iiif};

/// `Cache-Control` of tiles and packs (their URLs name immutable content).
pub(super) const TILE_CACHE: &str = "public, max-age=86400";
/// `Cache-Control` of manifests and pages.
const MANIFEST_CACHE: &str = "public, max-age=60";
const PAGE_CACHE: &str = "no-cache";

pub struct AppState {
    pub catalog: Catalog,
    pub cache: TileCache,
    /// `--max-concurrent`: requests answered at once.
    pub requests: Semaphore,
    /// Decode-and-encode jobs at once (one per core).
    pub blocking: Arc<Semaphore>,
    /// The local OpenSeadragon build (canonical), if given.
    pub openseadragon: Option<PathBuf>,
    pub local_addr: SocketAddr,
}

/// A finished answer before the method and CORS headers are applied.
pub(super) struct Reply {
    status: StatusCode,
    content_type: &'static str,
    body: Bytes,
    headers: Vec<(HeaderName, String)>,
}

impl Reply {
    pub(super) fn new(content_type: &'static str, body: impl Into<Bytes>) -> Reply {
        Reply { status: StatusCode::OK, content_type, body: body.into(), headers: Vec::new() }
    }
    fn text(status: StatusCode, message: impl std::fmt::Display) -> Reply {
        Reply { status, ..Reply::new("text/plain; charset=utf-8", format!("{message}\n")) }
    }
    fn with(mut self, name: HeaderName, value: impl Into<String>) -> Reply {
        self.headers.push((name, value.into()));
        self
    }
    pub(super) fn cached(self, cache_control: &str, etag: &str) -> Reply {
        self.with(header::CACHE_CONTROL, cache_control).with(header::ETAG, etag)
    }
}

impl From<Reject> for Reply {
    fn from(r: Reject) -> Reply {
        match r {
            Reject::BadRequest(_) => Reply::text(StatusCode::BAD_REQUEST, r),
            Reject::NotFound(_) => Reply::text(StatusCode::NOT_FOUND, r),
        }
    }
}

pub(super) fn internal(message: impl std::fmt::Display) -> Reply {
    eprintln!("serve: {message}");
    Reply::text(StatusCode::INTERNAL_SERVER_ERROR, message)
}

pub async fn handle(State(state): State<Arc<AppState>>, request: Request) -> Response {
    let Ok(_permit) = state.requests.acquire().await else {
        return respond(Reply::text(StatusCode::SERVICE_UNAVAILABLE, "shutting down"), false);
    };
    let method = request.method().clone();
    let reply = if method == Method::GET || method == Method::HEAD {
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

fn respond(reply: Reply, head: bool) -> Response {
    let len = reply.body.len();
    let mut response = Response::new(if head { Body::empty() } else { Body::from(reply.body) });
    *response.status_mut() = reply.status;
    let h = response.headers_mut();
    h.insert(header::CONTENT_TYPE, HeaderValue::from_static(reply.content_type));
    if reply.status != StatusCode::NOT_MODIFIED && reply.status != StatusCode::NO_CONTENT {
        h.insert(header::CONTENT_LENGTH, HeaderValue::from(len));
    }
    h.insert(header::ACCESS_CONTROL_ALLOW_ORIGIN, HeaderValue::from_static("*"));
    h.insert(
        header::ACCESS_CONTROL_EXPOSE_HEADERS,
        HeaderValue::from_static("ETag, Content-Length, Content-Range, Accept-Ranges"),
    );
    for (name, value) in reply.headers {
        if let Ok(v) = HeaderValue::from_str(&value) {
            h.append(name, v);
        }
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
                    let body = iiif::info_json(&t.layout, &id, iiif_extension(t));
                    Ok(Reply::new("application/json", body).with(header::CACHE_CONTROL, MANIFEST_CACHE))
                }
                Source::Tiled(t) => iiif_tile(state, index, t, &rest, headers).await,
                Source::Static(StaticDir { layout: StaticLayout::Iiif { info }, .. }) if is_info => {
                    let mut info = info.clone();
                    if info.get("@id").is_some() {
                        info["@id"] = id.clone().into();
                    }
                    info["id"] = id.into();
                    let body = serde_json::to_string_pretty(&info).map_err(|e| bad(e.to_string()))?;
                    Ok(Reply::new("application/json", body).with(header::CACHE_CONTROL, MANIFEST_CACHE))
                }
                Source::Static(s @ StaticDir { layout: StaticLayout::Iiif { .. }, .. }) => {
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
                    static_file(&s.root, &rest, s.etag, headers).await
                }
                Source::Static(_) => Err(not_found(format!("'{name}' has no XYZ tiles"))),
            }
        }
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

pub(super) fn etag(base: u64, key: &str) -> String {
    format!("\"{base:016x}-{:016x}\"", vortex_pack::format::fnv1a(0xcbf2_9ce4_8422_2325, key.as_bytes()))
}

/// 304 if the client holds `etag`, else `make()`.
fn conditional(headers: &HeaderMap, etag: &str, make: impl FnOnce() -> Reply) -> Reply {
    let held =
        headers.get_all(header::IF_NONE_MATCH).iter().filter_map(|v| v.to_str().ok()).any(|v| {
            v.split(',').map(|t| t.trim()).any(|t| t == "*" || t == etag || t.strip_prefix("W/") == Some(etag))
        });
    if held {
        Reply { status: StatusCode::NOT_MODIFIED, ..Reply::new("text/plain", Bytes::new()) }.cached(TILE_CACHE, etag)
    } else {
        make()
    }
}

pub(super) fn not_modified(headers: &HeaderMap, etag: &str) -> Option<Reply> {
    let r = conditional(headers, etag, || Reply::new("text/plain", Bytes::new()));
    (r.status == StatusCode::NOT_MODIFIED).then_some(r)
}

/// The pack file, whole or one byte range of it, straight from its memory map.
fn pack_file(t: &Tiled, headers: &HeaderMap) -> Result<Reply, Reject> {
    let Some(pack) = t.pack() else { return Err(not_found("not a pack")) };
    let etag = format!("\"{:016x}\"", t.etag);
    let len = pack.file().len() as u64;
    let ranged = headers
        .get(header::RANGE)
        .map(|v| v.to_str().map_err(|_| RangeError::Malformed).and_then(|v| range::parse(v, len)));
    let base = |status, body: Bytes| {
        Reply { status, ..Reply::new("application/octet-stream", body) }
            .cached(TILE_CACHE, &etag)
            .with(header::ACCEPT_RANGES, "bytes")
    };
    match ranged {
        None => Ok(conditional(headers, &etag, || base(StatusCode::OK, map_slice(pack, 0, len as usize)))),
        Some(Ok((first, last))) => {
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

/// A file under `root` (a viewer-layout directory, OpenSeadragon's build): the segments were
/// checked by `routes`; the canonical path must still lie under `root` (no link out of it).
async fn static_file(root: &Path, rel: &[String], base: u64, headers: &HeaderMap) -> Result<Reply, Reject> {
    let missing = || not_found(format!("/{}", rel.join("/")));
    let mut path = root.to_path_buf();
    path.extend(rel);
    let root = root.to_path_buf();
    // Reads the file on a blocking thread: its canonical path, its size and mtime, its bytes.
    let read = tokio::task::spawn_blocking(move || -> Option<(PathBuf, u64, u128, Vec<u8>)> {
        let path = std::fs::canonicalize(&path).ok().filter(|p| p.starts_with(&root))?;
        let meta = std::fs::metadata(&path).ok().filter(|m| m.is_file())?;
        let mtime = meta.modified().ok()?.duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_nanos());
        let bytes = std::fs::read(&path).ok()?;
        Some((path, meta.len(), mtime, bytes))
    });
    let (path, len, mtime, bytes) = read.await.ok().flatten().ok_or_else(missing)?;
    let etag = etag(base, &format!("{}:{len}:{mtime}", rel.join("/")));
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
    Ok(Reply::new(content_type, bytes).cached(cache, &etag))
}
