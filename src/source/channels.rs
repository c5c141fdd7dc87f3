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

use std::borrow::Cow;
use std::fs::File;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use tiff::tags::Tag;

use super::tiff::slide::{self, attribute, find_element};
use super::tiff::{description, open_decoder, open_error};
use super::{ImageHeader, Pick, PixelPitch, RowSource, Streamed};
use crate::error::{Result, TilerError};
use crate::limits::Budget;
use crate::pixel::{Channels, Depth, PixelLayout};

/// Channels an image may have here: OME-TIFF and microscopy files reach a few hundred; the cap
/// keeps a corrupt count from becoming a loop of thousands of passes.
pub(crate) const MAX_CHANNELS: usize = 4096;

/// The channels of one image, each to be opened as a grey source.
pub struct ChannelSet {
    /// Width of every channel in texels.
    pub width: u32,
    /// Height of every channel in texels.
    pub height: u32,
    /// Sample depth of every channel.
    pub depth: Depth,
    /// A name per channel: the OME-XML's `Channel Name`, a file's stem, or the colour's.
    pub names: Vec<String>,
    /// A colour per channel where the source gives one (the OME-XML's `Channel Color`: RGBA,
    /// red in the high byte); as many as `names`.
    pub colours: Vec<Option<u32>>,
    /// The physical size of a pixel, where the file states it, as the source's reader gives
    /// it for the same image read as it is (`Embedded::pitch`); `--channel` files' only where
    /// every file states the same.
    pub pitch: Option<PixelPitch>,
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
    pub fn open(path: &Path, pick: Pick, budget: Budget) -> Result<ChannelSet> {
        let max_memory = budget.bytes();
        if let Some(set) = ChannelSet::beyond_texels(path, pick, budget)? {
            return Ok(set);
        }
        let source = super::open_picked(path, budget, pick)?;
        let ImageHeader { width, height, layout } = source.header();
        let names = match layout.channels {
            Channels::Rgb | Channels::Rgba => ["red", "green", "blue", "alpha"].map(String::from).to_vec(),
            Channels::Grey => vec!["grey".to_string()],
            Channels::GreyAlpha => vec!["grey".to_string(), "alpha".to_string()],
        };
        let names: Vec<String> = names.into_iter().take(layout.channels.count()).collect();
        let colours = vec![None; names.len()];
        let kind = Kind::Texels { path: path.to_path_buf(), pick, layout };
        let pitch = source.embedded().pitch;
        Ok(ChannelSet { width, height, depth: layout.depth, names, colours, pitch, kind, max_memory })
    }

