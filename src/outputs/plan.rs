//! [`Plan::new`]: every output of a run checked against the source, the settings and the
//! budget, and its destination claimed, before the first tile.

use std::path::{Path, PathBuf};

use super::{Budget, DicomSettings, Format, OmeZarrSettings, Output, Settings, TiffSettings};
use crate::background::Background;
use crate::codec::{Codec, Subsampling};
use crate::error::{Result, ShowPath, TilerError};
use crate::formats::dicom;
use crate::formats::ome_zarr::PixelSize;
use crate::formats::ome_zarr::{LabelParent, Plane, Spec, label_parent};
use crate::formats::ome_zarr::{OmeZarrPlan, OmeZarrRequested};
use crate::formats::tiff::{self, BigTiff, Compression, Flavour};
use crate::formats::tiles::filename::FilenameFormat;
use crate::formats::tiles::info::InfoFile;
use crate::formats::viewer::{Viewer, ViewerTiles, dzi, iiif};
use crate::job::SplitOptions;
use crate::layout::{Layout, Levels};
use crate::limits::Limits;
use crate::output::{self, Claim, Existing, Product};
use crate::pixel::{Depth, PixelLayout};
use crate::pyramid::filter::Filter;
use crate::settings::{self, CodecChoice, Destination, Requested};
use crate::sink::icc::Profile;
use crate::source::ImageHeader;
use crate::source::associated::Associated;

/// A run's outputs, each checked and claimed.
#[derive(Debug)]
pub struct Plan {
    pub(super) outputs: Vec<Planned>,
    pub(super) budget: Budget,
    pub(super) pack: vortex_pack::WriteOptions,
    /// A resumable run's journal and what it took over ([`Plan::resumable`]).
    pub(super) resume: Option<super::resume::Resuming>,
}

/// One output of a [`Plan`]: how the pipeline cuts and encodes its pyramid, and what its
/// format writes besides the tiles.
#[derive(Debug)]
pub struct Planned {
    pub output: Output,
    /// How the pipeline cuts and encodes this output's pyramid.
    pub opts: SplitOptions,
    /// The page grid it is cut into.
    pub layout: Layout,
    /// Where a previous output's `info.json` set this run's defaults (a tile directory
    /// replacing one of ours): its path and `name value` of each setting it changed.
    pub changed: Option<(PathBuf, Vec<String>)>,
    pub(super) claim: Claim,
    pub(super) work: Work,
}

/// What each format needs besides the tiles, to start its sink and to finish it.
#[derive(Debug)]
pub(super) enum Work {
    Tiles {
        names: FilenameFormat,
        info: InfoFile,
        profile: Option<Profile>,
    },
    Pack {
        info: InfoFile,
        stored: PixelLayout,
    },
    Viewer {
        tiles: ViewerTiles,
        profile: Option<Profile>,
    },
    Pmtiles {
        name: String,
    },
    OmeZarr {
        spec: Box<Spec>,
        parent: Option<LabelParent>,
    },
    /// `levels` (`None`: not asked, the default): whether the slide's own levels are to be
    /// copied, decided when the source's levels are read ([`Plan::write`]).
    Tiff {
        spec: Box<tiff::Spec>,
        levels: Option<Levels>,
    },
    Dicom {
        spec: Box<dicom::Spec>,
        levels: Option<Levels>,
    },
}

impl Plan {
    /// Plans `outputs` of the source `header` describes (read from `inputs`, which no output
    /// may overwrite) with `settings`, within `budget`. Fails, before anything is written, on
    /// the first output that cannot hold what is asked, with the message `split` prints.
    pub fn new(
        outputs: Vec<Output>,
        settings: &Settings,
        header: &ImageHeader,
        inputs: &[&Path],
        budget: Budget,
    ) -> Result<Plan> {
        Plan::with_planes(outputs, settings, header, inputs, budget, None)
    }

    /// [`Plan::new`] for channels written one pass each (`planes`; `header` is a channel's),
    /// into an OME-Zarr or an OME-TIFF ([`Plan::write_channels`]).
    pub fn with_planes(
        outputs: Vec<Output>,
        settings: &Settings,
        header: &ImageHeader,
        inputs: &[&Path],
        budget: Budget,
        planes: Option<Vec<Plane>>,
    ) -> Result<Plan> {
        if outputs.is_empty() {
            return Err(options("a run needs an output".into()));
        }
        check_apart(&outputs)?;
        refuse_unread(settings, &outputs)?;
        let formats: Vec<Format> = outputs.iter().map(|o| o.format).collect();
        let mut planned = Vec::with_capacity(outputs.len());
        let input = inputs.first().copied().unwrap_or(Path::new(""));
        let (found, checked) = (std::cell::OnceCell::new(), std::cell::OnceCell::new());
        let at = Context {
            header,
            inputs,
            input,
            budget,
            force: settings.force,
            stored: settings.stored_subsampling,
            lossy: &settings.lossy,
            associated: &found,
            associated_checked: &checked,
        };
        for output in outputs {
            let own = Own::of(settings, output.format, &formats);
            if let Some(c @ (CodecChoice::Deflate | CodecChoice::Lzw)) = own.tiles.codec
                && !matches!(output.format, Format::Tiff(_) | Format::Dicom)
            {
                return Err(options(format!(
                    "{} ({}): --codec {} compresses a TIFF output's tiles (-o FILE.tif, FILE.ome.tif or FILE.cog.tif), not this output's; it takes png, raw or zstd: write it in a run of its own",
                    output.path.shown(),
                    output.format,
                    c.name()
                )));
            }
            planned.push(match output.format {
                Format::Tiles | Format::Pack => tiles(output, &own, &at)?,
                Format::Viewer(viewer) => for_viewer(output, viewer, &own, &at)?,
                Format::Pmtiles => for_viewer(output, Viewer::Xyz, &own, &at)?,
                Format::OmeZarr => ome_zarr(output, &own, &at, planes.clone())?,
                Format::Tiff(flavour) => tiff_output(output, flavour, &own, &at, planes.as_deref())?,
                Format::Dicom => dicom_output(output, &own, &at)?,
            });
        }
        Ok(Plan { outputs: planned, budget, pack: settings.pack, resume: None })
    }

    /// The outputs, in the order given.
    pub fn outputs(&self) -> &[Planned] {
        &self.outputs
    }

    /// Tiles the run writes, all outputs together (what a progress bar counts).
    pub fn total_tiles(&self) -> u64 {
        self.outputs.iter().map(|p| p.layout.total_tiles()).sum()
    }
}

impl Planned {
    /// The tiles it holds: a TIFF's or DICOM series' own levels' where it copies a slide's,
    /// else its pyramid's.
    pub(super) fn tiles(&self) -> u64 {
        match &self.work {
            Work::Tiff { spec, .. } => spec.total_tiles(),
            Work::Dicom { spec, .. } => (0..spec.level_count()).map(|k| spec.level(k).tiles()).sum(),
            _ => self.layout.total_tiles(),
        }
    }

    /// Which levels a TIFF or DICOM output holds (`--levels`, stored by default); our
    /// pyramid's for the other formats.
    pub(super) fn work_levels(&self) -> Levels {
        match &self.work {
            Work::Tiff { levels, .. } | Work::Dicom { levels, .. } => levels.unwrap_or_default(),
            _ => Levels::Pow2,
        }
    }

    /// The `info.json` a tile directory or a pack holds.
    pub fn info(&self) -> Option<&InfoFile> {
        match &self.work {
            Work::Tiles { info, .. } | Work::Pack { info, .. } => Some(info),
            _ => None,
        }
    }
}

