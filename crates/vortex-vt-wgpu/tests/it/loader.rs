//! The tile loader on small packs written here (4x4 pages of 16 texels with a 2-texel border):
//! texels as `decode_rgba8` gives them, the same answers whatever the thread count, stand-ins and
//! errors for bad tiles, absent tiles from their ancestors, the asynchronous API, the memory tier
//! (pages read again from RAM with the same texels; its budget and LRU order). No GPU needed.

use std::collections::HashMap;
use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Duration;

use vortex_pack::Level;
use vortex_pack::fuzzing::pyramid_levels;
use vortex_pack::{Description, NewTile, Pack, PackWriter, Tile, TileId, TileKind, WriteOptions};
use vortex_vt::page::{GridError, PageId, TextureGrid};
use vortex_vt::residency::Slot;
use vortex_vt_wgpu::loader::{
    LoadCounters, LoadError, LoadedPage, Loader, LoaderError, RetryPolicy, STAND_IN_COLORS, TIER_ENTRY_OVERHEAD,
    TierUsage, stand_in_tile,
};
use vortex_vt_wgpu::testing::{Gate, gated};
use vortex_vt_wgpu::{CacheFormat, PageSource, ReadError, ReadErrorKind, SourceTile, StoredRead, VirtualTexture};

const TILE: u32 = 16;
const BORDER: u32 = 2;
const PAGES: u32 = 4;

/// What to store for one tile.
#[derive(Clone, Copy, Debug)]
enum Spec {
    Absent,
    Constant([u8; 3]),
    Raw(u32),
    Zstd(u32),
    Png(u32),
    Jpeg(u32),
    /// Lossless JPEG XL, encoded by libjxl (decoded by `vortex_pack` with jxl-oxide).
    Jxl(u32),
    /// A payload of this kind that does not decode (its CRC is right).
    Garbage(TileKind),
}

fn description(tile_size: u32, border: u32, pages: u32, width: u32, height: u32) -> Description {
    let level_count = pages.trailing_zeros() + 1;
    Description { width, height, tile_size, border, level_count, channels: 3, sample_bytes: 1, sample_format: 0 }
}

/// RGB texels of one tile that depend on `seed` and vary across the tile.
fn rgb(tile_size: u32, seed: u32) -> Vec<u8> {
    let n = (tile_size * tile_size) as usize;
    (0..n)
        .flat_map(|i| {
            let (x, y) = (i as u32 % tile_size, i as u32 / tile_size);
            [(x * 13 + seed * 29) as u8, (y * 11 + seed * 7) as u8, ((x ^ y) * 5 + seed * 3) as u8]
        })
        .collect()
}

fn png(tile_size: u32, seed: u32) -> Vec<u8> {
    let mut out = Vec::new();
    let mut encoder = png::Encoder::new(&mut out, tile_size, tile_size);
    encoder.set_color(png::ColorType::Rgb);
    encoder.set_depth(png::BitDepth::Eight);
    let mut writer = encoder.write_header().unwrap();
    writer.write_image_data(&rgb(tile_size, seed)).unwrap();
    writer.finish().unwrap();
    out
}

fn jpeg(tile_size: u32, seed: u32) -> Vec<u8> {
    let mut out = Vec::new();
    let side = tile_size as u16;
    jpeg_encoder::Encoder::new(&mut out, 90)
        .encode(&rgb(tile_size, seed), side, side, jpeg_encoder::ColorType::Rgb)
        .unwrap();
    out
}

fn jxl(tile_size: u32, seed: u32) -> Vec<u8> {
    let texels = rgb(tile_size, seed);
    let pixels = vortex_jxl::Pixels::U8(&texels);
    let image = vortex_jxl::Image { width: tile_size, height: tile_size, channels: 3, pixels };
    vortex_jxl::encode(&image, vortex_jxl::Quality::Lossless, vortex_jxl::Effort::new(1).unwrap()).unwrap()
}

/// Writes a pack of `description` with the pyramid's levels, each tile as `spec` says.
fn write_pack(path: &Path, d: Description, spec: impl Fn(TileId) -> Spec) -> Arc<Pack> {
    let levels = pyramid_levels(&d, 1 << (d.level_count - 1));
    write_pack_with_levels(path, d, levels, spec)
}

fn write_pack_with_levels(path: &Path, d: Description, levels: Vec<Level>, spec: impl Fn(TileId) -> Spec) -> Arc<Pack> {
    let mut w = PackWriter::create(path, d, levels.clone(), b"{}", WriteOptions::default()).unwrap();
    for (lod, level) in levels.iter().enumerate() {
        for y in 0..level.tiles_h {
            for x in 0..level.tiles_w {
                let id = TileId { lod: lod as u32, x, y };
                let (kind, bytes) = match spec(id) {
                    Spec::Absent => {
                        w.add(id, NewTile::Absent).unwrap();
                        continue;
                    }
                    Spec::Constant(value) => {
                        w.add(id, NewTile::Constant(&value)).unwrap();
                        continue;
                    }
                    Spec::Raw(seed) => (TileKind::Raw, rgb(d.tile_size, seed)),
                    Spec::Zstd(seed) => (TileKind::Zstd, zstd::bulk::compress(&rgb(d.tile_size, seed), 3).unwrap()),
                    Spec::Png(seed) => (TileKind::Png, png(d.tile_size, seed)),
                    Spec::Jpeg(seed) => (TileKind::Jpeg, jpeg(d.tile_size, seed)),
                    Spec::Jxl(seed) => (TileKind::Jxl, jxl(d.tile_size, seed)),
                    Spec::Garbage(kind) => (kind, b"this is not an image of any kind".to_vec()),
                };
                w.add(id, NewTile::Data(kind, &bytes)).unwrap();
            }
        }
    }
    w.finish().unwrap();
    Arc::new(Pack::open(path).unwrap())
}

/// A distinct number per tile, to seed its content.
fn seed(id: TileId) -> u32 {
    id.lod * 100 + id.y * 10 + id.x + 1
}

