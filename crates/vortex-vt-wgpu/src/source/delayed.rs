//! A source that answers every tile after a fixed latency: what a slow disk, a network share or
//! an object store does to a frame loop, without one. `render --io-latency` and the never-stall
//! tests wrap their packs in it.

use std::path::Path;
use std::sync::Arc;
use std::time::Duration;

use super::{PageSource, ReadError, SourceTile};
use crate::loader::LoaderError;
use crate::page_cache::CacheFormat;
use crate::texture::VirtualTexture;

/// `inner`, each tile read `latency` late (the worker thread sleeps; a frame never does).
pub struct Delayed {
    inner: Arc<dyn PageSource>,
    latency: Duration,
}

impl Delayed {
    pub fn new(inner: Arc<dyn PageSource>, latency: Duration) -> Delayed {
        Delayed { inner, latency }
    }
}

impl PageSource for Delayed {
    fn location(&self) -> &Path {
        self.inner.location()
    }

    fn texture(&self) -> Result<VirtualTexture, LoaderError> {
        self.inner.texture()
    }

    fn read_tile(&self, lod: u8, x: u16, y: u16, format: CacheFormat) -> Result<SourceTile, ReadError> {
        std::thread::sleep(self.latency);
        self.inner.read_tile(lod, x, y, format)
    }

    fn holds_only_bc7(&self) -> bool {
        self.inner.holds_only_bc7()
    }

    fn opaque(&self) -> bool {
        self.inner.opaque()
    }
}
