//! Vortex packs in the browser: the pack protocol of `RemotePack` (the same code as the native
//! `HttpPack`'s: every header, index and payload CRC checked) over the page's `fetch` with
//! `Range` requests, awaited on the page's event loop. Nothing blocks: the web loader awaits
//! [`PageSource::prepare`] for a page, which fetches its tile and keeps it, and then decodes it
//! with [`PageSource::read_stored`], which answers from what was kept. A failed request (a
//! network error, a 5xx, a reply of the wrong range) is tried again after 100 ms, doubled each
//! time, six times in all. The browser keeps its own connections (six per host over HTTP/1.1),
//! so neighbouring reads are not merged here. A host that ignores `Range` (a 200 with the whole
//! file) is refused at open with the native reader's message, and a later whole-file reply is
//! dropped unread and retried, as there.
//!
//! A pack on another origin must be served with CORS headers that allow `Range` and expose
//! `Content-Range`.

use std::collections::{HashMap, VecDeque};
use std::future::Future;
use std::path::{Path, PathBuf};
use std::pin::Pin;
use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, Ordering};
use std::task::{Context, Poll, Waker};

use vortex_pack::{Limits, PackError, PackLayout, TileId, TileKind};
use wasm_bindgen::{JsCast, JsValue};
use wasm_bindgen_futures::JsFuture;

use super::pack::decode_stored;
use super::remote::{IndexPlan, RangeRead, RemotePack, ignores_range, lock, parse_content_range};
use super::{LocalFuture, PageSource, ReadError, SourceTile, StoredRead};
use crate::loader::LoaderError;
use crate::page_cache::CacheFormat;
use crate::texture::VirtualTexture;

/// Fetched tiles kept until the loader decodes them: far more than the loader ever has in
/// flight (it decodes a page as soon as its fetch is done), so none is dropped before use.
const HELD_TILES: usize = 512;

/// Attempts of one request before a read fails, and the wait before the first retry.
const ATTEMPTS: u32 = 6;
const BACKOFF_MS: i32 = 100;

/// What a web pack's reads have cost so far.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct WebStats {
    /// `fetch` requests made, retries included.
    pub requests: u64,
    /// Body bytes received.
    pub bytes: u64,
    /// Requests made again after a failure worth retrying.
    pub retries: u64,
    /// Payloads whose bytes failed their CRC.
    pub corrupt: u64,
}

/// A pack on a web server, read with `fetch` and `Range` on the page's event loop: a
/// [`PageSource`] for the browser.
pub struct WebPack {
    remote: RemotePack<FetchRange>,
    held: Mutex<Held>,
    gate: Mutex<Gate>,
}

#[derive(Default)]
struct Held {
    tiles: HashMap<TileId, Result<StoredRead, ReadError>>,
    order: VecDeque<TileId>,
}

/// Reads held back ([`WebPack::hold`]): tests take a frame while pages are in flight.
#[derive(Default)]
struct Gate {
    closed: bool,
    waiting: Vec<Waker>,
}

impl WebPack {
    /// Opens the pack at `url` (absolute, or relative to the page): its header, level table and
    /// metadata (and its index, when small) are fetched and checked, and its coarsest tile is
    /// fetched, so that a runtime made over it maps its root page at once.
    pub async fn open(url: &str) -> Result<WebPack, PackError> {
        let location = PathBuf::from(url);
        let reader = FetchRange { url: url.to_string(), counters: Counters::default() };
        // As `HttpOptions::default()`: a 1 MiB index (some 43,000 tiles) is read whole.
        let plan = IndexPlan { whole_up_to: 1 << 20, gap: 16 << 10 };
        let remote = RemotePack::open(location, reader, plan, Limits::default()).await?;
        let pack = WebPack { remote, held: Mutex::default(), gate: Mutex::default() };
        let root = pack.remote.layout().header().description.level_count.saturating_sub(1);
        pack.fetch(TileId { lod: root, x: 0, y: 0 }).await;
        Ok(pack)
    }

    /// The checked header and level table.
    pub fn layout(&self) -> &PackLayout {
        self.remote.layout()
    }

    /// The metadata: JSON text with the `info.json` members, its CRC checked.
    pub fn metadata(&self) -> &[u8] {
        self.remote.metadata()
    }

    /// What its reads have cost so far.
    pub fn stats(&self) -> WebStats {
        let c = &self.remote.reader().counters;
        let get = |a: &AtomicU64| a.load(Ordering::Relaxed);
        WebStats {
            requests: get(&c.requests),
            bytes: get(&c.bytes),
            retries: get(&c.retries),
            corrupt: get(&c.corrupt),
        }
    }