/// What every output's planning reads besides its settings.
struct Context<'a> {
    header: &'a ImageHeader,
    inputs: &'a [&'a Path],
    /// The first input, whose file stem names a pyramid by default.
    input: &'a Path,
    budget: Budget,
    force: bool,
    /// How the source's stored JPEG tiles code colour ([`Settings::stored_subsampling`]).
    stored: Option<Subsampling>,
    /// The lossy compressions the source's texels went through ([`Settings::lossy`]).
    lossy: &'a [crate::source::LossyStep],
    /// The source's associated images, found once for the outputs that carry them.
    associated: &'a std::cell::OnceCell<Vec<Associated>>,
    /// Set once they are checked, by the first output that carries them.
    associated_checked: &'a std::cell::OnceCell<()>,
}

impl Context<'_> {
    /// The source's associated images an output carries, none where `left_out`
    /// (`--no-associated`); and how many it leaves out. Each carried one is checked once a
    /// plan ([`Associated::check`]): one that cannot be decoded as the outputs need stops the
    /// run before its pyramid is cut.
    fn associated(&self, left_out: bool) -> Result<(Vec<Associated>, usize)> {
        if self.associated.get().is_none() {
            let _ = self.associated.set(crate::source::associated::of_file(self.input, self.budget)?);
        }
        let found = self.associated.get().cloned().unwrap_or_default();
        if left_out {
            return Ok((Vec::new(), found.len()));
        }
        if self.associated_checked.get().is_none() {
            for image in &found {
                image.check(self.associated_bytes())?;
            }
            let _ = self.associated_checked.set(());
        }
        Ok((found, 0))
    }

    /// The most bytes one associated image may take decoded: half the budget, the rest for
    /// its encoded strip or frame.
    fn associated_bytes(&self) -> u64 {
        self.budget.bytes() / 2
    }

    /// `opts` with JPEG tiles coded as the source's stored ones where `--subsampling` is not
    /// given: a TIFF or DICOM output declares one coding for all its tiles, so that only then
    /// can the stored tiles be copied into it.
    fn coded_as_stored(&self, mut opts: SplitOptions, given: Option<Subsampling>) -> SplitOptions {
        if let (None, Some(stored), Codec::Jpeg { subsampling, .. }) = (given, self.stored, &mut opts.codec) {
            *subsampling = stored;
        }
        opts
    }

    fn limits(&self) -> Limits {
        Limits { memory: self.budget.bytes(), ..Limits::default() }
    }

    fn claim(&self, path: &Path, product: Product) -> Result<Claim> {
        if let Some(url) = crate::store::ObjectUrl::of_path(path) {
            return crate::store::claim(&url?, product, self.force);
        }
        Ok(output::claim(path, product, self.inputs, self.force)?)
    }

    /// `--name`, else the input's file stem.
    fn name(&self, own: &Own) -> String {
        match &own.name {
            Some(name) => name.clone(),
            None => self.input.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default(),
        }
    }
}

/// The settings one output reads: those its format has, or, where no output of the run reads
/// a setting, every setting given (so that the output refuses it, naming the flag).
struct Own {
    tiles: Requested,
    overlap: Option<u32>,
    name: Option<String>,
    iiif_id: Option<String>,
    ome_zarr: OmeZarrSettings,
    tiff: TiffSettings,
    dicom: DicomSettings,
    keep_icc: Option<Vec<u8>>,
    levels: Option<Levels>,
    no_associated: bool,
    /// The source's georeferencing, for a generic TIFF or a COG.
    geo: Option<crate::source::GeoTags>,
    /// The one channel the source names, for an OME-TIFF.
    channel: Option<crate::source::ChannelLabel>,
}

/// The settings a format reads beyond those every format does (tile size, background,
/// flatten, tile type, filter, reencode).
#[derive(Clone, Copy, PartialEq, Eq)]
enum Setting {
    FilenameFormat,
    Border,
    Overlap,
    Name,
    IiifId,
    /// `--codec` and the JPEG, PNG and BC7 settings.
    ImageCodec,
    ZstdLevel,
    KeepIcc,
}

fn reads(format: Format, setting: Setting) -> bool {
    use Setting::*;
    match format {
        Format::Tiles | Format::Pack => matches!(setting, FilenameFormat | Border | ImageCodec | ZstdLevel | KeepIcc),
        Format::Viewer(viewer) => match setting {
            Overlap => viewer == Viewer::Dzi,
            IiifId => viewer == Viewer::Iiif,
            Name | ImageCodec | KeepIcc => true,
            _ => false,
        },
        Format::Pmtiles => matches!(setting, Name | ImageCodec),
        Format::OmeZarr => matches!(setting, Name | ZstdLevel),
        Format::Tiff(_) => matches!(setting, Name | ImageCodec | ZstdLevel | KeepIcc),
        Format::Dicom => matches!(setting, Name | ImageCodec),
    }
}

impl Own {
    fn of(s: &Settings, format: Format, all: &[Format]) -> Own {
        // Given to this output if it reads it, or if no output does (to be refused).
        let gets = |setting: Setting| reads(format, setting) || !all.iter().any(|f| reads(*f, setting));
        let t = &s.tiles;
        let image_codec = gets(Setting::ImageCodec);
        let tiles = Requested {
            filename_format: t.filename_format.clone().filter(|_| gets(Setting::FilenameFormat)),
            border: t.border.filter(|_| gets(Setting::Border)),
            // OME-Zarr takes `--codec zstd` (what it writes) and refuses any other it alone is given.
            codec: t.codec.filter(|c| image_codec || (format == Format::OmeZarr && *c == CodecChoice::Zstd)),
            quality: t.quality.filter(|_| image_codec),
            subsampling: t.subsampling.filter(|_| image_codec),
            png_level: t.png_level.filter(|_| image_codec),
            bc7_effort: t.bc7_effort.filter(|_| image_codec),
            lossless: t.lossless && image_codec,
            jxl_effort: t.jxl_effort.filter(|_| image_codec),
            zstd_level: t.zstd_level.filter(|_| gets(Setting::ZstdLevel)),
            max_memory: None,
            ..t.clone()
        };
        Own {
            tiles,
            overlap: s.overlap.filter(|_| gets(Setting::Overlap)),
            name: s.name.clone().filter(|_| gets(Setting::Name)),
            iiif_id: s.iiif_id.clone().filter(|_| gets(Setting::IiifId)),
            ome_zarr: match format {
                Format::OmeZarr => OmeZarrSettings { pixel_size: pixel_size(s), ..s.ome_zarr.clone() },
                // A TIFF records the pixel size (OME's PhysicalSize, the resolution tags).
                Format::Tiff(_) | Format::Dicom => {
                    OmeZarrSettings { pixel_size: pixel_size(s), ..OmeZarrSettings::default() }
                }
                _ => OmeZarrSettings::default(),
            },
            tiff: if matches!(format, Format::Tiff(_)) { s.tiff } else { TiffSettings::default() },
            dicom: if format == Format::Dicom { s.dicom.clone() } else { DicomSettings::default() },
            keep_icc: s.keep_icc.clone().filter(|_| gets(Setting::KeepIcc)),
            levels: s.levels.filter(|_| matches!(format, Format::Tiff(_) | Format::Dicom)),
            no_associated: s.no_associated,
            // Not a flag: an output that has nowhere to put it ignores it.
            geo: s.geo.clone().filter(|_| matches!(format, Format::Tiff(Flavour::Generic | Flavour::Cog))),
            channel: s.channel.clone().filter(|_| format == Format::Tiff(Flavour::Ome)),
        }
    }
}

