//! Reading a pack from Rust (the `vortex-pack` crate): open it, look at what it holds, find a
//! tile by its `TileId` and decode it to RGBA8.
//!
//!     cargo run --example read_pack -- PACK.vtpk
//!
//! A pack comes from `vortex-tiler split IMAGE --pack PACK.vtpk` (or the `tile_image` example).
//! `Pack::open` maps the file and checks its structure once; every lookup after that is O(1)
//! and borrows the map. Whatever the file claims is held to `Limits` before anything is sized
//! from it, so a damaged or hostile pack is an error naming the file and the byte, not a crash.

use std::collections::BTreeMap;

use vortex_pack::{Pack, Tile, TileId};

fn main() -> std::process::ExitCode {
    let Some(path) = std::env::args().nth(1) else {
        eprintln!("usage: read_pack PACK.vtpk");
        return std::process::ExitCode::FAILURE;
    };
    // `PackError`'s message names the file and, for a damaged pack, the section and byte.
    match read(&path) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            std::process::ExitCode::FAILURE
        }
    }
}

fn read(path: &str) -> vortex_pack::Result<()> {
    let pack = Pack::open(path)?;
    let d = pack.description();
    println!(
        "{path}: {}x{} texels, {}-texel tiles ({} of border), {} levels, {} channel(s) of {} byte(s)",
        d.width, d.height, d.tile_size, d.border, d.level_count, d.channels, d.sample_bytes
    );
    for (lod, level) in pack.levels().iter().enumerate() {
        println!("  LOD {lod}: {}x{} tiles over {}x{} texels", level.tiles_w, level.tiles_h, level.width, level.height);
    }

    // Every tile, by kind: how the pack stores them (`tile` checks the index entry; `tile_checked`
    // checks the payload's CRC-32C too).
    let mut kinds: BTreeMap<&str, u64> = BTreeMap::new();
    for id in pack.ids() {
        let kind = match pack.tile_checked(id)? {
            Tile::Absent => "absent",
            Tile::Constant(_) => "one colour",
            Tile::Data(kind, _) => kind.name(),
        };
        *kinds.entry(kind).or_default() += 1;
    }
    println!("  tiles: {kinds:?}");

    // The coarsest level's one tile, decoded whatever its kind (PNG, JPEG, zstd, BC, raw...):
    // its mean colour is the image's, near enough.
    let root = TileId::new(d.level_count - 1, 0, 0);
    match pack.decode_rgba8(root)? {
        Some(texels) => {
            let n = (texels.len() / 4) as u64;
            let mean: Vec<u64> =
                (0..4).map(|c| texels.iter().skip(c).step_by(4).map(|&v| u64::from(v)).sum::<u64>() / n).collect();
            println!("  root tile {root:?}: mean RGBA {mean:?}");
        }
        None => println!("  root tile {root:?} is absent"),
    }
    Ok(())
}
