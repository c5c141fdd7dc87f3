//! [`Staged`]: an output written as one object (PMTiles, a zipped OME-Zarr, a TIFF, a pack with
//! `--resume`) at an `s3://` URL, or a directory (OME-Zarr, DICOM) written locally before its
//! files are uploaded. The PMTiles writer lays out its directories once the data's order is
//! known, and the TIFF writer patches its directories' offsets, so the file is written by the
//! format's own sink into a local temporary (under `TMPDIR`), exactly as for a local
//! destination, then read back into a [`super::stream::Stream`] (a pack without `--resume` is
//! streamed as it is made, with no temporary). The object appears only when the upload
//! completes; a failure aborts the upload and the temporary is removed either way. Local disk
//! must therefore hold the whole file.
//!
//! A directory is staged the same way (the OME-Zarr sink reorders each 0.5 shard's chunks
//! through a local file and writes its metadata at the end; the DICOM sink writes each
//! instance's offset tables after its frames), then sent file by file through
//! [`super::bucket::Uploads`], which follows a directory layout's rules: the marker first, the
//! metadata last, everything deleted on failure. Not streamed yet either.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

use super::{ObjectUrl, StoreError};
use crate::error::Result;
use crate::output::{Product, staging};

/// Staging directories this process made, numbered from 0, so that a later run can find
/// those of a dead one ([`staging::remove_stale`]).
static MADE: AtomicUsize = AtomicUsize::new(0);

/// Whether `product` is one file, written to a bucket as one object.
pub(crate) fn single_object(product: Product) -> bool {
    matches!(product, Product::Pack | Product::Pmtiles | Product::Ozx | Product::Tiff)
}

/// Whether `product` is a directory written locally, then uploaded file by file: an OME-Zarr
/// directory, whose sink reorders each shard's chunks in a local file, and a DICOM series,
/// whose instances' offset tables are written after their frames.
pub(crate) fn staged_dir(product: Product) -> bool {
    matches!(product, Product::OmeZarr | Product::Dicom)
}

/// The names of Zarr's metadata files, uploaded after every chunk and shard.
#[cfg(feature = "s3")]
const ZARR_METADATA: [&str; 5] = ["zarr.json", ".zattrs", ".zarray", ".zgroup", ".zmetadata"];

/// A one-object output's local temporary, sent to its URL by [`Staged::upload`].
pub(crate) struct Staged {
    url: ObjectUrl,
    // Without the `s3` feature no claim of an s3:// URL succeeds, so none is ever uploaded.
    #[cfg_attr(not(feature = "s3"), allow(dead_code))]
    product: Product,
    /// Whether the claim found a previous output of ours at the prefix (a directory's).
    #[cfg_attr(not(feature = "s3"), allow(dead_code))]
    replaces: bool,
    /// The staging directory (removed when dropped) and the file in it the sink writes.
    dir: PathBuf,
    local: PathBuf,
    /// A resumable run's (`--resume`): the directory stays until the file is uploaded.
    keep: bool,
}

/// Where a resumable run (`--resume`, docs/resume.md) of this machine stages the file of
/// `url`: in a directory of its own under the system's temporary directory, named after the
/// URL and the endpoint, the same for every run of that command, so that the next `--resume`
/// finds the journal and the staged pack beside this path, as beside a local output.
pub(crate) fn resumable_path(url: &ObjectUrl) -> PathBuf {
    use std::hash::Hasher;
    let mut hash = crate::fnv::Fnv::default();
    hash.write(url.to_string().as_bytes());
    for name in ["AWS_ENDPOINT_URL", "AWS_ENDPOINT"] {
        hash.write(std::env::var(name).unwrap_or_default().as_bytes());
        hash.write(&[0]);
    }
    let name = url.key().rsplit('/').next().filter(|n| !n.is_empty()).unwrap_or("output");
    std::env::temp_dir().join(format!("vortex-s3-resume-{:016x}", hash.finish())).join(name)
}

impl Staged {
    /// A fresh staging directory for `url`'s file under the system's temporary directory;
    /// those that dead runs left there are removed first.
    pub(crate) fn create(url: &ObjectUrl, product: Product, replaces: bool) -> Result<Staged> {
        let n = MADE.fetch_add(1, Ordering::Relaxed);
        let base = std::env::temp_dir().join(format!("vortex-s3-{n}"));
        let fail = |path: &Path, source| StoreError::Staging { url: url.to_string(), path: path.to_path_buf(), source };
        staging::remove_stale(&base).map_err(|e| fail(&base, e))?;
        let dir = staging::partial_path(&base);
        staging::fresh_dir(&dir).map_err(|e| fail(&dir, e))?;
        let name = url.key().rsplit('/').next().filter(|n| !n.is_empty()).unwrap_or("output");
        Ok(Staged { url: url.clone(), product, replaces, local: dir.join(name), dir, keep: false })
    }

    /// The file of a resumable run, `local` ([`resumable_path`]): its directory is made if
    /// need be, and stays (with the journal and staged file a run that did not finish left in
    /// it) until the file is uploaded.
    pub(crate) fn resumable(url: &ObjectUrl, product: Product, local: PathBuf) -> Result<Staged> {
        let dir = local.parent().map(Path::to_path_buf).unwrap_or_default();
        let fail = |source| StoreError::Staging { url: url.to_string(), path: dir.clone(), source };
        std::fs::create_dir_all(&dir).map_err(fail)?;
        Ok(Staged { url: url.clone(), product, replaces: false, dir, local, keep: true })
    }