    /// Holds every later tile read until [`WebPack::release`] (reads already fetched stay): what
    /// a page looks like while its pages are in flight, on demand.
    pub fn hold(&self) {
        lock(&self.gate).closed = true;
    }

    /// Lets the reads held by [`WebPack::hold`] go on.
    pub fn release(&self) {
        let waiting = {
            let mut gate = lock(&self.gate);
            gate.closed = false;
            std::mem::take(&mut gate.waiting)
        };
        waiting.into_iter().for_each(Waker::wake);
    }

    /// Fetches tile `id` (once the gate is open) and keeps what came, or why not.
    async fn fetch(&self, id: TileId) {
        if lock(&self.held).tiles.contains_key(&id) {
            return;
        }
        Opened(&self.gate).await;
        let read = self.remote.stored(id).await;
        let mut held = lock(&self.held);
        if held.tiles.insert(id, read).is_none() {
            held.order.push_back(id);
        }
        while held.order.len() > HELD_TILES {
            if let Some(oldest) = held.order.pop_front() {
                held.tiles.remove(&oldest);
            }
        }
    }
}

impl PageSource for WebPack {
    fn location(&self) -> &Path {
        self.remote.location()
    }

    fn texture(&self) -> Result<VirtualTexture, LoaderError> {
        VirtualTexture::from_layout(self.remote.layout())
    }

    fn read_tile(&self, id: TileId, format: CacheFormat) -> Result<SourceTile, ReadError> {
        match self.read_stored(id)? {
            Some(read) => self.remote.texels(read, format),
            None => Ok(SourceTile::Absent),
        }
    }

    /// What [`PageSource::prepare`] fetched; a tile not fetched is an error, never a wait.
    fn read_stored(&self, id: TileId) -> Result<Option<StoredRead>, ReadError> {
        match lock(&self.held).tiles.get(&id) {
            Some(read) => read.clone().map(Some),
            // Not a wait, and not worth one: the loader prepares each tile before reading it.
            None => {
                Err(ReadError::unavailable("not fetched yet: the web loader prepares every tile before it reads it"))
            }
        }
    }

    fn decode(&self, _: TileId, kind: TileKind, bytes: &[u8], format: CacheFormat) -> Result<Vec<u8>, ReadError> {
        decode_stored(self.remote.layout(), kind, bytes, format)
    }

    fn prepare(&self, id: TileId) -> Option<LocalFuture<'_>> {
        Some(Box::pin(self.fetch(id)))
    }

    fn opaque(&self) -> bool {
        self.remote.opaque()
    }

    fn holds_only_bc7(&self) -> bool {
        self.remote.holds_only_bc7()
    }
}

/// Ready once the gate is open.
struct Opened<'a>(&'a Mutex<Gate>);

impl Future for Opened<'_> {
    type Output = ();

    fn poll(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<()> {
        let mut gate = lock(self.0);
        if !gate.closed {
            return Poll::Ready(());
        }
        gate.waiting.push(cx.waker().clone());
        Poll::Pending
    }
}

#[derive(Default)]
struct Counters {
    requests: AtomicU64,
    bytes: AtomicU64,
    retries: AtomicU64,
    corrupt: AtomicU64,
}

fn add(counter: &AtomicU64, n: u64) {
    counter.fetch_add(n, Ordering::Relaxed);
}

/// Whether a failed request is worth trying again.
enum Failure {
    Retry(String),
    Fatal(String),
}

/// Byte ranges of one URL by `fetch`.
struct FetchRange {
    url: String,
    counters: Counters,
}

impl RangeRead for FetchRange {
    async fn first(&self, n: u64) -> Result<(Vec<u8>, u64), ReadError> {
        self.with_retries(0, n, true).await
    }

    async fn read(&self, start: u64, end: u64) -> Result<Vec<u8>, ReadError> {
        if start >= end {
            return Ok(Vec::new());
        }
        self.with_retries(start, end, false).await.map(|(bytes, _)| bytes)
    }

    fn corrupt(&self) {
        add(&self.counters.corrupt, 1);
    }
}

impl FetchRange {
    async fn with_retries(&self, start: u64, end: u64, first: bool) -> Result<(Vec<u8>, u64), ReadError> {
        let mut wait = BACKOFF_MS;
        let mut tries = 1;
        loop {
            match self.request(start, end, first).await {
                Ok(answer) => return Ok(answer),
                Err(Failure::Fatal(message)) => return Err(ReadError::unavailable(message)),
                Err(Failure::Retry(message)) if tries >= ATTEMPTS => {
                    return Err(ReadError::io(format!("{message} ({tries} attempts)")));
                }
                Err(Failure::Retry(_)) => {
                    add(&self.counters.retries, 1);
                    sleep(wait).await;
                    wait = wait.saturating_mul(2);
                    tries += 1;
                }
            }
        }
    }

