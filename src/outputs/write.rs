//! [`Plan::write`]: the outputs' sinks, fed from one read of the source, finished together.

use std::path::PathBuf;
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, Ordering};

use super::plan::{Planned, Work};
use super::{Budget, Format, Plan};
use crate::background::Background;
use crate::error::{Result, TilerError};
use crate::formats::dicom::{self, DicomSink, DicomSummary};
use crate::formats::ome_zarr::OmeZarrSink;
use crate::formats::pack::PackSink;
use crate::formats::pmtiles::PmtilesSink;
use crate::formats::pmtiles::{Bounds, PmtilesSummary, TileType};
use crate::formats::tiff::{self, TiffSink, TiffSummary};
use crate::job::{Progress, SplitOptions, Summary, Written};
use crate::layout::Levels;
use crate::output::Claim;
use crate::sink::icc::{Profile, WithProfile};
use crate::sink::{DirSink, ResumeFrom, Target, TileSink};
use crate::source::channels::{ChannelSet, Ranged};
use crate::source::stored::{StoredLevels, read_header};
use crate::source::{RowSource, tee};
use crate::split;
use crate::store::ObjectUrl;
use crate::store::staged::Staged;

/// Rows of the source the outputs' pyramids may be apart by, when they read one source
/// together ([`tee`]): enough that one pyramid's read-ahead chunk does not stop the others.
const TEE_WINDOW_ROWS: usize = 256;

/// What one output wrote.
#[derive(Clone, Debug)]
#[non_exhaustive]
pub struct Wrote {
    /// The output's format.
    pub format: Format,
    /// Where it is, renamed into place.
    pub path: PathBuf,
    /// Tiles it holds, a place each (a tile shared by several places counts for each).
    pub tiles: u64,
    /// Bytes of tile data it holds (not its index, metadata or manifests).
    pub bytes: u64,
    /// The run that cut its pyramid, shared with the outputs cut from the same one: tiles
    /// encoded and copied, stages, memory.
    pub summary: Summary,
    /// Which of the run's pyramids it was cut from, counted from 0 in the order of the
    /// outputs that first need each; `None` for a TIFF or DICOM series of the slide's own
    /// levels, copied as stored (cut from none).
    pub pyramid: Option<usize>,
    /// Times the run read the source, for all its outputs: once for pyramids cut side by
    /// side, once per pyramid and stripe where the budget holds them only one after another.
    pub reads: usize,
    /// Its format's own figures, where the format has any.
    pub figures: Figures,
    /// Bytes this run sent to an `s3://` output: a directory's tile objects (not those kept
    /// from an interrupted run, `--resume`), a one-object output's file; `None` for a local
    /// output.
    pub uploaded: Option<u64>,
}

/// A format's own figures of what it wrote, beside the tiles and bytes every output counts.
#[derive(Clone, Debug)]
#[non_exhaustive]
pub enum Figures {
    /// A tile directory, a viewer layout or an OME-Zarr: its tiles and bytes say it all.
    None,
    /// A pack's payloads, deduplication and content hash.
    Pack(vortex_pack::WriteSummary),
    /// A PMTiles archive's tiles, directories and bytes.
    Pmtiles(PmtilesSummary),
    /// A TIFF's levels, BigTIFF or not, and bytes.
    Tiff(TiffSummary),
    /// A DICOM series' instances and frames.
    Dicom(DicomSummary),
}

/// An output being written: its plan and its sink; for one object at an `s3://` URL, the
/// local file its sink writes, uploaded once finished.
struct Open {
    planned: Planned,
    sink: Sink,
    staged: Option<Staged>,
    /// Bytes of uploads in flight at most, for an `s3://` destination.
    in_flight: u64,
}

/// The share of `--max-memory` that uploads to object storage take: an eighth, at most
/// 64 MiB, split among the run's `s3://` outputs; the pyramid gets the rest.
fn upload_reserve(budget: Budget, outputs: &[Planned]) -> (Budget, u64) {
    let uploading = outputs.iter().filter(|p| ObjectUrl::of_path(&p.output.path).is_some()).count() as u64;
    if uploading == 0 {
        return (budget, 0);
    }
    let reserve = (budget.bytes() / 8).min(64 << 20);
    (Budget::new(budget.bytes() - reserve), (reserve / uploading).max(1))
}

enum Sink {
    Dir(DirSink),
    Pack(PackSink),
    Pmtiles(PmtilesSink),
    OmeZarr(Box<OmeZarrSink>),
    Tiff(Box<TiffSink>),
    Dicom(DicomSink),
}

