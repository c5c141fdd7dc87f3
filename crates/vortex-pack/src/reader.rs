//! Opening a pack and finding tiles in it: O(1) per tile, no allocation per tile, no copy.
//!
//! A pack is a memory-mapped file ([`Pack::open`]), a file read into memory
//! ([`Pack::open_read`]) or bytes the caller holds ([`Pack::from_bytes`]); one function checks
//! all three the same way before it returns (magic, version, header checksum, the header's
//! claims against [`Limits`], file length, that every section lies inside the file, the level
//! table, the metadata checksum, and the level table's and index's checksum), so that nothing a
//! reader trusts (where each tile is, and what kind it is) comes from bytes no checksum has
//! vouched for. Tile payloads are checked on request ([`Pack::tile_checked`]), or all at once by
//! `verify`, which alone opens a pack whose index fails its checksum
//! ([`Pack::open_to_verify`]), to report that with everything else wrong.
//!
//! The memory-map contract: the file must not be truncated or rewritten while a `Pack` maps it
//! (a truncated mapping faults on access). Writers of this crate never rewrite a pack in place:
//! they write a new file and rename it over the old one, which leaves existing maps intact.

use std::fs::File;
use std::io::Read;
use std::path::{Path, PathBuf};

use memmap2::Mmap;

use crate::error::{PackError, Result};
use crate::format::{self, Description, ENTRY_LEN, Entry, HEADER_LEN, Header, LEVEL_LEN, Level, MAGIC, TileKind};
use crate::limits::Limits;

/// Where the bytes come from: a read-only map of a file, or bytes in memory (read from a file
/// where mapping is unwanted, or handed over by the caller); all give identical answers.
enum Bytes {
    Map(Mmap),
    Memory(Box<dyn AsRef<[u8]> + Send + Sync>),
}

impl Bytes {
    fn as_slice(&self) -> &[u8] {
        match self {
            Bytes::Map(m) => m,
            Bytes::Memory(b) => (**b).as_ref(),
        }
    }
}

/// Whether an open holds the index to its checksum (always, but for `verify`).
#[derive(Clone, Copy, PartialEq, Eq)]
enum Trust {
    Checked,
    Unchecked,
}

/// An open pack. `Send + Sync`: lookups take `&self` and touch no shared state.
pub struct Pack {
    bytes: Bytes,
    head: PackLayout,
}

/// Where everything in a pack lies, checked: the header, the level table and the caps a reader
/// holds it to, with the checks of each part and of each index entry and payload: what a
/// reader knows of a pack before it reads any tile. A
/// [`Pack`] has one over its whole file; a reader that fetches a pack in pieces (over HTTP
/// `Range` requests, say) builds one from the pieces it fetched ([`PackLayout::read_header`],
/// then [`PackLayout::new`]) and checks every entry ([`PackLayout::place`]) and payload
/// ([`PackLayout::check_payload`]) with the same code, so both readers refuse the same bytes with
/// the same errors.
#[derive(Clone, Debug)]
pub struct PackLayout {
    path: PathBuf,
    header: Header,
    levels: Vec<Level>,
    limits: Limits,
}

/// Where a tile's index entry says its texels are (see [`PackLayout::place`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Place<'a> {
    /// No tile: a runtime falls back to the parent tile.
    Absent,
    /// One colour: these samples, a prefix of the entry's bytes.
    Constant(&'a [u8]),
    /// A payload of `kind` at `offset` of `len` bytes, inside the data section, whose CRC-32C
    /// must be `crc`.
    Data {
        /// How the payload is stored.
        kind: TileKind,
        /// Its first byte in the file.
        offset: u64,
        /// Its length in bytes.
        len: u32,
        /// The CRC-32C its bytes must have.
        crc: u32,
    },
}

/// A tile as stored.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Tile<'a> {
    /// No tile: a runtime falls back to the parent tile.
    Absent,
    /// Every texel is these samples (channels x sample bytes, little-endian).
    Constant(&'a [u8]),
    /// Payload bytes of the given kind, a slice of the map.
    Data(TileKind, &'a [u8]),
}

/// A tile's address.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct TileId {
    /// The level, 0 the finest.
    pub lod: u32,
    /// The column of tiles in that level, 0 at the left.
    pub x: u32,
    /// The row of tiles in that level, 0 at the top.
    pub y: u32,
}

