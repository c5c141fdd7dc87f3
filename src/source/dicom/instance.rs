//! One DICOM Part-10 file read up to its Pixel Data: the attributes a whole-slide image's frames
//! need (dicom-rs's `dicom-object`), and where its Pixel Data starts (dicom-rs's token reader,
//! counting the bytes it consumes).
//!
//! The data set is read twice, both times stopping at Pixel Data: first as tokens, each
//! element's length checked against the bytes left in the file before its value is read (so a
//! hostile length never becomes an allocation) and the Pixel Data element's position taken;
//! then as an object, for typed access to the attributes and their sequences. Neither pass
//! reads a frame.

use std::cell::Cell;
use std::fs::File;
use std::io::{BufReader, Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};
use std::rc::Rc;

use dicom_core::Tag;
use dicom_dictionary_std::tags;
use dicom_encoding::TransferSyntaxIndex;
use dicom_encoding::transfer_syntax::Codec;
use dicom_object::{DefaultDicomObject, FileMetaTable, InMemDicomObject, OpenFileOptions};
use dicom_parser::DataSetReader;
use dicom_parser::dataset::DataToken;
use dicom_transfer_syntax_registry::TransferSyntaxRegistry;

use crate::error::{Result, TilerError};

/// Bytes one attribute's value may hold before the Pixel Data (an ICC profile is the largest a
/// slide carries, a few MiB): a larger one is refused before it is read.
const MOST_ATTRIBUTE_BYTES: u64 = 64 << 20;

/// The DICOM file signature: `DICM` after the 128-byte preamble.
pub(crate) const MAGIC_AT: usize = 128;

/// Whether `head` (a file's first bytes, 132 or more) is a DICOM Part-10 file's.
pub(crate) fn is_dicom(head: &[u8]) -> bool {
    head.get(MAGIC_AT..MAGIC_AT + 4) == Some(b"DICM")
}

/// Where an instance's Pixel Data lies.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum PixelData {
    /// Encapsulated (undefined length): its first item header is at this file offset.
    Encapsulated { items_at: u64 },
    /// Native: `len` bytes of samples from this file offset.
    Native { at: u64, len: u64 },
}

/// One instance: its path, its attributes (everything before the Pixel Data), its transfer
/// syntax and where its Pixel Data starts.
pub(crate) struct Instance {
    pub path: PathBuf,
    pub object: InMemDicomObject,
    pub transfer_syntax: String,
    pub pixel_data: Option<PixelData>,
    pub file_len: u64,
}

impl Instance {
    /// Reads `path` up to its Pixel Data. An error names the file and what is wrong with it.
    pub fn read(path: &Path) -> Result<Instance> {
        let (transfer_syntax, pixel_data, file_len) = locate_pixel_data(path)?;
        let object: DefaultDicomObject = OpenFileOptions::new()
            .read_until(tags::PIXEL_DATA)
            .open_file(path)
            .map_err(|e| TilerError::decode(path, format!("not a readable DICOM file: {e}")))?;
        Ok(Instance { path: path.to_path_buf(), object: object.into_inner(), transfer_syntax, pixel_data, file_len })
    }

    /// The attribute's text (trailing padding removed), if present.
    pub fn text(&self, tag: Tag) -> Option<String> {
        text_of(&self.object, tag)
    }

    /// The attribute's values as text.
    pub fn texts(&self, tag: Tag) -> Vec<String> {
        let Some(element) = self.object.get(tag) else { return Vec::new() };
        element.to_multi_str().map(|v| v.iter().map(|s| s.trim().to_string()).collect()).unwrap_or_default()
    }

    /// The attribute as an unsigned integer; `Ok(None)` where absent, an error naming it where
    /// it is not a number that fits.
    pub fn number(&self, tag: Tag, name: &str) -> Result<Option<u64>> {
        number_of(&self.path, &self.object, tag, name)
    }

    /// [`number`](Self::number) of an attribute the image cannot be read without.
    pub fn required(&self, tag: Tag, name: &str) -> Result<u64> {
        self.number(tag, name)?
            .ok_or_else(|| TilerError::decode(&self.path, format!("the instance has no {name} ({})", show_tag(tag))))
    }
}

/// `tag`'s text in `object`.
pub(crate) fn text_of(object: &InMemDicomObject, tag: Tag) -> Option<String> {
    let text = object.get(tag)?.to_str().ok()?;
    let text = text.trim_matches(|c: char| c == '\0' || c.is_whitespace());
    (!text.is_empty()).then(|| text.to_string())
}

/// `tag` in `object` as an unsigned integer, named `name` in an error.
pub(crate) fn number_of(path: &Path, object: &InMemDicomObject, tag: Tag, name: &str) -> Result<Option<u64>> {
    let Some(element) = object.get(tag) else { return Ok(None) };
    if element.to_str().is_ok_and(|s| s.trim_matches(|c: char| c == '\0' || c.is_whitespace()).is_empty()) {
        return Ok(None);
    }
    element
        .to_int::<u64>()
        .map(Some)
        .map_err(|e| TilerError::decode(path, format!("{name} ({}) is not an unsigned number: {e}", show_tag(tag))))
}

