//! A Deep Zoom pyramid as `vips dzsave` writes it: a `.dzi` descriptor
//! (`<Image TileSize="254" Overlap="1" Format="jpeg"><Size Width=".." Height=".."/></Image>`) and
//! the tiles in `<stem>_files/<level>/<col>_<row>.<format>`. Only the finest level is read: level
//! `ceil(log2(max(width, height)))`, the image at full size.
//!
//! Tile (c, r) of that level holds the texels of cell (c, r) plus `Overlap` texels on each side
//! that has a neighbour, so its first `Overlap` columns (rows) are skipped unless c (r) is 0.

use std::path::Path;

use crate::error::{Result, ShowPath, TilerError};
use crate::formats::viewer::dzi;
use crate::source::ImageHeader;
use crate::source::tiled::store::{Kind, MAX_DESCRIPTOR_BYTES, TileStore};
use crate::source::tiled::{CellData, TileGrid, any_tile_file_cap, probe_stored};
use crate::source::xml::unescape;

/// A Deep Zoom pyramid (`NAME.dzi` and `NAME_files/`, in a directory or a zip), its finest
/// level read as an image for `convert`: the overlap cut off each tile.
pub struct DeepZoom {
    store: TileStore,
    /// The descriptor, relative to the store.
    dzi: String,
    /// `<stem>_files/<level>`, relative to the store.
    level_dir: String,
    level: u32,
    tile_size: u32,
    overlap: u32,
    format: String,
    header: ImageHeader,
}

impl DeepZoom {
    /// Reads the descriptor at `dzi_path` and the first tile of the finest level (for the pixel
    /// layout).
    pub fn open(dzi_path: &Path) -> Result<DeepZoom> {
        let name = dzi_path
            .file_name()
            .and_then(|n| n.to_str())
            .ok_or_else(|| TilerError::decode(dzi_path, "has no UTF-8 file name to find its tiles by"))?;
        let parent = dzi_path.parent().unwrap_or(Path::new(""));
        DeepZoom::open_in(TileStore::dir(parent), name)
    }

    /// As [`DeepZoom::open`], for the descriptor `dzi` of `store` (a path inside it).
    pub(crate) fn open_in(store: TileStore, dzi: &str) -> Result<DeepZoom> {
        let dzi_path = store.name(dzi);
        let bytes = store.read(dzi, MAX_DESCRIPTOR_BYTES)?.ok_or_else(|| {
            TilerError::io(&dzi_path, std::io::Error::new(std::io::ErrorKind::NotFound, "No such file or directory"))
        })?;
        let text = std::str::from_utf8(&bytes)
            .map_err(|_| TilerError::decode(&dzi_path, "is not UTF-8 text, so not a Deep Zoom descriptor (.dzi)"))?;
        let d = Descriptor::parse(&dzi_path, text)?;
        let level = dzi::max_level(d.width, d.height);
        // `dir/name.dzi` has its tiles in `dir/name_files`, as Path::file_stem splits names.
        let file_at = dzi.rfind('/').map_or(0, |i| i + 1);
        let stem = match dzi[file_at..].rfind('.') {
            Some(dot) if dot > 0 => &dzi[..file_at + dot],
            _ => dzi,
        };
        let level_dir = dzi::level_dir(stem, level);
        if store.kind(&level_dir) != Some(Kind::Dir) {
            return Err(TilerError::decode(
                store.name(&level_dir),
                format!(
                    "is missing: {} describes a {}x{} image, whose full-size tiles are level {level}",
                    dzi_path.shown(),
                    d.width,
                    d.height
                ),
            ));
        }
        let (cols, rows) = (d.width.div_ceil(d.tile_size), d.height.div_ceil(d.tile_size));
        let first = first_tile(&store, &level_dir, &d.format, cols, rows)?;
        let side = d.tile_size.saturating_add(d.overlap.saturating_mul(2));
        let (_, _, layout) = probe_stored(&store, &first, any_tile_file_cap(side, side))?;
        Ok(DeepZoom {
            store,
            dzi: dzi.to_string(),
            level_dir,
            level,
            tile_size: d.tile_size,
            overlap: d.overlap,
            format: d.format,
            header: ImageHeader { width: d.width, height: d.height, layout },
        })
    }

    /// The level read (the finest one).
    pub fn level(&self) -> u32 {
        self.level
    }

