//! `split`/`convert --layout ome-zarr`: the same pipeline into an OME-Zarr image, a directory
//! or a `.ozx` file (docs/ome-zarr.md).

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Result, bail};

use vortex_tiler::error::ShowPath;
use vortex_tiler::formats::ome_zarr::{PixelSize, Plane, Version};
use vortex_tiler::formats::tiff::Flavour;
use vortex_tiler::outputs::{Budget, Format, OmeZarrSettings, Plan};
use vortex_tiler::source::Pick;
use vortex_tiler::source::channels::ChannelSet;

use super::{Finished, OutputArgs, report};

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
    /// as the levels' scale and the axes' unit [default: the input's own where its file
    /// states it (a slide's MPP, OME-XML, resolution tags in cm), else none: scales in pixels].
    /// A TIFF output records it too (OME's PhysicalSizeX/Y, the resolution tags), and a DICOM
    /// series needs it (its pixel spacing and imaged volume).
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

/// The flags as the library's OME-Zarr settings.
pub fn settings(a: &OmeZarrArgs) -> OmeZarrSettings {
    OmeZarrSettings {
        version: a.ome_zarr_version.map(|v| match v {
            OmeZarrVersion::V04 => Version::V04,
            OmeZarrVersion::V05 => Version::V05,
        }),
        shard_chunks: a.shard_chunks,
        pixel_size: a.pixel_size,
    }
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
        return Ok(Some((ChannelSet::files(files, Budget::new(a.max_memory))?, files.to_vec())));
    }
    let Some(input) = input else { bail!("an input image is required (or --channel FILE per channel)") };
    let set = match picks {
        true => Some(ChannelSet::open(input, pick, Budget::new(a.max_memory))?),
        false => ChannelSet::beyond_texels(input, pick, Budget::new(a.max_memory))?,
    };
    Ok(set.map(|set| (set, vec![input.to_path_buf()])))
}

/// Cuts the channels `picks` (all by default) of `set`: into OME-Zarr or an OME-TIFF, one pass
/// per channel (docs/ome-zarr.md, docs/tiff.md: a grey plane each); into another output, as
/// one grey or RGB image.
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
    let outputs = a.outputs()?;
    // OME-Zarr and OME-TIFF hold any number of channels, each a pyramid of its own.
    let planar = |f: Format| matches!(f, Format::OmeZarr | Format::Tiff(Flavour::Ome));
    if !outputs.iter().any(|o| planar(o.format)) {
        if ![1, 3].contains(&picks.len()) {
            let first = &outputs[0];
            bail!(
                "{}: {} channels, and a {} output ({}) holds one (grey) or three (RGB) of them a pixel: pick them with --channels 0,1,2, or write every channel with --layout ome-zarr or as a plane of an OME-TIFF (-o FILE.ome.tif)",
                inputs[0].shown(),
                picks.len(),
                first.format,
                first.path.shown(),
            );
        }
        let source = set.interleave(picks)?;
        let carried = super::Carried { pitch: set.pitch, ..super::Carried::default() };
        return super::tile(source, &inputs[0], names, a, started, carried);
    }
    if let Some(other) = outputs.iter().find(|o| !planar(o.format)) {
        bail!(
            "{}: its {} channels go into OME-Zarr and OME-TIFF planes one pass each, and {} ({}) holds no plane: write it in a run of its own",
            inputs[0].shown(),
            picks.len(),
            other.format,
            other.path.shown(),
        );
    }
    let planes = (picks.iter())
        .map(|&k| Plane { name: set.names[k].clone(), window: None, colour: set.colours.get(k).copied().flatten() })
        .collect();
    let first = set.channel(picks[0])?;
    let inputs: Vec<&Path> = inputs.iter().map(PathBuf::as_path).collect();
    // The source's pixel size, as a run of the image read as it is carries it; no ICC profile
    // or georeferencing: each plane is a grey channel, not the texels they describe.
    let settings = a.settings(names, super::Carried { pitch: set.pitch, ..super::Carried::default() }, None)?;
    let plan =
        Plan::with_planes(outputs, &settings, &first.header(), &inputs, Budget::new(a.max_memory), Some(planes))?;
    for planned in plan.outputs() {
        report::prepare(&planned.output.path)?;
    }
    a.run.init_pool()?;
    let watch = a.run.watch(plan.total_tiles() * picks.len() as u64)?;
    let wrote = plan.write_channels(&set, picks, first, &watch);
    watch.bar.finish_and_clear();
    let wrote = wrote?;
    let Some(first) = wrote.first() else { bail!("a run with no output") };
    let done = Finished {
        summary: first.summary.clone(),
        decoder: set.describe(),
        width: set.width,
        height: set.height,
        took: started.elapsed(),
    };
    match wrote.as_slice() {
        [one] => super::report_one(a, &done, one),
        all => super::report_all(a, &done, all),
    }
    Ok(())
}
