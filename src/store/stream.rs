//! [`Stream`]: one object written as a multipart upload while it is made, parts sent as they
//! fill, with no local copy: a pack ([`vortex_pack::PackOutput`]) whose head is known only at
//! the end, and any file written front to back (a PMTiles archive as it is assembled, a staged
//! file read back).
//!
//! The first part is held in memory to the end: it starts with the head, which a pack writes
//! last (the header, the level table and the index before the data). Every later part is sent
//! as soon as it fills, at most `parts` in flight; the first goes last, then the upload is
//! completed, which is when the object appears. A file that fits the first part is one PUT.
//! Any failure, and a stream dropped before it completes, aborts the upload: nothing is left,
//! visible or not (a process killed outright leaves an incomplete upload, which a bucket's
//! lifecycle rule removes: docs/object-storage.md).
//!
//! S3 takes parts of at least 5 MiB ([`MIN_PART`]: 8) but for the last, at most 5 GiB each and
//! 10,000 of them ([`MAX_PARTS`]); the caller chooses the part size from a bound on the
//! object's size ([`part_size`]). Every part but the first and last has that size; the first
//! is larger only where the head is (a pack of some hundred thousand tiles or more).

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use futures::FutureExt;
use futures::stream::{FuturesUnordered, StreamExt};
use object_store::multipart::PartId;
use object_store::path::Path as Key;
use object_store::{MultipartId, ObjectStoreExt, PutPayload};
use tokio::task::JoinHandle;

use super::bucket::{Bucket, reply};
use super::{ObjectUrl, StoreError};

/// The smallest part sent (but for the last): S3's minimum is 5 MiB.
pub(crate) const MIN_PART: u64 = 8 << 20;
/// The most parts of one multipart upload S3 takes.
pub(crate) const MAX_PARTS: u64 = 10_000;
/// The largest part S3 takes.
const MAX_PART: u64 = 5 << 30;

/// The part size for an object of at most `bound` bytes: [`MIN_PART`], or more where
/// [`MAX_PARTS`] parts of it would not hold `bound`.
pub(crate) fn part_size(bound: u64) -> u64 {
    MIN_PART.max(bound.div_ceil(MAX_PARTS - 1))
}

/// A part being sent: its index (0 is the first) and its id once stored.
type Sending = JoinHandle<Result<(usize, PartId), String>>;

/// One object written as it is made; see the module's description.
pub(crate) struct Stream {
    bucket: Bucket,
    url: ObjectUrl,
    key: Key,
    /// The size of every part but the first and the last.
    part: u64,
    /// Parts in flight at most.
    parts: usize,
    /// The first part's extent: from the first byte appended (where the head ends) to its end,
    /// fixed by the first append; the bytes of it appended so far.
    first_start: Option<u64>,
    first_end: u64,
    first: Vec<u8>,
    /// The part being filled: where it starts, its bytes so far, its index.
    filling_start: u64,
    filling: Vec<u8>,
    index: usize,
    /// The multipart upload, created when the second part fills.
    upload: Option<MultipartId>,
    sending: FuturesUnordered<Sending>,
    sent: Vec<Option<PartId>>,
    /// Where the next append may start (the end of what was appended).
    end: u64,
    done: bool,
    /// The path errors name: the URL.
    name: PathBuf,
    /// A pack's payloads, by offset: the first 16 bytes of each one's SHA-256, which stand for
    /// its bytes once they are sent away ([`vortex_pack::PackOutput::holds`]).
    payloads: HashMap<u64, Digest>,
}

/// The first 16 bytes of a payload's SHA-256: two different payloads among a billion agree
/// here with odds of about 10^-21.
type Digest = [u8; 16];

fn digest(bytes: &[u8]) -> Digest {
    let sha = ring::digest::digest(&ring::digest::SHA256, bytes);
    let mut d = Digest::default();
    d.copy_from_slice(&sha.as_ref()[..16]);
    d
}

