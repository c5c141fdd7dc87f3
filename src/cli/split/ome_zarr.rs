//! `split`/`convert --layout ome-zarr`: the same pipeline into an OME-Zarr image, a directory
//! or a `.ozx` file (docs/ome-zarr.md).

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Result, bail};

use vortex_tiler::error::ShowPath;
use vortex_tiler::limits::Limits;
use vortex_tiler::output::Product;
use vortex_tiler::settings::{OmeZarrPlan, OmeZarrRequested, Requested};
use vortex_tiler::sink::OmeZarrSink;
use vortex_tiler::sink::ome_zarr::{LabelParent, PixelSize, Plane, Spec, Version, label_parent, register_label};
use vortex_tiler::source::channels::{ChannelSet, Ranged};
use vortex_tiler::source::{ImageHeader, Pick, RowSource};
use vortex_tiler::split::{self, SplitOptions, Summary};

use super::{Finished, OutputArgs, OutputLayout, Run, report};

/// The flags only `--layout ome-zarr` reads.
#[derive(clap::Args, Debug)]
pub struct OmeZarrArgs {
    /// --layout ome-zarr: 0.5 (Zarr v3, chunks gathered into shards: the current
    /// specification) or 0.4 (Zarr v2, one file per chunk: what older readers and pipelines
    /// take) [default: 0.5].
    #[arg(long, value_enum, value_name = "VERSION")]
    ome_zarr_version: Option<OmeZarrVersion>,

    /// --layout ome-zarr 0.5: chunks per shard side; each shard file holds N x N chunks
    /// (--tile-size each), so that a large image is thousands of files, not millions
    /// [default: 16: 4096-texel shards with 256-texel chunks].
    #[arg(long, value_name = "N")]
    shard_chunks: Option<u32>,

