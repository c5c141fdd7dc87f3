//! `serve`: the built binary on 127.0.0.1:0, asked by a raw HTTP/1.1 client (a socket, so
//! malformed requests can be sent too), over inputs made by `split` in a temporary directory.

use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::Command;

use crate::common::cli::{fixture, ok, run, s};
use crate::common::server::Server;

/// sample.png (700 x 500) as a JPEG pack in 64-texel tiles with a border of 1 (payload 62):
/// LOD 0 is 12 x 9 pages, 5 LODs; Deep Zoom levels 10..6 are stored, 5..0 derived.
fn jpeg_pack(dir: &Path) -> PathBuf {
    let pack = dir.join("world.vtpk");
    let args = ["--tile-size", "64", "--border", "1", "--codec", "jpeg", "-q"];
    ok(&[&["split", s(&fixture("sample.png")), "--pack", s(&pack)][..], &args].concat());
    pack
}

#[test]
fn serve_deep_zoom_from_a_pack() {
    let dir = tempfile::tempdir().unwrap();
    let pack_path = jpeg_pack(dir.path());
    let server = Server::start(&[&pack_path], &[]);

    let dzi = server.get("/world.dzi", &[]);
    assert_eq!(dzi.status, 200);
    assert_eq!(dzi.header("content-type"), Some("application/xml"));
    assert_eq!(dzi.header("access-control-allow-origin"), Some("*"));
    let text = dzi.text();
    assert!(text.contains("Format=\"jpeg\" Overlap=\"1\" TileSize=\"62\""), "{text}");
    assert!(text.contains("<Size Width=\"700\" Height=\"500\"/>"), "{text}");

    // An interior tile of the finest level is the stored page, byte for byte.
    let pack = vortex_pack::Pack::open(&pack_path).unwrap();
    let vortex_pack::Tile::Data(vortex_pack::TileKind::Jpeg, stored) =
        pack.tile(vortex_pack::TileId::new(0, 3, 2)).unwrap()
    else {
        panic!("a JPEG page")
    };
    let tile = server.get("/world_files/10/3_2.jpeg", &[]);
    assert_eq!((tile.status, tile.header("content-type")), (200, Some("image/jpeg")));
    assert!(tile.body == stored, "the interior tile is not the stored payload");
    assert!(tile.header("cache-control").unwrap().contains("max-age"));

    // Edge tiles are cropped: the last column keeps 700 - (11 * 62 - 1) texels, the last row
    // 500 - (8 * 62 - 1); the first column and row have no left and top overlap.
    assert_eq!(server.get("/world_files/10/11_8.jpeg", &[]).image_size(), (19, 5));
    assert_eq!(server.get("/world_files/10/0_0.jpeg", &[]).image_size(), (63, 63));
    // Level 6 (LOD 4, one page, 44 x 32) and the derived levels below it, down to 1 x 1.
    assert_eq!(server.get("/world_files/6/0_0.jpeg", &[]).image_size(), (44, 32));
    assert_eq!(server.get("/world_files/5/0_0.jpeg", &[]).image_size(), (22, 16));
    assert_eq!(server.get("/world_files/1/0_0.jpeg", &[]).image_size(), (2, 1));
    assert_eq!(server.get("/world_files/0/0_0.jpeg", &[]).image_size(), (1, 1));
    // A second request for a re-encoded tile comes from the cache, the same bytes.
    let again = server.get("/world_files/10/11_8.jpeg", &[]);
    assert_eq!(again.body, server.get("/world_files/10/11_8.jpeg", &[]).body);
}