impl Open {
    /// Starts `planned`'s sink. Each writes under a temporary name and removes it when dropped
    /// unfinished. `resume`: the journal of a resumable run ([`Plan::resumable`]), for its one output.
    fn start(
        planned: Planned,
        pack: vortex_pack::WriteOptions,
        in_flight: u64,
        resume: Option<super::resume::Resuming>,
    ) -> Result<Open> {
        if let Some(resume) = resume {
            return Open::resuming(planned, pack, in_flight, resume);
        }
        // One object at an s3:// URL: a pack is streamed as it is made; the other sinks write a
        // local temporary, uploaded when finished.
        let url = ObjectUrl::of_path(&planned.claim.path).transpose()?;
        let streamed = matches!(planned.work, Work::Pack { .. }) && url.is_some();
        let staged = match url.clone() {
            Some(url) if !streamed && !crate::store::directory_product(planned.claim.product) => {
                let claim = &planned.claim;
                Some(Staged::create(&url, claim.product, claim.replaces.is_some())?)
            }
            _ => None,
        };
        let local;
        let claim = match &staged {
            Some(staged) => {
                local = Claim { path: staged.local().to_path_buf(), product: planned.claim.product, replaces: None };
                &local
            }
            None => &planned.claim,
        };
        let sink = match &planned.work {
            Work::Tiles { names, .. } => Sink::Dir(DirSink::create_uploading(claim, names.clone(), in_flight)?),
            Work::Viewer { tiles, .. } => Sink::Dir(DirSink::for_viewer_uploading(claim, tiles.clone(), in_flight)?),
            Work::Pack { info, stored } => {
                let (stored, metadata) = (*stored, info.to_json_pretty());
                let (layout, codec, metadata) = (&planned.layout, planned.opts.codec, metadata.as_bytes());
                Sink::Pack(match url.as_ref().filter(|_| streamed) {
                    Some(url) => {
                        let bound = crate::formats::pack::size_bound(layout, stored, metadata.len());
                        let out = crate::store::stream_pack(url, bound, in_flight)?;
                        PackSink::create_to(out, layout, stored, codec, metadata, pack)?
                    }
                    None => PackSink::create(&claim.path, layout, stored, codec, metadata, pack)?,
                })
            }
            Work::Pmtiles { .. } => {
                let tile_type = match planned.opts.codec.extension() {
                    "png" => TileType::Png,
                    "jxl" => TileType::Unknown,
                    _ => TileType::Jpeg,
                };
                Sink::Pmtiles(PmtilesSink::create(&claim.path, &planned.layout, tile_type)?)
            }
            Work::OmeZarr { spec, .. } => Sink::OmeZarr(Box::new(OmeZarrSink::create(claim, (**spec).clone())?)),
            Work::Tiff { spec, .. } => Sink::Tiff(Box::new(TiffSink::create(&claim.path, (**spec).clone())?)),
            Work::Dicom { spec, .. } => Sink::Dicom(DicomSink::create(claim, (**spec).clone())?),
        };
        Ok(Open { planned, sink, staged, in_flight })
    }

    /// [`start`](Self::start) for a resumable run: its sink records every tile and keeps
    /// what the interrupted run it takes over left whole.
    fn resuming(
        planned: Planned,
        pack: vortex_pack::WriteOptions,
        in_flight: u64,
        resume: super::resume::Resuming,
    ) -> Result<Open> {
        use super::resume::Resuming;
        let claim = &planned.claim;
        let (from, local) = match resume {
            Resuming::Journaled { journal, previous, local } => (ResumeFrom::Journal(journal, previous), local),
            Resuming::Prefix { run, listed } => {
                (ResumeFrom::Bucket { run, listed, layout: planned.layout, in_flight }, None)
            }
        };
        // A pack at s3:// is staged on this machine, at a place of its own, then uploaded.
        let staged = match (&local, ObjectUrl::of_path(&claim.path)) {
            (Some(local), Some(url)) => Some(Staged::resumable(&url?, claim.product, local.clone())?),
            _ => None,
        };
        let sink = match (&planned.work, from) {
            (Work::Tiles { names, .. }, from) => Sink::Dir(DirSink::create_resuming(claim, names.clone(), from)?),
            (Work::Viewer { tiles, .. }, from) => Sink::Dir(DirSink::for_viewer_resuming(claim, tiles.clone(), from)?),
            (Work::Pack { info, stored }, ResumeFrom::Journal(journal, previous)) => {
                let (stored, metadata) = (*stored, info.to_json_pretty());
                let (layout, codec) = (&planned.layout, planned.opts.codec);
                let dest = local.as_deref().unwrap_or(&claim.path);
                let sink = PackSink::create_resuming(
                    dest,
                    layout,
                    stored,
                    codec,
                    metadata.as_bytes(),
                    pack,
                    journal,
                    previous,
                )?;
                Sink::Pack(sink)
            }
            _ => return Err(TilerError::Internal("a resumable output of a format that is not resumed".into())),
        };
        Ok(Open { planned, sink, staged, in_flight })
    }

