//! `OmeZarrSink`: the pyramid as an OME-Zarr image (`split --layout ome-zarr`), each level
//! one array whose chunks are our pages (border 0).
//!
//! Tiles come from the encoders as raw texels (interleaved, little-endian); the sink reorders
//! them into the arrays' channel-first order and compresses them with zstd, on the encoder
//! threads. OME-Zarr 0.4 writes one file per chunk. 0.5 gathers `N x N` chunks into a shard
//! file: chunks are appended to a staging file of their shard as they come, in any order, and
//! once its last chunk is in the shard is written in row-major chunk order with its index at
//! the end, so that its bytes do not depend on which encoder thread finished first. No chunk
//! is held in memory beyond its own write, only the open shards' indexes (16 bytes a chunk).
//!
//! Everything is written into a staging directory beside the destination and renamed into
//! place when complete ([`crate::output::replace_dir`]). A `.ozx` (RFC-9 zipped OME-Zarr) is one
//! zip file written in one pass: the metadata first (known before the first tile), then each
//! shard as it completes, copied from its staging file into the zip (stored, not deflated: the
//! chunks are compressed already), with the RFC's zip comment.

mod meta;
mod plan;

use std::collections::{HashMap, HashSet};
use std::fs;
use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};

pub(crate) use meta::Spec;
pub use meta::{PixelSize, Plane, Version};
pub(crate) use plan::{OmeZarrPlan, OmeZarrRequested};

use crate::error::{Result, ShowPath, TilerError};
use crate::output::{Claim, Product, staging};
use crate::sink::TileSink;

/// Chunks per shard side of OME-Zarr 0.5 when not asked: with 256-texel chunks a shard is
/// 4096 x 4096 texels, so a 100-gigapixel image is about 8000 files (all levels), and a
/// shard's index is 4 KiB.
pub(crate) const DEFAULT_SHARD_CHUNKS: u32 = 16;
/// Chunk side when not asked: the common OME-Zarr chunk, a few hundred KiB raw.
pub(crate) const DEFAULT_CHUNK: u32 = 256;
/// The most chunks per shard side: a shard's index (16 bytes a chunk) stays within 1 MiB.
pub(crate) const MAX_SHARD_CHUNKS: u32 = 256;

/// A chunk slot of a shard's index that holds no chunk (the sharding codec's "empty").
const EMPTY: u64 = u64::MAX;
/// The zip's name inside the staging directory, and the folder of unfinished shards.
const ARCHIVE: &str = "archive.ozx";
const SHARDS: &str = "shards";

pub(crate) struct OmeZarrSink {
    spec: Spec,
    dest: PathBuf,
    staging: PathBuf,
    /// Whether the output is a `.ozx`, and its zip while being written.
    zipped: bool,
    zip: Mutex<Option<zip::ZipWriter<fs::File>>>,
    /// 0.5: the shards with chunks still to come.
    open: Mutex<HashMap<ShardKey, Arc<Mutex<Shard>>>>,
    made_dirs: Mutex<HashSet<PathBuf>>,
    bytes: AtomicU64,
    finished: AtomicBool,
}

/// A shard by its level, its channel (0 but for channels written one pass each) and its
/// column and row of shards.
type ShardKey = (u32, u32, u32, u32);

/// A shard being filled: where its chunks went, and how many are still to come.
struct Shard {
    /// Where it goes when complete (in the staging directory).
    path: PathBuf,
    /// Where its chunks are appended as they come.
    appended: PathBuf,
    end: u64,
    index: Vec<[u64; 2]>,
    missing: u64,
}

/// Whether `path` names a zipped OME-Zarr.
pub(crate) fn is_ozx(path: &Path) -> bool {
    path.extension().is_some_and(|e| e.eq_ignore_ascii_case("ozx"))
}

