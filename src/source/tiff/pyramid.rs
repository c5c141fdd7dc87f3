//! Which image of a multi-image TIFF is read: pyramidal TIFFs, OME-TIFF series and whole-slide
//! images keep their full-resolution image next to reduced levels and associated images (a
//! slide's label, macro photograph and thumbnail).
//!
//! The main chain of directories is surveyed once (sizes, NewSubfileType, ImageDescription,
//! SubIFDs), the vendor recognised from the first description ([`super::slide`]), and one page
//! chosen: `--page N` (the Nth directory, as `tiffinfo` and libvips count them), `--series N`
//! (OME-XML's Nth `Image`, or else the Nth full-resolution page), or by default the first
//! (OME: series 0). The summary line says what was read and what was skipped.

use std::fs::File;
use std::io::BufReader;
use std::path::Path;

use tiff::decoder::Decoder;
use tiff::tags::Tag;

use super::slide::{self, Page, Vendor};
use super::{open_decoder, open_error};
use crate::error::{Result, TilerError};
use crate::source::Pick;

/// Directories surveyed at most: real files have a few dozen (an OME-TIFF one per plane).
const MAX_PAGES: usize = 65_536;

/// Hamamatsu NDPI's private tag, in every directory of its files.
const NDPI_FORMAT_FLAG: u16 = 65420;
/// The XMP packet, where Ventana BIF files say `iScan`.
const XMP: u16 = 700;

/// The page chosen, and what the summary line says about it.
pub(super) struct Chosen {
    pub index: usize,
    pub label: String,
    /// The physical size of its pixels, where the file states it.
    pub pitch: Option<crate::source::PixelPitch>,
    /// The pages of the main chain that are the chosen page's reduced levels (tiled, smaller,
    /// in the file's order), for an output that copies every level; SubIFDs are not listed.
    pub levels: Vec<usize>,
    /// The one channel an OME-XML series (`--series`, or the first; not a `--page`) names.
    pub channel: Option<crate::source::ChannelLabel>,
}

/// Surveys the file, picks a page and positions `decoder` on it.
pub(super) fn choose(
    path: &Path,
    decoder: &mut Decoder<BufReader<File>>,
    pick: Pick,
    bigtiff: bool,
    max_memory: u64,
) -> Result<Chosen> {
    let (pages, ended) = survey(path, max_memory)?;
    let vendor = slide::recognise(&pages);
    let index = match (pick.page, pick.series) {
        (Some(_), Some(_)) => return Err(TilerError::Options("--page and --series cannot be given together".into())),
        (Some(page), None) => {
            if page as usize >= pages.len() {
                return Err(TilerError::unsupported(
                    path,
                    format!(
                        "--page {page}: the TIFF has {} page(s), 0 to {}{}",
                        pages.len(),
                        pages.len() - 1,
                        ended.as_ref().map_or(String::new(), |why| format!("; {why}"))
                    ),
                ));
            }
            page as usize
        }
        (None, series) => series_page(path, &pages, vendor, series.unwrap_or(0))?,
    };
    if index > 0 {
        decoder.seek_to_image(index).map_err(|e| open_error(path, e))?;
    }
    let mut label = label(&pages, vendor, index, bigtiff);
    if let Some(why) = ended {
        label += &format!(" ({why}: later pages not read)");
    }
    let pitch = super::pitch::of_page(vendor, &pages, index, decoder);
    if let Some(p) = &pitch {
        label += &match p.square() {
            Some(side) => format!(", {side:.4} µm/texel ({})", p.from),
            None => format!(", {:.4} x {:.4} µm/texel ({})", p.x_um, p.y_um, p.from),
        };
    }
    let levels = reduced_levels(&pages, vendor, index);
    let series = pick.series.filter(|_| pick.page.is_none()).unwrap_or(0);
    let channel = match (vendor, pick.page) {
        (Vendor::Ome, None) => slide::ome_channel_label(&pages[0].description, series),
        _ => None,
    };
    Ok(Chosen { index, label, pitch, levels, channel })
}