/// `--pixel-size`, or else the source's square pixel as its file states it.
fn pixel_size(s: &Settings) -> Option<PixelSize> {
    s.ome_zarr.pixel_size.or_else(|| {
        let side = s.pitch.as_ref()?.square()?;
        Some(PixelSize { value: side, unit: "micrometer" })
    })
}

/// OME-Zarr's own settings with no OME-Zarr output, and `--keep-icc` where no output keeps
/// the profile, are refused here; the rest by the output that does not read them.
fn refuse_unread(s: &Settings, outputs: &[Output]) -> Result<()> {
    let tiff = outputs.iter().any(|o| matches!(o.format, Format::Tiff(_)));
    if s.tiff.bigtiff != BigTiff::Auto && !tiff {
        return Err(options("--bigtiff belongs to a TIFF output (-o FILE.tif or FILE.ome.tif)".into()));
    }
    let dicom = outputs.iter().any(|o| o.format == Format::Dicom);
    let given = [(s.dicom.uid_root.is_some(), "--dicom-uid-root"), (s.dicom.meta.is_some(), "--dicom-meta")];
    for (given, flag) in given {
        if given && !dicom {
            return Err(options(format!("{flag} belongs to --layout dicom")));
        }
    }
    let carrying = outputs.iter().any(|o| matches!(o.format, Format::Tiff(Flavour::Generic | Flavour::Ome)));
    if s.no_associated && !carrying && !dicom {
        return Err(options(
            "--no-associated belongs to a generic TIFF (-o FILE.tif), an OME-TIFF (-o FILE.ome.tif) or --layout dicom, the outputs that carry a slide's associated images".into(),
        ));
    }
    if s.levels.is_some() && !tiff && !dicom {
        return Err(options(
            "--levels belongs to a TIFF output (-o FILE.tif, FILE.ome.tif or FILE.cog.tif) or --layout dicom".into(),
        ));
    }
    // A TIFF and a DICOM series record the pixel size too.
    let tiff = tiff || dicom;
    if !outputs.iter().any(|o| o.format == Format::OmeZarr) {
        let z = &s.ome_zarr;
        for (given, flag) in [
            (z.version.is_some(), "--ome-zarr-version"),
            (z.shard_chunks.is_some(), "--shard-chunks"),
            (z.pixel_size.is_some() && !tiff, "--pixel-size"),
        ] {
            if given {
                return Err(options(format!("{flag} belongs to --layout ome-zarr")));
            }
        }
    }
    let keeps = |o: &Output| reads(o.format, Setting::KeepIcc);
    if s.keep_icc.is_some()
        && let Some(o) = outputs.iter().find(|o| !keeps(o))
    {
        let what = match o.format {
            Format::Pmtiles => "a PMTiles archive",
            Format::Dicom => "a DICOM series (its frames state sRGB)",
            _ => "OME-Zarr",
        };
        return Err(options(format!(
            "--keep-icc keeps the profile in the JPEG and PNG tiles of a directory and in info.json (a pack's too), and in a TIFF's ICC tag; {what} has nowhere to keep it: leave --keep-icc out to convert the texels to sRGB"
        )));
    }
    Ok(())
}

/// No two outputs at one path, nor one inside another's directory (a directory is renamed
/// into place whole, which would take the other with it).
fn check_apart(outputs: &[Output]) -> Result<()> {
    let absolute = |p: &Path| std::path::absolute(p).unwrap_or_else(|_| p.to_path_buf());
    for (i, a) in outputs.iter().enumerate() {
        for b in &outputs[i + 1..] {
            let (pa, pb) = (absolute(&a.path), absolute(&b.path));
            if pa.starts_with(&pb) || pb.starts_with(&pa) {
                return Err(options(format!(
                    "{} ({}) and {} ({}): the outputs of one run need paths of their own, neither inside the other",
                    a.path.shown(),
                    a.format,
                    b.path.shown(),
                    b.format
                )));
            }
        }
    }
    Ok(())
}

/// This tool's tile directory or a pack.
fn tiles(output: Output, own: &Own, at: &Context) -> Result<Planned> {
    for (given, flag) in
        [(own.name.is_some(), "--name"), (own.overlap.is_some(), "--overlap"), (own.iiif_id.is_some(), "--iiif-id")]
    {
        if given {
            return Err(options(format!(
                "{flag} belongs to a viewer layout (--layout dzi, iiif, xyz or google); this tool's tiles have --border"
            )));
        }
    }
    let (product, destination) = match output.format {
        Format::Pack => (Product::Pack, Destination::Pack),
        _ => (Product::TileDir, Destination::TileDir),
    };
    let claim = at.claim(&output.path, product)?;
    // A previous output directory's info.json sets this run's defaults (the original tool's
    // way of configuring a run); the claim made sure the directory is ours.
    let info_path = (product == Product::TileDir && claim.replaces == Some(Existing::Ours))
        .then(|| output.path.join("info.json"))
        .filter(|p| p.is_file());
    let existing = info_path.as_deref().map(InfoFile::read).transpose()?;
    let requested = Requested { max_memory: Some(at.budget.bytes()), ..own.tiles.clone() };
    let existing = info_path.as_deref().zip(existing.as_ref());
    let icc = own.keep_icc.as_deref();
    let plan = settings::Plan::new(&requested, existing, at.header, destination, &at.limits(), icc)?;
    let settings::Plan { opts, names, layout, info, changed, stored } = plan;
    let changed = info_path.filter(|_| !changed.is_empty()).map(|p| (p, changed));
    let work = match output.format {
        Format::Pack => Work::Pack { info, stored },
        _ => {
            // The JPEG and PNG tiles of a directory carry the kept profile; a pack's tiles do
            // not (its metadata, info.json, holds it once: docs/colour.md).
            let profile = icc.map(|icc| Profile::for_tiles(icc, opts.codec)).transpose()?.flatten();
            Work::Tiles { names, info, profile }
        }
    };
    Ok(Planned { output, opts, layout, changed, claim, work })
}