#[test]
fn serve_iiif_and_xyz_from_a_pack() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(&[&jpeg_pack(dir.path())], &[]);

    let info = server.raw("GET /world/iiif/info.json HTTP/1.1\r\nHost: example.test:1234");
    assert_eq!(info.status, 200);
    assert!(info.header("content-type").unwrap().contains("json"));
    let json: serde_json::Value = serde_json::from_slice(&info.body).unwrap();
    assert_eq!(json["id"], "http://example.test:1234/world/iiif");
    assert_eq!((json["width"].as_u64(), json["tiles"][0]["width"].as_u64()), (Some(700), Some(62)));
    assert_eq!(json["tiles"][0]["scaleFactors"], serde_json::json!([1, 2, 4, 8, 16]));

    let tile = server.get("/world/iiif/62,124,62,62/62,62/0/default.jpg", &[]);
    assert_eq!((tile.status, tile.image_size()), (200, (62, 62)));
    // The last column at scale 2: 124-texel regions, the last 700 - 620 wide, 40 texels.
    assert_eq!(server.get("/world/iiif/620,0,80,124/40,62/0/default.jpg", &[]).image_size(), (40, 62));
    assert_eq!(server.get("/world/iiif/full/44,32/0/default.jpg", &[]).image_size(), (44, 32));
    for path in [
        "/world/iiif/0,0,62,62/31,31/0/default.jpg",
        "/world/iiif/1,0,62,62/62,62/0/default.jpg",
        "/world/iiif/0,0,62,62/62,62/0/default.png",
    ] {
        assert_eq!(server.get(path, &[]).status, 404, "{path}");
    }
    assert_eq!(server.get("/world/iiif", &[]).status, 303);

    // XYZ: zoom 4 is LOD 0; whole payloads, edge tiles padded as the pack pads them.
    let z4 = server.get("/world/xyz/4/11/8.jpg", &[]);
    assert_eq!((z4.status, z4.header("content-type"), z4.image_size()), (200, Some("image/jpeg"), (62, 62)));
    assert_eq!(server.get("/world/xyz/0/0/0.jpg", &[]).image_size(), (62, 62));
    for path in ["/world/xyz/4/12/0.jpg", "/world/xyz/4/0/9.jpg", "/world/xyz/5/0/0.jpg", "/world/xyz/0/0/0.png"] {
        assert_eq!(server.get(path, &[]).status, 404, "{path}");
    }
}

#[test]
fn serve_pack_file_with_ranges() {
    let dir = tempfile::tempdir().unwrap();
    let pack_path = jpeg_pack(dir.path());
    let file = std::fs::read(&pack_path).unwrap();
    let len = file.len();
    let server = Server::start(&[&pack_path], &[]);

    let whole = server.get("/world.vtpk", &[]);
    assert_eq!((whole.status, whole.header("accept-ranges")), (200, Some("bytes")));
    assert_eq!(whole.header("content-type"), Some("application/octet-stream"));
    assert!(whole.body == file);

    let part = server.get("/world.vtpk", &[("Range", "bytes=0-99")]);
    assert_eq!(part.status, 206);
    assert_eq!(part.header("content-range"), Some(format!("bytes 0-99/{len}").as_str()));
    assert!(part.body == file[..100]);
    let open = server.get("/world.vtpk", &[("Range", "bytes=100-")]);
    assert_eq!((open.status, open.body.len()), (206, len - 100));
    assert!(open.body == file[100..]);
    let suffix = server.get("/world.vtpk", &[("Range", "bytes=-64")]);
    assert_eq!(suffix.header("content-range"), Some(format!("bytes {}-{}/{len}", len - 64, len - 1).as_str()));
    assert!(suffix.body == file[len - 64..]);

    let past = server.get("/world.vtpk", &[("Range", &format!("bytes={len}-"))]);
    assert_eq!((past.status, past.header("content-range")), (416, Some(format!("bytes */{len}").as_str())));
    assert_eq!(server.get("/world.vtpk", &[("Range", "bytes=0-1,4-5")]).status, 416);
    for bad in ["bytes=abc", "bytes=5-1", "bytes=-"] {
        assert_eq!(server.get("/world.vtpk", &[("Range", bad)]).status, 400, "{bad}");
    }
}

