//! `split`: flags to options, the pipeline with a progress bar, one summary line.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result, bail};

use vortex_tiler::background::Background;
use vortex_tiler::codec::{Bc7Effort, PngLevel, Subsampling};
use vortex_tiler::error::ShowPath;
use vortex_tiler::layout::Layout;
use vortex_tiler::limits::Limits;
use vortex_tiler::output::{Existing, Product};
use vortex_tiler::pixel::Depth;
use vortex_tiler::pyramid::Filter;
use vortex_tiler::settings::{self, CodecChoice, Destination, Plan, Requested};
use vortex_tiler::sink::icc::{Profile, WithProfile};
use vortex_tiler::sink::{DirSink, PackSink, PmtilesSink, TileSink};
use vortex_tiler::source::RowSource;
use vortex_tiler::split::SplitOptions;
use vortex_tiler::tile_dir::info::InfoFile;
use vortex_tiler::viewer::{Viewer, ViewerTiles, dzi, iiif};
use vortex_tiler::{scale_out, source, split};

use super::report;
use super::shard::shard_path;

mod ome_zarr;

#[derive(clap::Args, Debug)]
pub struct SplitArgs {
    /// Image to cut: PNG, TIFF/BigTIFF, JPEG, PPM/PGM stream in bands; WebP, GIF, BMP, TGA and
    /// QOI are decoded whole within --max-memory.
    #[arg(value_name = "INPUT", required_unless_present_any = ["input_flag", "channel"])]
    input: Option<PathBuf>,

    /// The input, spelled as the original tool did (--input=in.png).
    #[arg(long = "input", value_name = "INPUT", conflicts_with = "input")]
    input_flag: Option<PathBuf>,

    /// Tile file names, printf-like with positional arguments 1 = LOD, 2 = x, 3 = y; '/' makes
    /// subdirectories [default: lod%1$02s-x%2$04s-y%3$04s.<ext>].
    #[arg(long, visible_alias = "ff", value_name = "PATTERN")]
    filename_format: Option<String>,

    /// Keep the stored row order: by default an EXIF orientation (JPEG, TIFF, PNG eXIf) is
    /// applied, so the tiles show the image as viewers and `vips autorot` do (orientations
    /// other than a left-right mirror hold the image, or read it in passes, within
    /// --max-memory).
    #[arg(long)]
    no_autorotate: bool,

    /// Keep the texels in the colours of the input's ICC profile, and the profile in every
    /// JPEG and PNG tile file (APP2, iCCP) and in info.json (base64, `iccProfile`; a pack's
    /// tiles rely on it), instead of converting them to sRGB [default: convert: browsers show
    /// untagged tiles as sRGB, and the linear-light LOD filters assume sRGB].
    #[arg(long)]
    keep_icc: bool,

    /// Map 32-bit integer or float samples linearly onto 8 bits (16 with --tile-type
    /// unsignedShort): MIN to 0, MAX to the top code, e.g. 0:4095 or -0.5:1.5 [default: none;
    /// without it such sources go only to raw/zstd packs and OME-Zarr, since JPEG and PNG would
    /// cut their range]. Every channel is mapped, alpha included; samples outside (and NaN) are
    /// clamped and counted in the summary, never cut silently.
    #[arg(long, value_name = "MIN:MAX", allow_hyphen_values = true)]
    range: Option<source::range::Range>,

    /// A TIFF holding several images: cut its Nth directory, counted from 0 as tiffinfo and
    /// libvips count them (a reduced level or a slide's label included) [default: the first
    /// full-resolution image; the summary says which page was read and what was skipped].
    #[arg(long, value_name = "N", conflicts_with = "series")]
    page: Option<u32>,

    /// Cut the Nth series: an OME-TIFF's Nth OME-XML Image, or the Nth full-resolution image
    /// of another multi-page TIFF (reduced levels and label/macro/thumbnail images skipped)
    /// [default: 0].
    #[arg(long, value_name = "N")]
    series: Option<u32>,

    /// One channel's image, a grey image of the others' size and sample type; repeated, in
    /// channel order, in place of INPUT: with --layout ome-zarr, one array of that many
    /// channels (docs/ome-zarr.md).
    #[arg(long, value_name = "FILE")]
    channel: Vec<PathBuf>,

    /// Channels to cut, counted from 0, e.g. 0,1,2: any number of them into --layout ome-zarr
    /// (a `c` axis), one (grey) or three (RGB) into the other layouts [default: every channel;
    /// an image of more than four (a TIFF of more samples or separate planes, an OME-TIFF's
    /// planes, --channel files) needs --layout ome-zarr or a pick].
    #[arg(long, value_name = "LIST", value_delimiter = ',')]
    channels: Option<Vec<usize>>,