impl OmeZarrSink {
    /// Prepares to write `spec`'s image into the destination `claim` checked: a directory
    /// (`Product::OmeZarr`) or a `.ozx` file (`Product::Ozx`).
    pub fn create(claim: &Claim, spec: Spec) -> Result<OmeZarrSink> {
        let zipped = match claim.product {
            Product::OmeZarr => false,
            Product::Ozx => true,
            other => {
                return Err(TilerError::Options(format!("{} was claimed for {}", claim.path.shown(), other.noun())));
            }
        };
        if zipped && spec.version != Version::V05 {
            return Err(TilerError::Options(format!(
                "{}: a zipped OME-Zarr (.ozx, RFC-9) holds OME-Zarr 0.5; use --ome-zarr-version 0.5 or write a directory",
                claim.path.shown()
            )));
        }
        let dest = claim.path.clone();
        let staging = staging::partial_path(&dest);
        staging::fresh_dir(&staging).map_err(|e| TilerError::write(&staging, e))?;
        let mut sink = OmeZarrSink {
            spec,
            dest,
            staging,
            zipped,
            zip: Mutex::new(None),
            open: Mutex::new(HashMap::new()),
            made_dirs: Mutex::new(HashSet::new()),
            bytes: AtomicU64::new(0),
            finished: AtomicBool::new(false),
        };
        if zipped {
            // The metadata first: RFC-9 asks for every zarr.json ahead of the chunks.
            let path = sink.staging.join(ARCHIVE);
            let file = fs::File::create(&path).map_err(|e| TilerError::write(&path, e))?;
            let mut zip = zip::ZipWriter::new(file);
            for (name, bytes) in sink.spec.files() {
                add_entry(&mut zip, &path, &name, &mut bytes.as_slice())?;
            }
            sink.zip = Mutex::new(Some(zip));
        }
        Ok(sink)
    }

    /// Writes the metadata (a directory's; a zip has it already) and the zip's directory,
    /// then renames the output into place.
    pub fn finish(self) -> Result<()> {
        let open = lock(&self.open).len();
        if open > 0 {
            return Err(TilerError::Internal(format!("{open} shard(s) of {} never completed", self.dest.shown())));
        }
        match lock(&self.zip).take() {
            None => {
                for (name, bytes) in self.spec.files() {
                    let path = self.staging.join(&name);
                    self.make_parent(&path)?;
                    fs::write(&path, bytes).map_err(|e| TilerError::write(&path, e))?;
                }
                staging::replace_dir(&self.staging, &self.dest).map_err(|e| TilerError::write(&self.dest, e))?;
            }
            Some(mut zip) => {
                let path = self.staging.join(ARCHIVE);
                zip.set_comment(self.spec.zip_comment()).map_err(|e| zip_err(&path, e))?;
                let file = zip.finish().map_err(|e| zip_err(&path, e))?;
                file.sync_all().map_err(|e| TilerError::write(&path, e))?;
                fs::rename(&path, &self.dest).map_err(|e| TilerError::write(&self.dest, e))?;
                let _ = fs::remove_dir_all(&self.staging);
            }
        }
        self.finished.store(true, Ordering::Relaxed);
        Ok(())
    }

    /// The range of channel `c`'s samples, for its `omero` window: a directory's metadata is
    /// written at the end, so it shows the data's range; a `.ozx`'s went first, with the
    /// sample type's.
    pub fn set_window(&mut self, c: usize, window: Option<(f64, f64)>) {
        if let Some(plane) = self.spec.planes.as_mut().and_then(|p| p.get_mut(c)) {
            plane.window = window;
        }
    }

    /// Chunk bytes as the arrays hold them: channel planes, zstd-compressed.
    fn chunk(&self, raw: &[u8]) -> std::result::Result<Vec<u8>, String> {
        // Channels written one pass each come as grey tiles, one channel's chunk each.
        let channels = if self.spec.planes.is_some() { 1 } else { self.spec.channels() };
        let sample = self.spec.stored.depth.bytes();
        let side = self.spec.layout.tile_size as usize;
        if raw.len() != side * side * channels * sample {
            return Err(format!(
                "{} bytes where a {side}x{side} raw tile has {}",
                raw.len(),
                side * side * channels * sample
            ));
        }
        let planar = planes(raw, channels, sample);
        crate::codec::zstd_frame(&planar, self.spec.zstd_level)
    }

    fn make_parent(&self, path: &Path) -> Result<()> {
        let Some(dir) = path.parent().filter(|d| *d != self.staging) else { return Ok(()) };
        let mut made = lock(&self.made_dirs);
        if !made.contains(dir) {
            fs::create_dir_all(dir).map_err(|e| TilerError::write(dir, e))?;
            made.insert(dir.to_path_buf());
        }
        Ok(())
    }

