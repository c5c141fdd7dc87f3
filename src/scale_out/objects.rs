//! A scale-out's packs at `s3://` (docs/scale-out.md): the shard packs `merge` reads, named or
//! listed under a prefix and downloaded whole to a local temporary ([`ShardFiles`]), and the
//! claim of a pack bound for a bucket ([`claim_pack`]); a pack there (a shard, or the merged
//! pack) is streamed as it is made ([`pack_output`]), as `split --pack` streams one.
//!
//! The shards are downloaded, not read in ranges: the pack reader maps a file and hands out
//! borrowed payloads, and the merge reads one page at a time in the one-machine order, which
//! goes from shard to shard; read through the bucket that would be one request per page.

use std::path::{Path, PathBuf};

use crate::error::{Result, TilerError};
use crate::output::{OutputError, Product};
use crate::store::ObjectUrl;
use crate::store::fetched::{Fetched, list_below};
use vortex_pack::PackOutput;

/// The shard packs a merge reads: each by the name it was given (a local path, or an `s3://`
/// URL, which errors and reports show) and the local file that holds it.
pub struct ShardFiles {
    names: Vec<PathBuf>,
    local: Vec<PathBuf>,
    /// The downloaded objects' directory, removed when this is dropped.
    _fetched: Option<Fetched>,
}

impl ShardFiles {
    /// The shards that `given` (merge's arguments) names, one path or URL each: a local path
    /// as it is, an `s3://` object as it is, and an `s3://` prefix written with a trailing `/`
    /// (`s3://bucket/parts/`) as every object directly below it, in the order of their keys.
    /// A prefix with no object is refused, naming it.
    pub fn list(given: &[PathBuf]) -> Result<Vec<PathBuf>> {
        let mut out = Vec::with_capacity(given.len());
        for path in given {
            let prefix = path.to_str().is_some_and(|t| t.ends_with('/'));
            match ObjectUrl::of_path(path) {
                Some(url) if prefix => {
                    let url = url?;
                    let below = list_below(&url)?;
                    if below.is_empty() {
                        return Err(TilerError::Options(format!(
                            "{url}/: no object directly below this prefix; `split --shard I/N --pack {url}/NAME` writes shard packs there"
                        )));
                    }
                    out.extend(below.iter().map(ObjectUrl::to_path));
                }
                Some(url) => out.push(url?.to_path()),
                None => out.push(path.clone()),
            }
        }
        Ok(out)
    }

    /// The shards `names` (as [`list`](Self::list) gives them): local files as they are,
    /// `s3://` objects downloaded, one after another, into a local temporary directory that
    /// lives as long as the value. A missing object is an error naming it.
    pub fn fetch(names: Vec<PathBuf>) -> Result<ShardFiles> {
        let urls: Vec<(usize, ObjectUrl)> = (names.iter().enumerate())
            .filter_map(|(i, n)| ObjectUrl::of_path(n).map(|u| u.map(|u| (i, u))))
            .collect::<std::result::Result<_, _>>()?;
        let mut local = names.clone();
        let fetched = match urls.is_empty() {
            true => None,
            false => {
                let fetched = Fetched::download(&urls.iter().map(|(_, u)| u.clone()).collect::<Vec<_>>())?;
                for ((i, _), file) in urls.iter().zip(fetched.files()) {
                    local[*i] = file.clone();
                }
                Some(fetched)
            }
        };
        Ok(ShardFiles { names, local, _fetched: fetched })
    }

    /// Local shard packs, named by their paths.
    pub fn local(paths: &[PathBuf]) -> ShardFiles {
        ShardFiles { names: paths.to_vec(), local: paths.to_vec(), _fetched: None }
    }

    /// The shards as given.
    pub fn names(&self) -> &[PathBuf] {
        &self.names
    }

    /// The local files that hold them, in the same order.
    pub fn files(&self) -> &[PathBuf] {
        &self.local
    }
}

/// Claims `dest`, an `s3://` URL, for a pack as `split --pack` does (an object that is not a
/// pack is replaced only with `force`), refusing it where it is one of `inputs`.
pub fn claim_pack(dest: &Path, inputs: &[PathBuf], force: bool) -> Result<()> {
    let url = bucket_url(dest)?;
    for input in inputs {
        if ObjectUrl::of_path(input).and_then(|u| u.ok()).is_some_and(|u| u == url) {
            return Err(OutputError::IsInput { path: dest.to_path_buf(), input: input.clone() }.into());
        }
    }
    crate::store::claim(&url, Product::Pack, force).map(drop)
}

/// The output of a pack at `dest`, an `s3://` URL already claimed: one multipart upload
/// streamed as the pack is made, in parts sized for `bound` bytes at most, [`IN_FLIGHT`] bytes
/// of them in flight. Nothing is visible until the pack is complete.
pub(crate) fn pack_output(dest: &Path, bound: u64) -> Result<Box<dyn PackOutput + Send>> {
    crate::store::stream_pack(&bucket_url(dest)?, bound, IN_FLIGHT)
}

/// Bytes of a scale-out pack's parts in flight: two parts of 8 MiB, which with the first part
/// (held to the end) and the one filling make 32 MiB besides `--max-memory` (a shard's budget
/// is its pyramid's, the same on every machine so that the merge can follow it).
const IN_FLIGHT: u64 = 16 << 20;

fn bucket_url(dest: &Path) -> Result<ObjectUrl> {
    match ObjectUrl::of_path(dest) {
        Some(url) => Ok(url?),
        None => Err(TilerError::Internal(format!("{} is not an s3:// URL", dest.display()))),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn local_shards_are_taken_as_given_and_an_input_is_not_an_output() {
        let given = [PathBuf::from("parts/a.vtpk"), PathBuf::from("b.vtpk")];
        assert_eq!(ShardFiles::list(&given).unwrap(), given);
        let files = ShardFiles::fetch(given.to_vec()).unwrap();
        assert_eq!((files.names(), files.files()), (&given[..], &given[..]));
        // Refused before anything is asked of the server.
        let url = PathBuf::from("s3://tiles/parts/a.vtpk");
        let Err(e) = claim_pack(&url, &[given[0].clone(), url.clone()], false) else { panic!("claimed") };
        assert!(e.to_string().contains("is the input"), "{e}");
    }
}
