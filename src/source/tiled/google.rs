//! A Google/XYZ ("slippy map") tile directory laid out `z/y/x.<ext>`: one directory per zoom
//! level, in it one directory per tile row, in that one file per tile. The highest zoom level
//! is the image: the bounding box of its tiles, cell (c, r) being tile `(xmin + c, ymin + r)`.
//! Tiles missing inside the box are missing cells; coarser levels are ignored.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use super::{CellData, TileGrid, probe, read_file};
use crate::error::{Result, TilerError};
use crate::source::ImageHeader;

pub struct Xyz {
    dir: PathBuf,
    zoom: u32,
    /// Tile coordinates of cell (0, 0).
    origin: (u32, u32),
    /// Tile (x, y) -> its file.
    tiles: HashMap<(u32, u32), PathBuf>,
    header: ImageHeader,
    cell: (u32, u32),
}

impl Xyz {
    /// Lists the highest zoom level under `dir` and reads its first tile (size and layout).
    #[expect(clippy::expect_used, reason = "the tile map was checked to be non-empty above")]
    pub fn open(dir: &Path) -> Result<Xyz> {
        let (zoom, zoom_dir) = highest_zoom(dir)?;
        let mut tiles: HashMap<(u32, u32), PathBuf> = HashMap::new();
        for (y, row_dir) in numbered_entries(&zoom_dir)? {
            if !row_dir.is_dir() {
                return Err(TilerError::decode(
                    &row_dir,
                    "is not a directory: a zoom directory of XYZ tiles (z/y/x.ext) holds only row directories named by their y",
                ));
            }
            let Some(y) = y else {
                return Err(TilerError::decode(
                    &row_dir,
                    "is not named by a row number, as XYZ tile directories are (z/y/x.ext)",
                ));
            };
            for path in visible_entries(&row_dir)? {
                let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
                let x = name
                    .split_once('.')
                    .filter(|(_, ext)| !ext.is_empty())
                    .and_then(|(x, _)| number(x))
                    .filter(|_| path.is_file())
                    .ok_or_else(|| {
                        TilerError::decode(&path, "is not a tile named <x>.<ext>, as XYZ tiles are (z/y/x.ext)")
                    })?;
                if let Some(other) = tiles.insert((x, y), path.clone()) {
                    return Err(TilerError::decode(
                        &path,
                        format!("is the same tile (z {zoom}, y {y}, x {x}) as {}", other.display()),
                    ));
                }
            }
        }
        let Some(xmin) = tiles.keys().map(|k| k.0).min() else {
            return Err(TilerError::decode(&zoom_dir, "holds no tiles (z/y/x.ext)"));
        };
        let xmax = tiles.keys().map(|k| k.0).max().expect("not empty");
        let ymin = tiles.keys().map(|k| k.1).min().expect("not empty");
        let ymax = tiles.keys().map(|k| k.1).max().expect("not empty");
        let first = tiles.iter().min_by_key(|((x, y), _)| (*y, *x)).map(|(_, p)| p.clone()).expect("not empty");
        let (tw, th, layout) = probe(&first)?;
        // In u64: tiles at x 0 and 2^32 - 1 span 2^32 columns, which wraps a u32 to zero.
        let (cols, rows) = (xmax as u64 - xmin as u64 + 1, ymax as u64 - ymin as u64 + 1);
        let too_big = || {
            TilerError::Geometry(format!(
                "{cols}x{rows} tiles of {tw}x{th} at zoom {zoom} of {} make an image too large",
                dir.display()
            ))
        };
        let header = ImageHeader {
            width: u32::try_from(cols * tw as u64).map_err(|_| too_big())?,
            height: u32::try_from(rows * th as u64).map_err(|_| too_big())?,
            layout,
        };
        Ok(Xyz { dir: dir.to_path_buf(), zoom, origin: (xmin, ymin), tiles, header, cell: (tw, th) })
    }

    /// The zoom level read (the highest).
    pub fn zoom(&self) -> u32 {
        self.zoom
    }

