//! Where each frame of an instance lies in its file: the items of encapsulated Pixel Data
//! (PS3.5 A.4) walked header by header, or the native Pixel Data cut into frames.
//!
//! Encapsulated: the first item is the Basic Offset Table (empty, or one 32-bit offset per
//! frame), then one item per fragment up to the sequence delimiter. A frame here is one
//! fragment (as every whole-slide writer stores them); a frame split over several fragments is
//! refused by name. The offset tables (the basic one, and the Extended Offset Table before the
//! Pixel Data) are not trusted: each entry is checked against the item the walk found, so a
//! wrong table is reported, not followed. Every length is checked against the file's size
//! before anything is read or allocated.

use std::fs::File;
use std::io::{BufReader, Read, Seek, SeekFrom};
use std::path::Path;

use crate::error::{Result, TilerError};

/// The item tag (FFFE,E000) and the sequence delimiter (FFFE,E0DD), as little-endian bytes.
const ITEM: [u8; 4] = [0xFE, 0xFF, 0x00, 0xE0];
const SEQUENCE_END: [u8; 4] = [0xFE, 0xFF, 0xDD, 0xE0];

/// Each frame's bytes in the file.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub(crate) struct Frames {
    pub offsets: Vec<u64>,
    pub counts: Vec<u64>,
}

/// The offset tables an instance may carry, as read.
pub(crate) struct Tables<'a> {
    /// The Extended Offset Table (7FE0,0001) and its lengths (7FE0,0002), 64-bit each.
    pub extended: Option<(&'a [u64], &'a [u64])>,
}

/// The `frames` frames of the encapsulated Pixel Data whose first item header is at
/// `items_at` in `path` (`file_len` bytes).
pub(crate) fn encapsulated(path: &Path, items_at: u64, file_len: u64, frames: u64, tables: Tables) -> Result<Frames> {
    let bad = |what: String| TilerError::decode(path, format!("Pixel Data (7FE0,0010): {what}"));
    // Each frame is an item of at least its 8-byte header.
    if frames > file_len.saturating_sub(items_at) / 8 {
        return Err(bad(format!(
            "{frames} frames cannot fit in the {} bytes left in the file: a truncated file or a wrong Number of Frames",
            file_len.saturating_sub(items_at)
        )));
    }
    let mut file = File::open(path).map_err(|e| TilerError::io(path, e))?;
    file.seek(SeekFrom::Start(items_at)).map_err(|e| TilerError::io(path, e))?;
    let mut reader = BufReader::new(file);
    let mut at = items_at;
    let header = |reader: &mut BufReader<File>, at: u64, what: &str| -> Result<([u8; 4], u64)> {
        let mut bytes = [0u8; 8];
        reader.read_exact(&mut bytes).map_err(|_| {
            bad(format!("the file ends at byte {file_len} before {what}'s item header (at {at}): a truncated file?"))
        })?;
        let len = u32::from_le_bytes([bytes[4], bytes[5], bytes[6], bytes[7]]) as u64;
        Ok(([bytes[0], bytes[1], bytes[2], bytes[3]], len))
    };
    let (tag, bot_len) = header(&mut reader, at, "the Basic Offset Table")?;
    if tag != ITEM {
        return Err(bad(format!("expected the Basic Offset Table's item at byte {at}, found tag {}", show(tag))));
    }
    if bot_len != 0 && bot_len != frames * 4 {
        return Err(bad(format!(
            "the Basic Offset Table holds {bot_len} bytes; {frames} frames need 0 or {}",
            frames * 4
        )));
    }
    let mut bot = vec![0u8; bot_len as usize];
    reader
        .read_exact(&mut bot)
        .map_err(|_| bad("the file ends inside the Basic Offset Table: a truncated file?".into()))?;
    at += 8 + bot_len;
    let first_item = at;
    let mut out = Frames { offsets: Vec::with_capacity(frames as usize), counts: Vec::with_capacity(frames as usize) };
    loop {
        let k = out.offsets.len() as u64;
        let (tag, len) = header(&mut reader, at, &format!("frame {k}"))?;
        if tag == SEQUENCE_END {
            break;
        }
        if tag != ITEM {
            return Err(bad(format!("expected frame {k}'s item at byte {at}, found tag {}", show(tag))));
        }
        if k == frames {
            return Err(TilerError::unsupported(
                path,
                format!(
                    "Pixel Data (7FE0,0010): more fragments than its {frames} frames: frames split over several fragments are not read"
                ),
            ));
        }
        let value = at + 8;
        if len == u32::MAX as u64 || value + len > file_len {
            return Err(bad(format!(
                "frame {k}: its {len} bytes at byte {value} run past the end of the file ({file_len} bytes): a truncated file?"
            )));
        }
        let relative = at - first_item;
        if !bot.is_empty() {
            let entry = u32::from_le_bytes(bot[k as usize * 4..][..4].try_into().unwrap_or_default()) as u64;
            if entry != relative {
                return Err(bad(format!(
                    "the Basic Offset Table puts frame {k} at byte {entry} of the fragments, its item is at {relative}: a wrong offset table"
                )));
            }
        }
        if let Some((offsets, lengths)) = tables.extended {
            let (entry, length) = (offsets.get(k as usize).copied(), lengths.get(k as usize).copied());
            if entry != Some(relative) || length != Some(len) {
                return Err(bad(format!(
                    "the Extended Offset Table puts frame {k} at byte {} ({} bytes), its item is at {relative} ({len} bytes): a wrong offset table",
                    entry.map_or("(none)".into(), |e| e.to_string()),
                    length.map_or("(none)".into(), |e| e.to_string())
                )));
            }
        }
        out.offsets.push(value);
        out.counts.push(len);
        reader.seek_relative(len as i64).map_err(|e| TilerError::io(path, e))?;
        at = value + len;
    }
    if (out.offsets.len() as u64) < frames {
        return Err(bad(format!("{} fragments for {frames} frames: frames are missing", out.offsets.len())));
    }
    Ok(out)
}

