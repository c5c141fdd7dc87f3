//! IIIF Image API 2 and 3 level-0 static tiles, as `vips dzsave --layout iiif|iiif3` writes
//! them: an `info.json` (`@context` `http://iiif.io/api/image/{2,3}/context.json`, `width`,
//! `height`, `tiles[0]` with `width`, optional `height` and `scaleFactors`) and one file per
//! tile named by the request that returns it. The full-size tile of region
//! `{x},{y},{w},{h}` (cropped to the image) is `{region}/{w},{h}/0/default.{ext}` in IIIF 3 and
//! `{region}/{w},/0/default.{ext}` in IIIF 2; an image that fits in one tile may instead be
//! stored whole at `full/{w},{h}` (`full/{w},`), `full/max` or `full/full`. Only scale factor 1
//! is read; coarser levels are ignored.
//!
//! The naming (size syntax, extension) is taken from the first tile found and then used for
//! every cell, so a missing tile costs one lookup, not one per spelling.

use std::path::Path;

use serde_json::Value;

use crate::error::{Result, ShowPath, TilerError};
use crate::formats::viewer::iiif::{region_file, whole_file};
use crate::pixel::{Channels, Depth, PixelLayout};
use crate::source::ImageHeader;
use crate::source::tiled::store::{Kind, MAX_DESCRIPTOR_BYTES, TileStore, join};
use crate::source::tiled::{CellData, TileGrid, any_tile_file_cap, probe_stored};

/// Tile file extensions tried, in this order.
const EXTENSIONS: [&str; 4] = ["jpg", "png", "webp", "jxl"];

/// Whether `bytes` (an `info.json`) is a IIIF Image API description: it names the API's
/// context. Malformed ones count too, so that the IIIF reader reports what is wrong with them.
pub fn looks_like_iiif(bytes: &[u8]) -> bool {
    bytes.windows(18).any(|w| w == b"iiif.io/api/image/")
}

/// How the finest tiles are named: the size segment of the path and the extension.
#[derive(Clone, Debug, PartialEq, Eq)]
enum Names {
    /// `{region}/{size}/0/default.{ext}` per cell; `with_height` writes `{w},{h}`, else `{w},`.
    Regions { with_height: bool, ext: &'static str },
    /// The one tile of a one-cell image, at this path (relative to the root).
    Whole(String),
}

/// A IIIF Image API 2 or 3 level-0 directory (`info.json` and its tile files, in a
/// directory or a zip), its full resolution read as an image for `convert`.
pub struct Iiif {
    store: TileStore,
    /// The directory holding `info.json`, relative to the store (`""` or a folder in a zip).
    root: String,
    version: u8,
    header: ImageHeader,
    cell: (u32, u32),
    names: Names,
}

impl Iiif {
    /// Reads `dir/info.json` and finds the first full-size tile (for the naming and the pixel
    /// layout).
    pub fn open(dir: &Path) -> Result<Iiif> {
        Iiif::open_in(TileStore::dir(dir), "")
    }

    /// As [`Iiif::open`], for the `info.json` in folder `root` of `store`.
    pub(crate) fn open_in(store: TileStore, root: &str) -> Result<Iiif> {
        let info_rel = join(root, "info.json");
        let info_name = store.name(&info_rel);
        let bytes = store.read(&info_rel, MAX_DESCRIPTOR_BYTES)?.ok_or_else(|| {
            TilerError::decode(&info_name, "is missing: a IIIF tile directory has its info.json at the top")
        })?;
        let info = Info::parse(&info_name, &bytes)?;
        let (cw, ch) = (info.tile_width.min(info.width), info.tile_height.min(info.height));
        let mut grid = Iiif {
            store,
            root: root.to_string(),
            version: info.version,
            // The layout is the first tile's, read below once the tiles are found.
            header: ImageHeader {
                width: info.width,
                height: info.height,
                layout: PixelLayout::new(Channels::Rgb, Depth::U8),
            },
            cell: (cw, ch),
            names: Names::Whole(String::new()),
        };
        let (names, first) = grid.find_first()?;
        grid.names = names;
        let (_, _, layout) = probe_stored(&grid.store, &first, any_tile_file_cap(cw, ch))?;
        grid.header.layout = layout;
        Ok(grid)
    }