impl Stream {
    /// A stream to `url` in parts of `part` bytes (at least [`MIN_PART`] for S3), at most
    /// `in_flight` bytes of parts sent at once (one part at least). Sends nothing yet.
    pub(crate) fn open(url: &ObjectUrl, part: u64, in_flight: u64) -> Result<Stream, StoreError> {
        Stream::with_bucket(Bucket::open(url)?, url, part, in_flight)
    }

    /// [`open`](Self::open) through `bucket`, the client of `url`'s bucket.
    pub(crate) fn with_bucket(
        bucket: Bucket,
        url: &ObjectUrl,
        part: u64,
        in_flight: u64,
    ) -> Result<Stream, StoreError> {
        if part == 0 || part > MAX_PART {
            let message = format!("parts of {part} bytes: S3 takes 1 to {MAX_PART}");
            return Err(bucket.failed(url.key(), "UploadPart", message));
        }
        Ok(Stream {
            key: bucket.key(url.key())?,
            bucket,
            url: url.clone(),
            part,
            parts: usize::try_from((in_flight / part).max(1)).unwrap_or(usize::MAX),
            first_start: None,
            first_end: 0,
            first: Vec::new(),
            filling_start: 0,
            filling: Vec::new(),
            index: 1,
            upload: None,
            sending: FuturesUnordered::new(),
            sent: Vec::new(),
            end: 0,
            done: false,
            name: url.to_path(),
            payloads: HashMap::new(),
        })
    }

    /// Stores `bytes` at `offset`, at or past the end of what was appended (the bytes between
    /// are zeros), sending each part that fills.
    pub(crate) fn append(&mut self, offset: u64, mut bytes: &[u8]) -> Result<(), StoreError> {
        if offset < self.end {
            let message = format!("bytes appended at {offset}, before the end {}", self.end);
            return Err(self.bucket.failed(self.url.key(), "UploadPart", message));
        }
        if self.first_start.is_none() {
            // The first part: from byte 0 through the head (not held: it comes at the end) to
            // a whole part, or the head alone.
            self.first_start = Some(offset);
            (self.first_end, self.end) = (offset.max(self.part), offset);
            self.filling_start = self.first_end;
        }
        let mut at = self.end;
        let zeros = offset - self.end;
        // The zeros, then the bytes, each into the part they fall in.
        let mut gap = zeros;
        while gap > 0 || !bytes.is_empty() {
            let (buffer, room) = if at < self.first_end {
                (&mut self.first, self.first_end - at)
            } else {
                if self.filling.len() as u64 == self.part {
                    self.send_filling()?;
                }
                (&mut self.filling, self.filling_start + self.part - at)
            };
            if gap > 0 {
                let n = gap.min(room);
                buffer.resize(buffer.len() + n as usize, 0);
                (gap, at) = (gap - n, at + n);
            } else {
                let n = (bytes.len() as u64).min(room) as usize;
                buffer.extend_from_slice(&bytes[..n]);
                (bytes, at) = (&bytes[n..], at + n as u64);
            }
        }
        self.end = at;
        Ok(())
    }

    /// Whether the bytes at `offset` are `bytes`: `false` where they differ, or where some of
    /// them were sent away already.
    pub(crate) fn holds(&self, offset: u64, bytes: &[u8]) -> bool {
        let stop = offset + bytes.len() as u64;
        let first = self.first_start.unwrap_or(0);
        let mut covered = 0u64;
        for (start, held) in [(first, &self.first), (self.filling_start, &self.filling)] {
            let (lo, hi) = (offset.max(start), stop.min(start + held.len() as u64));
            if lo >= hi {
                continue;
            }
            let theirs = &held[(lo - start) as usize..(hi - start) as usize];
            if theirs != &bytes[(lo - offset) as usize..(hi - offset) as usize] {
                return false;
            }
            covered += hi - lo;
        }
        covered == bytes.len() as u64
    }