/// A tag as DICOM writes it: `(7FE0,0010)`.
pub(crate) fn show_tag(tag: Tag) -> String {
    format!("({:04X},{:04X})", tag.group(), tag.element())
}

/// A reader that counts the bytes taken from it, where its owner can see them while the token
/// reader holds it: dicom-rs's token reader reads exactly what each token needs, never ahead,
/// so the count is the file offset it has reached.
struct Counted<R> {
    inner: R,
    at: Rc<Cell<u64>>,
}

impl<R: Read> Read for Counted<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = self.inner.read(buf)?;
        self.at.set(self.at.get() + n as u64);
        Ok(n)
    }
}

/// The transfer syntax and, if there is one, the Pixel Data of the data set's root, found by
/// reading the data set's tokens (every length checked against what is left of the file
/// before its value is read); and the file's size.
fn locate_pixel_data(path: &Path) -> Result<(String, Option<PixelData>, u64)> {
    let bad = |what: String| TilerError::decode(path, what);
    let mut file = File::open(path).map_err(|e| TilerError::io(path, e))?;
    let file_len = file.metadata().map_err(|e| TilerError::io(path, e))?.len();
    let mut head = [0u8; MAGIC_AT + 4];
    file.read_exact(&mut head).map_err(|_| bad("too short for a DICOM file (no 128-byte preamble and DICM)".into()))?;
    if !is_dicom(&head) {
        return Err(bad("not a DICOM Part-10 file (no DICM after the 128-byte preamble)".into()));
    }
    file.seek(SeekFrom::Start(MAGIC_AT as u64)).map_err(|e| TilerError::io(path, e))?;
    let position = Rc::new(Cell::new(MAGIC_AT as u64));
    let mut reader = Counted { inner: BufReader::new(file), at: Rc::clone(&position) };
    let meta = FileMetaTable::from_reader(&mut reader)
        .map_err(|e| bad(format!("its file meta information cannot be read: {e}")))?;
    let uid = meta.transfer_syntax().trim_end_matches(['\0', ' ']).to_string();
    let Some(ts) = TransferSyntaxRegistry.get(&uid) else {
        return Err(TilerError::unsupported(path, format!("unknown transfer syntax {uid}")));
    };
    // A deflated data set (Codec::Dataset) has no frames in place to read.
    let in_place = matches!(ts.codec(), Codec::None | Codec::EncapsulatedPixelData(..));
    if !in_place || ts.endianness() != dicom_encoding::Endianness::Little {
        return Err(TilerError::unsupported(
            path,
            format!(
                "transfer syntax {uid} ({}) is not read: the frames of a whole-slide image are read in place (explicit or implicit VR little endian, JPEG baseline, JPEG 2000)",
                ts.name()
            ),
        ));
    }
    let mut tokens =
        DataSetReader::new_with_ts(&mut reader, ts).map_err(|e| bad(format!("its data set cannot be read: {e}")))?;
    let mut depth = 0usize;
    let mut pixel_data = None;
    for token in tokens.by_ref() {
        let token = token.map_err(|e| bad(format!("its data set cannot be read: {e}")))?;
        let at = position.get();
        let left = file_len.saturating_sub(at);
        match token {
            DataToken::SequenceStart { .. } => depth += 1,
            DataToken::SequenceEnd => depth = depth.saturating_sub(1),
            DataToken::PixelSequenceStart if depth == 0 => {
                pixel_data = Some(PixelData::Encapsulated { items_at: at });
                break;
            }
            DataToken::PixelSequenceStart => depth += 1,
            DataToken::ElementHeader(header) => {
                let len = header.len.get().map_or(0, u64::from);
                if depth == 0 && header.tag == tags::PIXEL_DATA {
                    if len > left {
                        return Err(bad(format!(
                            "its Pixel Data (7FE0,0010) says {len} bytes, the file has {left} left: a truncated file?"
                        )));
                    }
                    pixel_data = Some(PixelData::Native { at, len });
                    break;
                }
                if len > left || len > MOST_ATTRIBUTE_BYTES {
                    return Err(bad(format!(
                        "attribute {} says {len} bytes at offset {at}, {}",
                        show_tag(header.tag),
                        if len > left {
                            format!("the file has {left} left: a truncated file?")
                        } else {
                            "more than an attribute may hold here".into()
                        }
                    )));
                }
            }
            DataToken::ItemStart { len } => {
                let len = len.get().map_or(0, u64::from);
                if len > left {
                    return Err(bad(format!(
                        "an item at offset {at} says {len} bytes, the file has {left} left: a truncated file?"
                    )));
                }
            }
            _ => {}
        }
    }
    drop(tokens);
    Ok((uid, pixel_data, file_len))
}
