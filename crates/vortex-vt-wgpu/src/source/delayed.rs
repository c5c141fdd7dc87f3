//! A source that answers every tile after a fixed latency: what a slow disk, a network share or
//! an object store does to a frame loop, without one. `render --io-latency` wraps its packs in
//! it, and the tests' gated source (reads held until the test lets them through) is the same
//! wrapper with another wait. Only reads wait: decoding stored bytes the memory tier kept does
//! not, which is the tier's whole gain.

use std::path::Path;
use std::sync::Arc;
use std::time::Duration;

use super::{PageSource, ReadError, SourceTile, StoredRead, TileId, TileKind};
use crate::loader::{LoaderError, RetryPolicy};
use crate::page_cache::CacheFormat;
use crate::texture::VirtualTexture;

/// What a read waits for before it is answered; an error fails that read.
type Wait = Box<dyn Fn() -> Result<(), ReadError> + Send + Sync>;

/// `inner`, each tile read answered after a wait on the loader's worker thread (a frame never
/// waits).
pub struct Delayed {
    inner: Arc<dyn PageSource>,
    wait: Wait,
}

impl Delayed {
    /// Each read `latency` late.
    pub fn new(inner: Arc<dyn PageSource>, latency: Duration) -> Delayed {
        Delayed::with_wait(inner, move || {
            std::thread::sleep(latency);
            Ok(())
        })
    }

    /// Each read answered once `wait` returns (or failed with its error).
    pub fn with_wait(
        inner: Arc<dyn PageSource>,
        wait: impl Fn() -> Result<(), ReadError> + Send + Sync + 'static,
    ) -> Delayed {
        Delayed { inner, wait: Box::new(wait) }
    }
}

impl PageSource for Delayed {
    fn location(&self) -> &Path {
        self.inner.location()
    }

    fn texture(&self) -> Result<VirtualTexture, LoaderError> {
        self.inner.texture()
    }

    fn read_tile(&self, tile: TileId, format: CacheFormat) -> Result<SourceTile, ReadError> {
        (self.wait)()?;
        self.inner.read_tile(tile, format)
    }

    fn read_stored(&self, tile: TileId) -> Result<Option<StoredRead>, ReadError> {
        let stored = self.inner.read_stored(tile);
        // A source with no stored form is read (and waited for) by `read_tile` instead.
        if !matches!(stored, Ok(None)) {
            (self.wait)()?;
        }
        stored
    }

    fn decode(&self, tile: TileId, kind: TileKind, bytes: &[u8], format: CacheFormat) -> Result<Vec<u8>, ReadError> {
        self.inner.decode(tile, kind, bytes, format)
    }

    fn retry_policy(&self, loader: RetryPolicy) -> RetryPolicy {
        self.inner.retry_policy(loader)
    }

    fn holds_only_bc7(&self) -> bool {
        self.inner.holds_only_bc7()
    }

    fn opaque(&self) -> bool {
        self.inner.opaque()
    }
}