    /// Sends the full part being filled, once fewer than `parts` are in flight, and starts the
    /// next. The upload is created with the first part sent.
    fn send_filling(&mut self) -> Result<(), StoreError> {
        let payload = PutPayload::from(std::mem::take(&mut self.filling));
        self.filling_start += self.part;
        self.send(self.index, payload)?;
        self.index += 1;
        Ok(())
    }

    /// Sends part `index`, waiting while `parts` are in flight; a part that failed fails this.
    fn send(&mut self, index: usize, payload: PutPayload) -> Result<(), StoreError> {
        if index as u64 >= MAX_PARTS {
            let message =
                format!("more than {MAX_PARTS} parts of {} bytes: the object outgrew its planned size", self.part);
            return Err(self.bucket.failed(self.url.key(), "UploadPart", message));
        }
        self.settle(self.parts.saturating_sub(1))?;
        let id = match &self.upload {
            Some(id) => id.clone(),
            None => {
                let create = self.bucket.store.create_multipart(&self.key);
                let id = (self.bucket.runtime.block_on(create))
                    .map_err(|e| self.bucket.failed(self.url.key(), "CreateMultipartUpload", reply(&e)))?;
                self.upload = Some(id.clone());
                id
            }
        };
        let (store, key) = (Arc::clone(&self.bucket.store), self.key.clone());
        self.sending.push(self.bucket.runtime.spawn(async move {
            let sent = store.put_part(&key, &id, index, payload).await;
            sent.map(|part| (index, part)).map_err(|e| reply(&e))
        }));
        Ok(())
    }

    /// Waits until at most `left` parts are in flight, taking the ids of those stored; the
    /// first failure, if any.
    fn settle(&mut self, left: usize) -> Result<(), StoreError> {
        // Those already done first, without waiting.
        while let Some(Some(done)) = self.sending.next().now_or_never() {
            self.take(done)?;
        }
        while self.sending.len() > left {
            match self.bucket.runtime.block_on(self.sending.next()) {
                Some(done) => self.take(done)?,
                None => break,
            }
        }
        Ok(())
    }

    fn take(
        &mut self,
        done: Result<Result<(usize, PartId), String>, tokio::task::JoinError>,
    ) -> Result<(), StoreError> {
        let (index, part) = done
            .map_err(|e| e.to_string())
            .and_then(|r| r)
            .map_err(|message| self.bucket.failed(self.url.key(), "UploadPart", message))?;
        if self.sent.len() <= index {
            self.sent.resize(index + 1, None);
        }
        self.sent[index] = Some(part);
        Ok(())
    }

    /// Moves the data down from `from` to `to` where all of it is still held in the first part
    /// (nothing sent yet): the first part then starts at `to`. `false` (nothing moved) where
    /// some was sent, or where `from` is not where the data starts.
    fn move_down(&mut self, from: u64, to: u64) -> bool {
        let held_whole = self.upload.is_none() && self.filling.is_empty();
        if !held_whole || self.first_start != Some(from) || to >= from {
            return false;
        }
        let shift = from - to;
        self.first_start = Some(to);
        self.end -= shift;
        self.payloads = std::mem::take(&mut self.payloads).into_iter().map(|(at, d)| (at - shift, d)).collect();
        true
    }

    /// The end of what was appended: the length of a file written front to back.
    pub(crate) fn end(&self) -> u64 {
        self.end
    }

