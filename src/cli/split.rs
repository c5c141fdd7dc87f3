//! `split`: flags to options, the pipeline with a progress bar, one summary line.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result, bail};

use vortex_tiler::background::Background;
use vortex_tiler::codec::{Bc7Effort, PngLevel, Subsampling};
use vortex_tiler::error::ShowPath;
use vortex_tiler::formats::dicom::DicomMeta;
use vortex_tiler::formats::tiff::{BigTiff, Flavour};
use vortex_tiler::formats::viewer::Viewer;
use vortex_tiler::layout::Levels;
use vortex_tiler::outputs::{Budget, DicomSettings, Figures, Format, Output, Plan, Settings, TiffSettings, Wrote};
use vortex_tiler::pixel::Depth;
use vortex_tiler::pyramid::Filter;
use vortex_tiler::settings::{CodecChoice, Requested};
use vortex_tiler::source::RowSource;
use vortex_tiler::{scale_out, source, split};

use super::report;
use super::shard::shard_path;

mod ome_zarr;

#[derive(clap::Args, Debug)]
pub struct SplitArgs {
    /// Image to cut: PNG, TIFF/BigTIFF, JPEG, PPM/PGM stream in bands; WebP, GIF, BMP, TGA and
    /// QOI are decoded whole within --max-memory.
    #[arg(help_heading = "Input", value_name = "INPUT", required_unless_present_any = ["input_flag", "channel"])]
    input: Option<PathBuf>,

    /// The input, spelled as the original tool did (--input=in.png).
    #[arg(help_heading = "Input", long = "input", value_name = "INPUT", conflicts_with = "input")]
    input_flag: Option<PathBuf>,

    /// Tile file names, printf-like with positional arguments 1 = LOD, 2 = x, 3 = y; '/' makes
    /// subdirectories [default: lod%1$02s-x%2$04s-y%3$04s.<ext>].
    #[arg(help_heading = "Outputs", long, visible_alias = "ff", value_name = "PATTERN")]
    filename_format: Option<String>,

    /// Keep the stored row order: by default an EXIF orientation (JPEG, TIFF, PNG eXIf) is
    /// applied, so the tiles show the image as viewers and `vips autorot` do (orientations
    /// other than a left-right mirror hold the image, or read it in passes, within
    /// --max-memory).
    #[arg(help_heading = "Input", long)]
    no_autorotate: bool,

    /// Keep the texels in the colours of the input's ICC profile, and the profile in every
    /// JPEG and PNG tile file (APP2, iCCP) and in info.json (base64, `iccProfile`; a pack's
    /// tiles rely on it), instead of converting them to sRGB [default: convert: browsers show
    /// untagged tiles as sRGB, and the linear-light LOD filters assume sRGB].
    #[arg(help_heading = "Colour", long)]
    keep_icc: bool,

    /// Map 32-bit integer or float samples linearly onto 8 bits (16 with --tile-type
    /// unsignedShort): MIN to 0, MAX to the top code, e.g. 0:4095 or -0.5:1.5 [default: none;
    /// without it such sources go only to raw/zstd packs and OME-Zarr, since JPEG and PNG would
    /// cut their range]. Every channel is mapped, alpha included; samples outside (and NaN) are
    /// clamped and counted in the summary, never cut silently.
    #[arg(help_heading = "Colour", long, value_name = "MIN:MAX", allow_hyphen_values = true)]
    range: Option<source::range::Range>,

    /// A TIFF holding several images: cut its Nth directory, counted from 0 as tiffinfo and
    /// libvips count them (a reduced level or a slide's label included) [default: the first
    /// full-resolution image; the summary says which page was read and what was skipped].
    #[arg(help_heading = "Input", long, value_name = "N", conflicts_with = "series")]
    page: Option<u32>,

    /// Cut the Nth series: an OME-TIFF's Nth OME-XML Image, or the Nth full-resolution image
    /// of another multi-page TIFF (reduced levels and label/macro/thumbnail images skipped)
    /// [default: 0].
    #[arg(help_heading = "Input", long, value_name = "N")]
    series: Option<u32>,

    /// One channel's image, a grey image of the others' size and sample type; repeated, in
    /// channel order, in place of INPUT: with --layout ome-zarr, one array of that many
    /// channels (docs/ome-zarr.md); into -o FILE.ome.tif, a grey plane each (docs/tiff.md).
    #[arg(help_heading = "Input", long, value_name = "FILE")]
    channel: Vec<PathBuf>,

    /// Channels to cut, counted from 0, e.g. 0,1,2: any number of them into --layout ome-zarr
    /// (a `c` axis) or an OME-TIFF (-o FILE.ome.tif: a grey plane each), one (grey) or three
    /// (RGB) into the other layouts [default: every channel; an image of more than four (a
    /// TIFF of more samples or separate planes, an OME-TIFF's planes, --channel files) needs
    /// --layout ome-zarr, an OME-TIFF or a pick].
    #[arg(help_heading = "Input", long, value_name = "LIST", value_delimiter = ',')]
    channels: Option<Vec<usize>>,

    #[command(flatten)]
    pub out: OutputArgs,
}

