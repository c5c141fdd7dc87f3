//! A sink that writes one PMTiles v3 archive (`split --pmtiles`): the web-map (XYZ) pyramid of
//! [`crate::formats::viewer::xyz`] in the single-file format that Leaflet, MapLibre and OpenLayers read
//! from any static host with HTTP range requests (<https://github.com/protomaps/PMTiles>,
//! `spec/v3/spec.md`). JPEG XL tiles have no tile type of their own: the header says 0
//! ("Unknown/Other") and the metadata's `format` says `jxl`.
//!
//! The spec wants the root directory within the first 16 KiB and, for a "clustered" archive,
//! tile data in tile-id (Hilbert) order, while our tiles arrive in the pipeline's order. So
//! each encoded tile is appended, as it comes, to a spool file beside the destination
//! (`.NAME.tmp-PID`); identical tiles are spooled once. `finish` sorts the directory entries
//! by tile id, reads its own directories back from the bytes it made of them, writes header,
//! root directory, metadata, leaf directories and then the data by copying the spooled
//! payloads in tile-id order into `.NAME.partial-PID`, and renames the archive into place.
//! Memory holds the directory entries only (see `ENTRY_MEMORY_BYTES`), never the payloads; the
//! disk holds the payloads twice until the spool is removed. At `s3://`, `finish_into` sends
//! the archive straight into the upload instead, so the disk holds the payloads once.

use std::collections::HashMap;
use std::fs::{self, File};
use std::io::{BufWriter, Read, Write};
use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use flate2::Compression;
use flate2::read::GzDecoder;
use flate2::write::GzEncoder;

use crate::error::{Result, ShowPath, TilerError};
use crate::layout::Layout;
use crate::output::staging;
use crate::sink::TileSink;

/// The header's length; the root directory follows it.
pub(crate) const HEADER_LEN: usize = 127;
/// The header and the root directory together must fit in the first 16 KiB (the spec), so
/// that a reader's first request gets both.
const ROOT_LIMIT: usize = 16384 - HEADER_LEN;
/// Entries per leaf directory to start from (as go-pmtiles); doubled until the root fits.
const FIRST_LEAF_SIZE: usize = 4096;
/// The deepest zoom a PMTiles reader accepts (tile ids must stay below 2^53 in JavaScript).
pub(crate) const MAX_ZOOM: u32 = 26;
/// Memory held per tile until `finish`, a bound for `--max-memory`: its spooled entry (24
/// bytes), its share of the content map (about 56), and its directory entry at the end (24).
pub(crate) const ENTRY_MEMORY_BYTES: u64 = 104;

/// The spec's tile types.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum TileType {
    /// "Unknown/Other": JPEG XL tiles, for which v3 has no value; the metadata's `format`
    /// says `jxl` (docs/jxl.md).
    Unknown = 0,
    Png = 2,
    Jpeg = 3,
}

/// One directory entry: `run_length` consecutive tile ids from `tile_id` share the bytes at
/// `offset` (relative to the data section); run length 0 points to a leaf directory instead.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Entry {
    pub tile_id: u64,
    pub offset: u64,
    pub length: u32,
    pub run_length: u32,
}

/// What `finish` wrote.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PmtilesSummary {
    /// Tiles a reader finds (the header's addressed tiles count).
    pub tiles: u64,
    /// Directory entries: runs of identical consecutive tiles count once.
    pub entries: u64,
    /// Distinct payloads stored.
    pub contents: u64,
    /// Leaf directories (0 when the root holds every entry).
    pub leaves: u64,
    /// Bytes of the tile data section (distinct payloads, each once).
    pub data_bytes: u64,
    /// Bytes of the whole archive: header, directories, metadata and tile data.
    pub file_bytes: u64,
}