    /// Sends a one-object output's finished local file to its `s3://` URL; the bytes sent.
    fn upload(staged: Option<Staged>, in_flight: u64) -> Result<Option<u64>> {
        staged.map(|staged| staged.upload(in_flight)).transpose()
    }

    fn tile_sink(&self) -> &dyn TileSink {
        match &self.sink {
            Sink::Dir(s) => s,
            Sink::Pack(s) => s,
            Sink::Pmtiles(s) => s,
            Sink::OmeZarr(s) => s.as_ref(),
            Sink::Tiff(s) => s.as_ref(),
            Sink::Dicom(s) => s,
        }
    }

    /// The kept ICC profile its tile files carry.
    fn profile(&self) -> Option<&Profile> {
        match &self.planned.work {
            Work::Tiles { profile, .. } | Work::Viewer { profile, .. } => profile.as_ref(),
            _ => None,
        }
    }

    /// Writes what the format writes last and renames the output into place.
    /// `planes`: the passes that wrote its tiles (an OME-Zarr's channels one pass each).
    fn finish(self, summary: &Summary, at: usize, pyramid: usize, planes: u64) -> Result<Wrote> {
        let Open { planned, sink, mut staged, in_flight } = self;
        let written = summary.per_target.get(at).copied().unwrap_or_default();
        let total = planned.layout.total_tiles() * planes;
        if written.tiles != total {
            return Err(TilerError::Internal(format!(
                "wrote {} tiles of {total} into {}",
                written.tiles,
                planned.output.path.display()
            )));
        }
        let in_bucket = ObjectUrl::of_path(&planned.output.path).is_some();
        let mut uploaded = match &sink {
            Sink::Dir(dir) if in_bucket => Some(dir.bytes_sent()),
            _ => None,
        };
        let figures = match (sink, &planned.work) {
            (Sink::Dir(dir), Work::Tiles { info, .. }) => dir.finish(info).map(|()| Figures::None)?,
            (Sink::Dir(dir), _) => dir.finish_viewer().map(|()| Figures::None)?,
            (Sink::Pack(sink), _) => {
                let written = sink.finish()?;
                if in_bucket && staged.is_none() {
                    uploaded = Some(written.file_bytes);
                }
                Figures::Pack(written)
            }
            (Sink::Pmtiles(mut sink), Work::Pmtiles { name }) => {
                let layout = &planned.layout;
                let metadata = serde_json::json!({
                    "name": name,
                    "format": planned.opts.codec.extension(),
                    "type": "baselayer",
                    "description": "an image without map coordinates: zoom 0 is the whole image at the top left of the web-mercator square",
                    "vortex": { "layout": "xyz", "width": layout.width, "height": layout.height, "tileSize": layout.tile_size },
                });
                let (bounds, metadata) = (Bounds::of_image(layout), metadata.to_string());
                Figures::Pmtiles(match staged.take() {
                    // At s3://, assembled from the spool straight into the upload.
                    Some(staged) => {
                        let bound = sink.archive_bound(metadata.len());
                        let finish = |w: &mut dyn std::io::Write, name: &std::path::Path| {
                            sink.finish_into(&bounds, metadata.as_bytes(), w, name)
                        };
                        let (written, sent) = staged.upload_written(bound, in_flight, finish)?;
                        uploaded = Some(sent);
                        written
                    }
                    None => sink.finish(&bounds, metadata.as_bytes())?,
                })
            }
            (Sink::OmeZarr(sink), Work::OmeZarr { spec, parent }) => {
                sink.finish()?;
                if let (Some(p), Some(label)) = (parent, planned.output.path.file_name()) {
                    crate::formats::ome_zarr::register_label(
                        &p.image.join("labels"),
                        spec.version,
                        &label.to_string_lossy(),
                    )?;
                }
                Figures::None
            }
            (Sink::Tiff(sink), _) => Figures::Tiff(sink.finish()?),
            (Sink::Dicom(sink), _) => Figures::Dicom(sink.finish()?),
            _ => return Err(TilerError::Internal("an output's sink is not its format's".into())),
        };
        if let Some(sent) = Open::upload(staged, in_flight)? {
            uploaded = Some(sent);
        }
        // The pyramid's summary in this output's terms: its levels, texels, tiles and bytes.
        let encoding = planned.opts.encoding();
        let stored = encoding.stored(summary.source)?;
        let (tiles, bytes, copied, cropped) = (written.tiles, written.bytes, written.copied, written.cropped);
        let recompressed = written.recompressed;
        let mut summary =
            Summary { layout: planned.layout, stored, tiles, bytes, copied, cropped, recompressed, ..summary.clone() };
        // Pages copied for the pyramid's other outputs were encoded for this one.
        if let Some(report) = &mut summary.stored_tiles
            && report.declined.is_none()
        {
            report.declined = encoding.declines_stored();
        }
        let Planned { output, .. } = planned;
        Ok(Wrote {
            format: output.format,
            path: output.path,
            tiles: written.tiles,
            bytes: written.bytes,
            summary,
            pyramid: Some(pyramid),
            reads: 0,
            figures,
            uploaded,
        })
    }