    #[command(flatten)]
    out: OutputArgs,
}

/// What `split` and `convert` write, and how.
#[derive(clap::Args, Debug)]
pub struct OutputArgs {
    /// Output directory (created; replaced only if it holds nothing but a previous output:
    /// its info.json and the tiles that names).
    #[arg(
        short,
        long,
        value_name = "DIR",
        required_unless_present_any = ["pack", "pmtiles"],
        conflicts_with_all = ["pack", "pmtiles"]
    )]
    output: Option<PathBuf>,

    /// Write one pack file instead of a directory of tiles (docs/pack-format.md). An existing
    /// pack is replaced; any other file only with --force.
    #[arg(long, value_name = "FILE")]
    pack: Option<PathBuf>,

    /// Write one PMTiles v3 archive of the web-map (XYZ) pyramid instead of a directory:
    /// one file any static web host serves to Leaflet, MapLibre or OpenLayers with the
    /// `pmtiles` JavaScript package (docs/web.md). JPEG or PNG tiles of --tile-size (default
    /// 256), zoom 0 the whole image; bounds name the image's place on the web-mercator square,
    /// as the image has no map coordinates. An existing PMTiles archive is replaced; any other
    /// file only with --force.
    #[arg(long, value_name = "FILE", conflicts_with = "pack")]
    pmtiles: Option<PathBuf>,

    /// Replace a regular file at --pack or --pmtiles that is not one. Never replaces a directory, a
    /// device, a FIFO, a link or the input.
    #[arg(long)]
    force: bool,

    #[command(flatten)]
    pack_layout: super::PackLayout,

    /// How the output directory is laid out: vortex (tiles + info.json, this tool's), or one a
    /// viewer opens as it is: dzi (NAME.dzi + NAME_files/, Deep Zoom as vips dzsave writes
    /// it: OpenSeadragon), iiif (IIIF Image API 3.0 level 0: info.json + static tiles), xyz
    /// ({z}/{x}/{y}, Leaflet/OpenLayers/MapLibre) or google ({z}/{y}/{x} as vips writes it).
    /// See docs/viewers.md. ome-zarr: an OME-Zarr image for microscopy tools (napari, Fiji,
    /// QuPath), -o DIR.ome.zarr or -o FILE.ozx (docs/ome-zarr.md).
    #[arg(long, value_enum, default_value = "vortex", value_name = "LAYOUT")]
    layout: OutputLayout,

    /// --layout dzi: the pyramid's name, NAME.dzi and NAME_files/ [default: the input's file
    /// stem].
    #[arg(long, value_name = "NAME")]
    name: Option<String>,

    /// --layout dzi: texels each tile shares with each neighbour (Deep Zoom's Overlap; not
    /// --border: an edge tile has no overlap where it has no neighbour) [default: 1].
    #[arg(long, value_name = "N")]
    overlap: Option<u32>,

    /// --layout iiif: the absolute http(s) URL the directory will be served at, e.g.
    /// https://example.org/iiif/slide. It becomes info.json's id and makes the directory a
    /// conformant IIIF level-0 service there: full/max (at most 2048 texels on a side, as
    /// maxWidth/maxHeight say) and the whole-image sizes are written too [default: '.',
    /// relative to the viewer's page, only the files libvips writes; serve rewrites it].
    #[arg(long, value_name = "URL")]
    iiif_id: Option<String>,

    #[command(flatten)]
    ome_zarr: ome_zarr::OmeZarrArgs,

    /// Side of a stored tile in texels, borders included [default: 128]. LOD 0 has
    /// ceil(width / payload) x ceil(height / payload) pages (payload = tile size - 2 x border),
    /// each LOD half as many per axis (rounding up), down to the first LOD of one page. In a
    /// viewer layout, the viewer's tile side (Deep Zoom: without overlap) [default: dzi 254,
    /// iiif 512, xyz and google 256]. In --layout ome-zarr, the chunk side [default: 256].
    #[arg(long, value_name = "N")]
    tile_size: Option<u32>,

    /// Texels copied from neighbouring pages into each tile edge, for filtering on the GPU: 1 is
    /// enough for bilinear and trilinear filtering without seams, with or without anisotropic
    /// filtering (vortex's probes each look up their own page; id Tech 5 used a border of 4 for
    /// its anisotropic filtering); 0 for the nearest filter and for viewers that never filter across
    /// tiles (docs/gpu-sampling.md) [default: 1; 0 where an existing info.json has no border, as
    /// the thesis's files].
    #[arg(long, value_name = "N")]
    border: Option<u32>,

    #[command(flatten)]
    enc: CodecArgs,

    /// Decode and encode every tile, even those the source stores as JPEG tiles on the grid of
    /// the finest level's pages [default: copy those: a JPEG-tiled TIFF or slide (or, for
    /// convert, JPEG tiles without overlap) cut at its tile size with no border or overlap
    /// (--layout dzi --overlap 0, iiif, xyz, or --border 0) keeps the stored tiles byte for
    /// byte, with no generation loss and no encoding time (edge tiles that dzi and iiif crop
    /// are cropped losslessly from them); the summary says how many were copied, how many of
    /// them cropped, and at what quality they were stored. An explicit --quality or --subsampling
    /// re-encodes them too; docs/sources.md].
    #[arg(long)]
    reencode: bool,

    /// Fill for the padding in the last page of each row and column, between the image's edge
    /// and the page's: edge (repeat the image's edge), #rrggbb, #rrggbbaa, r,g,b[,a] or a grey
    /// level [default: edge].
    #[arg(long, value_name = "COLOUR")]
    background: Option<Background>,

    /// Composite alpha over --background (black if edge) so that RGBA sources can be stored as JPEG.
    #[arg(long)]
    flatten: bool,

    /// How each LOD is made from the finer ones [default: linear-premultiplied]. box, linear,
    /// premultiplied and linear-premultiplied are exact means over the source footprint,
    /// rounded once (linear: in linear light; premultiplied: colour weighted by alpha, no
    /// fringes from transparent texels; box: of the stored values, as vips dzsave averages);
    /// lanczos3 and mitchell resample each LOD from the previous one. mode and nearest are for
    /// label (segmentation) images: each texel is one of its 2x2 block in the previous LOD (the
    /// most frequent, ties to the first of top-left, top-right, bottom-left, bottom-right; or
    /// the top-left), so no level holds a value the image does not; lossless codecs only.
    /// --layout ome-zarr defaults to box. 32-bit integer and float images default to box (their
    /// values are not sRGB codes) and take box, nearest and (integers) mode only.
    #[arg(long, value_parser = super::named::<Filter>())]
    filter: Option<Filter>,

    /// Sample type of stored tiles: unsignedByte or unsignedShort (png, raw, zstd, zstd-delta),
    /// or for a float source half (raw, zstd: 16-bit floats, what a GPU uploads as R16F, half
    /// the bytes; rounded to nearest even, beyond 65504 infinite) [default: the source's;
    /// 32-bit integer and float sources keep unsignedInt and float].
    #[arg(long, value_name = "TYPE", value_parser = super::parse_tile_type)]
    tile_type: Option<Depth>,

    /// Most memory a run may hold at once, checked before allocating: an image decoded whole
    /// when its format cannot be streamed (interlaced PNG, progressive JPEG, one-strip TIFF,
    /// WebP, ...), a pack's index, and the run's stages together (the source decoder's
    /// buffers, the read-ahead, the bands, the tiles and encodings in flight: --json's
    /// memory.plannedBytes, their most at once); e.g. 512M, 4G. An image too wide for that is
    /// cut in vertical stripes, reading the source once per stripe, for the same tiles; a
    /// budget too small even for those is refused before the run, saying what it needs.
    #[arg(long, value_name = "SIZE", default_value = "1G", value_parser = super::parse_size)]
    max_memory: u64,

    /// Make one shard of a split across machines, into a shard pack (--pack): I/N is shard I
    /// of N, counting from 0; auto reads the index from a Slurm job array
    /// (SLURM_ARRAY_TASK_ID, SLURM_ARRAY_TASK_COUNT) or a Kubernetes Indexed Job
    /// (JOB_COMPLETION_INDEX, with --shards). '{shard}' in --pack becomes the index.
    /// `vortex-tiler merge` joins the N shard packs into the pack --pack alone makes, byte for
    /// byte. See docs/scale-out.md.
    #[arg(long, value_name = "I/N|auto")]
    shard: Option<super::shard::ShardArg>,

    /// With --shard auto: how many shards there are (a Kubernetes Job's completions; a Slurm
    /// array says so itself).
    #[arg(long, value_name = "N", requires = "shard")]
    shards: Option<u32>,

    #[command(flatten)]
    run: super::RunFlags,
}

