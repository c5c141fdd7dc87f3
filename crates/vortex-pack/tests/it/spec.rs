//! `docs/pack-format.md` holds a hex dump of a tiny pack. This test writes that pack with the
//! real writer and compares every byte, so the spec and the code cannot drift apart. After an
//! intended format change, `BLESS=1 cargo test -p vortex-pack --test it spec` rewrites the dump.

use vortex_pack::fuzzing::pyramid_levels;
use vortex_pack::{Description, NewTile, Pack, PackWriter, Tile, TileId, TileKind, WriteOptions};

const BEGIN: &str = "<!-- hexdump:begin -->\n```text\n";
const END: &str = "```\n<!-- hexdump:end -->";

/// The spec's example: a 6x5 grey image in 4-texel tiles without border: 2x2 tiles at LOD 0,
/// one at LOD 1.
fn tiny_pack(path: &std::path::Path) {
    let d = Description {
        width: 6,
        height: 5,
        tile_size: 4,
        border: 0,
        level_count: 2,
        channels: 1,
        sample_bytes: 1,
        sample_format: 0,
    };
    let opts = WriteOptions { alignment: 64, payload_alignment: 8 };
    let mut w = PackWriter::create(path, d, pyramid_levels(&d, 2), br#"{"tileSize":4}"#, opts).unwrap();
    let ramp: Vec<u8> = (0..16).collect();
    let other: Vec<u8> = (0..16).map(|v| 255 - v).collect();
    w.add(TileId { lod: 1, x: 0, y: 0 }, NewTile::Data(TileKind::Raw, &ramp)).unwrap();
    w.add(TileId { lod: 0, x: 0, y: 0 }, NewTile::Constant(&[0x80])).unwrap();
    w.add(TileId { lod: 0, x: 1, y: 0 }, NewTile::Data(TileKind::Raw, &ramp)).unwrap();
    w.add(TileId { lod: 0, x: 1, y: 1 }, NewTile::Data(TileKind::Raw, &other)).unwrap();
    // (0, 1) is never added: absent.
    w.finish().unwrap();
}

/// `xxd`-style: offset, 16 bytes in groups of two, printable ASCII.
fn hexdump(bytes: &[u8]) -> String {
    let mut out = String::new();
    for (i, line) in bytes.chunks(16).enumerate() {
        let hex: Vec<String> = line.chunks(2).map(|p| p.iter().map(|b| format!("{b:02x}")).collect()).collect();
        let text: String =
            line.iter().map(|b| if b.is_ascii_graphic() || *b == b' ' { *b as char } else { '.' }).collect();
        out.push_str(&format!("{:08x}: {:<39}  {text}\n", i * 16, hex.join(" ")));
    }
    out
}

#[test]
fn spec_hexdump_is_what_the_writer_writes() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("tiny.vtpk");
    tiny_pack(&path);
    let bytes = std::fs::read(&path).unwrap();
    let dump = hexdump(&bytes);

    let doc_path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../docs/pack-format.md");
    let doc = std::fs::read_to_string(doc_path).unwrap();
    let start = doc.find(BEGIN).expect("hexdump begin marker") + BEGIN.len();
    let stop = doc[start..].find(END).expect("hexdump end marker") + start;
    if std::env::var_os("BLESS").is_some() {
        std::fs::write(doc_path, format!("{}{dump}{}", &doc[..start], &doc[stop..])).unwrap();
        return;
    }
    assert_eq!(
        &doc[start..stop],
        dump,
        "docs/pack-format.md's hex dump differs from the writer's bytes (bless with BLESS=1)"
    );

    // And the example reads back as the spec describes it.
    let pack = Pack::open(&path).unwrap();
    assert_eq!(bytes.len(), 480);
    assert_eq!(pack.tile(vortex_pack::TileId::new(0, 0, 0)).unwrap(), Tile::Constant(&[0x80]));
    assert_eq!(pack.tile(vortex_pack::TileId::new(0, 0, 1)).unwrap(), Tile::Absent);
    let Tile::Data(TileKind::Raw, shared) = pack.tile(vortex_pack::TileId::new(0, 1, 0)).unwrap() else { panic!() };
    assert_eq!(
        shared.as_ptr(),
        match pack.tile(vortex_pack::TileId::new(1, 0, 0)).unwrap() {
            Tile::Data(_, b) => b.as_ptr(),
            _ => panic!(),
        }
    );
}