    /// One `Range` request for bytes `start..end`, and the file's length. `first`: the opening
    /// read, which may get fewer bytes than asked for (a file shorter than `end`).
    async fn request(&self, start: u64, end: u64, first: bool) -> Result<(Vec<u8>, u64), Failure> {
        let retry = |m: String| Failure::Retry(format!("bytes {start}..{end}: {m}"));
        let fatal = |m: String| Failure::Fatal(format!("bytes {start}..{end}: {m}"));
        add(&self.counters.requests, 1);
        let window = web_sys::window().ok_or_else(|| fatal("no window: packs are read from a page".into()))?;
        let init = web_sys::RequestInit::new();
        init.set_method("GET");
        let headers = web_sys::Headers::new().map_err(|e| fatal(js(e)))?;
        headers.set("Range", &format!("bytes={start}-{}", end - 1)).map_err(|e| fatal(js(e)))?;
        init.set_headers(&headers);
        let request = web_sys::Request::new_with_str_and_init(&self.url, &init).map_err(|e| fatal(js(e)))?;
        // A network error (refused, reset, offline) rejects the promise: worth another try.
        let reply = JsFuture::from(window.fetch_with_request(&request)).await.map_err(|e| retry(js(e)))?;
        let response: web_sys::Response = reply.dyn_into().map_err(|e| fatal(js(e)))?;
        let status = response.status();
        match status {
            206 => {}
            // The whole file, `Range` ignored: refused at open, dropped unread (its stream
            // cancelled) and asked again after it, as the native reader does.
            200 => {
                if let Some(body) = response.body() {
                    let _ = body.cancel();
                }
                let size = response.headers().get("content-length").ok().flatten();
                if first {
                    return Err(fatal(ignores_range(size.as_deref())));
                }
                let size = size.map_or(String::new(), |n| format!(" ({n} bytes)"));
                return Err(retry(format!("a 200 reply with the whole file{size} to a Range request")));
            }
            416 if first => return Err(fatal("the file is empty (416 Range Not Satisfiable)".into())),
            408 | 429 | 500..=599 => return Err(retry(format!("HTTP {status}"))),
            _ => return Err(fatal(format!("HTTP {status}"))),
        }
        let range = response.headers().get("content-range").ok().flatten();
        let body = JsFuture::from(response.array_buffer().map_err(|e| fatal(js(e)))?)
            .await
            .map_err(|e| retry(format!("the body: {}", js(e))))?;
        let body = js_sys::Uint8Array::new(&body).to_vec();
        add(&self.counters.bytes, body.len() as u64);
        // What the reply holds: from which byte, and the file's length.
        let range = range.unwrap_or_default();
        let (from, _, total) = parse_content_range(&range)
            .ok_or_else(|| retry(format!("a 206 reply with Content-Range {range:?} (is it exposed by CORS?)")))?;
        let end = if first { end.min(total) } else { end };
        if end > total {
            return Err(retry(format!("the reply holds bytes from {from} of a {total}-byte file")));
        }
        // The bytes wanted, in a reply from `from`.
        let skip = start.checked_sub(from).ok_or_else(|| retry(format!("the reply starts at byte {from}")))?;
        let len = (end - start) as usize;
        let bytes = body.get(skip as usize..).and_then(|b| b.get(..len)).ok_or_else(|| {
            retry(format!("the reply ended after {} bytes from byte {from}; {len} were asked for", body.len()))
        })?;
        Ok((bytes.to_vec(), total))
    }
}

/// A JavaScript error's text.
fn js(e: JsValue) -> String {
    e.as_string()
        .or_else(|| e.dyn_ref::<js_sys::Error>().map(|e| String::from(e.message())))
        .unwrap_or_else(|| format!("{e:?}"))
}

/// Resolves after `ms` milliseconds, on the page's timer.
async fn sleep(ms: i32) {
    let promise = js_sys::Promise::new(&mut |resolve, _| {
        if let Some(window) = web_sys::window() {
            // Without a timer the read is retried at once.
            if window.set_timeout_with_callback_and_timeout_and_arguments_0(&resolve, ms).is_err() {
                let _ = resolve.call0(&JsValue::NULL);
            }
        }
    });
    let _ = JsFuture::from(promise).await;
}
