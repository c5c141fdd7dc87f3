//! [`DirSink`]: one file per tile plus a manifest (our `info.json`, or a viewer layout's
//! `.dzi`, IIIF `info.json` or TileJSON), written into a staging directory beside the
//! destination and renamed into place only when everything is written, so an interrupted run
//! never leaves a directory that looks like a finished pyramid.

use std::collections::HashSet;
use std::fs;
use std::io::Write;
use std::path::PathBuf;
use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, Ordering};

use super::TileSink;
use crate::error::{Result, ShowPath, TilerError};
use crate::formats::tiles::filename::FilenameFormat;
use crate::formats::tiles::info::Info;
use crate::formats::viewer::{Crop, Viewer, ViewerTiles};
use crate::output::{Claim, Product, staging};

/// One image file per tile plus a manifest. Dropped unfinished (a failed run, a later
/// output of the same run that failed), it removes what it wrote.
pub struct DirSink {
    dest: PathBuf,
    staging: PathBuf,
    names: Names,
    made_dirs: Mutex<HashSet<PathBuf>>,
    bytes: AtomicU64,
    /// Set once the directory is in place: nothing to remove.
    finished: bool,
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
    /// replaces.
    pub fn create(claim: &Claim, names: FilenameFormat) -> Result<DirSink> {
        Self::start(claim, Product::TileDir, Names::Pattern(names))
    }

    /// Prepares to write `tiles`' viewer layout into the destination `claim` checked.
    pub fn for_viewer(claim: &Claim, tiles: ViewerTiles) -> Result<DirSink> {
        Self::start(claim, Product::Viewer(tiles.viewer), Names::Viewer(tiles))
    }

    fn start(claim: &Claim, product: Product, names: Names) -> Result<DirSink> {
        if claim.product != product {
            return Err(TilerError::Options(format!(
                "{} was claimed for {}",
                claim.path.shown(),
                claim.product.noun()
            )));
        }
        let dest = claim.path.as_path();
        let staging = staging::partial_path(dest);
        if staging.exists() {
            fs::remove_dir_all(&staging).map_err(|e| TilerError::write(&staging, e))?;
        }
        fs::create_dir_all(&staging).map_err(|e| {
            TilerError::write(dest, std::io::Error::new(e.kind(), format!("cannot create {}: {e}", staging.shown())))
        })?;
        Ok(DirSink {
            dest: dest.to_path_buf(),
            staging,
            names,
            made_dirs: Mutex::new(HashSet::new()),
            bytes: AtomicU64::new(0),
            finished: false,
        })
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
                let read = |name: &str| fs::read(self.staging.join(name)).map_err(|e| format!("{name}: {e}"));
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
        for (name, bytes) in manifests {
            let path = self.staging.join(name);
            // IIIF's whole-image files go into folders of their own (`full/max/0/`).
            let folder = path.parent().map_or(Ok(()), fs::create_dir_all);
            folder.and_then(|()| fs::write(&path, bytes)).map_err(|e| TilerError::write(&path, e))?;
        }
        staging::replace_dir(&self.staging, &self.dest).map_err(|e| TilerError::write(&self.dest, e))?;
        self.finished = true;
        Ok(())
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

/// An unfinished directory's staging goes with it.
impl Drop for DirSink {
    fn drop(&mut self) {
        if !self.finished {
            let _ = fs::remove_dir_all(&self.staging);
        }
    }
}

impl DirSink {
    /// Writes one tile file at `name` under the staging directory, never over another: `false`
    /// if the name is taken.
    fn write_file(&self, name: &str, bytes: &[u8]) -> Result<bool> {
        let path = self.staging.join(name);
        if let Some(dir) = path.parent().filter(|d| *d != self.staging) {
            let mut made = self.made_dirs.lock().unwrap_or_else(|p| p.into_inner());
            if !made.contains(dir) {
                fs::create_dir_all(dir).map_err(|e| TilerError::write(dir, e))?;
                made.insert(dir.to_path_buf());
            }
        }
        let mut file = match fs::File::create_new(&path) {
            Ok(file) => file,
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => return Ok(false),
            Err(e) => return Err(TilerError::write(&path, e)),
        };
        file.write_all(bytes).map_err(|e| TilerError::write(&path, e))?;
        self.bytes.fetch_add(bytes.len() as u64, Ordering::Relaxed);
        Ok(true)
    }
}
