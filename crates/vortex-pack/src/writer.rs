//! Writing a pack in one pass, tiles in any order, in memory proportional to the tile count
//! (24 bytes per tile for the index, 16 per distinct payload for deduplication), never to the
//! data.
//!
//! The bytes go to a [`PackOutput`]: payloads appended as they come, past the room kept for
//! the head (header, level table, index, metadata), which `finish` hands over last. A local
//! file ([`PackFile`]) is written under a temporary name beside the destination: zeroed
//! placeholders, then payloads; `finish` writes the tables, syncs, writes the header last (its
//! signature is the "complete" mark: an unfinished file starts with zeros), syncs again and
//! renames the file into place. Dropping an unfinished writer deletes the temporary file.

use std::collections::HashMap;
use std::fs;
use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};

use crate::error::{PackError, Result};
use crate::format::{self, Description, ENTRY_LEN, Entry, FNV_OFFSET, HEADER_LEN, Header, LEVEL_LEN, Level, TileKind};
use crate::limits::Limits;
use crate::output::{PackFile, PackOutput};
use crate::reader::TileId;

/// A tile handed to the writer.
#[derive(Clone, Copy, Debug)]
pub enum NewTile<'a> {
    /// No tile: a runtime falls back to the parent tile (what a tile never added is, too).
    Absent,
    /// One texel's samples (channels x sample bytes, little-endian).
    Constant(&'a [u8]),
    /// A payload of this kind, stored as given (identical payloads once).
    Data(TileKind, &'a [u8]),
}

/// Layout choices.
#[derive(Clone, Copy, Debug)]
pub struct WriteOptions {
    /// Start of the data section; default 4096 (a page).
    pub alignment: u32,
    /// Start of every payload; default 8.
    pub payload_alignment: u32,
}

impl Default for WriteOptions {
    fn default() -> Self {
        WriteOptions { alignment: 4096, payload_alignment: 8 }
    }
}

/// What a finished pack holds.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct WriteSummary {
    /// Tiles in the index.
    pub tiles: u64,
    /// Payloads stored (each distinct payload once).
    pub stored_payloads: u64,
    /// Tiles whose payload equalled one already stored, which they share.
    pub deduplicated: u64,
    /// One-colour tiles, held in their entry.
    pub constant: u64,
    /// Absent tiles (added as such, or never added).
    pub absent: u64,
    /// Bytes of stored payloads.
    pub payload_bytes: u64,
    /// The file's length in bytes.
    pub file_bytes: u64,
    /// The header's content hash.
    pub content_hash: u64,
}

/// Writes a pack in one pass: tiles in any order ([`PackWriter::add`]), then
/// [`PackWriter::finish`], which writes the index and header and completes the output (a
/// local file is renamed into place). Dropped unfinished, its output leaves no pack (a local
/// file's temporary is removed unless kept for a later [`PackWriter::resume`]): a pack is
/// whole or absent.
pub struct PackWriter<O: PackOutput = PackFile> {
    out: O,
    description: Description,
    levels: Vec<Level>,
    metadata: Vec<u8>,
    options: WriteOptions,
    entries: Vec<Entry>,
    written: Vec<bool>,
    /// (crc, len) of every stored payload -> offsets holding those bytes.
    stored: HashMap<(u32, u32), Vec<u64>>,
    data_offset: u64,
    end: u64,
    /// Required-feature bits of the kinds stored so far.
    required_features: u64,
    summary: WriteSummary,
}

/// A writer's layout before its output exists: what [`PackWriter::plan`] checks and allocates.
struct Plan {
    description: Description,
    levels: Vec<Level>,
    metadata: Vec<u8>,
    options: WriteOptions,
    entries: Vec<Entry>,
    written: Vec<bool>,
    data_offset: u64,
}

impl Plan {
    /// The writer of this plan into `out`.
    fn into_writer<O: PackOutput>(self, out: O) -> PackWriter<O> {
        let Plan { description, levels, metadata, options, entries, written, data_offset } = self;
        PackWriter {
            out,
            description,
            levels,
            metadata,
            options,
            entries,
            written,
            stored: HashMap::new(),
            data_offset,
            end: data_offset,
            required_features: description.required_features(),
            summary: WriteSummary::default(),
        }
    }
}

