//! Vortex packs read over HTTP(S) with `Range` requests, from any static host: the header and
//! level table first, the index whole when it is small or in blocks as tiles need them, then each
//! tile's payload on demand. Everything is checked as [`Pack::open`](vortex_pack::Pack::open)
//! and [`Pack::tile_checked`](vortex_pack::Pack::tile_checked) check a local file, by the same
//! code ([`PackLayout`]): the header's CRC and claims before anything is sized from them, the
//! level table, the metadata's CRC, the index's CRC (before any entry is used when it is read
//! whole; once its last block has arrived otherwise, each entry checked for sense before use),
//! and every payload's CRC.
//!
//! The protocol (what is read, and every check) is `remote`'s, which the browser's `WebPack`
//! drives too; this module is its blocking transport.
//!
//! Reads run on the loader's worker threads, which block on the network and never on a frame.
//! At most [`HttpOptions::connections`] requests are in flight; reads that queue behind them
//! meanwhile are sorted and those lying close together in the file are fetched as one request
//! ([`Fetcher`]), so a view's tiles arrive in a few requests without any timer. A failed request
//! (connection refused, reset or dropped, a timeout, a 5xx, a reply of the wrong range or
//! length) is retried with exponential backoff; a payload whose bytes fail their CRC is read
//! again once, with its index block, and then reported as corrupt: a server that keeps sending
//! wrong bytes is never retried forever, and its bytes are never drawn. Every request has a
//! deadline ([`HttpOptions::deadline`]) besides the timeout between bytes, so a server that
//! trickles a byte now and then cannot hold a read for hours, and a caller's stop
//! ([`HttpPack::open_with_stop`]) ends the open and every read at the next bytes or retry. A
//! server that ignores `Range` and answers the first request with the whole file (200) is
//! refused at open: every read after the first would have to read the file from its start, and
//! a pack can be gigabytes; a later whole-file reply (a proxy that sometimes ignores `Range`) is
//! dropped unread and the request retried. What it all cost is counted ([`HttpStats`]).

use std::collections::{BTreeMap, HashMap};
use std::io::Read;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex, PoisonError};
use std::time::{Duration, Instant};

use vortex_pack::{Limits, PackError, PackLayout, TileId, TileKind};

use super::pack::decode_stored;
use super::remote::{IndexPlan, RangeRead, RemotePack, ignores_range, lock, parse_content_range};
use super::{PageSource, ReadError, SourceTile, StoredRead};
use crate::loader::{LoaderError, RetryPolicy};
use crate::page_cache::CacheFormat;
use crate::texture::VirtualTexture;

/// How a remote pack is read. `HttpOptions::default()` suits a pack on a web server or CDN.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct HttpOptions {
    /// Most requests in flight at once (HTTP/1.1 keeps one per connection): 6, a browser's
    /// per-host limit, which servers and CDNs are tuned for.
    pub connections: usize,
    /// Attempts of one request that fails with an I/O error before the read fails: 6, the last
    /// after `backoff` x (1 + 2 + 4 + 8 + 16) of waiting, about 3 s with the default backoff.
    pub attempts: u32,
    /// The wait before the first retry, doubled before each next one (100 ms).
    pub backoff: Duration,
    /// Reads closer than this many bytes are fetched as one request, the gap fetched and
    /// dropped (16 KiB: a round trip costs more than that on any link slower than ~10 Gbit/s
    /// at 10 ms).
    pub gap: u64,
    /// Most bytes one merged request spans (4 MiB).
    pub max_span: u64,
    /// The index is read whole at open when it is at most this many bytes (1 MiB, some 43,000
    /// tiles), else in blocks of [`INDEX_BLOCK`](super::INDEX_BLOCK) entries as tiles need them.
    pub whole_index_up_to: u64,
    /// A connection attempt, or a wait for the next bytes of a reply, that takes longer than
    /// this fails (and is retried): 10 s.
    pub timeout: Duration,
    /// A request not complete this long after it began (connecting, the reply's head and its
    /// whole body, redirects included) fails (and is retried): 30 s, in which the largest merged
    /// request (`max_span`, 4 MiB) arrives at 1.2 Mbit/s. Without it, the `timeout` between
    /// bytes alone would let a server that sends a byte every few seconds hold a read for hours.
    pub deadline: Duration,
}