/// Every kind of tile, at every LOD: JPEG, PNG, raw, constant, zstd in turn.
fn mixed(id: TileId) -> Spec {
    let s = seed(id);
    match (id.lod + id.x + 2 * id.y) % 6 {
        0 => Spec::Jpeg(s),
        1 => Spec::Png(s),
        2 => Spec::Raw(s),
        3 => Spec::Constant([s as u8, (s * 3) as u8, 200]),
        4 => Spec::Jxl(s),
        _ => Spec::Zstd(s),
    }
}

fn mixed_pack(dir: &Path, name: &str) -> Arc<Pack> {
    write_pack(&dir.join(name), description(TILE, BORDER, PAGES, 44, 40), mixed)
}

/// Every page of the texture, finest LOD first, with distinct slots.
fn all_pages(texture: u8, grid: TextureGrid, first_slot: Slot) -> Vec<(PageId, Slot)> {
    let mut pages = Vec::new();
    for lod in 0..grid.lod_count() {
        let [w, h] = grid.pages_at(lod);
        for y in 0..h {
            for x in 0..w {
                pages.push(PageId::new(texture, lod, x, y));
            }
        }
    }
    pages.into_iter().zip(first_slot..).collect()
}

fn expected_texels(pack: &Pack, page: PageId) -> Vec<u8> {
    pack.decode_rgba8(TileId { lod: page.lod.into(), x: page.x.into(), y: page.y.into() }).unwrap().unwrap()
}

fn payload_len(pack: &Pack, page: PageId) -> u64 {
    match pack.tile(vortex_pack::TileId::new(page.lod.into(), page.x.into(), page.y.into())).unwrap() {
        Tile::Data(_, bytes) => bytes.len() as u64,
        Tile::Constant(_) | Tile::Absent => 0,
    }
}

fn tempdir() -> tempfile::TempDir {
    tempfile::tempdir().unwrap()
}

#[test]
fn virtual_texture_describes_the_pack() {
    let dir = tempdir();
    let pack = mixed_pack(dir.path(), "a.vtpk");
    let t = VirtualTexture::from_pack(&pack).unwrap();
    assert_eq!(t.grid, TextureGrid::new(4, 4).unwrap());
    assert_eq!(t.grid.lod_count(), 3);
    assert_eq!((t.width, t.height, t.tile_size, t.border, t.payload()), (44, 40, 16, 2, 12));
    // An old square power-of-two pack: UV spans the 44 x 40 image, not the 48 x 48 grid.
    assert_eq!(t.size(), [44, 40]);
}

#[test]
fn packs_whose_levels_do_not_halve_are_rejected_with_a_typed_error() {
    let dir = tempdir();
    let level = |tiles_w, tiles_h, first_entry| Level { tiles_w, tiles_h, first_entry, width: 30, height: 30 };
    let d = |level_count| Description { level_count, ..description(TILE, BORDER, 4, 30, 30) };
    let not_halving = |lod, found: [u32; 2], expected: [u32; 2]| move |e: &GridError| matches!(e, GridError::NotHalving { lod: l, found: f, expected: x, .. } if *l == lod && *f == found && *x == expected);
    let too_few =
        |levels: usize| move |e: &GridError| matches!(e, GridError::TooFewLevels { levels: l, .. } if *l == levels);
    type Is = Box<dyn Fn(&GridError) -> bool>;
    let cases: [(&str, Description, Vec<Level>, Is); 4] = [
        ("three.vtpk", d(2), vec![level(3, 3, 0), level(2, 2, 9)], Box::new(too_few(2))),
        ("short.vtpk", d(2), vec![level(4, 4, 0), level(2, 2, 16)], Box::new(too_few(2))),
        (
            "odd.vtpk",
            d(3),
            vec![level(4, 4, 0), level(2, 3, 16), level(1, 1, 22)],
            Box::new(not_halving(1, [2, 3], [2, 2])),
        ),
        ("floor.vtpk", d(2), vec![level(3, 3, 0), level(1, 1, 9)], Box::new(not_halving(1, [1, 1], [2, 2]))),
    ];
    for (name, d, levels, is) in cases {
        let path = dir.path().join(name);
        let pack = write_pack_with_levels(&path, d, levels, |_| Spec::Constant([1, 2, 3]));
        let e = VirtualTexture::from_pack(&pack).unwrap_err();
        assert!(matches!(&e, LoaderError::Grid { path: p, source } if *p == path && is(source)), "{name}: {e}");
        assert!(e.to_string().contains(name), "{e}");
        assert!(Loader::new(vec![pack], 1).is_err());
    }
    // A rectangular grid whose levels halve rounding up is a texture.
    let path = dir.path().join("oblong.vtpk");
    let oblong = write_pack_with_levels(
        &path,
        Description { width: 30, height: 10, ..d(3) },
        vec![level(3, 1, 0), level(2, 1, 3), level(1, 1, 5)],
        |_| Spec::Constant([1, 2, 3]),
    );
    let t = VirtualTexture::from_pack(&oblong).unwrap();
    assert_eq!((t.grid.pages(), t.grid.lod_count(), t.size()), ([3, 1], 3, [30, 10]));
    // An image larger than the page grid covers.
    let too_wide =
        write_pack(&dir.path().join("wide.vtpk"), description(TILE, BORDER, 2, 25, 10), |_| Spec::Constant([0, 0, 0]));
    let e = VirtualTexture::from_pack(&too_wide).unwrap_err();
    assert!(matches!(&e, LoaderError::Layout { field: "width", .. }), "{e}");
}

