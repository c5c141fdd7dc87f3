//! `merge`: shard packs into the pack one machine's `split --pack` makes, byte for byte.
//!
//! 1. Every shard's header, metadata and index checksums are checked, then its manifest is
//!    read and checked against the first: the same input (fingerprint, size, texels; not the
//!    name it was given by), the same options, the same shard count; then every index once
//!    and none missing. Each error names the shard file.
//! 2. The options are read back from the pack metadata the shards carry, through the same
//!    resolution `split` uses, and must describe that metadata again exactly; the numbers the
//!    options imply (sum width, alignments) must be the ones `split` writes; the shard plan
//!    is recomputed and must give each shard the rectangles it says it made.
//! 3. The levels above the cut are made from the roots' sums (`RootRows` assembles each
//!    row of the cut level from the shards that hold it), through the same exact cascade and
//!    encoders as `split`, and kept in memory: they are the few coarse pages. Each sum must be
//!    one the source could give (at most its pixels' largest value times their number).
//! 4. Every page is added to a new pack in the order `split --pack` adds them
//!    ([`super::order`]): the shards' payloads as they are (their checksums checked), the
//!    coarse pages from step 3. The pack writer stores identical payloads once, across
//!    shards as within one.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use vortex_pack::{NewTile, Pack, PackWriter, Tile, TileId, WriteOptions, WriteSummary};

use super::manifest::{Manifest, shard_error};
use super::objects::ShardFiles;
use super::order::split_order;
use super::plan::ShardPlan;
use super::sums::{RootRows, RowReader, SumBound};
use crate::error::{Result, ShowPath, TilerError};
use crate::formats::pack::{pack_description, size_bound, tile_kind};
use crate::formats::tiles::info::InfoFile;
use crate::layout::Layout;
use crate::limits::{MAX_ALIGN, MAX_TILE_ALIGN, human_bytes};
use crate::pixel::PixelLayout;
use crate::pyramid::cascade::Span;
use crate::pyramid::stripes::{Beside, Plan};
use crate::settings::{self, Requested};
use crate::sink::TileSink;
use crate::source::ImageHeader;
use crate::split::{Progress, SplitOptions};

/// What a merge made and read.
#[derive(Clone, Debug)]
pub struct Merged {
    /// The merged pack's own summary: tiles, bytes, content hash.
    pub pack: WriteSummary,
    /// Shards merged.
    pub shards: u32,
    /// The cut level: LODs above it were made by the merge.
    pub cut: u32,
    /// Pages made above the cut.
    pub made: u64,
    /// Payload bytes copied from the shards.
    pub copied_bytes: u64,
    /// Compressed sums read from the shards' manifests.
    pub sums_bytes: u64,
}

/// One opened shard.
struct Shard {
    path: PathBuf,
    pack: Pack,
    manifest: Manifest,
}

/// Merges the shard packs at `paths` (any order) into a pack at `dest`. Runs the encoders of
/// the levels above the cut on the current rayon pool.
pub fn merge(paths: &[PathBuf], dest: &Path, progress: &dyn Progress) -> Result<Merged> {
    merge_files(&ShardFiles::local(paths), dest, progress)
}