impl Default for HttpOptions {
    fn default() -> Self {
        HttpOptions {
            connections: 6,
            attempts: 6,
            backoff: Duration::from_millis(100),
            gap: 16 << 10,
            max_span: 4 << 20,
            whole_index_up_to: 1 << 20,
            timeout: Duration::from_secs(10),
            deadline: Duration::from_secs(30),
        }
    }
}

/// What a remote pack's reads have cost so far.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct HttpStats {
    /// HTTP requests sent, retries included.
    pub requests: u64,
    /// Body bytes received (a whole-file reply's bytes up to those wanted).
    pub bytes: u64,
    /// Requests sent again after an I/O error.
    pub retries: u64,
    /// Requests that failed with an I/O error (dropped connection, timeout, 5xx, wrong range).
    pub io_errors: u64,
    /// Payloads whose bytes failed their CRC (each read again once, then reported).
    pub corrupt: u64,
    /// Replies of the whole file (200) to a `Range` request (refused at open; dropped unread
    /// and retried after it).
    pub whole_file_replies: u64,
    /// Payloads (and index blocks) that were fetched as part of a merged request with others.
    pub merged_reads: u64,
}

#[derive(Default)]
struct Counters {
    requests: AtomicU64,
    bytes: AtomicU64,
    retries: AtomicU64,
    io_errors: AtomicU64,
    corrupt: AtomicU64,
    whole_file_replies: AtomicU64,
    merged_reads: AtomicU64,
}

fn add(counter: &AtomicU64, n: u64) {
    counter.fetch_add(n, Ordering::Relaxed);
}

/// Why a fetch failed.
#[derive(Clone, Debug)]
enum FetchError {
    /// Worth retrying: the network or the server failed this time.
    Io(String),
    /// Not worth retrying: the URL is wrong, the server refuses, the file changed.
    Fatal(String),
}

impl FetchError {
    /// The failed fetch as a read error: an I/O error that outlasted its retries may still pass
    /// later ([`ReadErrorKind::Io`](super::ReadErrorKind::Io)); a fatal one will not.
    fn read_error(self) -> ReadError {
        match self {
            FetchError::Io(m) => ReadError::io(m),
            FetchError::Fatal(m) => ReadError::unavailable(m),
        }
    }
}

/// A pack on a web server, read with `Range` requests: a [`PageSource`]. The protocol is
/// `RemotePack`'s (shared with the browser's `WebPack`); this is its blocking transport.
pub struct HttpPack {
    remote: RemotePack<Fetcher>,
}

impl HttpPack {
    /// Opens the pack at `url` (`http://` or `https://`) with [`HttpOptions::default`] and the
    /// default [`Limits`].
    pub fn open(url: &str) -> Result<HttpPack, PackError> {
        HttpPack::open_with(url, HttpOptions::default(), Limits::default())
    }

    /// Opens the pack at `url`: its header, level table and metadata (and its whole index, when
    /// small) are fetched and checked before this returns.
    pub fn open_with(url: &str, options: HttpOptions, limits: Limits) -> Result<HttpPack, PackError> {
        HttpPack::open_with_stop(url, options, limits, || false)
    }