#[test]
fn texels_equal_decode_rgba8_for_every_tile_kind() {
    let dir = tempdir();
    let pack = mixed_pack(dir.path(), "a.vtpk");
    let loader = Loader::new(vec![Arc::clone(&pack)], 2).unwrap();
    assert_eq!((loader.tile_size(), loader.border(), loader.threads()), (16, 2, 2));
    let pages = all_pages(0, loader.textures()[0].grid, 0);
    assert_eq!(pages.len(), 21);
    let loaded = loader.load(&pages);
    let mut kinds = HashMap::new();
    for (answer, (page, slot)) in loaded.iter().zip(&pages) {
        assert_eq!((answer.page, answer.slot), (*page, *slot));
        assert_eq!(answer.error, None, "{page:?}");
        assert_eq!(answer.texels, expected_texels(&pack, *page), "{page:?}");
        assert_eq!(answer.bytes_read, payload_len(&pack, *page), "{page:?}");
        let kind = match pack.tile(vortex_pack::TileId::new(page.lod.into(), page.x.into(), page.y.into())).unwrap() {
            Tile::Data(kind, _) => kind,
            Tile::Constant(_) => TileKind::Constant,
            Tile::Absent => TileKind::Absent,
        };
        *kinds.entry(kind).or_insert(0) += 1;
    }
    for kind in [TileKind::Jpeg, TileKind::Png, TileKind::Raw, TileKind::Zstd, TileKind::Jxl, TileKind::Constant] {
        // 21 pages over six kinds: each at least twice.
        assert!(kinds.get(&kind).copied().unwrap_or(0) >= 2, "{kind:?}: {kinds:?}");
    }
    let c = loader.counters();
    assert_eq!((c.pages, c.tiles_decoded, c.absent_filled, c.errors), (21, 21, 0, 0));
}

#[test]
fn bytes_read_is_the_sum_of_payload_lengths() {
    let dir = tempdir();
    let pack = mixed_pack(dir.path(), "a.vtpk");
    let loader = Loader::new(vec![Arc::clone(&pack)], 3).unwrap();
    let pages = all_pages(0, loader.textures()[0].grid, 0);
    // Pages asked twice are read twice.
    let twice: Vec<(PageId, Slot)> = pages.iter().chain(&pages).copied().collect();
    let loaded = loader.load(&twice);
    let expected: u64 = twice.iter().map(|(page, _)| payload_len(&pack, *page)).sum();
    assert!(expected > 0);
    assert_eq!(loaded.iter().map(|p| p.bytes_read).sum::<u64>(), expected);
    assert_eq!(loader.counters().bytes_read, expected);
    assert_eq!(loader.counters().pages, twice.len() as u64);
}

#[test]
fn results_and_counters_do_not_depend_on_the_thread_count() {
    let dir = tempdir();
    let a = mixed_pack(dir.path(), "a.vtpk");
    let b = write_pack(&dir.path().join("b.vtpk"), description(TILE, BORDER, 2, 20, 24), |id| match seed(id) % 3 {
        0 => Spec::Absent,
        1 => Spec::Garbage(TileKind::Png),
        _ => Spec::Jpeg(seed(id) + 50),
    });
    let grids = [VirtualTexture::from_pack(&a).unwrap().grid, VirtualTexture::from_pack(&b).unwrap().grid];
    let mut pages = all_pages(0, grids[0], 0);
    pages.extend(all_pages(1, grids[1], 100));
    pages.extend(pages.clone());
    // Out of the grids, and an unknown texture.
    pages.extend([(PageId::new(0, 3, 0, 0), 7), (PageId::new(1, 0, 2, 0), 8), (PageId::new(2, 0, 0, 0), 9)]);
    // A fixed shuffle.
    let n = pages.len();
    for i in 0..n {
        pages.swap(i, (i * 7919 + 13) % n);
    }
    let run = |threads: usize| -> (Vec<LoadedPage>, LoadCounters) {
        let loader = Loader::new(vec![Arc::clone(&a), Arc::clone(&b)], threads).unwrap();
        let loaded = loader.load(&pages);
        (loaded, loader.counters())
    };
    let (one, one_counters) = run(1);
    let (four, four_counters) = run(4);
    assert_eq!(one.iter().map(|p| (p.page, p.slot)).collect::<Vec<_>>(), pages);
    assert!(one == four, "the answers differ between 1 and 4 threads");
    assert_eq!(one_counters, four_counters);
    assert!(one_counters.errors > 3 && one_counters.absent_filled > 0, "{one_counters:?}");
    assert_eq!(one_counters.errors, one.iter().filter(|p| !p.is_ok()).count() as u64);
}

#[test]
fn mismatched_tile_sizes_or_borders_are_rejected_naming_both_packs() {
    let dir = tempdir();
    let a = mixed_pack(dir.path(), "first.vtpk");
    let big = write_pack(&dir.path().join("big.vtpk"), description(32, BORDER, 2, 40, 40), |_| Spec::Constant([9; 3]));
    let thin = write_pack(&dir.path().join("thin.vtpk"), description(TILE, 1, 4, 40, 40), |_| Spec::Constant([9; 3]));
    for (other, field, value) in [(big, "tile_size", 32), (thin, "border", 1)] {
        let e = Loader::new(vec![Arc::clone(&a), Arc::clone(&a), Arc::clone(&other)], 1).err().unwrap();
        let text = e.to_string();
        assert!(text.contains("first.vtpk") && text.contains(&other.path().display().to_string()), "{text}");
        match e {
            LoaderError::Mismatch { field: f, first, other_value, .. } => {
                assert_eq!((f, first.as_path(), other_value), (field, a.path(), value));
            }
            other => panic!("{other}"),
        }
    }
    assert!(matches!(Loader::new(Vec::new(), 1), Err(LoaderError::NoTextures)));
    assert!(matches!(Loader::new(vec![a; 17], 1), Err(LoaderError::TooManyTextures { count: 17 })));
}

/// Flips one byte of the payload of `id` in a copy of the pack at `from`.
fn corrupt_copy(from: &Pack, to: &Path, id: TileId) -> (Arc<Pack>, u64) {
    let entry = from.entry(from.position(id).unwrap());
    let mut bytes = from.file().to_vec();
    bytes[(entry.offset_or_value + u64::from(entry.len) / 2) as usize] ^= 0x40;
    std::fs::write(to, &bytes).unwrap();
    (Arc::new(Pack::open(to).unwrap()), u64::from(entry.len))
}