/// [`merge`] of `shards`, each read from its local file and named in errors as it was given
/// (an `s3://` URL for one downloaded), into `dest`: a local file, or an `s3://` URL already
/// claimed ([`super::claim_pack`]), streamed as it is made.
pub fn merge_files(shards: &ShardFiles, dest: &Path, progress: &dyn Progress) -> Result<Merged> {
    let shards = open_all(shards.names(), shards.files())?;
    let first = &shards[0];
    let pixels = first.manifest.source.pixels(&first.path)?;
    let (opts, layout, stored) = read_options(first, pixels)?;
    // The pyramid the manifest describes must be the one each shard's level table holds, whose
    // size its file bounds, before the plan and the page order are sized from it.
    for shard in &shards {
        if *shard.pack.description() != pack_description(&layout, stored) {
            return Err(shard_error(&shard.path, "its pack header does not match its metadata".into()));
        }
    }
    let plan = ShardPlan::choose(&layout, first.manifest.count)?;
    for shard in &shards {
        check_pages(shard, &plan, &layout)?;
    }
    // Per shard, per rectangle: the compressed sums.
    let sums: Vec<Vec<Vec<u8>>> =
        shards.iter().map(|s| s.manifest.roots.iter().map(|r| r.sums(&s.path)).collect()).collect::<Result<_>>()?;
    let sums_bytes = sums.iter().flatten().map(|b| b.len() as u64).sum();
    let mut above = match plan.has_levels_above(&layout) {
        true => above_cut(&shards, &sums, &plan, &layout, &opts, pixels)?,
        false => HashMap::new(),
    };
    let made = above.len() as u64;

    // Every page, in the one-machine order.
    let o = &first.manifest.options;
    let options = WriteOptions { alignment: o.alignment, payload_alignment: o.payload_alignment };
    let (description, levels, info) = (pack_description(&layout, stored), layout.pack_levels(), o.info.as_bytes());
    let mut writer = match crate::store::ObjectUrl::of_path(dest) {
        Some(_) => {
            let out = super::objects::pack_output(dest, size_bound(&layout, stored, info.len()))?;
            PackWriter::with_output(out, description, levels, info, options)?
        }
        None => PackWriter::create(dest, description, levels, info, options)?.boxed(),
    };
    let kind = tile_kind(opts.codec)?;
    // A run too wide for one machine's memory has no order of its own: merge writes the one
    // a machine with enough memory would, into a pack, from a source that holds no decoder
    // buffers of its own (rows in memory, PNG, JPEG, uncompressed strips) and stores no tiles
    // to copy.
    let encoded_tile = opts.codec.most_encoded_bytes(layout.tile_size, stored);
    let beside = Beside { decoder: 0, encoded_tile, copies: false };
    let order = Plan::choose(&layout, pixels.bytes_per_pixel() as u64, opts.filter, opts.max_memory, beside)
        .unwrap_or_else(|_| Plan { stripes: vec![Span::whole(&layout)], coarse: None, read_ahead_rows: 0, held: 0 });
    let mut copied_bytes = 0u64;
    for row in split_order(&layout, &order) {
        if progress.cancelled() {
            return Err(TilerError::Interrupted);
        }
        for x in row.columns.clone() {
            let id = TileId { lod: row.lod, x, y: row.y };
            if id.lod > plan.cut {
                let tile = above.remove(&id).ok_or_else(|| missing(dest, id))?;
                writer.add(id, tile.as_new(kind))?;
                continue;
            }
            let shard = &shards[plan.owner(id.lod, x, id.y) as usize];
            match shard.pack.tile_checked(vortex_pack::TileId::new(id.lod, x, id.y))? {
                Tile::Absent => return Err(missing(&shard.path, id)),
                Tile::Constant(texel) => writer.add(id, NewTile::Constant(texel))?,
                Tile::Data(k, bytes) => {
                    copied_bytes += bytes.len() as u64;
                    writer.add(id, NewTile::Data(k, bytes))?;
                }
            }
        }
        progress.advance(row.columns.len() as u64);
    }
    let pack = writer.finish()?;
    Ok(Merged { pack, shards: plan.count(), cut: plan.cut, made, copied_bytes, sums_bytes })
}

/// Checks that `shard` holds what this version's plan gives its index: the cut level and its
/// rectangles of sums.
fn check_pages(shard: &Shard, plan: &ShardPlan, layout: &Layout) -> Result<()> {
    let m = &shard.manifest;
    let theirs: Vec<_> = m.roots.iter().map(|r| (r.columns, r.rows)).collect();
    let ours: Vec<_> = match plan.has_levels_above(layout) {
        false => Vec::new(),
        true => plan
            .regions(m.index)
            .iter()
            .map(|r| {
                let (columns, rows) = plan.sums_rect(layout, r);
                ([columns.start, columns.end], [rows.start, rows.end])
            })
            .collect(),
    };
    if m.cut_level != plan.cut || theirs != ours {
        return Err(shard_error(
            &shard.path,
            format!(
                "holds other pages than this version cuts shard {} of {} into (cut at LOD {}, not {}): merge with the vortex-tiler that made it",
                m.index, m.count, m.cut_level, plan.cut
            ),
        ));
    }
    Ok(())
}

