//! The pack protocol over byte ranges, apart from how the bytes travel: what to read first, how
//! the header, level table, metadata and index are checked ([`PackLayout`], the code
//! [`Pack::open`](vortex_pack::Pack::open) checks a local file with), the index held whole or in
//! blocks of [`INDEX_BLOCK`] entries (its CRC checked once every block is held), and each tile's
//! payload read and its CRC checked (a payload that fails is read again once, with its index
//! block). Written once as `async` code over a [`RangeRead`]: natively `HttpPack` drives it with
//! blocking `ureq` reads on the loader's threads (each future completes as soon as it is polled);
//! in the browser `WebPack` drives it with `fetch` on the page's event loop.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};

use vortex_pack::format::{ENTRY_LEN, LEVEL_LEN};
use vortex_pack::{Limits, PackError, PackLayout, Place, TileId, TileKind};

use super::pack::{absent_as, decode_stored, read_error};
use super::{ReadError, SourceTile, StoredRead, StoredTile};
use crate::page_cache::CacheFormat;

/// Index entries fetched together when the index is read in blocks: 6 KiB, less than a tile.
pub const INDEX_BLOCK: u64 = 256;

/// Bytes of one file, by range: the transport under [`RemotePack`]. Messages name the range; the
/// transport retries what is worth retrying before it answers, and its error's kind says whether
/// a later read may pass ([`ReadErrorKind::Io`](super::ReadErrorKind::Io)) or not.
#[allow(async_fn_in_trait)]
pub(crate) trait RangeRead {
    /// The first `n` bytes (fewer if the file is shorter) and the file's length.
    async fn first(&self, n: u64) -> Result<(Vec<u8>, u64), ReadError>;
    /// Bytes `start..end`.
    async fn read(&self, start: u64, end: u64) -> Result<Vec<u8>, ReadError>;
    /// A payload's bytes failed their CRC (for the transport's counters).
    fn corrupt(&self);
}

/// How a [`RemotePack`] reads its index.
#[derive(Clone, Copy, Debug)]
pub(crate) struct IndexPlan {
    /// The index is read whole at open when it is at most this many bytes, else in blocks.
    pub(crate) whole_up_to: u64,
    /// The index and the metadata are read as one range when at most this many bytes lie between.
    pub(crate) gap: u64,
}

/// A pack read through `R`: its checked head, and the index as far as it has been read.
pub(crate) struct RemotePack<R> {
    location: PathBuf,
    head: PackLayout,
    reader: R,
    plan: IndexPlan,
    /// The index by block number ([`INDEX_BLOCK`] entries each), as fetched.
    index: Mutex<HashMap<u64, Arc<[u8]>>>,
    /// The level table's bytes, for the index's CRC.
    raw_levels: Vec<u8>,
    metadata: Vec<u8>,
    /// Set once every index block has been fetched and their CRC did not match: every read fails.
    index_corrupt: Mutex<Option<String>>,
}

impl<R: RangeRead> RemotePack<R> {
    /// Opens the pack at `location` through `reader`: its header, level table and metadata (and
    /// its whole index, when small) are read and checked before this answers.
    pub(crate) async fn open(location: PathBuf, reader: R, plan: IndexPlan, limits: Limits) -> Result<Self, PackError> {
        let io = |e: ReadError| PackError::Io { path: location.clone(), source: std::io::Error::other(e.message) };
        // The first read: the header and, for most packs, the level table and metadata.
        let (first, file_len) = reader.first(2048).await.map_err(io)?;
        let h = PackLayout::read_header(&location, &first, file_len, limits)?;
        let section = async |offset: u64, len: u64| -> Result<Vec<u8>, PackError> {
            match first.get(offset as usize..).and_then(|rest| rest.get(..len as usize)) {
                Some(held) => Ok(held.to_vec()),
                None => reader.read(offset, offset + len).await.map_err(io),
            }
        };
        let raw_levels = section(h.levels_offset, h.description.level_count as u64 * LEVEL_LEN as u64).await?;
        // A local reader maps what a header claims; this one allocates it.
        PackLayout::check_metadata_len(&location, &h, limits)?;
        // The index (when read whole) and the metadata lie side by side: one read for both.
        let index_len = h.index_count * ENTRY_LEN as u64;
        let meta_end = h.meta_offset + u64::from(h.meta_len);
        let whole_index = index_len <= plan.whole_up_to;
        let (index, meta) = if whole_index && h.meta_offset - (h.index_offset + index_len) <= plan.gap {
            let mut both = section(h.index_offset, meta_end - h.index_offset).await?;
            let meta = both.split_off((h.meta_offset - h.index_offset) as usize);
            both.truncate(index_len as usize);
            (Some(both), meta)
        } else {
            let index = if whole_index { Some(section(h.index_offset, index_len).await?) } else { None };
            (index, section(h.meta_offset, u64::from(h.meta_len)).await?)
        };
        let head = PackLayout::new(&location, h, &raw_levels, &meta, limits)?;
        let mut blocks = HashMap::new();
        if let Some(index) = index {
            head.check_index(&raw_levels, &index)?;
            for (n, block) in index.chunks(INDEX_BLOCK as usize * ENTRY_LEN).enumerate() {
                blocks.insert(n as u64, Arc::from(block));
            }
        }
        Ok(RemotePack {
            location,
            head,
            reader,
            plan,
            index: Mutex::new(blocks),
            raw_levels,
            metadata: meta,
            index_corrupt: Mutex::default(),
        })
    }

