//! The inputs `serve` was started with: what each one is (a pack, a split directory, or a
//! directory already in a viewer layout), its name in URLs, and how to read its pages.
//!
//! Everything is opened and checked once at start, so a missing file, a file that is not a
//! pack, or two inputs of the same name stop the server before it listens.

use std::fs;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use bytes::Bytes;
use vortex_pack::{Pack, Tile, TileKind};

use super::ServeError;
use super::files::{self, Refused};
use super::tiles::{Format, Page};
use crate::codec::{Codec, PngLevel, Subsampling};
use crate::decode::Decoded;
use crate::error::ShowPath;
use crate::formats::tiles::filename::FilenameFormat;
use crate::formats::tiles::info::InfoFile;
use crate::formats::tiles::{TiledDir, codec_of};
use crate::formats::viewer::xyz;
use crate::layout::Layout;
use crate::pixel::{Channels, Depth, PixelLayout};

/// JPEG quality of re-encoded tiles when the input does not record its own.
pub const DEFAULT_QUALITY: u8 = 90;
/// The largest manifest read (`info.json`, `tilejson.json`, `.dzi`).
const MAX_MANIFEST_BYTES: u64 = 1 << 20;

/// The inputs a server answers for, each under its name in URLs: a pack's file stem, a
/// directory's name.
pub struct Catalog {
    pub(crate) inputs: Vec<Input>,
}

pub struct Input {
    /// The file stem (a directory's name): `/NAME.dzi`, `/NAME/iiif/...`.
    pub name: String,
    pub path: PathBuf,
    pub source: Source,
}

pub enum Source {
    /// Pages this server cuts viewer tiles from (a pack or a split directory).
    Tiled(Tiled),
    /// A directory in a viewer layout, served as its files.
    Static(StaticDir),
}

/// A pyramid of pages: the pack's grid, its tiles' format and where the pages come from.
pub struct Tiled {
    pub store: Store,
    /// The page grid (the pack's: LODs down to one page).
    pub layout: Layout,
    pub pixels: PixelLayout,
    /// What tiles are served as: JPEG for JPEG inputs, PNG for every other.
    pub format: Format,
    /// How re-encoded tiles are encoded.
    pub codec: Codec,
    /// The pack's content hash, or a hash of the directory's `info.json`.
    pub etag: u64,
}

pub enum Store {
    Pack(Arc<Pack>),
    Dir { dir: PathBuf, names: FilenameFormat },
}

pub struct StaticDir {
    /// Canonical: every file served must lie under it.
    pub root: PathBuf,
    pub layout: StaticLayout,
    /// A hash of the manifest.
    pub etag: u64,
    pub size: Option<(u64, u64)>,
}

pub enum StaticLayout {
    /// `STEM.dzi` + `STEM_files/` in the directory.
    Dzi { stem: String },
    /// `info.json` (IIIF level 0) + tiles; the manifest, its `id` rewritten per request.
    Iiif { info: serde_json::Value },
    /// `tilejson.json` + `{z}/{x}/{y}` (or `{z}/{y}/{x}`) tiles.
    Xyz,
}

impl Catalog {
    /// Opens every input (a pack, a tile directory, a viewer layout's directory): refuses
    /// one it cannot serve, and two that would have the same name.
    pub fn open(paths: &[PathBuf]) -> Result<Catalog, ServeError> {
        let mut inputs: Vec<Input> = Vec::new();
        for path in paths {
            let input = open_input(path)?;
            if let Some(first) = inputs.iter().find(|i| i.name == input.name) {
                return Err(ServeError::DuplicateName {
                    name: input.name,
                    first: first.path.clone(),
                    second: path.clone(),
                });
            }
            inputs.push(input);
        }
        Ok(Catalog { inputs })
    }
}

fn open_input(path: &Path) -> Result<Input, ServeError> {
    let fail = |message: String| ServeError::Input { path: path.to_path_buf(), message };
    let meta = fs::metadata(path).map_err(|e| fail(e.to_string()))?;
    // A FIFO would block the open until a writer comes; a device is no pack.
    if !meta.is_dir() && !meta.is_file() {
        return Err(fail("is neither a regular file (a pack) nor a directory".into()));
    }
    let canonical = fs::canonicalize(path).map_err(|e| fail(e.to_string()))?;
    let name = if meta.is_dir() { canonical.file_name() } else { canonical.file_stem() }
        .and_then(|n| n.to_str())
        .ok_or_else(|| fail("has no UTF-8 name to serve it under".into()))?
        .to_string();
    if name.is_empty() || name.starts_with('.') || name.contains(['/', '\\', '%', '?', '#']) {
        return Err(fail(format!("'{name}' cannot be a name in a URL (no leading dot, /, \\, %, ? or #)")));
    }
    if name == "view" || name == "openseadragon" {
        return Err(fail(format!("'{name}' is a path of the server itself; rename the input")));
    }
    let source = if meta.is_dir() { open_dir(&canonical).map_err(fail)? } else { open_pack(path).map_err(fail)? };
    Ok(Input { name, path: path.to_path_buf(), source })
}

