//! The viewer layouts: how Deep Zoom, IIIF and web-map (XYZ) viewers expect a pyramid's files
//! to be named and shaped, mapped onto the pages our pipeline cuts.
//!
//! Each layout is a view of the same page grid ([`Layout`]), so every level still comes from
//! the exact, streaming pipeline; what differs is the file name of page (lod, x, y), which part
//! of the stored page the viewer's tile keeps ([`Crop`]), the LODs a viewer asks for, and a
//! manifest (`NAME.dzi`, `info.json`, `tilejson.json`). `sink::ViewerSink` writes these files;
//! `serve` answers the same names from a pack.
//!
//! - [`dzi`]: Deep Zoom as `vips dzsave` writes it. Tile size = our payload, overlap = our
//!   border; an edge tile drops the border it has no neighbour for and stops at the image.
//! - [`iiif`]: IIIF Image API 3.0, level 0 (static tiles) as libvips 8.18 writes it.
//! - [`xyz`]: square power-of-two zoom levels, `{z}/{x}/{y}` (or `{z}/{y}/{x}` as vips'
//!   "google"), edge tiles padded with the background.

mod archive;
pub mod dzi;
pub mod iiif;
mod recognise;
pub mod xyz;

use std::fmt;

pub(crate) use crate::layout::Crop;
use crate::layout::Layout;

pub use archive::{is_iiif_dir, is_zip, open_zip};
pub(crate) use recognise::recognise;

/// A file layout a viewer opens directly (`--layout`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Viewer {
    /// `NAME.dzi` + `NAME_files/LEVEL/COL_ROW.EXT` (OpenSeadragon, Deep Zoom).
    Dzi,
    /// `info.json` + `{x},{y},{w},{h}/{w},{h}/0/default.EXT` (IIIF Image API 3.0, level 0).
    Iiif,
    /// `{z}/{x}/{y}.EXT` in square power-of-two levels (Leaflet, OpenLayers, MapLibre).
    Xyz,
    /// `{z}/{y}/{x}.EXT`, the order `vips dzsave --layout google` writes.
    Google,
}

impl Viewer {
    /// The layout's `--layout` value: `dzi`, `iiif`, `xyz` or `google`.
    pub fn name(self) -> &'static str {
        match self {
            Viewer::Dzi => "dzi",
            Viewer::Iiif => "iiif",
            Viewer::Xyz => "xyz",
            Viewer::Google => "google",
        }
    }

    /// The tile side a viewer of this layout expects by default (vips dzsave's defaults).
    pub(crate) fn default_tile_size(self) -> u32 {
        match self {
            Viewer::Dzi => dzi::DEFAULT_TILE_SIZE,
            Viewer::Iiif => iiif::DEFAULT_TILE_SIZE,
            Viewer::Xyz | Viewer::Google => xyz::DEFAULT_TILE_SIZE,
        }
    }

    /// The pipeline's page grid for a `width x height` image in this layout's tiles of
    /// `tile_size` texels (Deep Zoom: without the overlap) with `overlap` texels shared with
    /// each neighbour (Deep Zoom only; 0 elsewhere).
    pub fn page_grid(self, width: u32, height: u32, tile_size: u32, overlap: u32) -> crate::error::Result<Layout> {
        let stored = tile_size.checked_add(2 * overlap).ok_or_else(|| {
            crate::error::TilerError::Geometry(format!("tile size {tile_size} with overlap {overlap} is too large"))
        })?;
        let layout = Layout::new(width as u64, height as u64, stored, overlap)?;
        Ok(if self.down_to_one_texel() { layout.down_to_one_texel() } else { layout })
    }

    /// Whether the levels go on below one tile, down to 1 x 1 (Deep Zoom's do).
    pub fn down_to_one_texel(self) -> bool {
        self == Viewer::Dzi
    }

    /// The extension of a tile file: `jpeg` as vips writes Deep Zoom tiles, `jpg` elsewhere;
    /// `png` and `jxl` as they are.
    pub fn extension(self, codec_extension: &str) -> &'static str {
        match (self, codec_extension) {
            (_, "png") => "png",
            (_, "jxl") => "jxl",
            (Viewer::Dzi, _) => "jpeg",
            _ => "jpg",
        }
    }
}

impl fmt::Display for Viewer {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// One page as a viewer's file: where it goes under the output directory and what it keeps.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) struct Placed {
    pub path: String,
    /// A second name for the same bytes (IIIF's `full/max` of a one-tile image).
    pub alias: Option<String>,
    pub crop: Crop,
}

