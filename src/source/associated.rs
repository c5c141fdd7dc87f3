//! A slide's associated images: the label (the slide's paper label, photographed), the
//! overview (the macro photograph of the whole glass slide) and the thumbnail (a small copy of
//! the scanned area), which a scanner keeps beside the pyramid and no output cuts. An output
//! that carries them as they are (a DICOM series' LABEL, OVERVIEW and THUMBNAIL instances;
//! docs/dicom.md) lists them with [`of_file`] and decodes each with [`Associated::decode`].
//!
//! Found where the slide's reader finds them, never by a second parser: a TIFF's associated
//! directories as `tiff::pyramid` recognises them (an Aperio SVS's thumbnail, label and macro;
//! a Philips or generic slide's pages whose description names one), each decoded by the TIFF
//! reader opened on that page. Not found yet: an NDPI's macro (its directory names no kind)
//! and a DICOM series' own LABEL/OVERVIEW/THUMBNAIL instances.
//!
//! A label often shows a patient's name or number: an output that carries it says so, and
//! the user can leave the associated images out (`--no-associated`).

use std::path::{Path, PathBuf};

use crate::error::{Result, TilerError};
use crate::pixel::{Channels, Depth};

/// What an associated image is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Kind {
    /// The slide's label, photographed: often a patient's or case's name, number, barcode.
    Label,
    /// The whole glass slide, photographed at low power (a "macro"): its label too, often.
    Overview,
    /// A small copy of the scanned image.
    Thumbnail,
}

impl Kind {
    /// The name outputs and messages use: `label`, `overview`, `thumbnail`.
    pub fn name(self) -> &'static str {
        match self {
            Kind::Label => "label",
            Kind::Overview => "overview",
            Kind::Thumbnail => "thumbnail",
        }
    }

    /// The kind a vendor's word names (`macro` is the overview).
    fn from_word(word: &str) -> Option<Kind> {
        match word {
            "label" => Some(Kind::Label),
            "macro" | "overview" => Some(Kind::Overview),
            "thumbnail" => Some(Kind::Thumbnail),
            _ => None,
        }
    }
}

/// One associated image of a source: what it is, its size, and where it is stored.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct Associated {
    /// What it is.
    pub kind: Kind,
    /// Texels across, as stored.
    pub width: u32,
    /// Texels down, as stored.
    pub height: u32,
    from: Stored,
}

/// Where an associated image's pixels are.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
enum Stored {
    /// Directory `page` (counted from 0, as `--page` counts) of the TIFF at `path`.
    TiffPage { path: PathBuf, page: usize },
}

/// An associated image decoded: 8-bit grey or RGB samples, row after row, interleaved.
#[derive(Clone, Debug, PartialEq)]
pub struct Pixels {
    /// Texels across.
    pub width: u32,
    /// Texels down.
    pub height: u32,
    /// [`Channels::Grey`] or [`Channels::Rgb`].
    pub channels: Channels,
    /// `width x height x channels` bytes.
    pub samples: Vec<u8>,
    /// The lossy compressions its texels went through, as its reader says
    /// ([`Embedded::lossy`](super::Embedded::lossy)).
    pub lossy: Vec<super::LossyStep>,
}

impl Associated {
    /// Where it is stored, for messages and the summary: `page 3`.
    pub fn origin(&self) -> String {
        match &self.from {
            Stored::TiffPage { page, .. } => format!("page {page}"),
        }
    }

    /// Whether it can be decoded as [`decode`](Self::decode) decodes it, known before any
    /// texel is: its reader opens, its texels are 8-bit grey or RGB of the listed size, and
    /// they fit `max_bytes`. A run checks this when it plans, so that an image it cannot
    /// carry stops it before the pyramid is cut, not after; the error is `decode`'s.
    pub fn check(&self, max_bytes: u64) -> Result<()> {
        self.open(max_bytes).map(drop)
    }

    /// Its texels as 8-bit grey or RGB, decoded by the reader of its file. The decoded size is
    /// checked against `max_bytes` before anything is allocated; an image of other samples
    /// (16-bit, alpha, more channels) or one that cannot be decoded is an error naming the
    /// file and the image, and how to leave the images out.
    pub fn decode(&self, max_bytes: u64) -> Result<Pixels> {
        let (mut source, bytes) = self.open(max_bytes)?;
        let header = source.header();
        let channels = header.layout.channels;
        let row = header.width as usize * channels.count();
        let mut samples = vec![0u8; bytes];
        if row > 0 {
            for chunk in samples.chunks_exact_mut(row) {
                source.read_row(chunk).map_err(|e| self.named(e))?;
            }
        }
        let lossy = source.embedded().lossy;
        Ok(Pixels { width: header.width, height: header.height, channels, samples, lossy })
    }