/// What `split` and `convert` write, and how.
#[derive(clap::Args, Debug)]
pub struct OutputArgs {
    /// An output: a directory in the --layout that follows it (or, given before any -o, the
    /// first one's) [default: vortex], or a file or directory whose name says its format:
    /// FILE.vtpk a pack, FILE.pmtiles PMTiles, DIR.ome.zarr or FILE.ozx OME-Zarr. Repeat it
    /// (with --pack and --pmtiles) to write several outputs from one read of the input, e.g.
    /// `-o web --layout dzi -o slide.ome.zarr --pack slide.vtpk`: the outputs that share a
    /// pyramid and codec share each tile's encoding (docs/outputs.md). A directory is created,
    /// and replaced only if it holds nothing but a previous output of ours.
    ///
    /// s3://BUCKET/PREFIX writes a directory layout (vortex, dzi, iiif, xyz, google) to
    /// S3-compatible storage, one object a file, uploaded as the tiles are made; s3://BUCKET/KEY
    /// with a file's name (.vtpk, .pmtiles, .ozx, .tif) writes that file as one object (a pack
    /// streamed as it is made, the others staged under TMPDIR, then sent as one multipart
    /// upload); s3://BUCKET/PREFIX.ome.zarr is staged under
    /// TMPDIR too, then uploaded file by file. Credentials, region and endpoint come from the
    /// AWS environment: AWS_ACCESS_KEY_ID, AWS_SECRET_ACCESS_KEY, AWS_REGION, AWS_ENDPOINT_URL
    /// (MinIO, R2, a local server; with AWS_ALLOW_HTTP=true for plain http). A failed run
    /// deletes what it uploaded; a prefix holding anything but a previous output of ours is
    /// refused (docs/object-storage.md).
    #[arg(help_heading = "Outputs", short, long, value_name = "PATH")]
    output: Vec<PathBuf>,

    /// Write one pack file (docs/pack-format.md). An existing pack is replaced; any other file
    /// only with --force. An s3://BUCKET/KEY.vtpk URL writes it as one object (see -o).
    #[arg(help_heading = "Outputs", long, value_name = "FILE")]
    pack: Option<PathBuf>,

    /// Write one PMTiles v3 archive of the web-map (XYZ) pyramid instead of a directory:
    /// one file any static web host serves to Leaflet, MapLibre or OpenLayers with the
    /// `pmtiles` JavaScript package (docs/web.md). JPEG, PNG or JPEG XL (tile type 0, which
    /// browsers that decode JPEG XL show) tiles of --tile-size (default 256), zoom 0 the whole image; bounds name the image's place on the web-mercator square,
    /// as the image has no map coordinates. An existing PMTiles archive is replaced; any other
    /// file only with --force.
    #[arg(help_heading = "Outputs", long, value_name = "FILE")]
    pmtiles: Option<PathBuf>,

    /// Make the run resumable, and resume an interrupted one: the run journals each tile it
    /// finishes (a line with its place and a CRC-32C) in `.NAME.resume-PID` beside the output;
    /// after a kill (SIGKILL, a Slurm time limit, Ctrl-C) the same command with --resume
    /// checks the staged tiles against that journal, keeps those that are whole, and encodes
    /// only the others, for an output byte for byte that of an uninterrupted run. With
    /// nothing to resume it starts afresh (journaled), so a job script can always pass it. A
    /// journal of another input or other options is refused, naming what differs. One output:
    /// a pack, a tile directory or a viewer layout. At an s3:// prefix the bucket is the record
    /// (its marker names the run, the tiles listed there are kept), so any machine can resume
    /// it; a pack at s3:// is staged and journaled under TMPDIR, resumed on that machine
    /// (docs/resume.md).
    #[arg(help_heading = "Outputs", long)]
    resume: bool,

    /// Replace a regular file at --pack, --pmtiles or a TIFF output that is not one of ours.
    /// Never replaces a directory, a device, a FIFO, a link or the input.
    #[arg(help_heading = "Outputs", long)]
    force: bool,

    /// TIFF outputs: always BigTIFF [default: BigTIFF only where the file could pass 4 GiB,
    /// decided before writing].
    #[arg(help_heading = "Outputs", long)]
    bigtiff: bool,

    #[command(flatten, next_help_heading = "Outputs")]
    pack_layout: super::PackLayout,

    /// --layout dicom: the root the series' UIDs are made under, e.g. your organisation's
    /// registered root [default: 2.25, UUIDs: no registration needed]. The UIDs are a hash of
    /// the input and the options, the same on every run (docs/dicom.md).
    #[arg(help_heading = "Outputs", long, value_name = "ROOT")]
    dicom_uid_root: Option<String>,

    /// --layout dicom: a JSON object of the patient, study and equipment attributes, by DICOM
    /// keyword, e.g. {"PatientID": "P1", "AccessionNumber": "A7"} [default: none: the
    /// patient and study attributes are empty]. docs/dicom.md lists the keywords taken.
    #[arg(help_heading = "Outputs", long, value_name = "FILE")]
    dicom_meta: Option<PathBuf>,

    /// A TIFF or DICOM output: which levels it holds: stored (the slide's own levels, every
    /// JPEG tile copied as it is, nothing decoded, where the source is a pyramid of JPEG tiles
    /// the output can hold; else our pyramid, the summary saying why) or pow2 (our exact
    /// power-of-two pyramid, full-resolution tiles still copied where they fit)
    /// [default: stored]. See docs/tiff.md and docs/dicom.md.
    #[arg(help_heading = "Outputs", long, value_name = "LEVELS")]
    levels: Option<LevelsArg>,