#[test]
fn a_corrupted_payload_gives_the_stand_in_and_an_error_naming_the_tile() {
    let dir = tempdir();
    let pack = mixed_pack(dir.path(), "a.vtpk");
    let corrupt_path = dir.path().join("corrupt.vtpk");
    // (lod 1, x 1, y 0) is a raw tile, (lod 1, x 1, y 1) a zstd one: corrupt both.
    let (once, _) = corrupt_copy(&pack, &corrupt_path, TileId { lod: 1, x: 1, y: 0 });
    let (corrupt, len) = corrupt_copy(&once, &corrupt_path, TileId { lod: 1, x: 1, y: 1 });
    drop(once);
    let loader = Loader::new(vec![Arc::clone(&corrupt)], 2).unwrap();
    let pages = all_pages(0, loader.textures()[0].grid, 0);
    let loaded = loader.load(&pages);
    let bad: Vec<&LoadedPage> = loaded.iter().filter(|p| !p.is_ok()).collect();
    assert_eq!(bad.len(), 2);
    for (page, x, y) in [(bad[0], 1, 0), (bad[1], 1, 1)] {
        assert_eq!((page.page.lod, page.page.x, page.page.y), (1, x, y));
        match page.error.as_ref().unwrap() {
            LoadError::Tile { path, lod: 1, x: ex, y: ey, kind, message }
                if (*ex, *ey) == (u32::from(x), u32::from(y)) =>
            {
                assert_eq!(path, &corrupt_path);
                assert_eq!(*kind, ReadErrorKind::Corrupt, "a failed checksum is corrupt, not retried");
                assert!(message.contains("checksum"), "{message}");
            }
            other => panic!("{other}"),
        }
        assert_eq!(page.texels, stand_in_tile(TILE));
        assert_eq!(&page.texels[..4], &STAND_IN_COLORS[0]);
    }
    assert_eq!(bad[1].bytes_read, len);
    let message = bad[0].error.as_ref().unwrap().to_string();
    assert!(message.contains("corrupt.vtpk") && message.contains("(lod 1, x 1, y 0)"), "{message}");
    for page in loaded.iter().filter(|p| p.is_ok()) {
        assert_eq!(page.texels, expected_texels(&pack, page.page));
    }
    assert_eq!(loader.counters().errors, 2);
}

#[test]
fn undecodable_payloads_with_right_checksums_give_the_stand_in() {
    let dir = tempdir();
    let kinds = [TileKind::Png, TileKind::Jpeg, TileKind::Zstd, TileKind::Png];
    let pack = write_pack(&dir.path().join("garbage.vtpk"), description(TILE, BORDER, 2, 20, 20), |id| {
        if id.lod == 0 { Spec::Garbage(kinds[(id.y * 2 + id.x) as usize]) } else { Spec::Raw(1) }
    });
    let loader = Loader::new(vec![Arc::clone(&pack)], 2).unwrap();
    let loaded = loader.load(&all_pages(0, loader.textures()[0].grid, 0));
    for page in &loaded[..4] {
        let e = page.error.as_ref().unwrap();
        assert!(
            matches!(e, LoadError::Tile { lod: 0, x, y, .. } if (*x, *y) == (page.page.x.into(), page.page.y.into())),
            "{e}"
        );
        assert_eq!(page.texels, stand_in_tile(TILE));
    }
    assert!(loaded[4].is_ok());
    assert_eq!(loader.counters().errors, 4);
}

#[test]
fn pages_outside_the_grid_get_the_stand_in_and_an_error() {
    let dir = tempdir();
    let pack = mixed_pack(dir.path(), "a.vtpk");
    let loader = Loader::new(vec![Arc::clone(&pack)], 1).unwrap();
    let pages = [(PageId::new(0, 3, 0, 0), 0), (PageId::new(0, 0, 4, 0), 1), (PageId::new(0, 1, 0, 2), 2)];
    for page in loader.load(&pages) {
        assert_eq!(page.texels, stand_in_tile(TILE));
        let e = page.error.unwrap();
        assert!(matches!(&e, LoadError::OutOfGrid { path, .. } if path == pack.path()), "{e}");
    }
    let unknown = loader.load(&[(PageId::new(1, 0, 0, 0), 3)]);
    assert!(matches!(unknown[0].error, Some(LoadError::UnknownTexture { textures: 1, .. })));
    assert_eq!(unknown[0].texels, stand_in_tile(TILE));
    assert_eq!(loader.counters().errors, 4);
}

/// The reference magnification, in floating point: texel i of `page` is centred on
/// `x * payload - border + i + 1/2` at its LOD, sampled bilinearly (clamped to the tile) from the
/// ancestor `levels_up` LODs coarser, rounded half up.
fn magnified(ancestor: &[u8], page: PageId, levels_up: u8) -> Vec<u8> {
    let (t, b, p) = (TILE as f64, BORDER as f64, (TILE - 2 * BORDER) as f64);
    let scale = f64::from(1u32 << levels_up);
    let axis = |xy: u16, i: usize| {
        let origin = f64::from(xy >> levels_up) * p - b;
        let u = (f64::from(xy) * p - b + i as f64 + 0.5) / scale - origin - 0.5;
        let j = u.floor();
        let clamp = |v: f64| v.clamp(0.0, t - 1.0) as usize;
        (clamp(j), clamp(j + 1.0), u - j)
    };
    let side = TILE as usize;
    let mut out = Vec::new();
    for i in 0..side {
        let (y0, y1, fy) = axis(page.y, i);
        for k in 0..side {
            let (x0, x1, fx) = axis(page.x, k);
            for c in 0..4 {
                let at = |x: usize, y: usize| f64::from(ancestor[(y * side + x) * 4 + c]);
                let v = (1.0 - fy) * ((1.0 - fx) * at(x0, y0) + fx * at(x1, y0))
                    + fy * ((1.0 - fx) * at(x0, y1) + fx * at(x1, y1));
                out.push((v + 0.5).floor() as u8);
            }
        }
    }
    out
}