    pub(crate) fn location(&self) -> &Path {
        &self.location
    }

    pub(crate) fn layout(&self) -> &PackLayout {
        &self.head
    }

    pub(crate) fn metadata(&self) -> &[u8] {
        &self.metadata
    }

    pub(crate) fn reader(&self) -> &R {
        &self.reader
    }

    /// The index entry at `position`, from its block (fetched if not held).
    async fn raw_entry(&self, position: u64) -> Result<[u8; ENTRY_LEN], ReadError> {
        if let Some(message) = lock(&self.index_corrupt).clone() {
            return Err(ReadError::corrupt(message));
        }
        let n = position / INDEX_BLOCK;
        let held = lock(&self.index).get(&n).cloned();
        let block = match held {
            Some(block) => block,
            None => {
                let h = self.head.header();
                let first = n * INDEX_BLOCK;
                let count = INDEX_BLOCK.min(h.index_count - first);
                let start = self.head.entry_offset(first);
                let bytes: Arc<[u8]> = self
                    .reader
                    .read(start, start + count * ENTRY_LEN as u64)
                    .await
                    .map_err(|e| e.context(format!("index block at byte {start}")))?
                    .into();
                self.keep_block(n, Arc::clone(&bytes))?;
                bytes
            }
        };
        let at = (position % INDEX_BLOCK) as usize * ENTRY_LEN;
        let mut entry = [0u8; ENTRY_LEN];
        entry.copy_from_slice(&block[at..at + ENTRY_LEN]);
        Ok(entry)
    }

    /// Keeps index block `n`; once every block is held, checks the index's CRC.
    fn keep_block(&self, n: u64, bytes: Arc<[u8]>) -> Result<(), ReadError> {
        let h = self.head.header();
        let mut blocks = lock(&self.index);
        blocks.insert(n, bytes);
        if blocks.len() as u64 != h.index_count.div_ceil(INDEX_BLOCK) {
            return Ok(());
        }
        let parts = (0..blocks.len() as u64).map(|n| blocks.get(&n).map_or(&[][..], |b| &b[..]));
        let checked = self.head.check_index_parts(&self.raw_levels, parts);
        drop(blocks);
        checked.map_err(|e| {
            let message = e.to_string();
            *lock(&self.index_corrupt) = Some(message.clone());
            ReadError::corrupt(message)
        })
    }

    /// Tile `id` as stored, its payload's CRC checked; a payload that fails is read again once,
    /// with its index block (the entry may be what was wrong), then reported as corrupt.
    pub(crate) async fn stored(&self, id: TileId) -> Result<StoredRead, ReadError> {
        let position = self.head.position(id).map_err(read_error)?;
        let mut attempt = 0;
        loop {
            let raw = self.raw_entry(position).await?;
            let (kind, offset, len, crc) = match self.head.place(id, position, &raw).map_err(read_error)? {
                Place::Absent => return Ok(StoredRead { tile: StoredTile::Absent, bytes_read: 0 }),
                Place::Constant(value) => {
                    let tile = StoredTile::Stored { kind: TileKind::Constant, bytes: Arc::from(value) };
                    return Ok(StoredRead { tile, bytes_read: 0 });
                }
                Place::Data { kind, offset, len, crc } => (kind, offset, len, crc),
            };
            // No stored tile is larger than its texels: a bigger one is refused, not allocated.
            let most = self.head.limits().max_decoded_bytes;
            if u64::from(len) > most {
                let message = format!(
                    "a payload of {len} bytes at byte {offset}, over the limit of {most} (Limits::max_decoded_bytes)"
                );
                return Err(ReadError::unsupported(message));
            }
            let bytes = self
                .reader
                .read(offset, offset + len as u64)
                .await
                .map_err(|e| e.context(format!("payload at byte {offset}")))?;
            let bytes_read = bytes.len() as u64;
            match self.head.check_payload(id, offset, crc, &bytes) {
                Ok(()) => {
                    let tile = StoredTile::Stored { kind, bytes: bytes.into() };
                    return Ok(StoredRead { tile, bytes_read });
                }
                Err(e) => {
                    self.reader.corrupt();
                    if attempt == 1 {
                        return Err(read_error(e).with_bytes_read(bytes_read));
                    }
                    attempt += 1;
                    // Unless the index was read whole and its CRC checked, its entry is suspect too.
                    if !self.index_whole() {
                        lock(&self.index).remove(&(position / INDEX_BLOCK));
                    }
                }
            }
        }
    }

