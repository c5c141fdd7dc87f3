//! [`Fetched`]: objects at `s3://` URLs downloaded whole into a local temporary directory, for
//! a reader that maps files (`merge` reads shard packs so, a page at a time in the order one
//! machine writes them, jumping between shards: a request per page would be thousands of
//! small GETs). The directory is removed when dropped; a later run removes those of runs that
//! were killed. Local disk must hold the objects for the time of the run.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

use super::{ObjectUrl, StoreError};
use crate::error::Result;
use crate::output::staging;

/// Download directories this process made, numbered from 0, so that a later run can find
/// those of a dead one ([`staging::remove_stale`]).
static MADE: AtomicUsize = AtomicUsize::new(0);

/// Objects downloaded into a local temporary directory, each a file of its own.
pub(crate) struct Fetched {
    dir: PathBuf,
    files: Vec<PathBuf>,
}

impl Fetched {
    /// Downloads `urls`, one after another, into a fresh directory under the system's
    /// temporary directory (those dead runs left there are removed first). The first object
    /// that is missing or cannot be read fails the whole, naming it, and removes what was
    /// downloaded.
    pub(crate) fn download(urls: &[ObjectUrl]) -> Result<Fetched> {
        let Some(first) = urls.first() else { return Ok(Fetched { dir: PathBuf::new(), files: Vec::new() }) };
        let n = MADE.fetch_add(1, Ordering::Relaxed);
        let base = std::env::temp_dir().join(format!("vortex-s3-get-{n}"));
        let fail =
            |path: &Path, source| StoreError::Staging { url: first.to_string(), path: path.to_path_buf(), source };
        staging::remove_stale(&base).map_err(|e| fail(&base, e))?;
        let dir = staging::partial_path(&base);
        staging::fresh_dir(&dir).map_err(|e| fail(&dir, e))?;
        let mut fetched = Fetched { dir, files: Vec::with_capacity(urls.len()) };
        let mut client = Client::default();
        for (i, url) in urls.iter().enumerate() {
            // Numbered: two prefixes may hold objects of one name.
            let name = url.key().rsplit('/').next().filter(|n| !n.is_empty()).unwrap_or("object");
            let local = fetched.dir.join(format!("{i}-{name}"));
            client.get(url, &local)?;
            fetched.files.push(local);
        }
        Ok(fetched)
    }

    /// The local files, in the order of the URLs given.
    pub(crate) fn files(&self) -> &[PathBuf] {
        &self.files
    }
}

impl Drop for Fetched {
    fn drop(&mut self) {
        if !self.dir.as_os_str().is_empty() {
            let _ = std::fs::remove_dir_all(&self.dir);
        }
    }
}

/// The objects directly below the prefix `url` (none deeper), sorted by key.
#[cfg(feature = "s3")]
pub(crate) fn list_below(url: &ObjectUrl) -> Result<Vec<ObjectUrl>> {
    let bucket = super::bucket::Bucket::open(url)?;
    Ok(bucket.list_below(url)?.into_iter().map(|(url, _)| url).collect())
}

#[cfg(not(feature = "s3"))]
pub(crate) fn list_below(url: &ObjectUrl) -> Result<Vec<ObjectUrl>> {
    Err(StoreError::NotBuilt { url: url.to_string() }.into())
}

/// The client of the bucket last read from, kept while the URLs stay in it.
#[derive(Default)]
struct Client {
    #[cfg(feature = "s3")]
    bucket: Option<super::bucket::Bucket>,
}

impl Client {
    #[cfg(feature = "s3")]
    fn get(&mut self, url: &ObjectUrl, local: &Path) -> Result<()> {
        let bucket = match self.bucket.take() {
            Some(bucket) if bucket.holds(url) => bucket,
            _ => super::bucket::Bucket::open(url)?,
        };
        bucket.download(url, local)?;
        self.bucket = Some(bucket);
        Ok(())
    }

    #[cfg(not(feature = "s3"))]
    fn get(&mut self, url: &ObjectUrl, _: &Path) -> Result<()> {
        Err(StoreError::NotBuilt { url: url.to_string() }.into())
    }
}