    /// --layout ome-zarr: the physical side of a source pixel, e.g. 0.25um or 250nm, written
    /// as the levels' scale and the axes' unit [default: none: scales in pixels, no unit].
    #[arg(long, value_name = "SIZE")]
    pixel_size: Option<PixelSize>,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
enum OmeZarrVersion {
    #[value(name = "0.4")]
    V04,
    #[value(name = "0.5")]
    V05,
}

impl OmeZarrArgs {
    /// The flags are errors with another layout.
    pub fn refuse_elsewhere(&self) -> Result<()> {
        for (given, flag) in [
            (self.ome_zarr_version.is_some(), "--ome-zarr-version"),
            (self.shard_chunks.is_some(), "--shard-chunks"),
            (self.pixel_size.is_some(), "--pixel-size"),
        ] {
            if given {
                bail!("{flag} belongs to --layout ome-zarr");
            }
        }
        Ok(())
    }
}

pub fn tile(
    source: Box<dyn RowSource>,
    input: &Path,
    names: Option<String>,
    a: &OutputArgs,
    started: Instant,
) -> Result<()> {
    let plan = plan(source.header(), input, names, a, None)?;
    let claim = report::claim(&plan.dest, plan.product, &[input], a.force)?;
    let layout = plan.spec.layout;
    let run = Run::start(source, a, &layout, started)?;
    let total = layout.total_tiles();
    let version = plan.spec.version;
    let sink = OmeZarrSink::create(&claim, plan.spec)?;
    // On error the sink is dropped, which removes what it wrote.
    let done = run.execute(&sink, &plan.opts)?;
    if done.summary.tiles != total {
        bail!("internal error: wrote {} tiles of {total}", done.summary.tiles);
    }
    sink.finish()?;
    if let (Some(p), Some(label)) = (&plan.parent, plan.dest.file_name()) {
        register_label(&p.image.join("labels"), version, &label.to_string_lossy())?;
    }
    super::report(a, "ome-zarr", &done, &plan.dest, None);
    Ok(())
}

/// A run into OME-Zarr as the flags and the source make it, before the first tile.
struct Plan {
    dest: PathBuf,
    product: Product,
    spec: Spec,
    opts: SplitOptions,
    /// The image a label image belongs to (`-o IMAGE/labels/NAME`).
    parent: Option<LabelParent>,
}

/// Checks the flags that belong to other layouts, then plans the run through the library
/// ([`OmeZarrPlan`]) from the source (`header`: a channel's, for channels written one pass
/// each, `planes`).
fn plan(
    header: ImageHeader,
    input: &Path,
    names: Option<String>,
    a: &OutputArgs,
    planes: Option<Vec<Plane>>,
) -> Result<Plan> {
    let Some(dest) = &a.output else {
        bail!("--layout ome-zarr writes a directory or a .ozx file (-o DIR.ome.zarr or -o FILE.ozx), not a pack")
    };
    if a.shard.is_some() {
        bail!("--shard makes shard packs (--pack); --layout ome-zarr is written by one run");
    }
    for (given, flag) in [(a.overlap.is_some(), "--overlap"), (a.iiif_id.is_some(), "--iiif-id")] {
        if given {
            bail!("{flag} belongs to a viewer layout; OME-Zarr chunks do not overlap");
        }
    }
    let requested = Requested {
        tile_size: a.tile_size,
        border: a.border,
        background: a.background,
        flatten: a.flatten,
        tile_depth: a.tile_type,
        filename_format: names,
        filter: a.filter,
        max_memory: Some(a.max_memory),
        ..a.enc.requested()
    };
    let zarr = OmeZarrRequested {
        version: a.ome_zarr.ome_zarr_version.map(|v| match v {
            OmeZarrVersion::V04 => Version::V04,
            OmeZarrVersion::V05 => Version::V05,
        }),
        shard_chunks: a.ome_zarr.shard_chunks,
        pixel_size: a.ome_zarr.pixel_size,
        name: match &a.name {
            Some(name) => name.clone(),
            None => input.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default(),
        },
        planes,
    };
    // -o IMAGE/labels/NAME: a label image of IMAGE, in IMAGE's version.
    let parent = label_parent(dest);
    let limits = Limits { memory: a.max_memory, ..Limits::default() };
    let OmeZarrPlan { product, spec, opts } =
        OmeZarrPlan::new(&requested, zarr, dest, parent.as_ref(), &header, &limits)?;
    Ok(Plan { dest: dest.clone(), product, spec, opts, parent })
}

/// The channels of a run, where they are not an image's 1 to 4 samples as the pipeline reads
/// them: `--channel` files, an image of more channels than a texel holds (a TIFF of more than
/// four samples or of separate planes, an OME-TIFF of several grey planes), or any image whose
/// channels `--channels` picks. `None`: the input read as it is.
pub fn channel_set(
    input: Option<&Path>,
    files: &[PathBuf],
    picks: bool,
    pick: Pick,
    a: &OutputArgs,
) -> Result<Option<(ChannelSet, Vec<PathBuf>)>> {
    if !files.is_empty() {
        if input.is_some() {
            bail!("--channel names every channel's image; leave out the INPUT");
        }
        return Ok(Some((ChannelSet::files(files, a.max_memory)?, files.to_vec())));
    }
    let Some(input) = input else { bail!("an input image is required (or --channel FILE per channel)") };
    let set = match picks {
        true => Some(ChannelSet::open(input, pick, a.max_memory)?),
        false => ChannelSet::beyond_texels(input, pick, a.max_memory)?,
    };
    Ok(set.map(|set| (set, vec![input.to_path_buf()])))
}

/// Cuts the channels `picks` (all by default) of `set`: into OME-Zarr, one pass per channel
/// (docs/ome-zarr.md); into another layout, as one grey or RGB image.
pub fn tile_channels(
    set: ChannelSet,
    picks: Option<&[usize]>,
    inputs: &[PathBuf],
    names: Option<String>,
    a: &OutputArgs,
    started: Instant,
) -> Result<()> {
    let all: Vec<usize> = (0..set.count()).collect();
    let picks = picks.unwrap_or(&all);
    for (i, &k) in picks.iter().enumerate() {
        if k >= set.count() {
            bail!("--channels {k}: {} has {} channel(s), 0 to {}", inputs[0].shown(), set.count(), set.count() - 1);
        }
        if picks[..i].contains(&k) {
            bail!("--channels names channel {k} twice");
        }
    }
    if picks.is_empty() {
        bail!("--channels names no channel");
    }
    if a.layout != OutputLayout::OmeZarr {
        if ![1, 3].contains(&picks.len()) {
            bail!(
                "{}: {} channels, and --layout {} (or a pack) holds one (grey) or three (RGB) of them: pick them with --channels 0,1,2, or write every channel with --layout ome-zarr",
                inputs[0].shown(),
                picks.len(),
                clap::ValueEnum::to_possible_value(&a.layout).map(|v| v.get_name().to_string()).unwrap_or_default()
            );
        }
        let source = set.interleave(picks)?;
        return super::tile(source, &inputs[0], names, a, started, None);
    }
    let planes = picks.iter().map(|&k| Plane { name: set.names[k].clone(), window: None }).collect();
    let mut first = Some(set.channel(picks[0])?);
    let header =
        first.as_ref().map(|s| s.header()).unwrap_or(ImageHeader { width: 0, height: 0, layout: set.layout() });
    let plan = plan(header, &inputs[0], names, a, Some(planes))?;
    if plan.parent.is_some() {
        bail!("{}: a label image has one channel; pick it with --channels N", plan.dest.shown());
    }
    let inputs: Vec<&Path> = inputs.iter().map(PathBuf::as_path).collect();
    let claim = report::claim(&plan.dest, plan.product, &inputs, a.force)?;
    let total = plan.spec.layout.total_tiles();
    a.run.init_pool()?;
    let watch = a.run.watch(total * picks.len() as u64)?;
    let mut sink = OmeZarrSink::create(&claim, plan.spec)?;
    let mut summary: Option<Summary> = None;
    // One pass per channel, one after another: memory stays one grey pipeline's.
    for (c, &k) in picks.iter().enumerate() {
        let source = match first.take() {
            Some(source) => source,
            None => set.channel(k)?,
        };
        let (source, range) = Ranged::new(source);
        let done = split::split(Box::new(source), &sink.plane(c as u32), &plan.opts, &watch);
        let done = done.inspect_err(|_| watch.bar.finish_and_clear())?;
        if done.tiles != total {
            bail!("internal error: wrote {} tiles of {total} of channel {k}", done.tiles);
        }
        let window = *range.lock().unwrap_or_else(|p| p.into_inner());
        sink.set_window(c, window);
        summary = Some(match summary {
            None => done,
            Some(sum) => add(sum, done),
        });
    }
    watch.bar.finish_and_clear();
    sink.finish()?;
    let Some(summary) = summary else { bail!("--channels names no channel") };
    let done =
        Finished { summary, decoder: set.describe(), width: set.width, height: set.height, took: started.elapsed() };
    super::report(a, "ome-zarr", &done, &plan.dest, None);
    Ok(())
}

/// Two passes' summaries as one run's: their tiles, reads and stage times added up.
fn add(mut sum: Summary, pass: Summary) -> Summary {
    sum.tiles += pass.tiles;
    sum.encoded += pass.encoded;
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