/// The pages above the cut, encoded, from the shards' sums (`sums[shard][rectangle]`).
fn above_cut(
    shards: &[Shard],
    sums: &[Vec<Vec<u8>>],
    plan: &ShardPlan,
    layout: &Layout,
    opts: &SplitOptions,
    pixels: PixelLayout,
) -> Result<HashMap<TileId, Made>> {
    let sum_bytes = shards[0].manifest.options.sum_bytes as usize;
    let bound = SumBound {
        lod: plan.cut + 1,
        channels: pixels.channels.count(),
        width: layout.width.into(),
        height: layout.height.into(),
        summand: crate::split::max_summand(opts, pixels),
    };
    let mut roots = RootRows::new(bound);
    for (shard, sums) in shards.iter().zip(sums) {
        for (r, bytes) in shard.manifest.roots.iter().zip(sums) {
            let (columns, rows) = (r.columns[0]..r.columns[1], r.rows[0]..r.rows[1]);
            let reader = RowReader::new(bytes, columns, rows, bound.channels, sum_bytes)?;
            roots.add(&shard.path, reader);
        }
    }
    let image = ImageHeader { width: layout.width, height: layout.height, layout: pixels };
    let made = Collected::default();
    crate::split::above_cut(image, roots, &made, opts, &())?;
    made.tiles.into_inner().map_err(|_| TilerError::panicked("an encoder"))
}

fn missing(path: &Path, id: TileId) -> TilerError {
    shard_error(path, format!("page (lod {}, x {}, y {}) is missing", id.lod, id.x, id.y))
}

/// Opens every shard (named `paths`, read from `files`), checks that they belong together,
/// and returns them by index.
fn open_all(paths: &[PathBuf], files: &[PathBuf]) -> Result<Vec<Shard>> {
    if paths.is_empty() {
        return Err(TilerError::Options("no shards given: merge SHARD... -o PACK".into()));
    }
    let mut shards = Vec::with_capacity(paths.len());
    for (path, file) in paths.iter().zip(files) {
        // `open` checks the header's, the metadata's and the index's checksums: a damaged entry
        // can still read as a valid one (a page's kind turned to constant has no payload CRC to
        // fail), so none is used that the index's checksum does not vouch for.
        let pack = match path == file {
            true => Pack::open(path)?,
            false => Pack::open_named(file, path)?,
        };
        let manifest = Manifest::parse(path, pack.metadata())?;
        shards.push(Shard { path: path.clone(), pack, manifest });
    }
    let first = &shards[0];
    let (m0, count) = (&first.manifest, first.manifest.count);
    for s in &shards[1..] {
        let m = &s.manifest;
        if m.count != count {
            return Err(shard_error(
                &s.path,
                format!(
                    "is shard {} of {}, but {} is shard {} of {count}: they are not parts of one split",
                    m.index,
                    m.count,
                    first.path.shown(),
                    m0.index
                ),
            ));
        }
        if !m.source.same_input(&m0.source) {
            let id = |m: &Manifest| {
                format!(
                    "{} ({}x{}, fingerprint {})",
                    m.source.name, m.source.width, m.source.height, m.source.fingerprint
                )
            };
            return Err(shard_error(
                &s.path,
                format!(
                    "was cut from {}, but {} from {}: every shard must come from the same input",
                    id(m),
                    first.path.shown(),
                    id(m0)
                ),
            ));
        }
        if m.options != m0.options {
            return Err(shard_error(
                &s.path,
                format!(
                    "was made with other options than {}: {}",
                    first.path.shown(),
                    differences(&m.options, &m0.options)
                ),
            ));
        }
    }
    for s in &shards {
        let i = s.manifest.index;
        if i >= count {
            return Err(shard_error(&s.path, format!("says it is shard {i} of {count}")));
        }
    }
    // The count is the manifest's word: fewer shards than it says are missing some, and the
    // table of shards by index is sized only once it is known to be no longer than the list
    // of files given.
    if count as usize > shards.len() {
        let mut given: Vec<u32> = shards.iter().map(|s| s.manifest.index).collect();
        given.sort_unstable();
        given.dedup();
        return Err(missing_shards(count, &given, paths));
    }
    let mut by_index: Vec<Option<Shard>> = (0..count).map(|_| None).collect();
    for s in shards {
        let i = s.manifest.index;
        if let Some(other) = &by_index[i as usize] {
            let message = match other.path == s.path {
                true => "is given twice: give each shard once".to_string(),
                false => format!("is shard {i} of {count}, and so is {}: give each shard once", other.path.shown()),
            };
            return Err(shard_error(&s.path, message));
        }
        by_index[i as usize] = Some(s);
    }
    if by_index.iter().any(Option::is_none) {
        let given: Vec<u32> = (0..count).filter(|&i| by_index[i as usize].is_some()).collect();
        return Err(missing_shards(count, &given, paths));
    }
    Ok(by_index.into_iter().flatten().collect())
}

