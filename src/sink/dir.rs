//! [`DirSink`]: one file per tile plus a manifest (our `info.json`, or a viewer layout's
//! `.dzi`, IIIF `info.json` or TileJSON), the manifest last. The files go through
//! [`crate::store::Files`]: into a staging directory beside a local destination, renamed into
//! place only when everything is written, so an interrupted run never leaves a directory that
//! looks like a finished pyramid; or as objects under an `s3://` prefix, removed if the run
//! fails (docs/object-storage.md).

use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};

use super::TileSink;
use crate::error::{Result, ShowPath, TilerError};
use crate::formats::tiles::filename::FilenameFormat;
use crate::formats::tiles::info::Info;
use crate::formats::viewer::{Crop, Viewer, ViewerTiles};
use crate::output::{Claim, Product};
use crate::store::{Files, UPLOAD_BYTES, files_for};

/// One image file per tile plus a manifest. Dropped unfinished (a failed run, a later
/// output of the same run that failed), it removes what it wrote.
pub struct DirSink {
    dest: PathBuf,
    files: Box<dyn Files>,
    names: Names,
    bytes: AtomicU64,
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
        Ok(DirSink { dest: claim.path.clone(), files, names, bytes: AtomicU64::new(0) })
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
        self.files.publish(manifests)
    }
}

impl TileSink for DirSink {
    fn write_tile(&self, lod: u32, x: u32, y: u32, bytes: &[u8]) -> Result<()> {
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

impl DirSink {
    /// Writes one tile file at `name`, never over another: `false` if the name is taken.
    fn write_file(&self, name: &str, bytes: &[u8]) -> Result<bool> {
        let written = self.files.put_new(name, bytes)?;
        if written {
            self.bytes.fetch_add(bytes.len() as u64, Ordering::Relaxed);
        }
        Ok(written)
    }
}
