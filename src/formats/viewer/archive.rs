//! A zip archive as `vips dzsave NAME.zip` writes it, read in place: which pyramid is inside is
//! decided from its names. vips 8.14 puts everything in a folder named after the archive
//! (`name/name.dzi`, `name/name_files/..`; `name/{z}/{y}/{x}.jpg`; `name/info.json`), libvips
//! 8.18 puts a Deep Zoom pyramid at the top, so both the top and each top folder are searched.

use std::io::Read;
use std::path::Path;

use super::dzi::DeepZoom;
use super::iiif::{Iiif, looks_like_iiif};
use super::xyz::{Order, Xyz};
use crate::error::{Result, TilerError};
use crate::source::tiled::TileGrid;
use crate::source::tiled::store::{Kind, MAX_DESCRIPTOR_BYTES, TileStore};

/// Whether `path` is a zip archive: named `.zip`, or starting like one.
pub fn is_zip(path: &Path) -> bool {
    if path.extension().is_some_and(|e| e.eq_ignore_ascii_case("zip")) {
        return true;
    }
    let mut magic = Vec::with_capacity(4);
    let Ok(file) = std::fs::File::open(path) else { return false };
    file.take(4).read_to_end(&mut magic).is_ok() && (magic == b"PK\x03\x04" || magic == b"PK\x05\x06")
}

/// Whether `dir` holds an `info.json` that describes IIIF tiles (rather than this tool's own
/// pyramid).
pub fn is_iiif_dir(dir: &Path) -> bool {
    let mut head = Vec::new();
    // Not a FIFO or a device: opening or reading one would block.
    let Ok(Some(file)) = crate::source::tiled::store::open_regular(&dir.join("info.json")) else { return false };
    file.take(MAX_DESCRIPTOR_BYTES).read_to_end(&mut head).is_ok() && looks_like_iiif(&head)
}

/// Opens the pyramid in the zip archive at `path`: with `order`, the z/y/x (or z/x/y) tiles;
/// otherwise a `.dzi` descriptor, then an IIIF `info.json`, then z/y/x zoom directories, at the
/// top or one folder down.
pub fn open_zip(path: &Path, order: Option<Order>) -> Result<Box<dyn TileGrid>> {
    let store = TileStore::zip(path)?;
    let mut folders = vec![String::new()];
    folders.extend(store.list("")?.into_iter().filter(|e| e.kind == Kind::Dir).map(|e| e.name));
    if let Some(order) = order {
        let roots = folders.iter().filter(|f| has_zoom_dirs(&store, f)).cloned().collect();
        let root = only(path, "folders of zoom directories", roots, |s: &String| s)?;
        return match root {
            Some(root) => Ok(Box::new(Xyz::open_in(store, &root, order)?)),
            None => Err(TilerError::decode(
                path,
                "holds no zoom directories named by a number, at the top or one folder down",
            )),
        };
    }
    let mut dzis = Vec::new();
    let mut infos = Vec::new();
    for folder in &folders {
        for entry in store.list(folder)?.into_iter().filter(|e| e.kind == Kind::File) {
            let rel = if folder.is_empty() { entry.name.clone() } else { format!("{folder}/{}", entry.name) };
            if entry.name.to_ascii_lowercase().ends_with(".dzi") {
                dzis.push(rel);
            } else if entry.name == "info.json" {
                infos.push((folder.clone(), rel));
            }
        }
    }
    if let Some(dzi) = only(path, "Deep Zoom descriptors", dzis, |s: &String| s)? {
        return Ok(Box::new(DeepZoom::open_in(store, &dzi)?));
    }
    if let Some((folder, rel)) = only(path, "info.json files", infos, |(_, rel): &(String, String)| rel)? {
        let head = store.read(&rel, MAX_DESCRIPTOR_BYTES)?.unwrap_or_default();
        if !looks_like_iiif(&head) {
            return Err(TilerError::unsupported(
                store.name(&rel),
                "is not a IIIF info.json; this tool's own tile directories are read unzipped",
            ));
        }
        return Ok(Box::new(Iiif::open_in(store, &folder)?));
    }
    let roots = folders.iter().filter(|f| has_zoom_dirs(&store, f)).cloned().collect();
    if let Some(root) = only(path, "folders of zoom directories", roots, |s: &String| s)? {
        return Ok(Box::new(Xyz::open_in(store, &root, Order::Zyx)?));
    }
    Err(TilerError::decode(
        path,
        "holds no tiled image this tool reads (a .dzi, an IIIF info.json or z/y/x zoom directories, at the top or one folder down)",
    ))
}

/// Whether `folder` holds a directory named by a number (a zoom level).
fn has_zoom_dirs(store: &TileStore, folder: &str) -> bool {
    store.list(folder).is_ok_and(|entries| {
        entries.iter().any(|e| e.kind == Kind::Dir && !e.name.is_empty() && e.name.bytes().all(|b| b.is_ascii_digit()))
    })
}

