//! A Google/XYZ ("slippy map") tile directory: one directory per zoom level, in it one
//! directory per tile row and one file per tile (`z/y/x.<ext>`, [`Order::Zyx`], as `vips
//! dzsave --layout google` writes), or one directory per tile column and one file per tile
//! (`z/x/y.<ext>`, [`Order::Zxy`], as web maps number them). The highest zoom level is the
//! image: the bounding box of its tiles, cell (c, r) being tile `(xmin + c, ymin + r)`. Tiles
//! missing inside the box are missing cells; coarser levels are ignored.

use std::collections::HashMap;
use std::path::Path;

use crate::error::{Result, ShowPath, TilerError};
use crate::formats::viewer::xyz::Order;
use crate::source::ImageHeader;
use crate::source::tiled::store::{Entry, Kind, MAX_DESCRIPTOR_BYTES, TileStore, join};
use crate::source::tiled::{CellData, TileGrid, probe_stored};

/// Web-map tiles in `z/x/y` or `z/y/x` directories (in a directory or a zip), the finest
/// zoom read as an image for `convert`.
pub struct Xyz {
    store: TileStore,
    /// The directory holding the zoom directories, relative to the store.
    root: String,
    order: Order,
    zoom: u32,
    /// Tile coordinates of cell (0, 0).
    origin: (u32, u32),
    /// Tile (x, y) -> its file, relative to the store.
    tiles: HashMap<(u32, u32), String>,
    header: ImageHeader,
    cell: (u32, u32),
}

impl Xyz {
    /// Lists the highest zoom level under `dir` and reads its first tile (size and layout).
    pub fn open(dir: &Path, order: Order) -> Result<Xyz> {
        Xyz::open_in(TileStore::dir(dir), "", order)
    }