#[test]
fn an_absent_tile_is_its_nearest_ancestor_magnified() {
    let dir = tempdir();
    // LOD 0 (1, 1) and LOD 1 (0, 0) are absent: (1, 1) comes from the root, two LODs up.
    // LOD 0 (2, 1) and (3, 3) come from their parents, LOD 1 (1, 0) and (1, 1).
    let absent = [(0, 1, 1), (1, 0, 0), (0, 2, 1), (0, 3, 3), (0, 0, 0)];
    let pack = write_pack(&dir.path().join("holes.vtpk"), description(TILE, BORDER, PAGES, 44, 40), |id| {
        if absent.contains(&(id.lod, id.x, id.y)) { Spec::Absent } else { Spec::Raw(seed(id)) }
    });
    let loader = Loader::new(vec![Arc::clone(&pack)], 2).unwrap();
    let cases = [(PageId::new(0, 0, 1, 1), 2u8), (PageId::new(0, 0, 2, 1), 1), (PageId::new(0, 0, 3, 3), 1)];
    let cases = cases.into_iter().chain([(PageId::new(0, 0, 0, 0), 2), (PageId::new(0, 1, 0, 0), 1)]);
    for (page, levels_up) in cases {
        let answer = &loader.load(&[(page, 5)])[0];
        assert_eq!(answer.error, None);
        let ancestor = PageId::new(0, page.lod + levels_up, page.x >> levels_up, page.y >> levels_up);
        let want = magnified(&expected_texels(&pack, ancestor), page, levels_up);
        assert_eq!(answer.texels, want, "{page:?} from {ancestor:?}");
        assert_eq!(answer.bytes_read, payload_len(&pack, ancestor));
        assert_ne!(answer.texels, stand_in_tile(TILE));
    }
    let c = loader.counters();
    assert_eq!((c.pages, c.absent_filled, c.tiles_decoded, c.errors), (5, 5, 5, 0));
}

#[test]
fn an_absent_tile_of_a_constant_ancestor_is_that_constant() {
    let dir = tempdir();
    let pack = write_pack(&dir.path().join("flat.vtpk"), description(TILE, BORDER, PAGES, 44, 40), |id| {
        if id.lod == 2 { Spec::Constant([12, 34, 56]) } else { Spec::Absent }
    });
    let loader = Loader::new(vec![pack], 1).unwrap();
    for page in loader.load(&all_pages(0, loader.textures()[0].grid, 0)) {
        assert_eq!(page.error, None);
        assert_eq!(page.bytes_read, 0);
        assert_eq!(page.texels, [12, 34, 56, 255].repeat((TILE * TILE) as usize));
    }
}

#[test]
fn a_tile_with_no_stored_ancestor_gets_the_stand_in() {
    let dir = tempdir();
    let pack = write_pack(&dir.path().join("empty.vtpk"), description(TILE, BORDER, 2, 20, 20), |_| Spec::Absent);
    let loader = Loader::new(vec![pack], 1).unwrap();
    let loaded = loader.load(&[(PageId::new(0, 0, 1, 1), 0)]);
    assert!(matches!(loaded[0].error, Some(LoadError::NoAncestor { lod: 0, x: 1, y: 1, .. })));
    assert_eq!(loaded[0].texels, stand_in_tile(TILE));
}

#[test]
fn a_broken_ancestor_of_an_absent_tile_is_named() {
    let dir = tempdir();
    let pack = write_pack(&dir.path().join("a.vtpk"), description(TILE, BORDER, 2, 20, 20), |id| {
        if id.lod == 0 { Spec::Absent } else { Spec::Garbage(TileKind::Jpeg) }
    });
    let loader = Loader::new(vec![pack], 1).unwrap();
    let loaded = loader.load(&[(PageId::new(0, 0, 1, 0), 0)]);
    match loaded[0].error.as_ref().unwrap() {
        LoadError::Tile { lod: 1, x: 0, y: 0, message, .. } => assert!(message.contains("ancestor"), "{message}"),
        other => panic!("{other}"),
    }
    assert_eq!(loaded[0].texels, stand_in_tile(TILE));
}

/// A bound against a hang, never reached when the loader works, however slow the machine.
const FAIL_SAFE: Duration = Duration::from_secs(120);

/// Returns once every job queued on `loader` so far has been answered, without a clock: a
/// blocking load of one page of `gated` (a texture whose reads wait at the closed `gate`) per
/// worker, let through only once every worker holds one. Workers take jobs in order and answer
/// each before taking the next, so by then every earlier job has been answered.
fn answered_so_far(loader: &Loader, gated: u8, gate: &Gate) {
    let threads = loader.threads();
    let barrier: Vec<(PageId, Slot)> =
        (0..threads as Slot).map(|i| (PageId::new(gated, 0, 0, 0), 60_000 + i)).collect();
    std::thread::scope(|scope| {
        let load = scope.spawn(|| loader.load(&barrier));
        assert!(gate.wait_for_readers(threads, FAIL_SAFE), "{} of {threads} workers at the gate", gate.waiting());
        gate.open();
        assert_eq!(load.join().unwrap().len(), threads);
    });
    gate.close();
}

#[test]
fn request_and_poll_answer_every_page_exactly_once() {
    let dir = tempdir();
    let pack = mixed_pack(dir.path(), "a.vtpk");
    // Texture 1 (the same pack, its reads held at a gate) is only for `answered_so_far`.
    let gate = Gate::closed();
    let gated: Arc<dyn PageSource> = Arc::new(gated(Arc::clone(&pack) as _, Arc::clone(&gate)));
    let loader = Loader::with_sources(vec![Arc::clone(&pack) as _, gated], 3).unwrap();
    let grid = loader.textures()[0].grid;
    let pages: Vec<(PageId, Slot)> = (0..3).flat_map(|round| all_pages(0, grid, round * 100)).collect();
    let reference: HashMap<PageId, LoadedPage> =
        loader.load(&all_pages(0, grid, 0)).into_iter().map(|p| (p.page, p)).collect();
    let mut seen: HashMap<Slot, LoadedPage> = HashMap::new();
    let mut collect = |finished: Vec<LoadedPage>| {
        for page in finished {
            assert!(seen.insert(page.slot, page).is_none(), "answered twice");
        }
    };
    for chunk in pages.chunks(10) {
        loader.request(chunk);
        // A blocking load meanwhile shares the workers and is not mixed into the polled pages.
        assert_eq!(loader.load(&chunk[..1])[0].page, chunk[0].0);
        collect(loader.poll());
    }
    answered_so_far(&loader, 1, &gate);
    collect(loader.poll());
    assert_eq!(loader.pending(), 0);
    assert!(loader.poll().is_empty());
    assert_eq!(seen.len(), pages.len());
    for (page, slot) in &pages {
        let answer = &seen[slot];
        assert_eq!(answer.page, *page);
        let want = &reference[page];
        assert_eq!((&answer.texels, answer.bytes_read, &answer.error), (&want.texels, want.bytes_read, &want.error));
    }
}