    /// The IIIF Image API version (2 or 3).
    #[cfg(test)]
    pub(crate) fn version(&self) -> u8 {
        self.version
    }

    fn grid_size(&self) -> (u32, u32) {
        (self.header.width.div_ceil(self.cell.0), self.header.height.div_ceil(self.cell.1))
    }

    /// Region `(x, y, w, h)` of cell (col, row), cropped to the image.
    fn region(&self, col: u32, row: u32) -> (u32, u32, u32, u32) {
        let (cw, ch) = self.cell;
        let (x, y) = (col * cw, row * ch);
        (x, y, cw.min(self.header.width - x), ch.min(self.header.height - y))
    }

    fn region_path(&self, col: u32, row: u32, with_height: bool, ext: &str) -> String {
        let (x, y, w, h) = self.region(col, row);
        let size = if with_height { format!("{w},{h}") } else { format!("{w},") };
        join(&self.root, &region_file(x.into(), y.into(), w.into(), h.into(), &size, ext))
    }

    /// The naming of the tiles and the first tile's path: the first cell in reading order
    /// whose region directory the root lists and that holds a full-size tile, or for a
    /// one-cell image its whole-image file.
    fn find_first(&self) -> Result<(Names, String)> {
        let (cols, rows) = self.grid_size();
        let mut first: Option<(u32, u32)> = None;
        for entry in self.store.list(&self.root)? {
            if entry.kind != Kind::Dir {
                continue;
            }
            let Some((col, row)) = self.cell_of_region(&entry.name) else { continue };
            if first.is_none_or(|(c, r)| (row, col) < (r, c)) {
                first = Some((col, row));
            }
        }
        // The version's own size syntax first, then the other's: some writers mix them up.
        let forms = if self.version == 3 { [true, false] } else { [false, true] };
        if let Some((col, row)) = first {
            for with_height in forms {
                for ext in EXTENSIONS {
                    let path = self.region_path(col, row, with_height, ext);
                    if self.store.kind(&path) == Some(Kind::File) {
                        return Ok((Names::Regions { with_height, ext }, path));
                    }
                }
            }
        }
        if (cols, rows) == (1, 1) {
            let (w, h) = (self.header.width, self.header.height);
            let sizes = [format!("{w},{h}"), format!("{w},"), "max".into(), "full".into()];
            for size in &sizes {
                for ext in EXTENSIONS {
                    let path = join(&self.root, &whole_file(size, ext));
                    if self.store.kind(&path) == Some(Kind::File) {
                        return Ok((Names::Whole(path.clone()), path));
                    }
                }
            }
        }
        let example = self.region_path(0, 0, self.version == 3, "jpg");
        Err(TilerError::decode(
            self.store.name(&self.root),
            format!(
                "holds no full-size tile of the {cols}x{rows} grid of {}x{} tiles its info.json describes (such as {example}, .png or .webp)",
                self.cell.0, self.cell.1
            ),
        ))
    }

