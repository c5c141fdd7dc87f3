//! An S3-compatible bucket through Apache Arrow's `object_store` (feature `s3`): the client and
//! its runtime ([`Bucket`]), the claim of a prefix or an object, a directory output's files as
//! objects uploaded in parallel ([`Uploads`]); `stream.rs` sends one object as it is made.
//!
//! Credentials, region and endpoint come from the standard AWS environment
//! (`AWS_ACCESS_KEY_ID`, `AWS_SECRET_ACCESS_KEY`, `AWS_SESSION_TOKEN`, `AWS_REGION`,
//! `AWS_ENDPOINT_URL` for MinIO, R2 or a local server, `AWS_ALLOW_HTTP=true` for one without
//! TLS), and what it leaves out from the shared files' profile (`profile.rs`). Each request is retried with exponential backoff on 5xx replies, throttling, timeouts
//! and dropped connections, up to [`MAX_RETRIES`] times within [`RETRY_WINDOW`].
//!
//! Uploads run on a small tokio runtime of the output's own, so the encoder threads that call
//! [`Files::put_new`] only wait when the bytes in flight would pass the output's share of
//! `--max-memory`; the first failure is kept and returned by the next call (and by `publish`).

use std::collections::{HashMap, HashSet};
use std::hash::{BuildHasher, Hasher};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use futures::stream::{StreamExt, TryStreamExt};
use object_store::aws::AmazonS3Builder;
use object_store::multipart::MultipartStore;
use object_store::path::Path as Key;
use object_store::{BackoffConfig, ObjectStore, ObjectStoreExt, PutMode, PutPayload, RetryConfig, UpdateVersion};
use tokio::sync::oneshot;
use tokio::task::JoinHandle;

use super::{Files, ObjectUrl, StoreError};
use crate::error::Result;
use crate::output::{Existing, Product};
use crate::resume::Identity;

mod read;

/// The marker object a directory output keeps under its prefix (see [`crate::store`]).
pub(crate) const MARKER: &str = ".vortex-tiler";
/// Retries of one request after its first try.
const MAX_RETRIES: usize = 5;
/// No retry starts later than this after a request's first try.
const RETRY_WINDOW: Duration = Duration::from_secs(60);
/// Requests in flight at most per output, whatever their size (many small tiles).
const MAX_REQUESTS: usize = 64;
/// The largest marker object read back: ours are under 300 bytes.
const MAX_MARKER_BYTES: u64 = 4096;
/// How often a run writing a prefix rewrites its marker (its heartbeat), unless
/// `VORTEX_S3_HEARTBEAT_SECS` says otherwise.
const HEARTBEAT: Duration = Duration::from_secs(30);
/// A marker saying `writing` that stays the same for this many of its run's heartbeats is a
/// dead run's (killed, or cut off from the server): four, so that a beat retried for up to
/// [`RETRY_WINDOW`] still lands within them.
const BEATS_MISSED: u32 = 4;

/// The heartbeat of the runs this process starts: [`HEARTBEAT`], or
/// `VORTEX_S3_HEARTBEAT_SECS` (1 to 3600).
fn heartbeat() -> Duration {
    let secs = std::env::var("VORTEX_S3_HEARTBEAT_SECS").ok().and_then(|v| v.trim().parse::<u64>().ok());
    secs.filter(|s| (1..=3600).contains(s)).map_or(HEARTBEAT, Duration::from_secs)
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|p| p.into_inner())
}

/// What a bucket's client does: objects, and multipart uploads part by part (`AmazonS3`;
/// `object_store`'s `InMemory` in unit tests).
pub(crate) trait Store: ObjectStore + MultipartStore {}

impl<T: ObjectStore + MultipartStore> Store for T {}

/// A bucket's client and the runtime its requests run on.
pub(crate) struct Bucket {
    pub(super) store: Arc<dyn Store>,
    pub(super) runtime: tokio::runtime::Runtime,
    name: String,
}