/// `--layout`: this tool's tile directory or a viewer's.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum OutputLayout {
    /// Tiles named by --filename-format plus info.json (docs/info-json.md).
    Vortex,
    /// Deep Zoom: NAME.dzi and NAME_files/LEVEL/COL_ROW.jpeg, as vips dzsave writes it.
    Dzi,
    /// IIIF Image API 3.0, level 0: info.json and {x},{y},{w},{h}/{w},{h}/0/default.jpg.
    Iiif,
    /// Web-map tiles {z}/{x}/{y}.jpg in square power-of-two levels, plus tilejson.json.
    Xyz,
    /// {z}/{y}/{x}.jpg, the order of vips dzsave --layout google.
    Google,
    /// OME-Zarr (-o DIR.ome.zarr, or -o FILE.ozx zipped): one array per level, chunks = pages.
    OmeZarr,
}

impl OutputLayout {
    fn viewer(self) -> Option<Viewer> {
        match self {
            OutputLayout::Vortex | OutputLayout::OmeZarr => None,
            OutputLayout::Dzi => Some(Viewer::Dzi),
            OutputLayout::Iiif => Some(Viewer::Iiif),
            OutputLayout::Xyz => Some(Viewer::Xyz),
            OutputLayout::Google => Some(Viewer::Google),
        }
    }
}

