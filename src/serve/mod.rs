//! `vortex-tiler serve`: packs, split directories and viewer-layout directories over HTTP, as
//! Deep Zoom, IIIF level 0 and XYZ tiles (the names and crops of [`crate::formats::viewer`]), and packs
//! as files with `Range` requests. See docs/serve.md for the routes and headers.
//!
//! A program embeds it with three types: a [`Catalog`] of inputs, [`ServeOptions`] and the
//! [`Server`]. Its parts are private:
//! - `catalog`: the inputs, opened and checked at start, and their names;
//! - `routes`: URL paths into typed requests (400/404 for the rest);
//! - `tiles`: a stored page into a viewer tile (the stored bytes, or decode, crop, encode);
//! - `cache`: the re-encoded tiles, an LRU bounded by bytes;
//! - `range`: one `Range` header;
//! - `html`: the index and the OpenSeadragon page;
//! - `tile_routes`: a Deep Zoom, IIIF or XYZ tile name into its page, crop and bytes;
//! - `http`: the axum handler that puts these together, with the headers;
//! - `files`: the files of a served directory, opened only if regular and inside it;
//! - [`Server`]: the accept loop, with its cap on connections and its idle timeout.

mod cache;
mod catalog;
mod files;
mod html;
mod http;
mod range;
mod reply;
mod routes;
mod tile_routes;
mod tiles;

use std::future::Future;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

use hyper_util::rt::{TokioIo, TokioTimer};
use hyper_util::service::TowerToHyperService;
use tokio::sync::Semaphore;

use crate::error::ShowPath;
use cache::TileCache;
pub use catalog::Catalog;

/// What every request reads: the inputs, the tile cache and the limits on work at once.
pub(crate) struct AppState {
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

/// What stops the server before it serves.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ServeError {
    /// An input that is missing, unreadable or not something this server serves.
    #[error("{}: {message}", path.shown())]
    Input {
        /// The input as given.
        path: PathBuf,
        /// What is wrong with it.
        message: String,
    },
    /// Two inputs would answer at the same URLs.
    #[error("{} and {} are both named '{name}' in URLs; rename one (names are file stems)", first.shown(), second.shown())]
    DuplicateName {
        /// The name both would have in URLs (a file stem).
        name: String,
        /// The first input of that name.
        first: PathBuf,
        /// The second.
        second: PathBuf,
    },
    /// `--openseadragon` is not a directory holding `openseadragon.min.js`.
    #[error("{}: {message}", path.shown())]
    OpenSeadragon {
        /// The directory given.
        path: PathBuf,
        /// What is missing.
        message: String,
    },
    /// The address cannot be listened on (in use, not ours).
    #[error("cannot listen on {addr}: {source}")]
    Bind {
        /// The address asked for.
        addr: SocketAddr,
        /// The operating system's error.
        #[source]
        source: std::io::Error,
    },
    /// An option out of its range.
    #[error("{0}")]
    Options(String),
    /// An I/O error of the listener: its address not read back after binding, or serving.
    #[error("serving failed: {0}")]
    Io(#[from] std::io::Error),
}

/// How the server runs.
#[derive(Clone, Debug)]
pub struct ServeOptions {
    /// Address and port to listen on (`--addr`); port 0 takes a free one.
    pub addr: SocketAddr,
    /// Bytes of re-encoded tiles kept in memory (0: none).
    pub cache_bytes: u64,
    /// Requests answered at once; more wait.
    pub max_concurrent: usize,
    /// Decode-and-encode jobs at once.
    pub blocking_jobs: usize,
    /// Connections open at once; more wait in the listen queue until one closes.
    pub max_connections: usize,
    /// How long a connection may take to send a request's headers, and may stay idle between
    /// requests, before it is closed.
    pub idle_timeout: Duration,
    /// A local OpenSeadragon build (`openseadragon.min.js` + `images/`), else the CDN's.
    pub openseadragon: Option<PathBuf>,
}

/// The largest `--max-concurrent` and `--max-connections`: far more than one process serves
/// well, and far under what tokio's semaphores hold.
pub(crate) const MAX_CONNECTIONS: usize = 65_536;
/// The longest `--idle-timeout`, in seconds.
pub(crate) const MAX_IDLE_TIMEOUT_S: u64 = 3600;

impl ServeOptions {
    /// Refuses counts of 0 (no request would ever be answered) and counts over the caps,
    /// naming the flag, before anything is sized from them.
    pub fn check(&self) -> Result<(), ServeError> {
        let threads = crate::limits::max_threads();
        let counts = [
            ("--max-concurrent", self.max_concurrent, MAX_CONNECTIONS, String::new()),
            ("--max-connections", self.max_connections, MAX_CONNECTIONS, String::new()),
            ("--threads", self.blocking_jobs, threads, " (4 per core)".to_string()),
        ];
        for (flag, n, cap, why) in counts {
            if n == 0 || n > cap {
                return Err(ServeError::Options(format!("{flag} {n} is not between 1 and {cap}{why}")));
            }
        }
        let timeout = self.idle_timeout;
        if timeout < Duration::from_secs(1) || timeout > Duration::from_secs(MAX_IDLE_TIMEOUT_S) {
            return Err(ServeError::Options(format!(
                "--idle-timeout {} is not between 1 and {MAX_IDLE_TIMEOUT_S} seconds",
                timeout.as_secs()
            )));
        }
        Ok(())
    }
}

/// A server bound to its address, not yet serving.
pub struct Server {
    listener: tokio::net::TcpListener,
    state: Arc<AppState>,
    max_connections: usize,
    idle_timeout: Duration,
}

impl Server {
    /// Checks the options and listens; call inside a tokio runtime.
    pub async fn bind(catalog: Catalog, options: &ServeOptions) -> Result<Server, ServeError> {
        options.check()?;
        let openseadragon = match &options.openseadragon {
            None => None,
            Some(dir) => {
                let fail = |message: String| ServeError::OpenSeadragon { path: dir.clone(), message };
                let canonical = std::fs::canonicalize(dir).map_err(|e| fail(e.to_string()))?;
                if !canonical.join("openseadragon.min.js").is_file() {
                    return Err(fail("holds no openseadragon.min.js (give its build/openseadragon directory)".into()));
                }
                Some(canonical)
            }
        };
        let listener = tokio::net::TcpListener::bind(options.addr)
            .await
            .map_err(|source| ServeError::Bind { addr: options.addr, source })?;
        let local_addr = listener.local_addr()?;
        let state = Arc::new(AppState {
            catalog,
            cache: cache::TileCache::new(options.cache_bytes),
            requests: Semaphore::new(options.max_concurrent),
            blocking: Arc::new(Semaphore::new(options.blocking_jobs)),
            openseadragon,
            local_addr,
        });
        Ok(Server { listener, state, max_connections: options.max_connections, idle_timeout: options.idle_timeout })
    }