    /// The channels of `path` if the pipeline cannot read them as texels: a TIFF page of
    /// more than four samples (together or in planes), an OME-TIFF series of several grey pages.
    pub fn beyond_texels(path: &Path, pick: Pick, budget: Budget) -> Result<Option<ChannelSet>> {
        let max_memory = budget.bytes();
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
    pub fn files(paths: &[PathBuf], budget: Budget) -> Result<ChannelSet> {
        let max_memory = budget.bytes();
        if paths.len() > MAX_CHANNELS {
            return Err(TilerError::Options(format!("{} --channel files: at most {MAX_CHANNELS}", paths.len())));
        }
        let first = paths.first().ok_or_else(|| TilerError::Options("--channel names no file".into()))?;
        let header = super::open(first, budget)?.header();
        let names = paths
            .iter()
            .map(|p| {
                p.file_stem().map(|s| s.to_string_lossy().trim_end_matches(".ome").to_string()).unwrap_or_default()
            })
            .collect();
        let mut set = ChannelSet {
            width: header.width,
            height: header.height,
            depth: header.layout.depth,
            names,
            colours: vec![None; paths.len()],
            pitch: None,
            kind: Kind::Files(paths.to_vec()),
            max_memory,
        };
        // Every file is opened now, so that a wrong one fails before any output is made. The
        // pixel size is the files' where they all state one and agree (files of one size from
        // one instrument), else none: a size some channels contradict is no measurement.
        let mut pitches = Vec::with_capacity(paths.len());
        for (k, path) in paths.iter().enumerate() {
            if let Some(many) = ChannelSet::beyond_texels(path, Pick::default(), budget)? {
                return Err(TilerError::unsupported(
                    path,
                    format!(
                        "an image of {} channels, where a --channel file is one grey image; give it as INPUT (--channels picks some)",
                        many.count()
                    ),
                ));
            }
            pitches.push(set.channel(k)?.embedded().pitch);
        }
        set.pitch = match pitches.split_first() {
            Some((Some(first), rest)) if rest.iter().all(|p| p.is_some_and(|p| p.same_as(first))) => Some(*first),
            _ => None,
        };
        Ok(set)
    }

    /// How many channels: one per entry of `names`.
    pub fn count(&self) -> usize {
        self.names.len()
    }

    /// What the summary line says was read.
    pub fn describe(&self) -> String {
        let what = match &self.kind {
            Kind::Texels { .. } => "samples of each texel",
            Kind::Samples { .. } => "samples of a TIFF page",
            Kind::Pages { .. } => "grey pages of an OME-TIFF",
            Kind::Files(_) => "grey images",
        };
        let pitch = match self.pitch.as_ref().map(|p| (p, p.square())) {
            Some((p, Some(side))) => format!(", {side:.4} µm/texel ({})", p.from),
            Some((p, None)) => format!(", {:.4} x {:.4} µm/texel ({})", p.x_um, p.y_um, p.from),
            None => String::new(),
        };
        format!("{} channels ({what}), one pass each{pitch}", self.count())
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
                let inner = super::open_picked(path, Budget::new(self.max_memory), *pick)?;
                (Box::new(Interleave::pick(inner, layout.depth, k)), path)
            }
            Kind::Samples { path, page } => (super::tiff::open_sample(path, *page, k, self.max_memory)?, path),
            Kind::Pages { path, pages } => {
                let pick = Pick { page: Some(pages[k]), series: None };
                (super::open_picked(path, Budget::new(self.max_memory), pick)?, path)
            }
            Kind::Files(paths) => (super::open(&paths[k], Budget::new(self.max_memory))?, &paths[k]),
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
    let description = description(path, &mut decoder, max_memory)?;
    let file = path.file_name().map(|f| f.to_string_lossy()).unwrap_or_default();
    let ome = match pick.page.is_none() && description.contains("<OME") {
        true => Some(ome_channels(&description, pick.series, &file).map_err(|e| {
            TilerError::decode(
                path,
                format!("the OME-XML (ImageDescription of page 0) does not map onto the file's pages: {e}; --page N reads one directory as it is"),
            )
        })?),
        false => None,
    };
    let page = match (&ome, pick.page) {
        (Some(Some(planes)), _) if planes.ifds.len() > 1 => {
            if planes.ifds.len() > MAX_CHANNELS {
                return Err(TilerError::unsupported(
                    path,
                    format!("{} channels: at most {MAX_CHANNELS}", planes.ifds.len()),
                ));
            }
            let first = Pick { page: Some(planes.ifds[0]), series: None };
            // The series' first plane is the page the OME-XML's PhysicalSizeX/Y is found for.
            let source = super::open_picked(path, Budget::new(max_memory), first)?;
            let (header, pitch) = (source.header(), source.embedded().pitch);
            let kind = Kind::Pages { path: path.to_path_buf(), pages: planes.ifds.clone() };
            let (names, colours) = (planes.names.clone(), planes.colours.clone());
            let (width, height, depth) = (header.width, header.height, header.layout.depth);
            return Ok(Some(ChannelSet { width, height, depth, names, colours, pitch, kind, max_memory }));
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
    let (names, colours) = match &ome {
        Some(Some(planes)) if planes.names.len() == samples as usize => (planes.names.clone(), planes.colours.clone()),
        _ => ((0..samples).map(|k| format!("c{k}")).collect(), vec![None; samples as usize]),
    };
    let pitch = super::tiff::page_pitch(path, page, max_memory)?;
    let kind = Kind::Samples { path: path.to_path_buf(), page };
    let (width, height, depth) = (header.width, header.height, header.layout.depth);
    Ok(Some(ChannelSet { width, height, depth, names, colours, pitch, kind, max_memory }))
}

/// An OME-XML series' channels at the first focal plane and time point: the TIFF directory of
/// each, and its name.
#[derive(Debug, PartialEq)]
struct OmePlanes {
    ifds: Vec<u32>,
    names: Vec<String>,
    /// Each channel's `Color`, where it has a readable one.
    colours: Vec<Option<u32>>,
}

/// Channel `c` of series `series` (0 if not given) lies in the directory its plane index says:
/// planes are counted in the Pixels' DimensionOrder, and each TiffData maps a run of planes
/// (from its FirstC/FirstZ/FirstT, PlaneCount of them) to directories from its IFD on. A
/// channel of several samples (`Channel SamplesPerPixel`, an RGB plane) is one plane.
/// `Ok(None)`: the document has no series `series` (the TIFF reader's pickers say so). An
/// OME-XML that does not map onto directories of this file is an error naming the field: it is
/// never read as something else.
fn ome_channels(xml: &str, series: Option<u32>, file: &str) -> std::result::Result<Option<OmePlanes>, String> {
    let images = slide::images(xml);
    if images.is_empty() {
        return Err("it holds no Image element".into());
    }
    let n = series.unwrap_or(0) as usize;
    let Some(&image) = images.get(n) else { return Ok(None) };
    let pixels = find_element(image, "Pixels").ok_or_else(|| format!("Image {n} has no Pixels element"))?;
    let pixels = slide::start_tag(&image[pixels..]);
    let size = |name: &str| -> std::result::Result<u64, String> {
        match attribute(pixels, name) {
            None => Ok(1),
            Some(v) => match v.trim().parse::<u64>() {
                Ok(n) if n > 0 => Ok(n),
                _ => Err(format!("Pixels {name} \"{v}\" is not a positive whole number")),
            },
        }
    };
    let (size_c, size_z, size_t) = (size("SizeC")?, size("SizeZ")?, size("SizeT")?);
    let order = attribute(pixels, "DimensionOrder").unwrap_or(Cow::Borrowed("XYCZT"));
    let dims: Vec<char> = order.chars().collect();
    if dims.len() != 5 || dims[..2] != ['X', 'Y'] || !['C', 'Z', 'T'].iter().all(|d| dims[2..].contains(d)) {
        return Err(format!("Pixels DimensionOrder \"{order}\" is not XY followed by C, Z and T in some order"));
    }
    let dims = &dims[2..];
    let mut channels = Vec::new();
    let mut from = 0;
    while let Some(at) = find_element(&image[from..], "Channel") {
        channels.push(slide::start_tag(&image[from + at..]));
        from += at + 1;
    }
    // tifffile writes an RGB plane as SizeC 3 and one Channel of 3 samples.
    let per_channel = match channels.first().and_then(|c| attribute(c, "SamplesPerPixel")) {
        None => 1,
        Some(v) => v.trim().parse::<u64>().ok().filter(|&n| n > 0 && size_c % n == 0).ok_or_else(|| {
            format!("Channel SamplesPerPixel \"{v}\" does not divide Pixels SizeC {size_c} into planes")
        })?,
    };
    let planes_c = size_c / per_channel;
    if planes_c > MAX_CHANNELS as u64 {
        return Err(format!("Pixels SizeC is {size_c}: at most {MAX_CHANNELS} channels are read"));
    }
    let size_of = |d: char| match d {
        'C' => planes_c,
        'Z' => size_z,
        _ => size_t,
    };
    planes_c
        .checked_mul(size_z)
        .and_then(|p| p.checked_mul(size_t))
        .ok_or_else(|| format!("Pixels SizeC x SizeZ x SizeT ({size_c} x {size_z} x {size_t}) is too large"))?;
    // The plane index of (c, z, t): the first dimension of the order varies fastest.
    let index = |at: [u64; 3]| {
        let mut stride = 1;
        let mut index = 0;
        for &d in dims {
            index += stride
                * match d {
                    'C' => at[0],
                    'Z' => at[1],
                    _ => at[2],
                };
            stride *= size_of(d);
        }
        index
    };
    let runs = slide::tiff_data(xml, image, file)?;
    for run in &runs {
        for (k, (name, size)) in [("FirstC", planes_c), ("FirstZ", size_z), ("FirstT", size_t)].into_iter().enumerate()
        {
            if run.first[k] >= size {
                let pixels = ["SizeC", "SizeZ", "SizeT"][k];
                return Err(format!("TiffData {name} {} is past Pixels {pixels} {size}", run.first[k]));
            }
        }
    }
    let mut ifds = Vec::new();
    for c in 0..planes_c {
        let plane = index([c, 0, 0]);
        // The OME schema's defaults: one plane where an IFD is named, else every plane.
        let count = |run: &slide::TiffData| run.count.unwrap_or(if run.ifd.is_some() { 1 } else { u64::MAX });
        let run = runs
            .iter()
            .find(|run| (index(run.first)..index(run.first).saturating_add(count(run))).contains(&plane))
            .ok_or_else(|| format!("no TiffData maps channel {c} (plane {plane} in DimensionOrder {order})"))?;
        if let Some(other) = &run.elsewhere {
            return Err(format!(
                "channel {c} is stored in another file ({other}): the files of a multi-file OME-TIFF are not read together"
            ));
        }
        let ifd = run.ifd.unwrap_or(0).checked_add(plane - index(run.first)).and_then(|ifd| u32::try_from(ifd).ok());
        let past = || format!("channel {c}'s TiffData IFD {} is past any directory", run.ifd.unwrap_or(0));
        ifds.push(ifd.ok_or_else(past)?);
    }
    let mut names: Vec<String> = channels
        .iter()
        .enumerate()
        .map(|(k, c)| attribute(c, "Name").map_or_else(|| format!("c{k}"), Cow::into_owned))
        .collect();
    let mut colours: Vec<Option<u32>> =
        channels.iter().map(|c| attribute(c, "Color").and_then(|v| slide::colour(&v))).collect();
    if names.len() != ifds.len() {
        names = (0..ifds.len()).map(|c| format!("c{c}")).collect();
        colours = vec![None; ifds.len()];
    }
    Ok(Some(OmePlanes { ifds, names, colours }))
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

    fn decoding(&self) -> super::Decoding {
        self.sources.iter().map(|s| s.decoding()).fold(super::Decoding::default(), |a, b| a + b)
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
pub(crate) type Range = Arc<Mutex<Option<(f64, f64)>>>;

/// A source that notes the smallest and largest sample it delivers into [`Range`].
pub(crate) struct Ranged {
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
        let planes = ome_channels(xml, None, "a.ome.tif").unwrap().unwrap();
        assert_eq!(planes.ifds, vec![0, 2, 4]);
        assert_eq!(planes.names, vec!["DAPI", "GFP", "c2"]);
        // Bio-Formats' way: one TiffData per plane, in a second series.
        let xml = r#"<OME><Image ID="Image:0"><Pixels SizeC="1"><TiffData/></Pixels></Image>
            <Image ID="Image:1"><Pixels DimensionOrder="XYCZT" SizeC="2" SizeZ="1" SizeT="1">
            <TiffData FirstC="1" IFD="8" PlaneCount="1"/><TiffData FirstC="0" IFD="7" PlaneCount="1"/>
            </Pixels></Image></OME>"#;
        assert_eq!(ome_channels(xml, Some(1), "a").unwrap().unwrap().ifds, vec![7, 8]);
        assert_eq!(ome_channels(xml, Some(2), "a"), Ok(None), "no such series: the pickers say so");
        // tifffile's RGB: SizeC 3 as one Channel of 3 samples, one plane.
        let xml = r#"<OME><Image><Pixels SizeC="3"><Channel Name="RGB" SamplesPerPixel="3"/>
            <TiffData IFD="0" PlaneCount="1"/></Pixels></Image></OME>"#;
        let rgb = OmePlanes { ifds: vec![0], names: vec!["RGB".into()], colours: vec![None] };
        assert_eq!(ome_channels(xml, None, "a"), Ok(Some(rgb)));
        // Names are unescaped.
        let xml = r#"<OME><Image><Pixels SizeC="2"><Channel Name="A&amp;B"/><Channel Name="&#65;"/>
            <TiffData IFD="0" PlaneCount="2"/></Pixels></Image></OME>"#;
        assert_eq!(ome_channels(xml, None, "a").unwrap().unwrap().names, vec!["A&B", "A"]);
        // Colours: the schema's signed RGBA, an unsigned one, and none where unreadable.
        let xml = r#"<OME><Image><Pixels SizeC="4"><Channel Color="-16776961"/><Channel Color="16711935"/>
            <Channel Color="4278190335"/><Channel Color="blue"/><TiffData IFD="0" PlaneCount="4"/></Pixels></Image></OME>"#;
        let colours = ome_channels(xml, None, "a").unwrap().unwrap().colours;
        assert_eq!(colours, vec![Some(0xFF00_00FF), Some(0x00FF_00FF), Some(0xFF00_00FF), None]);
    }

    /// An OME-XML that does not map onto this file's pages is refused, naming the field: never
    /// read as page 0 alone.
    #[test]
    fn ome_xml_that_does_not_map_is_refused_naming_the_field() {
        let pixels =
            |attrs: &str, inner: &str| format!(r#"<OME><Image><Pixels {attrs}>{inner}</Pixels></Image></OME>"#);
        let planes = r#"<TiffData IFD="0" PlaneCount="2"/>"#;
        for (xml, says) in [
            (pixels(r#"SizeC="1000000000""#, planes), "Pixels SizeC is 1000000000: at most 4096"),
            (pixels(r#"SizeC="2" DimensionOrder="XYQQQ""#, planes), r#"DimensionOrder "XYQQQ""#),
            (pixels(r#"SizeC="two""#, planes), r#"Pixels SizeC "two" is not a positive whole number"#),
            (pixels(r#"SizeC="2""#, r#"<TiffData FirstC="5" IFD="0"/>"#), "TiffData FirstC 5 is past Pixels SizeC 2"),
            (pixels(r#"SizeC="2""#, r#"<TiffData IFD="0" PlaneCount="1"/>"#), "no TiffData maps channel 1"),
            (pixels(r#"SizeC="2""#, r#"<TiffData IFD="-1"/>"#), r#"TiffData IFD "-1" is not a number"#),
            (pixels(r#"SizeC="4""#, r#"<Channel SamplesPerPixel="3"/>"#), "SamplesPerPixel \"3\" does not divide"),
            (
                pixels(r#"SizeC="2" SizeZ="99999999999" SizeT="99999999999""#, planes),
                "SizeC x SizeZ x SizeT (2 x 99999999999 x 99999999999) is too large",
            ),
            (
                pixels(
                    r#"SizeC="2""#,
                    r#"<TiffData IFD="0" PlaneCount="2"><UUID FileName="b.ome.tif">urn:uuid:9</UUID></TiffData>"#,
                ),
                r#"channel 0 is stored in another file (FileName "b.ome.tif")"#,
            ),
            ("<OME><BinaryOnly/></OME>".to_string(), "it holds no Image element"),
            (r#"<OME><Image ID="Image:0"/></OME>"#.to_string(), "Image 0 has no Pixels element"),
        ] {
            let e = ome_channels(&xml, None, "a.ome.tif").unwrap_err();
            assert!(e.contains(says), "{xml}: {e}");
        }
    }

    #[test]
    fn ranges_of_rows() {
        assert_eq!(row_range::<u8>(&[5, 3, 9]), Some((3.0, 9.0)));
        assert_eq!(row_range::<u16>(bytemuck::cast_slice(&[700u16, 2])), Some((2.0, 700.0)));
        assert_eq!(row_range::<u8>(&[]), None);
    }
}
