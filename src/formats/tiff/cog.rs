//! What a Cloud Optimized GeoTIFF adds to the tiled pyramid: GDAL's layout (its COG driver's,
//! which its validator `validate_cloud_optimized_geotiff.py` checks), and the staging file
//! that lets a stream of tiles in the producer's order become it.
//!
//! ```text
//! 0    header ("II", 42 or 43, the first IFD's offset)
//! 8    the ghost area (16 in BigTIFF): "GDAL_STRUCTURAL_METADATA_SIZE=000140 bytes\n" and
//!      140 bytes of "KEY=VALUE\n" lines, GDAL's promises about the layout
//! 192  the IFDs, level 0 first (200 in BigTIFF: each IFD at an even offset), chained, each
//!      with its values (tile offsets and byte counts) after it
//! ..   the tile data: the coarsest level first, down to level 0, each level's tiles row by
//!      row, each tile as [its length, u32 LE][its bytes][its last 4 bytes again]
//! ```
//!
//! The IFDs come first and hold every tile's offset, which is known only once every tile has
//! been compressed; the tiles arrive in the producer's order (levels interleaved), not the
//! file's. So they are appended to a staging file beside the output as they come, each with
//! its leader and trailer, and [`assemble`] writes the file at the end: header, ghost area,
//! IFDs, then each tile's bytes copied from the staging file in the file's order
//! (`std::io::copy`, which is `copy_file_range` on Linux: the kernel copies, and runs of
//! tiles that lie in order in both files are one copy). Memory holds the tile index only; the
//! disk holds the tiles twice until the end.

use std::fs::{self, File};
use std::io::{self, BufWriter, Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

/// GDAL's structural metadata, as its COG driver writes it with tiles that carry a leader and
/// a trailer: the tiles follow the IFDs, each level's row by row, each tile's length in the 4
/// bytes before it and its last 4 bytes repeated after it (which lets a reader fetch a tile
/// without the offset arrays and check it was whole). The last line's space leaves room for
/// `YES`, which a program that edits the file in place and breaks these promises writes.
const STRUCTURAL: &str = "LAYOUT=IFDS_BEFORE_DATA\nBLOCK_ORDER=ROW_MAJOR\nBLOCK_LEADER=SIZE_AS_UINT4\n\
BLOCK_TRAILER=LAST_4_BYTES_REPEATED\nKNOWN_INCOMPATIBLE_EDITION=NO\n ";

/// The ghost area: the line that gives the metadata's size, then the metadata.
pub(super) fn ghost_area() -> Vec<u8> {
    format!("GDAL_STRUCTURAL_METADATA_SIZE={:06} bytes\n{STRUCTURAL}", STRUCTURAL.len()).into_bytes()
}

/// Where the first IFD lies: right after the header and the ghost area, at an even offset.
pub(super) fn first_ifd_at(big: bool) -> u64 {
    let header = if big { 16 } else { 8 };
    (header + ghost_area().len() as u64).next_multiple_of(2)
}

/// Bytes a tile takes in the file besides its own: the leader and the trailer.
pub(super) const FRAMING: u64 = 8;

/// The tiles of a COG being written, each framed as the file holds it, in the order they came.
pub(super) struct Staging {
    file: BufWriter<File>,
    /// Bytes written so far.
    len: u64,
    /// The staging file's name where it could not be unlinked while open (not Unix): removed
    /// when dropped.
    named: Option<PathBuf>,
}

impl Staging {
    /// A staging file beside `beside` (the output's temporary), unlinked at once where the
    /// system allows, so that nothing is left of it whatever becomes of the run.
    pub fn create(beside: &Path) -> io::Result<Staging> {
        let mut name = beside.as_os_str().to_owned();
        name.push(".tiles");
        let path = PathBuf::from(name);
        let file = fs::OpenOptions::new().read(true).write(true).create_new(true).open(&path)?;
        let named = match fs::remove_file(&path) {
            Ok(()) => None,
            Err(_) => Some(path),
        };
        Ok(Staging { file: BufWriter::with_capacity(1 << 20, file), len: 0, named })
    }

    /// Appends `bytes` framed (leader, bytes, trailer); returns the offset of the bytes.
    /// The caller has checked that the length fits the leader's 32 bits.
    pub fn append(&mut self, bytes: &[u8]) -> io::Result<u64> {
        let len = u32::try_from(bytes.len()).map_err(|_| io::Error::other("a tile of 4 GiB or more"))?;
        let mut trailer = [0u8; 4];
        let tail = &bytes[bytes.len().saturating_sub(4)..];
        trailer[4 - tail.len()..].copy_from_slice(tail);
        self.file.write_all(&len.to_le_bytes())?;
        self.file.write_all(bytes)?;
        self.file.write_all(&trailer)?;
        let at = self.len + 4;
        self.len += bytes.len() as u64 + FRAMING;
        Ok(at)
    }
}

impl Drop for Staging {
    fn drop(&mut self) {
        if let Some(path) = self.named.take() {
            let _ = fs::remove_file(path);
        }
    }
}

/// Copies the staged tiles into `out` (positioned where the tile data starts), in the order
/// `ranges` gives: each the staged offset of a tile's bytes and their length, framing
/// excluded. Runs of tiles that lie one after another in the staging file are one copy.
/// Returns the bytes copied.
pub(super) fn assemble(
    mut staging: Staging,
    out: &mut File,
    ranges: impl IntoIterator<Item = (u64, u64)>,
) -> io::Result<u64> {
    staging.file.flush()?;
    // `staging` is dropped at the end, which removes a named staging file.
    let file = staging.file.get_ref();
    let mut copied = 0u64;
    let mut copy = |(from, len): (u64, u64)| -> io::Result<()> {
        let mut reader = file;
        reader.seek(SeekFrom::Start(from))?;
        let n = io::copy(&mut reader.take(len), out)?;
        if n != len {
            return Err(io::Error::new(io::ErrorKind::UnexpectedEof, "the staged tiles end early"));
        }
        copied += n;
        Ok(())
    };
    let mut run: Option<(u64, u64)> = None;
    for (at, len) in ranges {
        let from = at.checked_sub(4).ok_or_else(|| io::Error::other("a staged tile without its leader"))?;
        let framed = len + FRAMING;
        run = match run {
            Some((start, n)) if start + n == from => Some((start, n + framed)),
            Some(done) => {
                copy(done)?;
                Some((from, framed))
            }
            None => Some((from, framed)),
        };
    }
    if let Some(done) = run {
        copy(done)?;
    }
    Ok(copied)
}