/// The `frames` frames of `frame_bytes` each that native Pixel Data of `len` bytes at `at` holds.
pub(crate) fn native(path: &Path, at: u64, len: u64, frames: u64, frame_bytes: u64) -> Result<Frames> {
    if frames.checked_mul(frame_bytes).is_none_or(|need| need > len) {
        return Err(TilerError::decode(
            path,
            format!(
                "Pixel Data (7FE0,0010) holds {len} bytes, {frames} frames of {frame_bytes} bytes need more: a truncated file?"
            ),
        ));
    }
    let offsets = (0..frames).map(|k| at + k * frame_bytes).collect();
    Ok(Frames { offsets, counts: vec![frame_bytes; frames as usize] })
}

/// A tag's bytes as DICOM writes it.
fn show(tag: [u8; 4]) -> String {
    format!("({:02X}{:02X},{:02X}{:02X})", tag[1], tag[0], tag[3], tag[2])
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Encapsulated items: the offset table `bot`, then one fragment of each length, then the
    /// delimiter (unless `end` is false).
    fn items(bot: &[u32], fragments: &[u32], end: bool) -> Vec<u8> {
        let mut out = ITEM.to_vec();
        out.extend((bot.len() as u32 * 4).to_le_bytes());
        out.extend(bot.iter().flat_map(|o| o.to_le_bytes()));
        for &len in fragments {
            out.extend(ITEM);
            out.extend(len.to_le_bytes());
            out.extend(vec![0xAB; len as usize]);
        }
        if end {
            out.extend(SEQUENCE_END);
            out.extend([0; 4]);
        }
        out
    }

    fn walk(bytes: &[u8], frames: u64) -> Result<Frames> {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("f.dcm");
        std::fs::write(&path, bytes).unwrap();
        encapsulated(&path, 0, bytes.len() as u64, frames, Tables { extended: None })
    }

    #[test]
    fn items_are_walked_and_the_offset_table_checked() {
        let frames = walk(&items(&[0, 12], &[4, 6], true), 2).unwrap();
        assert_eq!(frames, Frames { offsets: vec![24, 36], counts: vec![4, 6] });
        let said = |r: Result<Frames>| r.unwrap_err().to_string();
        assert!(said(walk(&items(&[0, 10], &[4, 6], true), 2)).contains("frame 1 at byte 10"));
        assert!(said(walk(&items(&[0], &[4, 6], true), 2)).contains("need 0 or 8"));
        assert!(said(walk(&items(&[], &[4, 6, 2], true), 2)).contains("more fragments than its 2 frames"));
        assert!(said(walk(&items(&[], &[4], true), 2)).contains("1 fragments for 2 frames"));
        let mut cut = items(&[], &[4, 6], false);
        cut.truncate(cut.len() - 3);
        assert!(said(walk(&cut, 2)).contains("frame 1: its 6 bytes"));
        // A frame count the file cannot hold is refused before anything is allocated.
        assert!(said(walk(&items(&[], &[4], true), u32::MAX as u64)).contains("cannot fit"));
    }
}