    /// Tile coordinates (x, y) of cell (0, 0): the top left of the tiles' bounding box.
    pub fn origin(&self) -> (u32, u32) {
        self.origin
    }
}

/// The highest-numbered zoom directory; other entries (metadata files, viewers) are ignored.
fn highest_zoom(dir: &Path) -> Result<(u32, PathBuf)> {
    let mut best: Option<(u32, PathBuf)> = None;
    for (z, path) in numbered_entries(dir)? {
        let Some(z) = z.filter(|_| path.is_dir()) else { continue };
        match &best {
            Some((bz, other)) if *bz == z => {
                return Err(TilerError::decode(&path, format!("is the same zoom level {z} as {}", other.display())));
            }
            Some((bz, _)) if *bz > z => {}
            _ => best = Some((z, path)),
        }
    }
    best.ok_or_else(|| TilerError::decode(dir, "holds no zoom directories named by a number (z/y/x.ext)"))
}

/// Entries not starting with '.', sorted, each with its name as a number if it is one.
fn numbered_entries(dir: &Path) -> Result<Vec<(Option<u32>, PathBuf)>> {
    Ok(visible_entries(dir)?
        .into_iter()
        .map(|path| (path.file_name().and_then(|n| n.to_str()).and_then(number), path))
        .collect())
}

/// Entries of `dir` whose names do not start with '.', sorted.
fn visible_entries(dir: &Path) -> Result<Vec<PathBuf>> {
    let mut out = Vec::new();
    for entry in std::fs::read_dir(dir).map_err(|e| TilerError::io(dir, e))? {
        let entry = entry.map_err(|e| TilerError::io(dir, e))?;
        if !entry.file_name().as_encoded_bytes().starts_with(b".") {
            out.push(entry.path());
        }
    }
    out.sort();
    Ok(out)
}

/// `s` as a tile coordinate: ASCII digits only, within u32.
fn number(s: &str) -> Option<u32> {
    if s.is_empty() || !s.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    s.parse().ok()
}