    /// As [`HttpPack::open_with`], and every request (the open's, and each read's after it)
    /// ends once `stop` answers true: it is asked before each attempt, during the waits between
    /// attempts and between the reads of a reply's body, so a stop ends a request within the
    /// between-bytes [`HttpOptions::timeout`] at the latest (a connection or a reply's head
    /// cannot be interrupted). A stopped open fails, a stopped read fails as unavailable; what
    /// `render` and `view` pass is "a signal asked the run to stop".
    pub fn open_with_stop(
        url: &str,
        options: HttpOptions,
        limits: Limits,
        stop: impl Fn() -> bool + Send + Sync + 'static,
    ) -> Result<HttpPack, PackError> {
        let location = PathBuf::from(url);
        if !(url.starts_with("http://") || url.starts_with("https://")) {
            let source = std::io::Error::other("not an http:// or https:// URL");
            return Err(PackError::Io { path: location, source });
        }
        let plan = IndexPlan { whole_up_to: options.whole_index_up_to, gap: options.gap };
        // The reads block on this thread, so the future is ready whenever it is polled.
        let fetcher = Fetcher::new(url, options, Arc::new(stop));
        let remote = pollster::block_on(RemotePack::open(location, fetcher, plan, limits))?;
        Ok(HttpPack { remote })
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
    pub fn stats(&self) -> HttpStats {
        let c = &self.remote.reader().counters;
        let get = |a: &AtomicU64| a.load(Ordering::Relaxed);
        HttpStats {
            requests: get(&c.requests),
            bytes: get(&c.bytes),
            retries: get(&c.retries),
            io_errors: get(&c.io_errors),
            corrupt: get(&c.corrupt),
            whole_file_replies: get(&c.whole_file_replies),
            merged_reads: get(&c.merged_reads),
        }
    }

    fn stored(&self, id: TileId) -> Result<StoredRead, ReadError> {
        pollster::block_on(self.remote.stored(id))
    }
}

impl PageSource for HttpPack {
    fn location(&self) -> &Path {
        self.remote.location()
    }

    fn texture(&self) -> Result<VirtualTexture, LoaderError> {
        VirtualTexture::from_layout(self.remote.layout())
    }

    fn read_tile(&self, id: TileId, format: CacheFormat) -> Result<SourceTile, ReadError> {
        self.remote.texels(self.stored(id)?, format)
    }

    fn read_stored(&self, id: TileId) -> Result<Option<StoredRead>, ReadError> {
        self.stored(id).map(Some)
    }

    fn decode(&self, _: TileId, kind: TileKind, bytes: &[u8], format: CacheFormat) -> Result<Vec<u8>, ReadError> {
        decode_stored(self.remote.layout(), kind, bytes, format)
    }

    /// None from the loader: each request was tried `HttpOptions::attempts` times already, so
    /// one page of a dead server costs that many requests, not that many times the loader's.
    fn retry_policy(&self, _loader: RetryPolicy) -> RetryPolicy {
        RetryPolicy::NONE
    }

    fn opaque(&self) -> bool {
        self.remote.opaque()
    }

    fn holds_only_bc7(&self) -> bool {
        self.remote.holds_only_bc7()
    }
}

impl RangeRead for Fetcher {
    async fn first(&self, n: u64) -> Result<(Vec<u8>, u64), ReadError> {
        let bytes = self.fetch_first(n).map_err(FetchError::read_error)?;
        Ok((bytes, self.file_len()))
    }

    async fn read(&self, start: u64, end: u64) -> Result<Vec<u8>, ReadError> {
        self.read(start, end).map_err(FetchError::read_error)
    }