/// A pyramid in one viewer layout: the page grid it is cut from and its names.
#[derive(Clone, Debug)]
pub struct ViewerTiles {
    /// Which layout names the tiles.
    pub viewer: Viewer,
    /// The page grid the tiles are cut from (for Deep Zoom, down to one texel).
    pub layout: Layout,
    /// The pyramid's name: Deep Zoom's `NAME.dzi`, the XYZ TileJSON's `name`.
    pub name: String,
    /// Tile file extension, without the dot.
    pub extension: &'static str,
    /// IIIF: a conformant service at an absolute id (`--iiif-id`), or `None` for the
    /// relative id `.` and only the files libvips writes.
    pub iiif: Option<iiif::Service>,
}

impl ViewerTiles {
    /// Where page (lod, x, y) goes and which of its texels it keeps.
    pub(crate) fn place(&self, lod: u32, x: u32, y: u32) -> Placed {
        let (l, ext) = (&self.layout, self.extension);
        let (path, alias) = match self.viewer {
            Viewer::Dzi => (dzi::tile_path(&self.name, dzi::level_of(l, lod), x, y, ext), None),
            Viewer::Iiif => (iiif::tile_path(l, lod, x, y, ext), iiif::full_max_path(l, lod, ext)),
            Viewer::Xyz | Viewer::Google => (xyz::tile_path(self.viewer, l.lod_count - 1 - lod, x, y, ext), None),
        };
        Placed { path, alias, crop: self.crop(lod, x, y) }
    }

    /// Which texels of page (lod, x, y) its tile keeps (no file name made: the encoders ask
    /// this of every page).
    pub(crate) fn crop(&self, lod: u32, x: u32, y: u32) -> Crop {
        match self.viewer {
            Viewer::Dzi => dzi::crop(&self.layout, lod, x, y),
            Viewer::Iiif => iiif::crop(&self.layout, lod, x, y),
            Viewer::Xyz | Viewer::Google => Crop::whole(self.layout.tile_size),
        }
    }

    /// The files a IIIF service needs besides its tiles: `full/max` and each size it lists that
    /// no tile is (see [`iiif::whole`]), made from the tiles `read(path)` gives back. None for
    /// other layouts, or IIIF without a service.
    pub(crate) fn whole_images(
        &self,
        read: impl Fn(&str) -> Result<Vec<u8>, String>,
    ) -> Result<Vec<(String, Vec<u8>)>, String> {
        let (Viewer::Iiif, Some(service)) = (self.viewer, &self.iiif) else { return Ok(Vec::new()) };
        let (l, ext) = (&self.layout, self.extension);
        let max = iiif::max_lod(l);
        let mut files = Vec::new();
        for (lod, w, h) in iiif::whole_sizes(l) {
            let bytes = if lod + 1 == l.lod_count {
                // The coarsest LOD is one tile, written under this name already.
                read(&iiif::full_path(w, h, ext))?
            } else {
                let bytes = iiif::whole::assemble(l, lod, service.codec, |col, row| {
                    let path = iiif::tile_path(l, lod, col, row, ext);
                    let decoded = crate::decode::decode_tile(std::path::Path::new(&path), &read(&path)?)
                        .map_err(|e| e.to_string())?;
                    let whole = Crop { x: 0, y: 0, width: decoded.width, height: decoded.height };
                    Ok((decoded, whole))
                })?;
                files.push((iiif::full_path(w, h, ext), bytes.clone()));
                bytes
            };
            if lod == max && iiif::full_max_path(l, lod, ext).is_none() {
                files.push((iiif::max_path(ext), bytes));
            }
        }
        Ok(files)
    }

    /// The manifest files, as (path under the output directory, bytes).
    pub(crate) fn manifests(&self) -> Vec<(String, Vec<u8>)> {
        let l = &self.layout;
        match self.viewer {
            Viewer::Dzi => vec![(format!("{}.dzi", self.name), dzi::descriptor(l, self.extension).into_bytes())],
            Viewer::Iiif => {
                let id = self.iiif.as_ref().map_or(iiif::DEFAULT_ID, |s| s.id.as_str());
                vec![("info.json".into(), iiif::info_json(l, id, self.extension, self.iiif.is_some()).into_bytes())]
            }
            Viewer::Xyz | Viewer::Google => {
                vec![(xyz::TILEJSON.into(), xyz::tilejson(self.viewer, l, &self.name, self.extension).into_bytes())]
            }
        }
    }
}