impl Bucket {
    /// The client of `url`'s bucket, configured from the AWS environment. Sends nothing.
    pub(crate) fn open(url: &ObjectUrl) -> Result<Bucket, StoreError> {
        let client = |message: String| StoreError::Client { url: url.to_string(), message };
        let mut backoff = BackoffConfig::default();
        (backoff.init_backoff, backoff.max_backoff, backoff.base) =
            (Duration::from_millis(100), Duration::from_secs(8), 2.0);
        let mut retry = RetryConfig::default();
        (retry.backoff, retry.max_retries, retry.retry_timeout) = (backoff, MAX_RETRIES, RETRY_WINDOW);
        let mut builder = AmazonS3Builder::from_env().with_bucket_name(url.bucket()).with_retry(retry);
        // The shared files' profile fills in what the environment does not say.
        let env = |name: &str| std::env::var(name).ok().filter(|v| !v.is_empty());
        if let Some(p) = super::profile::load(&env).map_err(client)? {
            if let (None, Some(id), Some(secret)) = (env("AWS_ACCESS_KEY_ID"), p.access_key_id, p.secret_access_key) {
                builder = builder.with_access_key_id(id).with_secret_access_key(secret);
                if let Some(token) = p.session_token {
                    builder = builder.with_token(token);
                }
            }
            if let (None, None, Some(region)) = (env("AWS_REGION"), env("AWS_DEFAULT_REGION"), p.region) {
                builder = builder.with_region(region);
            }
            if let (None, None, Some(endpoint)) = (env("AWS_ENDPOINT_URL"), env("AWS_ENDPOINT"), p.endpoint_url) {
                // An http:// endpoint the user wrote into the profile is allowed, as the SDKs do.
                builder = builder.with_allow_http(endpoint.starts_with("http://")).with_endpoint(endpoint);
            }
        }
        let store = builder.build().map_err(|e| client(e.to_string()))?;
        Bucket::with_store(Arc::new(store), url)
    }

    /// The bucket of `url` through the client `store`, on a runtime of its own.
    pub(crate) fn with_store(store: Arc<dyn Store>, url: &ObjectUrl) -> Result<Bucket, StoreError> {
        let runtime = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(2)
            .thread_name("vortex-s3")
            .enable_all()
            .build()
            .map_err(|e| StoreError::Client {
                url: url.to_string(),
                message: format!("cannot start its runtime: {e}"),
            })?;
        Ok(Bucket { store, runtime, name: url.bucket().to_string() })
    }

    /// `key` as the client takes it, refused (not re-encoded) where it could not be stored as
    /// spelt.
    pub(super) fn key(&self, key: &str) -> Result<Key, StoreError> {
        Key::parse(key).map_err(|e| StoreError::Url {
            url: format!("s3://{}/{}", self.name, key.escape_debug()),
            why: format!("not an object key this tool writes: {e}"),
        })
    }

    pub(super) fn failed(&self, key: &str, op: &'static str, e: impl ToString) -> StoreError {
        StoreError::Request { bucket: self.name.clone(), key: key.to_string(), op, message: e.to_string() }
    }

    /// Stores `bytes` at `key`, waiting for the reply.
    fn put(&self, key: &str, bytes: Vec<u8>) -> Result<(), StoreError> {
        let location = self.key(key)?;
        let put = self.store.put(&location, PutPayload::from(bytes));
        self.runtime.block_on(put).map(drop).map_err(|e| self.failed(key, "PUT", reply(&e)))
    }

    /// The object at `key`, `None` where there is none, refused past `max` bytes.
    fn get(&self, key: &str, max: u64) -> Result<Option<Vec<u8>>, StoreError> {
        let location = self.key(key)?;
        self.runtime.block_on(async {
            let got = match self.store.get(&location).await {
                Ok(got) => got,
                Err(object_store::Error::NotFound { .. }) => return Ok(None),
                Err(e) => return Err(self.failed(key, "GET", reply(&e))),
            };
            if got.meta.size > max {
                return Err(self.failed(key, "GET", format!("{} bytes, more than the {max} expected", got.meta.size)));
            }
            got.bytes().await.map(|b| Some(b.to_vec())).map_err(|e| self.failed(key, "GET", reply(&e)))
        })
    }

    /// The marker object at `key` and its version (ETag), `None` where there is none.
    fn get_marker(&self, key: &str) -> Result<Option<(Vec<u8>, UpdateVersion)>, StoreError> {
        let location = self.key(key)?;
        self.runtime.block_on(async {
            let got = match self.store.get(&location).await {
                Ok(got) => got,
                Err(object_store::Error::NotFound { .. }) => return Ok(None),
                Err(e) => return Err(self.failed(key, "GET", reply(&e))),
            };
            if got.meta.size > MAX_MARKER_BYTES {
                return Err(self.failed(key, "GET", format!("{} bytes: not a marker of ours", got.meta.size)));
            }
            let version = UpdateVersion { e_tag: got.meta.e_tag.clone(), version: got.meta.version.clone() };
            let bytes = got.bytes().await.map_err(|e| self.failed(key, "GET", reply(&e)))?;
            Ok(Some((bytes.to_vec(), version)))
        })
    }