/// A viewer layout's directory, or (as `Viewer::Xyz`) a PMTiles archive.
fn for_viewer(output: Output, viewer: Viewer, own: &Own, at: &Context) -> Result<Planned> {
    let t = &own.tiles;
    if t.filename_format.is_some() {
        return Err(options(format!(
            "--layout {viewer} names its tiles as viewers expect; --filename-format is for --layout vortex"
        )));
    }
    if t.border.is_some() {
        return Err(options(match viewer {
            Viewer::Dzi => "--layout dzi shares texels between tiles with --overlap (Deep Zoom's), not --border".into(),
            _ => format!("--layout {viewer} tiles have no border or overlap; --border is for --layout vortex"),
        }));
    }
    if own.overlap.is_some() && viewer != Viewer::Dzi {
        return Err(options(format!("--overlap is Deep Zoom's (--layout dzi); {viewer} tiles do not overlap")));
    }
    if own.iiif_id.is_some() && viewer != Viewer::Iiif {
        return Err(options("--iiif-id names a IIIF image (--layout iiif)".into()));
    }
    let iiif_service = own.iiif_id.as_deref().map(iiif::absolute_id).transpose().map_err(options)?;
    let name = at.name(own);
    if name.is_empty() || name.contains(['/', '\\']) || name == "." || name == ".." {
        return Err(options(format!("--name '{name}' must be a plain file name (it makes NAME.dzi and NAME_files/)")));
    }
    let pmtiles = output.format == Format::Pmtiles;
    let claim = at.claim(&output.path, if pmtiles { Product::Pmtiles } else { Product::Viewer(viewer) })?;

    let tile_size = t.tile_size.unwrap_or(viewer.default_tile_size());
    let overlap = match viewer {
        Viewer::Dzi => own.overlap.unwrap_or(dzi::DEFAULT_OVERLAP),
        _ => 0,
    };
    let (width, height) = (at.header.width, at.header.height);
    let layout = viewer.page_grid(width, height, tile_size, overlap)?;
    // Web maps pad their square with a colour (vips: white); the other layouts crop at the image.
    let background = match viewer {
        Viewer::Xyz | Viewer::Google => Some(t.background.unwrap_or(Background::Colour([255; 4]))),
        _ => t.background,
    };
    let requested = Requested {
        tile_size: Some(layout.tile_size),
        border: Some(layout.border),
        background,
        max_memory: Some(at.budget.bytes()),
        filename_format: None,
        ..t.clone()
    };
    let (mut opts, _) = settings::resolve(&requested, None, at.header.layout)?;
    opts.down_to_one_texel = viewer.down_to_one_texel();
    if !matches!(opts.codec.extension(), "jpg" | "png" | "jxl") {
        return Err(options(format!(
            "--layout {viewer} tiles are image files: use --codec jpeg, png or jxl, not {}",
            opts.codec.name()
        )));
    }
    if iiif_service.is_some() && opts.codec.extension() != "jpg" {
        return Err(options(format!(
            "--iiif-id makes a conformant IIIF level-0 service, whose one required format is JPEG (default.jpg): \
             use --codec jpeg, or leave --iiif-id out for {} tiles under a relative id",
            opts.codec.name()
        )));
    }
    at.limits().check_pyramid(&layout, false)?;
    if pmtiles {
        use crate::formats::pmtiles::ENTRY_MEMORY_BYTES;
        let need = layout.total_tiles().saturating_mul(ENTRY_MEMORY_BYTES);
        at.limits().check_memory(&format!("the PMTiles directory of {} tiles", layout.total_tiles()), need)?;
        return Ok(Planned { output, opts, layout, changed: None, claim, work: Work::Pmtiles { name } });
    }
    let tiles = ViewerTiles {
        viewer,
        layout,
        name,
        extension: viewer.extension(opts.codec.extension()),
        iiif: iiif_service.map(|id| iiif::Service { id, codec: opts.codec }),
    };
    let profile = own.keep_icc.as_deref().map(|icc| Profile::for_tiles(icc, opts.codec)).transpose()?.flatten();
    Ok(Planned { output, opts, layout, changed: None, claim, work: Work::Viewer { tiles, profile } })
}

/// An OME-Zarr image (docs/ome-zarr.md); `planes`: channels written one pass each.
fn ome_zarr(output: Output, own: &Own, at: &Context, planes: Option<Vec<Plane>>) -> Result<Planned> {
    for (given, flag) in [(own.overlap.is_some(), "--overlap"), (own.iiif_id.is_some(), "--iiif-id")] {
        if given {
            return Err(options(format!("{flag} belongs to a viewer layout; OME-Zarr chunks do not overlap")));
        }
    }
    let requested = Requested { max_memory: Some(at.budget.bytes()), ..own.tiles.clone() };
    let z = &own.ome_zarr;
    let zarr = OmeZarrRequested {
        version: z.version,
        shard_chunks: z.shard_chunks,
        pixel_size: z.pixel_size,
        name: at.name(own),
        planes,
    };
    // -o IMAGE/labels/NAME: a label image of IMAGE, in IMAGE's version.
    let parent = label_parent(&output.path);
    let OmeZarrPlan { product, spec, opts } =
        OmeZarrPlan::new(&requested, zarr, &output.path, parent.as_ref(), at.header, &at.limits())?;
    if parent.is_some() && spec.planes.is_some() {
        return Err(options(format!(
            "{}: a label image has one channel; pick it with --channels N",
            output.path.shown()
        )));
    }
    let claim = at.claim(&output.path, product)?;
    let layout = spec.layout;
    Ok(Planned { output, opts, layout, changed: None, claim, work: Work::OmeZarr { spec: Box::new(spec), parent } })
}