    /// [`finish`](Self::finish) for a TIFF or DICOM series of the slide's own levels:
    /// `tiles` copied from the source of `source` texels, no pyramid cut.
    fn finish_copied(self, tiles: u64, source: crate::pixel::PixelLayout, budget: Budget) -> Result<Wrote> {
        let bytes = self.tile_sink().bytes_written();
        let Open { planned, sink, staged, in_flight } = self;
        // The summary's grid: level 0's tiles, as many levels as the output has.
        let mut recompressed = crate::job::Recompressed::default();
        let (level, levels, stored, figures) = match (sink, &planned.work) {
            (Sink::Tiff(sink), Work::Tiff { spec, .. }) => {
                (spec.level(0), spec.level_count(), spec.stored, Figures::Tiff(sink.finish()?))
            }
            (Sink::Dicom(sink), Work::Dicom { spec, .. }) => {
                recompressed = sink.recompressed();
                let mut figures = sink.finish()?;
                figures.levels = Levels::Stored;
                (spec.level(0), spec.level_count(), spec.stored, Figures::Dicom(figures))
            }
            _ => return Err(TilerError::Internal("levels copied into an output that holds none".into())),
        };
        // A JPEG XL series' copied JPEG tiles, recompressed: told as the other outputs tell
        // theirs (`storedTiles.recompressed`).
        let stored_tiles = (recompressed.tiles > 0).then_some(crate::job::StoredReport {
            tile_size: level.tile,
            quality: None,
            declined: None,
            halved: false,
        });
        let uploaded = Open::upload(staged, in_flight)?;
        let mut layout = crate::layout::Layout::new(u64::from(level.width), u64::from(level.height), level.tile.0, 0)?;
        layout.lod_count = levels;
        let summary = Summary {
            layout,
            source,
            stored,
            tiles,
            per_target: vec![Written { tiles, bytes, copied: tiles, cropped: 0, recompressed }],
            encoded: 0,
            kept: 0,
            copied: tiles,
            cropped: 0,
            recompressed,
            stored_tiles,
            bytes,
            stripes: 0,
            passes: 0,
            stages: Default::default(),
            memory: crate::job::MemoryReport { budget: budget.bytes(), ..Default::default() },
        };
        let Planned { output, .. } = planned;
        let (format, path) = (output.format, output.path);
        Ok(Wrote { format, path, tiles, bytes, summary, pyramid: None, reads: 0, figures, uploaded })
    }
}

/// An output that copies the slide's own levels: the levels, and the form every tile must
/// have, which the output declares.
struct Copying {
    levels: StoredLevels,
    form: Form,
}

/// The form of a copied tile: a DICOM frame's photometric interpretation, a TIFF tile's coding.
enum Form {
    Dicom(dicom::Form),
    Tiff(tiff::Coding),
}

/// What [`choose_levels`] decided, an entry an output: those that copy, and why the others
/// that would copy do not.
struct Chosen {
    copying: Vec<Option<Copying>>,
    declined: Vec<Option<String>>,
}

