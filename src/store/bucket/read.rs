//! Reading a bucket back: the objects directly below a prefix, and an object downloaded whole
//! into a local file, streamed (`merge`'s shard packs at `s3://`, which the pack reader maps).

use std::io::Write;
use std::path::Path;

use futures::StreamExt;
use object_store::{ObjectStore, ObjectStoreExt};

use super::{Bucket, reply};
use crate::store::{ObjectUrl, StoreError};

impl Bucket {
    /// Whether `url` is in this client's bucket.
    pub(crate) fn holds(&self, url: &ObjectUrl) -> bool {
        self.name == url.bucket()
    }

    /// The objects directly below the prefix `url` (none under a deeper `/`), sorted by key:
    /// each as its URL and size.
    pub(crate) fn list_below(&self, url: &ObjectUrl) -> Result<Vec<(ObjectUrl, u64)>, StoreError> {
        let prefix = if url.key().is_empty() { None } else { Some(self.key(url.key())?) };
        let listed = self.runtime.block_on(self.store.list_with_delimiter(prefix.as_ref()));
        let listed = listed.map_err(|e| self.failed(url.key(), "LIST", reply(&e)))?;
        let mut objects = listed
            .objects
            .into_iter()
            .map(|meta| Ok((ObjectUrl::parse(&format!("s3://{}/{}", self.name, meta.location))?, meta.size)))
            .collect::<Result<Vec<_>, StoreError>>()?;
        objects.sort_by(|a, b| a.0.key().cmp(b.0.key()));
        Ok(objects)
    }

    /// Downloads the object `url` into `local`, a new file, a chunk at a time as the server
    /// sends them; returns its size. A missing object is an error naming it.
    pub(crate) fn download(&self, url: &ObjectUrl, local: &Path) -> Result<u64, StoreError> {
        let key = url.key();
        let location = self.key(key)?;
        let staging = |source| StoreError::Staging { url: url.to_string(), path: local.to_path_buf(), source };
        let mut file = std::fs::OpenOptions::new().write(true).create_new(true).open(local).map_err(staging)?;
        self.runtime.block_on(async {
            let got = match self.store.get(&location).await {
                Ok(got) => got,
                Err(object_store::Error::NotFound { .. }) => return Err(self.failed(key, "GET", "no such object")),
                Err(e) => return Err(self.failed(key, "GET", reply(&e))),
            };
            let size = got.meta.size;
            let mut chunks = got.into_stream();
            let mut written = 0u64;
            while let Some(chunk) = chunks.next().await {
                let chunk = chunk.map_err(|e| self.failed(key, "GET", reply(&e)))?;
                written += chunk.len() as u64;
                if written > size {
                    return Err(self.failed(key, "GET", format!("more than the {size} bytes the server announced")));
                }
                file.write_all(&chunk).map_err(staging)?;
            }
            if written != size {
                return Err(self.failed(key, "GET", format!("{written} bytes of the {size} the server announced")));
            }
            Ok(size)
        })
    }
}