    /// A generic TIFF (-o FILE.tif), an OME-TIFF (-o FILE.ome.tif) or --layout dicom: leave
    /// the slide's associated images (label, macro, thumbnail) out [default: each carried, an
    /// IFD, an OME image or an instance of its own]. A label often shows the patient's name or
    /// number.
    #[arg(help_heading = "Outputs", long)]
    no_associated: bool,

    /// How the output directory is laid out: vortex (tiles + info.json, this tool's), or one a
    /// viewer opens as it is: dzi (NAME.dzi + NAME_files/, Deep Zoom as vips dzsave writes
    /// it: OpenSeadragon), iiif (IIIF Image API 3.0 level 0: info.json + static tiles), xyz
    /// ({z}/{x}/{y}, Leaflet/OpenLayers/MapLibre) or google ({z}/{y}/{x} as vips writes it).
    /// See docs/viewers.md. ome-zarr: an OME-Zarr image for microscopy tools (napari, Fiji,
    /// QuPath), -o DIR.ome.zarr or -o FILE.ozx (docs/ome-zarr.md). tiff, ome-tiff and cog: one
    /// pyramidal TIFF file, as -o FILE.tif, -o FILE.ome.tif and -o FILE.cog.tif say
    /// (docs/tiff.md). dicom: a DICOM whole-slide image series, one instance a level, for
    /// PACS, DICOM viewers and OpenSlide 4 (-o DIR, with --pixel-size; docs/dicom.md). Each
    /// --layout belongs to the -o before it [default: vortex, or what the output's name says].
    #[arg(help_heading = "Outputs", long, value_enum, value_name = "LAYOUT")]
    layout: Vec<OutputLayout>,

    /// --layout dzi: the pyramid's name, NAME.dzi and NAME_files/ [default: the input's file
    /// stem].
    #[arg(help_heading = "Outputs", long, value_name = "NAME")]
    name: Option<String>,

    /// --layout dzi: texels each tile shares with each neighbour (Deep Zoom's Overlap; not
    /// --border: an edge tile has no overlap where it has no neighbour) [default: 1].
    #[arg(help_heading = "Tiles", long, value_name = "N")]
    overlap: Option<u32>,

    /// --layout iiif: the absolute http(s) URL the directory will be served at, e.g.
    /// https://example.org/iiif/slide. It becomes info.json's id and makes the directory a
    /// conformant IIIF level-0 service there: full/max (at most 2048 texels on a side, as
    /// maxWidth/maxHeight say) and the whole-image sizes are written too [default: '.',
    /// relative to the viewer's page, only the files libvips writes; serve rewrites it].
    #[arg(help_heading = "Outputs", long, value_name = "URL")]
    iiif_id: Option<String>,

    #[command(flatten, next_help_heading = "Outputs")]
    ome_zarr: ome_zarr::OmeZarrArgs,

    /// Side of a stored tile in texels, borders included [default: 128]. LOD 0 has
    /// ceil(width / payload) x ceil(height / payload) pages (payload = tile size - 2 x border),
    /// each LOD half as many per axis (rounding up), down to the first LOD of one page. In a
    /// viewer layout, the viewer's tile side (Deep Zoom: without overlap) [default: dzi 254,
    /// iiif 512, xyz and google 256]. In --layout ome-zarr, the chunk side [default: 256].
    #[arg(help_heading = "Tiles", short = 't', long, value_name = "N")]
    tile_size: Option<u32>,

    /// Texels copied from neighbouring pages into each tile edge, for filtering on the GPU: 1 is
    /// enough for bilinear and trilinear filtering without seams, with or without anisotropic
    /// filtering (vortex's probes each look up their own page; id Tech 5 used a border of 4 for
    /// its anisotropic filtering); 0 for the nearest filter and for viewers that never filter across
    /// tiles (docs/gpu-sampling.md) [default: 1; 0 where an existing info.json has no border, as
    /// the thesis's files].
    #[arg(help_heading = "Tiles", long, value_name = "N")]
    border: Option<u32>,

    #[command(flatten, next_help_heading = "Tiles")]
    enc: CodecArgs,

    /// Decode and encode every tile, even those the source stores as JPEG tiles on the grid of
    /// the finest level's pages [default: copy those: a JPEG-tiled TIFF or slide (or, for
    /// convert, JPEG tiles without overlap) cut at its tile size with no border or overlap
    /// (--layout dzi --overlap 0, iiif, xyz, or --border 0) keeps the stored tiles byte for
    /// byte, with no generation loss and no encoding time (edge tiles that dzi and iiif crop
    /// are cropped losslessly from them); the summary says how many were copied, how many of
    /// them cropped, and at what quality they were stored. An explicit --quality or --subsampling
    /// re-encodes them too; docs/sources.md].
    #[arg(help_heading = "Tiles", long)]
    reencode: bool,

    /// Fill for the padding in the last page of each row and column, between the image's edge
    /// and the page's: edge (repeat the image's edge), #rrggbb, #rrggbbaa, r,g,b[,a] or a grey
    /// level [default: edge].
    #[arg(help_heading = "Tiles", long, value_name = "COLOUR")]
    background: Option<Background>,