impl PackWriter<PackFile> {
    /// Starts `dest` (written as [`temporary_path`] beside it until `finish`). `levels` are the
    /// level table's rows, LOD 0 first; the writer places their entries one after another in
    /// the index (each level's `first_entry`, whatever it said). A pack that readers with the
    /// default [`Limits`] would refuse (a tile side or tile count over them) is refused here
    /// with [`PackError::LimitExceeded`], before its index is allocated.
    pub fn create(
        dest: impl AsRef<Path>,
        description: Description,
        levels: Vec<Level>,
        metadata: &[u8],
        options: WriteOptions,
    ) -> Result<PackWriter> {
        let dest = dest.as_ref();
        let plan = plan(dest, description, levels, metadata, options)?;
        let mut out = PackFile::create(dest, temporary_path(dest)).map_err(|e| io(dest, e))?;
        // Placeholders up to the data section: zeros, so that an unfinished file has no signature.
        out.truncate(plan.data_offset).map_err(|e| io(out.name(), e))?;
        Ok(plan.into_writer(out))
    }
}

impl<O: PackOutput> PackWriter<O> {
    /// Starts a pack written to `out` (which must be empty), with the arguments of
    /// [`PackWriter::create`]: a destination of the caller's own, such as an upload sent as
    /// it is made. Errors name [`PackOutput::name`].
    pub fn with_output(
        out: O,
        description: Description,
        levels: Vec<Level>,
        metadata: &[u8],
        options: WriteOptions,
    ) -> Result<PackWriter<O>> {
        Ok(plan(out.name(), description, levels, metadata, options)?.into_writer(out))
    }

    /// This writer with its output boxed, so that writers of different outputs are one type.
    pub fn boxed(self) -> PackWriter<Box<dyn PackOutput + Send>>
    where
        O: Send + 'static,
    {
        let PackWriter {
            out,
            description,
            levels,
            metadata,
            options,
            entries,
            written,
            stored,
            data_offset,
            end,
            required_features,
            summary,
        } = self;
        let out: Box<dyn PackOutput + Send> = Box::new(out);
        PackWriter {
            out,
            description,
            levels,
            metadata,
            options,
            entries,
            written,
            stored,
            data_offset,
            end,
            required_features,
            summary,
        }
    }
}

/// What [`PackWriter::create`], [`PackWriter::resume`] and [`PackWriter::with_output`] check
/// and allocate: the layout of a pack named `dest` (in errors), its index all absent.
fn plan(
    dest: &Path,
    description: Description,
    mut levels: Vec<Level>,
    metadata: &[u8],
    options: WriteOptions,
) -> Result<Plan> {
    let usage = PackError::Usage;
    if levels.len() != description.level_count as usize {
        return Err(usage(format!("{} levels given, description says {}", levels.len(), description.level_count)));
    }
    for a in [options.alignment, options.payload_alignment] {
        if !a.is_power_of_two() || a < 8 {
            return Err(usage(format!("alignment {a} is not a power of two >= 8")));
        }
    }
    // What the reader refuses, refused here (a texel over 8 bytes would not fit an entry).
    let d = &description;
    if !d.texel_ok() {
        return Err(usage(format!("{} is not a texel format", d.texel_name())));
    }
    if d.tile_size == 0 || d.border.checked_mul(2).is_none_or(|b| b >= d.tile_size) || d.width == 0 || d.height == 0 {
        return Err(usage(format!(
            "image {}x{}, tile {} border {} is not a valid texture",
            d.width, d.height, d.tile_size, d.border
        )));
    }
    if d.level_count == 0 || d.level_count > 32 {
        return Err(usage(format!("{} levels (1 to 32)", d.level_count)));
    }
    let meta_len = u32::try_from(metadata.len()).map_err(|_| usage("metadata over 4 GiB".into()))?;
    let mut count = 0u64;
    for l in &mut levels {
        if l.tiles_w == 0 || l.tiles_h == 0 {
            return Err(usage(format!("a level of {}x{} tiles: every level holds tiles", l.tiles_w, l.tiles_h)));
        }
        l.first_entry = count;
        count = count.checked_add(l.tiles_w as u64 * l.tiles_h as u64).ok_or_else(|| usage("too many tiles".into()))?;
    }
    let caps = Limits::default();
    let over = |field: &str, offset: usize, value: u64, limit: u64, cap| PackError::LimitExceeded {
        path: dest.to_path_buf(),
        field: field.into(),
        offset: offset as u64,
        value,
        limit,
        cap,
    };
    if d.tile_size > caps.max_tile_size {
        let (value, limit) = (d.tile_size.into(), caps.max_tile_size.into());
        return Err(over("tile_size", format::at::TILE_SIZE, value, limit, "max_tile_size"));
    }
    if count > caps.max_tiles {
        return Err(over("index_count", format::at::INDEX_COUNT, count, caps.max_tiles, "max_tiles"));
    }
    let count_usize = usize::try_from(count)
        .ok()
        .filter(|n| n.checked_mul(ENTRY_LEN).is_some())
        .ok_or_else(|| usage("too many tiles".into()))?;
    let out_of_memory = |e: std::collections::TryReserveError| {
        let message = format!("cannot allocate the index of {count} tiles: {e}");
        io(dest, std::io::Error::new(std::io::ErrorKind::OutOfMemory, message))
    };
    let mut entries = Vec::new();
    entries.try_reserve_exact(count_usize).map_err(out_of_memory)?;
    entries.resize(count_usize, Entry::ABSENT);
    let mut written = Vec::new();
    written.try_reserve_exact(count_usize).map_err(out_of_memory)?;
    written.resize(count_usize, false);
    let levels_offset = HEADER_LEN as u64;
    let index_offset = levels_offset + levels.len() as u64 * LEVEL_LEN as u64;
    let meta_offset = index_offset + count * ENTRY_LEN as u64;
    let data_offset = (meta_offset + meta_len as u64).next_multiple_of(options.alignment as u64);
    Ok(Plan { description, levels, metadata: metadata.to_vec(), options, entries, written, data_offset })
}

