//! Building blocks for tests and measurement programs (behind the `testing` feature): a LOD
//! chain reduced as the tiler's `box` filter reduces it, a page's stored tile with its border
//! laid out as the tiler lays it out, and a pack of every page. With them a test knows exactly
//! what the page cache must hold and what the reference sampler must give, without running the
//! tiler.
//!
//! A feature rather than a test helper so that the crate's own tests and the measurement crate
//! (`vortex-bench`) share one definition; it pulls in the pack writer, which the runtime itself
//! never needs. Lavapipe pinning is not here but in [`crate::device`], since the command-line
//! tests of `vortex-tiler render` need it without this feature.

use std::path::Path;
use std::sync::{Arc, Condvar, Mutex, MutexGuard, PoisonError};
use std::time::Duration;

use vortex_pack::{Description, Level, NewTile, Pack, PackError, PackWriter, TileId, TileKind, WriteOptions};
use vortex_vt::page::PageId;
use vortex_vt::sampler::{LodChain, LodImages, Rgba8Image};

use crate::source::{Delayed, PageSource, ReadError};
use crate::texture::VirtualTexture;

/// A gate that the reads of a [`gated`] source wait at while it is closed: a test holds reads
/// in flight for as long as it likes and knows when they have started, so that what must not
/// wait for a read ("a frame never waits", "a queued load is taken back") is shown without
/// sleeping or timing anything.
#[derive(Debug, Default)]
pub struct Gate {
    state: Mutex<GateState>,
    changed: Condvar,
}

#[derive(Debug, Default)]
struct GateState {
    open: bool,
    /// Reads waiting at the closed gate now.
    waiting: usize,
}

/// The longest a read waits at a closed gate: a test that never opens it (or fails while it is
/// closed) ends with errored reads instead of hanging. No test relies on it.
pub const GATE_FAIL_SAFE: Duration = Duration::from_secs(60);

impl Gate {
    /// A closed gate.
    pub fn closed() -> Arc<Gate> {
        Arc::new(Gate::default())
    }

    /// An open gate.
    pub fn opened() -> Arc<Gate> {
        let gate = Gate::default();
        gate.lock().open = true;
        Arc::new(gate)
    }

    fn lock(&self) -> MutexGuard<'_, GateState> {
        self.state.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// Lets the waiting reads through, and every read after them until [`Gate::close`].
    pub fn open(&self) {
        self.lock().open = true;
        self.changed.notify_all();
    }

    /// Holds every read from now on (those already past the gate go on).
    pub fn close(&self) {
        self.lock().open = false;
    }

    /// Reads waiting at the closed gate now.
    pub fn waiting(&self) -> usize {
        self.lock().waiting
    }

    /// Waits until at least `n` reads wait at the gate; `false` if they do not within
    /// `fail_safe` (a bound against a hang, not a measurement).
    pub fn wait_for_readers(&self, n: usize, fail_safe: Duration) -> bool {
        let state = self.lock();
        let (state, _) = self
            .changed
            .wait_timeout_while(state, fail_safe, |s| s.waiting < n)
            .unwrap_or_else(PoisonError::into_inner);
        state.waiting >= n
    }

    /// Returns once the gate is open, or with an error after [`GATE_FAIL_SAFE`].
    fn pass(&self) -> Result<(), ReadError> {
        let mut state = self.lock();
        if state.open {
            return Ok(());
        }
        state.waiting += 1;
        self.changed.notify_all();
        let (mut state, _) =
            self.changed.wait_timeout_while(state, GATE_FAIL_SAFE, |s| !s.open).unwrap_or_else(PoisonError::into_inner);
        state.waiting -= 1;
        match state.open {
            true => Ok(()),
            false => Err(ReadError::unavailable(format!("the test never opened the gate in {GATE_FAIL_SAFE:?}"))),
        }
    }
}

/// `inner`, each read waiting at `gate` while it is closed (decoding does not wait: the memory
/// tier's tiles come through at once, as with [`Delayed`]'s latency).
pub fn gated(inner: Arc<dyn PageSource>, gate: Arc<Gate>) -> Delayed {
    Delayed::with_wait(inner, move || gate.pass())
}