    /// Composite alpha over --background (black if edge) so that RGBA sources can be stored as JPEG.
    #[arg(help_heading = "Colour", long)]
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
    #[arg(help_heading = "Pyramid and filter", long, value_parser = super::named::<Filter>())]
    filter: Option<Filter>,

    /// Make LOD 1 from the source's stored JPEG tiles decoded at half size (libjpeg's scaled
    /// inverse DCT, as libvips shrinks a JPEG on load) instead of from the exact means of their
    /// decoded texels; the levels above it follow from LOD 1 with --filter. Faster, not exact:
    /// docs/accuracy.md measures both. Every output must copy the stored tiles into LOD 0 (a
    /// JPEG-tiled TIFF, slide or DICOM JPEG series cut at its tile size with no border or
    /// overlap), which stays the stored tiles, untouched; a page of one colour is then copied
    /// rather than stored as its colour.
    #[arg(help_heading = "Pyramid and filter", long)]
    fast_shrink: bool,

    /// Sample type of stored tiles: unsignedByte or unsignedShort (png, raw, zstd, zstd-delta),
    /// or for a float source half (raw, zstd: 16-bit floats, what a GPU uploads as R16F, half
    /// the bytes; rounded to nearest even, beyond 65504 infinite) [default: the source's;
    /// 32-bit integer and float sources keep unsignedInt and float].
    #[arg(help_heading = "Tiles", long, value_name = "TYPE", value_parser = super::parse_tile_type)]
    tile_type: Option<Depth>,

    /// Most memory a run may hold at once, checked before allocating: an image decoded whole
    /// when its format cannot be streamed (interlaced PNG, progressive JPEG, one-strip TIFF,
    /// WebP, ...), a pack's index, and the run's stages together (the source decoder's
    /// buffers, the read-ahead, the bands, the tiles and encodings in flight: --json's
    /// memory.plannedBytes, their most at once); e.g. 512M, 4G. An image too wide for that is
    /// cut in vertical stripes, reading the source once per stripe, for the same tiles; a
    /// budget too small even for those is refused before the run, saying what it needs.
    #[arg(help_heading = "Memory and speed", long, value_name = "SIZE", default_value = "1G", value_parser = super::parse_size)]
    max_memory: u64,

    /// Make one shard of a split across machines, into a shard pack (--pack): I/N is shard I
    /// of N, counting from 0; auto reads the index from a Slurm job array
    /// (SLURM_ARRAY_TASK_ID, SLURM_ARRAY_TASK_COUNT) or a Kubernetes Indexed Job
    /// (JOB_COMPLETION_INDEX, with --shards). '{shard}' in --pack becomes the index; --pack
    /// may be an s3://BUCKET/KEY.vtpk URL (streamed as it is made), so that the machines
    /// share no file system for the shards. `vortex-tiler merge` joins the N shard
    /// packs into the pack --pack alone makes, byte for byte. See docs/scale-out.md.
    #[arg(help_heading = "Scale-out", long, value_name = "I/N|auto")]
    shard: Option<super::shard::ShardArg>,

    /// With --shard auto: how many shards there are (a Kubernetes Job's completions; a Slurm
    /// array says so itself).
    #[arg(help_heading = "Scale-out", long, value_name = "N", requires = "shard")]
    shards: Option<u32>,

    #[command(flatten, next_help_heading = "Memory and speed")]
    run: super::RunFlags,

    /// Where each -o and --layout stood among the arguments, in order (`place_flags`).
    #[arg(skip)]
    placed: Vec<Placed>,
}

/// An `-o` or a `--layout`, in the order given.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Placed {
    Output(usize),
    Layout(usize),
}

/// `--levels`' values.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
enum LevelsArg {
    Stored,
    Pow2,
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
    /// One tiled TIFF file, every level an IFD of its own, as vips tiffsave --tile --pyramid.
    Tiff,
    /// One OME-TIFF file: the reduced levels as SubIFDs, OME-XML in the first IFD.
    OmeTiff,
    /// One Cloud Optimized GeoTIFF (GDAL's layout: IFDs first, tile data coarse to fine).
    Cog,
    /// A DICOM whole-slide image series: one VL Whole Slide Microscopy instance a level.
    Dicom,
}