    /// The cell whose full-size region directory is named `name` (`x,y,w,h`), if any.
    fn cell_of_region(&self, name: &str) -> Option<(u32, u32)> {
        let mut parts = name.split(',').map(|p| p.parse::<u32>().ok());
        let (x, y, w, h) = (parts.next()??, parts.next()??, parts.next()??, parts.next()??);
        if parts.next().is_some() || x % self.cell.0 != 0 || y % self.cell.1 != 0 {
            return None;
        }
        let (col, row) = (x / self.cell.0, y / self.cell.1);
        let (cols, rows) = self.grid_size();
        (col < cols && row < rows && self.region(col, row) == (x, y, w, h)).then_some((col, row))
    }
}

impl TileGrid for Iiif {
    fn describe(&self) -> String {
        let (cols, rows) = self.grid_size();
        let ext = match &self.names {
            Names::Regions { ext, .. } => ext,
            Names::Whole(path) => path.rsplit('.').next().unwrap_or(""),
        };
        format!(
            "the IIIF Image API {} tiles in {} ({cols}x{rows} tiles of {}x{}, {ext})",
            self.version,
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
        let path = match &self.names {
            Names::Regions { with_height, ext } => self.region_path(col, row, *with_height, ext),
            Names::Whole(path) => path.clone(),
        };
        Ok(self.store.read(&path, cap)?.map(|bytes| CellData::File(self.store.name(&path), bytes)))
    }
    fn crop(&self, _: u32, _: u32) -> (u32, u32) {
        (0, 0)
    }
    /// The region: full tiles inside, the remainder at the right and bottom edges.
    fn stored_size(&self, col: u32, row: u32) -> Option<(u32, u32)> {
        let (_, _, w, h) = self.region(col, row);
        Some((w, h))
    }
    /// The full-size region directories the root lists (the one image of a one-cell grid).
    fn tiles_found(&self) -> Result<Option<u64>> {
        if let Names::Whole(_) = self.names {
            return Ok(Some(1));
        }
        let entries = self.store.list(&self.root)?;
        Ok(
            Some(
                entries.iter().filter(|e| e.kind == Kind::Dir && self.cell_of_region(&e.name).is_some()).count() as u64
            ),
        )
    }
}

/// What an `info.json` says that the reader needs.
#[derive(Debug, PartialEq, Eq)]
struct Info {
    version: u8,
    width: u32,
    height: u32,
    tile_width: u32,
    tile_height: u32,
}

impl Info {
    /// Parses `bytes`; members this reader does not use (`id`, `profile`, `sizes`, ...) are
    /// accepted whatever they hold. Errors name `path` and the member.
    fn parse(path: &Path, bytes: &[u8]) -> Result<Info> {
        let value: Value = serde_json::from_slice(bytes)
            .map_err(|e| TilerError::decode(path, format!("is not valid JSON ({e}), so not a IIIF info.json")))?;
        let top = value
            .as_object()
            .ok_or_else(|| TilerError::decode(path, "is not a JSON object, so not a IIIF info.json"))?;
        let err = |field: &str, message: String| TilerError::Info { path: path.into(), field: field.into(), message };
        let context = top.get("@context").ok_or_else(|| err("@context", "missing: not a IIIF info.json".into()))?;
        let version = context_version(context).ok_or_else(|| {
            err(
                "@context",
                format!("{context} names neither http://iiif.io/api/image/2/context.json nor .../3/context.json"),
            )
        })?;
        let size = |object: &serde_json::Map<String, Value>, field: &str, name: &str| -> Result<Option<u32>> {
            let Some(v) = object.get(name) else { return Ok(None) };
            let n = v.as_u64().ok_or_else(|| err(field, format!("{v} is not a whole number")))?;
            if n == 0 {
                return Err(err(field, "is 0".into()));
            }
            u32::try_from(n)
                .map(Some)
                .map_err(|_| err(field, format!("{n} is over {}, the largest size read", u32::MAX)))
        };
        let required =
            |object, field: &str, name| size(object, field, name)?.ok_or_else(|| err(field, "missing".into()));
        let width = required(top, "width", "width")?;
        let height = required(top, "height", "height")?;
        let tiles = top.get("tiles").ok_or_else(|| err("tiles", "missing: only tiled IIIF images are read".into()))?;
        let tile = tiles
            .as_array()
            .ok_or_else(|| err("tiles", format!("{tiles} is not a list")))?
            .first()
            .ok_or_else(|| err("tiles", "is empty".into()))?
            .as_object()
            .ok_or_else(|| err("tiles[0]", "is not an object".into()))?;
        let tile_width = required(tile, "tiles[0].width", "width")?;
        let tile_height = size(tile, "tiles[0].height", "height")?.unwrap_or(tile_width);
        let factors = tile.get("scaleFactors").ok_or_else(|| err("tiles[0].scaleFactors", "missing".into()))?;
        let list =
            factors.as_array().ok_or_else(|| err("tiles[0].scaleFactors", format!("{factors} is not a list")))?;
        // vips 8.14 writes an empty list for an image that fits in one tile: only scale 1.
        if !list.is_empty() && !list.iter().any(|f| f.as_u64() == Some(1)) {
            return Err(err(
                "tiles[0].scaleFactors",
                format!("{factors} lacks 1: the full-size tiles, the only ones read, are not there"),
            ));
        }
        Ok(Info { version, width, height, tile_width, tile_height })
    }
}

/// 2 or 3 if `context` (a string, or a list of them as IIIF 3 allows) names an Image API
/// context.
fn context_version(context: &Value) -> Option<u8> {
    let of = |s: &str| {
        let s = s.strip_prefix("https://").or_else(|| s.strip_prefix("http://"))?;
        match s {
            "iiif.io/api/image/2/context.json" => Some(2),
            "iiif.io/api/image/3/context.json" => Some(3),
            _ => None,
        }
    };
    match context {
        Value::String(s) => of(s),
        Value::Array(list) => list.iter().filter_map(Value::as_str).find_map(of),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::source::read_all;
    use crate::source::tiled::TiledSource;
    use std::path::PathBuf;

    /// A reproducible RGB image.
    fn rgb_image(width: u32, height: u32, seed: u32) -> Vec<u8> {
        crate::source::tiled::noise((width * height * 3) as usize, seed)
    }

    fn info(version: u8, width: u32, height: u32, tile: &str) -> String {
        format!(
            r#"{{"@context": "http://iiif.io/api/image/{version}/context.json", "id": "https://example.com/x",
               "type": "ImageService3", "profile": ["level0", {{"formats": ["png"]}}], "protocol": "http://iiif.io/api/image",
               "tiles": [{tile}], "width": {width}, "height": {height}, "extra": {{"any": [1, null]}}}}"#
        )
    }

