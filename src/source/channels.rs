//! Many channels (docs/ome-zarr.md): an image of more channels than the pipeline's 1 to 4,
//! read one channel at a time, each as a grey source.
//!
//! A [`ChannelSet`] is one of: a TIFF page of more than four samples per texel (stored
//! contiguously or in separate planes, each channel read by the TIFF reader of samples as
//! they are stored, `tiff::kinds`, whatever the photometric calls them); an OME-TIFF series
//! whose channels are grey pages (the OME-XML's planes); a list of grey images of one size
//! and type (`--channel FILE`, repeated); or any image the pipeline reads, its texels' samples
//! being the channels. [`ChannelSet::channel`] opens channel `k` as a grey source of its own,
//! so the pipeline runs once per channel and each channel's pyramid is exactly what a grey
//! image of that channel would give. The source is read once per channel: a decoder that
//! delivers a texel's samples together decodes them all each time; the trade keeps memory at
//! one channel's band, whatever the channel count.

use std::fs::File;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use tiff::tags::Tag;

use super::tiff::slide::{attribute, find_closing, find_element};
use super::tiff::{open_decoder, open_error};
use super::{ImageHeader, Pick, RowSource, Streamed};
use crate::error::{Result, TilerError};
use crate::pixel::{Channels, Depth, PixelLayout};

/// Channels an image may have here: OME-TIFF and microscopy files reach a few hundred; the cap
/// keeps a corrupt count from becoming a loop of thousands of passes.
pub const MAX_CHANNELS: usize = 4096;

/// The channels of one image, each to be opened as a grey source.
pub struct ChannelSet {
    pub width: u32,
    pub height: u32,
    pub depth: Depth,
    /// A name per channel: the OME-XML's `Channel Name`, a file's stem, or the colour's.
    pub names: Vec<String>,
    kind: Kind,
    max_memory: u64,
}

enum Kind {
    /// An image the pipeline reads as it is: channel k is sample k of its texels.
    Texels { path: PathBuf, pick: Pick, layout: PixelLayout },
    /// A TIFF page whose texels hold more samples than a layout has, or whose samples are
    /// stored in separate planes.
    Samples { path: PathBuf, page: usize },
    /// One grey page of a TIFF per channel (an OME-TIFF's planes).
    Pages { path: PathBuf, pages: Vec<u32> },
    /// One grey image per channel.
    Files(Vec<PathBuf>),
}

impl ChannelSet {
    /// The channels of `path` (`pick` choosing a TIFF's page or series).
    pub fn open(path: &Path, pick: Pick, max_memory: u64) -> Result<ChannelSet> {
        if let Some(set) = ChannelSet::beyond_texels(path, pick, max_memory)? {
            return Ok(set);
        }
        let source = super::open_picked(path, max_memory, pick)?;
        let ImageHeader { width, height, layout } = source.header();
        let names = match layout.channels {
            Channels::Rgb | Channels::Rgba => ["red", "green", "blue", "alpha"].map(String::from).to_vec(),
            Channels::Grey => vec!["grey".to_string()],
            Channels::GreyAlpha => vec!["grey".to_string(), "alpha".to_string()],
        };
        let names = names.into_iter().take(layout.channels.count()).collect();
        let kind = Kind::Texels { path: path.to_path_buf(), pick, layout };
        Ok(ChannelSet { width, height, depth: layout.depth, names, kind, max_memory })
    }

    /// The channels of `path` if the pipeline cannot read them as texels: a TIFF page of
    /// more than four samples (together or in planes), an OME-TIFF series of several grey pages.
    pub fn beyond_texels(path: &Path, pick: Pick, max_memory: u64) -> Result<Option<ChannelSet>> {
        match is_tiff(path)? {
            true => tiff_channels(path, pick, max_memory),
            false => Ok(None),
        }
    }

    /// Grey samples of this set's type.
    pub fn layout(&self) -> PixelLayout {
        PixelLayout::new(Channels::Grey, self.depth)
    }