/// How tiles are encoded: `split`, `convert` and `pack` share these flags.
#[derive(clap::Args, Debug)]
pub struct CodecArgs {
    /// Tile codec [default: auto, or what the filename format's extension says]. raw, zstd,
    /// zstd-delta, bc1 and bc7 have no file format and write packs only.
    #[arg(long, value_parser = super::named::<CodecChoice>())]
    pub codec: Option<CodecChoice>,

    /// JPEG quality, 1-100 [default: 85].
    #[arg(long, value_name = "Q")]
    pub quality: Option<u8>,

    /// JPEG chroma subsampling [default: 420].
    #[arg(long, value_parser = super::named::<Subsampling>())]
    pub subsampling: Option<Subsampling>,

    /// PNG compression effort [default: fast].
    #[arg(long, value_parser = super::named::<PngLevel>())]
    pub png_compression: Option<PngLevel>,

    /// zstd level for --codec zstd and zstd-delta, 1-22 [default: 3].
    #[arg(long, value_name = "N", allow_negative_numbers = true)]
    pub zstd_level: Option<i32>,

    /// BC7 encoder effort, fastest first (Intel ISPC presets) [default: ultra-fast].
    #[arg(long, value_parser = super::named::<Bc7Effort>())]
    pub bc7_effort: Option<Bc7Effort>,
}

impl CodecArgs {
    /// These flags as the codec part of a request.
    pub fn requested(&self) -> Requested {
        Requested {
            codec: self.codec,
            quality: self.quality,
            subsampling: self.subsampling,
            png_level: self.png_compression,
            zstd_level: self.zstd_level,
            bc7_effort: self.bc7_effort,
            ..Requested::default()
        }
    }

    /// Whether any of them was given.
    pub fn any(&self) -> bool {
        let r = self.requested();
        r.codec.is_some()
            || r.quality.is_some()
            || r.subsampling.is_some()
            || r.png_level.is_some()
            || r.zstd_level.is_some()
            || r.bc7_effort.is_some()
    }
}

pub fn run(a: SplitArgs) -> Result<()> {
    let started = Instant::now();
    let input = a.input.or(a.input_flag);
    let pick = source::Pick { page: a.page, series: a.series };
    // Many channels (docs/ome-zarr.md): --channel files, --channels picks, or an image of more
    // channels than a texel holds.
    if let Some((set, inputs)) =
        ome_zarr::channel_set(input.as_deref(), &a.channel, a.channels.is_some(), pick, &a.out)?
    {
        return ome_zarr::tile_channels(set, a.channels.as_deref(), &inputs, a.filename_format, &a.out, started);
    }
    let input = input.context("an input image is required")?;
    let options =
        source::OpenOptions { max_memory: a.out.max_memory, autorotate: !a.no_autorotate, keep_icc: a.keep_icc, pick };
    let (mut source, kept_icc) = source::open_with(&input, options)?;
    if let Some(range) = a.range {
        source = source::range::map(source, range, a.out.tile_type.unwrap_or(Depth::U8))?;
    }
    tile(source, &input, a.filename_format, &a.out, started, kept_icc)
}

/// Runs the pipeline from `source` into the output `out` names, with the progress bar and
/// the summary line. `names` is the output filename format flag; `kept_icc` the profile the
/// texels are in (`--keep-icc`), for info.json.
impl OutputArgs {
    pub fn background(&self) -> Option<Background> {
        self.background
    }