    fn tile_path(&self, col: u32, row: u32) -> String {
        tile_path(&self.level_dir, &self.format, col, row)
    }

    fn grid_size(&self) -> (u32, u32) {
        (self.header.width.div_ceil(self.tile_size), self.header.height.div_ceil(self.tile_size))
    }
}

fn tile_path(level_dir: &str, format: &str, col: u32, row: u32) -> String {
    dzi::tile_in(level_dir, col, row, format)
}

/// The first tile of the `cols x rows` grid in reading order: 0_0 if present, else the first
/// of the level's files.
fn first_tile(store: &TileStore, level_dir: &str, format: &str, cols: u32, rows: u32) -> Result<String> {
    let zero = tile_path(level_dir, format, 0, 0);
    if store.kind(&zero) == Some(Kind::File) {
        return Ok(zero);
    }
    let mut best: Option<(u32, u32)> = None;
    for entry in store.list(level_dir)? {
        let Some(rest) = entry.name.strip_suffix(format).and_then(|n| n.strip_suffix('.')) else { continue };
        let Some((c, r)) = rest.split_once('_') else { continue };
        let (Ok(c), Ok(r)) = (c.parse::<u32>(), r.parse::<u32>()) else { continue };
        if entry.kind == Kind::File && c < cols && r < rows && best.is_none_or(|key| (r, c) < key) {
            best = Some((r, c));
        }
    }
    best.map(|(r, c)| tile_path(level_dir, format, c, r)).ok_or_else(|| {
        TilerError::decode(
            store.name(level_dir),
            format!("holds no tiles named <col>_<row>.{format} of the {cols}x{rows} grid"),
        )
    })
}

impl TileGrid for DeepZoom {
    fn describe(&self) -> String {
        let (cols, rows) = self.grid_size();
        format!(
            "level {} of the Deep Zoom pyramid {} ({cols}x{rows} tiles of {}, overlap {}, {})",
            self.level,
            self.store.name(&self.dzi).shown(),
            self.tile_size,
            self.overlap,
            self.format
        )
    }
    fn header(&self) -> ImageHeader {
        self.header
    }
    fn cell(&self) -> (u32, u32) {
        (self.tile_size, self.tile_size)
    }
    fn read(&self, col: u32, row: u32, cap: u64) -> Result<Option<CellData>> {
        let path = self.tile_path(col, row);
        Ok(self.store.read(&path, cap)?.map(|bytes| CellData::File(self.store.name(&path), bytes)))
    }
    fn crop(&self, col: u32, row: u32) -> (u32, u32) {
        let skip = |i: u32| if i > 0 { self.overlap } else { 0 };
        (skip(col), skip(row))
    }
    /// The cell plus the overlap on each side that has a neighbour.
    fn stored_size(&self, col: u32, row: u32) -> Option<(u32, u32)> {
        let (ts, ov) = (self.tile_size as u64, self.overlap as u64);
        let side = |i: u32, size: u32| {
            let (start, end) = dzi::tile_span(i, ts, ov, size);
            (end - start) as u32
        };
        Some((side(col, self.header.width), side(row, self.header.height)))
    }
    /// The level directory's files named as tiles of the grid (`{col}_{row}.{format}`).
    fn tiles_found(&self) -> Result<Option<u64>> {
        let (cols, rows) = self.grid_size();
        let suffix = format!(".{}", self.format);
        let is_tile = |name: &str| {
            let Some((col, row)) = name.strip_suffix(&suffix).and_then(|stem| stem.split_once('_')) else {
                return false;
            };
            col.parse::<u32>().is_ok_and(|c| c < cols) && row.parse::<u32>().is_ok_and(|r| r < rows)
        };
        let entries = self.store.list(&self.level_dir)?;
        Ok(Some(entries.iter().filter(|e| e.kind == Kind::File && is_tile(&e.name)).count() as u64))
    }
}

/// What a `.dzi` says.
#[derive(Debug, PartialEq, Eq)]
struct Descriptor {
    tile_size: u32,
    overlap: u32,
    format: String,
    width: u32,
    height: u32,
}