impl OutputLayout {
    fn format(self) -> Format {
        match self {
            OutputLayout::Vortex => Format::Tiles,
            OutputLayout::OmeZarr => Format::OmeZarr,
            OutputLayout::Dzi => Format::Viewer(Viewer::Dzi),
            OutputLayout::Iiif => Format::Viewer(Viewer::Iiif),
            OutputLayout::Xyz => Format::Viewer(Viewer::Xyz),
            OutputLayout::Google => Format::Viewer(Viewer::Google),
            OutputLayout::Tiff => Format::Tiff(Flavour::Generic),
            OutputLayout::OmeTiff => Format::Tiff(Flavour::Ome),
            OutputLayout::Cog => Format::Tiff(Flavour::Cog),
            OutputLayout::Dicom => Format::Dicom,
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

    /// JPEG quality, 1-100 [default: 85]. With --codec jxl, the JPEG XL quality, mapped to a
    /// Butteraugli distance as cjxl maps it: 0.1 + (100 - Q) x 0.09 from 30 up (90 = 1.0,
    /// visually lossless; 85 = 1.45), a parabola below [default: 90; docs/jxl.md].
    #[arg(long, value_name = "Q")]
    pub quality: Option<u8>,

    /// --codec jxl: keep every sample exactly (JPEG XL's modular mode; any layout, 8 or 16 bits),
    /// typically a third smaller than --codec png. Not with --quality.
    #[arg(long)]
    pub lossless: bool,

    /// --codec jxl: encoder effort, 1 (fastest) to 9 (smallest, slowest); never changes what is
    /// kept. Measured on 256-texel tiles: lossy 5 is 4% smaller than 3 for 3x the time, lossless
    /// 5 2% smaller than 3 for 5x (docs/jxl.md) [default: 5 lossy and for copied JPEG tiles'
    /// recompression, 3 lossless].
    #[arg(long, value_name = "N")]
    pub jxl_effort: Option<u8>,

    /// How JPEG tiles code colour [default: 420; a TIFF or DICOM output of a JPEG-tiled source:
    /// the source tiles' coding, so that they are copied].
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
            lossless: self.lossless,
            jxl_effort: self.jxl_effort,
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
            || r.lossless
            || r.jxl_effort.is_some()
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
        if a.out.resume {
            bail!(
                "--resume resumes a run into a pack, a tile directory or a viewer layout; not one of several channels"
            );
        }
        return ome_zarr::tile_channels(set, a.channels.as_deref(), &inputs, a.filename_format, &a.out, started);
    }
    let input = input.context("an input image is required")?;
    let options = source::OpenOptions {
        budget: Budget::new(a.out.max_memory),
        autorotate: !a.no_autorotate,
        keep_icc: a.keep_icc,
        pick,
    };
    let source::Opened { mut source, icc, geo, pitch, lossy, channel } = source::open_with(&input, options)?;
    if let Some(range) = a.range {
        source = source::range::map(source, range, a.out.tile_type.unwrap_or(Depth::U8))?;
    }
    tile(source, &input, a.filename_format, &a.out, started, Carried { icc, geo, pitch, lossy, channel })
}

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

    /// Notes where each -o and --layout stood in `matches` (the subcommand's), so that each
    /// --layout goes with the -o before it.
    pub fn place_flags(&mut self, matches: Option<&clap::ArgMatches>) {
        let at = |id: &str| -> Vec<usize> {
            let given = matches.filter(|m| m.value_source(id) == Some(clap::parser::ValueSource::CommandLine));
            given.and_then(|m| m.indices_of(id)).map(|i| i.collect()).unwrap_or_default()
        };
        let mut placed: Vec<(usize, Placed)> =
            at("output").into_iter().enumerate().map(|(k, i)| (i, Placed::Output(k))).collect();
        placed.extend(at("layout").into_iter().enumerate().map(|(k, i)| (i, Placed::Layout(k))));
        placed.sort_by_key(|&(i, _)| i);
        self.placed = placed.into_iter().map(|(_, p)| p).collect();
    }

    /// The outputs the flags name, each -o with the --layout after it (one given before any
    /// -o belongs to the first), or the format its name says; then --pack and --pmtiles.
    fn outputs(&self) -> Result<Vec<Output>> {
        let placed = match self.placed.is_empty() {
            // Flags not placed (a caller that did not parse a command line): in order.
            true => {
                (0..self.output.len()).map(Placed::Output).chain((0..self.layout.len()).map(Placed::Layout)).collect()
            }
            false => self.placed.clone(),
        };
        let mut layouts: Vec<Option<OutputLayout>> = vec![None; self.output.len()];
        let mut last = None;
        for p in placed {
            match p {
                Placed::Output(k) => last = Some(k),
                Placed::Layout(l) => {
                    let layout = self.layout[l];
                    let Some(k) = last.or((!self.output.is_empty()).then_some(0)) else {
                        self.refuse_layout_without_directory(layout)?;
                        continue;
                    };
                    if let Some(before) = layouts[k].replace(layout) {
                        bail!(
                            "-o {} has two layouts, {} and {}: give each -o its own --layout after it",
                            self.output[k].shown(),
                            name_of(before),
                            name_of(layout)
                        );
                    }
                }
            }
        }
        let mut outputs: Vec<Output> = (self.output.iter().zip(layouts))
            .map(|(path, layout)| {
                let format = match layout {
                    Some(layout) => layout.format(),
                    None => Format::of_path(path).unwrap_or(Format::Tiles),
                };
                Output::new(format, path)
            })
            .collect();
        outputs.extend(self.pack.iter().map(|p| Output::new(Format::Pack, p)));
        outputs.extend(self.pmtiles.iter().map(|p| Output::new(Format::Pmtiles, p)));
        if outputs.is_empty() {
            bail!(
                "no output: give -o DIR (with --layout), -o FILE.vtpk, FILE.pmtiles, DIR.ome.zarr, FILE.ozx, FILE.tif or FILE.ome.tif, --pack FILE or --pmtiles FILE"
            );
        }
        Ok(outputs)
    }