/// The PMTiles tile id of web-map tile (z, x, y): the tiles of all coarser zooms, then the
/// position of (x, y) along the Hilbert curve over the 2^z x 2^z grid.
pub(crate) fn tile_id(z: u32, x: u32, y: u32) -> u64 {
    let n = 1u64 << z;
    let coarser = ((1u64 << (2 * z)) - 1) / 3;
    let (mut x, mut y) = (x as u64, y as u64);
    let mut d = 0;
    let mut s = n / 2;
    while s > 0 {
        let rx = u64::from(x & s != 0);
        let ry = u64::from(y & s != 0);
        d += s * s * ((3 * rx) ^ ry);
        // Turn the quadrant so that the curve inside it runs the way the next step expects.
        if ry == 0 {
            if rx == 1 {
                x = n - 1 - x;
                y = n - 1 - y;
            }
            std::mem::swap(&mut x, &mut y);
        }
        s /= 2;
    }
    coarser + d
}

/// A payload in the spool.
#[derive(Clone, Copy)]
struct Spooled {
    tile_id: u64,
    offset: u64,
    length: u32,
}

struct Spool {
    file: File,
    len: u64,
    tiles: Vec<Spooled>,
    /// Spool offsets of the payloads with a given CRC-32C and length; a match is confirmed
    /// byte for byte before two tiles share one payload.
    by_content: HashMap<(u32, u32), Vec<u64>>,
}

/// Writes one PMTiles archive; see the module's description.
pub(crate) struct PmtilesSink {
    dest: PathBuf,
    spool_path: PathBuf,
    out_path: PathBuf,
    lod_count: u32,
    tile_type: TileType,
    spool: Mutex<Spool>,
    /// Whether the temporaries are gone (finished); `Drop` removes them otherwise.
    done: bool,
}

fn write_err(path: &Path) -> impl Fn(std::io::Error) -> TilerError + '_ {
    move |e| TilerError::write(path, e)
}

fn poisoned() -> TilerError {
    TilerError::panicked("a tile writer")
}

impl PmtilesSink {
    /// Starts an archive for `layout` (an XYZ page grid) at `dest`, which the caller has
    /// claimed.
    pub fn create(dest: &Path, layout: &Layout, tile_type: TileType) -> Result<PmtilesSink> {
        if layout.lod_count - 1 > MAX_ZOOM {
            return Err(TilerError::Limit(format!(
                "the pyramid needs zoom levels 0 to {}; PMTiles readers stop at {MAX_ZOOM}: a larger tile size gives fewer",
                layout.lod_count - 1
            )));
        }
        let out_path = staging::partial_path(dest);
        // The pack writer's temporary name, which the next run's clean-up also knows.
        let spool_path = staging::parent_of(dest).join(format!(
            ".{}.tmp-{}",
            dest.file_name().map_or_else(|| "out".into(), |n| n.to_string_lossy()),
            std::process::id()
        ));
        let file = File::options()
            .read(true)
            .write(true)
            .create(true)
            .truncate(true)
            .open(&spool_path)
            .map_err(write_err(&spool_path))?;
        Ok(PmtilesSink {
            dest: dest.to_path_buf(),
            spool_path,
            out_path,
            lod_count: layout.lod_count,
            tile_type,
            spool: Mutex::new(Spool { file, len: 0, tiles: Vec::new(), by_content: HashMap::new() }),
            done: false,
        })
    }

    /// Writes the archive with `bounds` and `metadata` (JSON), checks its directories and
    /// renames it into place.
    pub fn finish(mut self, bounds: &Bounds, metadata: &[u8]) -> Result<PmtilesSummary> {
        let out = self.out_path.clone();
        let file = File::create(&out).map_err(write_err(&out))?;
        let mut w = BufWriter::with_capacity(1 << 20, file);
        let summary = self.finish_into(bounds, metadata, &mut w, &out)?;
        let file = w.into_inner().map_err(|e| TilerError::write(&out, e.into_error()))?;
        file.sync_all().map_err(write_err(&out))?;
        drop(file);
        fs::rename(&self.out_path, &self.dest).map_err(write_err(&self.dest))?;
        let _ = fs::remove_file(&self.spool_path);
        self.done = true;
        if let Some(dir) = self.dest.parent().filter(|d| !d.as_os_str().is_empty()) {
            // Make the rename durable; not all file systems allow syncing a directory.
            let _ = File::open(dir).and_then(|d| d.sync_all());
        }
        Ok(summary)
    }