    pub fn max_memory(&self) -> u64 {
        self.max_memory
    }

    /// --tile-type, where given (convert's --range maps onto it as split's does).
    pub fn tile_type(&self) -> Option<Depth> {
        self.tile_type
    }
}

pub fn tile(
    source: Box<dyn RowSource>,
    input: &Path,
    names: Option<String>,
    a: &OutputArgs,
    started: Instant,
    kept_icc: Option<Vec<u8>>,
) -> Result<()> {
    if a.layout == OutputLayout::OmeZarr {
        if kept_icc.is_some() {
            bail!(
                "--keep-icc keeps the profile in the JPEG and PNG tiles of a directory and in info.json (a pack's too); OME-Zarr has nowhere to keep it: leave --keep-icc out to convert the texels to sRGB"
            );
        }
        return ome_zarr::tile(source, input, names, a, started);
    }
    a.ome_zarr.refuse_elsewhere()?;
    if a.pmtiles.is_some() {
        if kept_icc.is_some() {
            bail!(
                "--keep-icc keeps the profile in the JPEG and PNG tiles of a directory and in info.json (a pack's too); a PMTiles archive has nowhere to keep it: leave --keep-icc out to convert the texels to sRGB"
            );
        }
        if !matches!(a.layout, OutputLayout::Vortex | OutputLayout::Xyz) {
            let layout = a.layout.viewer().map_or("ome-zarr", Viewer::name);
            bail!("--pmtiles holds the web-map (xyz) pyramid; --layout {layout} writes a directory (-o DIR)");
        }
        return tile_for_viewer(source, input, names, a, Viewer::Xyz, started, None);
    }
    if let Some(viewer) = a.layout.viewer() {
        return tile_for_viewer(source, input, names, a, viewer, started, kept_icc.as_deref());
    }
    for (given, flag) in
        [(a.name.is_some(), "--name"), (a.overlap.is_some(), "--overlap"), (a.iiif_id.is_some(), "--iiif-id")]
    {
        if given {
            bail!(
                "{flag} belongs to a viewer layout (--layout dzi, iiif, xyz or google); this tool's tiles have --border"
            );
        }
    }
    let limits = Limits { memory: a.max_memory, ..Limits::default() };
    let shard = match (&a.shard, &a.pack) {
        (None, Some(pack)) if pack.to_string_lossy().contains("{shard}") => {
            bail!("'{{shard}}' in --pack {} stands for a shard's index: add --shard I/N or --shard auto", pack.shown())
        }
        (None, _) => None,
        (Some(_), None) => bail!("--shard writes a shard pack: give --pack FILE (merge joins them into one pack)"),
        (Some(s), Some(pack)) => {
            let chosen = s.choose(a.shards, |name| std::env::var(name).ok())?;
            let path = shard_path(pack, &chosen);
            // Every task of an array writes into the same directory: the first makes it.
            if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
                std::fs::create_dir_all(dir)
                    .with_context(|| format!("creating {} for the shard packs", dir.shown()))?;
            }
            Some((path, chosen))
        }
    };
    let (dest, product) = match (&a.output, &a.pack, &shard) {
        (_, _, Some((path, _))) => (path, Product::Pack),
        (Some(dir), _, _) => (dir, Product::TileDir),
        (None, Some(file), _) => (file, Product::Pack),
        (None, None, _) => unreachable!("clap requires --output or --pack"),
    };
    let claim = report::claim(dest, product, &[input], a.force)?;
    // A previous output directory's info.json sets this run's defaults (the original tool's
    // way of configuring a run); the claim above made sure the directory is ours.
    let info_path = (product == Product::TileDir && claim.replaces == Some(Existing::Ours))
        .then(|| dest.join("info.json"))
        .filter(|p| p.is_file());
    let existing = info_path.as_deref().map(InfoFile::read).transpose()?;
    let requested = Requested {
        tile_size: a.tile_size,
        border: a.border,
        background: a.background,
        flatten: a.flatten,
        tile_depth: a.tile_type,
        filename_format: names,
        filter: a.filter,
        max_memory: Some(a.max_memory),
        reencode: a.reencode,
        ..a.enc.requested()
    };
    let existing_ref = info_path.as_deref().zip(existing.as_ref());
    let destination = if product == Product::Pack { Destination::Pack } else { Destination::TileDir };
    let plan = Plan::new(&requested, existing_ref, &source.header(), destination, &limits, kept_icc.as_deref())?;
    let Plan { opts, names, layout, stored, info, changed } = plan;
    // Said once everything is checked, just before the work starts.
    if let (Some(path), false) = (&info_path, a.run.quiet)
        && !changed.is_empty()
    {
        eprintln!("settings from {}: {}", path.shown(), changed.join(", "));
    }
    if let Some((path, chosen)) = shard {
        if !a.run.quiet && !a.run.json {
            eprintln!("shard {} of {} (from {}) into {}", chosen.index, chosen.count, chosen.from, path.shown());
        }
        let job = chosen.job(input, info.to_json_pretty(), a.pack_layout.options()?);
        let run = Run::start_counting(source, a, job.pages(&layout)?, started)?;
        let (done, written) =
            run.execute_with(|source, watch| scale_out::write_shard(source, &path, &opts, &job, watch))?;
        if a.run.json {
            let mut doc: serde_json::Value =
                serde_json::from_str(&report::summary_json(&done, "shard", &path, Some(&written)))?;
            doc["shard"] = serde_json::json!({ "index": chosen.index, "count": chosen.count, "from": chosen.from });
            say!("{doc}");
        } else {
            report(a, "shard", &done, &path, Some(&written));
        }
        return Ok(());
    }
    // The JPEG and PNG tiles of a directory carry the kept profile; a pack's tiles do not (its
    // metadata, info.json, holds it once: docs/colour.md).
    let profile = match a.output {
        Some(_) => kept_icc.as_deref().map(|icc| Profile::for_tiles(icc, opts.codec)).transpose()?.flatten(),
        None => None,
    };
    let mut run = Run::start(source, a, &layout, started)?;
    match (&a.output, &a.pack) {
        (Some(dir), _) => {
            run.profile = profile;
            let sink = DirSink::create(&claim, names)?;
            let summary = run.into_dir(sink, &opts, |sink| sink.finish(&info))?;
            report(a, "vortex", &summary, dir, None);
        }
        (None, Some(file)) => {
            let sink = PackSink::create(
                file,
                &layout,
                stored,
                opts.codec,
                info.to_json_pretty().as_bytes(),
                a.pack_layout.options()?,
            )?;
            // On error the sink is dropped, which deletes the unfinished pack.
            let summary = run.execute(&sink, &opts)?;
            let written = sink.finish()?;
            report(a, "pack", &summary, file, Some(&written));
        }
        (None, None) => unreachable!("clap requires --output or --pack"),
    }
    Ok(())
}