    /// A --layout with no -o to belong to: vortex and (with --pmtiles) xyz say what --pack and
    /// --pmtiles write anyway; the others write a directory.
    fn refuse_layout_without_directory(&self, layout: OutputLayout) -> Result<()> {
        match (layout, self.pmtiles.is_some()) {
            (OutputLayout::Vortex, _) | (OutputLayout::Xyz, true) => Ok(()),
            (OutputLayout::Tiff | OutputLayout::OmeTiff | OutputLayout::Cog, _) => {
                bail!("--layout {} writes one file (-o FILE.tif), not a pack", name_of(layout))
            }
            (OutputLayout::Dicom, _) => bail!("--layout dicom writes a directory of instances (-o DIR), not a pack"),
            (OutputLayout::OmeZarr, _) => {
                bail!(
                    "--layout ome-zarr writes a directory or a .ozx file (-o DIR.ome.zarr or -o FILE.ozx), not a pack"
                )
            }
            (other, true) => {
                bail!(
                    "--pmtiles holds the web-map (xyz) pyramid; --layout {} writes a directory (-o DIR)",
                    name_of(other)
                )
            }
            (other, false) => bail!(
                "--layout {} writes a directory (-o DIR); a pack has one layout, which `vortex-tiler serve PACK` serves as Deep Zoom, IIIF and XYZ",
                name_of(other)
            ),
        }
    }

    /// `--dicom-uid-root` and `--dicom-meta` (the file read and checked).
    fn dicom(&self) -> Result<DicomSettings> {
        let meta = match &self.dicom_meta {
            None => None,
            Some(path) => {
                let text = std::fs::read_to_string(path).with_context(|| format!("--dicom-meta {}", path.shown()))?;
                let meta = DicomMeta::from_json(&text).with_context(|| path.shown().to_string())?;
                Some(meta)
            }
        };
        Ok(DicomSettings { uid_root: self.dicom_uid_root.clone(), meta })
    }

    /// The settings the outputs share, from the flags; `names`: the filename format flag;
    /// `stored`: how the source's stored JPEG tiles code colour.
    fn settings(&self, names: Option<String>, carried: Carried, stored: Option<Subsampling>) -> Result<Settings> {
        let o = &self.ome_zarr;
        Ok(Settings {
            tiles: Requested {
                tile_size: self.tile_size,
                border: self.border,
                background: self.background,
                flatten: self.flatten,
                tile_depth: self.tile_type,
                filename_format: names,
                filter: self.filter,
                reencode: self.reencode,
                fast_shrink: self.fast_shrink,
                ..self.enc.requested()
            },
            overlap: self.overlap,
            name: self.name.clone(),
            iiif_id: self.iiif_id.clone(),
            ome_zarr: ome_zarr::settings(o),
            tiff: TiffSettings { bigtiff: if self.bigtiff { BigTiff::Always } else { BigTiff::Auto } },
            dicom: self.dicom()?,
            no_associated: self.no_associated,
            levels: self.levels.map(|l| match l {
                LevelsArg::Stored => Levels::Stored,
                LevelsArg::Pow2 => Levels::Pow2,
            }),
            pack: self.pack_layout.options()?,
            keep_icc: carried.icc,
            geo: carried.geo,
            pitch: carried.pitch,
            lossy: carried.lossy,
            channel: carried.channel,
            stored_subsampling: stored,
            force: self.force,
        })
    }
}

/// A layout's name as --layout takes it.
fn name_of(layout: OutputLayout) -> String {
    clap::ValueEnum::to_possible_value(&layout).map(|v| v.get_name().to_string()).unwrap_or_default()
}

/// What the source's file says that the outputs may carry: its ICC profile where the run keeps
/// it (`--keep-icc`), a GeoTIFF's georeferencing, its pixel size, its lossy compressions, the
/// name of its one channel.
#[derive(Default)]
pub struct Carried {
    pub icc: Option<Vec<u8>>,
    pub geo: Option<vortex_tiler::source::GeoTags>,
    pub pitch: Option<vortex_tiler::source::PixelPitch>,
    pub lossy: Vec<vortex_tiler::source::LossyStep>,
    pub channel: Option<vortex_tiler::source::ChannelLabel>,
}