    fn corrupt(&self) {
        add(&self.counters.corrupt, 1);
    }
}

/// Redirects one request follows before it fails: 10, as ureq (browsers allow 20, curl 50).
const MAX_REDIRECTS: u32 = 10;

/// Where a redirect from `base` to `location` (a reply's `Location`) leads: an absolute
/// `http://` or `https://` URL, a network-path (`//host/path`), an absolute path or one relative
/// to `base`'s (RFC 3986's common cases; dot segments are left to the server). A `Location` of
/// any other scheme (`file:`, `ftp:`, `data:`...) is refused, naming it.
fn redirect_target(base: &str, location: &str) -> Result<String, String> {
    let location = location.trim();
    let scheme = location.split_once(':').map(|(s, _)| s).filter(|s| {
        s.chars().next().is_some_and(|c| c.is_ascii_alphabetic())
            && s.chars().all(|c| c.is_ascii_alphanumeric() || matches!(c, '+' | '-' | '.'))
    });
    if let Some(scheme) = scheme {
        return if scheme.eq_ignore_ascii_case("http") || scheme.eq_ignore_ascii_case("https") {
            Ok(location.to_string())
        } else {
            Err(format!("redirected to {location}, which is not an http:// or https:// URL"))
        };
    }
    let (base_scheme, rest) = base.split_once("://").ok_or_else(|| format!("cannot follow a redirect from {base}"))?;
    if location.starts_with("//") {
        return Ok(format!("{base_scheme}:{location}"));
    }
    let authority_len = rest.find(['/', '?', '#']).unwrap_or(rest.len());
    let (authority, path) = rest.split_at(authority_len);
    if location.starts_with('/') {
        return Ok(format!("{base_scheme}://{authority}{location}"));
    }
    let path = &path[..path.find(['?', '#']).unwrap_or(path.len())];
    let dir = &path[..path.rfind('/').map_or(0, |i| i + 1)];
    let dir = if dir.is_empty() { "/" } else { dir };
    Ok(format!("{base_scheme}://{authority}{dir}{location}"))
}

/// Byte ranges of one URL read by many threads, at most `connections` requests at a time. A read
/// queues its range; a thread whose range is queued and finds a connection free takes it, with
/// the queued ranges close to it, as one request, and hands each waiting thread its slice. While
/// every connection is busy, ranges pile up and are merged: the busier the link, the fewer and
/// larger the requests, and nothing waits on a timer.
struct Fetcher {
    url: String,
    agent: ureq::Agent,
    options: HttpOptions,
    /// Whether the caller wants every request to end now.
    stop: Arc<dyn Fn() -> bool + Send + Sync>,
    counters: Counters,
    state: Mutex<FetchState>,
    changed: Condvar,
}

#[derive(Default)]
struct FetchState {
    /// The file's length, from the first reply (0 until then).
    file_len: u64,
    /// The first reply's strong `ETag`, sent as `If-Match` with every later request: a pack
    /// replaced on the server is refused (412) instead of mixed with the old one's bytes.
    etag: Option<String>,
    /// Ranges waiting for a request: (start, ticket) -> end.
    queued: BTreeMap<(u64, u64), u64>,
    /// Requests in flight.
    running: usize,
    /// Answers not yet taken by their thread, by ticket.
    answers: HashMap<u64, Result<Vec<u8>, FetchError>>,
    next_ticket: u64,
}

/// One request's share of a merged read: the ticket and its range.
type Share = (u64, u64, u64);

impl Fetcher {
    fn new(url: &str, options: HttpOptions, stop: Arc<dyn Fn() -> bool + Send + Sync>) -> Fetcher {
        let config = ureq::Agent::config_builder()
            // Statuses are answered here: a 5xx is retried, a 404 is not.
            .http_status_as_error(false)
            .timeout_connect(Some(options.timeout))
            .timeout_recv_response(Some(options.timeout))
            .timeout_per_read(Some(options.timeout))
            // Each request's deadline (set per request, to what is left of it after redirects),
            // from its start to the last byte of its body.
            .timeout_global(Some(options.deadline))
            .max_redirects(0)
            .max_idle_connections_per_host(options.connections.max(1))
            .user_agent(concat!("vortex-vt-wgpu/", env!("CARGO_PKG_VERSION")))
            .build();
        Fetcher {
            url: url.to_string(),
            agent: config.into(),
            options,
            stop,
            counters: Counters::default(),
            state: Mutex::default(),
            changed: Condvar::new(),
        }
    }

    /// The error of a request the caller stopped.
    fn stopped(&self, start: u64, end: u64) -> FetchError {
        FetchError::Fatal(format!("bytes {start}..{end}: stopped (the run was asked to stop)"))
    }

    fn file_len(&self) -> u64 {
        lock(&self.state).file_len
    }

    /// The first `n` bytes (fewer if the file is shorter), learning the file's length.
    fn fetch_first(&self, n: u64) -> Result<Vec<u8>, FetchError> {
        self.with_retries((0, n), || self.request(0, n, true))
    }