    /// Writes the full-size tiles of `image` (RGB, PNG) as vips does for `version`, plus a
    /// coarser level that is not to be read, and `info.json`; returns the tiles written.
    fn write_tiles(dir: &Path, image: &[u8], (w, h): (u32, u32), (tw, th): (u32, u32), version: u8) -> Vec<PathBuf> {
        let mut written = Vec::new();
        for r in 0..h.div_ceil(th) {
            for c in 0..w.div_ceil(tw) {
                let (x, y) = (c * tw, r * th);
                let (rw, rh) = (tw.min(w - x), th.min(h - y));
                let mut tile = Vec::new();
                for yy in y..y + rh {
                    let row = (yy * w) as usize * 3;
                    tile.extend_from_slice(&image[row + x as usize * 3..row + (x + rw) as usize * 3]);
                }
                let size = if version == 3 { format!("{rw},{rh}") } else { format!("{rw},") };
                let path = dir.join(format!("{x},{y},{rw},{rh}/{size}/0/default.png"));
                std::fs::create_dir_all(path.parent().unwrap()).unwrap();
                image::save_buffer(&path, &tile, rw, rh, image::ExtendedColorType::Rgb8).unwrap();
                written.push(path);
            }
        }
        // Scale factor 2: the whole image at half size, an unreadable file that must not be read.
        let coarse = dir.join(format!("0,0,{w},{h}/{},/0/default.png", w.div_ceil(2)));
        std::fs::create_dir_all(coarse.parent().unwrap()).unwrap();
        std::fs::write(coarse, b"not a png").unwrap();
        let tile = if tw == th {
            format!(r#"{{"scaleFactors": [1, 2], "width": {tw}}}"#)
        } else {
            format!(r#"{{"scaleFactors": [1, 2], "width": {tw}, "height": {th}}}"#)
        };
        std::fs::write(dir.join("info.json"), info(version, w, h, &tile)).unwrap();
        written
    }

    fn read_image(grid: Iiif, strict: bool) -> Result<Vec<u8>> {
        let mut source = TiledSource::new(Box::new(grid), vec![0; 3], strict);
        read_all(&mut source)
    }

    #[test]
    fn reads_back_versions_2_and_3_bit_exactly() {
        let tmp = tempfile::tempdir().unwrap();
        for version in [2, 3] {
            for (w, h, tw, th) in [(53, 37, 16, 16), (40, 70, 16, 24), (9, 5, 16, 16), (32, 32, 16, 16)] {
                let dir = tmp.path().join(format!("v{version}-{w}x{h}-{tw}x{th}"));
                let image = rgb_image(w, h, w * h + version as u32);
                write_tiles(&dir, &image, (w, h), (tw, th), version);
                let grid = Iiif::open(&dir).unwrap();
                assert_eq!(grid.version(), version);
                assert_eq!(grid.cell(), (tw.min(w), th.min(h)));
                assert_eq!(grid.header().layout.to_string(), "rgb 8-bit");
                assert!(grid.describe().contains(&format!("IIIF Image API {version}")), "{}", grid.describe());
                assert!(read_image(grid, true).unwrap() == image, "v{version} {w}x{h} tiles {tw}x{th}");
            }
        }
    }

    #[test]
    fn a_one_tile_image_may_be_stored_whole() {
        let tmp = tempfile::tempdir().unwrap();
        let (w, h) = (20, 12);
        let image = rgb_image(w, h, 4);
        for (version, size) in [(3, "20,12"), (2, "20,"), (3, "max"), (2, "full")] {
            let dir = tmp.path().join(format!("{version}-{size}"));
            let path = dir.join(format!("full/{size}/0/default.png"));
            std::fs::create_dir_all(path.parent().unwrap()).unwrap();
            image::save_buffer(&path, &image, w, h, image::ExtendedColorType::Rgb8).unwrap();
            let tile = r#"{"scaleFactors": [1], "width": 512}"#;
            std::fs::write(dir.join("info.json"), info(version, w, h, tile)).unwrap();
            assert!(read_image(Iiif::open(&dir).unwrap(), true).unwrap() == image, "{size}");
        }
    }

    #[test]
    fn reads_from_a_folder_of_a_zip() {
        let tmp = tempfile::tempdir().unwrap();
        let (w, h) = (40, 30);
        let image = rgb_image(w, h, 8);
        let dir = tmp.path().join("i3");
        write_tiles(&dir, &image, (w, h), (16, 16), 3);
        let mut entries: Vec<(String, Vec<u8>)> = Vec::new();
        for path in walk(&dir) {
            let rel = path.strip_prefix(tmp.path()).unwrap().to_string_lossy().into_owned();
            entries.push((rel, std::fs::read(&path).unwrap()));
        }
        let entries: Vec<(&str, &[u8])> = entries.iter().map(|(n, b)| (n.as_str(), b.as_slice())).collect();
        let zip = tmp.path().join("i3.zip");
        crate::source::tiled::store::tests::write_zip(&zip, &entries, true);
        let grid = Iiif::open_in(TileStore::zip(&zip).unwrap(), "i3").unwrap();
        assert!(grid.describe().contains("i3.zip:i3"), "{}", grid.describe());
        assert!(read_image(grid, true).unwrap() == image);
    }

    fn walk(dir: &Path) -> Vec<PathBuf> {
        let mut out = Vec::new();
        for e in std::fs::read_dir(dir).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() { out.extend(walk(&p)) } else { out.push(p) }
        }
        out
    }

    #[test]
    fn a_missing_tile_is_filled_the_first_found_gives_the_naming() {
        let tmp = tempfile::tempdir().unwrap();
        let (w, h) = (40, 20);
        let mut image = rgb_image(w, h, 7);
        let tiles = write_tiles(tmp.path(), &image, (w, h), (16, 16), 3);
        std::fs::remove_dir_all(tiles[0].ancestors().nth(3).unwrap()).unwrap();
        for y in 0..16 {
            for x in 0..16 {
                image[((y * w + x) * 3) as usize..][..3].fill(0);
            }
        }
        let grid = Iiif::open(tmp.path()).unwrap();
        assert!(read_image(grid, false).unwrap() == image);
        let e = read_image(Iiif::open(tmp.path()).unwrap(), true).unwrap_err().to_string();
        assert!(e.contains("missing") && e.contains("x 0, y 0"), "{e}");
    }

    #[test]
    fn a_tile_of_the_wrong_size_is_an_error_naming_it() {
        let tmp = tempfile::tempdir().unwrap();
        let (w, h) = (40, 20);
        let tiles = write_tiles(tmp.path(), &rgb_image(w, h, 5), (w, h), (16, 16), 2);
        image::save_buffer(&tiles[1], &[0u8; 15 * 16 * 3], 15, 16, image::ExtendedColorType::Rgb8).unwrap();
        let e = read_image(Iiif::open(tmp.path()).unwrap(), false).unwrap_err().to_string();
        assert!(e.contains("16,0,16,16/16,/0/default.png") && e.contains("is 15x16"), "{e}");
    }

    #[test]
    fn no_tiles_is_an_error_naming_the_directory() {
        let tmp = tempfile::tempdir().unwrap();
        std::fs::write(tmp.path().join("info.json"), info(3, 100, 100, r#"{"width": 64, "scaleFactors": [1]}"#))
            .unwrap();
        // A coarser level only, and a region that is no cell.
        std::fs::create_dir_all(tmp.path().join("0,0,100,100/50,50/0")).unwrap();
        std::fs::create_dir_all(tmp.path().join("0,0,64,64/64,64/0")).unwrap();
        let e = Iiif::open(tmp.path()).err().unwrap().to_string();
        assert!(e.contains("holds no full-size tile") && e.contains("0,0,64,64/64,64/0/default.jpg"), "{e}");
        let e = Iiif::open(&tmp.path().join("none")).err().unwrap().to_string();
        assert!(e.contains("none/info.json") && e.contains("missing"), "{e}");
    }

    #[test]
    fn info_errors_name_the_file_and_member() {
        let tile = r#"{"scaleFactors": [1, 2, 4], "width": 256}"#;
        let ok = info(3, 700, 500, tile);
        assert_eq!(
            Info::parse(Path::new("i.json"), ok.as_bytes()).unwrap(),
            Info { version: 3, width: 700, height: 500, tile_width: 256, tile_height: 256 }
        );
        let v2 = info(2, 7, 5, r#"{"scaleFactors": [], "width": 256, "height": 128}"#).replace("http:", "https:");
        assert_eq!(Info::parse(Path::new("i.json"), v2.as_bytes()).unwrap().tile_height, 128);
        let list = ok.replace(
            r#""http://iiif.io/api/image/3/context.json""#,
            r#"["http://www.w3.org/ns/anno.jsonld", "http://iiif.io/api/image/3/context.json"]"#,
        );
        assert_eq!(Info::parse(Path::new("i.json"), list.as_bytes()).unwrap().version, 3);
        let cases = [
            (ok.replace("\"width\": 700", "\"width\": 5000000000"), "width: 5000000000 is over 4294967295"),
            (ok.replace("\"width\": 700", "\"width\": -1"), "width: -1 is not a whole number"),
            (ok.replace("\"width\": 700", "\"width\": 0"), "width: is 0"),
            (ok.replace("\"width\": 700, ", ""), "width: missing"),
            (ok.replace("\"height\": 500", "\"height\": \"500\""), "height: \"500\" is not a whole number"),
            (ok.replace("image/3/", "image/4/"), "@context: \"http://iiif.io/api/image/4/context.json\" names neither"),
            (ok.replace("\"@context\"", "\"context\""), "@context: missing"),
            (ok.replace("[1, 2, 4]", "[2, 4]"), "tiles[0].scaleFactors: [2,4] lacks 1"),
            (ok.replace("\"scaleFactors\": [1, 2, 4], ", ""), "tiles[0].scaleFactors: missing"),
            (
                ok.replace("\"scaleFactors\": [1, 2, 4]", "\"scaleFactors\": 1"),
                "tiles[0].scaleFactors: 1 is not a list",
            ),
            (ok.replace(", \"width\": 256", ""), "tiles[0].width: missing"),
            (ok.replace("\"width\": 256", "\"width\": 256, \"height\": 0"), "tiles[0].height: is 0"),
            (ok.replace(tile, ""), "tiles: is empty"),
            (ok.replace(&format!("[{tile}]"), "{}"), "tiles: {} is not a list"),
            (ok.replace(&format!("\"tiles\": [{tile}], "), ""), "tiles: missing"),
            ("[1]".to_string(), "is not a JSON object"),
            ("{\"@context\": ".to_string(), "is not valid JSON"),
        ];
        for (text, expected) in cases {
            let e = Info::parse(Path::new("d/info.json"), text.as_bytes()).unwrap_err().to_string();
            assert!(e.starts_with("d/info.json: ") && e.contains(expected), "{text}: {e}");
        }
    }

    #[test]
    fn sniffing() {
        assert!(looks_like_iiif(info(2, 1, 1, "{}").as_bytes()));
        assert!(!looks_like_iiif(br#"{"tileSize": 256, "width": 10}"#));
    }
}