#[test]
fn serve_etags_head_and_cors() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(&[&jpeg_pack(dir.path())], &[]);
    for path in ["/world_files/10/3_2.jpeg", "/world_files/10/11_8.jpeg", "/world.vtpk", "/world.dzi"] {
        let first = server.get(path, &[]);
        let etag = first.header("etag").unwrap_or_else(|| panic!("{path}: no ETag")).to_string();
        let again = server.get(path, &[("If-None-Match", &etag)]);
        assert_eq!((again.status, again.body.len()), (304, 0), "{path}");
        assert_eq!(server.get(path, &[("If-None-Match", "\"other\"")]).status, 200, "{path}");
        let head = server.request("HEAD", path, &[]);
        assert_eq!(head.status, 200, "{path}");
        assert!(head.body.is_empty(), "{path}");
        assert_eq!(head.header("content-length"), Some(first.body.len().to_string().as_str()), "{path}");
    }
    // Tiles of different coordinates have different ETags.
    let a = server.get("/world_files/10/3_2.jpeg", &[]);
    let b = server.get("/world_files/10/3_3.jpeg", &[]);
    assert_ne!(a.header("etag"), b.header("etag"));

    let pre = server.request(
        "OPTIONS",
        "/world.vtpk",
        &[("Origin", "http://x"), ("Access-Control-Request-Headers", "range")],
    );
    assert_eq!(pre.status, 204);
    assert_eq!(pre.header("access-control-allow-origin"), Some("*"));
    assert!(pre.header("access-control-allow-headers").unwrap().contains("Range"));
    assert_eq!(server.request("POST", "/world.vtpk", &[]).status, 405);
}

#[test]
fn serve_answers_bad_requests_and_keeps_serving() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(&[&jpeg_pack(dir.path())], &[]);
    let cases = [
        "/nobody.dzi",
        "/nobody_files/1/0_0.jpeg",
        "/nobody/iiif/info.json",
        "/world_files/11/0_0.jpeg",
        "/world_files/10/12_0.jpeg",
        "/world_files/10/0_9.jpeg",
        "/world_files/99999999999999999999/0_0.jpeg",
        "/world_files/4294967296/0_0.jpeg",
        "/world_files/10/-1_0.jpeg",
        "/world_files/10/0_0.png",
        "/world_files/10/0_0",
        "/world_files/10",
        "/world_files/../../etc/passwd",
        "/world_files/%2e%2e/%2e%2e/etc/passwd",
        "/%2e%2e/world.vtpk",
        "/world_files/10/%zz.jpeg",
        "/world/xyz/99999999999/0/0.jpg",
        "/world/iiif/0,0,1/1,1/0/default.jpg",
        "/world/iiif/99999999999999999999999,0,1,1/1,1/0/default.jpg",
        "/world.png",
        "/view/nobody",
        "/openseadragon/openseadragon.min.js",
    ];
    for path in cases {
        let r = server.get(path, &[]);
        assert!(r.status == 400 || r.status == 404, "{path}: {r:?}");
        assert!(!r.body.is_empty() && r.header("content-type").unwrap().starts_with("text/plain"), "{path}: {r:?}");
    }
    // Not HTTP at all, and a request without a Host (the IIIF id falls back to the address).
    let garbage = server.raw("GARBAGE");
    assert!((400..500).contains(&garbage.status), "{garbage:?}");
    let no_host = server.raw("GET /world/iiif/info.json HTTP/1.0");
    assert_eq!(no_host.status, 200);
    assert!(no_host.text().contains(&format!("http://127.0.0.1:{}/world/iiif", server.port)));
    // Still serving.
    assert_eq!(server.get("/world.dzi", &[]).status, 200);
    assert_eq!(server.get("/", &[]).status, 200);
}

