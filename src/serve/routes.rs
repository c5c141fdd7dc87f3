//! URLs into typed requests: which input, which layout, which tile; nothing here knows what
//! the inputs hold (that is `catalog` and `http`). Anything malformed is a [`Reject`] with a
//! status and a short reason, never a panic: numbers too large for a `u32`, percent-encoded
//! dots, empty or `.`/`..` segments, wrong extensions.

use std::fmt;

/// Why a request is answered with an error: 400 (malformed) or 404 (well formed, not here).
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Reject {
    BadRequest(String),
    NotFound(String),
}

impl fmt::Display for Reject {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Reject::BadRequest(m) => write!(f, "bad request: {m}"),
            Reject::NotFound(m) => write!(f, "not found: {m}"),
        }
    }
}

pub fn bad(message: impl Into<String>) -> Reject {
    Reject::BadRequest(message.into())
}

pub fn not_found(message: impl Into<String>) -> Reject {
    Reject::NotFound(message.into())
}

/// A request's path, decoded and split by what it asks for.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Route {
    /// `/`: the list of inputs.
    Index,
    /// `/view/NAME`: an OpenSeadragon page.
    View(String),
    /// `/openseadragon/REST`: the local copy of OpenSeadragon (`--openseadragon`).
    OpenSeadragon(Vec<String>),
    /// `/NAME.dzi`.
    DziDescriptor(String),
    /// `/NAME_files/REST...`: a Deep Zoom tile (or, for a directory, any file under it).
    DziFiles { name: String, rest: Vec<String> },
    /// `/NAME.vtpk`: the pack file.
    PackFile(String),
    /// `/NAME/iiif` (redirected to its `info.json`).
    IiifBase(String),
    /// `/NAME/iiif/REST...`: `info.json` or a tile.
    Iiif { name: String, rest: Vec<String> },
    /// `/NAME/xyz/REST...`.
    Xyz { name: String, rest: Vec<String> },
}

/// A Deep Zoom tile: `LEVEL/COL_ROW.EXT`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct DziTile {
    pub level: u32,
    pub col: u32,
    pub row: u32,
    pub extension: String,
}

/// A web-map tile: `Z/X/Y.EXT`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct XyzTile {
    pub zoom: u32,
    pub x: u32,
    pub y: u32,
    pub extension: String,
}

/// A IIIF level-0 tile: `RX,RY,RW,RH/W,H/0/default.EXT`, `full/W,H/0/default.EXT` or
/// `full/max/0/default.EXT`. Matched against the names `viewer::iiif` gives each page, so
/// only those exact names are tiles.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum IiifTile {
    Region { x: u64, y: u64, path: String },
    Full { path: String },
}

impl IiifTile {
    /// The extension of the tile's file name (`default.EXT`).
    pub fn extension(&self) -> &str {
        let (IiifTile::Region { path, .. } | IiifTile::Full { path }) = self;
        path.rsplit_once('.').map_or("", |(_, ext)| ext)
    }
}

/// Parses the path of a request URI (without the query).
pub fn parse(raw_path: &str) -> Result<Route, Reject> {
    let segments = segments(raw_path)?;
    let seg: Vec<&str> = segments.iter().map(String::as_str).collect();
    let owned = |s: &[&str]| s.iter().map(|v| v.to_string()).collect::<Vec<_>>();
    Ok(match seg.as_slice() {
        [] => Route::Index,
        ["view", name] => Route::View(name.to_string()),
        ["openseadragon", rest @ ..] if !rest.is_empty() => Route::OpenSeadragon(owned(rest)),
        [name, "iiif"] => Route::IiifBase(name.to_string()),
        [name, "iiif", rest @ ..] => Route::Iiif { name: name.to_string(), rest: owned(rest) },
        [name, "xyz", rest @ ..] if !rest.is_empty() => Route::Xyz { name: name.to_string(), rest: owned(rest) },
        [file] => match file.rsplit_once('.') {
            Some((name, "dzi")) if !name.is_empty() => Route::DziDescriptor(name.to_string()),
            Some((name, "vtpk")) if !name.is_empty() => Route::PackFile(name.to_string()),
            _ => return Err(not_found(format!("/{file}"))),
        },
        [first, rest @ ..] => match first.strip_suffix("_files") {
            Some(name) if !name.is_empty() => Route::DziFiles { name: name.to_string(), rest: owned(rest) },
            _ => return Err(not_found(format!("/{}", seg.join("/")))),
        },
    })
}