    /// Completes the object: `len` bytes (zeros after what was appended), the first of which
    /// are `head` (nothing appended may lie within it). The first part goes last; then the
    /// upload is completed, and the object appears. Returns the bytes sent.
    pub(crate) fn complete(&mut self, len: u64, head: &[u8]) -> Result<u64, StoreError> {
        let fail = |s: &Stream, message: String| s.bucket.failed(s.url.key(), "CompleteMultipartUpload", message);
        let start = self.first_start.unwrap_or(len);
        if (head.len() as u64) > start || len < self.end {
            let message = format!("a head of {} bytes before data at {start}, {len} bytes of {}", head.len(), self.end);
            return Err(fail(self, message));
        }
        self.append(len, &[])?;
        let first_len = head.len() as u64 + (start - head.len() as u64) + self.first.len() as u64;
        if first_len > MAX_PART {
            return Err(fail(self, format!("a first part of {first_len} bytes, more than S3's {MAX_PART}")));
        }
        let mut first = Vec::new();
        first.try_reserve_exact(first_len as usize).map_err(|e| fail(self, format!("{first_len} bytes: {e}")))?;
        first.extend_from_slice(head);
        first.resize((start as usize).max(head.len()), 0);
        first.append(&mut self.first);
        if self.upload.is_none() && first_len + self.filling.len() as u64 <= MAX_PART {
            // What one PUT takes: sent so.
            first.append(&mut self.filling);
            let put = self.bucket.store.put(&self.key, PutPayload::from(first));
            let put = self.bucket.runtime.block_on(put);
            put.map_err(|e| self.bucket.failed(self.url.key(), "PUT", reply(&e)))?;
            self.done = true;
            return Ok(len);
        }
        if !self.filling.is_empty() {
            let last = PutPayload::from(std::mem::take(&mut self.filling));
            self.send(self.index, last)?;
        }
        self.send(0, PutPayload::from(first))?;
        self.settle(0)?;
        let parts = std::mem::take(&mut self.sent).into_iter().collect::<Option<Vec<PartId>>>();
        let parts = parts.ok_or_else(|| fail(self, "a part was not sent".into()))?;
        let id = self.upload.clone().unwrap_or_default();
        let complete = self.bucket.store.complete_multipart(&self.key, &id, parts);
        self.bucket.runtime.block_on(complete).map_err(|e| fail(self, reply(&e)))?;
        self.done = true;
        Ok(len)
    }
}

/// A file written front to back into the stream (a PMTiles archive as it is assembled):
/// each write appended at the end; [`complete`](Stream::complete) with the length written.
impl std::io::Write for Stream {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.append(self.end, buf).map_err(io)?;
        Ok(buf.len())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

/// A pack streamed to the bucket as it is written ([`vortex_pack::PackWriter::with_output`]).
impl vortex_pack::PackOutput for Stream {
    fn name(&self) -> &Path {
        &self.name
    }

    fn append(&mut self, offset: u64, bytes: &[u8]) -> std::io::Result<()> {
        Stream::append(self, offset, bytes).map_err(io)?;
        self.payloads.insert(offset, digest(bytes));
        Ok(())
    }

    /// Byte for byte while the payload at `offset` is held, by its digest once it is sent
    /// away: a pack made at `s3://` shares the payloads a local run shares.
    fn holds(&mut self, offset: u64, bytes: &[u8]) -> std::io::Result<bool> {
        Ok(match Stream::holds(self, offset, bytes) {
            true => true,
            false => self.payloads.get(&offset) == Some(&digest(bytes)),
        })
    }

    /// Only while everything appended is still held (a pack smaller than a part): a shard
    /// pack's unused metadata room is then given back as in a local file.
    fn move_down(&mut self, from: u64, to: u64, len: u64) -> std::io::Result<bool> {
        Ok(from + len == self.end && Stream::move_down(self, from, to))
    }