    /// Bytes `start..end` of the file, merged with the ranges other threads are waiting for.
    fn read(&self, start: u64, end: u64) -> Result<Vec<u8>, FetchError> {
        // An empty range is no request (and `Range: bytes=a-(a-1)` is not one).
        if start >= end {
            return Ok(Vec::new());
        }
        let mut state = lock(&self.state);
        let ticket = state.next_ticket;
        state.next_ticket += 1;
        state.queued.insert((start, ticket), end);
        loop {
            if let Some(answer) = state.answers.remove(&ticket) {
                return answer;
            }
            if state.running < self.options.connections.max(1) && state.queued.contains_key(&(start, ticket)) {
                let shares = self.take_run(&mut state, (start, ticket));
                state.running += 1;
                drop(state);
                if shares.len() > 1 {
                    add(&self.counters.merged_reads, shares.len() as u64);
                }
                let (from, to) = (shares[0].1, shares.iter().map(|s| s.2).max().unwrap_or(end));
                let result = self.with_retries((from, to), || self.request(from, to, false));
                state = lock(&self.state);
                state.running -= 1;
                for (t, s, e) in shares {
                    let answer = result.as_ref().map(|b| b[(s - from) as usize..(e - from) as usize].to_vec());
                    state.answers.insert(t, answer.map_err(Clone::clone));
                }
                self.changed.notify_all();
                continue;
            }
            state = self.changed.wait(state).unwrap_or_else(PoisonError::into_inner);
        }
    }

    /// Takes from the queue the run of ranges that holds `mine`: neighbours in file order whose
    /// gaps are at most `gap` bytes, spanning at most `max_span`. Sorted by start.
    fn take_run(&self, state: &mut FetchState, mine: (u64, u64)) -> Vec<Share> {
        let (gap, span) = (self.options.gap, self.options.max_span);
        let mut run: Vec<Share> = Vec::new();
        let mut end = 0u64;
        let mut has_mine = false;
        for (&(s, t), &e) in &state.queued {
            let joins = !run.is_empty() && s <= end.saturating_add(gap) && e.max(end) - run[0].1 <= span;
            if !joins {
                if has_mine {
                    break;
                }
                run.clear();
                end = 0;
            }
            run.push((t, s, e));
            end = end.max(e);
            has_mine |= (s, t) == mine;
        }
        for &(t, s, _) in &run {
            state.queued.remove(&(s, t));
        }
        run
    }

    /// `attempt`, tried again after each I/O error (waiting `backoff`, doubled each time) up to
    /// `attempts` times in all, unless the caller stops it.
    fn with_retries(
        &self,
        (start, end): (u64, u64),
        attempt: impl Fn() -> Result<Vec<u8>, FetchError>,
    ) -> Result<Vec<u8>, FetchError> {
        let mut wait = self.options.backoff;
        let mut tries = 1;
        loop {
            if (self.stop)() {
                return Err(self.stopped(start, end));
            }
            match attempt() {
                Err(FetchError::Io(message)) => {
                    add(&self.counters.io_errors, 1);
                    if tries >= self.options.attempts {
                        return Err(FetchError::Io(format!("{message} ({tries} attempts)")));
                    }
                    add(&self.counters.retries, 1);
                    // The wait, a tenth of a second at a time, for a stop to end it.
                    let until = Instant::now() + wait;
                    while let Some(left) = until.checked_duration_since(Instant::now()).filter(|d| !d.is_zero()) {
                        if (self.stop)() {
                            return Err(self.stopped(start, end));
                        }
                        std::thread::sleep(left.min(Duration::from_millis(100)));
                    }
                    wait = wait.saturating_mul(2);
                    tries += 1;
                }
                other => return other,
            }
        }
    }