    /// The version of the marker at the prefix `url` once no other run writes there (`None`:
    /// no marker). A marker saying that a run is writing the prefix is watched for
    /// [`BEATS_MISSED`] of that run's heartbeats: if it changes, that run is alive and the
    /// prefix is refused; if not, the run is dead and its prefix may be taken over.
    fn idle_marker(&self, url: &ObjectUrl) -> Result<Option<UpdateVersion>, StoreError> {
        let key = url.child(MARKER);
        let Some((bytes, version)) = self.get_marker(&key)? else { return Ok(None) };
        let Some(every) = marker_heartbeat(&bytes) else { return Ok(Some(version)) };
        let watch = every * BEATS_MISSED;
        eprintln!(
            "note: {url}: a run is writing it, or was killed while writing it; watching its marker for {:.0} s",
            watch.as_secs_f64()
        );
        let until = Instant::now() + watch;
        while let Some(left) = until.checked_duration_since(Instant::now()).filter(|d| !d.is_zero()) {
            std::thread::sleep(left.min(every / 4).max(Duration::from_millis(50)));
            match self.get_marker(&key)? {
                Some((now, _)) if now == bytes => {}
                // Gone: that run failed and removed its output.
                None => return Ok(None),
                Some(_) => {
                    let why = "another run is writing it (its marker changed while this run watched it)";
                    return Err(StoreError::Busy { url: url.to_string(), why: why.into() });
                }
            }
        }
        Ok(Some(version))
    }

    /// Writes the marker object `key` (`bytes`) if it is still at `seen` (`None`: if there is
    /// none), returning its new version; `Ok(None)` where another writer changed it first.
    async fn put_marker(
        store: &dyn Store,
        location: &Key,
        bytes: Vec<u8>,
        seen: Option<UpdateVersion>,
    ) -> object_store::Result<Option<UpdateVersion>> {
        let mode = seen.map_or(PutMode::Create, PutMode::Update);
        match store.put_opts(location, PutPayload::from(bytes), mode.into()).await {
            Ok(put) => Ok(Some(put.into())),
            Err(object_store::Error::AlreadyExists { .. } | object_store::Error::Precondition { .. }) => Ok(None),
            Err(e) => Err(e),
        }
    }

    /// The first object under `prefix` (a key's segments; empty: the whole bucket), if any.
    fn first_under(&self, prefix: &str) -> Result<Option<String>, StoreError> {
        let location = if prefix.is_empty() { None } else { Some(self.key(prefix)?) };
        let mut listed = self.store.list(location.as_ref());
        match self.runtime.block_on(listed.next()) {
            None => Ok(None),
            Some(Ok(meta)) => Ok(Some(meta.location.to_string())),
            Some(Err(e)) => Err(self.failed(prefix, "LIST", reply(&e))),
        }
    }

    /// The identity of the resumable run whose marker is at the prefix `url`, if a run
    /// given `--resume` was writing it (and did not finish).
    pub(crate) fn resumable_run(&self, url: &ObjectUrl) -> Result<Option<Identity>, StoreError> {
        Ok(self.get(&url.child(MARKER), MAX_MARKER_BYTES)?.as_deref().and_then(marker_run))
    }

    /// Every object under the prefix `url` but the marker: its name below the prefix and its
    /// size.
    pub(crate) fn list_sizes(&self, url: &ObjectUrl) -> Result<HashMap<String, u64>, StoreError> {
        let prefix = if url.key().is_empty() { None } else { Some(self.key(url.key())?) };
        let skip = url.child("").len();
        self.runtime.block_on(async {
            let mut listed = self.store.list(prefix.as_ref());
            let mut out = HashMap::new();
            while let Some(meta) = listed.next().await {
                let meta = meta.map_err(|e| self.failed(url.key(), "LIST", reply(&e)))?;
                let name = meta.location.as_ref().get(skip..).unwrap_or_default().to_string();
                if name != MARKER {
                    out.insert(name, meta.size);
                }
            }
            Ok(out)
        })
    }

    /// Deletes the objects `names` under the prefix `url`.
    pub(crate) fn delete_names(&self, url: &ObjectUrl, names: &[String]) -> Result<(), StoreError> {
        let keys = names.iter().map(|n| self.key(&url.child(n))).collect::<Result<Vec<_>, _>>()?;
        self.runtime.block_on(async {
            let mut deleted = self.store.delete_stream(futures::stream::iter(keys.into_iter().map(Ok)).boxed());
            while let Some(result) = deleted.next().await {
                result.map_err(|e| self.failed(url.key(), "DELETE", reply(&e)))?;
            }
            Ok(())
        })
    }

    /// Deletes every object under `url`'s prefix, the marker last (so that a deletion cut
    /// short still leaves the prefix recognisably ours).
    pub(crate) fn delete_prefix(&self, url: &ObjectUrl) -> Result<(), StoreError> {
        self.delete_but_marker(url)?;
        let marker_key = url.child(MARKER);
        let marker = self.key(&marker_key)?;
        match self.runtime.block_on(self.store.delete(&marker)) {
            Ok(()) | Err(object_store::Error::NotFound { .. }) => Ok(()),
            Err(e) => Err(self.failed(&marker_key, "DELETE", reply(&e))),
        }
    }