fn open_pack(path: &Path) -> Result<Source, String> {
    let pack = Pack::open(path).map_err(|e| format!("not a pack this tool can read: {e}"))?;
    crate::shard::manifest::refuse_shard(path, pack.metadata()).map_err(|e| match e {
        // The caller names the path.
        crate::error::TilerError::Shard { message, .. } => message,
        e => e.to_string(),
    })?;
    let d = *pack.description();
    let layout = Layout::new(d.width as u64, d.height as u64, d.tile_size, d.border).map_err(|e| e.to_string())?;
    let levels = pack.levels();
    if (levels.len() as u32) < layout.lod_count
        || (0..layout.lod_count).any(|l| {
            let (c, r) = layout.grid(l);
            levels[l as usize].tiles_w < c || levels[l as usize].tiles_h < r
        })
    {
        return Err(format!(
            "its level table does not hold the {} LODs of a {}x{} image in {}-texel tiles with border {}",
            layout.lod_count, d.width, d.height, d.tile_size, d.border
        ));
    }
    let info: Option<InfoFile> = serde_json::from_slice(pack.metadata()).ok();
    let first_kind = pack.ids().take(64).find_map(|id| match pack.tile(id) {
        Ok(Tile::Data(kind, _)) => Some(kind),
        _ => None,
    });
    let codec = info.as_ref().and_then(|i| codec_of(i, None)).unwrap_or(match first_kind {
        Some(TileKind::Jpeg) => Codec::Jpeg { quality: DEFAULT_QUALITY, subsampling: Subsampling::S420 },
        Some(TileKind::Jxl) => Codec::Jxl { quality: None, effort: SERVED_JXL_EFFORT },
        _ => Codec::Png { level: PngLevel::Fast },
    });
    let (pixels, etag) = (crate::formats::tiles::layout_of(&d), pack.header().content_hash);
    Ok(Source::Tiled(served(Store::Pack(Arc::new(pack)), layout, pixels, codec, etag)))
}

/// `--jxl-effort` of a JPEG XL tile made while a browser waits (a cropped or halved page):
/// libjxl's fastest.
const SERVED_JXL_EFFORT: crate::codec::JxlEffort = crate::codec::JxlEffort::clamped(1);

/// The tiles of a pyramid whose pages are `codec`: JPEG stays JPEG (at its quality), JPEG XL
/// stays JPEG XL (at its quality or lossless), anything else is served as PNG.
fn served(store: Store, layout: Layout, pixels: PixelLayout, codec: Codec, etag: u64) -> Tiled {
    let (format, codec) = match codec {
        Codec::Jpeg { quality, subsampling } => (Format::Jpeg, Codec::Jpeg { quality, subsampling }),
        Codec::Jxl { quality, .. } => (Format::Jxl, Codec::Jxl { quality, effort: SERVED_JXL_EFFORT }),
        _ => (Format::Png, Codec::Png { level: PngLevel::Fast }),
    };
    Tiled { store, layout, pixels, format, codec, etag }
}

impl Tiled {
    /// The pack, if this is one.
    pub fn pack(&self) -> Option<&Arc<Pack>> {
        match &self.store {
            Store::Pack(p) => Some(p),
            Store::Dir { .. } => None,
        }
    }

    /// Page (lod, x, y) as stored; `Ok(None)` if the input has no such page. Reads a file for a
    /// directory and decodes raw, zstd and BC payloads: call it off the async threads.
    pub fn page(&self, lod: u32, x: u32, y: u32) -> Result<Option<Page>, String> {
        match &self.store {
            Store::Pack(pack) => pack_page(pack, lod, x, y),
            Store::Dir { dir, names } => {
                let path = dir.join(names.format(&[lod, x, y]));
                match files::read_under(dir, &path, self.max_page_file_bytes()) {
                    Ok(bytes) => Ok(Some(Page::Image(self.format, Bytes::from(bytes)))),
                    Err(Refused::Missing) => Ok(None),
                    Err(Refused::Refused(message)) => Err(message),
                }
            }
        }
    }
}