#[test]
fn dropping_the_loader_with_work_in_flight_stops_its_threads() {
    let dir = tempdir();
    let pack = mixed_pack(dir.path(), "a.vtpk");
    let grid = VirtualTexture::from_pack(&pack).unwrap().grid;
    let pages: Vec<(PageId, Slot)> = (0..20).flat_map(|_| all_pages(0, grid, 0)).collect();
    for threads in [1, 4] {
        let loader = Loader::new(vec![Arc::clone(&pack)], threads).unwrap();
        loader.request(&pages);
        let _ = loader.poll();
        drop(loader);
    }
    // No worker holds the pack any more.
    assert_eq!(Arc::strong_count(&pack), 1);
    let zero = Loader::new(vec![pack], 0).unwrap();
    assert!(zero.threads() >= 1);
    assert!(zero.load(&[]).is_empty());
}

#[test]
fn solid_bc7_blocks_decode_to_their_colour_exactly() {
    // Every 8-bit value in every channel: a 64x64 tile of 256 blocks, block i of colour
    // (i, 255 - i, 7i mod 256, i).
    let dir = tempfile::tempdir().unwrap();
    let d = Description {
        width: 64,
        height: 64,
        tile_size: 64,
        border: 0,
        level_count: 1,
        channels: 4,
        sample_bytes: 1,
        sample_format: 0,
    };
    let colour = |i: usize| [i as u8, 255 - i as u8, (i * 7 % 256) as u8, i as u8];
    let blocks: Vec<u8> = (0..256).flat_map(|i| vortex_vt_wgpu::bc7::solid_block(colour(i))).collect();
    let levels = pyramid_levels(&d, 1);
    let path = dir.path().join("solid.vtpk");
    let mut w = PackWriter::create(&path, d, levels, b"{}", WriteOptions::default()).unwrap();
    w.add(TileId { lod: 0, x: 0, y: 0 }, NewTile::Data(TileKind::Bc7, &blocks)).unwrap();
    w.finish().unwrap();
    let pack = Pack::open(&path).unwrap();
    let texels = pack.decode_rgba8(TileId { lod: 0, x: 0, y: 0 }).unwrap().unwrap();
    for (i, t) in texels.chunks_exact(4).enumerate() {
        let (x, y) = (i % 64, i / 64);
        assert_eq!(t, colour((y / 4) * 16 + x / 4), "texel ({x}, {y})");
    }
}

#[test]
fn cancelled_requests_are_never_answered_and_the_rest_are() {
    let dir = tempdir();
    let pack = mixed_pack(dir.path(), "a.vtpk");
    let gate = Gate::closed();
    let held: Arc<dyn PageSource> = Arc::new(gated(pack, Arc::clone(&gate)));
    let loader = Loader::with_sources(vec![held], 1).unwrap();
    let pages = all_pages(0, loader.textures()[0].grid, 0);
    loader.request(&pages[..6]);
    // The one worker holds the first page at the gate; the other five wait in the queue.
    assert!(gate.wait_for_readers(1, FAIL_SAFE), "the worker never read the first page");
    assert_eq!(loader.cancel(&pages[2..6]), 4);
    assert_eq!(loader.cancel(&pages[2..6]), 0, "taken back once");
    gate.open();
    // One worker answers in order: once a blocking load behind them is answered, so are they.
    assert_eq!(loader.load(&pages[..1]).len(), 1);
    let answered: Vec<(PageId, Slot)> = loader.poll().into_iter().map(|p| (p.page, p.slot)).collect();
    assert_eq!(answered, pages[..2]);
    assert_eq!(loader.pending(), 0);
}

/// A pack that counts its reads, with or without a stored form (without: only `read_tile`, as an
/// application's own source may be written).
struct Counting {
    pack: Arc<Pack>,
    stored: bool,
    reads: AtomicUsize,
}

impl Counting {
    fn new(pack: &Arc<Pack>, stored: bool) -> Arc<Counting> {
        Arc::new(Counting { pack: Arc::clone(pack), stored, reads: AtomicUsize::new(0) })
    }
}

impl PageSource for Counting {
    fn location(&self) -> &Path {
        self.pack.path()
    }

    fn texture(&self) -> Result<VirtualTexture, LoaderError> {
        VirtualTexture::from_pack(&self.pack)
    }

    fn read_tile(&self, tile: TileId, format: CacheFormat) -> Result<SourceTile, ReadError> {
        self.reads.fetch_add(1, Ordering::Relaxed);
        self.pack.read_tile(tile, format)
    }

    fn read_stored(&self, tile: TileId) -> Result<Option<StoredRead>, ReadError> {
        if !self.stored {
            return Ok(None);
        }
        self.reads.fetch_add(1, Ordering::Relaxed);
        self.pack.read_stored(tile)
    }

    fn decode(&self, tile: TileId, kind: TileKind, bytes: &[u8], format: CacheFormat) -> Result<Vec<u8>, ReadError> {
        self.pack.decode(tile, kind, bytes, format)
    }
}

/// A pack whose reads fail with `kind` until `failures` of them have failed, then read as usual;
/// it counts every read. An application's own source, reading its storage with `read_tile` only.
struct Failing {
    pack: Arc<Pack>,
    kind: ReadErrorKind,
    failures: usize,
    reads: AtomicUsize,
}

impl PageSource for Failing {
    fn location(&self) -> &Path {
        self.pack.path()
    }

    fn texture(&self) -> Result<VirtualTexture, LoaderError> {
        VirtualTexture::from_pack(&self.pack)
    }