/// The one candidate, `None` for none, or an error naming them when there are several: the
/// archive does not say which one is meant. The top of the archive wins over its folders.
fn only<T>(path: &Path, what: &str, found: Vec<T>, name: impl Fn(&T) -> &str) -> Result<Option<T>> {
    let depth = |s: &T| name(s).matches('/').count() + usize::from(!name(s).is_empty());
    let Some(top) = found.iter().map(depth).min() else { return Ok(None) };
    let mut at_top: Vec<T> = found.into_iter().filter(|s| depth(s) == top).collect();
    if at_top.len() > 1 {
        let names: Vec<&str> = at_top.iter().map(&name).collect();
        return Err(TilerError::unsupported(
            path,
            format!("holds several {what} ({}); extract the one to convert", names.join(", ")),
        ));
    }
    Ok(at_top.pop())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::source::read_all;
    use crate::source::tiled::TiledSource;
    use crate::source::tiled::store::tests::write_zip;

    fn png(width: u32, height: u32, seed: u32) -> (Vec<u8>, Vec<u8>) {
        let texels = crate::source::tiled::noise((width * height * 3) as usize, seed);
        let mut out = Vec::new();
        image::write_buffer_with_format(
            &mut std::io::Cursor::new(&mut out),
            &texels,
            width,
            height,
            image::ExtendedColorType::Rgb8,
            image::ImageFormat::Png,
        )
        .unwrap();
        (texels, out)
    }

    fn read(grid: Box<dyn TileGrid>) -> Vec<u8> {
        read_all(&mut TiledSource::new(grid, vec![0; 3], true)).unwrap()
    }

    /// A zip's entries: names and bytes.
    type Entries<'a> = Vec<(&'a str, &'a [u8])>;

    const DZI: &str = r#"<Image TileSize="254" Overlap="1" Format="png"><Size Width="20" Height="10"/></Image>"#;

    #[test]
    fn finds_each_layout_at_the_top_or_one_folder_down() {
        let tmp = tempfile::tempdir().unwrap();
        let (texels, tile) = png(20, 10, 3);
        let iiif = r#"{"@context": "http://iiif.io/api/image/3/context.json", "width": 20, "height": 10,
                       "tiles": [{"width": 512, "scaleFactors": [1]}]}"#;
        let cases: [(&str, Entries, &str); 5] = [
            ("dz-top", vec![("dz.dzi", DZI.as_bytes()), ("dz_files/5/0_0.png", &tile)], "Deep Zoom"),
            ("dz-down", vec![("a/a.dzi", DZI.as_bytes()), ("a/a_files/5/0_0.png", &tile)], "Deep Zoom"),
            ("iiif", vec![("i/info.json", iiif.as_bytes()), ("i/full/20,10/0/default.png", &tile)], "IIIF"),
            ("google", vec![("g/0/0/0.png", &tile), ("g/blank.png", b"x"), ("vips-properties.xml", b"<x/>")], "z/y/x"),
            ("google-top", vec![("4/2/1.png", &tile)], "z/y/x"),
        ];
        for (name, entries, kind) in cases {
            let zip = tmp.path().join(format!("{name}.zip"));
            write_zip(&zip, &entries, name.contains("down"));
            assert!(is_zip(&zip));
            let grid = open_zip(&zip, None).unwrap();
            assert!(grid.describe().contains(kind) && grid.describe().contains(".zip"), "{name}: {}", grid.describe());
            assert!(read(grid) == texels, "{name}");
        }
        // z/x/y when asked for: the tile at 4/2/1.png is x 2, y 1.
        let zip = tmp.path().join("google-top.zip");
        let grid = open_zip(&zip, Some(Order::Zxy)).unwrap();
        assert!(grid.describe().contains("from x 2, y 1"), "{}", grid.describe());
    }

    #[test]
    fn ambiguous_or_empty_archives_are_errors() {
        let tmp = tempfile::tempdir().unwrap();
        let zip = tmp.path().join("two.zip");
        write_zip(&zip, &[("a/a.dzi", DZI.as_bytes()), ("b/b.dzi", DZI.as_bytes())], false);
        let e = open_zip(&zip, None).err().unwrap().to_string();
        assert!(e.contains("two.zip") && e.contains("several") && e.contains("a/a.dzi, b/b.dzi"), "{e}");
        let zip = tmp.path().join("none.zip");
        write_zip(&zip, &[("readme.txt", b"hello")], false);
        let e = open_zip(&zip, None).err().unwrap().to_string();
        assert!(e.contains("none.zip") && e.contains("holds no tiled image"), "{e}");
        let e = open_zip(&zip, Some(Order::Zyx)).err().unwrap().to_string();
        assert!(e.contains("holds no zoom directories"), "{e}");
        let zip = tmp.path().join("ours.zip");
        write_zip(&zip, &[("out/info.json", br#"{"tileSize": 256}"#)], false);
        let e = open_zip(&zip, None).err().unwrap().to_string();
        assert!(e.contains("ours.zip:out/info.json") && e.contains("not a IIIF"), "{e}");
    }

    #[test]
    fn sniffs_zips_without_the_extension() {
        let tmp = tempfile::tempdir().unwrap();
        let zip = tmp.path().join("tiles.bin");
        write_zip(&zip, &[("x", b"y")], false);
        assert!(is_zip(&zip));
        std::fs::write(tmp.path().join("not"), b"PNG").unwrap();
        assert!(!is_zip(&tmp.path().join("not")) && !is_zip(&tmp.path().join("absent")));
    }
}