    /// `message` about this image, naming it and how to leave the images out.
    fn name(&self, message: String) -> String {
        let (kind, origin) = (self.kind.name(), self.origin());
        format!("the {kind} ({origin}): {message} (--no-associated leaves the associated images out)")
    }

    /// A reader's error about this image, named as [`name`](Self::name) names it.
    fn named(&self, e: TilerError) -> TilerError {
        match e {
            TilerError::Decode { path, message } => TilerError::Decode { path, message: self.name(message) },
            TilerError::DecodeRow { path, row, message } => {
                TilerError::Decode { path, message: self.name(format!("row {row}: {message}")) }
            }
            TilerError::Unsupported { path, message } => TilerError::Unsupported { path, message: self.name(message) },
            other => other,
        }
    }

    /// Its reader, at the first row, and the bytes of its texels decoded, checked as
    /// [`check`](Self::check) says.
    fn open(&self, max_bytes: u64) -> Result<(Box<dyn super::RowSource>, usize)> {
        let Stored::TiffPage { path, page } = &self.from;
        let pick = super::Pick { page: Some(*page as u32), series: None };
        let source = super::tiff::open(path, max_bytes, pick).map_err(|e| self.named(e))?;
        let header = source.header();
        let channels = header.layout.channels;
        if header.layout.depth != Depth::U8 || !matches!(channels, Channels::Grey | Channels::Rgb) {
            let message = format!("{} texels, not 8-bit grey or RGB", header.layout);
            return Err(TilerError::unsupported(path, self.name(message)));
        }
        if (header.width, header.height) != (self.width, self.height) {
            let message =
                format!("{}x{} as read, {}x{} as listed", header.width, header.height, self.width, self.height);
            return Err(TilerError::decode(path, self.name(message)));
        }
        let row = header.width as usize * channels.count();
        let bytes = (row as u64).checked_mul(u64::from(header.height)).filter(|&b| b <= max_bytes);
        let Some(bytes) = bytes.and_then(|b| usize::try_from(b).ok()) else {
            let message = format!(
                "{}x{} {} texels decoded are more than the {} MiB allowed (--max-memory)",
                header.width,
                header.height,
                header.layout,
                max_bytes >> 20
            );
            return Err(TilerError::unsupported(path, self.name(message)));
        };
        Ok((source, bytes))
    }
}

/// The associated images of the file at `path`, in the file's order: a TIFF's associated
/// directories (none for any other file, or a directory). An error where the TIFF's
/// directories cannot be read.
pub fn of_file(path: &Path, budget: crate::limits::Budget) -> Result<Vec<Associated>> {
    let max_memory = budget.bytes();
    let mut magic = Vec::with_capacity(4);
    let is_tiff = path.is_file()
        && std::fs::File::open(path)
            .and_then(|f| std::io::Read::read_to_end(&mut std::io::Read::take(f, 4), &mut magic))
            .is_ok_and(|_| super::Streamed::sniff(&magic) == Some(super::Streamed::Tiff));
    if !is_tiff {
        return Ok(Vec::new());
    }
    let pages = super::tiff::associated_pages(path, max_memory)?;
    Ok(pages
        .into_iter()
        .filter_map(|(word, page, width, height)| {
            let kind = Kind::from_word(word)?;
            Some(Associated { kind, width, height, from: Stored::TiffPage { path: path.to_path_buf(), page } })
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn vendors_words_name_the_kinds() {
        assert_eq!(Kind::from_word("macro"), Some(Kind::Overview));
        assert_eq!(Kind::from_word("label"), Some(Kind::Label));
        assert_eq!(Kind::from_word("thumbnail"), Some(Kind::Thumbnail));
        assert_eq!(Kind::from_word("level"), None);
    }

    /// A file that is no TIFF has none; a missing file has none either (its reader says why).
    #[test]
    fn other_files_have_none() {
        let dir = tempfile::tempdir().unwrap();
        let png = dir.path().join("a.png");
        std::fs::write(&png, b"\x89PNG\r\n\x1a\n").unwrap();
        assert_eq!(of_file(&png, crate::limits::Budget::new(1 << 20)).unwrap(), Vec::new());
        assert_eq!(of_file(dir.path(), crate::limits::Budget::new(1 << 20)).unwrap(), Vec::new());
    }
}