    /// Deletes every object under `url`'s prefix but the marker.
    fn delete_but_marker(&self, url: &ObjectUrl) -> Result<(), StoreError> {
        let marker = self.key(&url.child(MARKER))?;
        let prefix = if url.key().is_empty() { None } else { Some(self.key(url.key())?) };
        self.runtime.block_on(async {
            let keep = marker;
            let listed = self.store.list(prefix.as_ref()).map_ok(|m| m.location);
            let listed = listed.try_filter(move |l| futures::future::ready(*l != keep)).boxed();
            let mut deleted = self.store.delete_stream(listed);
            while let Some(result) = deleted.next().await {
                result.map_err(|e| self.failed(url.key(), "DELETE", reply(&e)))?;
            }
            Ok(())
        })
    }

    /// What the claim of a directory output at the prefix `url` finds: nothing, a previous
    /// output of ours (its marker names `noun`), or a refusal naming a foreign key.
    pub(crate) fn claim_prefix(&self, url: &ObjectUrl, noun: &'static str) -> Result<Option<Existing>, StoreError> {
        let foreign = |what: String| StoreError::Foreign {
            url: url.to_string(),
            what,
            product: noun,
            advice: "choose a new or empty prefix",
        };
        let marker_key = url.child(MARKER);
        match self.get(&marker_key, MAX_MARKER_BYTES)? {
            Some(bytes) => match marker_product(&bytes) {
                Some(product) if product == noun => Ok(Some(Existing::Ours)),
                Some(product) => Err(foreign(format!("{product} (its {MARKER} says so)"))),
                None => Err(foreign(format!("an object {marker_key} that is not our marker"))),
            },
            None => match self.first_under(url.key())? {
                Some(key) => Err(foreign(format!("the object {key}"))),
                None => Ok(None),
            },
        }
    }

    /// What the claim of a one-object output at `url` finds: nothing, a previous output of
    /// ours (a pack's or PMTiles' signature), or something replaced only with `force`.
    pub(crate) fn claim_object(
        &self,
        url: &ObjectUrl,
        product: Product,
        force: bool,
    ) -> Result<Option<Existing>, StoreError> {
        if url.key().is_empty() {
            let why = "a file output needs an object key: s3://BUCKET/KEY".into();
            return Err(StoreError::Url { url: url.to_string(), why });
        }
        let location = self.key(url.key())?;
        let head = self.runtime.block_on(self.store.head(&location));
        let size = match head {
            Ok(meta) => meta.size,
            Err(object_store::Error::NotFound { .. }) => {
                return match self.first_under(url.key())? {
                    Some(key) => Err(StoreError::Foreign {
                        url: url.to_string(),
                        what: format!("objects under it as a prefix ({key})"),
                        product: product.noun(),
                        advice: "choose another key",
                    }),
                    None => Ok(None),
                };
            }
            Err(e) => return Err(self.failed(url.key(), "HEAD", reply(&e))),
        };
        let range = self.store.get_range(&location, 0..size.min(8));
        let head = self.runtime.block_on(range).map_err(|e| self.failed(url.key(), "GET", reply(&e)))?;
        let ours = match product {
            Product::Pack => head[..] == vortex_pack::format::MAGIC[..],
            Product::Pmtiles => &head[..] == b"PMTiles\x03",
            _ => false,
        };
        match (ours, force) {
            (true, _) => Ok(Some(Existing::Ours)),
            (false, true) => Ok(Some(Existing::ForcedFile)),
            (false, false) => Err(StoreError::Foreign {
                url: url.to_string(),
                what: format!("an object of {size} bytes"),
                product: product.noun(),
                advice: "pass --force to replace it, or choose another key",
            }),
        }
    }
}

/// A client error as a message: its own text, then each cause it does not already quote (the
/// server's reply, or why no connection was made).
pub(crate) fn reply(e: &object_store::Error) -> String {
    let mut text = e.to_string();
    let mut cause = std::error::Error::source(e);
    while let Some(c) = cause {
        let more = c.to_string();
        if !text.contains(&more) {
            text = format!("{text}: {more}");
        }
        cause = c.source();
    }
    text
}

/// A writing run's pulse in its marker: its heartbeat, a token of the run, and a count that
/// changes with every beat (and so does the marker's ETag).
#[derive(Clone, Debug)]
struct Pulse {
    every: Duration,
    token: String,
    beat: u64,
}

impl Pulse {
    /// A new run's pulse: its token from the clock, the process and the host's randomness.
    fn new(every: Duration) -> Pulse {
        let mut hash = std::collections::hash_map::RandomState::new().build_hasher();
        hash.write_u128(
            std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).unwrap_or_default().as_nanos(),
        );
        hash.write_u32(std::process::id());
        Pulse { every, token: format!("{:016x}", hash.finish()), beat: 0 }
    }
}