    /// 0.4: one file per chunk.
    fn write_chunk_file(&self, lod: u32, c: u32, x: u32, y: u32, bytes: &[u8]) -> Result<()> {
        let path = self.staging.join(self.spec.chunk_key(lod, c, x, y));
        self.make_parent(&path)?;
        let mut file = match fs::File::create_new(&path) {
            Ok(file) => file,
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {
                return Err(TilerError::Encode { lod, x, y, message: "this chunk was written twice".into() });
            }
            Err(e) => return Err(TilerError::write(&path, e)),
        };
        file.write_all(bytes).map_err(|e| TilerError::write(&path, e))
    }

    /// 0.5: appends the chunk to its shard; the shard's last chunk closes it with its index.
    fn write_to_shard(&self, lod: u32, c: u32, x: u32, y: u32, bytes: &[u8]) -> Result<()> {
        let n = self.spec.shard_chunks;
        let key = (lod, c, x / n, y / n);
        let shard = {
            let mut open = lock(&self.open);
            match open.get(&key) {
                Some(shard) => Arc::clone(shard),
                None => {
                    let shard = Arc::new(Mutex::new(self.new_shard(key)?));
                    open.insert(key, Arc::clone(&shard));
                    shard
                }
            }
        };
        let mut s = lock(&shard);
        let slot = ((y % n) * n + (x % n)) as usize;
        if s.index[slot][0] != EMPTY {
            return Err(TilerError::Encode { lod, x, y, message: "this chunk was written twice".into() });
        }
        self.make_parent(&s.appended)?;
        let mut file = fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(&s.appended)
            .map_err(|e| TilerError::write(&s.appended, e))?;
        file.write_all(bytes).map_err(|e| TilerError::write(&s.appended, e))?;
        s.index[slot] = [s.end, bytes.len() as u64];
        s.end += bytes.len() as u64;
        s.missing -= 1;
        if s.missing > 0 {
            return Ok(());
        }
        drop(file);
        self.make_parent(&s.path)?;
        let mut shard = fs::File::create_new(&s.path).map_err(|e| TilerError::write(&s.path, e))?;
        let appended = fs::File::open(&s.appended).map_err(|e| TilerError::write(&s.appended, e))?;
        write_in_order(&appended, &s.index, &mut shard).map_err(|e| TilerError::write(&s.path, e))?;
        drop(shard);
        fs::remove_file(&s.appended).map_err(|e| TilerError::write(&s.appended, e))?;
        lock(&self.open).remove(&key);
        if self.zipped {
            let name = self.spec.chunk_key(lod, c, x, y);
            let mut shard_file = fs::File::open(&s.path).map_err(|e| TilerError::write(&s.path, e))?;
            let archive = self.staging.join(ARCHIVE);
            let mut zip = lock(&self.zip);
            let zip = zip.as_mut().ok_or_else(|| TilerError::Internal("the .ozx was finished early".into()))?;
            add_entry(zip, &archive, &name, &mut shard_file)?;
            fs::remove_file(&s.path).map_err(|e| TilerError::write(&s.path, e))?;
        }
        Ok(())
    }

    /// Shard `(lod, sx, sy)` before its first chunk: its file, an empty index, and how many
    /// chunks of the level's grid it covers (fewer at the level's right and bottom edges).
    fn new_shard(&self, (lod, c, sx, sy): ShardKey) -> Result<Shard> {
        let n = self.spec.shard_chunks;
        let (columns, rows) = self.spec.layout.grid(lod);
        let covered = |first: u32, count: u32| (count.saturating_sub(first)).min(n) as u64;
        let (path, appended) = match self.zipped {
            false => {
                let path = self.staging.join(self.spec.chunk_key(lod, c, sx * n, sy * n));
                let mut appended = path.clone().into_os_string();
                appended.push(".partial");
                (path, appended.into())
            }
            true => {
                let name = format!("{lod}-{c}-{sx}-{sy}");
                (self.staging.join(SHARDS).join(&name), self.staging.join(SHARDS).join(name + ".partial"))
            }
        };
        Ok(Shard {
            path,
            appended,
            end: 0,
            index: vec![[EMPTY, EMPTY]; (n * n) as usize],
            missing: covered(sx * n, columns) * covered(sy * n, rows),
        })
    }
}