/// A run about to start: the source, the worker threads and the progress bar.
struct Run {
    source: Box<dyn RowSource>,
    watch: report::Watch,
    total: u64,
    started: Instant,
    /// The kept ICC profile (`--keep-icc`), for the JPEG and PNG tiles of a directory.
    profile: Option<Profile>,
}

impl Run {
    fn start(source: Box<dyn RowSource>, a: &OutputArgs, layout: &Layout, started: Instant) -> Result<Run> {
        Run::start_counting(source, a, layout.total_tiles(), started)
    }

    /// A run that writes `total` tiles.
    fn start_counting(source: Box<dyn RowSource>, a: &OutputArgs, total: u64, started: Instant) -> Result<Run> {
        a.run.init_pool()?;
        Ok(Run { source, watch: a.run.watch(total)?, total, started, profile: None })
    }

    /// Runs the pipeline into `sink`; the summary keeps what the source was.
    fn execute(mut self, sink: &dyn TileSink, opts: &SplitOptions) -> Result<Finished> {
        let profile = self.profile.take();
        let tagged = profile.as_ref().map(|profile| WithProfile { inner: sink, profile });
        let sink = tagged.as_ref().map_or(sink, |t| t as &dyn TileSink);
        let (done, ()) = self.execute_with(|source, watch| Ok((split::split(source, sink, opts, watch)?, ())))?;
        Ok(done)
    }

    /// Runs `work` on the source, its encoders on the worker pool, with the progress bar.
    fn execute_with<R>(
        self,
        work: impl FnOnce(Box<dyn RowSource>, &report::Watch) -> vortex_tiler::error::Result<(split::Summary, R)>,
    ) -> Result<(Finished, R)> {
        let (decoder, width, height) = (self.source.describe(), self.source.width(), self.source.height());
        let after_run = self.source.after_run();
        let Run { source, watch, started, .. } = self;
        let result = work(source, &watch);
        watch.bar.finish_and_clear();
        let (summary, extra) = result?;
        let decoder = match after_run {
            Some(note) => format!("{decoder}; {}", note()),
            None => decoder,
        };
        Ok((Finished { summary, decoder, width, height, took: started.elapsed() }, extra))
    }