/// The tile directories' and viewers' flags, and whether each was given: a TIFF or a DICOM
/// series, which holds its tiles in files of its own, refuses them.
fn file_and_viewer_flags(own: &Own) -> [(bool, &'static str); 5] {
    let t = &own.tiles;
    [
        (own.overlap.is_some(), "--overlap"),
        (own.iiif_id.is_some(), "--iiif-id"),
        (t.filename_format.is_some(), "--filename-format"),
        (t.png_level.is_some(), "--png-compression"),
        (t.bc7_effort.is_some(), "--bc7-effort"),
    ]
}

/// A pyramidal TIFF (docs/tiff.md): pages without border, whole at the edges (TIFF pads its
/// edge tiles), JPEG tiles or the raw, Deflate or zstd ones the file stores, all from the
/// encoders ([`tiff::Spec::codec`]); `planes`: channels written one pass each, each a grey
/// plane of an OME-TIFF.
fn tiff_output(output: Output, flavour: Flavour, own: &Own, at: &Context, planes: Option<&[Plane]>) -> Result<Planned> {
    let t = &own.tiles;
    let what = flavour.name();
    if let Some(planes) = planes
        && flavour != Flavour::Ome
    {
        return Err(options(format!(
            "{}: {} channels one pass each go into an OME-TIFF's planes (-o FILE.ome.tif); a {what} holds one to four samples a pixel: pick one or three with --channels",
            output.path.shown(),
            planes.len()
        )));
    }
    let planar = planes.is_some();
    let channels: Vec<tiff::OmeChannel> = match planes {
        Some(planes) => {
            planes.iter().map(|p| tiff::OmeChannel { name: Some(p.name.clone()), colour: p.colour }).collect()
        }
        // An image's one channel, as its file names it (a one-channel OME-TIFF).
        None => (own.channel.iter()).map(|c| tiff::OmeChannel { name: c.name.clone(), colour: c.colour }).collect(),
    };
    for (given, flag) in file_and_viewer_flags(own) {
        if given {
            return Err(options(format!("{flag} does not apply to a {what} output, one file of tiled levels")));
        }
    }
    if let Some(border) = t.border.filter(|b| *b != 0) {
        return Err(options(format!("--border {border}: TIFF tiles have no border (each pixel is stored once)")));
    }
    let tile_size = t.tile_size.unwrap_or(tiff::DEFAULT_TILE_SIZE);
    let source = at.header.layout;
    let labels = t.filter.is_some_and(|f| f.is_label());
    let jpeg_fits = t.tile_depth.unwrap_or(source.depth) == Depth::U8
        && (!source.channels.has_alpha() || t.flatten)
        && !labels
        && source.depth.is_narrow_int();
    let choice = match t.codec.unwrap_or(CodecChoice::Auto) {
        CodecChoice::Auto if jpeg_fits => CodecChoice::Jpeg,
        CodecChoice::Auto => CodecChoice::Deflate,
        c => c,
    };
    let zstd_level = t.zstd_level.unwrap_or(crate::codec::DEFAULT_ZSTD_LEVEL);
    let (codec, compression) = match choice {
        CodecChoice::Jpeg => (CodecChoice::Jpeg, None),
        CodecChoice::Jxl => (CodecChoice::Jxl, None),
        CodecChoice::Deflate => (CodecChoice::Raw, Some(Compression::Deflate { level: 6 })),
        CodecChoice::Lzw => (CodecChoice::Raw, Some(Compression::Lzw)),
        CodecChoice::Zstd => (CodecChoice::Raw, Some(Compression::Zstd { level: zstd_level })),
        CodecChoice::Raw => (CodecChoice::Raw, Some(Compression::None)),
        other => {
            return Err(options(format!(
                "--codec {}: TIFF tiles are jpeg, jxl, deflate, lzw, zstd or raw (uncompressed)",
                other.name()
            )));
        }
    };
    if codec == CodecChoice::Raw {
        for (given, flag) in [(t.quality.is_some(), "--quality"), (t.subsampling.is_some(), "--subsampling")] {
            if given {
                return Err(options(format!("{flag} is JPEG's; this {what} output's tiles are {}", choice.name())));
            }
        }
    }
    if t.zstd_level.is_some() && choice != CodecChoice::Zstd {
        return Err(options(format!("--zstd-level is zstd's; this {what} output's tiles are {}", choice.name())));
    }
    let requested = Requested {
        tile_size: Some(tile_size),
        border: Some(0),
        codec: Some(codec),
        // Microscopy measures intensity linearly: OME-TIFF's levels, like OME-Zarr's, are means
        // of the stored values; the generic pyramid takes the run's default filter.
        filter: t.filter.or((flavour == Flavour::Ome).then_some(Filter::Box)),
        max_memory: Some(at.budget.bytes()),
        filename_format: None,
        zstd_level: None,
        ..t.clone()
    };
    let (opts, _) = settings::resolve(&requested, None, source)?;
    let mut opts = at.coded_as_stored(opts, t.subsampling);
    let layout = opts.layout(at.header.width, at.header.height)?;
    let stored = opts.codec.stored_layout(source, opts.flatten, opts.tile_depth)?;
    let compression = match (compression, opts.codec) {
        (Some(c), _) => c,
        (None, crate::codec::Codec::Jpeg { subsampling, .. }) => Compression::Jpeg { subsampling },
        (None, crate::codec::Codec::Jxl { .. }) => Compression::Jxl,
        (None, other) => return Err(TilerError::Internal(format!("TIFF tiles from --codec {}", other.name()))),
    };
    let pixel_size = own.ome_zarr.pixel_size.map(|p| tiff::Micrometres(micrometres(p)));
    // A slide's label, macro and thumbnail follow a generic pyramid's levels, and an
    // OME-TIFF's as images of their own; a COG leaves them out (its readers take every IFD
    // for an overview).
    let (associated, associated_left_out) = at.associated(own.no_associated || flavour == Flavour::Cog)?;
    // Written again as they are, or the run refused: a GIS tool would misplace a file whose
    // georeferencing is damaged, or drop it, without a word.
    let geo = match &own.geo {
        Some(geo) => geo.check().map_err(|why| {
            TilerError::decode(
                at.input,
                format!(
                    "{why}: the georeferencing cannot be carried into {}; repair it (gdal_edit.py -a_srs and -a_ullr) or write another output",
                    output.path.shown()
                ),
            )
        })?,
        None => &[],
    };
    let spec = tiff::Spec {
        flavour,
        layout,
        stored,
        compression,
        bigtiff: own.tiff.bigtiff,
        name: at.name(own).trim_end_matches(".ome").to_string(),
        pixel_size,
        geo: geo.to_vec(),
        icc: own.keep_icc.clone(),
        copied: Vec::new(),
        associated,
        associated_bytes: at.associated_bytes(),
        associated_left_out,
        channels,
        planar,
    };
    spec.check()?;
    at.limits().check_pyramid(&layout, false)?;
    // The encoders compress the tiles as the file stores them (resolved as raw above, which
    // keeps the same samples).
    if let Some(codec) = spec.codec() {
        opts.codec = codec;
    }
    at.limits().check_memory(&format!("the index of the TIFF's {} tiles", spec.total_tiles()), spec.index_bytes())?;
    let claim = at.claim(&output.path, Product::Tiff)?;
    Ok(Planned {
        output,
        opts,
        layout,
        changed: None,
        claim,
        work: Work::Tiff { spec: Box::new(spec), levels: own.levels },
    })
}

/// A DICOM whole-slide image series (docs/dicom.md): frames without border, whole at the
/// edges; JPEG baseline from the encoders or copied from a JPEG-tiled source, or native
/// (`--codec raw`, lossless, 8 or 16 bits); the pixel size is needed (the IOD states the
/// pixel spacing).
fn dicom_output(output: Output, own: &Own, at: &Context) -> Result<Planned> {
    let t = &own.tiles;
    for (given, flag) in file_and_viewer_flags(own).into_iter().chain([(t.zstd_level.is_some(), "--zstd-level")]) {
        if given {
            return Err(options(format!("{flag} does not apply to --layout dicom, a series of DICOM frames")));
        }
    }
    if let Some(border) = t.border.filter(|b| *b != 0) {
        return Err(options(format!("--border {border}: DICOM frames have no border (each pixel is stored once)")));
    }
    let transfer = match t.codec.unwrap_or(CodecChoice::Auto) {
        CodecChoice::Auto | CodecChoice::Jpeg => dicom::Transfer::JpegBaseline,
        CodecChoice::Raw => dicom::Transfer::Native,
        CodecChoice::Jxl if t.lossless => dicom::Transfer::JpegXlLossless,
        CodecChoice::Jxl => dicom::Transfer::JpegXl,
        other => {
            return Err(options(format!(
                "--codec {}: DICOM frames are JPEG baseline (jpeg, the default), JPEG XL (jxl) or native, uncompressed (raw){}",
                other.name(),
                if other == CodecChoice::Deflate {
                    "; the Deflated transfer syntax is not written (docs/dicom.md)"
                } else {
                    ""
                }
            )));
        }
    };
    let source = at.header.layout;
    let native = transfer == dicom::Transfer::Native;
    let jxl = transfer.jpeg_xl();
    let depth = t.tile_depth.unwrap_or(source.depth);
    if native || jxl {
        if !matches!(depth, Depth::U8 | Depth::U16) {
            return Err(options(format!(
                "{}: a {source} image: DICOM whole-slide frames hold 8- or 16-bit unsigned samples, no {} (map it onto them with --range MIN:MAX, or write OME-Zarr or OME-TIFF to keep it)",
                output.path.shown(),
                depth.tile_type()
            )));
        }
        if native {
            for (given, flag) in [(t.quality.is_some(), "--quality"), (t.subsampling.is_some(), "--subsampling")] {
                if given {
                    return Err(options(format!("{flag} is JPEG's; --codec raw writes native DICOM frames")));
                }
            }
        }
    } else if depth != Depth::U8 || t.filter.is_some_and(|f| f.is_label()) {
        return Err(options(format!(
            "{}: DICOM frames are JPEG baseline by default, 8-bit samples; a {source} image needs lossless frames: --codec raw writes them (native, 8 or 16 bits), or --tile-type u8 stores it in 8 bits",
            output.path.shown()
        )));
    }
    if source.channels.has_alpha() && !t.flatten {
        return Err(options(format!(
            "{}: a {source} image has alpha, which {} frames cannot hold: add --flatten (over --background, white by default)",
            output.path.shown(),
            if native || jxl { "DICOM whole-slide" } else { "JPEG" }
        )));
    }
    let Some(pixel_size) = own.ome_zarr.pixel_size else {
        return Err(options(format!(
            "{}: a DICOM whole-slide image states its pixel spacing (a type 1 attribute), and the input states no square pixel size (an Aperio MPP, OME-XML's PhysicalSizeX/Y, resolution tags in centimetres): give --pixel-size, e.g. 0.25um",
            output.path.shown()
        )));
    };
    let requested = Requested {
        tile_size: Some(t.tile_size.unwrap_or(dicom::DEFAULT_TILE_SIZE)),
        border: Some(0),
        codec: Some(match transfer {
            dicom::Transfer::Native => CodecChoice::Raw,
            _ if jxl => CodecChoice::Jxl,
            _ => CodecChoice::Jpeg,
        }),
        max_memory: Some(at.budget.bytes()),
        filename_format: None,
        zstd_level: None,
        ..t.clone()
    };
    let (opts, _) = settings::resolve(&requested, None, source)?;
    let mut opts = at.coded_as_stored(opts, t.subsampling);
    // A source's 4:4:4 JPEG tiles are not taken: no whole-slide image states YBR_FULL frames.
    if let (None, Codec::Jpeg { subsampling: s @ Subsampling::S444, .. }) = (t.subsampling, &mut opts.codec) {
        *s = Subsampling::S420;
    }
    let layout = opts.layout(at.header.width, at.header.height)?;
    let stored = opts.codec.stored_layout(source, opts.flatten, opts.tile_depth)?;
    let (quality, photometric, coding) = match opts.codec {
        Codec::Jpeg { quality, subsampling } => {
            let photometric = dicom::Photometric::of(stored.channels, subsampling);
            (quality, photometric, format!("jpeg q{quality} {}", photometric.name()))
        }
        // The associated images' frames are native too; the quality is not used.
        Codec::Raw => (settings::DEFAULT_QUALITY, dicom::Photometric::native(stored.channels), "native".to_string()),
        // JPEG XL frames decode to the samples as they are, grey or RGB (the XYB transform
        // of lossy frames is the codestream's own); the associated images' are JPEG baseline.
        Codec::Jxl { quality, effort } => {
            let coding = match quality {
                Some(q) => format!("jxl q{q} effort {}", effort.get()),
                None => format!("jxl lossless effort {}", effort.get()),
            };
            (settings::DEFAULT_QUALITY, dicom::Photometric::native(stored.channels), coding)
        }
        other => return Err(TilerError::Internal(format!("DICOM frames from --codec {}", other.name()))),
    };
    let uid_root = own.dicom.uid_root.clone().unwrap_or_else(|| dicom::DEFAULT_ROOT.to_string());
    dicom::check_root(&uid_root)?;
    let meta = own.dicom.meta.clone().unwrap_or_default();
    let name = at.name(own);
    // What the UIDs are a hash of: the input as it is, and what shapes the pixels and the
    // attributes.
    let input = crate::shard::fingerprint::fingerprint(at.input).unwrap_or_else(|_| at.input.display().to_string());
    let given: Vec<String> = meta.iter().map(|(k, v)| format!("{k}={v}")).collect();
    let identity = format!(
        "input {input}; {}x{} tile {} levels {}; {coding}; {stored}; filter {:?}; background {:?}; pixel {}; name {name}; {}",
        layout.width,
        layout.height,
        layout.tile_size,
        layout.lod_count,
        opts.filter,
        opts.background,
        micrometres(pixel_size),
        given.join("; ")
    );
    // The associated images (label, overview, thumbnail), each its own instance, unless left
    // out; their kinds and sizes are part of the identity.
    let (associated, associated_left_out) = at.associated(own.no_associated)?;
    let mut identity = identity;
    for a in &associated {
        identity += &format!("; {} {}x{} {}", a.kind.name(), a.width, a.height, a.origin());
    }
    let made = match meta.get("AcquisitionDateTime") {
        Some(dt) => date_time(dt),
        None => modified(at.input),
    };
    let spec = dicom::Spec {
        layout,
        copied: Vec::new(),
        stored,
        photometric,
        transfer,
        pixel_mm: dicom::millimetres(micrometres(pixel_size)),
        name,
        uid_root,
        identity,
        made,
        meta,
        associated,
        quality,
        jxl_effort: match opts.codec {
            Codec::Jxl { effort, .. } => Some(effort),
            _ => None,
        },
        associated_bytes: at.associated_bytes(),
        associated_left_out,
        source_lossy: at.lossy.to_vec(),
    };
    spec.check()?;
    at.limits().check_pyramid(&layout, false)?;
    at.limits()
        .check_memory(&format!("the index of the DICOM series' {} frames", layout.total_tiles()), spec.index_bytes())?;
    let claim = at.claim(&output.path, Product::Dicom)?;
    Ok(Planned {
        output,
        opts,
        layout,
        changed: None,
        claim,
        work: Work::Dicom { spec: Box::new(spec), levels: own.levels },
    })
}

/// A DICOM date-time given (YYYY at least) as the 14 digits YYYYMMDDHHMMSS, the parts not
/// given the earliest.
fn date_time(given: &str) -> String {
    let whole = given.split('.').next().unwrap_or_default();
    let earliest = "00000101000000";
    format!("{whole}{}", &earliest[whole.len().min(14)..])
}

/// The modification time of `path` as YYYYMMDDHHMMSS in UTC; the epoch where it has none.
fn modified(path: &Path) -> String {
    let seconds = std::fs::metadata(path)
        .and_then(|m| m.modified())
        .ok()
        .and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok())
        .map_or(0, |d| d.as_secs());
    let (days, rest) = (seconds / 86_400, seconds % 86_400);
    let (y, m, d) = civil(days as i64);
    format!("{y:04}{m:02}{d:02}{:02}{:02}{:02}", rest / 3600, rest % 3600 / 60, rest % 60)
}