impl OmeZarrSink {
    /// Chunk (`x`, `y`) of level `lod` of channel `c` (0 but for channels written one pass
    /// each), from a raw tile.
    fn write_plane(&self, c: u32, lod: u32, x: u32, y: u32, raw: &[u8]) -> Result<()> {
        let bytes = self.chunk(raw).map_err(|message| TilerError::Encode { lod, x, y, message })?;
        match self.spec.version {
            Version::V04 => self.write_chunk_file(lod, c, x, y, &bytes)?,
            Version::V05 => self.write_to_shard(lod, c, x, y, &bytes)?,
        }
        self.bytes.fetch_add(bytes.len() as u64, Ordering::Relaxed);
        Ok(())
    }

    /// The sink of channel `c`'s pass, for channels written one pass each.
    pub fn plane(&self, c: u32) -> PlaneSink<'_> {
        PlaneSink { sink: self, c }
    }
}

/// One channel's pass into an [`OmeZarrSink`] of channels written one pass each.
pub(crate) struct PlaneSink<'a> {
    sink: &'a OmeZarrSink,
    c: u32,
}

impl TileSink for PlaneSink<'_> {
    fn write_tile(&self, lod: u32, x: u32, y: u32, raw: &[u8]) -> Result<()> {
        self.sink.write_plane(self.c, lod, x, y, raw)
    }

    fn bytes_written(&self) -> u64 {
        self.sink.bytes_written()
    }
}

impl TileSink for OmeZarrSink {
    fn write_tile(&self, lod: u32, x: u32, y: u32, raw: &[u8]) -> Result<()> {
        self.write_plane(0, lod, x, y, raw)
    }

    fn bytes_written(&self) -> u64 {
        self.bytes.load(Ordering::Relaxed)
    }
}

impl Drop for OmeZarrSink {
    /// An unfinished output (an error, an interruption) leaves nothing behind.
    fn drop(&mut self) {
        if !self.finished.load(Ordering::Relaxed) {
            let _ = fs::remove_dir_all(&self.staging);
        }
    }
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
}

fn zip_err(path: &Path, e: zip::result::ZipError) -> TilerError {
    TilerError::write(path, std::io::Error::other(e.to_string()))
}

/// Adds one stored (uncompressed) entry; ZIP64 fields always, as RFC-9 recommends, so that
/// entries and offsets past 4 GiB need nothing else.
fn add_entry(zip: &mut zip::ZipWriter<fs::File>, path: &Path, name: &str, body: &mut dyn Read) -> Result<()> {
    let options =
        zip::write::SimpleFileOptions::default().compression_method(zip::CompressionMethod::Stored).large_file(true);
    zip.start_file(name, options).map_err(|e| zip_err(path, e))?;
    std::io::copy(body, zip).map_err(|e| TilerError::write(path, e))?;
    Ok(())
}

/// Interleaved texels as channel planes (Zarr's C order over `c, y, x`).
fn planes(raw: &[u8], channels: usize, sample: usize) -> std::borrow::Cow<'_, [u8]> {
    if channels == 1 {
        return std::borrow::Cow::Borrowed(raw);
    }
    let mut out = vec![0u8; raw.len()];
    match sample {
        1 => deinterleave::<1>(raw, channels, &mut out),
        2 => deinterleave::<2>(raw, channels, &mut out),
        4 => deinterleave::<4>(raw, channels, &mut out),
        _ => {
            let plane = raw.len() / channels;
            for (i, texel) in raw.chunks_exact(channels * sample).enumerate() {
                for (c, value) in texel.chunks_exact(sample).enumerate() {
                    out[c * plane + i * sample..][..sample].copy_from_slice(value);
                }
            }
        }
    }
    std::borrow::Cow::Owned(out)
}

/// [`planes`] for samples of `S` bytes, one plane at a time: each sample a copy of a known size
/// from a texel of a known size, not a call to `memcpy` (a call a byte made chunks cost more
/// than their zstd compression; issue 42). A chunk is small enough to stay in the cache for
/// the passes.
fn deinterleave<const S: usize>(raw: &[u8], channels: usize, out: &mut [u8]) {
    let plane = raw.len() / channels;
    for (c, plane) in out.chunks_exact_mut(plane).enumerate() {
        for (sample, texel) in plane.chunks_exact_mut(S).zip(raw.chunks_exact(channels * S)) {
            sample.copy_from_slice(&texel[c * S..][..S]);
        }
    }
}