    /// One channel per file, each a grey image of the first one's size and sample type.
    pub fn files(paths: &[PathBuf], max_memory: u64) -> Result<ChannelSet> {
        if paths.len() > MAX_CHANNELS {
            return Err(TilerError::Options(format!("{} --channel files: at most {MAX_CHANNELS}", paths.len())));
        }
        let first = paths.first().ok_or_else(|| TilerError::Options("--channel names no file".into()))?;
        let header = super::open(first, max_memory)?.header();
        let names = paths
            .iter()
            .map(|p| {
                p.file_stem().map(|s| s.to_string_lossy().trim_end_matches(".ome").to_string()).unwrap_or_default()
            })
            .collect();
        let set = ChannelSet {
            width: header.width,
            height: header.height,
            depth: header.layout.depth,
            names,
            kind: Kind::Files(paths.to_vec()),
            max_memory,
        };
        // Every file is opened now, so that a wrong one fails before any output is made.
        for (k, path) in paths.iter().enumerate() {
            if let Some(many) = ChannelSet::beyond_texels(path, Pick::default(), max_memory)? {
                return Err(TilerError::unsupported(
                    path,
                    format!(
                        "an image of {} channels, where a --channel file is one grey image; give it as INPUT (--channels picks some)",
                        many.count()
                    ),
                ));
            }
            set.channel(k)?;
        }
        Ok(set)
    }

    pub fn count(&self) -> usize {
        self.names.len()
    }

    /// Whether the pipeline can read this image as it is (1 to 4 samples per texel).
    pub fn is_texels(&self) -> bool {
        matches!(self.kind, Kind::Texels { .. })
    }

    /// What the summary line says was read.
    pub fn describe(&self) -> String {
        let what = match &self.kind {
            Kind::Texels { .. } => "samples of each texel",
            Kind::Samples { .. } => "samples of a TIFF page",
            Kind::Pages { .. } => "grey pages of an OME-TIFF",
            Kind::Files(_) => "grey images",
        };
        format!("{} channels ({what}), one pass each", self.count())
    }

    /// Channel `k` as a grey source of this set's size and sample type.
    pub fn channel(&self, k: usize) -> Result<Box<dyn RowSource>> {
        if k >= self.count() {
            return Err(TilerError::Options(format!(
                "channel {k}: the image has {} channel(s), 0 to {}",
                self.count(),
                self.count() - 1
            )));
        }
        let (source, path): (Box<dyn RowSource>, &Path) = match &self.kind {
            Kind::Texels { path, pick, layout } => {
                let inner = super::open_picked(path, self.max_memory, *pick)?;
                (Box::new(Interleave::pick(inner, layout.depth, k)), path)
            }
            Kind::Samples { path, page } => (super::tiff::open_sample(path, *page, k, self.max_memory)?, path),
            Kind::Pages { path, pages } => {
                let pick = Pick { page: Some(pages[k]), series: None };
                (super::open_picked(path, self.max_memory, pick)?, path)
            }
            Kind::Files(paths) => (super::open(&paths[k], self.max_memory)?, &paths[k]),
        };
        let want = ImageHeader {
            width: self.width,
            height: self.height,
            layout: PixelLayout::new(Channels::Grey, self.depth),
        };
        let got = source.header();
        if got != want {
            return Err(TilerError::unsupported(
                path,
                format!(
                    "channel {k} ({}) is a {}x{} {} image where the channels are {}x{} {}: each channel is one grey image of one size and type",
                    self.names[k], got.width, got.height, got.layout, want.width, want.height, want.layout
                ),
            ));
        }
        Ok(source)
    }

    /// The channels `picks` as one source of their count's layout (grey, or RGB for three),
    /// for the layouts whose texels hold one to four samples.
    pub fn interleave(&self, picks: &[usize]) -> Result<Box<dyn RowSource>> {
        let channels = match picks.len() {
            1 => Channels::Grey,
            3 => Channels::Rgb,
            n => {
                return Err(TilerError::Options(format!(
                    "--channels picks {n} channel(s): this layout takes one (grey) or three (RGB), e.g. --channels 0,1,2"
                )));
            }
        };
        let sources = picks.iter().map(|&k| self.channel(k)).collect::<Result<Vec<_>>>()?;
        Ok(Box::new(Interleave::new(sources, PixelLayout::new(channels, self.depth))))
    }
}

fn is_tiff(path: &Path) -> Result<bool> {
    // Anything but a file (a FIFO would block here) is left to the decoders, which say why not.
    if !std::fs::metadata(path).is_ok_and(|m| m.is_file()) {
        return Ok(false);
    }
    let mut magic = Vec::with_capacity(8);
    let file = File::open(path).map_err(|e| TilerError::io(path, e))?;
    std::io::Read::read_to_end(&mut std::io::Read::take(file, 8), &mut magic).map_err(|e| TilerError::io(path, e))?;
    Ok(Streamed::sniff(&magic) == Some(Streamed::Tiff))
}

