//! A finished answer ([`Reply`]) and the rules every route's answer follows: `Cache-Control`
//! and `ETag`, a 304 for a client that holds the bytes, the CORS headers, a file streamed
//! from disk. Below the routes (`http`, `tile_routes`), which both answer with it.

use std::pin::Pin;
use std::task::{Context, Poll};

use axum::body::Body;
use axum::http::{HeaderMap, HeaderName, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use bytes::Bytes;
use hyper::body::{Body as HttpBody, Frame, SizeHint};
use tokio::io::{AsyncRead, ReadBuf};

use super::routes::Reject;

/// `Cache-Control` of tiles and packs (their URLs name immutable content).
pub(super) const TILE_CACHE: &str = "public, max-age=86400";
/// A finished answer before the method and CORS headers are applied.
pub(super) struct Reply {
    pub(super) status: StatusCode,
    pub(super) content_type: &'static str,
    pub(super) body: Payload,
    pub(super) headers: Vec<(HeaderName, String)>,
}

/// A body in memory (tiles, manifests, pages, the pack's map) or a file streamed from disk.
pub(super) enum Payload {
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
    pub(super) fn text(status: StatusCode, message: impl std::fmt::Display) -> Reply {
        Reply { status, ..Reply::new("text/plain; charset=utf-8", format!("{message}\n")) }
    }
    pub(super) fn with(mut self, name: HeaderName, value: impl Into<String>) -> Reply {
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

/// Every answer carries its `Content-Type`, its length (but a 304's and a 204's) and the CORS
/// headers that let a viewer on any origin read it.
impl IntoResponse for Reply {
    fn into_response(self) -> Response {
        let reply = self;
        let len = reply.body.len();
        let body = match reply.body {
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
}

pub(super) fn etag(base: u64, key: &str) -> String {
    format!("\"{base:016x}-{:016x}\"", crate::fnv::hash(key.as_bytes()))
}

/// 304 if the client holds `etag`, else `make()`.
pub(super) fn conditional(headers: &HeaderMap, etag: &str, make: impl FnOnce() -> Reply) -> Reply {
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

/// A file sent in chunks as the client takes them, so a download holds one chunk in memory,
/// not the file. Exactly the length the headers announced is sent: a file that shrank while
/// it was sent ends the connection with an error, one that grew is cut at that length.
pub(super) struct FileBody {
    pub(super) file: tokio::fs::File,
    pub(super) left: u64,
    /// The buffer a read fills (kept across polls: a read may be pending).
    pub(super) chunk: Vec<u8>,
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