    /// Runs the pipeline into a directory sink and `finish`es it when every tile is written,
    /// else removes what it wrote.
    fn into_dir(
        self,
        sink: DirSink,
        opts: &SplitOptions,
        finish: impl FnOnce(DirSink) -> vortex_tiler::error::Result<()>,
    ) -> Result<Finished> {
        let total = self.total;
        match self.execute(&sink, opts) {
            Ok(done) if done.summary.tiles == total => {
                finish(sink)?;
                Ok(done)
            }
            Ok(done) => {
                sink.abandon();
                bail!("internal error: wrote {} tiles of {total}", done.summary.tiles);
            }
            Err(e) => {
                sink.abandon();
                Err(e)
            }
        }
    }
}

/// A finished run and what it read.
pub struct Finished {
    pub summary: split::Summary,
    pub decoder: String,
    pub width: u32,
    pub height: u32,
    pub took: std::time::Duration,
}

/// The summary line (and a pack's line), or with --json one JSON object; nothing with --quiet.
fn report(a: &OutputArgs, layout: &str, done: &Finished, dest: &Path, pack: Option<&vortex_pack::WriteSummary>) {
    if a.run.json {
        say!("{}", report::summary_json(done, layout, dest, pack));
    } else if !a.run.quiet {
        if let Some(written) = pack {
            say!("{}", report::pack_line(written));
        }
        say!("{}", report::summary_line(done, dest));
        if a.run.verbose {
            say!("{}", report::stages_line(&done.summary.stages, done.width, done.height));
            say!("{}", report::memory_line(&done.summary.memory));
        }
    }
}

/// `split`/`convert --layout dzi|iiif|xyz|google`: the same pipeline into a directory a viewer
/// opens as it is.
fn tile_for_viewer(
    source: Box<dyn RowSource>,
    input: &Path,
    names: Option<String>,
    a: &OutputArgs,
    viewer: Viewer,
    started: Instant,
    kept_icc: Option<&[u8]>,
) -> Result<()> {
    let (dest, product) = match (&a.output, &a.pmtiles) {
        (_, Some(file)) => (file, Product::Pmtiles),
        (Some(dir), None) => (dir, Product::Viewer(viewer)),
        (None, None) => bail!(
            "--layout {viewer} writes a directory (-o DIR); a pack has one layout, which `vortex-tiler serve PACK` serves as Deep Zoom, IIIF and XYZ"
        ),
    };
    if names.is_some() {
        bail!("--layout {viewer} names its tiles as viewers expect; --filename-format is for --layout vortex");
    }
    if a.shard.is_some() {
        bail!("--shard makes shard packs (--pack); cut the pack in shards, merge it, then serve it as {viewer}");
    }
    if a.border.is_some() {
        bail!(match viewer {
            Viewer::Dzi =>
                "--layout dzi shares texels between tiles with --overlap (Deep Zoom's), not --border".to_string(),
            _ => format!("--layout {viewer} tiles have no border or overlap; --border is for --layout vortex"),
        });
    }
    if a.overlap.is_some() && viewer != Viewer::Dzi {
        bail!("--overlap is Deep Zoom's (--layout dzi); {viewer} tiles do not overlap");
    }
    if a.iiif_id.is_some() && viewer != Viewer::Iiif {
        bail!("--iiif-id names a IIIF image (--layout iiif)");
    }
    let iiif_service = a.iiif_id.as_deref().map(iiif::absolute_id).transpose().map_err(anyhow::Error::msg)?;
    let name = match &a.name {
        Some(name) => name.clone(),
        None => input.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default(),
    };
    if name.is_empty() || name.contains(['/', '\\']) || name == "." || name == ".." {
        bail!("--name '{name}' must be a plain file name (it makes NAME.dzi and NAME_files/)");
    }
    let limits = Limits { memory: a.max_memory, ..Limits::default() };
    let claim = report::claim(dest, product, &[input], a.force)?;

    let tile_size = a.tile_size.unwrap_or(viewer.default_tile_size());
    let overlap = match viewer {
        Viewer::Dzi => a.overlap.unwrap_or(dzi::DEFAULT_OVERLAP),
        _ => 0,
    };
    let layout = viewer.page_grid(source.width(), source.height(), tile_size, overlap)?;
    // Web maps pad their square with a colour (vips: white); the other layouts crop at the image.
    let background = match viewer {
        Viewer::Xyz | Viewer::Google => Some(a.background.unwrap_or(Background::Colour([255; 4]))),
        _ => a.background,
    };
    let requested = Requested {
        tile_size: Some(layout.tile_size),
        border: Some(layout.border),
        background,
        flatten: a.flatten,
        tile_depth: a.tile_type,
        filter: a.filter,
        max_memory: Some(a.max_memory),
        reencode: a.reencode,
        ..a.enc.requested()
    };
    let (mut opts, _) = settings::resolve(&requested, None, source.layout())?;
    opts.down_to_one_texel = viewer.down_to_one_texel();
    if !matches!(opts.codec.extension(), "jpg" | "png") {
        bail!("--layout {viewer} tiles are image files: use --codec jpeg or png, not {}", opts.codec.name());
    }
    if iiif_service.is_some() && opts.codec.extension() != "jpg" {
        bail!(
            "--iiif-id makes a conformant IIIF level-0 service, whose one required format is JPEG (default.jpg): \
             use --codec jpeg, or leave --iiif-id out for {} tiles under a relative id",
            opts.codec.name()
        );
    }
    limits.check_pyramid(&layout, false)?;
    if product == Product::Pmtiles {
        return tile_to_pmtiles(source, a, &claim, &layout, &opts, &name, started);
    }
    let tiles = ViewerTiles {
        viewer,
        layout,
        name,
        extension: viewer.extension(opts.codec.extension()),
        iiif: iiif_service.map(|id| iiif::Service { id, codec: opts.codec }),
    };
    let profile = kept_icc.map(|icc| Profile::for_tiles(icc, opts.codec)).transpose()?.flatten();
    let mut run = Run::start(source, a, &layout, started)?;
    run.profile = profile;
    let sink = DirSink::for_viewer(&claim, tiles)?;
    let done = run.into_dir(sink, &opts, DirSink::finish_viewer)?;
    report(a, viewer.name(), &done, dest, None);
    Ok(())
}

