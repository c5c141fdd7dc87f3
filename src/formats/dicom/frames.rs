//! The encapsulated Pixel Data of one instance (PS3.5 A.4), written by our code after the
//! data set dicom-rs wrote:
//!
//! ```text
//! (7FE0,0010) OB, undefined length      E0 7F 10 00 'O' 'B' 00 00 FF FF FF FF
//! Basic Offset Table item               FE FF 00 E0 len, then len/4 offsets (u32 LE), or empty
//! one item a frame, row-major           FE FF 00 E0 len, the JPEG (padded with one 00 to even)
//! Sequence Delimitation Item            FE FF DD E0 00 00 00 00
//! ```
//!
//! The frames arrive in the producer's order, levels interleaved; each level's are appended
//! to a staging file of its own as items (header, bytes, pad), with only each item's place
//! in that file kept. At the end the instance is the data set, then the items copied from the
//! staging file in row-major order (`std::io::copy`: `copy_file_range` on Linux, and frames
//! that lie in order there are one copy). Offsets are those of each frame's item from the
//! first frame's; when the last passes 32 bits the Basic Offset Table is left empty and the
//! data set carries them in the Extended Offset Table (7FE0,0001/0002) instead.
//!
//! A slide's copied levels (`InOrder`) send their frames in row-major order: each such
//! instance is written in place instead, the data set and the Pixel Data header first, the
//! Basic Offset Table reserved (zeros) and filled in at the end, every item appended as it
//! comes, so that the disk holds the frames once. Where the offsets pass 32 bits, the instance
//! is written again at the end with the Extended Offset Table, its items copied from the first
//! file as staged ones are.
//!
//! Native frames (`Native`, PS3.5 8.1.1 and A.2) have no items and no offset table: every
//! frame is the same length, one after another, so frame `i` lies at `i` frame lengths from
//! the start of the value, and the element's length is known before the first frame comes:
//!
//! ```text
//! (7FE0,0010) OB or OW, its length   E0 7F 10 00 'O' 'B' 00 00 len (u32 LE, even)
//! frame 0, frame 1, ... row-major    the samples, interleaved, little-endian
//! a 00 pad where len would be odd
//! ```
//!
//! The instance is written in place: the data set and this header first, the file's length
//! set, and each frame written at its place as it comes (no copy at the end; the disk holds
//! the frames once).

use std::fs::{self, File};
use std::io::{self, BufWriter, Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

/// The tag of an item, little-endian.
const ITEM: [u8; 4] = [0xFE, 0xFF, 0x00, 0xE0];
/// The Sequence Delimitation Item, with its zero length.
const DELIMITER: [u8; 8] = [0xFE, 0xFF, 0xDD, 0xE0, 0, 0, 0, 0];
/// The Pixel Data element's header: OB, undefined length.
const PIXEL_DATA: [u8; 12] = [0xE0, 0x7F, 0x10, 0x00, b'O', b'B', 0, 0, 0xFF, 0xFF, 0xFF, 0xFF];

/// Where each frame's item lies in the instance's Pixel Data, from the first frame's item.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(super) struct Offsets {
    /// Each frame's item's offset, row-major.
    pub offsets: Vec<u64>,
    /// Each frame's length (its item's value: the JPEG and its pad).
    pub lengths: Vec<u64>,
}

impl Offsets {
    /// No frames to locate: a native instance's (its frames lie one after another).
    pub fn none() -> Offsets {
        Offsets { offsets: Vec::new(), lengths: Vec::new() }
    }

    /// Whether the offsets fit the Basic Offset Table's 32 bits.
    pub fn fit_basic(&self) -> bool {
        self.offsets.last().is_none_or(|&o| o <= u64::from(u32::MAX))
    }
}

/// One level's frames as they came, in a staging file.
pub(super) struct Staged {
    path: PathBuf,
    file: BufWriter<File>,
    /// Bytes written so far.
    len: u64,
    /// Each frame's item in the staging file, row-major: its offset and its whole length
    /// (header included); length 0 for a frame yet to come.
    items: Vec<(u64, u32)>,
}

