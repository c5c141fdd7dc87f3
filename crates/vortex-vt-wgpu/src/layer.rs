//! Layer stacks: several textures on one page grid (albedo, normal, roughness) bound as one
//! virtual texture with several layers. The layers share everything that decides residency: one
//! feedback word per sample, one page table, one residency decision per page, one slot number.
//! Each layer has its own physical cache (in the format that suits it) and its own loader, and a
//! page is uploaded and mapped only once every layer's tile of it has landed: no page-table
//! entry is ever valid for one layer and not another, and the table is written once per page,
//! not once per layer.
//!
//! A layer is given layer-major: layer `k` holds one source per texture id, so texture `t` of a
//! runtime is the stack of every layer's source `t`, which must all have the same grid.

use std::sync::Arc;

use crate::source::PageSource;

/// The most layers a runtime binds (WGSL has no arrays of textures of different formats without
/// a device feature, so each layer is its own binding).
pub const MAX_LAYERS: usize = 4;

/// What a layer's texels are, which decides how the cache holds and filters them.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum LayerKind {
    /// sRGB-encoded colour with straight alpha (albedo): premultiplied on load and filtered in
    /// linear light through an sRGB view, held as BC where the device samples it.
    #[default]
    Colour,
    /// Values that are not colour (normals, roughness, heights): held as stored in RGBA8 and
    /// filtered as stored, never premultiplied nor sRGB-decoded (a normal map decoded as sRGB
    /// bends every normal).
    Data,
}

impl LayerKind {
    /// The kind in a word (`colour`, `data`), as scenes and the command line spell it.
    pub fn name(self) -> &'static str {
        match self {
            LayerKind::Colour => "colour",
            LayerKind::Data => "data",
        }
    }

    /// The kind `name` names (`colour`, `data`).
    pub fn from_name(name: &str) -> Option<LayerKind> {
        [LayerKind::Colour, LayerKind::Data].into_iter().find(|k| k.name() == name)
    }
}

/// One layer of every texture of a runtime: `sources[t]` is texture `t`'s.
#[derive(Clone)]
pub struct Layer {
    /// Colour or data.
    pub kind: LayerKind,
    /// Texture `t`'s pages of this layer at index `t`.
    pub sources: Vec<Arc<dyn PageSource>>,
}

impl Layer {
    /// A colour layer of `sources`.
    pub fn colour(sources: Vec<Arc<dyn PageSource>>) -> Layer {
        Layer { kind: LayerKind::Colour, sources }
    }

    /// A data layer of `sources` (normals, roughness: filtered as stored).
    pub fn data(sources: Vec<Arc<dyn PageSource>>) -> Layer {
        Layer { kind: LayerKind::Data, sources }
    }
}

impl std::fmt::Debug for Layer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let locations: Vec<_> = self.sources.iter().map(|s| s.location().to_path_buf()).collect();
        f.debug_struct("Layer").field("kind", &self.kind).field("sources", &locations).finish()
    }
}