/// The marker's JSON: which product the prefix holds and whether it is complete; while a run
/// writes it, that run's pulse, and a resumable run's (`--resume`) identity.
fn marker_json(noun: &str, state: &str, run: Option<&Identity>, pulse: Option<&Pulse>) -> Vec<u8> {
    let mut json = serde_json::json!({ "writer": "vortex-tiler", "product": noun, "state": state });
    if let Some(run) = run {
        json["run"] = run.to_json();
    }
    if let Some(p) = pulse {
        let ms = u64::try_from(p.every.as_millis()).unwrap_or(u64::MAX);
        (json["heartbeat_ms"], json["token"], json["beat"]) = (ms.into(), p.token.clone().into(), p.beat.into());
    }
    json.to_string().into_bytes()
}

/// The heartbeat of the run a marker says is writing the prefix, if it says so (a run of a
/// version before heartbeats, or a finished one, has none).
fn marker_heartbeat(bytes: &[u8]) -> Option<Duration> {
    let json: serde_json::Value = serde_json::from_slice(bytes).ok()?;
    (json.get("state")?.as_str()? == "writing").then_some(())?;
    let ms = json.get("heartbeat_ms")?.as_u64()?;
    (1..=3_600_000).contains(&ms).then(|| Duration::from_millis(ms))
}

/// The identity of the resumable run a marker says is writing the prefix, if it says so.
fn marker_run(bytes: &[u8]) -> Option<Identity> {
    let json: serde_json::Value = serde_json::from_slice(bytes).ok()?;
    (json.get("state")?.as_str()? == "writing").then_some(())?;
    Identity::from_json(json.get("run")?)
}

/// The product a marker names, if it is ours.
fn marker_product(bytes: &[u8]) -> Option<String> {
    let json: serde_json::Value = serde_json::from_slice(bytes).ok()?;
    (json.get("writer")?.as_str()? == "vortex-tiler").then_some(())?;
    Some(json.get("product")?.as_str()?.to_string())
}

/// What is in flight: bytes, requests, and the first failure.
#[derive(Default)]
struct InFlight {
    bytes: u64,
    requests: usize,
    failed: Option<(String, String)>,
}

/// [`InFlight`] and the condition its waiters wait on.
#[derive(Default)]
struct Flight {
    state: Mutex<InFlight>,
    changed: Condvar,
}

impl Flight {
    /// A request of `bytes` ended, with `failure` (its key and the error) if it failed.
    fn ended(&self, bytes: u64, failure: Option<(String, String)>) {
        let mut s = lock(&self.state);
        s.bytes -= bytes;
        s.requests -= 1;
        if s.failed.is_none() {
            s.failed = failure;
        }
        self.changed.notify_all();
    }

    /// The run has failed at `key` for `message` (unless it had already).
    fn fail(&self, key: String, message: String) {
        let mut s = lock(&self.state);
        s.failed.get_or_insert((key, message));
        self.changed.notify_all();
    }
}

/// Why a run's heartbeat stopped it: its marker was rewritten by another run.
const TAKEN_OVER: &str = "another run has taken this prefix over (the marker is no longer this run's); \
     this run stops and leaves the prefix to it";

/// A writing run's heartbeat: a task rewriting its marker every [`Pulse::every`], each time
/// only if it is still the version this run wrote last. Another version means another run
/// took the prefix over: the run is failed ([`TAKEN_OVER`]) and leaves the prefix alone.
struct Heart {
    stop: Option<oneshot::Sender<()>>,
    task: Option<JoinHandle<()>>,
    /// The marker's version as this run wrote it last.
    version: Arc<Mutex<UpdateVersion>>,
    /// Whether another run took the prefix over.
    lost: Arc<AtomicBool>,
}

impl Heart {
    fn start(uploads: &Uploads, location: Key, mut pulse: Pulse, version: UpdateVersion) -> Heart {
        let (stop, mut stopped) = oneshot::channel::<()>();
        let version = Arc::new(Mutex::new(version));
        let lost = Arc::new(AtomicBool::new(false));
        let (store, flight) = (Arc::clone(&uploads.bucket.store), Arc::clone(&uploads.flight));
        let (noun, run, key) = (uploads.noun, uploads.run.clone(), uploads.url.child(MARKER));
        let (written, taken) = (Arc::clone(&version), Arc::clone(&lost));
        let task = uploads.bucket.runtime.spawn(async move {
            loop {
                tokio::select! {
                    _ = &mut stopped => return,
                    () = tokio::time::sleep(pulse.every) => {}
                }
                pulse.beat += 1;
                let bytes = marker_json(noun, "writing", run.as_ref(), Some(&pulse));
                let seen = lock(&written).clone();
                match Bucket::put_marker(store.as_ref(), &location, bytes, Some(seen)).await {
                    Ok(Some(now)) => *lock(&written) = now,
                    Ok(None) => {
                        taken.store(true, Ordering::SeqCst);
                        return flight.fail(key, TAKEN_OVER.into());
                    }
                    Err(e) => return flight.fail(key, reply(&e)),
                }
            }
        });
        Heart { stop: Some(stop), task: Some(task), version, lost }
    }