impl PackWriter<PackFile> {
    /// Goes on with the temporary file `from` that a writer of the same pack left unfinished
    /// (a run killed outright, or one that kept its file: [`keep_on_drop`](Self::keep_on_drop)),
    /// with `kept`: the tiles that writer added, in the order it added them, with the entries
    /// it gave them ([`entry`](Self::entry)). The arguments before `from` must be those the
    /// first writer was created with. The file is renamed to this process's
    /// [`temporary_path`]; each payload is read back and checked against its entry's length
    /// and CRC-32C, in order, and the first that fails (or lies outside the file, or breaks the
    /// order in which a writer appends) ends what is kept: the file is cut there, so that the
    /// tiles added next are appended exactly where the first writer would have appended them.
    /// Returns the writer and how many of `kept` it holds (a prefix).
    pub fn resume(
        dest: impl AsRef<Path>,
        description: Description,
        levels: Vec<Level>,
        metadata: &[u8],
        options: WriteOptions,
        from: &Path,
        kept: &[(TileId, Entry)],
    ) -> Result<(PackWriter, usize)> {
        let dest = dest.as_ref();
        let plan = plan(dest, description, levels, metadata, options)?;
        let tmp = temporary_path(dest);
        if from != tmp {
            fs::rename(from, &tmp).map_err(|e| {
                io(dest, std::io::Error::new(e.kind(), format!("cannot take over {}: {e}", from.display())))
            })?;
        }
        let out = PackFile::reopen(dest, tmp.clone()).map_err(|e| io(&tmp, e))?;
        let len = out.file().metadata().map_err(|e| io(&tmp, e))?.len();
        let mut w = plan.into_writer(out);
        let mut held = 0;
        let mut buf = Vec::new();
        for (id, entry) in kept {
            if !w.take_kept(*id, entry, len, &mut buf)? {
                break;
            }
            held += 1;
        }
        // What lies past the last payload kept goes: the next is appended where it would have been.
        let end = w.end.max(w.data_offset);
        w.out.truncate(end).map_err(|e| io(&tmp, e))?;
        Ok((w, held))
    }