/// Decides, for each TIFF and DICOM output of the slide's own levels (`--levels stored`, the
/// default), whether they are copied (its spec then describes them) or why not (it is then
/// cut from our pyramid; said where the levels were asked for, or where the slide has
/// some). The source's levels are read once, and only where some output would copy them.
fn choose_levels(outputs: &mut [Planned], source: &dyn RowSource) -> Result<Chosen> {
    let mut copying: Vec<Option<Copying>> = outputs.iter().map(|_| None).collect();
    let mut declined = vec![None; outputs.len()];
    let mut stored: Option<Option<StoredLevels>> = None;
    for (k, planned) in outputs.iter_mut().enumerate() {
        // Re-encoding asked (`--reencode`, `--quality`, `--subsampling`) is never copying.
        let reencode = planned.opts.encoding().declines_stored();
        let (Work::Tiff { levels: asked, .. } | Work::Dicom { levels: asked, .. }) = &planned.work else { continue };
        let asked = asked.is_some();
        if planned.work_levels() != Levels::Stored {
            continue;
        }
        if stored.is_none() {
            stored = Some(source.stored_levels()?);
        }
        let levels = match &stored {
            // A slide whose later levels are not JPEG tiles says why below.
            Some(Some(levels)) if levels.levels.len() > 1 || levels.unlike.is_some() => levels,
            Some(Some(_)) => {
                declined[k] = asked.then(|| "the slide has no reduced levels".into());
                continue;
            }
            _ => {
                declined[k] = asked.then(|| "the source is no slide of JPEG-tiled levels".into());
                continue;
            }
        };
        if let Work::Dicom { spec, .. } = &planned.work
            && spec.transfer == dicom::Transfer::Native
        {
            declined[k] = Some("native frames asked (--codec raw), which no stored JPEG or JPEG 2000 tile is".into());
            continue;
        }
        if let Some(why) = reencode {
            declined[k] = Some(format!("the tiles are encoded: {why}"));
            continue;
        }
        if let Work::Tiff { spec, .. } = &planned.work
            && spec.compression == tiff::Compression::Jxl
        {
            // Its stored JPEG tiles are recompressed losslessly where the pages line up with
            // them; the slide's reduced levels are not: ours are.
            declined[k] = Some("JPEG XL tiles asked (--codec jxl), which no stored JPEG level is".into());
            continue;
        }
        let form = match &mut planned.work {
            Work::Dicom { spec, .. } => match dicom::copyable(levels)? {
                Err(why) => Err(why),
                // JPEG XL frames: every stored JPEG tile recompressed losslessly (`copy_levels`).
                Ok((_, form)) if spec.transfer.jpeg_xl() && form.transfer != dicom::Transfer::JpegBaseline => {
                    Err("JPEG XL frames asked (--codec jxl), and the slide's JPEG 2000 tiles are no JPEG to recompress"
                        .into())
                }
                Ok((copied, form)) => {
                    let shapes: Vec<String> = (copied.iter())
                        .map(|l| format!("{}x{}/{}x{}", l.width, l.height, l.tile.0, l.tile.1))
                        .collect();
                    let photometric = form.photometric.name();
                    let transfer = match spec.transfer.jpeg_xl() {
                        true => dicom::Transfer::JpegXlRecompression,
                        false => form.transfer,
                    };
                    spec.identity = format!(
                        "{}; levels stored {} {photometric} {}",
                        spec.identity,
                        shapes.join(" "),
                        transfer.uid()
                    );
                    (spec.copied, spec.photometric, spec.transfer) = (copied, form.photometric, transfer);
                    spec.check()?;
                    Ok(Form::Dicom(form))
                }
            },
            Work::Tiff { spec, .. } => match tiff::copyable(levels, spec.stored.channels)? {
                Err(why) => Err(why),
                Ok((copied, coding)) => {
                    (spec.copied, spec.compression) = (copied, tiff::compression(coding));
                    spec.check()?;
                    Ok(Form::Tiff(coding))
                }
            },
            _ => continue,
        };
        match form {
            Ok(form) => copying[k] = Some(Copying { levels: levels.clone(), form }),
            Err(why) => declined[k] = Some(why),
        }
    }
    Ok(Chosen { copying, declined })
}

/// Outputs cut from one pyramid: their indexes, and the options that cut it (down to the
/// deepest member's levels). Each member encodes the pages its own way.
struct Pyramid {
    members: Vec<usize>,
    opts: SplitOptions,
}