    fn read_tile(&self, tile: TileId, format: CacheFormat) -> Result<SourceTile, ReadError> {
        if self.reads.fetch_add(1, Ordering::Relaxed) < self.failures {
            return Err(ReadError::new(self.kind, "this read fails").with_bytes_read(10));
        }
        self.pack.read_tile(tile, format)
    }
}

/// One page (the root) read from a source that fails `failures` times with `kind`, by a loader
/// that reads at most `attempts` times with no wait between (the backoff is what a real source
/// waits for, not what a test should): the answer, how often the source was read, the counters.
fn read_failing(kind: ReadErrorKind, failures: usize, attempts: u32) -> (LoadedPage, usize, LoadCounters) {
    let dir = tempdir();
    let pack = mixed_pack(dir.path(), "a.vtpk");
    let source = Arc::new(Failing { pack, kind, failures, reads: AtomicUsize::new(0) });
    let loader = Loader::with_sources(vec![Arc::clone(&source) as Arc<dyn PageSource>], 1).unwrap();
    loader.set_retry(RetryPolicy { attempts, backoff: Duration::ZERO });
    let root = PageId::new(0, loader.textures()[0].grid.lod_count() - 1, 0, 0);
    let page = loader.load(&[(root, 7)]).remove(0);
    (page, source.reads.load(Ordering::Relaxed), loader.counters())
}

#[test]
fn io_errors_are_read_again_and_the_page_loads() {
    let (page, reads, counters) = read_failing(ReadErrorKind::Io, 2, 3);
    assert!(page.is_ok(), "{:?}", page.error);
    assert_ne!(page.texels, stand_in_tile(TILE));
    assert_eq!(reads, 3, "two failed reads and the one that passed");
    assert_eq!((counters.read_retries, counters.errors), (2, 0));
    assert_eq!(page.bytes_read, 20 + root_payload_len(), "the failed reads' bytes count too");
}

#[test]
fn io_errors_past_the_attempts_give_the_stand_in_and_say_io() {
    let (page, reads, counters) = read_failing(ReadErrorKind::Io, usize::MAX, 4);
    assert_eq!(reads, 4, "as many reads as attempts, no more");
    assert_eq!((counters.read_retries, counters.errors), (3, 1));
    assert_eq!(page.texels, stand_in_tile(TILE));
    assert!(matches!(page.error, Some(LoadError::Tile { kind: ReadErrorKind::Io, .. })), "{:?}", page.error);
}

#[test]
fn other_errors_are_not_read_again() {
    for kind in [ReadErrorKind::Corrupt, ReadErrorKind::Unsupported, ReadErrorKind::Unavailable] {
        let (page, reads, counters) = read_failing(kind, usize::MAX, 5);
        assert_eq!(reads, 1, "{kind:?} was read again");
        assert_eq!((counters.read_retries, counters.errors), (0, 1));
        assert_eq!(page.texels, stand_in_tile(TILE), "{kind:?}");
        match page.error {
            Some(LoadError::Tile { kind: got, message, .. }) => {
                assert_eq!(got, kind);
                assert!(message.contains("fails"), "{message}");
            }
            other => panic!("{other:?}"),
        }
    }
}

/// A source that retries its own reads, as `HttpPack` does, and says so: its reads fail with an
/// I/O error every time.
struct RetriesItself(Failing);

impl PageSource for RetriesItself {
    fn location(&self) -> &Path {
        self.0.location()
    }

    fn texture(&self) -> Result<VirtualTexture, LoaderError> {
        self.0.texture()
    }

    fn read_tile(&self, tile: TileId, format: CacheFormat) -> Result<SourceTile, ReadError> {
        self.0.read_tile(tile, format)
    }

    fn retry_policy(&self, _loader: RetryPolicy) -> RetryPolicy {
        RetryPolicy::NONE
    }
}

#[test]
fn a_source_that_retries_itself_is_read_once_by_the_loader() {
    let dir = tempdir();
    let pack = mixed_pack(dir.path(), "a.vtpk");
    let failing = || Failing {
        pack: Arc::clone(&pack),
        kind: ReadErrorKind::Io,
        failures: usize::MAX,
        reads: AtomicUsize::new(0),
    };
    let own = Arc::new(RetriesItself(failing()));
    // Wrapped too: a wrapper (here the latency one, with no wait) keeps the source's policy.
    let wrapped = Arc::new(RetriesItself(failing()));
    let delayed =
        Arc::new(vortex_vt_wgpu::source::Delayed::with_wait(Arc::clone(&wrapped) as Arc<dyn PageSource>, || Ok(())));
    let plain = Arc::new(failing());
    let sources: Vec<Arc<dyn PageSource>> = vec![own.clone(), delayed, plain.clone()];
    let loader = Loader::with_sources(sources, 1).unwrap();
    loader.set_retry(RetryPolicy { attempts: 4, backoff: Duration::ZERO });
    let lods = loader.textures()[0].grid.lod_count();
    let pages: Vec<_> = (0..3).map(|t| (PageId::new(t, lods - 1, 0, 0), Slot::from(t))).collect();
    let loaded = loader.load(&pages);
    assert!(loaded.iter().all(|p| matches!(p.error, Some(LoadError::Tile { kind: ReadErrorKind::Io, .. }))));
    let reads = |f: &Failing| f.reads.load(Ordering::Relaxed);
    assert_eq!((reads(&own.0), reads(&wrapped.0)), (1, 1), "the loader read a self-retrying source again");
    assert_eq!(reads(&plain), 4, "a source that does not retry itself gets the loader's attempts");
    assert_eq!(loader.counters().read_retries, 3);
}

/// The root payload's length in [`mixed_pack`] (what a successful read of it counts).
fn root_payload_len() -> u64 {
    let dir = tempdir();
    let pack = mixed_pack(dir.path(), "a.vtpk");
    let root = TileId { lod: pack.levels().len() as u32 - 1, x: 0, y: 0 };
    match pack.tile(root).unwrap() {
        Tile::Data(_, payload) => payload.len() as u64,
        _ => 0,
    }
}