/// `lods` levels: `lod0`, then each level the mean of the (up to) 2x2 texels of the one above
/// that it covers, in code values, rounded half up (the tiler's `box` filter, cascaded): level
/// k + 1 is `ceil(w_k / 2) x ceil(h_k / 2)`, anchored at the top-left, and a texel on an odd
/// edge averages the one or two texels it covers.
pub fn box_chain(lod0: Rgba8Image, lods: u8) -> LodChain {
    let mut levels = vec![lod0];
    while levels.len() < lods as usize {
        let Some(fine) = levels.last() else { break };
        let coarse = Rgba8Image::from_fn(fine.width.div_ceil(2), fine.height.div_ceil(2), |x, y| {
            let mut sum = [0u32; 4];
            let mut n = 0;
            for (fx, fy) in [(2 * x, 2 * y), (2 * x + 1, 2 * y), (2 * x, 2 * y + 1), (2 * x + 1, 2 * y + 1)] {
                if fx < fine.width && fy < fine.height {
                    let t = fine.texels[(fy * fine.width + fx) as usize];
                    (0..4).for_each(|c| sum[c] += u32::from(t[c]));
                    n += 1;
                }
            }
            sum.map(|c| ((c + n / 2) / n) as u8)
        });
        levels.push(coarse);
    }
    LodChain(levels)
}

/// A material's three layers made from one picture, as a test's layer stack: the picture
/// (albedo, colour), a tangent-space normal map of its luma taken as a height field (data: each
/// channel `(n + 1) / 2` in code values, blue up), and a roughness map (data: grey, the inverse
/// luma). Each layer differs from the others wherever the picture is not flat.
pub fn material_stack(albedo: &Rgba8Image) -> [Rgba8Image; 3] {
    let (w, h) = (albedo.width, albedo.height);
    let luma = |x: u32, y: u32| {
        let t = albedo.texels[(y.min(h - 1) * w + x.min(w - 1)) as usize];
        (2126 * u32::from(t[0]) + 7152 * u32::from(t[1]) + 722 * u32::from(t[2])) as f32 / 10000.0 / 255.0
    };
    let normal = Rgba8Image::from_fn(w, h, |x, y| {
        let dx = luma(x + 1, y) - luma(x.saturating_sub(1), y);
        let dy = luma(x, y + 1) - luma(x, y.saturating_sub(1));
        let n = [-dx * 4.0, -dy * 4.0, 1.0];
        let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
        let code = |c: f32| ((c / len * 0.5 + 0.5) * 255.0).round() as u8;
        [code(n[0]), code(n[1]), code(n[2]), 255]
    });
    let roughness = Rgba8Image::from_fn(w, h, |x, y| {
        let r = 255 - (luma(x, y) * 255.0).round() as u8;
        [r, r, r, 255]
    });
    [albedo.clone(), normal, roughness]
}

/// The stored tile of `page` of `texture`: its payload and `border` texels of its neighbours on
/// each side, texels beyond the level's edge repeating the edge (the tiler's layout with
/// `--background edge`); RGBA8 row-major, `tile_size²` texels.
pub fn bordered_tile(chain: &impl LodImages, texture: &VirtualTexture, page: PageId) -> Vec<u8> {
    let (w, h) = chain.size(page.lod);
    let (side, border, payload) =
        (i64::from(texture.tile_size), i64::from(texture.border), i64::from(texture.payload()));
    let mut out = Vec::with_capacity((side * side * 4) as usize);
    for j in 0..side {
        let y = (i64::from(page.y) * payload + j - border).clamp(0, i64::from(h) - 1) as u32;
        for i in 0..side {
            let x = (i64::from(page.x) * payload + i - border).clamp(0, i64::from(w) - 1) as u32;
            out.extend_from_slice(&chain.texel(page.lod, x, y));
        }
    }
    out
}