/// The path's segments, percent-decoded. A trailing slash is ignored; empty, `.` and `..`
/// segments (encoded or not), backslashes and control characters are refused.
pub fn segments(raw_path: &str) -> Result<Vec<String>, Reject> {
    let path = raw_path.strip_prefix('/').ok_or_else(|| bad("the path must start with /"))?;
    let path = path.strip_suffix('/').unwrap_or(path);
    if path.is_empty() {
        return Ok(Vec::new());
    }
    path.split('/')
        .map(|raw| {
            let s = percent_decode(raw)?;
            if s.is_empty() || s == "." || s == ".." {
                return Err(bad("empty, . and .. path segments are not allowed"));
            }
            if s.contains(['/', '\\']) || s.chars().any(char::is_control) {
                return Err(bad("a path segment holds a slash, backslash or control character"));
            }
            Ok(s)
        })
        .collect()
}

fn percent_decode(s: &str) -> Result<String, Reject> {
    let b = s.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'%' {
            let hex = b.get(i + 1..i + 3).and_then(|h| std::str::from_utf8(h).ok());
            let byte = hex
                .and_then(|h| u8::from_str_radix(h, 16).ok())
                .ok_or_else(|| bad("a % in the path is not followed by two hex digits"))?;
            out.push(byte);
            i += 3;
        } else {
            out.push(b[i]);
            i += 1;
        }
    }
    String::from_utf8(out).map_err(|_| bad("the path is not UTF-8"))
}

/// A decimal `u32`: digits only (no sign, no spaces); too large is a 400, not a wrap.
pub fn number(s: &str, what: &str) -> Result<u32, Reject> {
    if s.is_empty() || !s.bytes().all(|b| b.is_ascii_digit()) {
        return Err(bad(format!("{what} '{s}' is not a number")));
    }
    s.parse().map_err(|_| bad(format!("{what} {s} is out of range")))
}

fn number_u64(s: &str, what: &str) -> Result<u64, Reject> {
    if s.is_empty() || !s.bytes().all(|b| b.is_ascii_digit()) {
        return Err(bad(format!("{what} '{s}' is not a number")));
    }
    s.parse().map_err(|_| bad(format!("{what} {s} is out of range")))
}

/// `STEM.EXT` split at the last dot, both non-empty.
fn stem_and_extension<'a>(file: &'a str, what: &str) -> Result<(&'a str, &'a str), Reject> {
    file.rsplit_once('.')
        .filter(|(s, e)| !s.is_empty() && !e.is_empty())
        .ok_or_else(|| bad(format!("{what} '{file}' has no extension")))
}

/// `LEVEL/COL_ROW.EXT` under `NAME_files/`.
pub fn dzi_tile(rest: &[String]) -> Result<DziTile, Reject> {
    let [level, file] = rest else {
        return Err(not_found("a Deep Zoom tile is NAME_files/LEVEL/COL_ROW.EXT"));
    };
    let (stem, extension) = stem_and_extension(file, "tile")?;
    let (col, row) = stem.split_once('_').ok_or_else(|| bad(format!("tile '{file}' is not COL_ROW.EXT")))?;
    Ok(DziTile {
        level: number(level, "level")?,
        col: number(col, "column")?,
        row: number(row, "row")?,
        extension: extension.to_string(),
    })
}

/// `Z/X/Y.EXT` under `NAME/xyz/`.
pub fn xyz_tile(rest: &[String]) -> Result<XyzTile, Reject> {
    let [z, x, file] = rest else {
        return Err(not_found("a web-map tile is NAME/xyz/Z/X/Y.EXT"));
    };
    let (y, extension) = stem_and_extension(file, "tile")?;
    Ok(XyzTile { zoom: number(z, "zoom")?, x: number(x, "x")?, y: number(y, "y")?, extension: extension.to_string() })
}