    /// A bound on the bytes of the archive, with `metadata_len` bytes of metadata: the payloads
    /// spooled, at most 40 bytes of directory a tile (a varint entry is at most 4 x 10 bytes
    /// before gzip, which shrinks such runs), and room for the header.
    pub(crate) fn archive_bound(&self, metadata_len: usize) -> u64 {
        let (spooled, tiles) = self.spool.lock().map_or((0, 0), |s| (s.len, s.tiles.len() as u64));
        spooled.saturating_add(tiles.saturating_mul(40)).saturating_add(metadata_len as u64 + (1 << 20))
    }

    /// Writes the archive with `bounds` and `metadata` (JSON), its directories checked, front
    /// to back into `w` (`name` in errors): the local temporary of [`finish`](Self::finish), or
    /// an upload. The spool is removed when the sink is dropped.
    pub(crate) fn finish_into(
        &mut self,
        bounds: &Bounds,
        metadata: &[u8],
        w: &mut dyn Write,
        name: &Path,
    ) -> Result<PmtilesSummary> {
        let spool = self.spool.get_mut().map_err(|_| poisoned())?;
        let tiles = std::mem::take(&mut spool.tiles);
        spool.by_content = HashMap::new();
        let spooled = spool.file.try_clone().map_err(write_err(&self.spool_path))?;
        self.write_archive(&spooled, tiles, bounds, metadata, w, name)
    }

    fn write_archive(
        &self,
        spooled: &File,
        mut tiles: Vec<Spooled>,
        bounds: &Bounds,
        metadata: &[u8],
        w: &mut dyn Write,
        out: &Path,
    ) -> Result<PmtilesSummary> {
        tiles.sort_unstable_by_key(|t| t.tile_id);
        if let Some(w) = tiles.windows(2).find(|w| w[0].tile_id == w[1].tile_id) {
            return Err(TilerError::Internal(format!("tile id {} written twice", w[0].tile_id)));
        }
        // Data in tile-id order, each distinct payload once, where it first occurs.
        let mut placed: HashMap<u64, u64> = HashMap::new();
        let mut copies: Vec<(u64, u32)> = Vec::new();
        let mut data_len = 0u64;
        let mut entries: Vec<Entry> = Vec::with_capacity(tiles.len());
        for t in &tiles {
            let offset = *placed.entry(t.offset).or_insert_with(|| {
                copies.push((t.offset, t.length));
                data_len += u64::from(t.length);
                data_len - u64::from(t.length)
            });
            match entries.last_mut() {
                Some(last) if last.offset == offset && last.tile_id + u64::from(last.run_length) == t.tile_id => {
                    last.run_length += 1;
                }
                _ => entries.push(Entry { tile_id: t.tile_id, offset, length: t.length, run_length: 1 }),
            }
        }
        drop(placed);
        drop(tiles);
        let (root, leaves, leaf_count) = directories(&entries)?;
        let metadata = gzip(metadata)?;

        let header = Header {
            root_offset: HEADER_LEN as u64,
            root_length: root.len() as u64,
            metadata_offset: (HEADER_LEN + root.len()) as u64,
            metadata_length: metadata.len() as u64,
            leaves_offset: (HEADER_LEN + root.len() + metadata.len()) as u64,
            leaves_length: leaves.len() as u64,
            data_offset: (HEADER_LEN + root.len() + metadata.len() + leaves.len()) as u64,
            data_length: data_len,
            addressed_tiles: entries.iter().map(|e| u64::from(e.run_length)).sum(),
            tile_entries: entries.len() as u64,
            tile_contents: copies.len() as u64,
            tile_type: self.tile_type,
            max_zoom: (self.lod_count - 1) as u8,
            bounds: *bounds,
        };
        let mut head = header.encode().to_vec();
        for part in [&root, &metadata, &leaves] {
            head.extend_from_slice(part);
        }
        // Read our own directories back, from the bytes written: the header and every
        // directory must give the entries.
        let (read_header, read_entries) = read_entries(out, &head)?;
        if read_header != header.stored() || read_entries != entries {
            return Err(TilerError::Internal(format!(
                "{}: the archive's directories read back differ from those written",
                out.shown()
            )));
        }
        w.write_all(&head).map_err(write_err(out))?;
        drop(head);
        let mut buf = Vec::new();
        for (offset, length) in &copies {
            buf.resize(*length as usize, 0);
            spooled.read_exact_at(&mut buf, *offset).map_err(write_err(&self.spool_path))?;
            w.write_all(&buf).map_err(write_err(out))?;
        }
        w.flush().map_err(write_err(out))?;
        Ok(PmtilesSummary {
            tiles: header.addressed_tiles,
            entries: header.tile_entries,
            contents: header.tile_contents,
            leaves: leaf_count,
            data_bytes: data_len,
            file_bytes: header.data_offset + data_len,
        })
    }
}