impl Descriptor {
    fn parse(path: &Path, text: &str) -> Result<Descriptor> {
        let elements = elements(path, text)?;
        let image_at = elements
            .iter()
            .position(|e| local(e.name) == "Image")
            .ok_or_else(|| TilerError::decode(path, "has no <Image> element: not a Deep Zoom descriptor (.dzi)"))?;
        let image = &elements[image_at];
        let size = elements[image_at + 1..].iter().find(|e| local(e.name) == "Size").ok_or_else(|| {
            TilerError::Info { path: path.into(), field: "Size".into(), message: "no <Size> element in <Image>".into() }
        })?;
        let number = |element: &Element, name: &str, min: u32| -> Result<u32> {
            let value = element.attribute(path, name)?;
            let bad = |why: &str| TilerError::Info {
                path: path.into(),
                field: name.into(),
                message: format!("\"{value}\" {why}"),
            };
            let n: u32 = value.trim().parse().map_err(|_| bad("is not a whole number"))?;
            if n < min {
                return Err(bad(&format!("is below {min}")));
            }
            Ok(n)
        };
        let tile_size = number(image, "TileSize", 1)?;
        let overlap = number(image, "Overlap", 0)?;
        let width = number(size, "Width", 1)?;
        let height = number(size, "Height", 1)?;
        let format = image.attribute(path, "Format")?.trim().to_string();
        if format.is_empty() || !format.chars().all(|c| c.is_ascii_alphanumeric()) {
            return Err(TilerError::Info {
                path: path.into(),
                field: "Format".into(),
                message: format!("\"{format}\" is not a file extension (jpeg, png, ...)"),
            });
        }
        Ok(Descriptor { tile_size, overlap, format, width, height })
    }
}

/// A start tag: its name and attributes (values with entities replaced).
struct Element<'a> {
    name: &'a str,
    attributes: Vec<(&'a str, String)>,
}

impl Element<'_> {
    fn attribute(&self, path: &Path, name: &str) -> Result<&str> {
        self.attributes.iter().find(|(n, _)| *n == name).map(|(_, v)| v.as_str()).ok_or_else(|| TilerError::Info {
            path: path.into(),
            field: name.into(),
            message: format!("missing from <{}>", self.name),
        })
    }
}

/// The name without a namespace prefix.
fn local(name: &str) -> &str {
    name.rsplit(':').next().unwrap_or(name)
}

/// Every start (or empty-element) tag of `text`, in order; comments, processing instructions,
/// declarations and end tags are skipped. Just enough XML for a `.dzi`.
fn elements<'a>(path: &Path, text: &'a str) -> Result<Vec<Element<'a>>> {
    let malformed = |at: usize, why: &str| {
        let line = text[..at].matches('\n').count() + 1;
        TilerError::decode(path, format!("line {line}: {why}: not a well-formed Deep Zoom descriptor (.dzi)"))
    };
    let skip_to = |from: usize, end: &str, what: &str| -> Result<usize> {
        text[from..]
            .find(end)
            .map(|i| from + i + end.len())
            .ok_or_else(|| malformed(from, &format!("unterminated {what}")))
    };
    let mut out = Vec::new();
    let mut at = 0;
    while let Some(i) = text[at..].find('<') {
        let start = at + i;
        let rest = &text[start + 1..];
        if rest.starts_with("!--") {
            at = skip_to(start + 4, "-->", "comment")?;
        } else if rest.starts_with("![CDATA[") {
            at = skip_to(start + 9, "]]>", "CDATA section")?;
        } else if rest.starts_with('?') {
            at = skip_to(start + 2, "?>", "processing instruction")?;
        } else if rest.starts_with('!') || rest.starts_with('/') {
            at = skip_to(start + 2, ">", "tag")?;
        } else {
            let (element, end) = start_tag(text, start + 1).map_err(|(at, why)| malformed(at, &why))?;
            out.push(element);
            at = end;
        }
    }
    Ok(out)
}

