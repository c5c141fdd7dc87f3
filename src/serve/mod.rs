//! `vortex-tiler serve`: packs, split directories and viewer-layout directories over HTTP, as
//! Deep Zoom, IIIF level 0 and XYZ tiles (the names and crops of [`crate::viewer`]), and packs
//! as files with `Range` requests. See docs/serve.md for the routes and headers.
//!
//! - [`catalog`]: the inputs, opened and checked at start, and their names;
//! - [`routes`]: URL paths into typed requests (400/404 for the rest);
//! - [`tiles`]: a stored page into a viewer tile (the stored bytes, or decode, crop, encode);
//! - [`cache`]: the re-encoded tiles, an LRU bounded by bytes;
//! - [`range`]: one `Range` header;
//! - [`html`]: the index and the OpenSeadragon page;
//! - `tile_routes`: a Deep Zoom, IIIF or XYZ tile name into its page, crop and bytes;
//! - `http`: the axum handler that puts these together, with the headers.

pub mod cache;
pub mod catalog;
pub mod html;
mod http;
pub mod range;
pub mod routes;
mod tile_routes;
pub mod tiles;

use std::future::Future;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::Arc;

use tokio::sync::Semaphore;

pub use catalog::Catalog;

/// What stops the server before it serves.
#[derive(Debug, thiserror::Error)]
pub enum ServeError {
    /// An input that is missing, unreadable or not something this server serves.
    #[error("{}: {message}", path.display())]
    Input { path: PathBuf, message: String },
    /// Two inputs would answer at the same URLs.
    #[error("{} and {} are both named '{name}' in URLs; rename one (names are file stems)", first.display(), second.display())]
    DuplicateName { name: String, first: PathBuf, second: PathBuf },
    /// `--openseadragon` is not a directory holding `openseadragon.min.js`.
    #[error("{}: {message}", path.display())]
    OpenSeadragon { path: PathBuf, message: String },
    /// The address cannot be listened on (in use, not ours).
    #[error("cannot listen on {addr}: {source}")]
    Bind {
        addr: SocketAddr,
        #[source]
        source: std::io::Error,
    },
    #[error("serving failed: {0}")]
    Io(#[from] std::io::Error),
}

/// How the server runs.
#[derive(Clone, Debug)]
pub struct ServeOptions {
    pub addr: SocketAddr,
    /// Bytes of re-encoded tiles kept in memory (0: none).
    pub cache_bytes: u64,
    /// Requests answered at once; more wait.
    pub max_concurrent: usize,
    /// Decode-and-encode jobs at once.
    pub blocking_jobs: usize,
    /// A local OpenSeadragon build (`openseadragon.min.js` + `images/`), else the CDN's.
    pub openseadragon: Option<PathBuf>,
}

/// A server bound to its address, not yet serving.
pub struct Server {
    listener: tokio::net::TcpListener,
    state: Arc<http::AppState>,
}

impl Server {
    /// Checks the options and listens; call inside a tokio runtime.
    pub async fn bind(catalog: Catalog, options: &ServeOptions) -> Result<Server, ServeError> {
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
        let state = Arc::new(http::AppState {
            catalog,
            cache: cache::TileCache::new(options.cache_bytes),
            requests: Semaphore::new(options.max_concurrent.max(1)),
            blocking: Arc::new(Semaphore::new(options.blocking_jobs.max(1))),
            openseadragon,
            local_addr,
        });
        Ok(Server { listener, state })
    }

    /// The address listened on (the real port for port 0).
    pub fn local_addr(&self) -> SocketAddr {
        self.state.local_addr
    }

    pub fn input_count(&self) -> usize {
        self.state.catalog.inputs.len()
    }

    /// Serves until `shutdown` completes, then stops taking connections and lets the open
    /// ones finish their requests (at most `grace` more).
    pub async fn serve(
        self,
        shutdown: impl Future<Output = ()> + Send + 'static,
        grace: std::time::Duration,
    ) -> Result<(), ServeError> {
        let app = axum::Router::new().fallback(http::handle).with_state(self.state);
        let stopping = Arc::new(tokio::sync::Notify::new());
        let notify = stopping.clone();
        let signal = async move {
            shutdown.await;
            notify.notify_one();
        };
        let server = axum::serve(self.listener, app).with_graceful_shutdown(signal);
        tokio::select! {
            result = server => result.map_err(ServeError::Io),
            () = async { stopping.notified().await; tokio::time::sleep(grace).await } => Ok(()),
        }
    }
}