    /// Stops the beats, after the one in flight; the marker's version as this run wrote it last.
    fn stop(&mut self, runtime: &tokio::runtime::Runtime) -> UpdateVersion {
        if let Some(stop) = self.stop.take() {
            let _ = stop.send(());
        }
        if let Some(task) = self.task.take() {
            let _ = runtime.block_on(task);
        }
        lock(&self.version).clone()
    }
}

/// A directory output's files as objects under a prefix (see [`crate::store`]). Dropped
/// unpublished, it deletes every object under the prefix.
pub(crate) struct Uploads {
    bucket: Bucket,
    url: ObjectUrl,
    noun: &'static str,
    /// Hashes of the names written: two files of one name are refused as on a disk.
    names: Mutex<HashSet<u64>>,
    flight: Arc<Flight>,
    /// Bytes of uploads in flight at most (a larger file goes alone).
    cap: u64,
    published: bool,
    /// A resumable run's identity (`--resume`): its marker names it while the run writes, and
    /// what it uploaded stays when it is dropped unpublished, for the next `--resume`.
    run: Option<Identity>,
    heart: Option<Heart>,
}

impl Uploads {
    /// Starts a directory output (`noun`) at the prefix `url`, claimed; a previous output of
    /// ours there (`replaces`) is deleted first. At most `in_flight` bytes go at once.
    pub(crate) fn start(url: &ObjectUrl, noun: &'static str, replaces: bool, in_flight: u64) -> Result<Uploads> {
        Uploads::open(Bucket::open(url)?, url, noun, replaces, in_flight, None, heartbeat())
    }

    /// [`start`](Self::start) for a resumable run of `run` (`--resume`): the marker names the
    /// run until it is published, and the objects stay when it is dropped unpublished. `clear`:
    /// what the prefix holds is deleted first (a previous output of ours, or a run that cannot
    /// be resumed); otherwise it is the interrupted run's, kept.
    pub(crate) fn resuming(
        url: &ObjectUrl,
        noun: &'static str,
        clear: bool,
        in_flight: u64,
        run: Identity,
    ) -> Result<Uploads> {
        Uploads::open(Bucket::open(url)?, url, noun, clear, in_flight, Some(run), heartbeat())
    }

    /// Takes the prefix: once no other run writes it ([`Bucket::idle_marker`]), the marker is
    /// written only if it is still the one seen (or still absent), so that of two runs starting
    /// at once one is refused; then what the prefix held is deleted (`replaces`), and the
    /// heartbeat starts.
    fn open(
        bucket: Bucket,
        url: &ObjectUrl,
        noun: &'static str,
        replaces: bool,
        in_flight: u64,
        run: Option<Identity>,
        every: Duration,
    ) -> Result<Uploads> {
        let busy = |why: &str| StoreError::Busy { url: url.to_string(), why: why.into() };
        let seen = bucket.idle_marker(url)?;
        if seen.is_some() && !replaces && run.is_none() {
            return Err(busy("another run began writing it after this one found it empty").into());
        }
        let pulse = Pulse::new(every);
        let key = url.child(MARKER);
        let location = bucket.key(&key)?;
        let bytes = marker_json(noun, "writing", run.as_ref(), Some(&pulse));
        let put = Bucket::put_marker(bucket.store.as_ref(), &location, bytes, seen);
        let version = bucket.runtime.block_on(put).map_err(|e| bucket.failed(&key, "PUT", reply(&e)))?;
        let Some(version) = version else {
            return Err(busy("another run began writing it at the same time").into());
        };
        let mut uploads = Uploads {
            bucket,
            url: url.clone(),
            noun,
            names: Mutex::new(HashSet::new()),
            flight: Arc::default(),
            cap: in_flight.max(1),
            published: false,
            run,
            heart: None,
        };
        if replaces {
            uploads.bucket.delete_but_marker(url)?;
        }
        uploads.heart = Some(Heart::start(&uploads, location, pulse, version));
        Ok(uploads)
    }

    /// Deletes the objects `names` ('/'-separated, under the prefix).
    pub(crate) fn delete(&self, names: &[String]) -> Result<(), StoreError> {
        self.bucket.delete_names(&self.url, names)
    }

    /// Waits until nothing is in flight; the first failure, if any.
    fn settle(&self) -> Result<(), StoreError> {
        let mut s = lock(&self.flight.state);
        while s.requests > 0 {
            s = self.flight.changed.wait(s).unwrap_or_else(|p| p.into_inner());
        }
        match &s.failed {
            None => Ok(()),
            Some((key, message)) => Err(self.bucket.failed(key, "PUT", message)),
        }
    }
}