impl TileId {
    /// Tile `(x, y)` of level `lod`.
    pub const fn new(lod: u32, x: u32, y: u32) -> TileId {
        TileId { lod, x, y }
    }
}

impl Pack {
    /// Maps `path` read-only and checks its structure against the default [`Limits`].
    pub fn open(path: impl AsRef<Path>) -> Result<Pack> {
        Pack::open_with_limits(path, Limits::default())
    }

    /// As [`Pack::open`], holding the pack to `limits`.
    pub fn open_with_limits(path: impl AsRef<Path>, limits: Limits) -> Result<Pack> {
        let path = path.as_ref();
        Pack::new(path, map(path)?, limits, Trust::Checked)
    }

    /// As [`Pack::open`], for a local copy of a pack kept elsewhere: maps `path` but names the
    /// pack `name` (the URL it was downloaded from) in errors and [`Pack::path`], where `path`
    /// (a temporary) would mean nothing to the user. An error opening the file names both.
    pub fn open_named(path: impl AsRef<Path>, name: impl Into<PathBuf>) -> Result<Pack> {
        let (path, name) = (path.as_ref(), name.into());
        let bytes = map(path).map_err(|e| match e {
            PackError::Io { source, .. } => {
                let why = format!("its local copy {}: {source}", path.display());
                io(&name, std::io::Error::new(source.kind(), why))
            }
            other => other,
        })?;
        Pack::new(&name, bytes, Limits::default(), Trust::Checked)
    }

    /// For `verify` alone: maps `path` and checks it as [`Pack::open_with_limits`] does, but for
    /// the level table's and index's checksum, which [`verify`](crate::verify()) then reports
    /// among every other problem (an entry pointing outside the data section, payloads that
    /// fail their checksum...) instead of the open failing on it alone. Entries are still
    /// checked for sense as each is used, but nothing vouches for them: a reader that draws,
    /// converts or serves tiles opens with [`Pack::open`].
    pub fn open_to_verify(path: impl AsRef<Path>, limits: Limits) -> Result<Pack> {
        let path = path.as_ref();
        Pack::new(path, map(path)?, limits, Trust::Unchecked)
    }

    /// Reads the whole file into memory instead of mapping it.
    pub fn open_read(path: impl AsRef<Path>) -> Result<Pack> {
        Pack::open_read_with_limits(path, Limits::default())
    }

    /// As [`Pack::open_read`], holding the pack to `limits`.
    pub fn open_read_with_limits(path: impl AsRef<Path>, limits: Limits) -> Result<Pack> {
        let path = path.as_ref();
        let mut file = File::open(path).map_err(|e| io(path, e))?;
        let len = file.metadata().map_err(|e| io(path, e))?.len();
        let mut bytes = Vec::new();
        bytes
            .try_reserve_exact(usize::try_from(len).unwrap_or(usize::MAX))
            .map_err(|e| io(path, std::io::Error::new(std::io::ErrorKind::OutOfMemory, e.to_string())))?;
        file.read_to_end(&mut bytes).map_err(|e| io(path, e))?;
        Pack::new(path, Bytes::Memory(Box::new(bytes)), limits, Trust::Checked)
    }

    /// A pack held in memory (a `Vec<u8>`, `Box<[u8]>`, `Arc<[u8]>`, a static slice...),
    /// checked exactly as [`Pack::open`] checks a file, against the default [`Limits`]. `name`
    /// stands for the path in errors and [`Pack::path`] (a file name, a URL, `<memory>`).
    pub fn from_bytes(name: impl Into<PathBuf>, bytes: impl AsRef<[u8]> + Send + Sync + 'static) -> Result<Pack> {
        Pack::from_bytes_with_limits(name, bytes, Limits::default())
    }

    /// As [`Pack::from_bytes`], holding the pack to `limits`.
    pub fn from_bytes_with_limits(
        name: impl Into<PathBuf>,
        bytes: impl AsRef<[u8]> + Send + Sync + 'static,
        limits: Limits,
    ) -> Result<Pack> {
        Pack::new(&name.into(), Bytes::Memory(Box::new(bytes)), limits, Trust::Checked)
    }