impl TileGrid for Xyz {
    fn describe(&self) -> String {
        let (cols, rows) = (self.header.width / self.cell.0, self.header.height / self.cell.1);
        let (x, y) = self.origin;
        format!(
            "zoom {} of the XYZ tiles in {} ({cols}x{rows} tiles of {}x{} from x {x}, y {y})",
            self.zoom,
            self.dir.display(),
            self.cell.0,
            self.cell.1
        )
    }
    fn header(&self) -> ImageHeader {
        self.header
    }
    fn cell(&self) -> (u32, u32) {
        self.cell
    }
    fn read(&self, col: u32, row: u32) -> Result<Option<CellData>> {
        match self.tiles.get(&(self.origin.0 + col, self.origin.1 + row)) {
            Some(path) => read_file(path),
            None => Ok(None),
        }
    }
    fn crop(&self, _: u32, _: u32) -> (u32, u32) {
        (0, 0)
    }
    /// Every tile has the first one's size.
    fn stored_size(&self, _: u32, _: u32) -> Option<(u32, u32)> {
        Some(self.cell)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::source::read_all;
    use crate::source::tiled::TiledSource;

    const TS: u32 = 8;

    /// A reproducible RGBA image.
    fn rgba_image(width: u32, height: u32, seed: u32) -> Vec<u8> {
        crate::source::tiled::noise((width * height * 4) as usize, seed)
    }

    /// Writes `image` (RGBA, `cols x rows` tiles of TS) as PNG tiles `z/y/x.png` from tile
    /// (x0, y0), leaving out the tiles in `skip` (cell coordinates).
    fn write_tiles(dir: &Path, z: u32, origin: (u32, u32), image: &[u8], cols: u32, rows: u32, skip: &[(u32, u32)]) {
        let width = cols * TS;
        for r in 0..rows {
            for c in 0..cols {
                if skip.contains(&(c, r)) {
                    continue;
                }
                let mut tile = Vec::new();
                for y in r * TS..(r + 1) * TS {
                    let row = (y * width) as usize * 4;
                    tile.extend_from_slice(&image[row + (c * TS) as usize * 4..][..TS as usize * 4]);
                }
                let row_dir = dir.join(format!("{z}/{}", origin.1 + r));
                std::fs::create_dir_all(&row_dir).unwrap();
                let path = row_dir.join(format!("{}.png", origin.0 + c));
                image::save_buffer(path, &tile, TS, TS, image::ExtendedColorType::Rgba8).unwrap();
            }
        }
    }

    fn read_image(dir: &Path, fill: Vec<u8>, strict: bool) -> Result<Vec<u8>> {
        let grid = Xyz::open(dir)?;
        let mut source = TiledSource::new(Box::new(grid), fill, strict);
        read_all(&mut source)
    }

    fn open_error(dir: &Path) -> String {
        Xyz::open(dir).err().expect("an error").to_string()
    }

    #[test]
    fn reads_back_the_highest_zoom_bit_exactly() {
        let tmp = tempfile::tempdir().unwrap();
        let (cols, rows) = (3, 2);
        let image = rgba_image(cols * TS, rows * TS, 5);
        write_tiles(tmp.path(), 11, (1021, 680), &image, cols, rows, &[]);
        // A coarser level (even an unreadable one), metadata and hidden files are ignored.
        std::fs::create_dir_all(tmp.path().join("9/170")).unwrap();
        std::fs::write(tmp.path().join("9/170/255.png"), b"not a png").unwrap();
        std::fs::write(tmp.path().join("metadata.json"), b"{}").unwrap();
        std::fs::write(tmp.path().join("11/.DS_Store"), b"").unwrap();
        std::fs::write(tmp.path().join("11/680/.hidden"), b"").unwrap();
        let grid = Xyz::open(tmp.path()).unwrap();
        assert_eq!((grid.zoom(), grid.origin(), grid.cell()), (11, (1021, 680), (TS, TS)));
        assert_eq!((grid.header().width, grid.header().height), (cols * TS, rows * TS));
        assert_eq!(grid.header().layout.to_string(), "rgba 8-bit");
        assert!(grid.describe().contains("zoom 11") && grid.describe().contains("3x2 tiles"), "{}", grid.describe());
        assert!(read_image(tmp.path(), vec![0; 4], true).unwrap() == image);
    }

    #[test]
    fn missing_tiles_in_the_box_are_filled_or_an_error_with_strict() {
        let tmp = tempfile::tempdir().unwrap();
        let (cols, rows) = (3, 3);
        let mut image = rgba_image(cols * TS, rows * TS, 9);
        // Cell (0, 0) is missing too, so the size and layout come from a later tile.
        let skip = [(1, 1), (0, 0)];
        write_tiles(tmp.path(), 4, (2, 5), &image, cols, rows, &skip);
        let fill = [1, 2, 3, 4];
        for (c, r) in skip {
            for y in r * TS..(r + 1) * TS {
                for x in c * TS..(c + 1) * TS {
                    image[((y * cols * TS + x) * 4) as usize..][..4].copy_from_slice(&fill);
                }
            }
        }
        assert_eq!(Xyz::open(tmp.path()).unwrap().origin(), (2, 5));
        assert!(read_image(tmp.path(), fill.to_vec(), false).unwrap() == image);
        let e = read_image(tmp.path(), fill.to_vec(), true).unwrap_err().to_string();
        assert!(e.contains("missing") && e.contains("x 0, y 0"), "{e}");
    }

    #[test]
    fn other_names_are_errors_naming_the_file() {
        let image = rgba_image(TS, TS, 1);
        let tile = "is not a tile named <x>.<ext>";
        let cases: [(&str, &str, &str); 6] = [
            ("3/4/tile.png", "3/4/tile.png", tile),
            ("3/4/5", "3/4/5", tile),
            ("3/4/5.", "3/4/5.", tile),
            ("3/4/-5.png", "3/4/-5.png", tile),
            ("3/4/99999999999.png", "3/4/99999999999.png", tile),
            ("3/row/5.png", "3/row", "is not named by a row number"),
        ];
        for (name, named, expected) in cases {
            let tmp = tempfile::tempdir().unwrap();
            write_tiles(tmp.path(), 3, (0, 0), &image, 1, 1, &[]);
            let path = tmp.path().join(name);
            std::fs::create_dir_all(path.parent().unwrap()).unwrap();
            std::fs::write(&path, b"").unwrap();
            let e = open_error(tmp.path());
            let named = tmp.path().join(named).display().to_string();
            assert!(e.starts_with(&format!("{named}: {expected}")), "{name}: {e}");
        }
        let tmp = tempfile::tempdir().unwrap();
        write_tiles(tmp.path(), 3, (0, 0), &image, 1, 1, &[]);
        std::fs::write(tmp.path().join("3/readme.txt"), b"").unwrap();
        let e = open_error(tmp.path());
        assert!(e.contains("3/readme.txt: is not a directory"), "{e}");
        std::fs::remove_file(tmp.path().join("3/readme.txt")).unwrap();
        std::fs::create_dir_all(tmp.path().join("3/0/7.png")).unwrap();
        let e = open_error(tmp.path());
        assert!(e.contains("3/0/7.png: is not a tile"), "{e}");
    }

    #[test]
    fn duplicate_coordinates_are_errors_naming_both() {
        let image = rgba_image(TS, TS, 1);
        for (a, b) in [("3/4/5.png", "3/4/05.png"), ("3/4/5.png", "3/4/5.jpg"), ("3/4/5.png", "3/04/5.png")] {
            let tmp = tempfile::tempdir().unwrap();
            write_tiles(tmp.path(), 3, (5, 4), &image, 1, 1, &[]);
            let (a, b) = (tmp.path().join(a), tmp.path().join(b));
            std::fs::create_dir_all(b.parent().unwrap()).unwrap();
            std::fs::copy(&a, &b).unwrap();
            let e = open_error(tmp.path());
            assert!(
                e.contains(&a.display().to_string()) && e.contains(&b.display().to_string()) && e.contains("same tile"),
                "{e}"
            );
        }
        let tmp = tempfile::tempdir().unwrap();
        write_tiles(tmp.path(), 3, (0, 0), &image, 1, 1, &[]);
        std::fs::create_dir_all(tmp.path().join("03/0")).unwrap();
        let e = open_error(tmp.path());
        assert!(e.contains("same zoom level 3"), "{e}");
    }

    #[test]
    fn empty_inputs_are_errors() {
        let tmp = tempfile::tempdir().unwrap();
        let e = open_error(tmp.path());
        assert!(e.contains("holds no zoom directories"), "{e}");
        std::fs::create_dir_all(tmp.path().join("2/1")).unwrap();
        let e = open_error(tmp.path());
        assert!(e.contains("/2: holds no tiles"), "{e}");
        let e = open_error(&tmp.path().join("nothing"));
        assert!(e.contains("nothing"), "{e}");
    }

    #[test]
    fn tiles_of_another_layout_or_size_are_errors() {
        let tmp = tempfile::tempdir().unwrap();
        write_tiles(tmp.path(), 1, (0, 0), &rgba_image(TS, TS, 1), 1, 1, &[]);
        let grey = tmp.path().join("1/0/1.png");
        image::save_buffer(&grey, &[7u8; (TS * TS) as usize], TS, TS, image::ExtendedColorType::L8).unwrap();
        let e = read_image(tmp.path(), vec![0; 4], false).unwrap_err().to_string();
        assert!(e.contains("1/0/1.png") && e.contains("luminance 8-bit"), "{e}");
        let big = rgba_image(2 * TS, TS, 2);
        image::save_buffer(&grey, &big, 2 * TS, TS, image::ExtendedColorType::Rgba8).unwrap();
        let e = read_image(tmp.path(), vec![0; 4], false).unwrap_err().to_string();
        assert!(e.contains("1/0/1.png") && e.contains("is 16x8"), "{e}");
    }
}