#[test]
fn serve_index_and_viewer_pages() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(&[&jpeg_pack(dir.path())], &[]);
    let index = server.get("/", &[]);
    assert_eq!(index.header("content-type"), Some("text/html; charset=utf-8"));
    let html = index.text();
    for needle in ["/view/world", "/world.dzi", "/world/iiif/info.json", "/world.vtpk", "700 x 500"] {
        assert!(html.contains(needle), "index lacks {needle}: {html}");
    }
    let view = server.get("/view/world", &[]).text();
    for needle in
        ["window.viewer = OpenSeadragon(", "crossOriginPolicy: \"Anonymous\"", "\"/world.dzi\"", "openseadragon@6.1"]
    {
        assert!(view.contains(needle), "view lacks {needle}: {view}");
    }

    // With a local OpenSeadragon, its files are served and the page uses them.
    let osd = dir.path().join("osd");
    std::fs::create_dir_all(osd.join("images")).unwrap();
    std::fs::write(osd.join("openseadragon.min.js"), "// osd").unwrap();
    std::fs::write(osd.join("images/home.png"), "png").unwrap();
    let local = Server::start(&[&dir.path().join("world.vtpk")], &["--openseadragon", s(&osd)]);
    assert!(local.get("/view/world", &[]).text().contains("src=\"/openseadragon/openseadragon.min.js\""));
    let js = local.get("/openseadragon/openseadragon.min.js", &[]);
    assert_eq!((js.status, js.text().as_str()), (200, "// osd"));
    assert_eq!(local.get("/openseadragon/images/home.png", &[]).status, 200);
    assert_eq!(local.get("/openseadragon/../world.vtpk", &[]).status, 400);
}

#[test]
fn serve_split_and_viewer_directories() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let sample = fixture("sample.png");
    let tiles = d.join("tiles");
    ok(&["split", s(&sample), "-o", s(&tiles), "--tile-size", "64", "--border", "2", "--codec", "png", "-q"]);
    let dzi = d.join("deep");
    ok(&["split", s(&sample), "-o", s(&dzi), "--layout", "dzi", "-q"]);
    let iiif = d.join("image");
    ok(&["split", s(&sample), "-o", s(&iiif), "--layout", "iiif", "-q"]);
    let xyz = d.join("map");
    ok(&["split", s(&sample), "-o", s(&xyz), "--layout", "xyz", "-q"]);
    let zstd = d.join("z.vtpk");
    ok(&["split", s(&sample), "--pack", s(&zstd), "--tile-size", "64", "--codec", "zstd", "-q"]);
    // A link out of a viewer directory is never followed.
    std::os::unix::fs::symlink(&sample, dzi.join("sample_files/escape.png")).unwrap();
    let server = Server::start(&[&tiles, &dzi, &iiif, &xyz, &zstd], &[]);

    // A split directory of PNG tiles (payload 60): its stored interior tile as it is.
    assert!(server.get("/tiles.dzi", &[]).text().contains("Format=\"png\" Overlap=\"2\" TileSize=\"60\""));
    let t = server.get("/tiles_files/10/3_2.png", &[]);
    assert_eq!((t.status, t.header("content-type")), (200, Some("image/png")));
    let info: serde_json::Value = serde_json::from_slice(&std::fs::read(tiles.join("info.json")).unwrap()).unwrap();
    let names =
        vortex_tiler::formats::tiles::filename::FilenameFormat::parse(info["filenameFormat"].as_str().unwrap(), 3)
            .unwrap();
    assert!(t.body == std::fs::read(tiles.join(names.format(&[0, 3, 2]))).unwrap());
    assert_eq!(t.image_size(), (64, 64));
    assert_eq!(server.get("/tiles_files/10/11_8.png", &[]).image_size(), (700 - (11 * 60 - 2), 500 - (8 * 60 - 2)));

    // IIIF and XYZ tiles of a bordered pyramid are the page's payload: the Deep Zoom tile
    // (the whole page here) without its 2-texel overlap.
    let page = image::load_from_memory(&t.body).unwrap().to_rgb8();
    let payload = image::imageops::crop_imm(&page, 2, 2, 60, 60).to_image();
    let iiif_tile = server.get("/tiles/iiif/180,120,60,60/60,60/0/default.png", &[]);
    assert_eq!(image::load_from_memory(&iiif_tile.body).unwrap().to_rgb8(), payload);
    let xyz_tile = server.get("/tiles/xyz/4/3/2.png", &[]);
    assert_eq!(image::load_from_memory(&xyz_tile.body).unwrap().to_rgb8(), payload);

    // A zstd pack is served as PNG, decoded.
    assert_eq!(server.get("/z_files/10/1_1.png", &[]).image_size(), (64, 64));
    assert_eq!(server.get("/z/xyz/0/0/0.png", &[]).status, 200);

    // A Deep Zoom directory: its files as they are.
    let stored = std::fs::read(dzi.join("sample_files/10/0_0.jpeg")).unwrap();
    assert!(server.get("/deep_files/10/0_0.jpeg", &[]).body == stored);
    assert!(server.get("/deep.dzi", &[]).text().contains("TileSize=\"254\""));
    assert_eq!(server.get("/deep_files/escape.png", &[]).status, 404);
    assert_eq!(server.get("/deep_files/10/../../../sample.png", &[]).status, 400);

    // IIIF: info.json's id rewritten to this server; tiles as stored.
    let info: serde_json::Value = serde_json::from_slice(&server.get("/image/iiif/info.json", &[]).body).unwrap();
    assert_eq!(info["id"], format!("http://127.0.0.1:{}/image/iiif", server.port));
    let full = server.get("/image/iiif/full/350,250/0/default.jpg", &[]);
    assert_eq!((full.status, full.header("content-type")), (200, Some("image/jpeg")));

    // XYZ: tilejson.json and tiles.
    assert_eq!(server.get("/map/xyz/tilejson.json", &[]).status, 200);
    assert!(server.get("/map/xyz/0/0/0.jpg", &[]).status == 200);
    assert_eq!(server.get("/map.dzi", &[]).status, 404);
}