impl Staged {
    /// A staging file at `path` for `frames` frames.
    pub fn create(path: &Path, frames: usize) -> io::Result<Staged> {
        let file = fs::OpenOptions::new().read(true).write(true).create_new(true).open(path)?;
        Ok(Staged {
            path: path.to_path_buf(),
            file: BufWriter::with_capacity(1 << 20, file),
            len: 0,
            items: vec![(0, 0); frames],
        })
    }

    /// Appends frame `index` (row-major) as an item. The caller has checked the index.
    pub fn append(&mut self, index: usize, frame: &[u8]) -> io::Result<()> {
        let padded = frame.len() + frame.len() % 2;
        let value = u32::try_from(padded).ok().filter(|&v| v < u32::MAX - 8);
        let value = value.ok_or_else(|| io::Error::other("a frame of 4 GiB or more"))?;
        if self.items[index].1 != 0 {
            return Err(io::Error::other(format!("frame {index} came twice")));
        }
        self.file.write_all(&ITEM)?;
        self.file.write_all(&value.to_le_bytes())?;
        self.file.write_all(frame)?;
        if padded > frame.len() {
            self.file.write_all(&[0])?;
        }
        self.items[index] = (self.len, value + 8);
        self.len += u64::from(value) + 8;
        Ok(())
    }

    /// Where each frame will lie; `None` if one has not come.
    pub fn offsets(&self) -> Option<Offsets> {
        let mut at = 0u64;
        let mut offsets = Vec::with_capacity(self.items.len());
        let mut lengths = Vec::with_capacity(self.items.len());
        for &(_, whole) in &self.items {
            if whole == 0 {
                return None;
            }
            offsets.push(at);
            lengths.push(u64::from(whole) - 8);
            at += u64::from(whole);
        }
        Some(Offsets { offsets, lengths })
    }

    /// Bytes of the frames (their items' values).
    pub fn frame_bytes(&self) -> u64 {
        self.items.iter().map(|&(_, whole)| u64::from(whole).saturating_sub(8)).sum()
    }

    /// Writes the Pixel Data element into `out` (after the data set): its header, the offset
    /// table (`basic`: the offsets, else empty), every frame in row-major order, the
    /// delimiter. Removes the staging file. Returns the bytes written.
    pub fn write_pixel_data(mut self, out: &mut File, offsets: &Offsets, basic: bool) -> io::Result<u64> {
        self.file.flush()?;
        let head = pixel_data_head(basic.then_some(&offsets.offsets[..]));
        out.write_all(&head)?;
        let mut written = head.len() as u64;
        let staged = self.file.get_ref();
        let mut copy = |(from, len): (u64, u64)| -> io::Result<()> {
            copy_range(staged, from, len, out)?;
            written += len;
            Ok(())
        };
        let mut run: Option<(u64, u64)> = None;
        for &(at, whole) in &self.items {
            let whole = u64::from(whole);
            run = match run {
                Some((start, n)) if start + n == at => Some((start, n + whole)),
                Some(done) => {
                    copy(done)?;
                    Some((at, whole))
                }
                None => Some((at, whole)),
            };
        }
        if let Some(done) = run {
            copy(done)?;
        }
        out.write_all(&DELIMITER)?;
        written += DELIMITER.len() as u64;
        let path = std::mem::take(&mut self.path);
        drop(self);
        fs::remove_file(&path)?;
        Ok(written)
    }
}

/// Copies `len` bytes at `from` in `source` to the end of `out`.
fn copy_range(source: &File, from: u64, len: u64, out: &mut File) -> io::Result<()> {
    let mut reader = source;
    reader.seek(SeekFrom::Start(from))?;
    let n = io::copy(&mut reader.take(len), out)?;
    if n != len {
        return Err(io::Error::new(io::ErrorKind::UnexpectedEof, "the staged frames end early"));
    }
    Ok(())
}