/// A IIIF tile path under `NAME/iiif/` (anything but `info.json`).
pub fn iiif_tile(rest: &[String]) -> Result<IiifTile, Reject> {
    let path = rest.join("/");
    let shape_error = || not_found(format!("'{path}' is not a IIIF level-0 tile of this image"));
    let [region, size, rotation, quality] = rest else {
        return Err(shape_error());
    };
    if rotation != "0" || !quality.starts_with("default.") {
        return Err(shape_error());
    }
    if region == "full" {
        if size != "max" {
            let (w, h) = size.split_once(',').ok_or_else(shape_error)?;
            number(w, "width")?;
            number(h, "height")?;
        }
        return Ok(IiifTile::Full { path });
    }
    let parts: Vec<&str> = region.split(',').collect();
    let [x, y, w, h] = parts[..] else {
        return Err(bad(format!("region '{region}' is not x,y,w,h")));
    };
    let (x, y) = (number_u64(x, "region x")?, number_u64(y, "region y")?);
    number_u64(w, "region width")?;
    number_u64(h, "region height")?;
    Ok(IiifTile::Region { x, y, path })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn v(s: &[&str]) -> Vec<String> {
        s.iter().map(|x| x.to_string()).collect()
    }

    #[test]
    fn routes_by_shape() {
        assert_eq!(parse("/"), Ok(Route::Index));
        assert_eq!(parse("/view/world"), Ok(Route::View("world".into())));
        assert_eq!(parse("/world.dzi"), Ok(Route::DziDescriptor("world".into())));
        assert_eq!(parse("/world.vtpk"), Ok(Route::PackFile("world".into())));
        assert_eq!(
            parse("/world_files/12/3_4.jpeg"),
            Ok(Route::DziFiles { name: "world".into(), rest: v(&["12", "3_4.jpeg"]) })
        );
        assert_eq!(parse("/world/iiif"), Ok(Route::IiifBase("world".into())));
        assert_eq!(parse("/world/iiif/info.json"), Ok(Route::Iiif { name: "world".into(), rest: v(&["info.json"]) }));
        assert_eq!(parse("/w/xyz/1/0/1.png"), Ok(Route::Xyz { name: "w".into(), rest: v(&["1", "0", "1.png"]) }));
        assert_eq!(parse("/openseadragon/images/home.png"), Ok(Route::OpenSeadragon(v(&["images", "home.png"]))));
        // Percent-encoded names are decoded.
        assert_eq!(parse("/my%20map.dzi"), Ok(Route::DziDescriptor("my map".into())));
    }

    #[test]
    fn refuses_traversal_and_garbage() {
        for p in [
            "/../etc/passwd",
            "/a/../b",
            "/%2e%2e/x",
            "/a/%2E%2E/b",
            "/a//b",
            "/a/./b",
            "/a%2fb/c",
            "/a%5cb",
            "/%zz",
            "/%e2%28",
            "x",
        ] {
            assert!(matches!(parse(p), Err(Reject::BadRequest(_))), "{p}: {:?}", parse(p));
        }
        assert!(matches!(parse("/nothing"), Err(Reject::NotFound(_))));
        assert!(matches!(parse("/a/b/c"), Err(Reject::NotFound(_))));
        assert!(matches!(parse("/.dzi"), Err(Reject::NotFound(_))));
    }

    #[test]
    fn tile_numbers_are_checked_not_wrapped() {
        let t = dzi_tile(&v(&["12", "3_4.jpeg"])).unwrap();
        assert_eq!(t, DziTile { level: 12, col: 3, row: 4, extension: "jpeg".into() });
        assert!(matches!(dzi_tile(&v(&["99999999999999999999", "0_0.jpeg"])), Err(Reject::BadRequest(_))));
        assert!(matches!(dzi_tile(&v(&["4294967296", "0_0.jpeg"])), Err(Reject::BadRequest(_))));
        assert_eq!(dzi_tile(&v(&["4294967295", "0_0.png"])).unwrap().level, u32::MAX);
        for bad_tile in [
            ["1", "-1_0.jpeg"],
            ["1", "+1_0.jpeg"],
            ["1", "0x1_0.jpeg"],
            ["1", "00.jpeg"],
            ["1", "0_0"],
            ["", "0_0.png"],
        ] {
            assert!(matches!(dzi_tile(&v(&bad_tile)), Err(Reject::BadRequest(_))), "{bad_tile:?}");
        }
        assert!(matches!(dzi_tile(&v(&["1"])), Err(Reject::NotFound(_))));
        assert_eq!(
            xyz_tile(&v(&["2", "1", "3.png"])).unwrap(),
            XyzTile { zoom: 2, x: 1, y: 3, extension: "png".into() }
        );
        assert!(matches!(xyz_tile(&v(&["2", "1", "99999999999.png"])), Err(Reject::BadRequest(_))));
    }

    #[test]
    fn iiif_tiles() {
        assert_eq!(
            iiif_tile(&v(&["512,1024,512,300", "512,300", "0", "default.jpg"])),
            Ok(IiifTile::Region { x: 512, y: 1024, path: "512,1024,512,300/512,300/0/default.jpg".into() })
        );
        assert!(matches!(iiif_tile(&v(&["full", "max", "0", "default.png"])), Ok(IiifTile::Full { .. })));
        assert!(matches!(iiif_tile(&v(&["full", "10,10", "90", "default.png"])), Err(Reject::NotFound(_))));
        assert!(matches!(iiif_tile(&v(&["1,2,3", "1,1", "0", "default.png"])), Err(Reject::BadRequest(_))));
        assert!(matches!(
            iiif_tile(&v(&["99999999999999999999,0,1,1", "1,1", "0", "default.png"])),
            Err(Reject::BadRequest(_))
        ));
    }
}
