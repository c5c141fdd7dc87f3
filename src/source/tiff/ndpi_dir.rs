//! An NDPI directory read by hand, for what the `tiff` crate cannot see in it: the high 32 bits
//! of its offsets and the restart-interval offset table.
//!
//! NDPI is classic TIFF (12-byte entries, 32-bit value fields) whose files pass 4 GiB. Hamamatsu
//! widens its offsets without changing the entries: the header's first-directory offset and each
//! directory's next-directory offset take 8 bytes, and after the next-directory offset every
//! directory holds one more 32-bit word per entry, the high half of that entry's value or offset
//! (as OpenSlide and tifffile read it). The layout is recognised as OpenSlide does: the header's
//! 8-byte offset leads to a directory, read that way, holding the NDPI tag; otherwise the file is
//! laid out as plain classic TIFF (high halves 0).
//!
//! The offset table (McuStarts, tag 65426, high halves in 65432) gives, for each restart
//! interval of the strip's JPEG, where its entropy-coded data starts, from the start of the strip:
//! with it an interval is read where it lies, and the intervals before it are not scanned.

use std::fs::File;
use std::os::unix::fs::FileExt;
use std::path::Path;

use crate::error::{Result, TilerError};

/// Hamamatsu's format flag: present in every NDPI directory.
const NDPI_FORMAT_FLAG: u16 = 65420;
/// The offset table's low and high 32 bits.
const MCU_STARTS: u16 = 65426;
const MCU_STARTS_HIGH: u16 = 65432;
const LONG: u16 = 4;

/// A field of the directory: its type, count and value field widened by its high half.
#[derive(Clone, Copy)]
struct Field {
    kind: u16,
    count: u32,
    /// The value field: the value itself where it fits in 4 bytes, else where the values are.
    value: u64,
    /// The value field's 4 bytes as stored (for values held in it).
    inline: [u8; 4],
}

/// What one directory says about its strip.
pub(super) struct Directory {
    big_endian: bool,
    /// The one strip's offset and byte count, high halves included.
    pub strip: Option<(u64, u64)>,
    starts: Option<Field>,
    starts_high: Option<Field>,
}

impl Directory {
    /// Reads directory `page` of the main chain; `Err` where the file is no NDPI that can be
    /// read so (the caller keeps the `tiff` crate's reading then).
    pub fn read(file: &File, file_len: u64, page: usize) -> std::result::Result<Directory, String> {
        let mut head = [0u8; 12];
        file.read_exact_at(&mut head, 0).map_err(|e| format!("its header cannot be read: {e}"))?;
        let big_endian = match &head[..4] {
            b"II*\0" => false,
            b"MM\0*" => true,
            _ => return Err("not a classic TIFF".into()),
        };
        let reader = Reader { file, file_len, big_endian };
        let wide_first = reader.u64(&head[4..12]);
        let wide =
            reader.entries(wide_first, true).is_ok_and(|(fields, _)| fields.iter().any(|f| f.0 == NDPI_FORMAT_FLAG));
        let mut at = if wide { wide_first } else { reader.u32(&head[4..8]) as u64 };
        let mut fields = Vec::new();
        for index in 0..=page {
            let (these, next) = reader.entries(at, wide)?;
            (fields, at) = (these, next);
            if index < page && at == 0 {
                return Err(format!("it has no directory {page}"));
            }
        }
        let find = |tag: u16| fields.iter().find(|f| f.0 == tag).map(|f| f.1);
        let one = |tag| find(tag).filter(|f| f.count == 1 && matches!(f.kind, 3 | LONG | 16)).map(|f| f.value);
        let strip = one(273).zip(one(279));
        Ok(Directory { big_endian, strip, starts: find(MCU_STARTS), starts_high: find(MCU_STARTS_HIGH) })
    }

    /// The offset table (where each of `intervals` restart intervals starts, from the strip's
    /// start), or why it cannot be used: absent, of another length, or not in order within the
    /// strip's `data_start..len`.
    pub fn mcu_starts(
        &self,
        file: &File,
        file_len: u64,
        intervals: u64,
        data: (u64, u64),
    ) -> std::result::Result<Vec<u64>, String> {
        let reader = Reader { file, file_len, big_endian: self.big_endian };
        let low = self.starts.ok_or("no offset table (tag 65426)")?;
        let longs = |field: Field| -> std::result::Result<Vec<u32>, String> {
            if field.kind != LONG || field.count as u64 != intervals {
                return Err(format!(
                    "its offset table has {} entries of type {}, not {intervals} LONGs (one per restart interval)",
                    field.count, field.kind
                ));
            }
            reader.longs(field)
        };
        let high = match self.starts_high {
            Some(field) => longs(field)?,
            None => vec![0; intervals as usize],
        };
        let starts: Vec<u64> = longs(low)?.iter().zip(high).map(|(&l, h)| l as u64 | (h as u64) << 32).collect();
        // Each interval but the first follows a 2-byte restart marker.
        let (data_start, len) = data;
        let ordered = starts.windows(2).all(|w| w[1] >= w[0] + 2) && starts.last().is_some_and(|&l| l < len);
        if starts.first() != Some(&data_start) || !ordered {
            return Err("its offset table (tag 65426) is not in order within the strip's JPEG data".into());
        }
        Ok(starts)
    }
}