impl Drop for PmtilesSink {
    /// An unfinished archive leaves nothing behind.
    fn drop(&mut self) {
        if !self.done {
            let _ = fs::remove_file(&self.spool_path);
            let _ = fs::remove_file(&self.out_path);
        }
    }
}

impl TileSink for PmtilesSink {
    fn write_tile(&self, lod: u32, x: u32, y: u32, bytes: &[u8]) -> Result<()> {
        let length = u32::try_from(bytes.len()).map_err(|_| TilerError::Encode {
            lod,
            x,
            y,
            message: format!("{} bytes is more than a PMTiles entry holds", bytes.len()),
        })?;
        let zoom = self.lod_count - 1 - lod;
        let tile_id = tile_id(zoom, x, y);
        let crc = crc32c::crc32c(bytes);
        let mut spool = self.spool.lock().map_err(|_| poisoned())?;
        let spool = &mut *spool;
        let mut same = None;
        let mut existing = Vec::new();
        for &offset in spool.by_content.get(&(crc, length)).into_iter().flatten() {
            existing.resize(bytes.len(), 0);
            spool.file.read_exact_at(&mut existing, offset).map_err(write_err(&self.spool_path))?;
            if existing == bytes {
                same = Some(offset);
                break;
            }
        }
        let offset = match same {
            Some(offset) => offset,
            None => {
                let offset = spool.len;
                spool.file.write_all_at(bytes, offset).map_err(write_err(&self.spool_path))?;
                spool.len += u64::from(length);
                spool.by_content.entry((crc, length)).or_default().push(offset);
                offset
            }
        };
        spool.tiles.push(Spooled { tile_id, offset, length });
        Ok(())
    }

    /// Payload bytes spooled: identical tiles count once.
    fn bytes_written(&self) -> u64 {
        self.spool.lock().map_or(0, |s| s.len)
    }
}

/// The area and view a map reader is told about, in degrees.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Bounds {
    pub min_lon: f64,
    pub min_lat: f64,
    pub max_lon: f64,
    pub max_lat: f64,
    pub center_zoom: u8,
    pub center_lon: f64,
    pub center_lat: f64,
}