/// A TIFF's channels where the pipeline cannot read them as texels: an OME-TIFF series of
/// several grey pages, or a page of separate planes or of more than four samples. `None` for
/// a TIFF read as it is.
fn tiff_channels(path: &Path, pick: Pick, max_memory: u64) -> Result<Option<ChannelSet>> {
    let mut decoder = open_decoder(path, max_memory)?;
    let description = decoder.get_tag_ascii_string(Tag::ImageDescription).unwrap_or_default();
    let ome = (pick.page.is_none() && description.contains("<OME")).then(|| ome_channels(&description, pick.series));
    let page = match (&ome, pick.page) {
        (Some(Some(planes)), _) if planes.ifds.len() > 1 => {
            if planes.ifds.len() > MAX_CHANNELS {
                return Err(TilerError::unsupported(
                    path,
                    format!("{} channels: at most {MAX_CHANNELS}", planes.ifds.len()),
                ));
            }
            let first = Pick { page: Some(planes.ifds[0]), series: None };
            let header = super::open_picked(path, max_memory, first)?.header();
            let kind = Kind::Pages { path: path.to_path_buf(), pages: planes.ifds.clone() };
            let names = planes.names.clone();
            let (width, height, depth) = (header.width, header.height, header.layout.depth);
            return Ok(Some(ChannelSet { width, height, depth, names, kind, max_memory }));
        }
        (Some(Some(planes)), _) => planes.ifds[0] as usize,
        (_, Some(page)) => page as usize,
        // Another TIFF's Nth series is its Nth full-resolution page: the TIFF reader's choice.
        (_, None) if pick.series.is_some_and(|n| n > 0) => return Ok(None),
        _ => 0,
    };
    if page > 0 && decoder.seek_to_image(page).is_err() {
        // The page pickers say why (a page past the last, a series naming none).
        return Ok(None);
    }
    let samples: u16 = decoder.find_tag_unsigned(Tag::SamplesPerPixel).map_err(|e| open_error(path, e))?.unwrap_or(1);
    // Up to four samples, stored together or in planes, are texels the TIFF reader gives
    // (planes: `tiff::kinds`, which also applies the photometric and the profile).
    if samples <= 4 {
        return Ok(None);
    }
    if samples as usize > MAX_CHANNELS {
        return Err(TilerError::unsupported(path, format!("{samples} samples per texel: at most {MAX_CHANNELS}")));
    }
    let header = super::tiff::open_sample(path, page, 0, max_memory)?.header();
    let names = match &ome {
        Some(Some(planes)) if planes.names.len() == samples as usize => planes.names.clone(),
        _ => (0..samples).map(|k| format!("c{k}")).collect(),
    };
    let kind = Kind::Samples { path: path.to_path_buf(), page };
    let (width, height, depth) = (header.width, header.height, header.layout.depth);
    Ok(Some(ChannelSet { width, height, depth, names, kind, max_memory }))
}

/// An OME-XML series' channels at the first focal plane and time point: the TIFF directory of
/// each, and its name.
#[derive(Debug, PartialEq)]
struct OmePlanes {
    ifds: Vec<u32>,
    names: Vec<String>,
}