#[test]
fn serve_stops_cleanly_on_sigterm() {
    let dir = tempfile::tempdir().unwrap();
    let mut server = Server::start(&[&jpeg_pack(dir.path())], &[]);
    assert_eq!(server.get("/world.dzi", &[]).status, 200);
    let kill = Command::new("kill").args(["-TERM", &server.child.id().to_string()]).status().unwrap();
    assert!(kill.success());
    // The child's exit is the event: waited for, not polled (a server that never stops hangs
    // the test, which the harness's own timeout reports, rather than a guess at how long is long).
    let status = server.child.wait().unwrap();
    assert_eq!(status.code(), Some(0));
    let mut err = String::new();
    server.child.stderr.take().unwrap().read_to_string(&mut err).unwrap();
    assert!(err.contains("SIGTERM") && err.contains("stopped"), "{err}");
}

#[test]
fn serve_help_teaches_the_routes() {
    let help = ok(&["serve", "--help"]);
    for needle in
        ["/NAME.dzi", "/NAME/iiif/info.json", "/NAME/xyz/", "Range", "Examples:", "--openseadragon", "[default: 64M]"]
    {
        assert!(help.contains(needle), "serve --help lacks {needle}");
    }
}

#[test]
fn serve_refuses_bad_inputs_at_start() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let missing = run(&["serve", s(&d.join("missing.vtpk")), "--addr", "127.0.0.1:0"]);
    crate::common::cli::fails_with(&missing, &["missing.vtpk"]);
    let not_a_pack = d.join("notes.vtpk");
    std::fs::write(&not_a_pack, "hello").unwrap();
    crate::common::cli::fails_with(
        &run(&["serve", s(&not_a_pack), "--addr", "127.0.0.1:0"]),
        &["notes.vtpk", "not a pack"],
    );

    let pack = jpeg_pack(d);
    std::fs::create_dir(d.join("other")).unwrap();
    let twin = d.join("other/world.vtpk");
    std::fs::copy(&pack, &twin).unwrap();
    crate::common::cli::fails_with(
        &run(&["serve", s(&pack), s(&twin), "--addr", "127.0.0.1:0"]),
        &["both named 'world'"],
    );

    let server = Server::start(&[&pack], &[]);
    let addr = format!("127.0.0.1:{}", server.port);
    crate::common::cli::fails_with(&run(&["serve", s(&pack), "--addr", &addr]), &["cannot listen on", &addr]);
}