impl Files for Uploads {
    fn put_new(&self, name: &str, bytes: &[u8]) -> Result<bool> {
        let key = self.url.child(name);
        let location = self.bucket.key(&key)?;
        let mut hash = crate::fnv::Fnv::default();
        hash.write(name.as_bytes());
        if !lock(&self.names).insert(hash.finish()) {
            return Ok(false);
        }
        let len = bytes.len() as u64;
        {
            let mut s = lock(&self.flight.state);
            while s.failed.is_none() && s.requests > 0 && (s.requests >= MAX_REQUESTS || s.bytes + len > self.cap) {
                s = self.flight.changed.wait(s).unwrap_or_else(|p| p.into_inner());
            }
            if let Some((key, message)) = &s.failed {
                return Err(self.bucket.failed(key, "PUT", message).into());
            }
            s.bytes += len;
            s.requests += 1;
        }
        let (store, flight) = (Arc::clone(&self.bucket.store), Arc::clone(&self.flight));
        let payload = PutPayload::from(bytes.to_vec());
        self.bucket.runtime.spawn(async move {
            let result = store.put(&location, payload).await;
            flight.ended(len, result.err().map(|e| (key, reply(&e))));
        });
        Ok(true)
    }

    fn read(&self, name: &str) -> Result<Vec<u8>> {
        self.settle()?;
        let key = self.url.child(name);
        match self.bucket.get(&key, u64::MAX)? {
            Some(bytes) => Ok(bytes),
            None => Err(self.bucket.failed(&key, "GET", "no such object, though this run wrote it").into()),
        }
    }

    fn publish(&mut self, manifests: Vec<(String, Vec<u8>)>) -> Result<()> {
        self.settle()?;
        for (name, bytes) in manifests {
            self.bucket.put(&self.url.child(&name), bytes)?;
        }
        // The last word only if the marker is still this run's.
        let seen = self.heart.as_mut().map(|h| h.stop(&self.bucket.runtime));
        let key = self.url.child(MARKER);
        let location = self.bucket.key(&key)?;
        let bytes = marker_json(self.noun, "complete", None, None);
        let put = Bucket::put_marker(self.bucket.store.as_ref(), &location, bytes, seen);
        match self.bucket.runtime.block_on(put).map_err(|e| self.bucket.failed(&key, "PUT", reply(&e)))? {
            Some(_) => self.published = true,
            None => {
                if let Some(h) = &self.heart {
                    h.lost.store(true, Ordering::SeqCst);
                }
                return Err(self.bucket.failed(&key, "PUT", TAKEN_OVER).into());
            }
        }
        Ok(())
    }
}