/// Channel `c` of series `series` (0 if not given) lies in the directory its plane index says:
/// planes are counted in the Pixels' DimensionOrder, and each TiffData maps a run of planes
/// (from its FirstC/FirstZ/FirstT, PlaneCount of them) to directories from its IFD on.
fn ome_channels(xml: &str, series: Option<u32>) -> Option<OmePlanes> {
    let mut rest = xml;
    let mut image = None;
    for _ in 0..=series.unwrap_or(0) {
        let at = find_element(rest, "Image")?;
        let body = &rest[at..];
        let end = find_closing(body, "Image").unwrap_or(body.len());
        image = Some(&body[..end]);
        rest = &body[end.max(1)..];
    }
    let image = image?;
    let tag_at = |text: &str, at: usize| -> String {
        let tag = &text[at..];
        tag[..tag.find('>').unwrap_or(tag.len())].to_string()
    };
    let pixels = tag_at(image, find_element(image, "Pixels")?);
    let size = |name: &str| attribute(&pixels, name).and_then(|v| v.parse::<u64>().ok()).unwrap_or(1).max(1);
    let (size_c, size_z, size_t) = (size("SizeC"), size("SizeZ"), size("SizeT"));
    if size_c as usize > MAX_CHANNELS {
        return None;
    }
    let order = attribute(&pixels, "DimensionOrder").unwrap_or("XYCZT");
    let dims: Vec<char> = order.chars().skip(2).collect();
    if dims.len() != 3 || !['C', 'Z', 'T'].iter().all(|d| dims.contains(d)) {
        return None;
    }
    let size_of = |d: char| match d {
        'C' => size_c,
        'Z' => size_z,
        _ => size_t,
    };
    // The plane index of (c, z, t): the first dimension of the order varies fastest.
    let index = |c: u64, z: u64, t: u64| {
        let mut stride = 1;
        let mut at = 0;
        for &d in &dims {
            at += stride
                * match d {
                    'C' => c,
                    'Z' => z,
                    _ => t,
                };
            stride *= size_of(d);
        }
        at
    };
    let mut runs = Vec::new();
    let mut from = 0;
    while let Some(at) = find_element(&image[from..], "TiffData") {
        let tag = tag_at(image, from + at);
        let number = |name: &str| attribute(&tag, name).and_then(|v| v.parse::<u64>().ok());
        let ifd = number("IFD");
        let first = index(number("FirstC").unwrap_or(0), number("FirstZ").unwrap_or(0), number("FirstT").unwrap_or(0));
        // The OME schema's defaults: one plane where an IFD is named, else every plane.
        let count = number("PlaneCount").unwrap_or(if ifd.is_some() { 1 } else { size_c * size_z * size_t });
        runs.push((first, count, ifd.unwrap_or(0)));
        from += at + 1;
    }
    let ifds = (0..size_c)
        .map(|c| {
            let plane = index(c, 0, 0);
            let (first, _, ifd) = runs.iter().find(|(first, count, _)| (*first..first + count).contains(&plane))?;
            u32::try_from(ifd + (plane - first)).ok()
        })
        .collect::<Option<Vec<u32>>>()?;
    let mut names = Vec::new();
    let mut from = 0;
    while let Some(at) = find_element(&image[from..], "Channel") {
        let tag = tag_at(image, from + at);
        names.push(attribute(&tag, "Name").map(str::to_string).unwrap_or_else(|| format!("c{}", names.len())));
        from += at + 1;
    }
    if names.len() != ifds.len() {
        names = (0..ifds.len()).map(|c| format!("c{c}")).collect();
    }
    Some(OmePlanes { ifds, names })
}

/// Samples of several sources side by side in one texel; one source's sample `k` alone.
struct Interleave {
    sources: Vec<Box<dyn RowSource>>,
    /// Which sample of each source's texels is taken (the first, where not picked).
    pick: Option<usize>,
    layout: PixelLayout,
    scratch: Vec<u8>,
}

impl Interleave {
    fn new(sources: Vec<Box<dyn RowSource>>, layout: PixelLayout) -> Interleave {
        Interleave { sources, pick: None, layout, scratch: Vec::new() }
    }

    fn pick(source: Box<dyn RowSource>, depth: Depth, k: usize) -> Interleave {
        Interleave {
            sources: vec![source],
            pick: Some(k),
            layout: PixelLayout::new(Channels::Grey, depth),
            scratch: Vec::new(),
        }
    }
}

impl RowSource for Interleave {
    fn header(&self) -> ImageHeader {
        let first = self.sources[0].header();
        ImageHeader { width: first.width, height: first.height, layout: self.layout }
    }

    fn read_row(&mut self, row: &mut [u8]) -> Result<()> {
        let b = self.layout.depth.bytes();
        let out_texel = self.layout.bytes_per_pixel();
        for (c, source) in self.sources.iter_mut().enumerate() {
            let texel = source.layout().bytes_per_pixel();
            self.scratch.resize(source.width() as usize * texel, 0);
            source.read_row(&mut self.scratch)?;
            for (to, from) in row.chunks_exact_mut(out_texel).zip(self.scratch.chunks_exact(texel)) {
                to[c * b..][..b].copy_from_slice(&from[self.pick.unwrap_or(0) * b..][..b]);
            }
        }
        Ok(())
    }

    fn skip_rows(&mut self, rows: u32) -> Result<()> {
        self.sources.iter_mut().try_for_each(|s| s.skip_rows(rows))
    }

    fn rewind(&mut self) -> Result<()> {
        self.sources.iter_mut().try_for_each(|s| s.rewind())
    }

    /// The sources' decoders, all held at once (each picked channel is a source of its own).
    fn buffer_bytes(&self) -> u64 {
        self.sources.iter().map(|s| s.buffer_bytes()).sum()
    }