/// The level table of `texture`'s pack: its grid's pages per LOD, and the image at each LOD
/// (`ceil(size / 2^lod)`).
pub fn levels(texture: &VirtualTexture) -> Vec<Level> {
    (0..texture.grid.lod_count())
        .map(|lod| {
            let [w, h] = texture.grid.pages_at(lod).map(u32::from);
            let shrink = |v: u32| v.div_ceil(1 << lod);
            Level::new(w, h, shrink(texture.width), shrink(texture.height))
        })
        .collect()
}

/// One tile of a pack that [`write_pack_with`] writes.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum TestTile {
    /// `tile_size²` RGBA8 texels, stored as the pack's kind.
    Texels(Vec<u8>),
    /// One colour over the whole tile, borders included.
    Constant([u8; 4]),
    /// No tile: the runtime magnifies the nearest stored ancestor.
    Absent,
}

/// Writes a pack at `path` of every page of `texture` (texture id 0), each the
/// [bordered tile](bordered_tile) of `chain` stored as `kind`: `Raw`, or `Bc7` (the tile encoded
/// by [`crate::bc7::solid_blocks`], exact when each 4x4 block is one colour). Opens it.
pub fn write_pack(
    path: &Path,
    chain: &impl LodImages,
    texture: &VirtualTexture,
    kind: TileKind,
) -> Result<Arc<Pack>, PackError> {
    write_pack_with(path, texture, kind, |page| TestTile::Texels(bordered_tile(chain, texture, page)))
}

/// Writes a pack at `path` of every page of `texture` (texture id 0), each the bordered tile of
/// `chain` stored raw with three channels (its alpha dropped): an opaque texture, as the tiler
/// writes an RGB image. Opens it.
pub fn write_opaque_pack(
    path: &Path,
    chain: &impl LodImages,
    texture: &VirtualTexture,
) -> Result<Arc<Pack>, PackError> {
    write_pack_channels(path, texture, TileKind::Raw, 3, |page| TestTile::Texels(bordered_tile(chain, texture, page)))
}

/// Writes a pack at `path` of every page of `texture` (texture id 0), each as `tile` says, the
/// texels stored as `kind` (`Raw` or `Bc7`, as [`write_pack`]). For textures too large to hold
/// as a [`LodChain`]: most of their tiles can be one colour or absent. Opens it.
pub fn write_pack_with(
    path: &Path,
    texture: &VirtualTexture,
    kind: TileKind,
    tile: impl FnMut(PageId) -> TestTile,
) -> Result<Arc<Pack>, PackError> {
    write_pack_channels(path, texture, kind, 4, tile)
}

/// [`write_pack_with`] with `channels` (3 or 4) per texel: RGBA tiles lose their alpha for 3.
fn write_pack_channels(
    path: &Path,
    texture: &VirtualTexture,
    kind: TileKind,
    channels: u8,
    mut tile: impl FnMut(PageId) -> TestTile,
) -> Result<Arc<Pack>, PackError> {
    let d = Description {
        width: texture.width,
        height: texture.height,
        tile_size: texture.tile_size,
        border: texture.border,
        level_count: u32::from(texture.grid.lod_count()),
        channels,
        sample_bytes: 1,
        sample_format: 0,
    };
    let levels = levels(texture);
    let mut writer = PackWriter::create(path, d, levels.clone(), b"{}", WriteOptions::default())?;
    for (lod, level) in levels.iter().enumerate() {
        for y in 0..level.tiles_h {
            for x in 0..level.tiles_w {
                let id = TileId { lod: lod as u32, x, y };
                match tile(PageId::new(0, lod as u8, x as u16, y as u16)) {
                    TestTile::Texels(mut bytes) => {
                        if kind == TileKind::Bc7 {
                            bytes = crate::bc7::solid_blocks(&bytes, texture.tile_size);
                        } else if channels == 3 {
                            bytes = bytes.chunks_exact(4).flat_map(|t| [t[0], t[1], t[2]]).collect();
                        }
                        writer.add(id, NewTile::Data(kind, &bytes))?;
                    }
                    TestTile::Constant(colour) => writer.add(id, NewTile::Constant(&colour))?,
                    TestTile::Absent => writer.add(id, NewTile::Absent)?,
                }
            }
        }
    }
    writer.finish()?;
    Ok(Arc::new(Pack::open(path)?))
}