/// The Pixel Data element's header and its Basic Offset Table item: `offsets`, or empty.
fn pixel_data_head(offsets: Option<&[u64]>) -> Vec<u8> {
    let offsets = offsets.unwrap_or_default();
    let mut head = Vec::with_capacity(PIXEL_DATA.len() + 8 + 4 * offsets.len());
    head.extend_from_slice(&PIXEL_DATA);
    head.extend_from_slice(&ITEM);
    head.extend_from_slice(&(4 * offsets.len() as u32).to_le_bytes());
    for &o in offsets {
        // The caller checked that each fits (`Offsets::fit_basic`).
        head.extend_from_slice(&(o as u32).to_le_bytes());
    }
    head
}

/// One instance of encapsulated frames that come in row-major order, written in place: its
/// data set and Pixel Data header first, the Basic Offset Table reserved, each frame's item
/// appended as it comes.
pub(super) struct InOrder {
    path: PathBuf,
    file: BufWriter<File>,
    /// Where the Basic Offset Table's values lie in the file.
    table: u64,
    /// Where the first frame's item starts in the file.
    first: u64,
    /// The frames that came: each item's offset from the first's, and its value's length.
    offsets: Offsets,
    frames: usize,
    /// Bytes of the items so far.
    len: u64,
}

impl InOrder {
    /// Starts the instance at `path`: `header` (File Meta and data set up to Pixel Data, of
    /// no Extended Offset Table), then the Pixel Data element's header and a Basic Offset
    /// Table of `frames` offsets, zeros until `finish`.
    pub fn create(path: &Path, header: &[u8], frames: usize) -> io::Result<InOrder> {
        if frames.checked_mul(4).is_none_or(|n| n > u32::MAX as usize - 8) {
            return Err(io::Error::other(format!("{frames} frames: more than a Basic Offset Table lists")));
        }
        let file = fs::OpenOptions::new().read(true).write(true).create_new(true).open(path)?;
        let mut file = BufWriter::with_capacity(1 << 20, file);
        file.write_all(header)?;
        let zeros = vec![0u64; frames];
        let head = pixel_data_head(Some(&zeros));
        file.write_all(&head)?;
        let (table, first) = ((header.len() + PIXEL_DATA.len() + 8) as u64, (header.len() + head.len()) as u64);
        let offsets = Offsets { offsets: Vec::with_capacity(frames), lengths: Vec::with_capacity(frames) };
        Ok(InOrder { path: path.to_path_buf(), file, table, first, offsets, frames, len: 0 })
    }

    /// Appends frame `index` as an item: the next in row-major order, or an error.
    pub fn append(&mut self, index: usize, frame: &[u8]) -> io::Result<()> {
        let next = self.offsets.offsets.len();
        if index != next || next >= self.frames {
            return Err(io::Error::other(format!("frame {index} came where frame {next} was due")));
        }
        let padded = frame.len() + frame.len() % 2;
        let value = u32::try_from(padded).ok().filter(|&v| v < u32::MAX - 8);
        let value = value.ok_or_else(|| io::Error::other("a frame of 4 GiB or more"))?;
        self.file.write_all(&ITEM)?;
        self.file.write_all(&value.to_le_bytes())?;
        self.file.write_all(frame)?;
        if padded > frame.len() {
            self.file.write_all(&[0])?;
        }
        self.offsets.offsets.push(self.len);
        self.offsets.lengths.push(u64::from(value));
        self.len += u64::from(value) + 8;
        Ok(())
    }

    /// Where each frame lies; `None` if one has not come.
    pub fn offsets(&self) -> Option<&Offsets> {
        (self.offsets.offsets.len() == self.frames).then_some(&self.offsets)
    }

    /// Bytes of the frames (their items' values).
    pub fn frame_bytes(&self) -> u64 {
        self.offsets.lengths.iter().sum()
    }