/// The main chain's directories, as far as they can be read, and why the chain ended early
/// where it did (a directory the crate cannot read, a cycle of offsets): said in the summary.
fn survey(path: &Path, max_memory: u64) -> Result<(Vec<Page>, Option<String>)> {
    let mut decoder = open_decoder(path, max_memory)?;
    let mut pages = Vec::new();
    loop {
        let description = super::description(path, &mut decoder, max_memory);
        // The first page's description says what the file is (OME-XML, a vendor's); a later
        // one too large to read is only not looked at.
        let description = if pages.is_empty() { description? } else { description.unwrap_or_default() };
        pages.push(page(&mut decoder, description));
        // A later directory the crate cannot read ends the survey: it is never chosen.
        if pages.len() >= MAX_PAGES || !decoder.more_images() {
            return Ok((pages, None));
        }
        if let Err(e) = decoder.next_image() {
            let e = match e {
                // A seek past 2^63 bytes.
                tiff::TiffError::IoError(io) if io.kind() == std::io::ErrorKind::InvalidInput => {
                    "its next-directory offset lies past any file".to_string()
                }
                e => e.to_string(),
            };
            let why = format!("the directory chain stops after page {} ({e})", pages.len() - 1);
            return Ok((pages, Some(why)));
        }
    }
}

fn page(decoder: &mut Decoder<BufReader<File>>, description: String) -> Page {
    let (width, height) = decoder.dimensions().unwrap_or((0, 0));
    let subfile: u32 = decoder.find_tag_unsigned(Tag::NewSubfileType).ok().flatten().unwrap_or(0);
    let sub_ifds = decoder.find_tag(Tag::SubIfd).ok().flatten().map_or(0, |v| match v {
        tiff::decoder::ifd::Value::List(items) => items.len(),
        _ => 1,
    });
    let has = |decoder: &mut Decoder<BufReader<File>>, tag| decoder.find_tag(Tag::Unknown(tag)).ok().flatten();
    let hint = if has(decoder, NDPI_FORMAT_FLAG).is_some() {
        Some(Vendor::Hamamatsu)
    } else if has(decoder, XMP).is_some()
        && decoder.get_tag_u8_vec(Tag::Unknown(XMP)).is_ok_and(|x| x.windows(5).any(|w| w == b"iScan"))
    {
        Some(Vendor::Ventana)
    } else {
        None
    };
    Page {
        width,
        height,
        reduced: subfile & 1 == 1,
        tiled: decoder.get_chunk_type() == tiff::decoder::ChunkType::Tile,
        description,
        sub_ifds,
        hint,
    }
}

/// The associated images of the file (a slide's label, macro and thumbnail directories, as
/// [`slide::associated`] recognises them): each one's kind (`label`, `macro`, `thumbnail`),
/// directory, width and height, in the file's order.
pub(super) fn associated_pages(path: &Path, max_memory: u64) -> Result<Vec<(&'static str, usize, u32, u32)>> {
    let (pages, _) = survey(path, max_memory)?;
    let vendor = slide::recognise(&pages);
    Ok((0..pages.len())
        .filter_map(|i| Some((slide::associated(vendor, &pages, i)?, i, pages[i].width, pages[i].height)))
        .collect())
}

/// The reduced levels of page `index` in the main chain: the tiled levels after it, each
/// smaller than the one before, up to the next full-resolution page (another series).
fn reduced_levels(pages: &[Page], vendor: Vendor, index: usize) -> Vec<usize> {
    let chosen = &pages[index];
    if vendor == Vendor::Ome || !chosen.tiled || slide::associated(vendor, pages, index).is_some() {
        return Vec::new();
    }
    let mut levels = Vec::new();
    let mut last = (chosen.width, chosen.height);
    for i in index + 1..pages.len() {
        if slide::associated(vendor, pages, i).is_some() {
            continue;
        }
        if !slide::is_level(vendor, pages, i) {
            break;
        }
        let p = &pages[i];
        if p.tiled && p.width <= last.0 && p.height <= last.1 && (p.width, p.height) != last {
            levels.push(i);
            last = (p.width, p.height);
        }
    }
    levels
}