    /// Whether the index was read whole at open (and its CRC checked before any entry was used).
    fn index_whole(&self) -> bool {
        self.head.header().index_count * ENTRY_LEN as u64 <= self.plan.whole_up_to
    }

    /// A tile as [`RemotePack::stored`] read it, made into `format` (an absent tile stays
    /// absent, for the loader to magnify its ancestor: RGBA8 only).
    pub(crate) fn texels(&self, read: StoredRead, format: CacheFormat) -> Result<SourceTile, ReadError> {
        let StoredRead { tile, bytes_read } = read;
        match tile {
            StoredTile::Absent if format == CacheFormat::Rgba8 => Ok(SourceTile::Absent),
            StoredTile::Absent => Err(absent_as(format)),
            StoredTile::Stored { kind, bytes } => decode_stored(&self.head, kind, &bytes, format)
                .map(|texels| SourceTile::Texels { texels, bytes_read })
                .map_err(|e| e.with_bytes_read(bytes_read)),
        }
    }

    /// One or three channels: no alpha stored.
    pub(crate) fn opaque(&self) -> bool {
        matches!(self.head.header().description.channels, 1 | 3)
    }

    /// Answered from the index when it was read whole (else not known without reading it all:
    /// such a pack is decoded and transcoded like any other).
    pub(crate) fn holds_only_bc7(&self) -> bool {
        let h = self.head.header();
        if !h.description.tile_size.is_multiple_of(4) || !self.index_whole() {
            return false;
        }
        let blocks = lock(&self.index);
        (0..h.index_count).all(|i| {
            blocks.get(&(i / INDEX_BLOCK)).is_some_and(|b| {
                let kind = b[(i % INDEX_BLOCK) as usize * ENTRY_LEN + 16];
                matches!(TileKind::from_u8(kind), Some(TileKind::Bc7 | TileKind::Constant))
            })
        })
    }
}

/// Why a pack is refused whose host answered the open's first `Range` request with the whole
/// file (200, `Range` ignored; `size`: its `Content-Length`, if given): every later read would
/// have to read the file from its start. One rule for the native and the browser reader; a
/// whole-file reply after the open (a proxy that sometimes ignores `Range`) is dropped unread and
/// the request tried again.
pub(crate) fn ignores_range(size: Option<&str>) -> String {
    let size = size.map_or(String::new(), |n| format!(" ({n} bytes)"));
    format!(
        "this host ignores Range requests: it answered 200 with the whole file{size}; a pack is read in byte \
         ranges, and reading every range from the start of a file that can be gigabytes is refused (nginx, \
         Apache, S3 and CDNs honour Range)"
    )
}

/// `bytes FIRST-LAST/TOTAL` (a `Content-Range` reply header) as (first, last, total).
pub(crate) fn parse_content_range(v: &str) -> Option<(u64, u64, u64)> {
    let (range, total) = v.trim().strip_prefix("bytes ")?.split_once('/')?;
    let (first, last) = range.split_once('-')?;
    let (first, last, total) = (first.trim().parse().ok()?, last.trim().parse().ok()?, total.trim().parse().ok()?);
    (first <= last && last < total).then_some((first, last, total))
}

/// Nothing that can panic runs under these locks, so a poisoned one still holds consistent data.
pub(crate) fn lock<T>(mutex: &Mutex<T>) -> MutexGuard<'_, T> {
    mutex.lock().unwrap_or_else(PoisonError::into_inner)
}
