//! Where a [`PackWriter`](crate::PackWriter) puts a pack's bytes: [`PackOutput`], which a local
//! file ([`PackFile`], what [`PackWriter::create`](crate::PackWriter::create) writes) and a
//! caller's own destination (an upload sent as it is made) implement.
//!
//! A pack is written in one pass: the payloads are appended after the data section's start,
//! in the order they come, and the head (header, level table, index, metadata, padding), which
//! only the end of the run knows, is handed over last. So an output needs no seeking back: it
//! may hold the head's place and send everything else as it comes.

use std::fs::{self, File, OpenOptions};
use std::io::{Seek, SeekFrom, Write};
use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};

use crate::format::HEADER_LEN;
use crate::writeback::Writeback;

/// The destination of a pack being written by a [`PackWriter`](crate::PackWriter).
///
/// The writer calls [`append`](Self::append) with strictly increasing offsets, all at or past
/// the data section's start (the first is the data section's start), then
/// [`complete`](Self::complete) once with the head; nothing else is written. An output that is
/// dropped without being completed must leave no pack behind (or, for a file kept for a later
/// resume, one whose zeroed header says it is unfinished).
pub trait PackOutput {
    /// What errors name: the file, or the object's URL.
    fn name(&self) -> &Path;

    /// Stores `bytes` at `offset`, which is at or past the end of what was stored; the bytes
    /// between are zeros.
    fn append(&mut self, offset: u64, bytes: &[u8]) -> std::io::Result<()>;

    /// Whether the bytes stored at `offset` (a payload appended earlier) are known to equal
    /// `bytes`: `false` when they differ, and when the output can no longer tell; the writer
    /// then stores `bytes` again. A local file compares them byte for byte; an output that
    /// sent them away may compare a cryptographic digest of them (never a checksum alone).
    fn holds(&mut self, offset: u64, bytes: &[u8]) -> std::io::Result<bool>;

    /// Moves the `len` bytes at `from` down to `to` (`to < from`), if this output can: `false`
    /// (nothing moved) if it cannot, as an output that sent them away. The writer asks so when
    /// shorter metadata than planned left room before the data section.
    fn move_down(&mut self, from: u64, to: u64, len: u64) -> std::io::Result<bool> {
        let _ = (from, to, len);
        Ok(false)
    }

    /// Completes the pack: `len` bytes in all, the first of which are `head` (the header's
    /// [`HEADER_LEN`] bytes, then the tables and the padding up to the data section). The
    /// header must become durable or visible no sooner than everything else: it is what marks
    /// a pack complete.
    fn complete(&mut self, len: u64, head: &[u8]) -> std::io::Result<()>;
}

/// A boxed output: writers of outputs chosen at run time as one type
/// ([`PackWriter::boxed`](crate::PackWriter::boxed)).
impl<O: PackOutput + ?Sized> PackOutput for Box<O> {
    fn name(&self) -> &Path {
        (**self).name()
    }

    fn append(&mut self, offset: u64, bytes: &[u8]) -> std::io::Result<()> {
        (**self).append(offset, bytes)
    }

    fn holds(&mut self, offset: u64, bytes: &[u8]) -> std::io::Result<bool> {
        (**self).holds(offset, bytes)
    }

    fn move_down(&mut self, from: u64, to: u64, len: u64) -> std::io::Result<bool> {
        (**self).move_down(from, to, len)
    }

    fn complete(&mut self, len: u64, head: &[u8]) -> std::io::Result<()> {
        (**self).complete(len, head)
    }
}

/// A pack written to a local file under a temporary name beside its destination
/// ([`temporary_path`](crate::temporary_path)), renamed into place when complete: the output of
/// [`PackWriter::create`](crate::PackWriter::create) and
/// [`PackWriter::resume`](crate::PackWriter::resume). Dropped incomplete, it deletes the
/// temporary file, unless asked to keep it for a later resume.
#[derive(Debug)]
pub struct PackFile {
    dest: PathBuf,
    tmp: PathBuf,
    file: File,
    /// Where the next append would start writing without a seek.
    at: u64,
    writeback: Writeback,
    /// Leave the temporary file when dropped incomplete.
    keep: bool,
    /// Renamed into place: nothing to delete.
    done: bool,
}