/// The first page of series `n`: OME-XML's Nth `Image`, or else the Nth page that is
/// neither a reduced level nor an associated image.
fn series_page(path: &Path, pages: &[Page], vendor: Vendor, n: u32) -> Result<usize> {
    if vendor == Vendor::Ome {
        let file = path.file_name().map(|f| f.to_string_lossy()).unwrap_or_default();
        let series = slide::ome_series(&pages[0].description, &file)
            .map_err(|e| TilerError::decode(path, format!("the OME-XML (ImageDescription of page 0): {e}")))?;
        return match series.get(n as usize) {
            Some(Some(slide::TiffData { elsewhere: Some(other), .. })) => Err(TilerError::unsupported(
                path,
                format!(
                    "the OME-XML's series {n} is stored in another file ({other}): the files of a multi-file OME-TIFF are not read together; give that file"
                ),
            )),
            Some(Some(slide::TiffData { ifd, .. })) if ifd.unwrap_or(0) < pages.len() as u64 => {
                Ok(ifd.unwrap_or(0) as usize)
            }
            Some(_) => Err(TilerError::decode(
                path,
                format!(
                    "the OME-XML's series {n} names no directory of the file (TiffData IFD missing or past the last page)"
                ),
            )),
            None if series.is_empty() => Err(TilerError::decode(
                path,
                "the OME-XML (ImageDescription of page 0) holds no Image element: not an OME-TIFF this reader can map; --page N reads a directory as it is",
            )),
            None => Err(TilerError::unsupported(
                path,
                format!(
                    "--series {n}: the OME-TIFF has {} series, 0 to {}",
                    series.len(),
                    series.len().saturating_sub(1)
                ),
            )),
        };
    }
    let full: Vec<usize> = (0..pages.len())
        .filter(|&i| slide::associated(vendor, pages, i).is_none() && !slide::is_level(vendor, pages, i))
        .collect();
    full.get(n as usize).copied().ok_or_else(|| {
        TilerError::unsupported(
            path,
            format!("--series {n}: the TIFF has {} full-resolution image(s); --page N picks any directory", full.len()),
        )
    })
}

/// "tiff (Aperio SVS, page 0 of 6: full resolution, 3 reduced level(s) not read; skipped
/// thumbnail 1024x768 (page 1), ...)"
fn label(pages: &[Page], vendor: Vendor, index: usize, bigtiff: bool) -> String {
    let kind = if bigtiff { "bigtiff" } else { "tiff" };
    if pages.len() == 1 && pages[0].sub_ifds == 0 && vendor == Vendor::Plain {
        return kind.to_string();
    }
    let chosen = &pages[index];
    let levels = (index + 1..pages.len()).filter(|&i| slide::is_level(vendor, pages, i)).count() + chosen.sub_ifds;
    let what = match slide::associated(vendor, pages, index) {
        Some(kind) => kind.to_string(),
        None if slide::is_level(vendor, pages, index) => "a reduced-resolution level".to_string(),
        None if levels > 0 => format!("full resolution, {levels} reduced level(s) not read"),
        None => "full resolution".to_string(),
    };
    let series = match vendor {
        Vendor::Ome => slide::ome_series(&pages[0].description, "")
            .unwrap_or_default()
            .iter()
            .position(|t| t.as_ref().is_some_and(|t| t.ifd.unwrap_or(0) == index as u64))
            .map_or(String::new(), |s| format!("series {s}, ")),
        _ => String::new(),
    };
    let named = if vendor == Vendor::Plain { String::new() } else { format!("{}, ", vendor.name()) };
    let mut label = format!("{kind} ({named}{series}page {index} of {}: {what}", pages.len());
    let skipped: Vec<String> = (0..pages.len())
        .filter(|&i| i != index)
        .filter_map(|i| {
            let p = &pages[i];
            slide::associated(vendor, pages, i).map(|kind| format!("{kind} {}x{} (page {i})", p.width, p.height))
        })
        .collect();
    if !skipped.is_empty() {
        label += &format!("; skipped {}", skipped.join(", "));
    }
    label += ")";
    label
}