struct Reader<'a> {
    file: &'a File,
    file_len: u64,
    big_endian: bool,
}

impl Reader<'_> {
    fn u32(&self, b: &[u8]) -> u32 {
        let b = [b[0], b[1], b[2], b[3]];
        if self.big_endian { u32::from_be_bytes(b) } else { u32::from_le_bytes(b) }
    }

    fn u64(&self, b: &[u8]) -> u64 {
        let (first, second) = (self.u32(&b[..4]) as u64, self.u32(&b[4..8]) as u64);
        if self.big_endian { first << 32 | second } else { second << 32 | first }
    }

    fn read(&self, at: u64, len: u64) -> std::result::Result<Vec<u8>, String> {
        if at.checked_add(len).is_none_or(|end| end > self.file_len) {
            return Err(format!("{len} bytes at {at} lie past the end of the file ({} bytes)", self.file_len));
        }
        let mut buf = vec![0u8; len as usize];
        self.file.read_exact_at(&mut buf, at).map_err(|e| format!("{len} bytes at {at} cannot be read: {e}"))?;
        Ok(buf)
    }

    /// The (tag, field) entries of the directory at `at`, and the next directory's offset.
    fn entries(&self, at: u64, wide: bool) -> std::result::Result<(Vec<(u16, Field)>, u64), String> {
        if at == 0 {
            return Err("a directory offset of 0".into());
        }
        let count = self.read(at, 2)?;
        let n = if self.big_endian {
            u16::from_be_bytes([count[0], count[1]])
        } else {
            u16::from_le_bytes([count[0], count[1]])
        } as u64;
        let next_size = if wide { 8 } else { 4 };
        let body = self.read(at + 2, 12 * n + next_size + if wide { 4 * n } else { 0 })?;
        let (entries, rest) = body.split_at(12 * n as usize);
        let next = if wide { self.u64(rest) } else { self.u32(rest) as u64 };
        let highs = &rest[next_size as usize..];
        let fields = entries
            .chunks_exact(12)
            .enumerate()
            .map(|(i, e)| {
                let short = |b: &[u8]| {
                    if self.big_endian { u16::from_be_bytes([b[0], b[1]]) } else { u16::from_le_bytes([b[0], b[1]]) }
                };
                let high = if wide { self.u32(&highs[4 * i..]) as u64 } else { 0 };
                let inline = [e[8], e[9], e[10], e[11]];
                let kind = short(&e[2..4]);
                // A SHORT held in the field is its first two bytes.
                let low = if kind == 3 { short(&e[8..10]) as u64 } else { self.u32(&e[8..12]) as u64 };
                (short(&e[..2]), Field { kind, count: self.u32(&e[4..8]), value: low | high << 32, inline })
            })
            .collect();
        Ok((fields, next))
    }

    /// A LONG field's values (in its value field where one fits, else where it points).
    fn longs(&self, field: Field) -> std::result::Result<Vec<u32>, String> {
        let bytes = match field.count {
            0 => Vec::new(),
            1 => field.inline.to_vec(),
            n => self.read(field.value, 4 * n as u64)?,
        };
        Ok(bytes.chunks_exact(4).map(|b| self.u32(b)).collect())
    }
}

/// Refuses an NDPI file whose directories lie past 4 GiB (Hamamatsu may write them after the
/// data): the `tiff` crate follows 32-bit directory offsets only and would read other bytes as
/// a directory. Files of 4 GiB or less are not looked at.
pub(super) fn check_reachable(path: &Path) -> Result<()> {
    let file = File::open(path).map_err(|e| TilerError::io(path, e))?;
    let file_len = file.metadata().map_err(|e| TilerError::io(path, e))?.len();
    if file_len <= u32::MAX as u64 {
        return Ok(());
    }
    let mut head = [0u8; 12];
    file.read_exact_at(&mut head, 0).map_err(|e| TilerError::io(path, e))?;
    let big_endian = match &head[..4] {
        b"II*\0" => false,
        b"MM\0*" => true,
        _ => return Ok(()),
    };
    let reader = Reader { file: &file, file_len, big_endian };
    let mut at = reader.u64(&head[4..12]);
    let ndpi = reader.entries(at, true).is_ok_and(|(fields, _)| fields.iter().any(|f| f.0 == NDPI_FORMAT_FLAG));
    // A chain longer than a slide's few levels and images is not followed further here.
    for index in 0..64 {
        if !ndpi || at == 0 {
            break;
        }
        if at > u32::MAX as u64 {
            return Err(TilerError::unsupported(
                path,
                format!(
                    "its NDPI directory {index} lies at byte {at}, past 4 GiB, where the TIFF reader used here cannot follow (directories within the first 4 GiB and data past it are read)"
                ),
            ));
        }
        at = reader.entries(at, true).map_or(0, |(_, next)| next);
    }
    Ok(())
}