    fn most_buffer_bytes(&self) -> u64 {
        self.sources.iter().map(|s| s.most_buffer_bytes()).sum()
    }

    fn describe(&self) -> String {
        let inner = self.sources[0].describe();
        match (self.sources.len(), self.pick) {
            (1, Some(k)) => format!("{inner}, sample {k}"),
            (1, None) => inner,
            (n, _) => format!("{inner}, {n} channels side by side"),
        }
    }
}

/// The range of a source's samples, seen as its rows are read (the `omero` windows).
pub type Range = Arc<Mutex<Option<(f64, f64)>>>;

/// A source that notes the smallest and largest sample it delivers into [`Range`].
pub struct Ranged {
    pub inner: Box<dyn RowSource>,
    pub range: Range,
}

impl Ranged {
    pub fn new(inner: Box<dyn RowSource>) -> (Ranged, Range) {
        let range = Range::default();
        (Ranged { inner, range: Arc::clone(&range) }, range)
    }
}

/// The smallest and largest of `row`'s samples of type `S`.
fn row_range<S: bytemuck::Pod + Into<f64>>(row: &[u8]) -> Option<(f64, f64)> {
    let mut it = row.chunks_exact(size_of::<S>()).map(|s| bytemuck::pod_read_unaligned::<S>(s).into());
    let first = it.next()?;
    Some(it.fold((first, first), |(lo, hi), v: f64| (lo.min(v), hi.max(v))))
}

impl RowSource for Ranged {
    fn header(&self) -> ImageHeader {
        self.inner.header()
    }

    fn read_row(&mut self, row: &mut [u8]) -> Result<()> {
        self.inner.read_row(row)?;
        let seen = match self.layout().depth {
            Depth::U8 => row_range::<u8>(row),
            Depth::U16 => row_range::<u16>(row),
            Depth::U32 => row_range::<u32>(row),
            Depth::F32 => row_range::<f32>(row),
            // Sources hand on half floats as f32; nothing reaches here as F16.
            Depth::F16 => None,
        };
        if let Some((lo, hi)) = seen {
            let mut range = self.range.lock().unwrap_or_else(|p| p.into_inner());
            *range = Some(range.map_or((lo, hi), |(a, b)| (a.min(lo), b.max(hi))));
        }
        Ok(())
    }

    forward_row_order_to_inner!();

    fn describe(&self) -> String {
        self.inner.describe()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ome_planes_follow_the_dimension_order_and_tiff_data() {
        // tifffile's way: one TiffData for every plane, channels slowest after Z.
        let xml = r#"<OME><Image ID="Image:0"><Pixels DimensionOrder="XYZCT" SizeC="3" SizeZ="2" SizeT="1">
            <Channel ID="Channel:0:0" Name="DAPI"/><Channel ID="Channel:0:1" Name="GFP"/><Channel ID="Channel:0:2"/>
            <TiffData IFD="0" PlaneCount="6"/></Pixels></Image></OME>"#;
        let planes = ome_channels(xml, None).unwrap();
        assert_eq!(planes.ifds, vec![0, 2, 4]);
        assert_eq!(planes.names, vec!["DAPI", "GFP", "c2"]);
        // Bio-Formats' way: one TiffData per plane, in a second series.
        let xml = r#"<OME><Image ID="Image:0"><Pixels SizeC="1"><TiffData/></Pixels></Image>
            <Image ID="Image:1"><Pixels DimensionOrder="XYCZT" SizeC="2" SizeZ="1" SizeT="1">
            <TiffData FirstC="1" IFD="8" PlaneCount="1"/><TiffData FirstC="0" IFD="7" PlaneCount="1"/>
            </Pixels></Image></OME>"#;
        assert_eq!(ome_channels(xml, Some(1)).unwrap().ifds, vec![7, 8]);
        // A plane no TiffData names: not a channel set this reader can map.
        let xml = r#"<OME><Image><Pixels SizeC="2"><TiffData IFD="0" PlaneCount="1"/></Pixels></Image></OME>"#;
        assert_eq!(ome_channels(xml, None), None);
    }

    #[test]
    fn ranges_of_rows() {
        assert_eq!(row_range::<u8>(&[5, 3, 9]), Some((3.0, 9.0)));
        assert_eq!(row_range::<u16>(bytemuck::cast_slice(&[700u16, 2])), Some((2.0, 700.0)));
        assert_eq!(row_range::<u8>(&[]), None);
    }
}