/// The most missing indices an error lists: the count comes from a file and may be billions.
const LISTED: usize = 8;

/// The error for shards missing from `given` (sorted indices below `count`, each once): the
/// first few indices, how many more, and the first few files given.
fn missing_shards(count: u32, given: &[u32], paths: &[PathBuf]) -> TilerError {
    // Walks the gaps between the given indices, so as to list a few of billions without
    // counting through them.
    let mut absent = Vec::new();
    let mut next = 0u64;
    for i in given.iter().chain([&count]).map(|&i| i as u64) {
        absent.extend((next..i).take(LISTED - absent.len()).map(|i| i.to_string()));
        next = i + 1;
    }
    let total = count as u64 - given.len() as u64;
    if total > absent.len() as u64 {
        absent.push(format!("and {} more", total - absent.len() as u64));
    }
    let files: Vec<String> = paths.iter().take(4).map(|p| p.shown().to_string()).collect();
    let more = if paths.len() > 4 { format!(" and {} more", paths.len() - 4) } else { String::new() };
    TilerError::Options(format!(
        "shard{} {} of {count} missing from those given ({}{more}); `split --shard I/{count}` makes shard I",
        if total == 1 { "" } else { "s" },
        absent.join(", "),
        files.join(", ")
    ))
}

/// The options two shards disagree on, as `member: ours against theirs`.
fn differences(a: &super::manifest::ShardOptions, b: &super::manifest::ShardOptions) -> String {
    let mut out = Vec::new();
    let (ia, ib): (serde_json::Value, serde_json::Value) =
        (serde_json::from_str(&a.info).unwrap_or_default(), serde_json::from_str(&b.info).unwrap_or_default());
    if let (Some(ia), Some(ib)) = (ia.as_object(), ib.as_object()) {
        for key in ia.keys().chain(ib.keys().filter(|k| !ia.contains_key(*k))) {
            if ia.get(key) != ib.get(key) {
                let show = |v: Option<&serde_json::Value>| v.map_or("none".to_string(), |v| v.to_string());
                out.push(format!("{key} {} against {}", show(ia.get(key)), show(ib.get(key))));
            }
        }
    }
    for (name, x, y) in [
        ("flatten", a.flatten as u64, b.flatten as u64),
        ("max-memory", a.max_memory, b.max_memory),
        ("align", a.alignment as u64, b.alignment as u64),
        ("tile-align", a.payload_alignment as u64, b.payload_alignment as u64),
        ("sum bytes", a.sum_bytes as u64, b.sum_bytes as u64),
    ] {
        if x != y {
            out.push(format!("{name} {x} against {y}"));
        }
    }
    out.join(", ")
}