/// An unpublished output's objects are deleted: a failed run leaves nothing under the prefix.
impl Drop for Uploads {
    fn drop(&mut self) {
        if self.published {
            return;
        }
        let lost = self.heart.as_mut().is_some_and(|h| {
            h.stop(&self.bucket.runtime);
            h.lost.load(Ordering::SeqCst)
        });
        let _ = self.settle();
        // Another run's now, or kept for the next `--resume`.
        if lost || self.run.is_some() {
            return;
        }
        if let Err(e) = self.bucket.delete_prefix(&self.url) {
            // Nothing to return the error to: the run has failed already, with its own error.
            eprintln!("warning: removing the unfinished output at {}: {e}", self.url);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_marker_names_its_product_and_only_ours_counts() {
        let marker = marker_json("a Deep Zoom pyramid", "writing", None, None);
        assert_eq!(marker_product(&marker).as_deref(), Some("a Deep Zoom pyramid"));
        assert_eq!((marker_run(&marker), marker_heartbeat(&marker)), (None, None));
        let run = Identity::new().with("tile size", 256);
        let pulse = Pulse::new(Duration::from_millis(1500));
        let marker = marker_json("a Deep Zoom pyramid", "writing", Some(&run), Some(&pulse));
        assert_eq!(marker_product(&marker).as_deref(), Some("a Deep Zoom pyramid"));
        assert_eq!(marker_run(&marker), Some(run.clone()));
        assert_eq!(marker_heartbeat(&marker), Some(Duration::from_millis(1500)));
        let done = marker_json("a Deep Zoom pyramid", "complete", Some(&run), Some(&pulse));
        assert_eq!((marker_run(&done), marker_heartbeat(&done)), (None, None));
        assert_eq!(marker_product(br#"{"writer":"someone","product":"a Deep Zoom pyramid"}"#), None);
        assert_eq!(marker_product(b"not json"), None);
    }

    #[test]
    fn a_reply_carries_its_causes_once() {
        let cause = std::io::Error::new(std::io::ErrorKind::ConnectionRefused, "Connection refused");
        let e = object_store::Error::Generic { store: "S3", source: Box::new(cause) };
        let text = reply(&e);
        assert_eq!(text.matches("Connection refused").count(), 1, "{text}");
    }

    const NOUN: &str = "a Deep Zoom pyramid";

    /// A client of `s3://tiles/out` in `memory`, as a second run on another machine would have.
    fn client(memory: &Arc<object_store::memory::InMemory>) -> (Bucket, ObjectUrl) {
        let url = ObjectUrl::parse("s3://tiles/out").unwrap();
        (Bucket::with_store(Arc::clone(memory) as Arc<dyn Store>, &url).unwrap(), url)
    }

    /// A run writing `s3://tiles/out` with a heartbeat of `every`.
    fn run(memory: &Arc<object_store::memory::InMemory>, replaces: bool, every: Duration) -> Result<Uploads> {
        let (bucket, url) = client(memory);
        Uploads::open(bucket, &url, NOUN, replaces, 1 << 20, None, every)
    }

    fn busy(e: crate::error::TilerError) -> String {
        let text = e.to_string();
        assert!(matches!(e, crate::error::TilerError::Store(StoreError::Busy { .. })), "{text}");
        text
    }

    #[test]
    fn a_prefix_a_run_is_writing_is_refused_and_a_dead_runs_taken_over() {
        let memory = Arc::new(object_store::memory::InMemory::new());
        let beat = Duration::from_millis(100);
        let mut first = run(&memory, false, beat).unwrap();
        assert!(first.put_new("a.jpeg", b"first").unwrap());
        // The first run beats while the second watches: refused, and nothing of the first's
        // is touched.
        let text = busy(run(&memory, true, beat).err().expect("a second run on a live prefix"));
        assert!(text.contains("s3://tiles/out: another run is writing it"), "{text}");
        first.publish(vec![("out.dzi".into(), b"manifest".to_vec())]).unwrap();
        let (bucket, url) = client(&memory);
        assert_eq!(bucket.list_sizes(&url).unwrap().len(), 2);
        let marker = bucket.get(&url.child(MARKER), MAX_MARKER_BYTES).unwrap().unwrap();
        assert_eq!((marker_product(&marker).as_deref(), marker_heartbeat(&marker)), (Some(NOUN), None));
        drop(first);

        // A killed run's marker, which never changes: watched for four of its beats, then
        // taken over, and what that run left is deleted.
        let mut pulse = Pulse::new(beat);
        pulse.beat = 7;
        bucket.put(&url.child(MARKER), marker_json(NOUN, "writing", None, Some(&pulse))).unwrap();
        bucket.put(&url.child("b.jpeg"), b"killed".to_vec()).unwrap();
        let mut second = run(&memory, true, beat).unwrap();
        assert!(second.put_new("c.jpeg", b"second").unwrap());
        second.publish(Vec::new()).unwrap();
        let names: HashSet<String> = bucket.list_sizes(&url).unwrap().into_keys().collect();
        assert_eq!(names, HashSet::from(["c.jpeg".to_string()]));
    }

    #[test]
    fn a_run_whose_prefix_is_taken_over_stops_and_leaves_it() {
        let memory = Arc::new(object_store::memory::InMemory::new());
        let mut first = run(&memory, false, Duration::from_millis(20)).unwrap();
        assert!(first.put_new("a.jpeg", b"first").unwrap());
        // Another writer's marker (a run that judged this one dead), and its tile.
        let (bucket, url) = client(&memory);
        let theirs = marker_json(NOUN, "writing", None, Some(&Pulse::new(Duration::from_secs(30))));
        bucket.put(&url.child(MARKER), theirs.clone()).unwrap();
        bucket.put(&url.child("theirs.jpeg"), b"theirs".to_vec()).unwrap();
        // The next beat finds it and stops the run; without a clock in the test, it is waited
        // for by the tiles refused (a beat every 20 ms, so within a few tries).
        let mut tries = 0;
        let e = loop {
            match first.put_new(&format!("t{tries}.jpeg"), b"x") {
                Ok(_) => std::thread::sleep(Duration::from_millis(20)),
                Err(e) => break e,
            }
            tries += 1;
            assert!(tries < 5000, "the run went on writing a prefix taken over");
        };
        assert!(e.to_string().contains("another run has taken this prefix over"), "{e}");
        assert!(first.publish(Vec::new()).is_err());
        drop(first);
        // Dropped unpublished, it deletes nothing: the prefix is the other run's.
        assert_eq!(bucket.get(&url.child(MARKER), MAX_MARKER_BYTES).unwrap(), Some(theirs));
        assert!(bucket.list_sizes(&url).unwrap().contains_key("theirs.jpeg"));
    }

    #[test]
    fn of_two_marker_writes_from_one_version_one_wins() {
        let memory = Arc::new(object_store::memory::InMemory::new());
        let (bucket, url) = client(&memory);
        let location = bucket.key(&url.child(MARKER)).unwrap();
        let put = |seen: Option<UpdateVersion>| {
            let store = bucket.store.as_ref();
            bucket.runtime.block_on(Bucket::put_marker(store, &location, b"m".to_vec(), seen)).unwrap()
        };
        let first = put(None).expect("created");
        assert_eq!(put(None), None, "created twice");
        let second = put(Some(first.clone())).expect("updated from the version seen");
        assert_eq!(put(Some(first)), None, "updated from a version replaced since");
        assert!(put(Some(second)).is_some());
    }
}