/// Every kind of tile, and absent ones (magnified from an ancestor that is itself a page).
fn mixed_with_holes(id: TileId) -> Spec {
    if id.lod == 0 && (id.x + id.y).is_multiple_of(3) { Spec::Absent } else { mixed(id) }
}

#[test]
fn the_memory_tier_serves_pages_again_without_a_read_and_with_the_same_texels() {
    let dir = tempdir();
    let pack = write_pack(&dir.path().join("holes.vtpk"), description(TILE, BORDER, PAGES, 44, 40), mixed_with_holes);
    let grid = VirtualTexture::from_pack(&pack).unwrap().grid;
    let pages = all_pages(0, grid, 0);
    // Twice over, in two loads: the second finds every tile the first read.
    let run = |tier: u64, threads: usize| {
        let source = Counting::new(&pack, true);
        let loader = Loader::with_sources(vec![Arc::clone(&source) as Arc<dyn PageSource>], threads).unwrap();
        loader.set_memory_tier(tier);
        let first = loader.load(&pages);
        let reads = source.reads.load(Ordering::Relaxed);
        let second = loader.load(&pages);
        (first, second, reads, source.reads.load(Ordering::Relaxed) - reads, loader.counters(), loader.memory_tier())
    };
    let (off_first, off_second, off_reads, off_reads_again, off_counters, off_usage) = run(0, 2);
    assert!(off_first.iter().all(LoadedPage::is_ok) && off_counters.absent_filled > 0, "{off_counters:?}");
    assert_eq!(off_reads_again, off_reads, "without the tier every page is read again");
    assert_eq!((off_counters.tier_hits, off_counters.tier_misses), (0, 2 * off_reads as u64));
    assert_eq!(off_usage, TierUsage::default());
    for threads in [1, 4] {
        let (first, second, reads, reads_again, counters, usage) = run(1 << 20, threads);
        assert_eq!(reads_again, 0, "{threads} threads: the second pass read the pack");
        for (i, (on, off)) in first.iter().chain(&second).zip(off_first.iter().chain(&off_second)).enumerate() {
            assert_eq!((&on.page, &on.texels, &on.error), (&off.page, &off.texels, &off.error), "answer {i}");
        }
        for page in &second {
            assert_eq!((page.bytes_read, page.tier_misses), (0, 0), "{:?}", page.page);
            assert!(page.tier_hits >= 1, "{:?}", page.page);
        }
        let hits: u64 = first.iter().chain(&second).map(|p| u64::from(p.tier_hits)).sum();
        assert_eq!((counters.tier_hits, counters.tier_misses), (hits, reads as u64));
        // Every tile is held once (an absent one as the answer "absent").
        assert_eq!(usage.tiles, pages.len());
        let stored: u64 = pages.iter().map(|(page, _)| stored_len(&pack, *page)).sum();
        assert_eq!(usage.bytes, stored + pages.len() as u64 * TIER_ENTRY_OVERHEAD);
        if threads == 1 {
            // Finest first: an absent page's ancestor is read for it, and found when its own turn
            // comes. Two threads may both miss a tile they want at once.
            assert_eq!(reads, pages.len(), "each tile read once");
            let payloads: u64 = pages.iter().map(|(page, _)| payload_len(&pack, *page)).sum();
            assert_eq!(counters.bytes_read, payloads);
            assert!(counters.bytes_read < off_counters.bytes_read / 2, "{counters:?} against {off_counters:?}");
        }
    }
}

/// A tile's stored bytes: its payload, or its constant value.
fn stored_len(pack: &Pack, page: PageId) -> u64 {
    match pack.tile(vortex_pack::TileId::new(page.lod.into(), page.x.into(), page.y.into())).unwrap() {
        Tile::Data(_, bytes) | Tile::Constant(bytes) => bytes.len() as u64,
        Tile::Absent => 0,
    }
}

#[test]
fn a_small_tier_keeps_the_latest_tiles_within_its_budget() {
    let dir = tempdir();
    let pack =
        write_pack(&dir.path().join("raw.vtpk"), description(TILE, BORDER, PAGES, 44, 40), |id| Spec::Raw(seed(id)));
    let tile_cost = stored_len(&pack, PageId::new(0, 0, 0, 0)) + TIER_ENTRY_OVERHEAD;
    let loader = Loader::new(vec![pack], 2).unwrap();
    loader.set_memory_tier(3 * tile_cost + tile_cost / 2);
    let page = |x| (PageId::new(0, 0, x, 0), Slot::from(x));
    for x in 0..4 {
        loader.load(&[page(x)]);
    }
    let usage = loader.memory_tier();
    assert_eq!((usage.tiles, usage.bytes), (3, 3 * tile_cost));
    let hits = |x| loader.load(&[page(x)])[0].tier_hits;
    // 1, 2 and 3 are held; 0, the least recently used, went to make room for 3.
    assert_eq!([hits(3), hits(1), hits(2)], [1, 1, 1]);
    assert_eq!(hits(0), 0, "0 is read again, and 3 (now the least recently used) goes");
    assert_eq!([hits(1), hits(2), hits(0), hits(3)], [1, 1, 1, 0]);
    loader.set_memory_tier(tile_cost);
    assert_eq!(loader.memory_tier().tiles, 1);
    loader.set_memory_tier(0);
    assert_eq!(loader.memory_tier(), TierUsage::default());
}

#[test]
fn a_source_without_a_stored_form_is_read_every_time() {
    let dir = tempdir();
    let pack = mixed_pack(dir.path(), "a.vtpk");
    let source = Counting::new(&pack, false);
    let loader = Loader::with_sources(vec![Arc::clone(&source) as Arc<dyn PageSource>], 2).unwrap();
    loader.set_memory_tier(1 << 20);
    let pages = all_pages(0, loader.textures()[0].grid, 0);
    let first = loader.load(&pages);
    let second = loader.load(&pages);
    assert_eq!(source.reads.load(Ordering::Relaxed), 2 * pages.len());
    assert!(first == second);
    assert!(second.iter().all(|p| p.tier_hits == 0 && p.tier_misses == 1));
    assert_eq!(loader.memory_tier().tiles, 0);
}