/// The split options, page grid and stored texels the shards were made with, read back from
/// the metadata they carry for the merged pack.
fn read_options(
    shard: &Shard,
    pixels: crate::pixel::PixelLayout,
) -> Result<(SplitOptions, Layout, crate::pixel::PixelLayout)> {
    let o = &shard.manifest.options;
    let info: InfoFile = serde_json::from_str(&o.info)
        .map_err(|e| shard_error(&shard.path, format!("the pack metadata it carries is damaged: {e}")))?;
    let requested = Requested { flatten: o.flatten, max_memory: Some(o.max_memory), ..Requested::default() };
    let (opts, names) = settings::resolve(&requested, Some((&shard.path, &info)), pixels)?;
    let layout = opts.layout(shard.manifest.source.width, shard.manifest.source.height)?;
    let stored = opts.codec.stored_layout(pixels, opts.flatten, opts.tile_depth)?;
    if settings::describe(&layout, stored, &opts, &names).to_json_pretty() != o.info {
        return Err(shard_error(
            &shard.path,
            "its options do not read back as they were written (made by another version?)".into(),
        ));
    }
    check_written(shard, &opts, pixels, &layout)?;
    Ok((opts, layout, stored))
}

/// The manifest's numbers that are not tiling options must be what `split --shard` writes
/// for those options: the width of a stored sum sizes how the sums are read, and the
/// alignments how the merged pack is padded.
fn check_written(shard: &Shard, opts: &SplitOptions, pixels: PixelLayout, layout: &Layout) -> Result<()> {
    let o = &shard.manifest.options;
    let field = |name: &str, value: u32, wanted: String| {
        shard_error(
            &shard.path,
            format!("its options.{name} is {value}, where a shard holds {wanted}: the shard is damaged or forged"),
        )
    };
    let sum_bytes = crate::split::sum_bytes(opts, pixels, layout) as u32;
    if o.sum_bytes != sum_bytes {
        let wanted = format!("{sum_bytes} for its filter and pyramid depth");
        return Err(field("sumBytes", o.sum_bytes, wanted));
    }
    for (name, value, most) in
        [("alignment", o.alignment, MAX_ALIGN), ("payloadAlignment", o.payload_alignment, MAX_TILE_ALIGN)]
    {
        if !value.is_power_of_two() || !(8..=most).contains(&value) {
            return Err(field(name, value, format!("a power of two from 8 to {}", human_bytes(most.into()))));
        }
    }
    Ok(())
}

/// A page made above the cut.
enum Made {
    Encoded(Vec<u8>),
    Constant(Vec<u8>),
}

impl Made {
    fn as_new(&self, kind: vortex_pack::TileKind) -> NewTile<'_> {
        match self {
            Made::Encoded(bytes) => NewTile::Data(kind, bytes),
            Made::Constant(texel) => NewTile::Constant(texel),
        }
    }
}

/// A sink that keeps the pages above the cut in memory until they are stored in order.
#[derive(Default)]
struct Collected {
    tiles: Mutex<HashMap<TileId, Made>>,
}

impl Collected {
    fn put(&self, lod: u32, x: u32, y: u32, tile: Made) -> Result<()> {
        let mut tiles = self.tiles.lock().map_err(|_| TilerError::panicked("an encoder"))?;
        tiles.insert(TileId { lod, x, y }, tile);
        Ok(())
    }
}

impl TileSink for Collected {
    fn write_tile(&self, lod: u32, x: u32, y: u32, bytes: &[u8]) -> Result<()> {
        self.put(lod, x, y, Made::Encoded(bytes.to_vec()))
    }
    fn takes_constants(&self) -> bool {
        true
    }
    fn write_constant(&self, lod: u32, x: u32, y: u32, texel: &[u8]) -> Result<()> {
        self.put(lod, x, y, Made::Constant(texel.to_vec()))
    }
    fn bytes_written(&self) -> u64 {
        0
    }
}