/// The OME-Zarr image a label image belongs to, as its labels must match it.
#[derive(Debug)]
pub(crate) struct LabelParent {
    pub image: PathBuf,
    pub version: Version,
    /// Its levels, its full size (width, height) and its chunk side, as its metadata says.
    pub levels: u32,
    pub size: (u64, u64),
    pub chunk: u32,
}

/// The image `dest` is a label image of, where `dest` is `IMAGE/labels/NAME` and IMAGE holds
/// OME-Zarr metadata we can read.
pub(crate) fn label_parent(dest: &Path) -> Option<LabelParent> {
    let labels = dest.parent().filter(|p| p.file_name().is_some_and(|n| n == "labels"))?;
    let image = labels.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    let json =
        |name: &str| -> Option<serde_json::Value> { serde_json::from_slice(&fs::read(image.join(name)).ok()?).ok() };
    let (version, multiscales, level0) = match json("zarr.json") {
        Some(root) => (Version::V05, root.pointer("/attributes/ome/multiscales/0")?.clone(), json("0/zarr.json")?),
        None => (Version::V04, json(".zattrs")?.pointer("/multiscales/0")?.clone(), json("0/.zarray")?),
    };
    let levels = multiscales.get("datasets")?.as_array()?.len() as u32;
    let last_two = |v: &serde_json::Value| -> Option<(u64, u64)> {
        let a = v.as_array()?;
        Some((a.get(a.len().checked_sub(1)?)?.as_u64()?, a.get(a.len().checked_sub(2)?)?.as_u64()?))
    };
    let size = last_two(level0.get("shape")?)?;
    let chunk = match version {
        Version::V04 => level0.get("chunks"),
        // The inner chunks of a sharded array, else its chunk grid's.
        Version::V05 => level0
            .pointer("/codecs/0/configuration/chunk_shape")
            .or_else(|| level0.pointer("/chunk_grid/configuration/chunk_shape")),
    };
    let chunk = u32::try_from(last_two(chunk?)?.0).ok()?;
    Some(LabelParent { image: image.to_path_buf(), version, levels, size, chunk })
}