    fn complete(&mut self, len: u64, head: &[u8]) -> std::io::Result<()> {
        Stream::complete(self, len, head).map(drop).map_err(io)
    }
}

/// A store error as the pack writer's I/O error, which names the object itself.
fn io(e: StoreError) -> std::io::Error {
    match e {
        StoreError::Request { op, message, .. } => std::io::Error::other(format!("{op} failed: {message}")),
        e => std::io::Error::other(e.to_string()),
    }
}

/// An unfinished stream aborts its upload: what was sent is discarded.
impl Drop for Stream {
    fn drop(&mut self) {
        if self.done {
            return;
        }
        while !self.sending.is_empty() {
            let _ = self.settle(0);
        }
        if let Some(id) = self.upload.take() {
            let abort = self.bucket.store.abort_multipart(&self.key, &id);
            if let Err(e) = self.bucket.runtime.block_on(abort) {
                // Nothing to return the error to: the run has failed already, with its own.
                eprintln!("warning: aborting the upload of {}: {} (a lifecycle rule removes it)", self.url, reply(&e));
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::store::bucket::Store;
    use object_store::ObjectStoreExt;
    use object_store::memory::InMemory;
    use vortex_pack::{Description, Level, NewTile, Pack, PackWriter, TileId, TileKind, WriteOptions};

    /// A stream to `s3://tiles/KEY` in a store held in memory, in parts of `part` bytes, two in
    /// flight; the store, to read back.
    fn stream(key: &str, part: u64) -> (Stream, Arc<InMemory>) {
        let memory = Arc::new(InMemory::new());
        let url = ObjectUrl::parse(&format!("s3://tiles/{key}")).unwrap();
        let bucket = Bucket::with_store(Arc::clone(&memory) as Arc<dyn Store>, &url).unwrap();
        (Stream::with_bucket(bucket, &url, part, 2 * part).unwrap(), memory)
    }

    /// The object at `key`, if any.
    fn object(memory: &InMemory, key: &str) -> Option<Vec<u8>> {
        let runtime = tokio::runtime::Builder::new_current_thread().build().unwrap();
        runtime.block_on(async {
            let got = memory.get(&Key::from(key)).await.ok()?;
            Some(got.bytes().await.unwrap().to_vec())
        })
    }

    /// A pack of 64-texel raw RGBA tiles, every one different but two alike near each other
    /// and two alike far apart, written by `writer` (with `metadata` in place of the room
    /// given at its start, if any).
    fn pack<O: vortex_pack::PackOutput>(
        mut writer: PackWriter<O>,
        metadata: Option<&[u8]>,
    ) -> vortex_pack::WriteSummary {
        for y in 0..4u32 {
            for x in 0..4u32 {
                let seed = match (x, y) {
                    (1, 0) => 0,         // as (0, 0), still in memory
                    (3, 3) => 1 + 4 + 1, // as (1, 1), sent long before
                    _ => x + 4 * y,
                };
                let tile: Vec<u8> = (0..64 * 64 * 4u32).map(|i| (i.wrapping_mul(seed * 2 + 1) >> 3) as u8).collect();
                writer.add(TileId { lod: 0, x, y }, NewTile::Data(TileKind::Raw, &tile)).unwrap();
            }
        }
        writer.add(TileId { lod: 2, x: 0, y: 0 }, NewTile::Constant(&[1, 2, 3, 4])).unwrap();
        if let Some(m) = metadata {
            writer.set_metadata(m.to_vec()).unwrap();
        }
        writer.finish().unwrap()
    }

    fn description() -> (Description, Vec<Level>) {
        let d = Description {
            width: 256,
            height: 256,
            tile_size: 64,
            border: 0,
            level_count: 3,
            channels: 4,
            sample_bytes: 1,
            sample_format: 0,
        };
        (d, vec![Level::new(4, 4, 256, 256), Level::new(2, 2, 128, 128), Level::new(1, 1, 64, 64)])
    }

    #[test]
    fn a_pack_of_many_parts_equals_the_local_file() {
        let dir = tempfile::tempdir().unwrap();
        let local = dir.path().join("p.vtpk");
        let (d, levels) = description();
        let options = WriteOptions::default();
        let on_disk = pack(PackWriter::create(&local, d, levels.clone(), b"{}", options).unwrap(), None);
        // Parts of 20000 bytes: some of a tile each, the first held to the end.
        let (out, memory) = stream("p.vtpk", 20_000);
        let streamed = pack(PackWriter::with_output(out, d, levels, b"{}", options).unwrap(), None);
        let bytes = object(&memory, "p.vtpk").expect("the pack was not stored");
        assert!(bytes.len() > 10 * 20_000, "{} bytes: not many parts", bytes.len());
        // The duplicate still in memory is shared, and the one sent away too (by its digest).
        assert_eq!((on_disk.deduplicated, streamed.deduplicated), (2, 2));
        assert!(bytes == std::fs::read(&local).unwrap(), "the streamed pack is not the local one");
        let pack = vortex_pack::Pack::from_bytes("s3://tiles/p.vtpk", bytes).unwrap();
        assert!(vortex_pack::verify(&pack, Default::default()).is_ok());
    }

    /// A shard pack's metadata room, mostly unused at the end (more than an eighth of the
    /// data), is given back where the whole pack is still held, as a local file gives it back:
    /// the same bytes. Once parts are sent it stays as zeros: other bytes, the same tiles.
    #[test]
    fn unused_metadata_room_is_given_back_while_the_pack_is_held() {
        let dir = tempfile::tempdir().unwrap();
        let local = dir.path().join("p.vtpk");
        let (d, levels) = description();
        let (options, room, used) = (WriteOptions::default(), vec![b' '; 100_000], Some(&b"{}"[..]));
        pack(PackWriter::create(&local, d, levels.clone(), &room, options).unwrap(), used);
        let local = std::fs::read(&local).unwrap();
        let (out, memory) = stream("held.vtpk", 1 << 20);
        pack(PackWriter::with_output(out, d, levels.clone(), &room, options).unwrap(), used);
        assert!(object(&memory, "held.vtpk").unwrap() == local, "the held pack differs from the local one");
        let (out, memory) = stream("sent.vtpk", 20_000);
        pack(PackWriter::with_output(out, d, levels, &room, options).unwrap(), used);
        let sent = object(&memory, "sent.vtpk").unwrap();
        assert!(
            sent.len() > local.len() + 90_000,
            "{} bytes, {} locally: the room was not kept",
            sent.len(),
            local.len()
        );
        let (sent, local) = (Pack::from_bytes("sent", sent).unwrap(), Pack::from_bytes("local", local).unwrap());
        for (x, y) in (0..4).flat_map(|y| (0..4).map(move |x| (x, y))) {
            let id = vortex_pack::TileId::new(0, x, y);
            assert_eq!(sent.tile(id).unwrap(), local.tile(id).unwrap(), "tile ({x}, {y})");
        }
    }

    #[test]
    fn a_file_smaller_than_a_part_is_one_put_and_an_unfinished_one_leaves_nothing() {
        let (mut out, memory) = stream("small", 1 << 20);
        out.append(0, b"hello ").unwrap();
        out.append(10, b"world").unwrap();
        assert!(out.holds(10, b"world") && !out.holds(10, b"World"));
        assert_eq!(out.complete(16, &[]).unwrap(), 16);
        assert_eq!(object(&memory, "small").unwrap(), b"hello \0\0\0\0world\0");
        assert!(out.upload.is_none(), "a multipart upload for one part");

        let (mut out, memory) = stream("cut", 1000);
        out.append(100, &[7; 5000]).unwrap();
        assert!(out.upload.is_some(), "the parts that filled were not sent");
        assert!(out.holds(900, &[7; 100]), "the first part is held");
        assert!(!out.holds(1100, &[7; 100]), "a part sent away is not");
        drop(out);
        assert_eq!(object(&memory, "cut"), None, "an unfinished stream left an object");
    }

    #[test]
    fn parts_grow_with_the_object_s_bound() {
        assert_eq!(part_size(0), MIN_PART);
        assert_eq!(part_size(MIN_PART * (MAX_PARTS - 1)), MIN_PART);
        let big = 400u64 << 30;
        assert!(part_size(big) * (MAX_PARTS - 1) >= big && part_size(big) > MIN_PART);
    }
}
