//! A directory of tiles named by a positional printf-like pattern whose first argument is the
//! column and second the row (`x%02s-y%02s.png`), as the thesis's `--tiled --filename-format`.
//! The grid comes from the names (or the image size from an `info.json` beside them, if it has
//! `width` and `height`); tile size and pixel layout from the tiles themselves.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use crate::error::{Result, ShowPath, TilerError};
use crate::formats::tiles::filename::FilenameFormat;
use crate::formats::tiles::info::InfoFile;
use crate::source::ImageHeader;
use crate::source::tiled::store::MAX_TILE_BYTES;
use crate::source::tiled::{CellData, TileGrid, probe, read_file, tile_file_cap};

/// A directory of tiles named by a pattern with a column and a row (`%1$` x, `%2$` y), the
/// thesis's named tiles, as one image for `convert`; the image's size comes from the tiles.
pub struct NamedDir {
    dir: PathBuf,
    names: FilenameFormat,
    cells: HashMap<(u32, u32), PathBuf>,
    header: ImageHeader,
    cell: (u32, u32),
    /// The size came from the tiles, so edge tiles must be exactly the remainder.
    exact: bool,
}

impl NamedDir {
    #[expect(clippy::expect_used, reason = "the files were listed under dir and checked to be non-empty above")]
    /// Lists the files of `dir` that `pattern` names and probes the tiles' size and layout.
    pub fn open(dir: &Path, pattern: &str) -> Result<NamedDir> {
        let names =
            FilenameFormat::parse(pattern, 2).map_err(|m| TilerError::Options(format!("--filename-format: {m}")))?;
        let mut cells: HashMap<(u32, u32), PathBuf> = HashMap::new();
        let mut files: Vec<PathBuf> = Vec::new();
        collect_files(dir, &mut files)?;
        files.sort();
        for path in files {
            let rel = path.strip_prefix(dir).expect("under dir").to_string_lossy().replace('\\', "/");
            if rel == "info.json" || rel.split('/').any(|part| part.starts_with('.')) {
                continue;
            }
            let Some(xy) = names.match_name(&rel) else {
                return Err(TilerError::decode(&path, format!("does not match the filename format '{pattern}'")));
            };
            if let Some(other) = cells.insert((xy[0], xy[1]), path.clone()) {
                return Err(TilerError::decode(
                    &path,
                    format!("has the same coordinates (x {}, y {}) as {}", xy[0], xy[1], other.shown()),
                ));
            }
        }
        let cols = cells
            .keys()
            .map(|k| k.0 + 1)
            .max()
            .ok_or_else(|| TilerError::decode(dir, format!("holds no tiles named like '{pattern}'")))?;
        let rows = cells.keys().map(|k| k.1 + 1).max().expect("not empty");
        // The first tile in reading order sets the size and layout; edge tiles may be smaller.
        let first = cells.iter().min_by_key(|((x, y), _)| (*y, *x)).map(|(_, p)| p.clone()).expect("not empty");
        let (tw, th, layout) = probe(&first, MAX_TILE_BYTES)?;
        let edge = |key: (u32, u32), full: (u32, u32)| -> Result<(u32, u32)> {
            match cells.get(&key) {
                Some(p) => probe(p, tile_file_cap(tw, th, layout)).map(|(w, h, _)| (w, h)),
                None => Ok(full),
            }
        };
        let (last_w, _) = edge((cols - 1, 0), (tw, th))?;
        let (_, last_h) = edge((0, rows - 1), (tw, th))?;
        let mut width = (cols - 1) as u64 * tw as u64 + last_w.min(tw) as u64;
        let mut height = (rows - 1) as u64 * th as u64 + last_h.min(th) as u64;
        // An info.json beside the tiles gives the image size (tiles beyond it are ignored).
        let info_path = dir.join("info.json");
        let mut exact = true;
        if info_path.is_file() {
            let info = InfoFile::read(&info_path)?;
            if let (Some(w), Some(h)) = (info.width, info.height) {
                (width, height, exact) = (w as u64, h as u64, false);
            }
        }
        let too_big = || TilerError::Geometry(format!("{cols}x{rows} tiles of {tw}x{th} make an image too large"));
        let header = ImageHeader {
            width: u32::try_from(width).map_err(|_| too_big())?,
            height: u32::try_from(height).map_err(|_| too_big())?,
            layout,
        };
        Ok(NamedDir { dir: dir.to_path_buf(), names, cells, header, cell: (tw, th), exact })
    }
}

fn collect_files(dir: &Path, out: &mut Vec<PathBuf>) -> Result<()> {
    for entry in std::fs::read_dir(dir).map_err(|e| TilerError::io(dir, e))? {
        let path = entry.map_err(|e| TilerError::io(dir, e))?.path();
        if path.is_dir() {
            collect_files(&path, out)?;
        } else {
            out.push(path);
        }
    }
    Ok(())
}

impl TileGrid for NamedDir {
    fn describe(&self) -> String {
        let (c, r) = (self.header.width.div_ceil(self.cell.0), self.header.height.div_ceil(self.cell.1));
        format!(
            "{c}x{r} tiles of {}x{} named '{}' in {}",
            self.cell.0,
            self.cell.1,
            self.names.as_str(),
            self.dir.shown()
        )
    }
    fn header(&self) -> ImageHeader {
        self.header
    }
    fn cell(&self) -> (u32, u32) {
        self.cell
    }
    fn read(&self, col: u32, row: u32, cap: u64) -> Result<Option<CellData>> {
        match self.cells.get(&(col, row)) {
            Some(path) => read_file(path, cap),
            None => Ok(None),
        }
    }
    fn crop(&self, _: u32, _: u32) -> (u32, u32) {
        (0, 0)
    }
    /// Full tiles, smaller only in the last column and row (unless info.json set the size).
    fn stored_size(&self, col: u32, row: u32) -> Option<(u32, u32)> {
        let (w, h) = (self.header.width, self.header.height);
        self.exact.then(|| (self.cell.0.min(w - col * self.cell.0), self.cell.1.min(h - row * self.cell.1)))
    }
}