    /// The one place a local pack is opened: every check of [`PackLayout::read_header`] and
    /// [`PackLayout::new`], then (unless `verify` asked otherwise) the level table's and index's
    /// checksum, so that no entry is used that the checksum does not vouch for. An index of
    /// 350,000 tiles is 8 MiB: a few milliseconds of CRC-32C, read once.
    fn new(path: &Path, bytes: Bytes, limits: Limits, trust: Trust) -> Result<Pack> {
        let b = bytes.as_slice();
        let h = PackLayout::read_header(path, b, b.len() as u64, limits)?;
        let levels = &b[h.levels_offset as usize..][..h.description.level_count as usize * LEVEL_LEN];
        let meta = &b[h.meta_offset as usize..][..h.meta_len as usize];
        let head = PackLayout::new(path, h, levels, meta, limits)?;
        let pack = Pack { bytes, head };
        if trust == Trust::Checked {
            pack.check_index()?;
        }
        Ok(pack)
    }

    /// The checked header and level table.
    pub fn layout(&self) -> &PackLayout {
        &self.head
    }

    /// The caps this pack was opened with (and that decoding it is held to).
    pub fn limits(&self) -> &Limits {
        &self.head.limits
    }

    /// The file it was opened from (or the name given to its bytes), for messages.
    pub fn path(&self) -> &Path {
        &self.head.path
    }

    /// Checks the level table and index against their CRC-32C: done by every `open` (but
    /// [`Pack::open_to_verify`]), and by `verify`.
    pub fn check_index(&self) -> Result<()> {
        let h = &self.head.header;
        let b = self.file();
        let levels = &b[h.levels_offset as usize..][..self.head.levels.len() * LEVEL_LEN];
        let index = &b[h.index_offset as usize..][..h.index_count as usize * ENTRY_LEN];
        self.head.check_index(levels, index)
    }

    /// The checked header.
    pub fn header(&self) -> &Header {
        &self.head.header
    }

    /// What the texture is: its size, tiles and texels.
    pub fn description(&self) -> &Description {
        &self.head.header.description
    }

    /// The level table, LOD 0 first.
    pub fn levels(&self) -> &[Level] {
        &self.head.levels
    }

    /// The metadata: JSON text with the `info.json` members (not needed for addressing).
    pub fn metadata(&self) -> &[u8] {
        let h = &self.head.header;
        &self.file()[h.meta_offset as usize..][..h.meta_len as usize]
    }

    /// The whole file.
    pub fn file(&self) -> &[u8] {
        self.bytes.as_slice()
    }

    /// Index position of a tile: `first_entry[lod] + y * tiles_w[lod] + x`.
    pub fn position(&self, id: TileId) -> Result<u64> {
        self.head.position(id)
    }

    /// The raw index entry at `position`.
    pub fn entry(&self, position: u64) -> Entry {
        Entry::decode(self.raw_entry(position))
    }

    fn raw_entry(&self, position: u64) -> &[u8] {
        &self.file()[self.head.entry_offset(position) as usize..][..ENTRY_LEN]
    }

    /// Tile `id`: O(1), zero copy. Checks that the entry is well formed and its bytes lie in
    /// the data section; does not check the payload's CRC (see `tile_checked`).
    pub fn tile(&self, id: TileId) -> Result<Tile<'_>> {
        let position = self.position(id)?;
        self.tile_at(id, position)
    }

    /// As [`Pack::tile`], and the payload's CRC-32C must match.
    pub fn tile_checked(&self, id: TileId) -> Result<Tile<'_>> {
        let position = self.position(id)?;
        let tile = self.tile_at(id, position)?;
        if let Tile::Data(_, bytes) = tile {
            let e = self.entry(position);
            self.head.check_payload(id, e.offset_or_value, e.crc, bytes)?;
        }
        Ok(tile)
    }

    pub(crate) fn tile_at(&self, id: TileId, position: u64) -> Result<Tile<'_>> {
        Ok(match self.head.place(id, position, self.raw_entry(position))? {
            Place::Absent => Tile::Absent,
            Place::Constant(value) => Tile::Constant(value),
            Place::Data { kind, offset, len, .. } => Tile::Data(kind, &self.file()[offset as usize..][..len as usize]),
        })
    }

    /// Every tile address, level by level (coarsest last), rows top down.
    pub fn ids(&self) -> impl Iterator<Item = TileId> + '_ {
        self.head.levels.iter().enumerate().flat_map(|(lod, l)| {
            (0..l.tiles_h).flat_map(move |y| (0..l.tiles_w).map(move |x| TileId { lod: lod as u32, x, y }))
        })
    }

    /// Tiles with payload in the order their bytes lie in the file (for sequential readers).
    pub fn ids_in_file_order(&self) -> Vec<(TileId, Entry)> {
        let mut v: Vec<(TileId, Entry)> = self
            .ids()
            .enumerate()
            .map(|(i, id)| (id, self.entry(i as u64)))
            .filter(|(_, e)| TileKind::from_u8(e.kind).is_some_and(TileKind::has_payload))
            .collect();
        v.sort_by_key(|(_, e)| e.offset_or_value);
        v
    }
}

