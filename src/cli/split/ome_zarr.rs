//! `split`/`convert --layout ome-zarr`: the same pipeline into an OME-Zarr image, a directory
//! or a `.ozx` file (docs/ome-zarr.md).

use std::path::Path;
use std::time::Instant;

use anyhow::{Result, bail};

use vortex_tiler::codec::ZSTD_LEVELS;
use vortex_tiler::limits::Limits;
use vortex_tiler::output::Product;
use vortex_tiler::pyramid::Filter;
use vortex_tiler::settings::{self, CodecChoice, Requested};
use vortex_tiler::sink::OmeZarrSink;
use vortex_tiler::sink::ome_zarr::{
    DEFAULT_CHUNK, DEFAULT_SHARD_CHUNKS, MAX_SHARD_CHUNKS, PixelSize, Spec, Version, is_ozx, label_parent,
    register_label,
};
use vortex_tiler::source::RowSource;

use super::{OutputArgs, Run, report};

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
    let Some(dest) = &a.output else {
        bail!("--layout ome-zarr writes a directory or a .ozx file (-o DIR.ome.zarr or -o FILE.ozx), not a pack")
    };
    if names.is_some() {
        bail!("--layout ome-zarr names its chunks as Zarr does; --filename-format is for --layout vortex");
    }
    if a.shard.is_some() {
        bail!("--shard makes shard packs (--pack); --layout ome-zarr is written by one run");
    }
    for (given, flag) in [(a.overlap.is_some(), "--overlap"), (a.iiif_id.is_some(), "--iiif-id")] {
        if given {
            bail!("{flag} belongs to a viewer layout; OME-Zarr chunks do not overlap");
        }
    }
    // Zarr chunks tile the array edge to edge: a border would be texels stored twice.
    if let Some(border) = a.border.filter(|b| *b != 0) {
        bail!("--border {border}: OME-Zarr chunks have no border (each texel is stored once); leave it out");
    }
    let enc = &a.enc;
    if let Some(codec) = enc.codec.filter(|c| *c != CodecChoice::Zstd) {
        bail!(
            "--codec {}: OME-Zarr chunks are zstd-compressed (the codec every Zarr reader has); leave --codec out or set --zstd-level",
            codec.name()
        );
    }
    for (given, flag) in [
        (enc.quality.is_some(), "--quality"),
        (enc.subsampling.is_some(), "--subsampling"),
        (enc.png_compression.is_some(), "--png-compression"),
        (enc.bc7_effort.is_some(), "--bc7-effort"),
    ] {
        if given {
            bail!("{flag} does not apply to --layout ome-zarr, whose chunks are zstd-compressed (--zstd-level)");
        }
    }
    let asked = a.ome_zarr.ome_zarr_version.map(|v| match v {
        OmeZarrVersion::V04 => Version::V04,
        OmeZarrVersion::V05 => Version::V05,
    });
    // -o IMAGE/labels/NAME: a label image of IMAGE, in IMAGE's version.
    let parent = label_parent(dest);
    let version = match (&parent, asked) {
        (Some(p), Some(ours)) if p.version != ours => bail!(
            "{} is OME-Zarr {}: its labels are too; leave out --ome-zarr-version {}",
            p.image.display(),
            p.version.name(),
            ours.name()
        ),
        (Some(p), _) => p.version,
        (None, asked) => asked.unwrap_or(Version::V05),
    };
    if parent.is_some() && !a.filter.is_some_and(Filter::is_label) {
        bail!(
            "{}: a label image's levels need --filter mode or --filter nearest (a mean would invent labels)",
            dest.display()
        );
    }
    let shard_chunks = match (version, a.ome_zarr.shard_chunks) {
        (Version::V04, Some(_)) => bail!("--shard-chunks: OME-Zarr 0.4 (Zarr v2) has no shards; it is for 0.5"),
        (_, Some(n)) if !(1..=MAX_SHARD_CHUNKS).contains(&n) => {
            bail!("--shard-chunks {n} must be from 1 to {MAX_SHARD_CHUNKS}")
        }
        (_, n) => n.unwrap_or(DEFAULT_SHARD_CHUNKS),
    };
    let product = if is_ozx(dest) { Product::Ozx } else { Product::OmeZarr };
    if product == Product::Ozx && version != Version::V05 {
        bail!(
            "{}: a zipped OME-Zarr (.ozx, RFC-9) holds OME-Zarr 0.5; leave out --ome-zarr-version 0.4 or write a directory",
            dest.display()
        );
    }
    let limits = Limits { memory: a.max_memory, ..Limits::default() };
    let requested = Requested {
        // A label image's levels are its image's: the same chunks by default.
        tile_size: Some(a.tile_size.or(parent.as_ref().map(|p| p.chunk)).unwrap_or(DEFAULT_CHUNK)),
        border: Some(0),
        codec: Some(CodecChoice::Raw),
        background: a.background,
        flatten: a.flatten,
        tile_depth: a.tile_type,
        // Microscopy samples measure intensity linearly: the mean of the stored values is the
        // right reduction, not one in sRGB's linear light.
        filter: Some(a.filter.unwrap_or(Filter::Box)),
        max_memory: Some(a.max_memory),
        ..Requested::default()
    };
    let (opts, _) = settings::resolve(&requested, None, source.layout())?;
    // Raw tiles go to the sink, which compresses the chunks itself.
    let zstd_level = enc.zstd_level.unwrap_or(settings::DEFAULT_ZSTD_LEVEL);
    if !ZSTD_LEVELS.contains(&zstd_level) {
        bail!("zstd level {zstd_level} (--zstd-level) is outside {}..={}", ZSTD_LEVELS.start(), ZSTD_LEVELS.end());
    }
    let layout = opts.layout(source.width(), source.height())?;
    let stored = opts.codec.stored_layout(source.layout(), opts.flatten, opts.tile_depth)?;
    limits.check_pyramid(&layout, false)?;
    if let Some(p) = &parent {
        let ours = (layout.width as u64, layout.height as u64, layout.lod_count);
        if ours != (p.size.0, p.size.1, p.levels) {
            bail!(
                "{} is {}x{} in {} levels, but this label image is {}x{} in {} levels (--tile-size {}); a label image matches its image",
                p.image.display(),
                p.size.0,
                p.size.1,
                p.levels,
                ours.0,
                ours.1,
                ours.2,
                layout.tile_size
            );
        }
    }
    let name = match &a.name {
        Some(name) => name.clone(),
        None => input.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default(),
    };
    let spec = Spec {
        version,
        layout,
        stored,
        shard_chunks,
        zstd_level,
        pixel_size: a.ome_zarr.pixel_size,
        name: name.trim_end_matches(".ome").to_string(),
        filter: opts.filter.name().to_string(),
        label: parent.is_some(),
    };
    limits.check_memory(
        &format!(
            "holding the indexes of {} shards of {shard_chunks}x{shard_chunks} chunks (all open at worst; larger chunks, --tile-size, need fewer)",
            spec.shard_count()
        ),
        spec.index_bytes(),
    )?;
    let claim = report::claim(dest, product, &[input], a.force)?;
    let run = Run::start(source, a, &layout, started)?;
    let total = layout.total_tiles();
    let sink = OmeZarrSink::create(&claim, spec)?;
    // On error the sink is dropped, which removes what it wrote.
    let done = run.execute(&sink, &opts)?;
    if done.summary.tiles != total {
        bail!("internal error: wrote {} tiles of {total}", done.summary.tiles);
    }
    sink.finish()?;
    if let (Some(p), Some(label)) = (&parent, dest.file_name()) {
        register_label(&p.image.join("labels"), version, &label.to_string_lossy())?;
    }
    super::report(a, "ome-zarr", &done, dest, None);
    Ok(())
}