    /// Ends the instance, every frame come: the delimiter, then the offsets into the table
    /// where they fit 32 bits; else (`extended`: the data set with the Extended Offset Table)
    /// the instance is written again, the items copied behind an empty table. Returns the
    /// file's length.
    pub fn finish(self, extended: Option<&[u8]>) -> io::Result<u64> {
        let InOrder { path, file, table, first, offsets, len, .. } = self;
        let mut file = file.into_inner().map_err(|e| e.into_error())?;
        file.write_all(&DELIMITER)?;
        let Some(header) = extended else {
            let values: Vec<u8> = offsets.offsets.iter().flat_map(|&o| (o as u32).to_le_bytes()).collect();
            file.seek(SeekFrom::Start(table))?;
            file.write_all(&values)?;
            file.sync_all()?;
            return Ok(first + len + DELIMITER.len() as u64);
        };
        let again = path.with_extension("extended");
        let mut out = fs::OpenOptions::new().write(true).create_new(true).open(&again)?;
        let head = pixel_data_head(None);
        out.write_all(header)?;
        out.write_all(&head)?;
        copy_range(&file, first, len, &mut out)?;
        out.write_all(&DELIMITER)?;
        out.sync_all()?;
        drop(file);
        fs::rename(&again, &path)?;
        Ok((header.len() + head.len() + DELIMITER.len()) as u64 + len)
    }
}

/// One native instance being written in place: its data set and Pixel Data header written,
/// each frame written at its place as it comes.
pub(super) struct Native {
    file: File,
    /// Where frame 0 starts in the file.
    start: u64,
    /// Bytes of each frame.
    frame_len: u64,
    /// Which frames came, row-major.
    came: Vec<bool>,
    /// Frames yet to come.
    left: usize,
    /// The file's length once complete.
    len: u64,
}

impl Native {
    /// Starts the instance at `path`: `header` (File Meta and data set up to Pixel Data),
    /// then the Pixel Data element of `frames` frames of `frame_len` bytes, OW where the
    /// samples are 16-bit (`wide`), else OB. Refuses a value past the 32-bit length.
    pub fn create(path: &Path, header: &[u8], frames: usize, frame_len: u64, wide: bool) -> io::Result<Native> {
        let value =
            (frames as u64).checked_mul(frame_len).ok_or_else(|| io::Error::other("a Pixel Data past 64 bits"))?;
        let padded = value + value % 2;
        let length = u32::try_from(padded)
            .ok()
            .filter(|&l| u64::from(l) <= super::NATIVE_MOST_BYTES)
            .ok_or_else(|| io::Error::other(format!("{padded} bytes of Pixel Data, past a 32-bit length")))?;
        let mut file = fs::OpenOptions::new().read(true).write(true).create_new(true).open(path)?;
        file.write_all(header)?;
        let vr = if wide { b"OW" } else { b"OB" };
        let mut element = PIXEL_DATA[..4].to_vec();
        element.extend_from_slice(vr);
        element.extend_from_slice(&[0, 0]);
        element.extend_from_slice(&length.to_le_bytes());
        file.write_all(&element)?;
        let start = (header.len() + element.len()) as u64;
        let len = start + padded;
        // The frames' place, zeros (and the pad) until they come.
        file.set_len(len)?;
        Ok(Native { file, start, frame_len, came: vec![false; frames], left: frames, len })
    }

    /// Writes frame `index` (row-major) at its place. The caller has checked the index.
    pub fn put(&mut self, index: usize, frame: &[u8]) -> io::Result<()> {
        if frame.len() as u64 != self.frame_len {
            return Err(io::Error::other(format!(
                "frame {index} is {} bytes, not the {} of a native frame",
                frame.len(),
                self.frame_len
            )));
        }
        if std::mem::replace(&mut self.came[index], true) {
            return Err(io::Error::other(format!("frame {index} came twice")));
        }
        self.file.seek(SeekFrom::Start(self.start + index as u64 * self.frame_len))?;
        self.file.write_all(frame)?;
        self.left -= 1;
        Ok(())
    }