impl PackFile {
    /// Creates `tmp`, empty, for `dest`.
    pub(crate) fn create(dest: &Path, tmp: PathBuf) -> std::io::Result<PackFile> {
        let file = OpenOptions::new()
            .write(true)
            .read(true)
            .create(true)
            .truncate(true)
            .open(&tmp)
            .map_err(|e| std::io::Error::new(e.kind(), format!("cannot create {}: {e}", tmp.display())))?;
        Ok(PackFile::of(dest, tmp, file))
    }

    /// Opens `tmp`, the file an earlier writer of `dest` left, as it is.
    pub(crate) fn reopen(dest: &Path, tmp: PathBuf) -> std::io::Result<PackFile> {
        let file = OpenOptions::new().write(true).read(true).open(&tmp)?;
        Ok(PackFile::of(dest, tmp, file))
    }

    fn of(dest: &Path, tmp: PathBuf, file: File) -> PackFile {
        let writeback = Writeback::default();
        PackFile { dest: dest.to_path_buf(), tmp, file, at: 0, writeback, keep: false, done: false }
    }

    /// The open file, for a resumed writer's checks.
    pub(crate) fn file(&self) -> &File {
        &self.file
    }

    /// Cuts (or extends with zeros) the file to `len` bytes, the next append's position.
    pub(crate) fn truncate(&mut self, len: u64) -> std::io::Result<()> {
        self.file.set_len(len)?;
        self.file.seek(SeekFrom::Start(len))?;
        self.at = len;
        Ok(())
    }

    /// Leave the temporary file when dropped incomplete.
    pub(crate) fn keep_on_drop(&mut self) {
        self.keep = true;
    }
}

impl PackOutput for PackFile {
    fn name(&self) -> &Path {
        &self.tmp
    }

    fn append(&mut self, offset: u64, bytes: &[u8]) -> std::io::Result<()> {
        let pad = offset
            .checked_sub(self.at)
            .ok_or_else(|| std::io::Error::other(format!("an append at byte {offset}, before the end {}", self.at)))?;
        if pad > 65536 {
            self.file.seek(SeekFrom::Start(offset))?;
        } else {
            self.file.write_all(&[0u8; 65536][..pad as usize])?;
        }
        self.file.write_all(bytes)?;
        self.at = offset + bytes.len() as u64;
        self.writeback.written(&self.file, self.at);
        Ok(())
    }

    fn holds(&mut self, offset: u64, bytes: &[u8]) -> std::io::Result<bool> {
        let mut buf = vec![0u8; bytes.len()];
        self.file.read_exact_at(&mut buf, offset)?;
        Ok(buf == bytes)
    }

    fn move_down(&mut self, from: u64, to: u64, len: u64) -> std::io::Result<bool> {
        // Front to back: every chunk lands below where it was read.
        let mut chunk = vec![0u8; (1u64 << 20).min(len) as usize];
        let mut done = 0;
        while done < len {
            let n = chunk.len().min((len - done) as usize);
            self.file.read_exact_at(&mut chunk[..n], from + done)?;
            self.file.write_all_at(&chunk[..n], to + done)?;
            done += n as u64;
        }
        self.at -= from - to;
        Ok(true)
    }

    /// Pads the file to `len`, writes the tables, syncs, writes the header, syncs again and
    /// renames the file into place.
    fn complete(&mut self, len: u64, head: &[u8]) -> std::io::Result<()> {
        let (header, tables) = head.split_at(HEADER_LEN.min(head.len()));
        // Pad the end so that the data section ends the file exactly (the padding of a
        // zero-payload pack is the data section itself).
        self.file.set_len(len)?;
        self.file.write_all_at(tables, header.len() as u64)?;
        self.file.sync_data()?;
        self.file.write_all_at(header, 0)?;
        self.file.sync_all()?;
        fs::rename(&self.tmp, &self.dest)
            .map_err(|e| std::io::Error::new(e.kind(), format!("cannot rename it to {}: {e}", self.dest.display())))?;
        self.done = true;
        if let Some(dir) = self.dest.parent().filter(|d| !d.as_os_str().is_empty()) {
            // Make the rename itself durable; not all file systems allow syncing a directory.
            let _ = File::open(dir).and_then(|d| d.sync_all());
        }
        Ok(())
    }
}

impl Drop for PackFile {
    fn drop(&mut self) {
        if !self.done && !self.keep {
            let _ = fs::remove_file(&self.tmp);
        }
    }
}