/// Runs the pipeline from `source` into the outputs `a` names, with the progress bar and the
/// summary. `names` is the output filename format flag; `carried` what the source's file says.
pub fn tile(
    source: Box<dyn RowSource>,
    input: &Path,
    names: Option<String>,
    a: &OutputArgs,
    started: Instant,
    carried: Carried,
) -> Result<()> {
    let outputs = a.outputs()?;
    let settings = a.settings(names, carried, source.stored_tiles().and_then(|t| t.subsampling()))?;
    let budget = Budget::new(a.max_memory);
    if a.shard.is_some() || a.pack.as_ref().is_some_and(|p| p.to_string_lossy().contains("{shard}")) {
        if a.resume {
            bail!("--resume resumes a whole run; a shard is made again whole: run its index again (docs/scale-out.md)");
        }
        return shard(source, input, outputs, &settings, a, started);
    }
    let mut plan = Plan::new(outputs, &settings, &source.header(), &[input], budget)?;
    // Taken over before the clean-up of dead runs' temporaries, which would remove them.
    let resumed = match a.resume {
        true => Some(plan.resumable(input)?),
        false => None,
    };
    for planned in plan.outputs() {
        // An s3:// output leaves nothing beside it on local disk to clean up.
        if vortex_tiler::store::ObjectUrl::of_path(&planned.output.path).is_none() {
            if resumed.is_some() {
                report::prepare_resumable(&planned.output.path)?;
            } else {
                report::prepare(&planned.output.path)?;
            }
        }
    }
    if let Some(r) = resumed.as_ref().filter(|_| !a.run.quiet) {
        match &r.from {
            Some(from) if vortex_tiler::store::ObjectUrl::of_path(from).is_some() => eprintln!(
                "resuming the interrupted run that {} names: {} objects under its prefix, each tile kept whose objects are all there",
                from.shown(),
                r.recorded
            ),
            Some(from) => eprintln!(
                "resuming the interrupted run of {}: {} tiles recorded, checked against its staged output",
                from.shown(),
                r.recorded
            ),
            None => eprintln!("nothing to resume: starting afresh, journaled in {}", r.journal.shown()),
        }
    }
    // Said once everything is checked, just before the work starts.
    for (path, changed) in plan.outputs().iter().filter_map(|p| p.changed.as_ref()) {
        if !a.run.quiet {
            eprintln!("settings from {}: {}", path.shown(), changed.join(", "));
        }
    }
    let run = Run::start_counting(source, a, plan.total_tiles(), started)?;
    let result = run.execute_with(|source, watch| {
        let wrote = plan.write(source, watch)?;
        let summary = wrote.first().map(|w| w.summary.clone());
        Ok((summary.ok_or_else(|| vortex_tiler::error::TilerError::Options("a run with no output".into()))?, wrote))
    });
    if let (Err(_), Some(r)) = (&result, &resumed) {
        if vortex_tiler::store::ObjectUrl::of_path(&r.journal).is_some() {
            eprintln!(
                "note: the tiles uploaded so far stay under the prefix, whose {} names this run: run the same command with --resume to go on from them",
                r.journal.shown()
            );
        } else {
            eprintln!(
                "note: the tiles finished so far stay beside the output, journaled in {}: run the same command with --resume to go on from them",
                r.journal.shown()
            );
        }
    }
    let (done, wrote) = result.map_err(|e| match (e.downcast_ref::<vortex_tiler::error::TilerError>(), &resumed) {
        (Some(vortex_tiler::error::TilerError::Interrupted), Some(_)) => super::InterruptedForResume.into(),
        _ => e,
    })?;
    match wrote.as_slice() {
        [one] => report_one(a, &done, one),
        all => report_all(a, &done, all),
    }
    Ok(())
}

/// `--shard`: one shard of the pack that --pack names (docs/scale-out.md).
fn shard(
    source: Box<dyn RowSource>,
    input: &Path,
    outputs: Vec<Output>,
    settings: &Settings,
    a: &OutputArgs,
    started: Instant,
) -> Result<()> {
    let viewer = outputs.iter().find_map(|o| match o.format {
        Format::Viewer(v) => Some(v.name()),
        Format::Pmtiles => Some("xyz"),
        _ => None,
    });
    let pack = match (&a.shard, &a.pack) {
        (None, pack) => {
            let pack = pack.as_deref().unwrap_or(Path::new(""));
            bail!("'{{shard}}' in --pack {} stands for a shard's index: add --shard I/N or --shard auto", pack.shown())
        }
        (Some(_), _) if let Some(viewer) = viewer => {
            bail!("--shard makes shard packs (--pack); cut the pack in shards, merge it, then serve it as {viewer}")
        }
        (Some(_), _) if outputs.iter().any(|o| o.format == Format::OmeZarr) => {
            bail!("--shard makes shard packs (--pack); --layout ome-zarr is written by one run")
        }
        (Some(_), None) => bail!("--shard writes a shard pack: give --pack FILE (merge joins them into one pack)"),
        (Some(_), Some(_)) if outputs.len() > 1 => {
            bail!("--shard makes one shard pack (--pack FILE) and no other output")
        }
        (Some(_), Some(pack)) => pack.clone(),
    };
    let chosen = a.shard.as_ref().map(|s| s.choose(a.shards, |name| std::env::var(name).ok())).transpose()?;
    let Some(chosen) = chosen else { bail!("--shard is required here") };
    let path = shard_path(&pack, &chosen);
    let in_bucket = vortex_tiler::store::ObjectUrl::of_path(&path).is_some();
    // Every task of an array writes into the same directory: the first makes it.
    if let Some(dir) = path.parent().filter(|d| !in_bucket && !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {} for the shard packs", dir.shown()))?;
    }
    let output = Output::new(Format::Pack, &path);
    let plan = Plan::new(vec![output], settings, &source.header(), &[input], Budget::new(a.max_memory))?;
    // At s3:// (claimed by the plan) the shard pack is streamed as it is made.
    if !in_bucket {
        report::prepare(&path)?;
    }
    let planned = &plan.outputs()[0];
    let info = planned.info().map(|i| i.to_json_pretty()).unwrap_or_default();
    if !a.run.quiet && !a.run.json {
        eprintln!("shard {} of {} (from {}) into {}", chosen.index, chosen.count, chosen.from, path.shown());
    }
    let job = chosen.job(input, info, a.pack_layout.options()?);
    let run = Run::start_counting(source, a, job.pages(&planned.layout)?, started)?;
    let opts = &planned.opts;
    let (done, written) = run.execute_with(|source, watch| scale_out::write_shard(source, &path, opts, &job, watch))?;
    let uploaded = in_bucket.then_some(written.file_bytes);
    if a.run.json {
        let figures = Figures::Pack(written);
        let mut doc: serde_json::Value = serde_json::from_str(&report::summary_json(&done, "shard", &path, &figures))?;
        doc["shard"] = serde_json::json!({ "index": chosen.index, "count": chosen.count, "from": chosen.from });
        if let Some(sent) = uploaded {
            doc["uploadedBytes"] = sent.into();
        }
        say!("{doc}");
    } else {
        report(a, "shard", &done, &path, &Figures::Pack(written), uploaded);
    }
    Ok(())
}

