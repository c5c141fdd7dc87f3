//! [`DirSink`]: one file per tile plus a manifest (our `info.json`, or a viewer layout's
//! `.dzi`, IIIF `info.json` or TileJSON), the manifest last. The files go through
//! [`crate::store::Files`]: into a staging directory beside a local destination, renamed into
//! place only when everything is written, so an interrupted run never leaves a directory that
//! looks like a finished pyramid; or as objects under an `s3://` prefix, removed if the run
//! fails (docs/object-storage.md).

use std::collections::{HashMap, HashSet};
use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};

use vortex_pack::TileId;

use super::TileSink;
use crate::error::{Result, ShowPath, TilerError};
use crate::formats::tiles::filename::FilenameFormat;
use crate::formats::tiles::info::Info;
use crate::formats::viewer::{Crop, Viewer, ViewerTiles};
use crate::layout::Layout;
use crate::output::{Claim, Product};
use crate::resume::{self, Identity, Interrupted, Journal, Record};
use crate::store::local::StagingDir;
use crate::store::{Files, ObjectUrl, UPLOAD_BYTES, files_for};

/// One image file per tile plus a manifest. Dropped unfinished (a failed run, a later
/// output of the same run that failed), it removes what it wrote, unless it is a resumable
/// run's (`--resume`), whose staged tiles stay for the next `--resume`.
pub struct DirSink {
    dest: PathBuf,
    files: Box<dyn Files>,
    names: Names,
    bytes: AtomicU64,
    /// A resumable run's journal (none at an `s3://` prefix, where the bucket is the record)
    /// and the tiles kept from the run it resumes, with their files' lengths.
    resume: Option<(Option<Journal>, HashMap<TileId, u64>)>,
}

/// Where a resumable directory run (`--resume`) records its tiles, and what it finds of an
/// interrupted run of it.
pub(crate) enum ResumeFrom {
    /// A local destination: the journal, and the interrupted run it took over, if any.
    Journal(Journal, Option<Interrupted>),
    /// An `s3://` prefix: the bucket is the record. The run's identity (the prefix's marker
    /// names it while the run writes), the objects an interrupted run of it left under the
    /// prefix (`None`: nothing to resume), and the output's grid.
    Bucket { run: Identity, listed: Option<HashMap<String, u64>>, layout: Layout, in_flight: u64 },
}

/// How tiles are named.
enum Names {
    /// Our tile directory: `info.json`'s `filenameFormat`.
    Pattern(FilenameFormat),
    /// A viewer layout, which also crops each page to the viewer's tile.
    Viewer(ViewerTiles),
}

impl DirSink {
    /// Prepares to write a tile directory into the destination `claim` checked (see
    /// [`crate::output::claim`]): absent, empty, or a previous output of ours, which `finish`
    /// replaces. An `s3://` destination ([`crate::store`]) has up to 32 MiB of uploads in flight.
    pub fn create(claim: &Claim, names: FilenameFormat) -> Result<DirSink> {
        Self::start(claim, Product::TileDir, Names::Pattern(names), UPLOAD_BYTES)
    }

    /// Prepares to write `tiles`' viewer layout into the destination `claim` checked.
    pub fn for_viewer(claim: &Claim, tiles: ViewerTiles) -> Result<DirSink> {
        Self::start(claim, Product::Viewer(tiles.viewer), Names::Viewer(tiles), UPLOAD_BYTES)
    }

    /// [`create`](Self::create) with at most `in_flight` bytes of uploads at once to an
    /// `s3://` prefix.
    pub(crate) fn create_uploading(claim: &Claim, names: FilenameFormat, in_flight: u64) -> Result<DirSink> {
        Self::start(claim, Product::TileDir, Names::Pattern(names), in_flight)
    }

    /// [`for_viewer`](Self::for_viewer) with at most `in_flight` bytes of uploads at once.
    pub(crate) fn for_viewer_uploading(claim: &Claim, tiles: ViewerTiles, in_flight: u64) -> Result<DirSink> {
        Self::start(claim, Product::Viewer(tiles.viewer), Names::Viewer(tiles), in_flight)
    }

    fn start(claim: &Claim, product: Product, names: Names, in_flight: u64) -> Result<DirSink> {
        if claim.product != product {
            return Err(TilerError::Options(format!(
                "{} was claimed for {}",
                claim.path.shown(),
                claim.product.noun()
            )));
        }
        let files = files_for(claim, in_flight)?;
        Ok(DirSink { dest: claim.path.clone(), files, names, bytes: AtomicU64::new(0), resume: None })
    }

    /// [`create`](Self::create) for a resumable run (`--resume`): every tile written is
    /// recorded, and the tiles an interrupted run left whole are kept. At a local destination
    /// the journal records them, and the interrupted run's staged tiles (taken over by
    /// [`Journal::start`]) are checked against its journal; at an `s3://` prefix the bucket is
    /// the record: a tile is kept where an object of its size is listed under each of its names
    /// (a PUT is whole or absent). What the run wrote stays when the sink is dropped unfinished.
    pub(crate) fn create_resuming(claim: &Claim, names: FilenameFormat, from: ResumeFrom) -> Result<DirSink> {
        Self::resuming(claim, Product::TileDir, Names::Pattern(names), from)
    }

