//! Where an output's files go: a staging directory on local disk renamed into place when
//! complete (`local.rs`), or objects in an S3-compatible bucket (`bucket.rs`, feature `s3`),
//! named by an `s3://bucket/prefix` URL given where a path goes (`-o`, `--pack`, `--pmtiles`).
//!
//! The directory layouts' sink ([`crate::sink::DirSink`]) writes every file through `Files`
//! and does not know which of the two it writes to. A local directory is staged and renamed
//! into place ([`crate::output`]). An object store has no rename, so a bucket prefix is
//! written in place, and what a reader may see is governed thus (docs/object-storage.md):
//!
//! * A marker object, `PREFIX/.vortex-tiler`, is written before the first tile (saying
//!   `writing`) and rewritten after the last manifest (saying `complete`). It is how a later
//!   run recognises the prefix as ours, also after a killed run; a prefix that holds objects
//!   and no marker is refused, naming one of its keys: nothing the user owns is overwritten.
//! * The manifests (`info.json`, `.dzi`, IIIF `info.json`, TileJSON) are written only after
//!   every tile has been stored, so a viewer never finds a manifest whose tiles are missing.
//! * A run that fails (or is interrupted) deletes every object under the prefix, the marker
//!   last. A previous output of ours at the prefix is deleted before the new one starts:
//!   without a rename, keeping it until the new one is complete would need a second prefix
//!   and a server-side copy of every tile.
//! * A run holds the prefix by its marker: it rewrites it every 30 s while it writes (a
//!   heartbeat), each write conditional on the version it wrote last. A run that finds a
//!   marker saying `writing` watches it for four beats and is refused if it changes (another
//!   run is alive); it takes the prefix with one conditional write of the marker, so that of
//!   two runs starting together one is refused, before anything is deleted.
//!
//! A pack (a shard's and `merge`'s too) is sent as one multipart upload while it is made
//! (`stream.rs`), which the server makes visible only when the upload completes; a failure
//! aborts the upload. The other files
//! written as one object (PMTiles, `.ozx`, a TIFF) are staged to a local temporary and sent the
//! same way once complete (`staged.rs`). An OME-Zarr directory and a DICOM series are staged
//! too, then uploaded file by file with the directory layouts' rules.

pub(crate) mod fetched;
pub(crate) mod local;
pub(crate) mod staged;
mod url;

#[cfg(feature = "s3")]
pub(crate) mod bucket;
#[cfg(feature = "s3")]
mod profile;
#[cfg(feature = "s3")]
pub(crate) mod stream;

pub use crate::error::StoreError;
pub use url::ObjectUrl;

use std::collections::HashMap;
use std::path::PathBuf;

use crate::error::Result;
use crate::output::{Claim, Product};
use crate::resume::Identity;

/// Bytes of uploads in flight per output when the caller does not say: each request's body
/// is held until the server has it.
pub(crate) const UPLOAD_BYTES: u64 = 32 << 20;

/// The files of one directory output, written in any order from many threads, published
/// together. Dropped unpublished, it removes what it wrote.
pub(crate) trait Files: Send + Sync {
    /// Stores `bytes` as the file `name` ('/'-separated, relative to the output), never over
    /// one this run wrote: `false` if the name is taken.
    fn put_new(&self, name: &str, bytes: &[u8]) -> Result<bool>;
    /// The bytes of a file this run wrote.
    fn read(&self, name: &str) -> Result<Vec<u8>>;
    /// Waits for every file, writes `manifests` last, and makes the output visible as a
    /// complete one.
    fn publish(&mut self, manifests: Vec<(String, Vec<u8>)>) -> Result<()>;
}

/// Where [`Files`] for `claim` go: a staging directory beside a local destination, or the
/// prefix of an `s3://` URL with at most `in_flight` bytes of uploads at once.
pub(crate) fn files_for(claim: &Claim, in_flight: u64) -> Result<Box<dyn Files>> {
    match ObjectUrl::of_path(&claim.path) {
        None => Ok(Box::new(local::StagingDir::create(&claim.path)?)),
        Some(url) => open_prefix(&url?, claim, in_flight),
    }
}

#[cfg(feature = "s3")]
fn open_prefix(url: &ObjectUrl, claim: &Claim, in_flight: u64) -> Result<Box<dyn Files>> {
    let replaces = claim.replaces.is_some();
    Ok(Box::new(bucket::Uploads::start(url, claim.product.noun(), replaces, in_flight)?))
}

#[cfg(not(feature = "s3"))]
fn open_prefix(url: &ObjectUrl, _: &Claim, _: u64) -> Result<Box<dyn Files>> {
    Err(StoreError::NotBuilt { url: url.to_string() }.into())
}