    /// Takes one tile a previous writer added, as [`resume`](Self::resume) describes: `false`
    /// (nothing taken) where it cannot be kept.
    fn take_kept(&mut self, id: TileId, entry: &Entry, len: u64, buf: &mut Vec<u8>) -> Result<bool> {
        let Ok(position) = self.position(id) else { return Ok(false) };
        if self.written[position] {
            return Ok(false);
        }
        let Some(kind) = TileKind::from_u8(entry.kind) else { return Ok(false) };
        if kind == TileKind::Constant {
            self.summary.constant += 1;
        } else if kind == TileKind::Absent {
            self.summary.absent += 1;
        } else {
            let (offset, n) = (entry.offset_or_value, entry.len as u64);
            let Some(stop) = offset.checked_add(n) else { return Ok(false) };
            if n == 0 || offset < self.data_offset || stop > len || self.description.refuses(kind).is_some() {
                return Ok(false);
            }
            let known = self.stored.get(&(entry.crc, entry.len)).is_some_and(|o| o.contains(&offset));
            if known {
                self.summary.deduplicated += 1;
            } else {
                // A new payload lies where a writer appends the next: at the end, aligned.
                if offset != self.end.next_multiple_of(self.options.payload_alignment as u64) {
                    return Ok(false);
                }
                buf.resize(entry.len as usize, 0);
                self.out.file().read_exact_at(buf, offset).map_err(|e| io(self.out.name(), e))?;
                if crc32c::crc32c(buf) != entry.crc {
                    return Ok(false);
                }
                self.end = stop;
                self.stored.entry((entry.crc, entry.len)).or_default().push(offset);
                self.summary.stored_payloads += 1;
                self.summary.payload_bytes += n;
            }
            self.required_features |= kind.required_feature();
        }
        self.written[position] = true;
        self.entries[position] = *entry;
        self.summary.tiles += 1;
        Ok(true)
    }

    /// Has an unfinished writer leave its temporary file when dropped, for a later
    /// [`resume`](Self::resume), instead of removing it.
    pub fn keep_on_drop(&mut self) {
        self.out.keep_on_drop();
    }
}

impl<O: PackOutput> PackWriter<O> {
    /// The entry tile `id` was given when added (`None`: not added yet), for a caller that
    /// records what was written so that [`resume`](Self::resume) can go on after a crash.
    pub fn entry(&self, id: TileId) -> Option<Entry> {
        let position = self.position(id).ok()?;
        self.written[position].then(|| self.entries[position])
    }

    /// Adds the tile at `id`; each tile at most once. Identical payloads are stored once.
    pub fn add(&mut self, id: TileId, tile: NewTile) -> Result<()> {
        let position = self.position(id)?;
        if self.written[position] {
            return Err(PackError::Usage(format!("tile (lod {}, x {}, y {}) written twice", id.lod, id.x, id.y)));
        }
        let texel = self.description.channels as usize * self.description.sample_bytes as usize;
        let entry = match tile {
            NewTile::Absent => {
                self.summary.absent += 1;
                Entry::ABSENT
            }
            NewTile::Constant(value) => {
                if value.len() != texel {
                    return Err(PackError::Usage(format!("a constant texel has {texel} bytes, not {}", value.len())));
                }
                if texel > 8 {
                    return Err(PackError::Usage(format!("a constant texel of {texel} bytes does not fit an entry")));
                }
                let mut v = [0u8; 8];
                v[..texel].copy_from_slice(value);
                self.summary.constant += 1;
                Entry { offset_or_value: u64::from_le_bytes(v), len: 0, crc: 0, kind: TileKind::Constant as u8 }
            }
            NewTile::Data(kind, bytes) => {
                if !kind.has_payload() {
                    return Err(PackError::Usage(format!("{} tiles have no payload", kind.name())));
                }
                if bytes.is_empty() {
                    return Err(PackError::Usage(format!("an empty {} payload", kind.name())));
                }
                let raw_len = self.description.raw_tile_len().unwrap_or(u64::MAX);
                if kind == TileKind::Raw && bytes.len() as u64 != raw_len {
                    return Err(PackError::Usage(format!("a raw tile has {raw_len} bytes, not {}", bytes.len())));
                }
                if let Some(why) = self.description.refuses(kind) {
                    return Err(PackError::Usage(why));
                }
                if let Some(n) = self.description.block_tile_len(kind).filter(|n| *n != bytes.len() as u64) {
                    return Err(PackError::Usage(format!("a {} tile has {n} bytes, not {}", kind.name(), bytes.len())));
                }
                self.required_features |= kind.required_feature();
                let len = u32::try_from(bytes.len()).map_err(|_| PackError::Usage("a tile over 4 GiB".into()))?;
                let crc = crc32c::crc32c(bytes);
                let offset = match self.find_stored(crc, bytes)? {
                    Some(offset) => {
                        self.summary.deduplicated += 1;
                        offset
                    }
                    None => self.append(crc, bytes)?,
                };
                Entry { offset_or_value: offset, len, crc, kind: kind as u8 }
            }
        };
        // Only now: a tile refused above may be added again.
        self.written[position] = true;
        self.entries[position] = entry;
        self.summary.tiles += 1;
        Ok(())
    }