    /// [`for_viewer`](Self::for_viewer) for a resumable run, as [`create_resuming`](Self::create_resuming).
    pub(crate) fn for_viewer_resuming(claim: &Claim, tiles: ViewerTiles, from: ResumeFrom) -> Result<DirSink> {
        Self::resuming(claim, Product::Viewer(tiles.viewer), Names::Viewer(tiles), from)
    }

    fn resuming(claim: &Claim, product: Product, names: Names, from: ResumeFrom) -> Result<DirSink> {
        let in_bucket = ObjectUrl::of_path(&claim.path).is_some();
        if claim.product != product || in_bucket != matches!(from, ResumeFrom::Bucket { .. }) {
            return Err(TilerError::Internal(format!(
                "{} cannot be resumed as {}",
                claim.path.shown(),
                product.noun()
            )));
        }
        let mut kept = HashMap::new();
        let (files, journal): (Box<dyn Files>, _) = match from {
            ResumeFrom::Journal(journal, previous) => {
                if let Some(previous) = previous {
                    // What is not recorded (written as the run was killed) or not whole goes.
                    let names_of = |id: TileId| names.of(id);
                    let whole = resume::check_files(&previous.staging, &previous.records, &names_of);
                    let keep: HashSet<String> = whole.iter().flat_map(|r| names_of(r.id())).collect();
                    resume::prune(&previous.staging, &keep)?;
                    journal.keep(&whole)?;
                    for r in &whole {
                        if let Record::File { id, len, .. } = r {
                            kept.insert(*id, *len);
                        }
                    }
                }
                (Box::new(StagingDir::resumable(&claim.path)?), Some(journal))
            }
            ResumeFrom::Bucket { run, listed, layout, in_flight } => {
                let mut stale = Vec::new();
                if let Some(listed) = &listed {
                    kept = names.whole(&layout, listed);
                    // Objects that are no kept tile's (a manifest, a tile missing a name) go.
                    let keep: HashSet<String> = kept.keys().flat_map(|id| names.of(*id)).collect();
                    stale = listed.keys().filter(|n| !keep.contains(*n)).cloned().collect();
                }
                (crate::store::resuming_prefix(claim, in_flight, run, listed.is_none(), &stale)?, None)
            }
        };
        // Every kept tile is part of the output: its bytes count as written.
        let bytes = AtomicU64::new(kept.iter().map(|(id, len)| len * names.of(*id).len() as u64).sum());
        Ok(DirSink { dest: claim.path.clone(), files, names, bytes, resume: Some((journal, kept)) })
    }

    /// Bytes of the tile files this run wrote: those kept from an interrupted run
    /// (`--resume`) are not counted.
    pub(crate) fn bytes_sent(&self) -> u64 {
        let kept = self
            .resume
            .as_ref()
            .map_or(0, |(_, kept)| kept.iter().map(|(id, len)| len * self.names.of(*id).len() as u64).sum());
        self.bytes_written() - kept
    }

    /// Writes `info.json` last, then moves the staging directory into place. A previous output
    /// at the destination is moved aside first and deleted only after the new one is in place.
    pub fn finish(self, info: &Info) -> Result<()> {
        self.complete(vec![("info.json".to_string(), info.to_json_pretty().into_bytes())])
    }

    /// [`finish`](Self::finish) for a viewer layout: its manifest (`.dzi`, IIIF `info.json`,
    /// TileJSON) last.
    pub fn finish_viewer(self) -> Result<()> {
        let manifests = match &self.names {
            Names::Viewer(tiles) => {
                // A IIIF service's whole-image files, made from the tiles just written.
                let read = |name: &str| self.files.read(name).map_err(|e| format!("{name}: {e}"));
                match tiles.whole_images(read) {
                    Ok(mut files) => {
                        files.extend(tiles.manifests());
                        files
                    }
                    Err(message) => {
                        let message = format!("the IIIF whole image: {message}");
                        return Err(TilerError::Decode { path: self.dest.clone(), message });
                    }
                }
            }
            Names::Pattern(_) => {
                return Err(TilerError::Internal("a tile directory is finished with its info.json".into()));
            }
        };
        self.complete(manifests)
    }

    fn complete(mut self, manifests: Vec<(String, Vec<u8>)>) -> Result<()> {
        self.files.publish(manifests)?;
        match self.resume.take() {
            Some((Some(journal), _)) => journal.finish(),
            _ => Ok(()),
        }
    }
}