/// Adds `name` to the `labels` list of the group `labels` (made if absent), each file
/// replaced whole through a temporary.
pub(crate) fn register_label(labels: &Path, version: Version, name: &str) -> Result<()> {
    let attributes_file = labels.join(match version {
        Version::V04 => ".zattrs",
        Version::V05 => "zarr.json",
    });
    let mut doc: serde_json::Value = match fs::read(&attributes_file) {
        Ok(bytes) => serde_json::from_slice(&bytes).map_err(|e| TilerError::Info {
            path: attributes_file.clone(),
            field: "labels".into(),
            message: format!("is not JSON ({e})"),
        })?,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => match version {
            Version::V04 => serde_json::json!({ "labels": [] }),
            Version::V05 => serde_json::json!({
                "zarr_format": 3, "node_type": "group", "attributes": { "ome": { "version": "0.5", "labels": [] } }
            }),
        },
        Err(e) => return Err(TilerError::write(&attributes_file, e)),
    };
    let list = match version {
        Version::V04 => doc.get_mut("labels"),
        Version::V05 => doc.pointer_mut("/attributes/ome/labels"),
    };
    let Some(serde_json::Value::Array(list)) = list else {
        return Err(TilerError::Info {
            path: attributes_file,
            field: "labels".into(),
            message: "is not a list of label names".into(),
        });
    };
    if !list.iter().any(|n| n == name) {
        list.push(serde_json::json!(name));
    }
    let bytes = serde_json::to_vec_pretty(&doc).unwrap_or_default();
    staging::write_file(&attributes_file, &bytes).map_err(|e| TilerError::write(&attributes_file, e))?;
    if version == Version::V04 {
        let group = labels.join(".zgroup");
        staging::write_file(&group, br#"{ "zarr_format": 2 }"#).map_err(|e| TilerError::write(&group, e))?;
    }
    Ok(())
}

/// A shard's file: the chunks `index` places in `appended` ((offset, length) per chunk slot,
/// [`EMPTY`] for none), copied in slot order (row-major), then the index of where they are
/// now, little-endian, and its CRC-32C.
fn write_in_order(appended: &fs::File, index: &[[u64; 2]], shard: &mut fs::File) -> std::io::Result<()> {
    use std::io::{Seek, SeekFrom};
    let mut from = appended;
    let mut placed = Vec::with_capacity(index.len() * 16 + 4);
    let mut end = 0u64;
    for &[offset, length] in index {
        if offset == EMPTY {
            placed.extend_from_slice(&EMPTY.to_le_bytes());
            placed.extend_from_slice(&EMPTY.to_le_bytes());
            continue;
        }
        from.seek(SeekFrom::Start(offset))?;
        let copied = std::io::copy(&mut from.take(length), shard)?;
        if copied != length {
            return Err(std::io::Error::new(std::io::ErrorKind::UnexpectedEof, "a shard's staging file is short"));
        }
        placed.extend_from_slice(&end.to_le_bytes());
        placed.extend_from_slice(&length.to_le_bytes());
        end += length;
    }
    placed.extend_from_slice(&crc32c::crc32c(&placed).to_le_bytes());
    shard.write_all(&placed)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A shard's bytes are the same whatever order its chunks came in.
    #[test]
    fn a_shard_is_written_in_chunk_order() {
        let dir = tempfile::tempdir().unwrap();
        let chunks: [&[u8]; 3] = [b"first", b"second chunk", b"3"];
        // Slots 0, 1 and 3 of a 2 x 2 shard; slot 2 lies outside the array.
        let slots = [0usize, 1, 3];
        let shard_of = |order: &[usize], name: &str| {
            let appended = dir.path().join(format!("{name}.partial"));
            let mut index = vec![[EMPTY, EMPTY]; 4];
            let mut bytes = Vec::new();
            for &i in order {
                index[slots[i]] = [bytes.len() as u64, chunks[i].len() as u64];
                bytes.extend_from_slice(chunks[i]);
            }
            fs::write(&appended, &bytes).unwrap();
            let path = dir.path().join(name);
            let mut shard = fs::File::create_new(&path).unwrap();
            write_in_order(&fs::File::open(&appended).unwrap(), &index, &mut shard).unwrap();
            fs::read(path).unwrap()
        };
        let a = shard_of(&[2, 0, 1], "a");
        assert_eq!(a, shard_of(&[0, 1, 2], "b"));
        assert_eq!(a, shard_of(&[1, 2, 0], "c"));
        // Its layout, read back independently: the chunks in slot order, then 4 (offset,
        // length) pairs and the CRC-32C of those 64 bytes.
        let data = b"firstsecond chunk3";
        assert_eq!(&a[..data.len()], data);
        let pairs: Vec<u64> =
            a[data.len()..data.len() + 64].chunks(8).map(|b| u64::from_le_bytes(b.try_into().unwrap())).collect();
        assert_eq!(pairs, [0, 5, 5, 12, u64::MAX, u64::MAX, 17, 1]);
        let crc = u32::from_le_bytes(a[data.len() + 64..].try_into().unwrap());
        assert_eq!(crc, crc32c::crc32c(&a[data.len()..data.len() + 64]));
    }

    #[test]
    fn texels_become_channel_planes() {
        let raw = [1u8, 2, 3, 4, 5, 6];
        assert_eq!(&planes(&raw, 3, 1)[..], &[1, 4, 2, 5, 3, 6]);
        let raw16 = [1u8, 0, 2, 0, 3, 0, 4, 0];
        assert_eq!(&planes(&raw16, 2, 2)[..], &[1, 0, 3, 0, 2, 0, 4, 0]);
        let raw32: Vec<u8> = (0..24).collect();
        let expected: Vec<u8> =
            [0, 1, 2, 3, 12, 13, 14, 15, 4, 5, 6, 7, 16, 17, 18, 19, 8, 9, 10, 11, 20, 21, 22, 23].into();
        assert_eq!(&planes(&raw32, 3, 4)[..], &expected[..]);
    }
}