impl PackLayout {
    /// The header of a pack of `file_len` bytes from its first bytes `first` (at least
    /// [`HEADER_LEN`] of them when the file has as many), checked as [`Pack::open`] checks it:
    /// signature, checksum, reserved bytes, version, required features, fixed lengths, the
    /// claims against `limits`, and that every section lies inside the file in order.
    pub fn read_header(path: &Path, first: &[u8], file_len: u64, limits: Limits) -> Result<Header> {
        let b = first;
        let corrupt = |offset: u64, message: String| PackError::Corrupt {
            path: path.to_path_buf(),
            section: "header",
            offset,
            message,
        };
        if b.len() < HEADER_LEN {
            return Err(corrupt(
                0,
                format!(
                    "the file is {} bytes, shorter than a pack header ({HEADER_LEN})",
                    file_len.min(b.len() as u64)
                ),
            ));
        }
        if b[..8] != MAGIC {
            let hint = if b[..8].iter().all(|v| *v == 0) {
                "all zero: an unfinished write (the header is written last)"
            } else if b[1..4] == MAGIC[1..4] {
                "damaged in transfer (text-mode or 7-bit conversion?)"
            } else {
                "not a Vortex pack"
            };
            return Err(corrupt(0, format!("bad signature: {hint}")));
        }
        let stored_crc = format::u32_at(b, format::at::HEADER_CRC);
        if crc32c::crc32c(&b[..format::at::HEADER_CRC]) != stored_crc {
            return Err(corrupt(format::at::HEADER_CRC as u64, "header checksum mismatch".into()));
        }
        let reserved = [71usize].into_iter().chain(format::at::RESERVED..format::at::HEADER_CRC);
        if let Some(at) = reserved.into_iter().find(|at| b[*at] != 0) {
            return Err(corrupt(at as u64, "reserved byte is not zero".into()));
        }
        let h = Header::decode(b);
        let unsupported = |message: String| PackError::Unsupported { path: path.to_path_buf(), message };
        if h.major != format::MAJOR {
            return Err(unsupported(format!(
                "format version {}.{} (this reader reads {}.x)",
                h.major,
                h.minor,
                format::MAJOR
            )));
        }
        if h.required_features & !format::KNOWN_REQUIRED_FEATURES != 0 {
            return Err(unsupported(format!("required features {:#x} unknown to this reader", h.required_features)));
        }
        // The sizes of the header and of an index entry are fixed in 1.x; a reader that ignored
        // these fields would misread a file that says otherwise.
        for (field, expected) in [(format::at::HEADER_LEN, HEADER_LEN), (format::at::ENTRY_LEN, ENTRY_LEN)] {
            let value = format::u32_at(b, field);
            if value as usize != expected {
                return Err(corrupt(field as u64, format!("length field says {value}, expected {expected}")));
            }
        }
        let over = |field: String, offset: u64, value: u64, limit: u64, cap: &'static str| PackError::LimitExceeded {
            path: path.to_path_buf(),
            field,
            offset,
            value,
            limit,
            cap,
        };
        // The claims a caller sizes buffers from, before anything else is believed.
        let d = &h.description;
        if d.tile_size > limits.max_tile_size {
            let (value, limit) = (d.tile_size.into(), limits.max_tile_size.into());
            return Err(over("tile_size".into(), format::at::TILE_SIZE as u64, value, limit, "max_tile_size"));
        }
        if h.index_count > limits.max_tiles {
            let offset = format::at::INDEX_COUNT as u64;
            return Err(over("index_count".into(), offset, h.index_count, limits.max_tiles, "max_tiles"));
        }
        check_header(&h, file_len).map_err(|(offset, m)| corrupt(offset, m))?;
        Ok(h)
    }

    /// For a reader that allocates the metadata it reads (one that fetches a pack in pieces; a
    /// mapped pack costs nothing): the header's `meta_len` held to `limits.max_decoded_bytes`,
    /// the cap on any one buffer, before it is fetched. `read_header` checked the claim against
    /// the file's length only.
    pub fn check_metadata_len(path: &Path, h: &Header, limits: Limits) -> Result<()> {
        if u64::from(h.meta_len) > limits.max_decoded_bytes {
            return Err(PackError::LimitExceeded {
                path: path.to_path_buf(),
                field: "meta_len".into(),
                offset: format::at::META_LEN as u64,
                value: h.meta_len.into(),
                limit: limits.max_decoded_bytes,
                cap: "max_decoded_bytes",
            });
        }
        Ok(())
    }

    /// The head of a pack whose header [`PackLayout::read_header`] checked, from its level table
    /// (`levels`, the header's `level_count` rows) and metadata (`meta`, `meta_len` bytes):
    /// the level table's claims against `limits` and its sense, and the metadata's checksum.
    pub fn new(path: &Path, h: Header, levels: &[u8], meta: &[u8], limits: Limits) -> Result<PackLayout> {
        let corrupt = |section: &'static str, offset: u64, message: String| PackError::Corrupt {
            path: path.to_path_buf(),
            section,
            offset,
            message,
        };
        let levels_len = h.description.level_count as usize * LEVEL_LEN;
        if levels.len() != levels_len || meta.len() != h.meta_len as usize {
            let message = format!("{} bytes of level table and {} of metadata given", levels.len(), meta.len());
            return Err(PackError::Usage(format!("{}: {message}", path.display())));
        }
        let raw_levels = levels;
        let levels: Vec<Level> = raw_levels.chunks_exact(LEVEL_LEN).map(Level::decode).collect();
        let mut tiles = 0u64;
        for (lod, l) in levels.iter().enumerate() {
            tiles = tiles.saturating_add(l.tiles_w as u64 * l.tiles_h as u64);
            if tiles > limits.max_tiles {
                let field = format!("the tile count of levels 0..={lod} (level {lod}: {}x{})", l.tiles_w, l.tiles_h);
                let offset = h.levels_offset + (lod * LEVEL_LEN) as u64;
                return Err(PackError::LimitExceeded {
                    path: path.to_path_buf(),
                    field,
                    offset,
                    value: tiles,
                    limit: limits.max_tiles,
                    cap: "max_tiles",
                });
            }
        }
        check_levels(&h, &levels, raw_levels).map_err(|(o, m)| corrupt("levels", h.levels_offset + o, m))?;
        if crc32c::crc32c(meta) != h.meta_crc {
            return Err(corrupt("metadata", h.meta_offset, "metadata checksum mismatch".into()));
        }
        Ok(PackLayout { path: path.to_path_buf(), header: h, levels, limits })
    }

    /// The pack's file or URL, for messages.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The checked header.
    pub fn header(&self) -> &Header {
        &self.header
    }

    /// The level table, LOD 0 first.
    pub fn levels(&self) -> &[Level] {
        &self.levels
    }

    /// The caps the pack was checked against.
    pub fn limits(&self) -> &Limits {
        &self.limits
    }

    /// Index position of a tile: `first_entry[lod] + y * tiles_w[lod] + x`.
    pub fn position(&self, id: TileId) -> Result<u64> {
        let out =
            |message: String| PackError::OutOfRange { path: self.path.clone(), lod: id.lod, x: id.x, y: id.y, message };
        let level = self
            .levels
            .get(id.lod as usize)
            .ok_or_else(|| out(format!("the pack has {} levels", self.levels.len())))?;
        if id.x >= level.tiles_w || id.y >= level.tiles_h {
            return Err(out(format!("level {} is {}x{} tiles", id.lod, level.tiles_w, level.tiles_h)));
        }
        Ok(level.first_entry + id.y as u64 * level.tiles_w as u64 + id.x as u64)
    }

    /// The file offset of index entry `position` (one of [`PackLayout::position`]'s answers).
    pub fn entry_offset(&self, position: u64) -> u64 {
        self.header.index_offset + position * ENTRY_LEN as u64
    }

    /// Where tile `id`'s entry (`raw`, the [`ENTRY_LEN`] bytes at index `position`) says its
    /// texels are, once the entry is checked: a known kind the header's required features allow,
    /// reserved bytes zero, a payload inside the data section.
    pub fn place<'a>(&self, id: TileId, position: u64, raw: &'a [u8]) -> Result<Place<'a>> {
        let entry_at = self.entry_offset(position);
        let e = Entry::decode(raw);
        let kind = TileKind::from_u8(e.kind)
            .ok_or_else(|| self.tile_error(id, entry_at, format!("unknown tile kind {}", e.kind)))?;
        if self.header.required_features & kind.required_feature() != kind.required_feature() {
            let message =
                format!("a {} tile in a pack without required-feature bit {:#x}", kind.name(), kind.required_feature());
            return Err(self.tile_error(id, entry_at + 16, message));
        }
        if raw[17..ENTRY_LEN].iter().any(|b| *b != 0) {
            return Err(self.tile_error(id, entry_at + 17, "reserved entry bytes are not zero".into()));
        }
        match kind {
            TileKind::Absent => Ok(Place::Absent),
            TileKind::Constant => {
                let d = &self.header.description;
                let n = d.channels as usize * d.sample_bytes as usize;
                if n > 8 {
                    let message = format!("a constant tile, but a texel of {n} bytes does not fit an entry");
                    return Err(self.tile_error(id, entry_at + 16, message));
                }
                Ok(Place::Constant(&raw[..n]))
            }
            _ => {
                let (start, end) = (e.offset_or_value, e.offset_or_value.checked_add(e.len as u64));
                let data = self.header.data_offset..self.header.data_offset + self.header.data_len;
                match end {
                    Some(end) if start >= data.start && end <= data.end => {
                        Ok(Place::Data { kind, offset: start, len: e.len, crc: e.crc })
                    }
                    _ => Err(self.tile_error(
                        id,
                        entry_at,
                        format!("payload {start}+{} lies outside the data section", e.len),
                    )),
                }
            }
        }
    }

    /// Tile `id`'s payload `bytes`, read from `offset`, must have the CRC-32C `crc` its entry
    /// gives.
    pub fn check_payload(&self, id: TileId, offset: u64, crc: u32, bytes: &[u8]) -> Result<()> {
        if crc32c::crc32c(bytes) != crc {
            return Err(self.tile_error(id, offset, "payload checksum mismatch".into()));
        }
        Ok(())
    }

    /// The level table's bytes and the whole index's must match the header's CRC-32C of both.
    pub fn check_index(&self, levels: &[u8], index: &[u8]) -> Result<()> {
        self.check_index_parts(levels, [index])
    }

    /// As [`PackLayout::check_index`], the index given in consecutive parts (blocks fetched one by
    /// one), none copied.
    pub fn check_index_parts<'a>(&self, levels: &[u8], index: impl IntoIterator<Item = &'a [u8]>) -> Result<()> {
        let h = &self.header;
        let crc = index.into_iter().fold(crc32c::crc32c(levels), crc32c::crc32c_append);
        if crc != h.index_crc {
            return Err(PackError::Corrupt {
                path: self.path.clone(),
                section: "index",
                offset: h.index_offset,
                message: "level table or index checksum mismatch".into(),
            });
        }
        Ok(())
    }

    pub(crate) fn tile_error(&self, id: TileId, offset: u64, message: String) -> PackError {
        PackError::Tile { path: self.path.clone(), lod: id.lod, x: id.x, y: id.y, offset, message }
    }
}

