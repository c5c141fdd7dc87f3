//! The one request handler: method, route, input, then the answer with its headers
//! (`Content-Type`, `ETag` / `If-None-Match`, `Cache-Control`, CORS, `Range` for packs); the
//! tiles themselves are `tile_routes`'.
//!
//! Every request holds a permit of `--max-concurrent` while it is answered; decoding and
//! encoding run on tokio's blocking threads, at most one per core at a time. No request can
//! panic the server: each path returns a status and a short text.

use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::pin::Pin;
use std::sync::Arc;
use std::task::{Context, Poll};
use std::time::UNIX_EPOCH;

use axum::body::Body;
use axum::extract::{Request, State};
use axum::http::{HeaderMap, HeaderName, HeaderValue, Method, StatusCode, header};
use axum::response::Response;
use bytes::Bytes;
use hyper::body::{Body as HttpBody, Frame, SizeHint};
use tokio::io::{AsyncRead, ReadBuf};
use tokio::sync::Semaphore;

use super::cache::TileCache;
use super::catalog::{Catalog, Input, Source, StaticDir, StaticLayout, Tiled, map_slice};
use super::files::{self, Refused};
use super::html;
use super::range::{self, RangeError};
use super::routes::{self, Reject, Route, bad, not_found};
use super::tile_routes::{dzi_extension, dzi_tile, iiif_extension, iiif_tile, xyz_tile};
use crate::viewer::{dzi, iiif, xyz};

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
    body: Payload,
    headers: Vec<(HeaderName, String)>,
}

/// A body in memory (tiles, manifests, pages, the pack's map) or a file streamed from disk.
enum Payload {
    Bytes(Bytes),
    File(FileBody),
}

impl Payload {
    fn len(&self) -> u64 {
        match self {
            Payload::Bytes(b) => b.len() as u64,
            Payload::File(f) => f.left,
        }
    }
}

impl Reply {
    pub(super) fn new(content_type: &'static str, body: impl Into<Bytes>) -> Reply {
        Reply { status: StatusCode::OK, content_type, body: Payload::Bytes(body.into()), headers: Vec::new() }
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

fn respond(reply: Reply, head: bool) -> Response {
    let len = reply.body.len();
    let body = match reply.body {
        _ if head => Body::empty(),
        Payload::Bytes(b) => Body::from(b),
        Payload::File(f) => Body::new(f),
    };
    let mut response = Response::new(body);
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

pub(super) fn etag(base: u64, key: &str) -> String {
    format!("\"{base:016x}-{:016x}\"", crate::fnv::hash(key.as_bytes()))
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

/// A file sent in chunks as the client takes them, so a download holds one chunk in memory,
/// not the file. Exactly the length the headers announced is sent: a file that shrank while
/// it was sent ends the connection with an error, one that grew is cut at that length.
pub(super) struct FileBody {
    file: tokio::fs::File,
    left: u64,
    /// The buffer a read fills (kept across polls: a read may be pending).
    chunk: Vec<u8>,
}

/// Bytes read from a file at a time.
const CHUNK: usize = 64 << 10;

impl HttpBody for FileBody {
    type Data = Bytes;
    type Error = std::io::Error;

    fn poll_frame(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
    ) -> Poll<Option<Result<Frame<Bytes>, std::io::Error>>> {
        let this = &mut *self;
        if this.left == 0 {
            return Poll::Ready(None);
        }
        let want = this.left.min(CHUNK as u64) as usize;
        this.chunk.resize(want, 0);
        let mut buf = ReadBuf::new(&mut this.chunk);
        match Pin::new(&mut this.file).poll_read(cx, &mut buf) {
            Poll::Pending => Poll::Pending,
            Poll::Ready(Err(e)) => Poll::Ready(Some(Err(e))),
            Poll::Ready(Ok(())) if buf.filled().is_empty() => {
                Poll::Ready(Some(Err(std::io::Error::new(std::io::ErrorKind::UnexpectedEof, "the file shrank"))))
            }
            Poll::Ready(Ok(())) => {
                let data = Bytes::copy_from_slice(buf.filled());
                this.left -= data.len() as u64;
                Poll::Ready(Some(Ok(Frame::data(data))))
            }
        }
    }

    fn is_end_stream(&self) -> bool {
        self.left == 0
    }

    fn size_hint(&self) -> SizeHint {
        SizeHint::with_exact(self.left)
    }
}