impl Bounds {
    /// An image without map coordinates: the web-mercator world is the square of zoom 0,
    /// the image at its top left (as the XYZ tiles place it), so the bounds are the image's
    /// extent on that square and the centre its middle, seen at zoom 0 (the whole image).
    pub fn of_image(layout: &Layout) -> Bounds {
        let side = (layout.payload() as f64) * f64::from(1u32 << (layout.lod_count - 1));
        let (fx, fy) = (layout.width as f64 / side, layout.height as f64 / side);
        let lon = |f: f64| -180.0 + 360.0 * f;
        // Web mercator: y from the top (0) to the bottom (1) of the square.
        let lat = |f: f64| (std::f64::consts::PI * (1.0 - 2.0 * f)).sinh().atan().to_degrees();
        Bounds {
            min_lon: lon(0.0),
            min_lat: lat(fy),
            max_lon: lon(fx),
            max_lat: lat(0.0),
            center_zoom: 0,
            center_lon: lon(fx / 2.0),
            center_lat: lat(fy / 2.0),
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq)]
struct Header {
    root_offset: u64,
    root_length: u64,
    metadata_offset: u64,
    metadata_length: u64,
    leaves_offset: u64,
    leaves_length: u64,
    data_offset: u64,
    data_length: u64,
    addressed_tiles: u64,
    tile_entries: u64,
    tile_contents: u64,
    tile_type: TileType,
    max_zoom: u8,
    bounds: Bounds,
}

/// Degrees as the header stores them: 10^-7 degree steps.
fn e7(deg: f64) -> i32 {
    (deg * 1e7).round() as i32
}

const MAGIC: &[u8; 7] = b"PMTiles";
const GZIP: u8 = 2;
const NO_COMPRESSION: u8 = 1;

impl Header {
    fn encode(&self) -> [u8; HEADER_LEN] {
        let mut h = [0u8; HEADER_LEN];
        h[..7].copy_from_slice(MAGIC);
        h[7] = 3;
        let numbers = [
            self.root_offset,
            self.root_length,
            self.metadata_offset,
            self.metadata_length,
            self.leaves_offset,
            self.leaves_length,
            self.data_offset,
            self.data_length,
            self.addressed_tiles,
            self.tile_entries,
            self.tile_contents,
        ];
        for (i, n) in numbers.iter().enumerate() {
            h[8 + 8 * i..16 + 8 * i].copy_from_slice(&n.to_le_bytes());
        }
        h[96] = 1; // clustered: data in tile-id order
        h[97] = GZIP; // directories and metadata
        h[98] = NO_COMPRESSION; // JPEG, PNG and JPEG XL tiles are compressed already
        h[99] = self.tile_type as u8;
        h[100] = 0; // min zoom
        h[101] = self.max_zoom;
        let b = &self.bounds;
        for (i, deg) in [b.min_lon, b.min_lat, b.max_lon, b.max_lat].into_iter().enumerate() {
            h[102 + 4 * i..106 + 4 * i].copy_from_slice(&e7(deg).to_le_bytes());
        }
        h[118] = b.center_zoom;
        h[119..123].copy_from_slice(&e7(b.center_lon).to_le_bytes());
        h[123..127].copy_from_slice(&e7(b.center_lat).to_le_bytes());
        h
    }

    /// Our own header read back (the fields we write; the bounds to the stored precision).
    fn decode(h: &[u8; HEADER_LEN]) -> Option<Header> {
        if &h[..7] != MAGIC || h[7] != 3 || h[96] != 1 || h[97] != GZIP || h[98] != NO_COMPRESSION || h[100] != 0 {
            return None;
        }
        let n = |i: usize| u64::from_le_bytes(h[8 + 8 * i..16 + 8 * i].try_into().unwrap_or_default());
        let deg = |at: usize| f64::from(i32::from_le_bytes(h[at..at + 4].try_into().unwrap_or_default())) / 1e7;
        Some(Header {
            root_offset: n(0),
            root_length: n(1),
            metadata_offset: n(2),
            metadata_length: n(3),
            leaves_offset: n(4),
            leaves_length: n(5),
            data_offset: n(6),
            data_length: n(7),
            addressed_tiles: n(8),
            tile_entries: n(9),
            tile_contents: n(10),
            tile_type: match h[99] {
                0 => TileType::Unknown,
                2 => TileType::Png,
                3 => TileType::Jpeg,
                _ => return None,
            },
            max_zoom: h[101],
            bounds: Bounds {
                min_lon: deg(102),
                min_lat: deg(106),
                max_lon: deg(110),
                max_lat: deg(114),
                center_zoom: h[118],
                center_lon: deg(119),
                center_lat: deg(123),
            },
        })
    }