/// What a resumable run (`--resume`, docs/resume.md) of identity `run` finds at the prefix
/// `url` of a directory output: its marker's URL (where the run is recorded), and, where the
/// marker names an interrupted resumable run of this identity, every object it left there (its
/// name under the prefix and its size). A marker naming another run is refused, naming what
/// differs, before anything is written or deleted.
#[cfg(feature = "s3")]
pub(crate) fn resumable_prefix(url: &ObjectUrl, run: &Identity) -> Result<(PathBuf, Option<HashMap<String, u64>>)> {
    let bucket = bucket::Bucket::open(url)?;
    let marker = PathBuf::from(format!("s3://{}/{}", url.bucket(), url.child(bucket::MARKER)));
    let Some(then) = bucket.resumable_run(url)? else { return Ok((marker, None)) };
    let differences = run.differences(&then);
    if !differences.is_empty() {
        return Err(crate::error::ResumeError::Mismatch { journal: marker, differences }.into());
    }
    let listed = bucket.list_sizes(url)?;
    Ok((marker, Some(listed)))
}

#[cfg(not(feature = "s3"))]
pub(crate) fn resumable_prefix(url: &ObjectUrl, _: &Identity) -> Result<(PathBuf, Option<HashMap<String, u64>>)> {
    Err(StoreError::NotBuilt { url: url.to_string() }.into())
}

/// [`Files`] of a resumable run of identity `run` at the `s3://` prefix `claim` names: with
/// `clear`, what the prefix holds is deleted first (nothing there is resumed); otherwise the
/// interrupted run's objects stay but `stale` (names under the prefix: a manifest, a tile not
/// whole), which go. The objects stay when the files are dropped unpublished.
#[cfg(feature = "s3")]
pub(crate) fn resuming_prefix(
    claim: &Claim,
    in_flight: u64,
    run: Identity,
    clear: bool,
    stale: &[String],
) -> Result<Box<dyn Files>> {
    let url = match ObjectUrl::of_path(&claim.path) {
        Some(url) => url?,
        None => return Err(crate::error::TilerError::Internal("a local output resumed as a bucket's".into())),
    };
    let clear = clear && claim.replaces.is_some();
    let uploads = bucket::Uploads::resuming(&url, claim.product.noun(), clear, in_flight, run)?;
    if !clear && !stale.is_empty() {
        uploads.delete(stale)?;
    }
    Ok(Box::new(uploads))
}

#[cfg(not(feature = "s3"))]
pub(crate) fn resuming_prefix(claim: &Claim, _: u64, _: Identity, _: bool, _: &[String]) -> Result<Box<dyn Files>> {
    Err(StoreError::NotBuilt { url: claim.path.display().to_string() }.into())
}

/// The output of a pack streamed to `url` as it is made ([`stream::Stream`]), in parts sized
/// for an object of at most `bound` bytes, at most `in_flight` bytes of them in flight.
#[cfg(feature = "s3")]
pub(crate) fn stream_pack(
    url: &ObjectUrl,
    bound: u64,
    in_flight: u64,
) -> Result<Box<dyn vortex_pack::PackOutput + Send>> {
    Ok(Box::new(stream::Stream::open(url, stream::part_size(bound), in_flight)?))
}

#[cfg(not(feature = "s3"))]
pub(crate) fn stream_pack(url: &ObjectUrl, _: u64, _: u64) -> Result<Box<dyn vortex_pack::PackOutput + Send>> {
    Err(StoreError::NotBuilt { url: url.to_string() }.into())
}

/// Checks that the object URL `url` may receive `product` (the rule of [`crate::output::claim`]
/// for a bucket): a prefix that is empty or holds a previous output of ours; an object that is
/// absent, one of ours, or (with `force`) anything else.
pub(crate) fn claim(url: &ObjectUrl, product: Product, force: bool) -> Result<Claim> {
    if !directory_product(product) && !staged::single_object(product) && !staged::staged_dir(product) {
        return Err(StoreError::Unsupported { url: url.to_string(), product: product.noun() }.into());
    }
    claim_in_bucket(url, product, force)
}

/// Whether `product` is written through [`Files`] (one object a file).
pub(crate) fn directory_product(product: Product) -> bool {
    matches!(product, Product::TileDir | Product::Viewer(_))
}

#[cfg(feature = "s3")]
fn claim_in_bucket(url: &ObjectUrl, product: Product, force: bool) -> Result<Claim> {
    let bucket = bucket::Bucket::open(url)?;
    let replaces = match directory_product(product) || staged::staged_dir(product) {
        true => bucket.claim_prefix(url, product.noun())?,
        false => bucket.claim_object(url, product, force)?,
    };
    Ok(Claim { path: url.to_path(), product, replaces })
}

#[cfg(not(feature = "s3"))]
fn claim_in_bucket(url: &ObjectUrl, _: Product, _: bool) -> Result<Claim> {
    Err(StoreError::NotBuilt { url: url.to_string() }.into())
}