/// `split`/`convert --pmtiles FILE`: the web-map pyramid into one PMTiles archive.
fn tile_to_pmtiles(
    source: Box<dyn RowSource>,
    a: &OutputArgs,
    claim: &vortex_tiler::output::Claim,
    layout: &Layout,
    opts: &SplitOptions,
    name: &str,
    started: Instant,
) -> Result<()> {
    use vortex_tiler::sink::pmtiles::{self, Bounds, TileType};
    let need = layout.total_tiles().saturating_mul(pmtiles::ENTRY_MEMORY_BYTES);
    Limits { memory: a.max_memory, ..Limits::default() }
        .check_memory(&format!("the PMTiles directory of {} tiles", layout.total_tiles()), need)?;
    let (tile_type, format) = match opts.codec.extension() {
        "png" => (TileType::Png, "png"),
        _ => (TileType::Jpeg, "jpg"),
    };
    let run = Run::start(source, a, layout, started)?;
    // On error the sink is dropped, which deletes its temporaries.
    let sink = PmtilesSink::create(&claim.path, layout, tile_type)?;
    let done = run.execute(&sink, opts)?;
    if done.summary.tiles != layout.total_tiles() {
        bail!("internal error: wrote {} tiles of {}", done.summary.tiles, layout.total_tiles());
    }
    let metadata = serde_json::json!({
        "name": name,
        "format": format,
        "type": "baselayer",
        "description": "an image without map coordinates: zoom 0 is the whole image at the top left of the web-mercator square",
        "vortex": { "layout": "xyz", "width": layout.width, "height": layout.height, "tileSize": layout.tile_size },
    });
    let written = sink.finish(&Bounds::of_image(layout), metadata.to_string().as_bytes())?;
    let file = &claim.path;
    if a.run.json {
        let mut doc: serde_json::Value = serde_json::from_str(&report::summary_json(&done, "pmtiles", file, None))?;
        doc["pmtiles"] = serde_json::json!({
            "tiles": written.tiles,
            "entries": written.entries,
            "contents": written.contents,
            "leafDirectories": written.leaves,
            "dataBytes": written.data_bytes,
            "fileBytes": written.file_bytes,
        });
        say!("{doc}");
    } else if !a.run.quiet {
        say!(
            "pmtiles: {} tiles in {} directory entries, {} distinct payloads, {} leaf directories, {} file bytes",
            written.tiles,
            written.entries,
            written.contents,
            written.leaves,
            written.file_bytes
        );
        say!("{}", report::summary_line(&done, file));
    }
    Ok(())
}