/// The proleptic Gregorian date `days` after 1970-01-01 (the days-from-civil inverse of the
/// era arithmetic: 400-year eras of 146097 days, years starting in March).
fn civil(days: i64) -> (i64, u32, u32) {
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = (doy - (153 * mp + 2) / 5 + 1) as u32;
    let m = if mp < 10 { mp + 3 } else { mp - 9 } as u32;
    let y = yoe + era * 400 + i64::from(m <= 2);
    (y, m, d)
}

/// A pixel size in micrometres.
fn micrometres(p: crate::formats::ome_zarr::PixelSize) -> f64 {
    let per = match p.unit {
        "nanometer" => 1e-3,
        "millimeter" => 1e3,
        "centimeter" => 1e4,
        "meter" => 1e6,
        _ => 1.0,
    };
    p.value * per
}

fn options(message: String) -> TilerError {
    TilerError::Options(message)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pixel::{Channels, Depth};

    fn rgb(width: u32, height: u32) -> ImageHeader {
        ImageHeader { width, height, layout: PixelLayout::new(Channels::Rgb, Depth::U8) }
    }

    /// Plans `outputs` (paths under a folder that does not exist: nothing is claimed that is
    /// there) of a 1000 x 700 RGB image: `Ok` or the message.
    fn plan(outputs: &[(Format, &str)], settings: Settings) -> std::result::Result<Plan, String> {
        let root = Path::new("/nonexistent-vortex-plan-test");
        let outputs = outputs.iter().map(|(f, p)| Output::new(*f, root.join(p))).collect();
        Plan::new(outputs, &settings, &rgb(1000, 700), &[Path::new("/nonexistent-input/slide.png")], Budget::default())
            .map_err(|e| e.to_string())
    }

    fn with(f: impl FnOnce(&mut Settings)) -> Settings {
        let mut s = Settings::default();
        f(&mut s);
        s
    }

    const DZI: Format = Format::Viewer(Viewer::Dzi);
    const IIIF: Format = Format::Viewer(Viewer::Iiif);
    const XYZ: Format = Format::Viewer(Viewer::Xyz);
    const TIFF: Format = Format::Tiff(Flavour::Generic);
    const OME_TIFF: Format = Format::Tiff(Flavour::Ome);
    const DICOM: Format = Format::Dicom;

    fn with_pixel_size(f: impl FnOnce(&mut Settings)) -> Settings {
        with(|s| {
            s.ome_zarr.pixel_size = Some("0.5um".parse().unwrap());
            f(s);
        })
    }

    /// Every refusal `split` makes of the outputs it is given, as a table: the outputs, the
    /// settings, and what the message must say.
    #[test]
    fn refusals() {
        type Case = (&'static [(Format, &'static str)], Settings, &'static str);
        let cases: Vec<Case> = vec![
            (&[], Settings::default(), "a run needs an output"),
            (&[(Format::Tiles, "a"), (DZI, "a")], Settings::default(), "paths of their own"),
            (&[(Format::Tiles, "a"), (Format::Pack, "a/b.vtpk")], Settings::default(), "neither inside the other"),
            (&[(Format::Tiles, "a")], with(|s| s.name = Some("x".into())), "--name belongs to a viewer layout"),
            (&[(Format::Pack, "a.vtpk")], with(|s| s.overlap = Some(1)), "--overlap belongs to a viewer layout"),
            (&[(Format::Tiles, "a")], with(|s| s.iiif_id = Some("https://x.org/a".into())), "--iiif-id belongs"),
            (
                &[(Format::Tiles, "a")],
                with(|s| s.ome_zarr.shard_chunks = Some(4)),
                "--shard-chunks belongs to --layout ome-zarr",
            ),
            (
                &[(DZI, "a")],
                with(|s| s.tiles.filename_format = Some("%1$s.png".into())),
                "--filename-format is for --layout vortex",
            ),
            (&[(DZI, "a")], with(|s| s.tiles.border = Some(1)), "--overlap (Deep Zoom's), not --border"),
            (&[(IIIF, "a")], with(|s| s.tiles.border = Some(1)), "--layout iiif tiles have no border"),
            (&[(IIIF, "a")], with(|s| s.overlap = Some(1)), "--overlap is Deep Zoom's"),
            (&[(DZI, "a")], with(|s| s.iiif_id = Some("https://x.org/a".into())), "--iiif-id names a IIIF image"),
            (&[(IIIF, "a")], with(|s| s.iiif_id = Some("ftp://x".into())), "--iiif-id"),
            (&[(DZI, "a")], with(|s| s.name = Some("a/b".into())), "must be a plain file name"),
            (&[(XYZ, "a")], with(|s| s.tiles.codec = Some(CodecChoice::Zstd)), "tiles are image files"),
            (
                &[(IIIF, "a")],
                with(|s| {
                    s.iiif_id = Some("https://x.org/a".into());
                    s.tiles.codec = Some(CodecChoice::Png);
                }),
                "whose one required format is JPEG",
            ),
            (&[(Format::Tiles, "a")], with(|s| s.tiles.codec = Some(CodecChoice::Raw)), "writes packs only"),
            (
                &[(Format::Pmtiles, "a.pmtiles")],
                with(|s| s.keep_icc = Some(vec![0; 200])),
                "a PMTiles archive has nowhere",
            ),
            (&[(Format::OmeZarr, "a.ome.zarr")], with(|s| s.keep_icc = Some(vec![0; 200])), "OME-Zarr has nowhere"),
            (&[(Format::OmeZarr, "a.ome.zarr")], with(|s| s.overlap = Some(1)), "OME-Zarr chunks do not overlap"),
            (&[(Format::OmeZarr, "a.ome.zarr")], with(|s| s.tiles.quality = Some(80)), "--quality does not apply"),
            (&[(Format::OmeZarr, "a.ome.zarr")], with(|s| s.tiles.border = Some(2)), "chunks have no border"),
            (
                &[(Format::OmeZarr, "a.ozx")],
                with(|s| s.ome_zarr.version = Some(crate::formats::ome_zarr::Version::V04)),
                "holds OME-Zarr 0.5",
            ),
            (&[(TIFF, "a.tif")], with(|s| s.tiles.border = Some(2)), "TIFF tiles have no border"),
            (&[(OME_TIFF, "a.ome.tif")], with(|s| s.tiles.tile_size = Some(100)), "a multiple of 16"),
            (
                &[(TIFF, "a.tif")],
                with(|s| s.tiles.codec = Some(CodecChoice::Png)),
                "jpeg, jxl, deflate, lzw, zstd or raw",
            ),
            (
                &[(Format::Pack, "a.vtpk")],
                with(|s| s.tiles.codec = Some(CodecChoice::Deflate)),
                "a.vtpk (pack): --codec deflate compresses a TIFF output's tiles",
            ),
            (
                &[(TIFF, "a.tif"), (DZI, "web")],
                with(|s| s.tiles.codec = Some(CodecChoice::Lzw)),
                "web (dzi): --codec lzw compresses a TIFF output's tiles",
            ),
            (
                &[(TIFF, "a.tif")],
                with(|s| {
                    s.tiles.codec = Some(CodecChoice::Deflate);
                    s.tiles.quality = Some(80);
                }),
                "--quality is JPEG's",
            ),
            (&[(TIFF, "a.tif")], with(|s| s.tiles.zstd_level = Some(5)), "--zstd-level is zstd's"),
            (&[(TIFF, "a.tif")], with(|s| s.overlap = Some(1)), "--overlap does not apply to a tiff output"),
            (&[(OME_TIFF, "a.ome.tif")], with(|s| s.tiles.filename_format = Some("%1$s.png".into())), "ome-tiff"),
            (&[(Format::Pack, "a.vtpk")], with(|s| s.tiff.bigtiff = BigTiff::Always), "--bigtiff belongs to a TIFF"),
            (&[(DICOM, "a")], Settings::default(), "give --pixel-size"),
            (&[(DICOM, "a")], with_pixel_size(|s| s.tiles.codec = Some(CodecChoice::Zstd)), "JPEG baseline"),
            (&[(DICOM, "a")], with_pixel_size(|s| s.tiles.border = Some(1)), "DICOM frames have no border"),
            (&[(DICOM, "a")], with_pixel_size(|s| s.tiles.tile_depth = Some(Depth::U16)), "8-bit samples"),
            (
                &[(DICOM, "a")],
                with_pixel_size(|s| {
                    s.tiles.codec = Some(CodecChoice::Raw);
                    s.tiles.tile_depth = Some(Depth::F32);
                }),
                "8- or 16-bit unsigned",
            ),
            (
                &[(DICOM, "a")],
                with_pixel_size(|s| {
                    s.tiles.codec = Some(CodecChoice::Raw);
                    s.tiles.subsampling = Some(Subsampling::S444);
                }),
                "--subsampling is JPEG's",
            ),
            (
                &[(DICOM, "a")],
                with_pixel_size(|s| s.tiles.codec = Some(CodecChoice::Deflate)),
                "Deflated transfer syntax is not written",
            ),
            (&[(DICOM, "a")], with_pixel_size(|s| s.keep_icc = Some(vec![0; 200])), "a DICOM series"),
            (&[(TIFF, "a.tif")], with(|s| s.dicom.uid_root = Some("1.2".into())), "--dicom-uid-root belongs"),
            (&[(DICOM, "a")], with_pixel_size(|s| s.dicom.uid_root = Some("1.2.".into())), "--dicom-uid-root"),
        ];
        for (outputs, settings, want) in cases {
            match plan(outputs, settings) {
                Ok(_) => panic!("{outputs:?} planned; expected an error saying {want:?}"),
                Err(message) => assert!(message.contains(want), "{outputs:?}: {message:?} lacks {want:?}"),
            }
        }
    }

    /// A setting goes to the outputs that read it: Deep Zoom's overlap beside a pack, the
    /// pack's border beside Deep Zoom, JPEG quality beside OME-Zarr's zstd chunks.
    #[test]
    fn each_output_reads_its_own_settings() {
        let settings = with(|s| {
            s.overlap = Some(0);
            s.tiles.border = Some(0);
            s.tiles.quality = Some(70);
            s.tiles.tile_size = Some(256);
            // The image outputs' codec: not OME-Zarr's, which would refuse it alone.
            s.tiles.codec = Some(CodecChoice::Jpeg);
        });
        let p = plan(&[(DZI, "web"), (Format::Pack, "a.vtpk"), (Format::OmeZarr, "a.ome.zarr")], settings).unwrap();
        let [dzi, pack, zarr] = &p.outputs[..] else { panic!("three outputs") };
        assert_eq!((dzi.layout.tile_size, dzi.layout.border), (256, 0));
        assert_eq!((pack.layout.tile_size, pack.layout.border), (256, 0));
        assert_eq!(
            dzi.opts,
            SplitOptions { down_to_one_texel: true, ..pack.opts.clone() },
            "one pyramid but for its depth"
        );
        assert!(matches!(pack.opts.codec, crate::codec::Codec::Jpeg { quality: 70, .. }));
        assert!(matches!(zarr.opts.codec, crate::codec::Codec::Raw), "OME-Zarr's chunks: {:?}", zarr.opts.codec);
        assert_eq!(p.total_tiles(), dzi.layout.total_tiles() + pack.layout.total_tiles() + zarr.layout.total_tiles());
    }

    /// A TIFF beside Deep Zoom of the same tiles shares its pyramid (JPEG by default); the
    /// codec flags say its compression; 16 bits or alpha are Deflate by default; OME-TIFF's
    /// levels are box means; `--pixel-size` is a TIFF's too.
    #[test]
    fn a_tiff_reads_the_run_s_settings() {
        let settings = with(|s| {
            s.overlap = Some(0);
            s.tiles.tile_size = Some(256);
            s.ome_zarr.pixel_size = Some("0.5um".parse().unwrap());
            s.keep_icc = Some(vec![7; 300]);
        });
        let p = plan(&[(TIFF, "a.tif"), (DZI, "web"), (OME_TIFF, "b.ome.tif")], settings).unwrap();
        let [tiff, dzi, ome] = &p.outputs[..] else { panic!("three outputs") };
        assert_eq!(dzi.opts, SplitOptions { down_to_one_texel: true, ..tiff.opts.clone() }, "one pyramid");
        let Work::Tiff { spec, .. } = &tiff.work else { panic!("a TIFF's work") };
        assert!(matches!(spec.compression, Compression::Jpeg { .. }), "{:?}", spec.compression);
        let l = &spec.layout;
        assert_eq!((l.width, l.height, l.tile_size, l.lod_count), (1000, 700, 256, 3));
        assert_eq!(spec.pixel_size, Some(tiff::Micrometres(0.5)));
        assert_eq!(spec.icc, Some(vec![7; 300]), "--keep-icc: the profile the samples are in");
        assert_eq!(spec.name, "slide");
        assert_eq!(ome.opts.filter, Filter::Box, "OME-TIFF's levels are means of the stored values");

        let zstd = with(|s| {
            s.tiles.codec = Some(CodecChoice::Zstd);
            s.tiles.zstd_level = Some(9);
        });
        let p = plan(&[(TIFF, "a.tif")], zstd).unwrap();
        let Work::Tiff { spec, .. } = &p.outputs[0].work else { panic!() };
        assert_eq!(spec.compression, Compression::Zstd { level: 9 });
        assert_eq!(
            p.outputs[0].opts.codec,
            crate::codec::Codec::Zstd { level: 9, filter: crate::codec::RowFilter::Delta },
            "the encoders compress the tiles, with the predictor"
        );

        let header = ImageHeader { width: 300, height: 200, layout: PixelLayout::new(Channels::Rgba, Depth::U16) };
        let outputs = vec![Output::new(OME_TIFF, "/nonexistent-vortex-plan-test/c.ome.tiff")];
        let p = Plan::new(outputs, &Settings::default(), &header, &[], Budget::default()).unwrap();
        let Work::Tiff { spec, .. } = &p.outputs[0].work else { panic!() };
        assert_eq!(spec.compression, Compression::Deflate { level: 6 });
        assert_eq!(spec.stored, PixelLayout::new(Channels::Rgba, Depth::U16));
    }

    /// A DICOM series beside Deep Zoom of the same tiles shares its pyramid; its frames are
    /// JPEG at the run's subsampling (YBR_FULL_422 for 4:2:0); the pixel size in mm.
    #[test]
    fn a_dicom_series_reads_the_run_s_settings() {
        let settings = with_pixel_size(|s| {
            s.overlap = Some(0);
            s.tiles.tile_size = Some(256);
        });
        let p = plan(&[(DICOM, "a"), (DZI, "web")], settings).unwrap();
        let [dicom, dzi] = &p.outputs[..] else { panic!("two outputs") };
        assert_eq!(dzi.opts, SplitOptions { down_to_one_texel: true, ..dicom.opts.clone() }, "one pyramid");
        let Work::Dicom { spec, .. } = &dicom.work else { panic!("a DICOM series' work") };
        assert_eq!(spec.photometric, dicom::Photometric::YbrFull422);
        assert_eq!(spec.pixel_mm, 0.0005);
        assert_eq!((spec.layout.tile_size, spec.layout.lod_count), (256, 3));
        assert_eq!(spec.name, "slide");
        assert_eq!(spec.uid_root, dicom::DEFAULT_ROOT);
        assert_eq!(spec.transfer, dicom::Transfer::JpegBaseline);

        // `--codec raw`: native frames of the samples as they are, 16-bit kept; the encoders
        // write raw tiles; the UIDs differ from the JPEG series'.
        let header = ImageHeader { width: 300, height: 200, layout: PixelLayout::new(Channels::Grey, Depth::U16) };
        let settings = with_pixel_size(|s| s.tiles.codec = Some(CodecChoice::Raw));
        let outputs = vec![Output::new(DICOM, "/nonexistent-vortex-plan-test/n")];
        let p = Plan::new(outputs, &settings, &header, &[], Budget::default()).unwrap();
        let Work::Dicom { spec: native, .. } = &p.outputs[0].work else { panic!("a DICOM series' work") };
        assert_eq!(native.transfer, dicom::Transfer::Native);
        assert_eq!(native.photometric, dicom::Photometric::Monochrome);
        assert_eq!(native.stored, PixelLayout::new(Channels::Grey, Depth::U16));
        assert_eq!(p.outputs[0].opts.codec, crate::codec::Codec::Raw);
        assert!(native.identity.contains("; native;"), "{}", native.identity);
    }

    #[test]
    fn a_name_says_its_format() {
        for (name, want) in [
            ("a.vtpk", Some(Format::Pack)),
            ("A.PMTILES", Some(Format::Pmtiles)),
            ("slide.ome.zarr", Some(Format::OmeZarr)),
            ("slide.ome.zarr/", Some(Format::OmeZarr)),
            ("slide.ozx", Some(Format::OmeZarr)),
            ("web", None),
            ("x.zarr", None),
            ("scan.tif", Some(TIFF)),
            ("scan.TIFF", Some(TIFF)),
            ("slide.ome.tif", Some(OME_TIFF)),
            ("SLIDE.OME.TIFF", Some(OME_TIFF)),
            ("ortho.cog.tif", Some(Format::Tiff(Flavour::Cog))),
            ("ORTHO.COG.TIFF", Some(Format::Tiff(Flavour::Cog))),
            ("x.tif.vtpk", Some(Format::Pack)),
        ] {
            assert_eq!(Format::of_path(Path::new(name)), want, "{name}");
        }
    }
}