    /// Where the format's sink writes the file (its destination, as if local).
    pub(crate) fn local(&self) -> &Path {
        &self.local
    }

    /// Sends the finished file as a multipart upload with at most `in_flight` bytes of parts
    /// in flight (one part at least), then removes the temporary. Returns the bytes sent.
    #[cfg(feature = "s3")]
    pub(crate) fn upload(mut self, in_flight: u64) -> Result<u64> {
        let sent = self.send(in_flight)?;
        self.keep = false;
        Ok(sent)
    }

    #[cfg(feature = "s3")]
    fn send(&self, in_flight: u64) -> Result<u64> {
        if staged_dir(self.product) {
            return self.upload_dir(in_flight);
        }
        use std::io::Read;
        let fail = |source| StoreError::Staging { url: self.url.to_string(), path: self.local.clone(), source };
        let mut file = std::fs::File::open(&self.local).map_err(fail)?;
        let size = file.metadata().map_err(fail)?.len();
        let mut stream = super::stream::Stream::open(&self.url, super::stream::part_size(size), in_flight)?;
        let mut chunk = vec![0u8; 1 << 20];
        let mut at = 0u64;
        loop {
            let n = file.read(&mut chunk).map_err(fail)?;
            if n == 0 {
                break;
            }
            stream.append(at, &chunk[..n])?;
            at += n as u64;
        }
        Ok(stream.complete(at, &[])?)
    }

    /// A finished directory sent file by file under the URL's prefix, in parallel, with the
    /// rules of a directory layout (`crate::store`): the marker first, Zarr's metadata after
    /// every chunk and shard, everything deleted on failure.
    #[cfg(feature = "s3")]
    fn upload_dir(&self, in_flight: u64) -> Result<u64> {
        use super::Files;
        let fail =
            |path: &Path, source| StoreError::Staging { url: self.url.to_string(), path: path.to_path_buf(), source };
        let mut files = Vec::new();
        walk(&self.local, &self.local, &mut files).map_err(|e| fail(&self.local, e))?;
        files.sort();
        let is_metadata = |rel: &str| ZARR_METADATA.contains(&rel.rsplit('/').next().unwrap_or(rel));
        let (metadata, data): (Vec<_>, Vec<_>) = files.into_iter().partition(|(rel, _)| is_metadata(rel));
        let mut uploads = super::bucket::Uploads::start(&self.url, self.product.noun(), self.replaces, in_flight)?;
        let mut sent = 0u64;
        for (rel, path) in data {
            let bytes = std::fs::read(&path).map_err(|e| fail(&path, e))?;
            sent += bytes.len() as u64;
            if !uploads.put_new(&rel, &bytes)? {
                return Err(crate::error::TilerError::Internal(format!("{}: {rel} was uploaded twice", self.url)));
            }
        }
        let manifests = (metadata.into_iter())
            .map(|(rel, path)| std::fs::read(&path).map(|bytes| (rel, bytes)).map_err(|e| fail(&path, e)))
            .collect::<Result<Vec<_>, _>>()?;
        uploads.publish(manifests)?;
        Ok(sent)
    }

    #[cfg(not(feature = "s3"))]
    pub(crate) fn upload(self, _: u64) -> Result<u64> {
        Err(StoreError::NotBuilt { url: self.url.to_string() }.into())
    }

    /// Sends what `write` writes front to back (a file assembled from what is staged, such as
    /// a PMTiles archive from its spool) straight into the upload, as it is written, in parts
    /// sized for at most `bound` bytes, at most `in_flight` bytes in flight; `write` gets the
    /// URL to name in errors. Then removes the staging directory. Returns what `write`
    /// returned and the bytes sent.
    #[cfg(feature = "s3")]
    pub(crate) fn upload_written<T>(
        self,
        bound: u64,
        in_flight: u64,
        write: impl FnOnce(&mut dyn std::io::Write, &Path) -> Result<T>,
    ) -> Result<(T, u64)> {
        let mut stream = super::stream::Stream::open(&self.url, super::stream::part_size(bound), in_flight)?;
        let made = write(&mut stream, &self.url.to_path())?;
        let sent = stream.complete(stream.end(), &[])?;
        Ok((made, sent))
    }

    #[cfg(not(feature = "s3"))]
    pub(crate) fn upload_written<T>(
        self,
        _: u64,
        _: u64,
        _: impl FnOnce(&mut dyn std::io::Write, &Path) -> Result<T>,
    ) -> Result<(T, u64)> {
        Err(StoreError::NotBuilt { url: self.url.to_string() }.into())
    }
}

impl Drop for Staged {
    fn drop(&mut self) {
        if self.keep {
            return;
        }
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

/// Every regular file under `dir`, as its path relative to `base` ('/'-separated) and itself.
#[cfg(feature = "s3")]
fn walk(dir: &Path, base: &Path, out: &mut Vec<(String, PathBuf)>) -> std::io::Result<()> {
    for entry in std::fs::read_dir(dir)? {
        let entry = entry?;
        let path = entry.path();
        if entry.file_type()?.is_dir() {
            walk(&path, base, out)?;
        } else {
            let rel = path.strip_prefix(base).map_err(std::io::Error::other)?;
            let rel = rel.iter().map(|c| c.to_string_lossy()).collect::<Vec<_>>().join("/");
            out.push((rel, path));
        }
    }
    Ok(())
}