/// Every section must lie inside the file, in order, without overlap.
fn check_header(h: &Header, file_len: u64) -> std::result::Result<(), (u64, String)> {
    use format::at;
    let d = &h.description;
    if h.file_len != file_len {
        let what = if file_len < h.file_len { "truncated" } else { "has trailing bytes" };
        return Err((
            at::FILE_LEN as u64,
            format!("the header says {} bytes but the file has {file_len}: {what}", h.file_len),
        ));
    }
    if !d.texel_ok() {
        return Err((at::CHANNELS as u64, format!("{} is not a texel format", d.texel_name())));
    }
    if h.required_features & d.required_features() != d.required_features() {
        let message = format!("{} samples without required-feature bit {:#x}", d.texel_name(), d.required_features());
        return Err((at::REQUIRED as u64, message));
    }
    if d.tile_size == 0 || d.border.checked_mul(2).is_none_or(|b| b >= d.tile_size) || d.width == 0 || d.height == 0 {
        return Err((
            at::WIDTH as u64,
            format!("image {}x{}, tile {} border {} is not a valid texture", d.width, d.height, d.tile_size, d.border),
        ));
    }
    if d.level_count == 0 || d.level_count > 32 {
        return Err((at::LEVEL_COUNT as u64, format!("{} levels", d.level_count)));
    }
    for (value, field) in [(h.alignment, at::ALIGNMENT), (h.payload_alignment, at::PAYLOAD_ALIGNMENT)] {
        if !value.is_power_of_two() || value < 8 {
            return Err((field as u64, format!("alignment {value} is not a power of two >= 8")));
        }
    }
    let sections = [
        ("level table", h.levels_offset, d.level_count as u64 * LEVEL_LEN as u64, at::LEVELS_OFFSET),
        ("index", h.index_offset, h.index_count.saturating_mul(ENTRY_LEN as u64), at::INDEX_OFFSET),
        ("metadata", h.meta_offset, h.meta_len as u64, at::META_OFFSET),
        ("data", h.data_offset, h.data_len, at::DATA_OFFSET),
    ];
    let mut end_of_previous = HEADER_LEN as u64;
    for (name, offset, len, field) in sections {
        let end = offset.saturating_add(len);
        if offset < end_of_previous || end > file_len {
            return Err((
                field as u64,
                format!(
                    "the {name} ({offset}+{len}) overlaps what precedes it or lies outside the {file_len}-byte file"
                ),
            ));
        }
        if name != "metadata" && offset % 8 != 0 {
            return Err((field as u64, format!("the {name} at {offset} is not 8-byte aligned")));
        }
        end_of_previous = end;
    }
    if !h.data_offset.is_multiple_of(h.alignment as u64) {
        return Err((
            at::DATA_OFFSET as u64,
            format!("the data section at {} is not aligned to {}", h.data_offset, h.alignment),
        ));
    }
    if h.data_offset + h.data_len != file_len {
        return Err((at::DATA_LEN as u64, "the data section does not end the file".into()));
    }
    Ok(())
}