impl Tiled {
    /// The largest tile file of a split directory read: a compressed page is at most a little
    /// over its raw texels, so twice them and a MiB leave room for any encoder's overhead
    /// while a file that is no tile (a link to a disk image, `/dev/zero`) is refused unread.
    fn max_page_file_bytes(&self) -> u64 {
        let side = self.layout.tile_size as u64;
        side * side * self.pixels.bytes_per_pixel() as u64 * 2 + (1 << 20)
    }
}

/// A JPEG, PNG or JPEG XL payload of `pack`, its checksum checked, as bytes that borrow its memory map
/// (no copy); `None` for any other tile, and for a damaged one (which the decoding path then
/// reports).
pub fn stored_image(pack: &Arc<Pack>, lod: u32, x: u32, y: u32) -> Option<(Format, Bytes)> {
    image_of(pack, &pack.tile_checked(vortex_pack::TileId::new(lod, x, y)).ok()?)
}

/// A JPEG, PNG or JPEG XL tile of `pack` as bytes that borrow its memory map.
fn image_of(pack: &Arc<Pack>, tile: &Tile) -> Option<(Format, Bytes)> {
    let (format, bytes) = match tile {
        Tile::Data(TileKind::Jpeg, b) => (Format::Jpeg, b),
        Tile::Data(TileKind::Png, b) => (Format::Png, b),
        Tile::Data(TileKind::Jxl, b) => (Format::Jxl, b),
        _ => return None,
    };
    let start = (bytes.as_ptr() as usize).checked_sub(pack.file().as_ptr() as usize)?;
    Some((format, map_slice(pack, start, bytes.len())))
}

/// `len` bytes of the pack's file from `start`, sharing its memory map.
pub fn map_slice(pack: &Arc<Pack>, start: usize, len: usize) -> Bytes {
    struct Slice {
        pack: Arc<Pack>,
        start: usize,
        len: usize,
    }
    impl AsRef<[u8]> for Slice {
        fn as_ref(&self) -> &[u8] {
            self.pack.file().get(self.start..self.start + self.len).unwrap_or(&[])
        }
    }
    Bytes::from_owner(Slice { pack: pack.clone(), start, len })
}

fn pack_page(pack: &Arc<Pack>, lod: u32, x: u32, y: u32) -> Result<Option<Page>, String> {
    let d = pack.description();
    let tile = match pack.tile_checked(vortex_pack::TileId::new(lod, x, y)) {
        Ok(t) => t,
        Err(vortex_pack::PackError::OutOfRange { .. }) => return Ok(None),
        Err(e) => return Err(e.to_string()),
    };
    let pixels = crate::formats::tiles::layout_of(d);
    let side = d.tile_size;
    let texels = |bytes: Vec<u8>| Decoded { width: side, height: side, layout: pixels, bytes: native(bytes, pixels) };
    Ok(Some(match tile {
        Tile::Absent => return Ok(None),
        Tile::Constant(value) => {
            let n = side as usize * side as usize;
            Page::Texels(texels(value.iter().copied().cycle().take(n * value.len()).collect()))
        }
        Tile::Data(TileKind::Jpeg | TileKind::Png | TileKind::Jxl, _) => {
            let (format, bytes) = image_of(pack, &tile).ok_or("the payload lies outside the pack's file")?;
            Page::Image(format, bytes)
        }
        Tile::Data(kind, bytes) => {
            let limit = vortex_pack::DEFAULT_MAX_DECODED_BYTES;
            Page::Texels(texels(Tile::Data(kind, bytes).decode_texels(d, limit).map_err(|e| e.to_string())?))
        }
    }))
}

/// Little-endian samples (a pack's) as native-endian ones.
fn native(mut bytes: Vec<u8>, pixels: PixelLayout) -> Vec<u8> {
    if pixels.depth == Depth::U16 && cfg!(target_endian = "big") {
        for sample in bytes.chunks_exact_mut(2) {
            sample.swap(0, 1);
        }
    }
    bytes
}