    /// One `Range` request for bytes `start..end`. `first`: the opening read, which learns the
    /// file's length and may get fewer bytes than asked for (a file shorter than `end`).
    fn request(&self, start: u64, end: u64, first: bool) -> Result<Vec<u8>, FetchError> {
        let io = |m: String| FetchError::Io(format!("bytes {start}..{end}: {m}"));
        let fatal = |m: String| FetchError::Fatal(format!("bytes {start}..{end}: {m}"));
        add(&self.counters.requests, 1);
        let etag = lock(&self.state).etag.clone();
        // Redirects are followed here, not by ureq, so that one to another scheme is named as
        // such, and the deadline spans them all.
        let began = Instant::now();
        let mut url = self.url.clone();
        let mut redirects = 0;
        let response = loop {
            let mut get = self.agent.get(&url).header("Range", format!("bytes={start}-{}", end - 1));
            if let Some(etag) = &etag {
                get = get.header("If-Match", etag);
            }
            let left = self.options.deadline.saturating_sub(began.elapsed());
            let response = get.config().timeout_global(Some(left)).build().call().map_err(|e| match e {
                ureq::Error::BadUri(_) | ureq::Error::HostNotFound if first => fatal(e.to_string()),
                e => io(self.describe(e)),
            })?;
            if !matches!(response.status().as_u16(), 301 | 302 | 303 | 307 | 308) {
                break response;
            }
            let status = response.status().as_u16();
            let location = response.headers().get("location").and_then(|v| v.to_str().ok());
            let location = location.ok_or_else(|| fatal(format!("HTTP {status} without a Location")))?;
            redirects += 1;
            if redirects > MAX_REDIRECTS {
                return Err(fatal(format!("more than {MAX_REDIRECTS} redirects (the last to {location})")));
            }
            url = redirect_target(&url, location).map_err(fatal)?;
        };
        let status = response.status().as_u16();
        let header = |name: &str| response.headers().get(name).and_then(|v| v.to_str().ok()).map(str::to_string);
        let known_len = self.file_len();
        let etag_of_reply = header("etag");
        // What the reply holds: from which byte, how many, and the file's length.
        let (from, total) = match status {
            206 => {
                let range = header("content-range").unwrap_or_default();
                let (from, _, total) = parse_content_range(&range)
                    .ok_or_else(|| io(format!("a 206 reply with Content-Range {range:?}")))?;
                (from, total)
            }
            // The whole file, `Range` ignored: refused at open (every later read would have to
            // read the file from its start); after it, a proxy that sometimes ignores `Range`,
            // so dropped unread and asked again.
            200 => {
                add(&self.counters.whole_file_replies, 1);
                let size = header("content-length");
                if first {
                    return Err(fatal(ignores_range(size.as_deref())));
                }
                let size = size.map_or(String::new(), |n| format!(" ({n} bytes)"));
                return Err(io(format!("a 200 reply with the whole file{size} to a Range request")));
            }
            416 if first => return Err(fatal("the file is empty (416 Range Not Satisfiable)".into())),
            412 => {
                let etag = etag.unwrap_or_default();
                return Err(fatal(format!(
                    "the pack changed on the server since it was opened (ETag {etag} no longer matches)"
                )));
            }
            408 | 429 | 500..=599 => return Err(io(format!("HTTP {status}"))),
            _ => return Err(fatal(format!("HTTP {status}"))),
        };
        if known_len != 0 && total != known_len {
            return Err(fatal(format!("the file is now {total} bytes, not {known_len}: it changed on the server")));
        }
        let end = if first { end.min(total) } else { end };
        if from != start || end > total {
            return Err(io(format!("the reply holds bytes from {from} of a {total}-byte file")));
        }
        let mut body = response.into_body().into_reader();
        let len = end - start;
        let mut bytes = Vec::new();
        bytes.try_reserve_exact(len as usize).map_err(|e| fatal(e.to_string()))?;
        bytes.resize(len as usize, 0);
        // Read as it comes, so that a stop is seen between the reads of a slow reply.
        let mut got = 0;
        while got < bytes.len() {
            if (self.stop)() {
                add(&self.counters.bytes, got as u64);
                return Err(self.stopped(start, end));
            }
            match body.read(&mut bytes[got..]) {
                Ok(0) => break,
                Ok(n) => got += n,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e) => {
                    add(&self.counters.bytes, got as u64);
                    return Err(io(self.describe(e.into())));
                }
            }
        }
        add(&self.counters.bytes, got as u64);
        if got as u64 != len {
            return Err(io(format!("the reply ended after {got} of {len} bytes")));
        }
        if first {
            let mut state = lock(&self.state);
            state.file_len = total;
            // A weak ETag (W/...) may stay when the bytes change: only a strong one says they did not.
            state.etag = etag_of_reply.filter(|e| e.starts_with('"'));
        }
        Ok(bytes)
    }