/// The outputs grouped by the pyramid they share: the same tile size, border, filter and
/// budget ([`SplitOptions::pyramid_key`]), whatever their encodings, levels and padding. A
/// group whose members pad differently is cut with the edge repeated, which the encoders fill
/// with each member's colour.
fn pyramids(planned: &[&Planned]) -> Vec<Pyramid> {
    let mut out: Vec<Pyramid> = Vec::new();
    for (k, p) in planned.iter().enumerate() {
        match out.iter_mut().find(|g| g.opts.pyramid_key() == p.opts.pyramid_key()) {
            Some(g) => {
                g.members.push(k);
                g.opts.down_to_one_texel |= p.opts.down_to_one_texel;
                if g.opts.background != p.opts.background {
                    g.opts.background = Background::Edge;
                }
            }
            None => out.push(Pyramid { members: vec![k], opts: p.opts.clone() }),
        }
    }
    out
}

impl Plan {
    /// Writes every output from one read of `source` (the image the plan was made for), and
    /// says what each wrote, in the order given. `progress` hears of every tile of every output
    /// and can stop the run. On failure nothing of any output is left (each output that was
    /// finished before a later one failed to finish stays, complete).
    pub fn write(self, mut source: Box<dyn RowSource>, progress: &dyn Progress) -> Result<Vec<Wrote>> {
        let Plan { mut outputs, budget, pack, mut resume } = self;
        let source_layout = source.layout();
        let asked: Vec<Levels> = outputs.iter().map(Planned::work_levels).collect();
        // A TIFF or DICOM series of the slide's own levels copies them, cut from no pyramid.
        let Chosen { copying, mut declined } = choose_levels(&mut outputs, source.as_ref())?;
        if copying.iter().any(Option::is_some) {
            progress.total(outputs.iter().map(Planned::tiles).sum());
        }
        let (budget, in_flight) = upload_reserve(budget, &outputs);
        let open: Vec<Open> =
            outputs.into_iter().map(|p| Open::start(p, pack, in_flight, resume.take())).collect::<Result<_>>()?;
        let cut: Vec<usize> = (0..open.len()).filter(|&k| copying[k].is_none()).collect();
        let mut copied = vec![0u64; open.len()];
        for (k, c) in copying.iter().enumerate() {
            let Some(c) = c else { continue };
            copied[k] = match (&c.form, &open[k].sink) {
                (Form::Dicom(form), Sink::Dicom(sink)) => dicom::copy_levels(sink, &c.levels, *form, progress)?,
                (Form::Tiff(coding), Sink::Tiff(sink)) => {
                    let fits = |file: &[u8], _| read_header(file).is_some_and(|h| tiff::fits(&h, *coding));
                    crate::formats::levels::copy(
                        sink.as_ref(),
                        &c.levels,
                        &format!("{} JPEG", tiff::coding_name(*coding)),
                        &fits,
                        progress,
                    )?
                }
                _ => return Err(TilerError::Internal("levels copied into an output of another form".into())),
            };
        }
        let planned: Vec<&Planned> = cut.iter().map(|&k| &open[k].planned).collect();
        let pyramids = pyramids(&planned);
        let tagged: Vec<Option<WithProfile>> =
            open.iter().map(|o| o.profile().map(|profile| WithProfile { inner: o.tile_sink(), profile })).collect();
        let sink = |k: usize| tagged[k].as_ref().map_or(open[k].tile_sink(), |t| t as &dyn TileSink);
        let targets: Vec<Vec<Target>> = (pyramids.iter())
            .map(|g| {
                let target = |k: usize| {
                    let p = &open[k].planned;
                    let (lods, background, encoding) = (p.layout.lod_count, p.opts.background, p.opts.encoding());
                    Target { sink: sink(k), lods, background, encoding }
                };
                g.members.iter().map(|&m| target(cut[m])).collect()
            })
            .collect();
        let (summaries, reads) = match pyramids.len() {
            0 => (Vec::new(), 0),
            1 => {
                let summary = split::split_to(source.as_mut(), &targets[0], &pyramids[0].opts, progress)?;
                let reads = summary.passes;
                (vec![summary], reads)
            }
            _ => cut_together(source, &pyramids, &targets, budget, progress)?,
        };
        drop(tagged);
        let mut place = vec![None; open.len()];
        for (g, pyramid) in pyramids.iter().enumerate() {
            for (at, &m) in pyramid.members.iter().enumerate() {
                place[cut[m]] = Some((g, at));
            }
        }
        let mut wrote = Vec::with_capacity(open.len());
        for (k, o) in open.into_iter().enumerate() {
            let mut w = match place[k] {
                Some((g, at)) => o.finish(&summaries[g], at, g, 1)?,
                None => o.finish_copied(copied[k], source_layout, budget)?,
            };
            match &mut w.figures {
                Figures::Dicom(f) if w.pyramid.is_some() => {
                    f.levels = asked[k];
                    f.levels_declined = declined[k].take();
                }
                Figures::Tiff(f) => f.levels_declined = declined[k].take(),
                _ => {}
            }
            wrote.push(Wrote { reads, ..w });
        }
        Ok(wrote)
    }
}