    /// As [`Xyz::open`], for the zoom directories in folder `root` of `store`.
    #[expect(clippy::expect_used, reason = "the tile map was checked to be non-empty above")]
    pub(crate) fn open_in(store: TileStore, root: &str, order: Order) -> Result<Xyz> {
        let pattern = order.pattern();
        let (outer_name, inner_name) = order.names();
        let (zoom, zoom_dir) = highest_zoom(&store, root, order)?;
        let mut tiles: HashMap<(u32, u32), String> = HashMap::new();
        for (outer, outer_entry) in numbered_entries(&store, &zoom_dir)? {
            let outer_dir = join(&zoom_dir, &outer_entry.name);
            if outer_entry.kind != Kind::Dir {
                return Err(TilerError::decode(
                    store.name(&outer_dir),
                    format!(
                        "is not a directory: a zoom directory of tiles laid out {pattern} holds only {outer_name} directories named by their number"
                    ),
                ));
            }
            let Some(outer) = outer else {
                return Err(TilerError::decode(
                    store.name(&outer_dir),
                    format!("is not named by a {outer_name} number, as tile directories laid out {pattern} are"),
                ));
            };
            for entry in visible_entries(&store, &outer_dir)? {
                let path = join(&outer_dir, &entry.name);
                let inner = entry
                    .name
                    .split_once('.')
                    .filter(|(_, ext)| !ext.is_empty())
                    .and_then(|(n, _)| number(n))
                    .filter(|_| entry.kind == Kind::File)
                    .ok_or_else(|| {
                        TilerError::decode(
                            store.name(&path),
                            format!("is not a tile named <{inner_name}>.<ext>, as tiles laid out {pattern} are"),
                        )
                    })?;
                let (x, y) = order.xy(outer, inner);
                if let Some(other) = tiles.insert((x, y), path.clone()) {
                    return Err(TilerError::decode(
                        store.name(&path),
                        format!("is the same tile (z {zoom}, x {x}, y {y}) as {}", store.name(&other).shown()),
                    ));
                }
            }
        }
        let Some(xmin) = tiles.keys().map(|k| k.0).min() else {
            return Err(TilerError::decode(store.name(&zoom_dir), format!("holds no tiles ({pattern})")));
        };
        let xmax = tiles.keys().map(|k| k.0).max().expect("not empty");
        let ymin = tiles.keys().map(|k| k.1).min().expect("not empty");
        let ymax = tiles.keys().map(|k| k.1).max().expect("not empty");
        let first = tiles.iter().min_by_key(|((x, y), _)| (*y, *x)).map(|(_, p)| p.clone()).expect("not empty");
        // The tile size is what the first tile says: its file is read whole only if its header
        // is not in its first MiB.
        let (tw, th, layout) = probe_stored(&store, &first, crate::source::tiled::store::MAX_TILE_BYTES)?;
        // In u64: tiles at x 0 and 2^32 - 1 span 2^32 columns, which wraps a u32 to zero.
        let (cols, rows) = (xmax as u64 - xmin as u64 + 1, ymax as u64 - ymin as u64 + 1);
        let too_big = || {
            TilerError::Geometry(format!(
                "{cols}x{rows} tiles of {tw}x{th} at zoom {zoom} of {} make an image too large",
                store.name(root).shown()
            ))
        };
        let mut header = ImageHeader {
            width: u32::try_from(cols * tw as u64).map_err(|_| too_big())?,
            height: u32::try_from(rows * th as u64).map_err(|_| too_big())?,
            layout,
        };
        // Our `--layout xyz|google` records the image's size: the padding past it is not read.
        if (xmin, ymin) == (0, 0)
            && let Some((width, height)) = recorded_size(&store, root, zoom)?
        {
            header.width = header.width.min(width);
            header.height = header.height.min(height);
        }
        Ok(Xyz { store, root: root.to_string(), order, zoom, origin: (xmin, ymin), tiles, header, cell: (tw, th) })
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

/// The image's size that `tilejson.json` records under `vortex` (written by `split --layout
/// xyz|google`), if it describes this zoom level as the finest.
fn recorded_size(store: &TileStore, root: &str, zoom: u32) -> Result<Option<(u32, u32)>> {
    let path = join(root, crate::formats::viewer::xyz::TILEJSON);
    let Some(bytes) = store.read(&path, MAX_DESCRIPTOR_BYTES)? else { return Ok(None) };
    let doc: serde_json::Value = serde_json::from_slice(&bytes)
        .map_err(|e| TilerError::decode(store.name(&path), format!("is not JSON: {e}")))?;
    let number = |v: &serde_json::Value| v.as_u64().and_then(|n| u32::try_from(n).ok()).filter(|n| *n > 0);
    let size = number(&doc["vortex"]["width"]).zip(number(&doc["vortex"]["height"]));
    Ok(size.filter(|_| doc["maxzoom"].as_u64() == Some(zoom as u64)))
}

/// The highest-numbered zoom directory; other entries (metadata files, viewers) are ignored.
fn highest_zoom(store: &TileStore, root: &str, order: Order) -> Result<(u32, String)> {
    let mut best: Option<(u32, String)> = None;
    for (z, entry) in numbered_entries(store, root)? {
        let Some(z) = z.filter(|_| entry.kind == Kind::Dir) else { continue };
        let path = join(root, &entry.name);
        match &best {
            Some((bz, other)) if *bz == z => {
                return Err(TilerError::decode(
                    store.name(&path),
                    format!("is the same zoom level {z} as {}", store.name(other).shown()),
                ));
            }
            Some((bz, _)) if *bz > z => {}
            _ => best = Some((z, path)),
        }
    }
    best.ok_or_else(|| {
        TilerError::decode(
            store.name(root),
            format!("holds no zoom directories named by a number ({})", order.pattern()),
        )
    })
}

/// Entries not starting with '.', sorted, each with its name as a number if it is one.
fn numbered_entries(store: &TileStore, dir: &str) -> Result<Vec<(Option<u32>, Entry)>> {
    Ok(visible_entries(store, dir)?.into_iter().map(|entry| (number(&entry.name), entry)).collect())
}

/// Entries of `dir` whose names do not start with '.', sorted.
fn visible_entries(store: &TileStore, dir: &str) -> Result<Vec<Entry>> {
    Ok(store.list(dir)?.into_iter().filter(|e| !e.name.starts_with('.')).collect())
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
        // The recorded size may end inside the last tile: it is a tile all the same.
        let (cols, rows) = (self.header.width.div_ceil(self.cell.0), self.header.height.div_ceil(self.cell.1));
        let (x, y) = self.origin;
        format!(
            "zoom {} of the {} tiles in {} ({cols}x{rows} tiles of {}x{} from x {x}, y {y})",
            self.zoom,
            self.order.pattern(),
            self.store.name(&self.root).shown(),
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
    fn read(&self, col: u32, row: u32, cap: u64) -> Result<Option<CellData>> {
        let Some(path) = self.tiles.get(&(self.origin.0 + col, self.origin.1 + row)) else { return Ok(None) };
        Ok(self.store.read(path, cap)?.map(|bytes| CellData::File(self.store.name(path), bytes)))
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
        let grid = Xyz::open(dir, Order::Zyx)?;
        let mut source = TiledSource::new(Box::new(grid), fill, strict);
        read_all(&mut source)
    }

    fn open_error(dir: &Path) -> String {
        Xyz::open(dir, Order::Zyx).err().expect("an error").to_string()
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
        let grid = Xyz::open(tmp.path(), Order::Zyx).unwrap();
        assert_eq!((grid.zoom(), grid.origin(), grid.cell()), (11, (1021, 680), (TS, TS)));
        assert_eq!((grid.header().width, grid.header().height), (cols * TS, rows * TS));
        assert_eq!(grid.header().layout.to_string(), "rgba 8-bit");
        assert!(grid.describe().contains("zoom 11") && grid.describe().contains("3x2 tiles"), "{}", grid.describe());
        assert!(read_image(tmp.path(), vec![0; 4], true).unwrap() == image);
    }

    /// The count of tiles described is the grid's, also where the image recorded in
    /// `tilejson.json` ends inside the last tile.
    #[test]
    fn the_description_counts_partly_used_tiles() {
        let tmp = tempfile::tempdir().unwrap();
        let (cols, rows) = (3, 2);
        let image = rgba_image(cols * TS, rows * TS, 5);
        write_tiles(tmp.path(), 4, (0, 0), &image, cols, rows, &[]);
        let (width, height) = (2 * TS + 1, TS + 1);
        let tilejson = format!(r#"{{"maxzoom": 4, "vortex": {{"width": {width}, "height": {height}}}}}"#);
        std::fs::write(tmp.path().join(crate::formats::viewer::xyz::TILEJSON), tilejson).unwrap();
        let grid = Xyz::open(tmp.path(), Order::Zyx).unwrap();
        assert_eq!((grid.header().width, grid.header().height), (width, height));
        assert!(grid.describe().contains("3x2 tiles"), "{}", grid.describe());
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
        assert_eq!(Xyz::open(tmp.path(), Order::Zyx).unwrap().origin(), (2, 5));
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

    #[test]
    fn z_x_y_reads_the_same_image_from_column_directories() {
        let tmp = tempfile::tempdir().unwrap();
        let (cols, rows) = (3, 2);
        let image = rgba_image(cols * TS, rows * TS, 6);
        let zyx = tmp.path().join("zyx");
        write_tiles(&zyx, 7, (4, 9), &image, cols, rows, &[]);
        // The same files with the two directory levels swapped: 7/<x>/<y>.png.
        let zxy = tmp.path().join("zxy");
        for r in 0..rows {
            for c in 0..cols {
                let (x, y) = (4 + c, 9 + r);
                std::fs::create_dir_all(zxy.join(format!("7/{x}"))).unwrap();
                std::fs::copy(zyx.join(format!("7/{y}/{x}.png")), zxy.join(format!("7/{x}/{y}.png"))).unwrap();
            }
        }
        let grid = Xyz::open(&zxy, Order::Zxy).unwrap();
        assert_eq!((grid.origin(), grid.header().width, grid.header().height), ((4, 9), cols * TS, rows * TS));
        assert!(grid.describe().contains("z/x/y.ext"), "{}", grid.describe());
        let mut source = TiledSource::new(Box::new(grid), vec![0; 4], true);
        assert!(read_all(&mut source).unwrap() == image);
        // Read in the other order, the tiles are transposed: another box, another image.
        let wrong = Xyz::open(&zxy, Order::Zyx).unwrap();
        assert_eq!(wrong.origin(), (9, 4));
        let e = open_error_in(&zxy.join("7/4"), Order::Zxy);
        assert!(e.contains("holds no zoom directories") && e.contains("z/x/y.ext"), "{e}");
    }

    fn open_error_in(dir: &Path, order: Order) -> String {
        Xyz::open(dir, order).err().expect("an error").to_string()
    }

    #[test]
    fn reads_tiles_from_a_folder_of_a_zip() {
        let tmp = tempfile::tempdir().unwrap();
        let (cols, rows) = (2, 3);
        let image = rgba_image(cols * TS, rows * TS, 12);
        let dir = tmp.path().join("g");
        write_tiles(&dir, 3, (0, 1), &image, cols, rows, &[]);
        let mut entries: Vec<(String, Vec<u8>)> = vec![("g/blank.png".into(), b"not read".to_vec())];
        for r in 0..rows {
            for c in 0..cols {
                let name = format!("g/3/{}/{c}.png", 1 + r);
                entries.push((name.clone(), std::fs::read(tmp.path().join(&name)).unwrap()));
            }
        }
        let entries: Vec<(&str, &[u8])> = entries.iter().map(|(n, b)| (n.as_str(), b.as_slice())).collect();
        let zip = tmp.path().join("g.zip");
        crate::source::tiled::store::tests::write_zip(&zip, &entries, false);
        let grid = Xyz::open_in(TileStore::zip(&zip).unwrap(), "g", Order::Zyx).unwrap();
        assert!(grid.describe().contains("g.zip:g"), "{}", grid.describe());
        let mut source = TiledSource::new(Box::new(grid), vec![0; 4], true);
        assert!(read_all(&mut source).unwrap() == image);
    }
}
