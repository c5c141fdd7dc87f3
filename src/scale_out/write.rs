//! Making one shard pack: `split --shard I/N --pack FILE`.

use std::path::Path;

use vortex_pack::{WriteOptions, WriteSummary};

use super::manifest::{FORMAT, Manifest, ShardOptions, SourceId, StoredRoots};
use super::plan::{Region, ShardPlan};
use crate::error::{Result, TilerError};
use crate::formats::pack::{PackSink, size_bound};
use crate::layout::Layout;
use crate::limits::human_bytes;
use crate::pixel::PixelLayout;
use crate::pyramid::cascade::Span;
use crate::pyramid::stripes::span_bytes;
use crate::source::RowSource;
use crate::split::{self, Progress, SplitOptions, Summary};

/// Which shard to make, and of what.
pub struct ShardJob<'a> {
    /// This shard, counting from 0: less than `count`.
    pub index: u32,
    /// Shards the split is cut into, 1 or more.
    pub count: u32,
    /// The input as given (fingerprinted, and named in the manifest).
    pub input: &'a Path,
    /// The metadata of the merged pack: what `split --pack` of the same input and options
    /// writes.
    pub info: String,
    /// The pack's alignments (`--align`, `--tile-align`), those of the merged pack too.
    pub pack: WriteOptions,
}

impl ShardJob<'_> {
    /// Pages shard `index` makes: its subtrees at the cut level and below.
    pub fn pages(&self, layout: &Layout) -> Result<u64> {
        let plan = ShardPlan::choose(layout, self.count)?;
        let pages = |r: &Region| {
            let span = plan.span(layout, r);
            span.lods.clone().map(|lod| span.columns_at(lod).len() as u64 * span.rows_at(lod).len() as u64).sum::<u64>()
        };
        Ok(plan.regions(self.index).iter().map(pages).sum())
    }
}

/// Cuts shard `job.index` of `source` into a shard pack at `dest`: a local file, or an
/// `s3://` URL already claimed, streamed as it is made.
pub fn write_shard(
    source: Box<dyn RowSource>,
    dest: &Path,
    opts: &SplitOptions,
    job: &ShardJob,
    progress: &dyn Progress,
) -> Result<(Summary, WriteSummary)> {
    let header = source.header();
    let layout = opts.layout(header.width, header.height)?;
    let plan = ShardPlan::choose(&layout, job.count)?;
    if job.index >= job.count {
        return Err(TilerError::Options(format!(
            "shard {} of {}: the index counts from 0 to {}",
            job.index,
            job.count,
            job.count - 1
        )));
    }
    let spans = shard_spans(&plan, &layout, opts, header.layout, job.index)?;
    let fingerprint = super::fingerprint(job.input)?;
    let stored = opts.codec.stored_layout(header.layout, opts.flatten, opts.tile_depth)?;
    let mut manifest = Manifest {
        vortex_shard: FORMAT,
        index: job.index,
        count: job.count,
        cut_level: plan.cut,
        source: SourceId {
            name: job.input.display().to_string(),
            fingerprint,
            width: header.width,
            height: header.height,
            tile_format: header.layout.channels.tile_format().into(),
            sample_bytes: header.layout.depth.bytes() as u8,
        },
        options: ShardOptions {
            info: job.info.clone(),
            flatten: opts.flatten,
            max_memory: opts.max_memory,
            alignment: job.pack.alignment,
            payload_alignment: job.pack.payload_alignment,
            sum_bytes: split::sum_bytes(opts, header.layout, &layout) as u32,
        },
        roots: Vec::new(),
    };
    // The metadata is written last but its room is set first, for the sums however little
    // they compress (the pack writer gives back what is left unused).
    let sums_room: u64 = match plan.has_levels_above(&layout) {
        false => 0,
        true => plan.regions(job.index).iter().map(|r| sums_room(&plan, &layout, r, opts, header.layout)).sum(),
    };
    let room = manifest.to_json().len() as u64 + sums_room;
    let room = usize::try_from(room).ok().filter(|&r| u32::try_from(r).is_ok()).ok_or_else(|| {
        TilerError::Limit(format!(
            "shard {}: its root sums would not fit a pack's metadata; cut more shards",
            job.index
        ))
    })?;
    let room = vec![b' '; room];
    let sink = match crate::store::ObjectUrl::of_path(dest) {
        Some(_) => {
            let out = super::objects::pack_output(dest, size_bound(&layout, stored, room.len()))?;
            PackSink::create_to(out, &layout, stored, opts.codec, &room, job.pack)?
        }
        None => PackSink::create(dest, &layout, stored, opts.codec, &room, job.pack)?,
    };
    let (summary, roots) = split::split_shard(source, &sink, opts, spans, progress)?;
    manifest.roots = roots.iter().map(|r| StoredRoots::new(r.columns.clone(), r.rows.clone(), &r.bytes)).collect();
    let written = sink.finish_with_metadata(manifest.to_json())?;
    Ok((summary, written))
}

/// The passes of shard `index`, once it is known that they can be made: by an exact filter
/// (the others resample each level across the shards' edges), each within `--max-memory`.
fn shard_spans(
    plan: &ShardPlan,
    layout: &Layout,
    opts: &SplitOptions,
    pixels: PixelLayout,
    index: u32,
) -> Result<Vec<Span>> {
    if !opts.filter.is_exact() {
        return Err(TilerError::Options(format!(
            "--filter {} cannot be sharded (it resamples each level across the shards' edges); an exact filter such as the default can",
            opts.filter
        )));
    }
    let spans: Vec<Span> = plan.regions(index).iter().map(|r| plan.span(layout, r)).collect();
    let sums = split::sum_bytes(opts, pixels, layout) as u64 * pixels.channels.count() as u64;
    for span in &spans {
        let (columns, rows) = (span.window(layout, plan.cut), span.window_rows(layout, plan.cut));
        let roots = (columns.end - columns.start) * (rows.end - rows.start) * sums;
        let need = span_bytes(layout, span, pixels.bytes_per_pixel() as u64).saturating_add(roots);
        if need > opts.max_memory {
            let window = span.window(layout, 0);
            return Err(TilerError::Limit(format!(
                "shard {index} of {} makes pages {} texels wide, which needs {}, more than --max-memory ({}); raise --max-memory or cut more shards",
                plan.count(),
                window.end - window.start,
                human_bytes(need),
                human_bytes(opts.max_memory)
            )));
        }
    }
    Ok(spans)
}

/// The most bytes the stored sums of `region` can take: zstd's bound for the byte planes that
/// can be non-zero (a sum of `4^(cut + 1)` values up to the filter's largest has that many
/// significant bytes; the planes above are all zero, a few bytes per row), in base64.
fn sums_room(plan: &ShardPlan, layout: &Layout, region: &Region, opts: &SplitOptions, pixels: PixelLayout) -> u64 {
    let (columns, rows) = plan.sums_rect(layout, region);
    let samples = (columns.end - columns.start) * pixels.channels.count() as u64;
    let rows = rows.end - rows.start;
    let largest = split::max_summand(opts, pixels) as u128 * (1u128 << (2 * (plan.cut + 1)));
    let significant = (128 - largest.leading_zeros()).div_ceil(8) as u64;
    let packed = zstd::zstd_safe::compress_bound((samples * significant * rows) as usize) as u64 + 64 * rows;
    packed.div_ceil(3) * 4 + 128
}