    /// Frames the instance holds.
    pub fn frames(&self) -> u64 {
        self.came.len() as u64
    }

    /// Bytes of the frames.
    pub fn frame_bytes(&self) -> u64 {
        self.came.len() as u64 * self.frame_len
    }

    /// Ends the instance: every frame must have come. Returns the file's length.
    pub fn finish(self) -> io::Result<u64> {
        if self.left != 0 {
            let first = self.came.iter().position(|c| !c).unwrap_or_default();
            return Err(io::Error::other(format!("{} frames never came, frame {first} the first", self.left)));
        }
        self.file.sync_all()?;
        Ok(self.len)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Frames that come out of order are written row-major, each an item padded to even,
    /// behind a Basic Offset Table of their items' offsets.
    #[test]
    fn frames_come_out_row_major_behind_their_offsets() {
        let dir = tempfile::tempdir().unwrap();
        let mut staged = Staged::create(&dir.path().join("s"), 3).unwrap();
        assert_eq!(staged.offsets(), None, "frames yet to come");
        staged.append(2, b"ccc").unwrap();
        staged.append(0, b"a").unwrap();
        staged.append(1, b"bbbb").unwrap();
        assert!(staged.append(1, b"bb").is_err(), "a frame twice");
        let offsets = staged.offsets().unwrap();
        assert_eq!(offsets, Offsets { offsets: vec![0, 10, 22], lengths: vec![2, 4, 4] });
        assert!(offsets.fit_basic());
        let path = dir.path().join("out");
        let mut out = File::create(&path).unwrap();
        let n = staged.write_pixel_data(&mut out, &offsets, true).unwrap();
        drop(out);
        let bytes = fs::read(&path).unwrap();
        assert_eq!(n, bytes.len() as u64);
        let mut want = PIXEL_DATA.to_vec();
        want.extend_from_slice(&[0xFE, 0xFF, 0x00, 0xE0, 12, 0, 0, 0, 0, 0, 0, 0, 10, 0, 0, 0, 22, 0, 0, 0]);
        want.extend_from_slice(&[0xFE, 0xFF, 0x00, 0xE0, 2, 0, 0, 0, b'a', 0]);
        want.extend_from_slice(&[0xFE, 0xFF, 0x00, 0xE0, 4, 0, 0, 0, b'b', b'b', b'b', b'b']);
        want.extend_from_slice(&[0xFE, 0xFF, 0x00, 0xE0, 4, 0, 0, 0, b'c', b'c', b'c', 0]);
        want.extend_from_slice(&DELIMITER);
        assert_eq!(bytes, want);
        assert!(!dir.path().join("s").exists(), "the staging file is removed");

        let far = Offsets { offsets: vec![0, 1 << 32], lengths: vec![1, 1] };
        assert!(!far.fit_basic(), "past 32 bits: the Extended Offset Table");
    }

    /// Frames written in place as they come in order make the instance staged frames make,
    /// byte for byte; one out of order is refused; past 32 bits the instance is written again
    /// with the header given and an empty Basic Offset Table.
    #[test]
    fn frames_in_order_are_written_in_place_as_staged_ones_are() {
        let dir = tempfile::tempdir().unwrap();
        let frames: [&[u8]; 3] = [b"a", b"bbbb", b"ccc"];
        let mut staged = Staged::create(&dir.path().join("s"), 3).unwrap();
        let in_place = dir.path().join("in-place.dcm");
        let mut in_order = InOrder::create(&in_place, b"HEAD", 3).unwrap();
        assert!(in_order.append(1, b"bbbb").is_err(), "frame 1 before frame 0");
        for (i, frame) in frames.iter().enumerate() {
            staged.append(i, frame).unwrap();
            assert!(in_order.offsets().is_none(), "frames yet to come");
            in_order.append(i, frame).unwrap();
        }
        assert!(in_order.append(3, b"d").is_err(), "a fourth frame of three");
        let offsets = staged.offsets().unwrap();
        assert_eq!(in_order.offsets(), Some(&offsets));
        assert_eq!(in_order.frame_bytes(), staged.frame_bytes());
        let n = in_order.finish(None).unwrap();
        let want_path = dir.path().join("staged.dcm");
        let mut want = File::create(&want_path).unwrap();
        want.write_all(b"HEAD").unwrap();
        staged.write_pixel_data(&mut want, &offsets, true).unwrap();
        drop(want);
        let (got, want) = (fs::read(&in_place).unwrap(), fs::read(&want_path).unwrap());
        assert_eq!(got, want);
        assert_eq!(n, got.len() as u64);

        // Past 32 bits (here: the caller says so by giving the Extended Offset Table's header).
        let far = dir.path().join("far.dcm");
        let mut in_order = InOrder::create(&far, b"HEAD", 2).unwrap();
        in_order.append(0, b"x").unwrap();
        in_order.append(1, b"yy").unwrap();
        let n = in_order.finish(Some(b"HEAD+EOT")).unwrap();
        let mut want = b"HEAD+EOT".to_vec();
        want.extend_from_slice(&PIXEL_DATA);
        want.extend_from_slice(&[0xFE, 0xFF, 0x00, 0xE0, 0, 0, 0, 0]);
        want.extend_from_slice(&[
            0xFE, 0xFF, 0x00, 0xE0, 2, 0, 0, 0, b'x', 0, 0xFE, 0xFF, 0x00, 0xE0, 2, 0, 0, 0, b'y', b'y',
        ]);
        want.extend_from_slice(&DELIMITER);
        assert_eq!(fs::read(&far).unwrap(), want);
        assert_eq!(n, want.len() as u64);
        assert_eq!(fs::read_dir(dir.path()).unwrap().count(), 3, "no second file left");
    }

    /// Native frames that come out of order lie row-major after the element's header, OB for
    /// 8-bit samples, its length the frames' padded to even; a frame of another length, or
    /// twice, is refused; an instance lacking a frame does not finish.
    #[test]
    fn native_frames_lie_row_major_in_place() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("n.dcm");
        let mut native = Native::create(&path, b"HEAD", 3, 3, false).unwrap();
        native.put(2, b"ccc").unwrap();
        native.put(0, b"aaa").unwrap();
        assert!(native.put(1, b"bb").is_err(), "a short frame");
        assert!(native.put(0, b"aaa").is_err(), "a frame twice");
        native.put(1, b"bbb").unwrap();
        assert_eq!(native.frame_bytes(), 9);
        let n = native.finish().unwrap();
        let bytes = fs::read(&path).unwrap();
        assert_eq!(n, bytes.len() as u64);
        let mut want = b"HEAD".to_vec();
        want.extend_from_slice(&[0xE0, 0x7F, 0x10, 0x00, b'O', b'B', 0, 0, 10, 0, 0, 0]);
        want.extend_from_slice(b"aaabbbccc\0");
        assert_eq!(bytes, want);

        // 16-bit samples: OW, even already.
        let wide = dir.path().join("w.dcm");
        let mut native = Native::create(&wide, b"", 1, 4, true).unwrap();
        native.put(0, &[1, 0, 2, 0]).unwrap();
        native.finish().unwrap();
        assert_eq!(fs::read(&wide).unwrap(), [0xE0, 0x7F, 0x10, 0x00, b'O', b'W', 0, 0, 4, 0, 0, 0, 1, 0, 2, 0]);

        let short = Native::create(&dir.path().join("s.dcm"), b"", 2, 2, false).unwrap();
        assert!(short.finish().unwrap_err().to_string().contains("frame 0 the first"));
        let past = Native::create(&dir.path().join("p.dcm"), b"", 1 << 20, 1 << 12, false);
        assert!(past.is_err(), "4 GiB of frames");
    }
}