impl Plan {
    /// Writes the outputs of a plan made with planes ([`Plan::with_planes`]: OME-Zarr images
    /// and OME-TIFFs of a grey plane a channel) from the channels `picks` of `set`, one pass
    /// each, one after another, each pass's one pyramid feeding every output (memory stays
    /// one grey pipeline's); `first` is channel `picks[0]`, opened already. Says what each
    /// output wrote, in the order given.
    pub fn write_channels(
        self,
        set: &ChannelSet,
        picks: &[usize],
        first: Box<dyn RowSource>,
        progress: &dyn Progress,
    ) -> Result<Vec<Wrote>> {
        let Plan { outputs, pack, .. } = self;
        if outputs.iter().any(|p| !matches!(p.work, Work::OmeZarr { .. } | Work::Tiff { .. })) {
            return Err(TilerError::Internal("channels one pass each go to OME-Zarr and OME-TIFF outputs".into()));
        }
        let open: Vec<Open> = outputs
            .into_iter()
            .map(|p| Open::start(p, pack, crate::store::UPLOAD_BYTES, None))
            .collect::<Result<_>>()?;
        // Both formats take the run's tile size and the box filter unless one is given for
        // all: their pyramids are one.
        let [pyramid] = <[Pyramid; 1]>::try_from(pyramids(&open.iter().map(|o| &o.planned).collect::<Vec<_>>()))
            .map_err(|_| TilerError::Internal("the planar outputs need pyramids of their own".into()))?;
        let mut summary: Option<Summary> = None;
        let mut windows = Vec::with_capacity(picks.len());
        let mut first = Some(first);
        for (c, &k) in picks.iter().enumerate() {
            let source = match first.take() {
                Some(source) => source,
                None => set.channel(k)?,
            };
            let (mut source, range) = Ranged::new(source);
            let planes: Vec<Box<dyn TileSink + '_>> = (open.iter())
                .map(|o| match &o.sink {
                    Sink::OmeZarr(sink) => Ok(Box::new(sink.plane(c as u32)) as Box<dyn TileSink>),
                    Sink::Tiff(sink) => Ok(Box::new(sink.plane(c as u32)) as Box<dyn TileSink>),
                    _ => Err(TilerError::Internal("a planar output's sink is not its format's".into())),
                })
                .collect::<Result<_>>()?;
            let targets: Vec<Target> = (open.iter().zip(&planes))
                .map(|(o, plane)| {
                    let p = &o.planned;
                    let (lods, background) = (p.layout.lod_count, p.opts.background);
                    Target { sink: plane.as_ref(), lods, background, encoding: p.opts.encoding() }
                })
                .collect();
            let pass = split::split_to(&mut source, &targets, &pyramid.opts, progress)?;
            windows.push(*range.lock().unwrap_or_else(|p| p.into_inner()));
            summary = Some(match summary {
                None => pass,
                Some(sum) => add(sum, pass),
            });
        }
        let Some(summary) = summary else { return Err(TilerError::Options("--channels names no channel".into())) };
        let mut wrote = Vec::with_capacity(open.len());
        for (at, mut o) in open.into_iter().enumerate() {
            if let Sink::OmeZarr(sink) = &mut o.sink {
                for (c, window) in windows.iter().enumerate() {
                    sink.set_window(c, *window);
                }
            }
            wrote.push(Wrote { reads: summary.passes, ..o.finish(&summary, at, 0, picks.len() as u64)? });
        }
        Ok(wrote)
    }
}