/// The level table must tile the index exactly, level after level.
fn check_levels(h: &Header, levels: &[Level], raw: &[u8]) -> std::result::Result<(), (u64, String)> {
    let mut next = 0u64;
    for (lod, l) in levels.iter().enumerate() {
        let at = (lod * LEVEL_LEN) as u64;
        if raw[lod * LEVEL_LEN + 24..(lod + 1) * LEVEL_LEN].iter().any(|b| *b != 0) {
            return Err((at + 24, format!("level {lod}: reserved bytes are not zero")));
        }
        if l.first_entry != next || l.tiles_w == 0 || l.tiles_h == 0 {
            return Err((
                at,
                format!(
                    "level {lod} starts at entry {} with {}x{} tiles; expected to start at {next}",
                    l.first_entry, l.tiles_w, l.tiles_h
                ),
            ));
        }
        next = next.checked_add(l.tiles_w as u64 * l.tiles_h as u64).ok_or((at, "tile count overflows".to_string()))?;
    }
    if next != h.index_count {
        return Err((0, format!("the levels hold {next} tiles but the index has {} entries", h.index_count)));
    }
    Ok(())
}

/// `path` mapped read-only.
fn map(path: &Path) -> Result<Bytes> {
    let file = File::open(path).map_err(|e| io(path, e))?;
    // SAFETY: a read-only map of a file opened read-only; see the module's contract on
    // concurrent truncation (a pack rewritten in place by another process).
    #[expect(unsafe_code)]
    let map = unsafe { Mmap::map(&file) }.map_err(|e| io(path, e))?;
    Ok(Bytes::Map(map))
}

fn io(path: &Path, source: std::io::Error) -> PackError {
    PackError::Io { path: path.to_path_buf(), source }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pack_is_send_and_sync() {
        fn check<T: Send + Sync>() {}
        check::<Pack>();
    }
}