/// A run about to start: the source, the worker threads and the progress bar.
struct Run {
    source: Box<dyn RowSource>,
    watch: report::Watch,
    started: Instant,
}

impl Run {
    /// A run that writes `total` tiles.
    fn start_counting(source: Box<dyn RowSource>, a: &OutputArgs, total: u64, started: Instant) -> Result<Run> {
        a.run.init_pool()?;
        Ok(Run { source, watch: a.run.watch(total)?, started })
    }

    /// Runs `work` on the source, its encoders on the worker pool, with the progress bar.
    fn execute_with<R>(
        self,
        work: impl FnOnce(Box<dyn RowSource>, &report::Watch) -> vortex_tiler::error::Result<(split::Summary, R)>,
    ) -> Result<(Finished, R)> {
        let (decoder, width, height) = (self.source.describe(), self.source.width(), self.source.height());
        let after_run = self.source.after_run();
        let Run { source, watch, started } = self;
        let result = work(source, &watch);
        watch.bar.finish_and_clear();
        let (summary, extra) = result?;
        let decoder = match after_run {
            Some(note) => format!("{decoder}; {}", note()),
            None => decoder,
        };
        Ok((Finished { summary, decoder, width, height, took: started.elapsed() }, extra))
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

/// The summary line (after the format's own line), or with --json one JSON object; nothing
/// with --quiet.
fn report(a: &OutputArgs, layout: &str, done: &Finished, dest: &Path, figures: &Figures, uploaded: Option<u64>) {
    if a.run.json {
        let mut doc = report::summary_value(done, layout, dest, figures);
        if let Some(sent) = uploaded {
            doc["uploadedBytes"] = sent.into();
        }
        say!("{doc}");
    } else if !a.run.quiet {
        if let Some(line) = report::figures_line(figures) {
            say!("{line}");
        }
        say!("{}", report::summary_line(done, dest));
        if a.run.verbose {
            say!("{}", report::stages_line(&done.summary.stages, done.width, done.height));
            say!("{}", report::memory_line(&done.summary.memory));
        }
    }
}

/// A run of one output: its summary as `split` has always printed it.
fn report_one(a: &OutputArgs, done: &Finished, wrote: &Wrote) {
    report(a, wrote.format.name(), done, &wrote.path, &wrote.figures, wrote.uploaded);
}

/// A run of several outputs: a line for each (its own figures, its pyramid's stages), then
/// one for the run; with --json, `outputs` and the run's time.
fn report_all(a: &OutputArgs, done: &Finished, all: &[Wrote]) {
    let each = |w: &Wrote| Finished {
        summary: w.summary.clone(),
        decoder: done.decoder.clone(),
        width: done.width,
        height: done.height,
        took: done.took,
    };
    let pyramids = all.iter().filter_map(|w| w.pyramid).map(|p| p + 1).max().unwrap_or(0);
    if a.run.json {
        let outputs: Vec<serde_json::Value> = all
            .iter()
            .map(|w| {
                let mut doc = report::summary_value(&each(w), w.format.name(), &w.path, &w.figures);
                doc["pyramid"] = w.pyramid.into();
                if let Some(sent) = w.uploaded {
                    doc["uploadedBytes"] = sent.into();
                }
                doc
            })
            .collect();
        let doc = serde_json::json!({
            "outputs": outputs,
            "pyramids": pyramids,
            "sourceReads": all.first().map_or(0, |w| w.reads),
            "width": done.width,
            "height": done.height,
            "source": done.decoder,
            "seconds": done.took.as_secs_f64(),
            "peakMemoryBytes": report::peak_rss(),
        });
        say!("{doc}");
    } else if !a.run.quiet {
        for w in all {
            if let Some(line) = report::figures_line(&w.figures) {
                say!("{line}");
            }
            say!("{}: {}", w.format, report::summary_line(&each(w), &w.path));
            if a.run.verbose {
                say!("{}", report::stages_line(&w.summary.stages, done.width, done.height));
                say!("{}", report::memory_line(&w.summary.memory));
            }
        }
        let reads = all.first().map_or(0, |w| w.reads);
        say!(
            "{} outputs in {:.2} s from {} pyramid{}, the source read {}{}",
            all.len(),
            done.took.as_secs_f64(),
            pyramids,
            if pyramids == 1 { "" } else { "s" },
            match reads {
                0 => "for no pyramid (every level copied as stored)".to_string(),
                1 => "once".to_string(),
                n => format!("{n} times (the budget holds the pyramids only one after another)"),
            },
            report::peak_rss().map(|b| format!(", peak memory {}", report::mib(b))).unwrap_or_default()
        );
    }
}