/// Two passes' summaries as one run's: their tiles, reads and stage times added up.
fn add(mut sum: Summary, pass: Summary) -> Summary {
    sum.tiles += pass.tiles;
    // Each target's tiles added up; its sink counts every pass's bytes.
    for (to, from) in sum.per_target.iter_mut().zip(&pass.per_target) {
        (to.tiles, to.copied, to.cropped) = (to.tiles + from.tiles, to.copied + from.copied, to.cropped + from.cropped);
        to.bytes = from.bytes;
    }
    sum.encoded += pass.encoded;
    sum.kept += pass.kept;
    // The sink counts every pass's bytes.
    sum.bytes = pass.bytes;
    sum.passes += pass.passes;
    // The passes run one after another: the run held at most what its largest pass held.
    if pass.memory.peaks.total > sum.memory.peaks.total {
        sum.memory = pass.memory;
    }
    let (s, p) = (&mut sum.stages, pass.stages);
    for (to, from) in [
        (&mut s.read, p.read),
        (&mut s.read_wait, p.read_wait),
        (&mut s.pyramid, p.pyramid),
        (&mut s.cut, p.cut),
        (&mut s.producer_blocked, p.producer_blocked),
        (&mut s.encoders_idle, p.encoders_idle),
        (&mut s.encode, p.encode),
        (&mut s.store, p.store),
    ] {
        *to += from;
    }
    sum
}

/// Several pyramids from one read of `source` ([`tee`]), each on its own thread with its
/// share of `budget`, where each then reads the source in one pass; else one after another,
/// each with the whole budget, the source read again for each (`split` says so in its
/// passes).
fn cut_together(
    mut source: Box<dyn RowSource>,
    pyramids: &[Pyramid],
    targets: &[Vec<Target>],
    budget: Budget,
    progress: &dyn Progress,
) -> Result<(Vec<Summary>, usize)> {
    let n = pyramids.len() as u64;
    let window = tee::window_bytes(&source.header(), TEE_WINDOW_ROWS);
    let share = budget.bytes().saturating_sub(window) / n;
    let shared: Vec<SplitOptions> =
        pyramids.iter().map(|g| SplitOptions { max_memory: share, ..g.opts.clone() }).collect();
    let one_pass = shared
        .iter()
        .zip(targets)
        .all(|(opts, t)| split::plan(source.as_ref(), t, opts).is_ok_and(|p| p.passes() == 1));
    // --fast-shrink reads the source at half size, which one read cannot share.
    if !one_pass || pyramids.iter().any(|g| g.opts.fast_shrink) {
        let mut summaries = Vec::with_capacity(pyramids.len());
        for (k, (g, t)) in pyramids.iter().zip(targets).enumerate() {
            if k > 0 {
                source.rewind()?;
            }
            summaries.push(split::split_to(source.as_mut(), t, &g.opts, progress)?);
        }
        let reads = summaries.iter().map(|s| s.passes).sum();
        return Ok((summaries, reads));
    }
    let branches = tee::tee(source, pyramids.len(), TEE_WINDOW_ROWS);
    let stop = Joint { inner: progress, failed: AtomicBool::new(false), first: Mutex::new(None) };
    let results: Vec<Result<Summary>> = std::thread::scope(|scope| {
        let runs: Vec<_> = (branches.into_iter().zip(&shared).zip(targets))
            .map(|((mut branch, opts), t)| {
                let stop = &stop;
                scope.spawn(move || {
                    let result = split::split_to(branch.as_mut(), t, opts, stop);
                    result.map_err(|e| stop.fail(e))
                })
            })
            .collect();
        runs.into_iter().map(|r| r.join().unwrap_or_else(|_| Err(TilerError::panicked("a pyramid's run")))).collect()
    });
    // The error that stopped the others, not theirs.
    match stop.first.into_inner().unwrap_or_else(|poisoned| poisoned.into_inner()) {
        Some(e) => Err(e),
        None => Ok((results.into_iter().collect::<Result<_>>()?, 1)),
    }
}

/// The caller's progress, and a stop for every pyramid once one has failed.
struct Joint<'a> {
    inner: &'a dyn Progress,
    failed: AtomicBool,
    /// The first failure other than being stopped.
    first: Mutex<Option<TilerError>>,
}

impl Joint<'_> {
    /// Stops the other pyramids; keeps `e` if it is the first real failure.
    fn fail(&self, e: TilerError) -> TilerError {
        self.failed.store(true, Ordering::SeqCst);
        let mut first = self.first.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
        match (&*first, e) {
            (None, e) if !matches!(e, TilerError::Interrupted) => {
                *first = Some(e);
                TilerError::Interrupted
            }
            (_, e) => e,
        }
    }
}

impl Progress for Joint<'_> {
    fn advance(&self, tiles: u64) {
        self.inner.advance(tiles);
    }
    fn cancelled(&self) -> bool {
        self.failed.load(Ordering::SeqCst) || self.inner.cancelled()
    }
}