impl TileSink for DirSink {
    fn write_tile(&self, lod: u32, x: u32, y: u32, bytes: &[u8]) -> Result<()> {
        let id = TileId { lod, x, y };
        if let Some((journal, kept)) = &self.resume {
            if kept.contains_key(&id) {
                return Ok(());
            }
            self.write_names(lod, x, y, bytes)?;
            return journal.as_ref().map_or(Ok(()), |j| j.record(Record::file(id, bytes)));
        }
        self.write_names(lod, x, y, bytes)
    }

    fn kept(&self, lod: u32, x: u32, y: u32) -> bool {
        self.resume.as_ref().is_some_and(|(_, kept)| kept.contains_key(&TileId { lod, x, y }))
    }

    fn crop(&self, lod: u32, x: u32, y: u32) -> Option<Crop> {
        match &self.names {
            Names::Pattern(_) => None,
            Names::Viewer(tiles) => Some(tiles.crop(lod, x, y)),
        }
    }

    fn bytes_written(&self) -> u64 {
        self.bytes.load(Ordering::Relaxed)
    }
}

impl Names {
    /// The tiles of `layout` whose every file is among `listed` (names and sizes), all of one
    /// size: their ids and that size.
    fn whole(&self, layout: &Layout, listed: &HashMap<String, u64>) -> HashMap<TileId, u64> {
        let mut whole = HashMap::new();
        for lod in 0..layout.lod_count {
            let (columns, rows) = layout.grid(lod);
            for (x, y) in (0..rows).flat_map(|y| (0..columns).map(move |x| (x, y))) {
                let id = TileId { lod, x, y };
                let sizes: Option<Vec<u64>> = self.of(id).iter().map(|n| listed.get(n).copied()).collect();
                if let Some([first, rest @ ..]) = sizes.as_deref()
                    && rest.iter().all(|s| s == first)
                {
                    whole.insert(id, *first);
                }
            }
        }
        whole
    }

    /// The files that hold tile `id`.
    fn of(&self, id: TileId) -> Vec<String> {
        match self {
            Names::Pattern(names) => vec![names.format(&[id.lod, id.x, id.y])],
            Names::Viewer(tiles) => {
                let placed = tiles.place(id.lod, id.x, id.y);
                std::iter::once(placed.path).chain(placed.alias).collect()
            }
        }
    }
}

impl DirSink {
    /// Writes tile `(lod, x, y)`'s file, under each name its layout gives it.
    fn write_names(&self, lod: u32, x: u32, y: u32, bytes: &[u8]) -> Result<()> {
        let taken = |name: &str, why: String| {
            TilerError::Options(format!("tile (lod {lod}, x {x}, y {y}) would overwrite {name}: {why}"))
        };
        match &self.names {
            Names::Pattern(names) => {
                let name = names.format(&[lod, x, y]);
                match self.write_file(&name, bytes)? {
                    true => Ok(()),
                    false => Err(taken(
                        &name,
                        format!(
                            "the filename format '{}' gives two tiles one name; pad the numbers or separate them",
                            names.as_str()
                        ),
                    )),
                }
            }
            Names::Viewer(tiles) => {
                let placed = tiles.place(lod, x, y);
                for name in std::iter::once(&placed.path).chain(&placed.alias) {
                    // IIIF names a tile by its region and size: a sliver at the image's edge
                    // (say 1 x 1 texels) can have the same region and size at two scale
                    // factors, and so the same texels; it is written once.
                    if !self.write_file(name, bytes)? && tiles.viewer != Viewer::Iiif {
                        return Err(taken(name, format!("two tiles of the {} layout have one name", tiles.viewer)));
                    }
                }
                Ok(())
            }
        }
    }

    /// Writes one tile file at `name`, never over another: `false` if the name is taken.
    fn write_file(&self, name: &str, bytes: &[u8]) -> Result<bool> {
        let written = self.files.put_new(name, bytes)?;
        if written {
            self.bytes.fetch_add(bytes.len() as u64, Ordering::Relaxed);
        }
        Ok(written)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A tile is whole where its objects are listed; a listing's other names are no tile's.
    #[test]
    fn tiles_whole_in_a_listing_are_those_all_of_whose_objects_are_listed() {
        // 3 x 2 pages, then 2 x 1, then 1.
        let layout = Layout::new(300, 200, 128, 0).unwrap();
        assert_eq!(layout.lod_count, 3);
        let names = Names::Pattern(FilenameFormat::parse("%d/%d_%d.png", 3).unwrap());
        let listed: HashMap<String, u64> =
            [("0/0_0.png", 10), ("0/2_1.png", 7), ("2/0_0.png", 3), ("info.json", 99), ("0/9_9.png", 1)]
                .into_iter()
                .map(|(n, s)| (n.to_string(), s))
                .collect();
        let whole = names.whole(&layout, &listed);
        let id = |lod, x, y| TileId { lod, x, y };
        let expected: HashMap<TileId, u64> = [(id(0, 0, 0), 10), (id(0, 2, 1), 7), (id(2, 0, 0), 3)].into();
        assert_eq!(whole, expected);
    }
}