/// A manifest of the directory `dir` (canonical): a regular file inside it, as every file
/// served from it.
fn read_manifest(dir: &Path, name: &str) -> Result<Vec<u8>, String> {
    let path = dir.join(name);
    files::read_under(dir, &path, MAX_MANIFEST_BYTES).map_err(|e| match e {
        Refused::Missing => format!("{}: not found", path.shown()),
        Refused::Refused(message) => message,
    })
}

fn hash(bytes: &[u8]) -> u64 {
    crate::fnv::hash(bytes)
}

/// A split directory (our `info.json`), or a directory in a viewer layout.
fn open_dir(dir: &Path) -> Result<Source, String> {
    let info_path = dir.join("info.json");
    if info_path.is_file() {
        let text = read_manifest(dir, "info.json")?;
        let json: serde_json::Value =
            serde_json::from_slice(&text).map_err(|e| format!("{}: not JSON: {e}", info_path.shown()))?;
        if json.get("@context").is_some() {
            let size = json["width"].as_u64().zip(json["height"].as_u64());
            return Ok(Source::Static(StaticDir {
                root: dir.to_path_buf(),
                layout: StaticLayout::Iiif { info: json },
                etag: hash(&text),
                size,
            }));
        }
        let t = TiledDir::read(dir).map_err(|e| e.to_string())?;
        let d = t.description;
        let layout = Layout::new(d.width as u64, d.height as u64, d.tile_size, d.border).map_err(|e| e.to_string())?;
        let pixels = crate::formats::tiles::layout_of(&d);
        // A JPEG pyramid is 8-bit whatever tileType says.
        let pixels = if t.codec.name() == "jpeg" { PixelLayout::new(pixels.channels, Depth::U8) } else { pixels };
        let store = Store::Dir { dir: dir.to_path_buf(), names: t.names };
        return Ok(Source::Tiled(served(store, layout, pixels, t.codec, hash(&text))));
    }
    let tilejson = dir.join(xyz::TILEJSON);
    if tilejson.is_file() {
        let text = read_manifest(dir, xyz::TILEJSON)?;
        let json: serde_json::Value =
            serde_json::from_slice(&text).map_err(|e| format!("{}: not JSON: {e}", tilejson.shown()))?;
        let v = &json["vortex"];
        let size = v["width"].as_u64().zip(v["height"].as_u64());
        return Ok(Source::Static(StaticDir {
            root: dir.to_path_buf(),
            layout: StaticLayout::Xyz,
            etag: hash(&text),
            size,
        }));
    }
    let dzis: Vec<String> = fs::read_dir(dir)
        .map_err(|e| format!("{}: {e}", dir.shown()))?
        .filter_map(|e| e.ok()?.file_name().into_string().ok())
        .filter_map(|n| n.strip_suffix(".dzi").map(str::to_string))
        .filter(|stem| dir.join(format!("{stem}_files")).is_dir())
        .collect();
    match dzis.as_slice() {
        [stem] => {
            let text = read_manifest(dir, &format!("{stem}.dzi"))?;
            let s = String::from_utf8_lossy(&text);
            let attr = |name: &str| -> Option<u64> {
                let at = s.find(&format!("{name}=\""))? + name.len() + 2;
                s[at..].split('"').next()?.parse().ok()
            };
            let size = attr("Width").zip(attr("Height"));
            Ok(Source::Static(StaticDir {
                root: dir.to_path_buf(),
                layout: StaticLayout::Dzi { stem: stem.clone() },
                etag: hash(&text),
                size,
            }))
        }
        [] => Err("is neither a split directory (info.json), nor a Deep Zoom (NAME.dzi + NAME_files), IIIF (info.json) or XYZ (tilejson.json) directory".into()),
        _ => Err(format!("holds {} Deep Zoom pyramids; serve one directory per pyramid", dzis.len())),
    }
}

/// What an input is, for the index page.
pub fn describe(source: &Source) -> String {
    match source {
        Source::Tiled(t) => {
            let what = if t.pack().is_some() { "pack" } else { "split directory" };
            let channels = match t.pixels.channels {
                Channels::Grey => "grey",
                Channels::GreyAlpha => "grey+alpha",
                Channels::Rgb => "RGB",
                Channels::Rgba => "RGBA",
            };
            format!("{what}, {channels}, {} tiles", t.codec.name())
        }
        Source::Static(s) => match s.layout {
            StaticLayout::Dzi { .. } => "Deep Zoom directory".into(),
            StaticLayout::Iiif { .. } => "IIIF level-0 directory".into(),
            StaticLayout::Xyz => "XYZ directory".into(),
        },
    }
}