    fn position(&self, id: TileId) -> Result<usize> {
        let l = self.levels.get(id.lod as usize).filter(|l| id.x < l.tiles_w && id.y < l.tiles_h).ok_or_else(|| {
            PackError::Usage(format!("tile (lod {}, x {}, y {}) is outside the pack's grid", id.lod, id.x, id.y))
        })?;
        Ok((l.first_entry + id.y as u64 * l.tiles_w as u64 + id.x as u64) as usize)
    }

    /// An offset already holding exactly `bytes` (compared byte for byte, never by hash alone).
    /// An output that can no longer tell (its bytes sent away) gets the payload again.
    fn find_stored(&mut self, crc: u32, bytes: &[u8]) -> Result<Option<u64>> {
        let Some(offsets) = self.stored.get(&(crc, bytes.len() as u32)) else { return Ok(None) };
        for &offset in offsets {
            if self.out.holds(offset, bytes).map_err(|e| io(self.out.name(), e))? {
                return Ok(Some(offset));
            }
        }
        Ok(None)
    }

    fn append(&mut self, crc: u32, bytes: &[u8]) -> Result<u64> {
        let offset = self.end.next_multiple_of(self.options.payload_alignment as u64);
        self.out.append(offset, bytes).map_err(|e| io(self.out.name(), e))?;
        self.end = offset + bytes.len() as u64;
        self.stored.entry((crc, bytes.len() as u32)).or_default().push(offset);
        self.summary.stored_payloads += 1;
        self.summary.payload_bytes += bytes.len() as u64;
        Ok(offset)
    }

    /// Replaces the metadata given to [`create`](Self::create), which is written at the end,
    /// so that a writer may describe what it learnt while storing the tiles (a shard's root
    /// sums). It may not be longer: the data section starts after the room given at `create`
    /// (the rest of the room stays zero padding).
    pub fn set_metadata(&mut self, metadata: Vec<u8>) -> Result<()> {
        if metadata.len() > self.metadata.len() {
            return Err(PackError::Usage(format!(
                "metadata of {} bytes is longer than the {} bytes of room left for it",
                metadata.len(),
                self.metadata.len()
            )));
        }
        self.metadata = metadata;
        Ok(())
    }

    /// Payload bytes stored so far (shared tiles counted once).
    pub fn payload_bytes(&self) -> u64 {
        self.summary.payload_bytes
    }

    /// Hands the head (header, tables, padding) to the output and completes it: a local file
    /// gets its tables, a sync, its header and another sync, and is renamed into place. Tiles
    /// never added are absent.
    pub fn finish(mut self) -> Result<WriteSummary> {
        let meta_end = HEADER_LEN as u64
            + (self.levels.len() * LEVEL_LEN) as u64
            + (self.entries.len() * ENTRY_LEN) as u64
            + self.metadata.len() as u64;
        self.reclaim_room(meta_end).map_err(|e| io(self.out.name(), e))?;
        let levels: Vec<u8> = self.levels.iter().flat_map(|l| l.encode()).collect();
        let index: Vec<u8> = self.entries.iter().flat_map(|e| e.encode()).collect();
        let levels_offset = HEADER_LEN as u64;
        let index_offset = levels_offset + levels.len() as u64;
        let meta_offset = index_offset + index.len() as u64;
        let content_hash = format::fnv1a(format::fnv1a(FNV_OFFSET, &self.metadata), &index);
        let header = Header {
            major: format::MAJOR,
            minor: format::MINOR,
            required_features: self.required_features,
            optional_features: 0,
            file_len: self.end,
            content_hash,
            description: self.description,
            alignment: self.options.alignment,
            payload_alignment: self.options.payload_alignment,
            levels_offset,
            index_offset,
            index_count: self.entries.len() as u64,
            index_crc: crc32c::crc32c_append(crc32c::crc32c(&levels), &index),
            meta_offset,
            meta_len: self.metadata.len() as u32,
            meta_crc: crc32c::crc32c(&self.metadata),
            data_offset: self.data_offset,
            data_len: self.end - self.data_offset,
        };
        // The head: everything before the data section, the padding after the metadata zeros.
        let mut head = header.encode().to_vec();
        head.extend_from_slice(&levels);
        drop(levels);
        head.extend_from_slice(&index);
        drop(index);
        head.extend_from_slice(&self.metadata);
        head.resize(self.data_offset as usize, 0);
        self.out.complete(self.end, &head).map_err(|e| io(self.out.name(), e))?;
        self.summary.file_bytes = self.end;
        self.summary.content_hash = content_hash;
        self.summary.absent += self.written.iter().filter(|w| !**w).count() as u64;
        self.summary.tiles = self.entries.len() as u64;
        Ok(self.summary)
    }