/// Parses the start tag whose name begins at `from`; returns it and the offset after its `>`.
fn start_tag(text: &str, from: usize) -> std::result::Result<(Element<'_>, usize), (usize, String)> {
    let is_name = |c: char| c.is_alphanumeric() || matches!(c, ':' | '_' | '-' | '.');
    let name_at = |at: usize| -> &str {
        let len = text[at..].find(|c: char| !is_name(c)).unwrap_or(text.len() - at);
        &text[at..at + len]
    };
    let name = name_at(from);
    if name.is_empty() {
        return Err((from, "'<' not followed by an element name".into()));
    }
    let mut element = Element { name, attributes: Vec::new() };
    let mut at = from + name.len();
    loop {
        at += text[at..].len() - text[at..].trim_start().len();
        let rest = &text[at..];
        if rest.starts_with("/>") {
            return Ok((element, at + 2));
        }
        if rest.starts_with('>') {
            return Ok((element, at + 1));
        }
        if rest.is_empty() {
            return Err((at, format!("<{name}> is not closed with '>'")));
        }
        let attr = name_at(at);
        if attr.is_empty() {
            return Err((at, format!("unexpected '{}' in <{name}>", rest.chars().next().unwrap_or(' '))));
        }
        at += attr.len();
        at += text[at..].len() - text[at..].trim_start().len();
        if !text[at..].starts_with('=') {
            return Err((at, format!("attribute {attr} of <{name}> has no '=' and value")));
        }
        at += 1;
        at += text[at..].len() - text[at..].trim_start().len();
        let quote = match text[at..].chars().next() {
            Some(q @ ('"' | '\'')) => q,
            _ => return Err((at, format!("the value of {attr} in <{name}> is not quoted"))),
        };
        let len = text[at + 1..]
            .find(quote)
            .ok_or_else(|| (at, format!("the value of {attr} in <{name}> has no closing {quote}")))?;
        let value = unescape(&text[at + 1..at + 1 + len]).into_owned();
        if element.attributes.iter().any(|(n, _)| *n == attr) {
            return Err((at, format!("attribute {attr} appears twice in <{name}>")));
        }
        element.attributes.push((attr, value));
        at += len + 2;
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

    /// Writes the finest level of a Deep Zoom pyramid of `image` (RGB, PNG tiles) as dzsave
    /// does, plus `dzi` as `<dir>/img.dzi`; returns the .dzi path.
    fn write_pyramid(dir: &Path, image: &[u8], width: u32, height: u32, ts: u32, overlap: u32, dzi: &str) -> PathBuf {
        let level = dzi::max_level(width, height);
        let level_dir = dir.join("img_files").join(level.to_string());
        std::fs::create_dir_all(&level_dir).unwrap();
        for r in 0..height.div_ceil(ts) {
            for c in 0..width.div_ceil(ts) {
                let x0 = (c * ts).saturating_sub(if c > 0 { overlap } else { 0 });
                let y0 = (r * ts).saturating_sub(if r > 0 { overlap } else { 0 });
                let x1 = ((c + 1) * ts + overlap).min(width);
                let y1 = ((r + 1) * ts + overlap).min(height);
                let mut tile = Vec::new();
                for y in y0..y1 {
                    let row = (y * width) as usize * 3;
                    tile.extend_from_slice(&image[row + x0 as usize * 3..row + x1 as usize * 3]);
                }
                let path = level_dir.join(format!("{c}_{r}.png"));
                image::save_buffer(path, &tile, x1 - x0, y1 - y0, image::ExtendedColorType::Rgb8).unwrap();
            }
        }
        let path = dir.join("img.dzi");
        std::fs::write(&path, dzi).unwrap();
        path
    }

    fn dzi(width: u32, height: u32, ts: u32, overlap: u32) -> String {
        format!(
            r#"<?xml version="1.0" encoding="UTF-8"?>
<Image xmlns="http://schemas.microsoft.com/deepzoom/2008"
  Format="png"
  Overlap="{overlap}"
  TileSize="{ts}"
  >
  <Size
    Height="{height}"
    Width="{width}"
  />
</Image>
"#
        )
    }

    fn read_image(dzi_path: &Path, fill: Vec<u8>, strict: bool) -> Result<Vec<u8>> {
        let grid = DeepZoom::open(dzi_path)?;
        let mut source = TiledSource::new(Box::new(grid), fill, strict);
        read_all(&mut source)
    }

    #[test]
    fn reads_back_the_image_bit_exactly() {
        let tmp = tempfile::tempdir().unwrap();
        // 4x3 cells of 16, the last column 5 wide and the last row 5 high.
        let (w, h) = (53, 37);
        let image = rgb_image(w, h, 1);
        let path = write_pyramid(tmp.path(), &image, w, h, 16, 1, &dzi(w, h, 16, 1));
        // A coarser level, even an unreadable one, is not read.
        std::fs::create_dir_all(tmp.path().join("img_files/5")).unwrap();
        std::fs::write(tmp.path().join("img_files/5/0_0.png"), b"not a png").unwrap();
        let grid = DeepZoom::open(&path).unwrap();
        assert_eq!(grid.level(), 6);
        assert_eq!(grid.header(), ImageHeader { width: w, height: h, layout: grid.header().layout });
        assert_eq!(grid.header().layout.to_string(), "rgb 8-bit");
        assert_eq!(grid.cell(), (16, 16));
        assert_eq!(
            (grid.crop(0, 0), grid.crop(1, 0), grid.crop(0, 2), grid.crop(3, 2)),
            ((0, 0), (1, 0), (0, 1), (1, 1))
        );
        let sizes = [(0, 0), (1, 1), (3, 0), (3, 2)].map(|(c, r)| grid.stored_size(c, r).unwrap());
        assert_eq!(sizes, [(17, 17), (18, 18), (6, 17), (6, 6)]);
        assert!(grid.describe().contains("level 6"), "{}", grid.describe());
        assert!(read_image(&path, vec![0; 3], true).unwrap() == image);
    }

    #[test]
    fn wider_overlap_and_one_tile_images() {
        let tmp = tempfile::tempdir().unwrap();
        for (w, h, ts, overlap) in [(40, 70, 16, 3), (9, 5, 16, 1), (32, 32, 16, 0), (1, 1, 254, 1)] {
            let dir = tmp.path().join(format!("{w}x{h}-{ts}-{overlap}"));
            let image = rgb_image(w, h, w * h);
            let path = write_pyramid(&dir, &image, w, h, ts, overlap, &dzi(w, h, ts, overlap));
            assert!(read_image(&path, vec![0; 3], true).unwrap() == image, "{w}x{h} tile {ts} overlap {overlap}");
        }
    }

    #[test]
    fn attributes_in_any_order_and_quotes() {
        let text = "\u{feff}<?xml version='1.0'?><!-- made by hand --><dz:Image Overlap = '2' \
                    Format='j&#112;eg' TileSize=\"254\" xmlns:dz='x'><dz:Size Width='300' Height=\"200\"></dz:Size></dz:Image>";
        let d = Descriptor::parse(Path::new("a.dzi"), text).unwrap();
        assert_eq!(d, Descriptor { tile_size: 254, overlap: 2, format: "jpeg".into(), width: 300, height: 200 });
    }

    #[test]
    fn a_missing_tile_is_filled_or_an_error_with_strict() {
        let tmp = tempfile::tempdir().unwrap();
        let (w, h) = (40, 20);
        let mut image = rgb_image(w, h, 7);
        let path = write_pyramid(tmp.path(), &image, w, h, 16, 1, &dzi(w, h, 16, 1));
        std::fs::remove_file(tmp.path().join("img_files/6/1_0.png")).unwrap();
        // Cell (1, 0): x 16..32, y 0..16.
        for y in 0..16 {
            for x in 16..32 {
                image[((y * w + x) * 3) as usize..][..3].copy_from_slice(&[9, 8, 7]);
            }
        }
        assert!(read_image(&path, vec![9, 8, 7], false).unwrap() == image);
        let e = read_image(&path, vec![9, 8, 7], true).unwrap_err().to_string();
        assert!(e.contains("missing") && e.contains("x 1, y 0"), "{e}");
    }

    #[test]
    fn a_tile_of_the_wrong_size_is_an_error() {
        let tmp = tempfile::tempdir().unwrap();
        let (w, h) = (40, 20);
        let image = rgb_image(w, h, 5);
        let path = write_pyramid(tmp.path(), &image, w, h, 16, 1, &dzi(w, h, 16, 1));
        // Tile 1_0 without its right overlap column: 17x17 instead of 18x17.
        let tile = tmp.path().join("img_files/6/1_0.png");
        image::save_buffer(&tile, &[0u8; 17 * 17 * 3], 17, 17, image::ExtendedColorType::Rgb8).unwrap();
        let e = read_image(&path, vec![0; 3], false).unwrap_err().to_string();
        assert!(e.contains("1_0.png") && e.contains("is 17x17") && e.contains("18x17"), "{e}");
    }

    #[test]
    fn the_layout_comes_from_a_later_tile_when_the_first_is_missing() {
        let tmp = tempfile::tempdir().unwrap();
        let (w, h) = (40, 20);
        let image = rgb_image(w, h, 3);
        let path = write_pyramid(tmp.path(), &image, w, h, 16, 1, &dzi(w, h, 16, 1));
        std::fs::remove_file(tmp.path().join("img_files/6/0_0.png")).unwrap();
        assert_eq!(DeepZoom::open(&path).unwrap().header().layout.to_string(), "rgb 8-bit");
        for c in 1..3 {
            for r in 0..2 {
                std::fs::remove_file(tmp.path().join(format!("img_files/6/{c}_{r}.png"))).unwrap();
            }
        }
        std::fs::remove_file(tmp.path().join("img_files/6/0_1.png")).unwrap();
        let e = DeepZoom::open(&path).err().unwrap().to_string();
        assert!(e.contains("holds no tiles"), "{e}");
    }

    #[test]
    fn a_missing_level_names_the_directory() {
        let tmp = tempfile::tempdir().unwrap();
        let path = tmp.path().join("img.dzi");
        std::fs::write(&path, dzi(1000, 10, 254, 1)).unwrap();
        let e = DeepZoom::open(&path).err().unwrap().to_string();
        assert!(e.contains("img_files/10") && e.contains("is missing") && e.contains("level 10"), "{e}");
    }

    #[test]
    fn descriptor_errors_name_the_file_and_attribute() {
        let ok = r#"<Image TileSize="254" Overlap="1" Format="jpg"><Size Width="10" Height="10"/></Image>"#;
        assert!(Descriptor::parse(Path::new("a.dzi"), ok).is_ok());
        let cases = [
            (ok.replace(r#"TileSize="254" "#, ""), "TileSize: missing from <Image>"),
            (ok.replace(r#"Overlap="1" "#, ""), "Overlap: missing"),
            (ok.replace(r#" Format="jpg""#, ""), "Format: missing"),
            (ok.replace(r#"Width="10" "#, ""), "Width: missing from <Size>"),
            (ok.replace("Height", "height"), "Height: missing"),
            (ok.replace(r#""254""#, r#""big""#), "TileSize: \"big\" is not a whole number"),
            (ok.replace(r#""254""#, r#""0""#), "TileSize: \"0\" is below 1"),
            (ok.replace(r#"Overlap="1""#, r#"Overlap="-1""#), "Overlap: \"-1\" is not a whole number"),
            (ok.replace(r#""jpg""#, r#""../x""#), "Format: \"../x\" is not a file extension"),
            (ok.replace(r#"<Size Width="10" Height="10"/>"#, ""), "Size: no <Size> element"),
            (ok.replace(r#"Height="10""#, r#"Height="10"#), "the value of Height in <Size> has no closing \""),
            (ok.replace(r#""254""#, "254"), "TileSize in <Image> is not quoted"),
            (ok.replace(r#"="254""#, r#" "254""#), "has no '='"),
            (ok.replace(r#"Overlap="1""#, r#"Overlap="1" Overlap="2""#), "Overlap appears twice"),
            (ok.replace("</Image>", "<!-- open"), "unterminated comment"),
            ("<Image TileSize='1'".into(), "not closed"),
            ("{\"Image\": {}}".into(), "no <Image> element"),
            ("<Size Width='1' Height='1'/><Image TileSize='1' Overlap='0' Format='png'/>".into(), "no <Size> element"),
        ];
        for (text, expected) in cases {
            let e = Descriptor::parse(Path::new("dir/a.dzi"), &text).unwrap_err().to_string();
            assert!(e.starts_with("dir/a.dzi: ") && e.contains(expected), "{text}: {e}");
        }
    }

    #[test]
    fn open_errors_name_the_file() {
        let tmp = tempfile::tempdir().unwrap();
        let missing = tmp.path().join("none.dzi");
        let e = DeepZoom::open(&missing).err().unwrap().to_string();
        assert!(e.contains("none.dzi"), "{e}");
        let binary = tmp.path().join("bin.dzi");
        std::fs::write(&binary, [0xff, 0xfe, 0x00]).unwrap();
        let e = DeepZoom::open(&binary).err().unwrap().to_string();
        assert!(e.contains("bin.dzi") && e.contains("not UTF-8"), "{e}");
    }
}