    /// The address listened on (the real port for port 0).
    pub fn local_addr(&self) -> SocketAddr {
        self.state.local_addr
    }

    /// How many inputs (packs and directories) the server answers for.
    pub fn input_count(&self) -> usize {
        self.state.catalog.inputs.len()
    }

    /// Serves until `shutdown` completes, then stops taking connections and lets the open
    /// ones finish their requests (at most `grace` more).
    ///
    /// Each connection holds one of `--max-connections` permits; without one the loop accepts
    /// nothing, so the clients past the cap wait in the listen queue and no descriptor is
    /// spent on them. hyper's header-read timeout (`--idle-timeout`) closes a connection that
    /// sends no complete request head in time, on a new connection as between requests, so
    /// idle or slow clients give their permits back.
    pub async fn serve(
        self,
        shutdown: impl Future<Output = ()> + Send + 'static,
        grace: Duration,
    ) -> Result<(), ServeError> {
        let app = axum::Router::new().fallback(http::handle).with_state(self.state);
        let service = TowerToHyperService::new(app);
        let mut http = hyper::server::conn::http1::Builder::new();
        http.timer(TokioTimer::new()).header_read_timeout(self.idle_timeout);
        let connections = Arc::new(Semaphore::new(self.max_connections));
        let (stopping, stop) = tokio::sync::watch::channel(false);
        let mut shutdown = std::pin::pin!(shutdown);
        loop {
            let permit = tokio::select! {
                () = &mut shutdown => break,
                permit = connections.clone().acquire_owned() => permit.map_err(|e| std::io::Error::other(e.to_string()))?,
            };
            let stream = tokio::select! {
                () = &mut shutdown => break,
                accepted = self.listener.accept() => match accepted {
                    Ok((stream, _)) => stream,
                    // Out of descriptors, or a connection reset before it was taken: not the
                    // server's end. A pause, so that a full descriptor table is no busy loop.
                    Err(e) => {
                        eprintln!("serve: accepting a connection: {e}");
                        tokio::time::sleep(Duration::from_millis(100)).await;
                        continue;
                    }
                },
            };
            let connection = http.serve_connection(TokioIo::new(stream), service.clone());
            let mut stop = stop.clone();
            tokio::spawn(async move {
                let _permit = permit;
                let mut connection = std::pin::pin!(connection);
                tokio::select! {
                    _ = connection.as_mut() => return,
                    _ = stop.wait_for(|stop| *stop) => connection.as_mut().graceful_shutdown(),
                }
                // Errors of one connection (a client gone, a timeout) are that client's.
                let _ = connection.await;
            });
        }
        // Stop every connection after its request in flight, and wait for all of them to give
        // their permits back, at most `grace`.
        let _ = stopping.send(true);
        let all = u32::try_from(self.max_connections).unwrap_or(u32::MAX);
        let _ = tokio::time::timeout(grace, connections.acquire_many(all)).await;
        Ok(())
    }
}