    /// Moves the data section down over the room that shorter metadata left unused
    /// ([`set_metadata`](Self::set_metadata)), in whole units of both alignments so that every
    /// offset stays aligned, when that room is more than an eighth of the data (the copy costs
    /// at most eight times the bytes it saves) and the output can move what it holds. Less, or
    /// an output that cannot, leaves zero padding (most file systems store it as a hole).
    fn reclaim_room(&mut self, meta_end: u64) -> std::io::Result<()> {
        let unit = self.options.alignment.max(self.options.payload_alignment) as u64;
        let wanted = meta_end.next_multiple_of(self.options.alignment as u64);
        let shift = self.data_offset.saturating_sub(wanted) / unit * unit;
        if shift == 0 || shift * 8 < self.end - self.data_offset {
            return Ok(());
        }
        let len = self.end - self.data_offset;
        if !self.out.move_down(self.data_offset, self.data_offset - shift, len)? {
            return Ok(());
        }
        for e in &mut self.entries {
            if TileKind::from_u8(e.kind).is_some_and(TileKind::has_payload) {
                e.offset_or_value -= shift;
            }
        }
        self.data_offset -= shift;
        self.end -= shift;
        Ok(())
    }
}

/// Where [`PackWriter::create`] writes `dest` until `finish` renames it over `dest`:
/// `.NAME.tmp-PID` in the same directory, NAME being `dest`'s file name and PID this process's
/// id. A killed writer leaves it behind; [`temporary_pid`] recognises it, to clean up after.
pub fn temporary_path(dest: &Path) -> PathBuf {
    let name = dest.file_name().map_or_else(|| "pack".into(), |n| n.to_string_lossy());
    dest.with_file_name(format!(".{name}.tmp-{}", std::process::id()))
}

/// The id of the process that was writing a pack named `dest_name` (a file name, no directory)
/// as `file_name`, if `file_name` is such a temporary ([`temporary_path`]): `.NAME.tmp-PID`.
pub fn temporary_pid(dest_name: &str, file_name: &str) -> Option<u32> {
    let digits = file_name.strip_prefix('.')?.strip_prefix(dest_name)?.strip_prefix(".tmp-")?;
    if digits.is_empty() || !digits.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    digits.parse().ok()
}

fn io(path: &Path, source: std::io::Error) -> PackError {
    PackError::Io { path: path.to_path_buf(), source }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_temporary_name_is_parsed_as_it_is_made() {
        let tmp = temporary_path(Path::new("/some/dir/world.vtpk"));
        assert_eq!(tmp.parent(), Some(Path::new("/some/dir")));
        let name = tmp.file_name().and_then(|n| n.to_str()).unwrap_or_default();
        assert_eq!(temporary_pid("world.vtpk", name), Some(std::process::id()));
        assert_eq!(temporary_pid("other.vtpk", name), None);
        assert_eq!(temporary_pid("p", ".p.tmp-123"), Some(123));
        for not in [".p.tmp-", ".p.tmp-12x", ".p.partial-12", "p.tmp-12", ".p.tmp-12.old", ".pq.tmp-1"] {
            assert_eq!(temporary_pid("p", not), None, "{not}");
        }
    }
}