    /// What went wrong with a request, the timeouts named by what they bound.
    fn describe(&self, e: ureq::Error) -> String {
        let secs = |d: Duration| d.as_secs_f64();
        match e {
            ureq::Error::Timeout(ureq::Timeout::Global) => format!(
                "no complete reply within the deadline of {} s per request (HttpOptions::deadline)",
                secs(self.options.deadline)
            ),
            ureq::Error::Timeout(ureq::Timeout::PerRead) => {
                format!(
                    "no bytes for {} s (the timeout between bytes, HttpOptions::timeout)",
                    secs(self.options.timeout)
                )
            }
            ureq::Error::Timeout(ureq::Timeout::RecvResponse) => {
                format!("no reply within {} s (HttpOptions::timeout)", secs(self.options.timeout))
            }
            ureq::Error::Timeout(ureq::Timeout::Connect) => {
                format!("no connection within {} s (HttpOptions::timeout)", secs(self.options.timeout))
            }
            e => e.to_string(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn redirects_resolve_against_the_url_and_other_schemes_are_named() {
        let base = "http://h:8080/dir/p.vtpk?x=1";
        assert_eq!(redirect_target(base, "https://cdn/p.vtpk").unwrap(), "https://cdn/p.vtpk");
        assert_eq!(redirect_target(base, "//cdn/p.vtpk").unwrap(), "http://cdn/p.vtpk");
        assert_eq!(redirect_target(base, "/other/q.vtpk").unwrap(), "http://h:8080/other/q.vtpk");
        assert_eq!(redirect_target(base, "q.vtpk").unwrap(), "http://h:8080/dir/q.vtpk");
        assert_eq!(redirect_target("http://h", "q.vtpk").unwrap(), "http://h/q.vtpk");
        let e = redirect_target(base, "file:///etc/passwd").unwrap_err();
        assert_eq!(e, "redirected to file:///etc/passwd, which is not an http:// or https:// URL");
        assert!(redirect_target(base, "FTP://x/y").is_err());
    }

    #[test]
    fn content_ranges_parse_and_nonsense_does_not() {
        assert_eq!(parse_content_range("bytes 0-191/5000"), Some((0, 191, 5000)));
        assert_eq!(parse_content_range("bytes 10-9/5000"), None);
        assert_eq!(parse_content_range("bytes 0-5000/5000"), None);
        assert_eq!(parse_content_range("bytes */5000"), None);
        assert_eq!(parse_content_range(""), None);
    }

    fn fetcher_with(queued: &[(u64, u64)], gap: u64, max_span: u64) -> (Fetcher, FetchState) {
        let options = HttpOptions { gap, max_span, ..HttpOptions::default() };
        let mut state = FetchState::default();
        for (t, &(s, e)) in queued.iter().enumerate() {
            state.queued.insert((s, t as u64), e);
        }
        (Fetcher::new("http://localhost/x.vtpk", options, Arc::new(|| false)), state)
    }

    #[test]
    fn a_run_takes_close_neighbours_and_leaves_the_rest() {
        let (f, mut state) = fetcher_with(&[(0, 100), (150, 200), (10_000, 10_100), (10_100, 10_200)], 64, 1 << 20);
        let run = f.take_run(&mut state, (150, 1));
        assert_eq!(run, vec![(0, 0, 100), (1, 150, 200)]);
        assert_eq!(state.queued.len(), 2, "the far pair stays queued");
        let run = f.take_run(&mut state, (10_100, 3));
        assert_eq!(run, vec![(2, 10_000, 10_100), (3, 10_100, 10_200)]);
    }

    #[test]
    fn a_run_stops_at_the_span_and_overlaps_merge() {
        let (f, mut state) = fetcher_with(&[(0, 100), (50, 120), (120, 300), (300, 400)], 0, 300);
        let run = f.take_run(&mut state, (0, 0));
        assert_eq!(run, vec![(0, 0, 100), (1, 50, 120), (2, 120, 300)], "300..400 would span 400 > 300");
        assert_eq!(state.queued.len(), 1);
    }
}