    /// The header as written, with the bounds rounded to what the file stores.
    fn stored(mut self) -> Header {
        let r = |d: f64| f64::from(e7(d)) / 1e7;
        let b = &mut self.bounds;
        (b.min_lon, b.min_lat, b.max_lon, b.max_lat) = (r(b.min_lon), r(b.min_lat), r(b.max_lon), r(b.max_lat));
        (b.center_lon, b.center_lat) = (r(b.center_lon), r(b.center_lat));
        self
    }
}

fn gzip(bytes: &[u8]) -> Result<Vec<u8>> {
    let mut e = GzEncoder::new(Vec::new(), Compression::default());
    e.write_all(bytes).and_then(|()| e.finish()).map_err(|e| TilerError::Internal(format!("gzip: {e}")))
}

fn push_varint(out: &mut Vec<u8>, mut v: u64) {
    while v >= 0x80 {
        out.push((v as u8) | 0x80);
        v >>= 7;
    }
    out.push(v as u8);
}

/// A directory as the spec stores it (before compression): the count, then each column of
/// the entries: tile-id deltas, run lengths, lengths, offsets (0 for "right after the
/// previous entry's bytes", else offset + 1).
pub(crate) fn serialize_directory(entries: &[Entry]) -> Vec<u8> {
    let mut out = Vec::with_capacity(entries.len() * 6 + 10);
    push_varint(&mut out, entries.len() as u64);
    let mut last = 0;
    for e in entries {
        push_varint(&mut out, e.tile_id - last);
        last = e.tile_id;
    }
    for e in entries {
        push_varint(&mut out, e.run_length.into());
    }
    for e in entries {
        push_varint(&mut out, e.length.into());
    }
    for (i, e) in entries.iter().enumerate() {
        let follows = i > 0 && e.offset == entries[i - 1].offset + u64::from(entries[i - 1].length);
        push_varint(&mut out, if follows { 0 } else { e.offset + 1 });
    }
    out
}

/// Reads a directory [`serialize_directory`] wrote; `None` if it is not one.
pub(crate) fn deserialize_directory(bytes: &[u8]) -> Option<Vec<Entry>> {
    let mut at = 0;
    let mut next = || -> Option<u64> {
        let mut v = 0u64;
        for shift in (0..64).step_by(7) {
            let b = *bytes.get(at)?;
            at += 1;
            v |= u64::from(b & 0x7f) << shift;
            if b < 0x80 {
                return Some(v);
            }
        }
        None
    };
    let count = usize::try_from(next()?).ok()?;
    // Each entry takes at least 4 bytes: a count beyond that is not a directory (and is not
    // allocated).
    if count > bytes.len() / 4 {
        return None;
    }
    let mut entries = vec![Entry { tile_id: 0, offset: 0, length: 0, run_length: 0 }; count];
    let mut id = 0u64;
    for e in entries.iter_mut() {
        id = id.checked_add(next()?)?;
        e.tile_id = id;
    }
    for e in entries.iter_mut() {
        e.run_length = u32::try_from(next()?).ok()?;
    }
    for e in entries.iter_mut() {
        e.length = u32::try_from(next()?).ok()?;
    }
    for i in 0..count {
        let v = next()?;
        entries[i].offset = match v {
            0 if i > 0 => entries[i - 1].offset.checked_add(u64::from(entries[i - 1].length))?,
            0 => return None,
            v => v - 1,
        };
    }
    (at == bytes.len()).then_some(entries)
}

/// The root directory and the leaf directories (one section) of `entries`, and how many
/// leaves: all in the root when it fits the first 16 KiB, else leaves of `FIRST_LEAF_SIZE`
/// entries and more until the root of their pointers fits.
fn directories(entries: &[Entry]) -> Result<(Vec<u8>, Vec<u8>, u64)> {
    let root = gzip(&serialize_directory(entries))?;
    if root.len() <= ROOT_LIMIT {
        return Ok((root, Vec::new(), 0));
    }
    let mut leaf_size = FIRST_LEAF_SIZE;
    loop {
        let mut leaves = Vec::new();
        let mut pointers = Vec::new();
        for chunk in entries.chunks(leaf_size) {
            let leaf = gzip(&serialize_directory(chunk))?;
            pointers.push(Entry {
                tile_id: chunk[0].tile_id,
                offset: leaves.len() as u64,
                length: leaf.len() as u32,
                run_length: 0,
            });
            leaves.extend_from_slice(&leaf);
        }
        let root = gzip(&serialize_directory(&pointers))?;
        if root.len() <= ROOT_LIMIT {
            return Ok((root, leaves, pointers.len() as u64));
        }
        leaf_size *= 2;
    }
}

/// The head of an archive this module wrote (`path`'s bytes before the tile data), read back:
/// its header and every tile entry (leaves followed), in tile-id order. Sizes are checked
/// against the head before anything is read.
fn read_entries(path: &Path, head: &[u8]) -> Result<(Header, Vec<Entry>)> {
    let bad = |what: &str| TilerError::decode(path, format!("not a PMTiles archive as written: {what}"));
    let h: &[u8; HEADER_LEN] = head.get(..HEADER_LEN).and_then(|h| h.try_into().ok()).ok_or_else(|| bad("header"))?;
    let header = Header::decode(h).ok_or_else(|| bad("header"))?;
    let section = |offset: u64, length: u64| -> Result<Vec<Entry>> {
        let range = usize::try_from(offset).ok().zip(usize::try_from(length).ok());
        let Some(bytes) = range.and_then(|(o, n)| head.get(o..o.checked_add(n)?)) else {
            return Err(bad("a directory past the end of the directories"));
        };
        let mut plain = Vec::new();
        // A directory entry is at least 4 bytes before compression and gzip expands by at
        // most ~1032x: bound what is inflated by what any honest directory can be.
        GzDecoder::new(bytes)
            .take(length.saturating_mul(1032) + 64)
            .read_to_end(&mut plain)
            .map_err(|_| bad("a directory that does not inflate"))?;
        deserialize_directory(&plain).ok_or_else(|| bad("a malformed directory"))
    };
    let mut entries = Vec::new();
    for e in section(header.root_offset, header.root_length)? {
        if e.run_length > 0 {
            entries.push(e);
            continue;
        }
        let leaf = section(header.leaves_offset + e.offset, e.length.into())?;
        if leaf.iter().any(|l| l.run_length == 0) {
            return Err(bad("a leaf directory that points to another"));
        }
        entries.extend(leaf);
    }
    Ok((header.stored(), entries))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tile_ids_follow_the_spec() {
        // The spec's examples and values from the reference implementation (Python pmtiles).
        let ids: Vec<u64> =
            [(0, 0, 0), (1, 0, 0), (1, 0, 1), (1, 1, 1), (1, 1, 0), (2, 0, 0), (3, 5, 2), (12, 3000, 1234)]
                .iter()
                .map(|&(z, x, y)| tile_id(z, x, y))
                .collect();
        assert_eq!(ids, [0, 1, 2, 3, 4, 5, 76, 20220825]);
    }

    #[test]
    fn directories_round_trip_with_runs_and_shared_offsets() {
        let entries = vec![
            Entry { tile_id: 0, offset: 0, length: 10, run_length: 1 },
            Entry { tile_id: 1, offset: 10, length: 5, run_length: 3 },
            Entry { tile_id: 7, offset: 0, length: 10, run_length: 1 },
            Entry { tile_id: 1 << 40, offset: 15, length: 1, run_length: 1 },
        ];
        let bytes = serialize_directory(&entries);
        assert_eq!(deserialize_directory(&bytes), Some(entries));
        assert_eq!(deserialize_directory(&bytes[..bytes.len() - 1]), None);
        // A huge count in a few bytes is refused, not allocated.
        assert_eq!(deserialize_directory(&[0xff, 0xff, 0xff, 0xff, 0x0f]), None);
    }

    #[test]
    fn many_entries_go_to_leaves_and_the_root_fits_16k() {
        // Entries whose lengths and gaps vary enough not to compress into 16 KiB.
        let mut offset = 0;
        let entries: Vec<Entry> = (0..200_000u64)
            .map(|i| {
                let length = 100 + (i * 7919 % 5000) as u32;
                let e = Entry { tile_id: i * 3, offset, length, run_length: 1 };
                offset += u64::from(length) + (i % 3);
                e
            })
            .collect();
        let (root, leaves, count) = directories(&entries).unwrap();
        assert!(root.len() <= ROOT_LIMIT && count > 1, "root {} bytes, {count} leaves", root.len());
        let mut plain = Vec::new();
        GzDecoder::new(&root[..]).read_to_end(&mut plain).unwrap();
        let mut all = Vec::new();
        for p in deserialize_directory(&plain).unwrap() {
            let mut leaf = Vec::new();
            let at = p.offset as usize;
            GzDecoder::new(&leaves[at..at + p.length as usize]).read_to_end(&mut leaf).unwrap();
            all.extend(deserialize_directory(&leaf).unwrap());
        }
        assert_eq!(all, entries);
    }
}
