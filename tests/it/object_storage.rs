//! Outputs at `s3://` URLs against a real S3 server (moto, `common::s3`): what lands in the
//! bucket is byte for byte what a local run writes; a prefix that is not ours is refused; a
//! failed run (a missing bucket, a broken input, the server gone) says which object failed
//! and why, exits non-zero, and leaves no object and no open multipart upload.

use std::collections::BTreeMap;
use std::path::Path;
use std::time::Duration;

use crate::common::cli::{fixture, s, wait_or_kill};
use crate::common::s3::Moto;

/// Every regular file under `dir`, by its path relative to `dir` ('/'-separated).
fn files(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    fn walk(dir: &Path, base: &Path, out: &mut BTreeMap<String, Vec<u8>>) {
        for entry in std::fs::read_dir(dir).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                walk(&path, base, out);
            } else {
                let rel = path.strip_prefix(base).unwrap().to_string_lossy().replace('\\', "/");
                out.insert(rel, std::fs::read(&path).unwrap());
            }
        }
    }
    let mut out = BTreeMap::new();
    walk(dir, dir, &mut out);
    out
}

/// Asserts that two sets of files are equal, naming the first difference.
fn assert_same_files(bucket: &BTreeMap<String, Vec<u8>>, local: &BTreeMap<String, Vec<u8>>, what: &str) {
    let names = |m: &BTreeMap<String, Vec<u8>>| m.keys().cloned().collect::<Vec<_>>();
    assert_eq!(names(bucket), names(local), "{what}: the bucket's objects are not the local run's files");
    for (name, bytes) in local {
        assert!(
            bucket[name] == *bytes,
            "{what}: {name} differs ({} bytes in the bucket, {} local)",
            bucket[name].len(),
            bytes.len()
        );
    }
}

/// A zip's entries by name, and its comment as the entry "".
fn zip_entries(bytes: &[u8]) -> BTreeMap<String, Vec<u8>> {
    let mut zip = zip::ZipArchive::new(std::io::Cursor::new(bytes)).unwrap();
    let mut out = BTreeMap::from([(String::new(), zip.comment().to_vec())]);
    for i in 0..zip.len() {
        let mut entry = zip.by_index(i).unwrap();
        let mut body = Vec::new();
        std::io::Read::read_to_end(&mut entry, &mut body).unwrap();
        out.insert(entry.name().unwrap().into_owned(), body);
    }
    out
}

/// The objects under `prefix/`, downloaded.
fn download(moto: &Moto, bucket: &str, prefix: &str) -> BTreeMap<String, Vec<u8>> {
    let dir = tempfile::tempdir().unwrap();
    moto.boto(&["get", bucket, &format!("{prefix}/"), s(dir.path())]);
    files(dir.path())
}

fn stderr(out: &std::process::Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

#[test]
fn deep_zoom_a_tile_directory_a_pack_and_pmtiles_in_a_bucket_equal_the_local_run() {
    let Some(moto) = Moto::start("the s3:// output test") else { return };
    moto.boto(&["mb", "tiles"]);
    let work = tempfile::tempdir().unwrap();
    let tmp = tempfile::tempdir().unwrap();
    let local = work.path().join("local");
    let input = fixture("sample.png");
    let common = ["--tile-size", "128", "-q"];
    let mut args = vec!["split", s(&input)];
    let (dz, vt, pack, pm) = (local.join("dz"), local.join("vt"), local.join("p.vtpk"), local.join("m.pmtiles"));
    args.extend(["-o", s(&dz), "--layout", "dzi", "-o", s(&vt), "--pack", s(&pack), "--pmtiles", s(&pm)]);
    args.extend(common);
    let out = moto.run(&args, tmp.path());
    assert!(out.status.success(), "local run: {}", stderr(&out));

    let mut args = vec!["split", s(&input)];
    args.extend(["-o", "s3://tiles/run/dz", "--layout", "dzi", "-o", "s3://tiles/run/vt"]);
    args.extend(["--pack", "s3://tiles/run/p.vtpk", "--pmtiles", "s3://tiles/run/m.pmtiles"]);
    args.extend(common);
    let out = moto.run(&args, tmp.path());
    assert!(out.status.success(), "s3 run: {}", stderr(&out));

    for (prefix, dir) in [("run/dz", &dz), ("run/vt", &vt)] {
        let mut bucket = download(&moto, "tiles", prefix);
        let marker = bucket.remove(".vortex-tiler").unwrap_or_else(|| panic!("{prefix}: no marker"));
        let marker = String::from_utf8(marker).unwrap();
        assert!(marker.contains("\"state\":\"complete\""), "{prefix}: {marker}");
        assert_same_files(&bucket, &files(dir), prefix);
    }
    let got = tempfile::tempdir().unwrap();
    for (key, path) in [("run/p.vtpk", &pack), ("run/m.pmtiles", &pm)] {
        let keys = moto.boto(&["get", "tiles", key, s(got.path())]);
        assert_eq!(keys, [key.to_string()]);
        let name = key.rsplit('/').next().unwrap();
        let bucket = std::fs::read(got.path().join(name)).unwrap();
        assert!(bucket == std::fs::read(path).unwrap(), "{key} differs from the local file");
    }
    assert!(moto.boto(&["uploads", "tiles"]).is_empty(), "a multipart upload was left open");
    // The one-object outputs' local temporaries are gone.
    assert_eq!(std::fs::read_dir(tmp.path()).unwrap().count(), 0, "TMPDIR keeps staged files");
}

#[test]
fn ome_zarr_zipped_or_not_and_a_tiff_in_a_bucket_equal_the_local_files() {
    let Some(moto) = Moto::start("the s3:// .ozx and TIFF test") else { return };
    moto.boto(&["mb", "tiles"]);
    let work = tempfile::tempdir().unwrap();
    let tmp = tempfile::tempdir().unwrap();
    let input = fixture("sample.png");
    for (name, extra) in [("s.ozx", ["--layout", "ome-zarr"]), ("s.tif", ["--tile-size", "128"])] {
        let local = work.path().join(name);
        let url = format!("s3://tiles/files/{name}");
        for dest in [s(&local), url.as_str()] {
            let mut args = vec!["split", s(&input), "-o", dest, "-q"];
            args.extend(extra);
            let out = moto.run(&args, tmp.path());
            assert!(out.status.success(), "{dest}: {}", stderr(&out));
        }
        let got = tempfile::tempdir().unwrap();
        let key = format!("files/{name}");
        assert_eq!(moto.boto(&["get", "tiles", &key, s(got.path())]), std::slice::from_ref(&key));
        let (bucket, local) = (std::fs::read(got.path().join(name)).unwrap(), std::fs::read(&local).unwrap());
        if name.ends_with(".ozx") {
            // A .ozx's shards go into the zip as they complete, in an order the threads
            // decide, locally too: the same entries and comment, byte for byte.
            assert_same_files(&zip_entries(&bucket), &zip_entries(&local), &key);
        } else {
            assert!(bucket == local, "{key} differs from the local file");
        }
    }
    // An OME-Zarr directory (0.5, sharded): staged, then uploaded file by file.
    let local = work.path().join("s.ome.zarr");
    for dest in [s(&local), "s3://tiles/files/s.ome.zarr"] {
        let out = moto.run(&["split", s(&input), "-o", dest, "--tile-size", "128", "-q"], tmp.path());
        assert!(out.status.success(), "{dest}: {}", stderr(&out));
    }
    let mut bucket = download(&moto, "tiles", "files/s.ome.zarr");
    assert!(bucket.remove(".vortex-tiler").is_some(), "no marker");
    assert_same_files(&bucket, &files(&local), "s.ome.zarr");
    assert!(moto.boto(&["uploads", "tiles"]).is_empty(), "a multipart upload was left open");
    assert_eq!(std::fs::read_dir(tmp.path()).unwrap().count(), 0, "TMPDIR keeps staged files");
}

#[test]
fn a_prefix_or_object_that_is_not_ours_is_refused_and_ours_is_replaced() {
    let Some(moto) = Moto::start("the s3:// claim test") else { return };
    moto.boto(&["mb", "tiles"]);
    let tmp = tempfile::tempdir().unwrap();
    let input = fixture("sample.png");
    let dzi = |url: &str| moto.run(&["split", s(&input), "-o", url, "--layout", "dzi", "-q"], tmp.path());
    // A previous output of ours is replaced, twice over.
    for _ in 0..2 {
        let out = dzi("s3://tiles/ours");
        assert!(out.status.success(), "{}", stderr(&out));
    }
    assert!(download(&moto, "tiles", "ours").contains_key("sample.dzi"));
    // Somebody's object under the prefix: refused, named, kept.
    moto.boto(&["put", "tiles", "theirs/notes.txt", "my notes"]);
    let out = dzi("s3://tiles/theirs");
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    let err = stderr(&out);
    assert!(
        err.contains("s3://tiles/theirs") && err.contains("theirs/notes.txt") && err.contains("not a Deep Zoom"),
        "{err}"
    );
    assert_eq!(download(&moto, "tiles", "theirs").keys().collect::<Vec<_>>(), ["notes.txt"]);
    // Somebody's object where a pack goes: only with --force.
    moto.boto(&["put", "tiles", "theirs.vtpk", "not a pack"]);
    let out = moto.run(&["split", s(&input), "--pack", "s3://tiles/theirs.vtpk", "-q"], tmp.path());
    let err = stderr(&out);
    assert!(out.status.code() == Some(1) && err.contains("--force") && err.contains("s3://tiles/theirs.vtpk"), "{err}");
    let out = moto.run(&["split", s(&input), "--pack", "s3://tiles/theirs.vtpk", "-q", "--force"], tmp.path());
    assert!(out.status.success(), "{}", stderr(&out));
    // A URL that is no bucket's.
    let out = dzi("s3://Bad_Bucket/x");
    let err = stderr(&out);
    assert!(out.status.code() == Some(1) && err.contains("Bad_Bucket") && err.contains("lower-case"), "{err}");
}

/// The shared files' profile stands in for the environment, as in the AWS CLI: with no
/// `AWS_*` variable but `AWS_PROFILE`, the keys come from `~/.aws/credentials`, the region and
/// an http:// endpoint (this server) from `~/.aws/config`, and the pack lands in the bucket as
/// a local run writes it. A profile that assumes a role is refused, naming it; nothing lands.
#[test]
fn an_aws_profile_s_keys_region_and_endpoint_are_used() {
    let Some(moto) = Moto::start("the AWS profile test") else { return };
    moto.boto(&["mb", "tiles"]);
    let (home, tmp, work) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    let endpoint = moto.env().into_iter().find(|(k, _)| *k == "AWS_ENDPOINT_URL").unwrap().1;
    let aws = home.path().join(".aws");
    std::fs::create_dir(&aws).unwrap();
    let config = format!(
        "[profile lab]\nregion = us-east-1\nendpoint_url = {endpoint}\n\n[profile admin]\nrole_arn = arn:aws:iam::1:role/x\nsource_profile = lab\n"
    );
    std::fs::write(aws.join("config"), config).unwrap();
    std::fs::write(aws.join("credentials"), "[lab]\naws_access_key_id = test\naws_secret_access_key = test\n").unwrap();
    let input = fixture("sample.png");
    let local = work.path().join("p.vtpk");
    let out = moto.run(&["split", s(&input), "--pack", s(&local), "--tile-size", "128", "-q"], tmp.path());
    assert!(out.status.success(), "local run: {}", stderr(&out));
    let with_profile = |profile: &str, url: &str| {
        let mut cmd = std::process::Command::new(crate::common::cli::BIN);
        cmd.args(["split", s(&input), "--pack", url, "--tile-size", "128", "-q"]);
        cmd.env("HOME", home.path()).env("TMPDIR", tmp.path()).env("AWS_PROFILE", profile).env("NO_COLOR", "1");
        let others = ["AWS_DEFAULT_REGION", "AWS_ENDPOINT", "AWS_SESSION_TOKEN", "AWS_CONFIG_FILE"];
        for name in moto.env().into_iter().map(|(k, _)| k).chain(others).chain(["AWS_SHARED_CREDENTIALS_FILE"]) {
            cmd.env_remove(name);
        }
        cmd.output().unwrap()
    };
    let out = with_profile("lab", "s3://tiles/p.vtpk");
    assert!(out.status.success(), "profile run: {}", stderr(&out));
    let got = tempfile::tempdir().unwrap();
    assert_eq!(moto.boto(&["get", "tiles", "p.vtpk", s(got.path())]), ["p.vtpk"]);
    assert!(std::fs::read(got.path().join("p.vtpk")).unwrap() == std::fs::read(&local).unwrap());
    let out = with_profile("admin", "s3://tiles/q.vtpk");
    let err = stderr(&out);
    assert!(out.status.code() == Some(1) && err.contains("'admin'") && err.contains("role_arn"), "{err}");
    assert_eq!(moto.boto(&["count", "tiles", "q"]), ["0"]);
}

#[test]
fn a_failed_run_names_the_object_and_leaves_nothing() {
    let Some(moto) = Moto::start("the s3:// failure test") else { return };
    moto.boto(&["mb", "tiles"]);
    let tmp = tempfile::tempdir().unwrap();
    let input = fixture("sample.png");
    // A bucket that does not exist: the server's reply, for a directory and for a pack.
    let out = moto.run(&["split", s(&input), "-o", "s3://no-such-bucket/x", "--layout", "dzi", "-q"], tmp.path());
    let err = stderr(&out);
    assert!(
        out.status.code() == Some(1) && err.contains("s3://no-such-bucket/x") && err.contains("NoSuchBucket"),
        "{err}"
    );
    let out = moto.run(&["split", s(&input), "--pack", "s3://no-such-bucket/p.vtpk", "-q"], tmp.path());
    let err = stderr(&out);
    assert!(
        out.status.code() == Some(1) && err.contains("s3://no-such-bucket/p.vtpk") && err.contains("NoSuchBucket"),
        "{err}"
    );
    // An input that breaks after its first rows: the tiles already uploaded are deleted.
    let bytes = std::fs::read(&input).unwrap();
    let broken = tmp.path().join("broken.png");
    std::fs::write(&broken, &bytes[..bytes.len() * 2 / 3]).unwrap();
    let out = moto
        .run(&["split", s(&broken), "-o", "s3://tiles/cut", "--layout", "dzi", "--tile-size", "64", "-q"], tmp.path());
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    let out = moto.run(&["split", s(&broken), "--pack", "s3://tiles/cut.vtpk", "-q"], tmp.path());
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    std::fs::remove_file(&broken).unwrap();
    let left = download(&moto, "tiles", "");
    assert!(left.is_empty(), "objects left: {:?}", left.keys().collect::<Vec<_>>());
    assert!(moto.boto(&["uploads", "tiles"]).is_empty(), "a multipart upload was left open");
    assert_eq!(std::fs::read_dir(tmp.path()).unwrap().count(), 0, "TMPDIR keeps staged files");
}

#[test]
fn the_server_stopped_mid_upload_is_a_clear_error() {
    let Some(mut moto) = Moto::start("the s3:// server-stopped test") else { return };
    moto.boto(&["mb", "tiles"]);
    let tmp = tempfile::tempdir().unwrap();
    // Enough 32-texel tiles (some 12000) that the run is still uploading when the server
    // stops; a streamed pack of the same tiles beside them.
    let input = tmp.path().join("noise.ppm");
    noise_ppm(&input, 3000, 3000, 0);
    let work = tempfile::tempdir().unwrap();
    let args = ["split", s(&input), "-o", "s3://tiles/big", "--layout", "dzi", "--tile-size", "32", "-q"];
    let args = [&args[..], &["--pack", "s3://tiles/big.vtpk"]].concat();
    let mut child = moto.command(&args, work.path()).stderr(std::process::Stdio::piped()).spawn().unwrap();
    // Once tiles are arriving (the marker and more), the server goes; a run that ends first is
    // named (one that never uploads is ended by CI's test timeout).
    loop {
        let count: usize = moto.boto(&["count", "tiles", "big/"])[0].parse().unwrap();
        if count > 3 {
            break;
        }
        assert!(child.try_wait().unwrap().is_none(), "the run ended before the server was stopped");
        std::thread::sleep(Duration::from_millis(50));
    }
    moto.stop();
    let pid = child.id();
    let out = wait_or_kill(pid, "split to a stopped server", move || child.wait_with_output().unwrap());
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "the run did not fail (did it end before the server stopped?): {err}");
    assert!(err.contains("error: s3://tiles/big") && err.contains("failed"), "{err}");
    assert!(err.contains("Connection refused"), "the reply (no connection) is not named: {err}");
    assert!(!err.contains("panicked"), "{err}");
}

/// Two runs at one prefix (a job submitted twice): the second, started while the first is
/// writing, watches the first's marker beat (every second here, `Moto::env`) and stops before
/// it writes or deletes anything; the first finishes whole. A run killed outright is taken
/// over once its marker has stood still for four of its beats, and the result is the local
/// run's.
#[test]
fn a_second_run_on_a_prefix_being_written_is_refused_and_a_killed_ones_taken_over() {
    let Some(moto) = Moto::start("the s3:// two-runs test") else { return };
    moto.boto(&["mb", "tiles"]);
    let (work, tmp) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    // Some 3000 tiles of 64 texels: several seconds of PUTs to moto, so that the first run
    // is still writing when the second has looked (a run that ends first is named).
    let input = work.path().join("noise.ppm");
    noise_ppm(&input, 3072, 3072, 5);
    let local = work.path().join("local");
    let args = |dest: &str| -> Vec<String> {
        ["split", s(&input), "-o", dest, "--layout", "dzi", "--tile-size", "64", "-q"].map(String::from).to_vec()
    };
    fn refs(a: &[String]) -> Vec<&str> {
        a.iter().map(String::as_str).collect()
    }
    let out = moto.run(&refs(&args(s(&local))), tmp.path());
    assert!(out.status.success(), "local run: {}", stderr(&out));
    let local = files(&local);
    let writing = |child: &mut std::process::Child, prefix: &str| loop {
        assert!(child.try_wait().unwrap().is_none(), "the first run ended before it was watched");
        if moto.quick_count("tiles", prefix) > 20 {
            break;
        }
        std::thread::sleep(Duration::from_millis(50));
    };

    let mut first = moto.command(&refs(&args("s3://tiles/busy")), tmp.path()).spawn().unwrap();
    writing(&mut first, "busy/");
    let second = moto.run(&refs(&args("s3://tiles/busy")), tmp.path());
    let err = stderr(&second);
    assert_eq!(second.status.code(), Some(1), "{err}");
    assert!(err.contains("error: s3://tiles/busy: another run is writing it"), "{err}");
    assert!(first.wait().unwrap().success(), "the first run failed beside the refused one");
    let mut bucket = download(&moto, "tiles", "busy");
    let marker = String::from_utf8(bucket.remove(".vortex-tiler").expect("no marker")).unwrap();
    assert!(marker.contains("\"state\":\"complete\""), "{marker}");
    assert_same_files(&bucket, &local, "busy");

    let mut killed = moto.command(&refs(&args("s3://tiles/killed")), tmp.path()).spawn().unwrap();
    writing(&mut killed, "killed/");
    killed.kill().unwrap();
    killed.wait().unwrap();
    let out = moto.run(&refs(&args("s3://tiles/killed")), tmp.path());
    let err = stderr(&out);
    assert!(out.status.success(), "{err}");
    assert!(err.contains("watching its marker for 4 s"), "{err}");
    let mut bucket = download(&moto, "tiles", "killed");
    bucket.remove(".vortex-tiler").expect("no marker");
    assert_same_files(&bucket, &local, "killed");
}

/// A noise image of `w` x `h` as a PPM at `path` (written fast, read fast, no two tiles alike),
/// different for each `seed`.
fn noise_ppm(path: &Path, w: usize, h: usize, seed: u64) {
    let mut state = 0x9E37_79B9_7F4A_7C15u64 ^ seed.wrapping_mul(0xD1B5_4A32_D192_ED03);
    let mut ppm = format!("P6 {w} {h} 255\n").into_bytes();
    ppm.extend((0..w * h * 3).map(|i| {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        // Smooth enough to compress, noisy enough that no two pages are alike.
        ((i / 3 % w) as u64 / 4 + (state & 15)) as u8
    }));
    std::fs::write(path, ppm).unwrap();
}

/// The object at `key`, downloaded.
fn object(moto: &Moto, bucket: &str, key: &str) -> Vec<u8> {
    let got = tempfile::tempdir().unwrap();
    assert_eq!(moto.boto(&["get", bucket, key, s(got.path())]), [key.to_string()], "no object {key}");
    std::fs::read(got.path().join(key.rsplit('/').next().unwrap())).unwrap()
}

/// The tiling options of the scale-out tests: 32-texel pages over a 300 x 200 image, so that
/// three shards are cut below a level that `merge` makes.
const SHARDED: [&str; 5] = ["--tile-size", "32", "--border", "2", "-q"];

/// `split --shard I/N` writes its shard pack to `s3://` (`{shard}` in the URL as in a path),
/// the same bytes as to a local file; `merge` reads them from the bucket, listed under a
/// prefix or named one by one, and writes the one-machine pack, byte for byte, into the
/// bucket or to a local file.
#[test]
fn shards_in_a_bucket_merge_to_the_one_machine_pack_in_the_bucket_or_locally() {
    let Some(moto) = Moto::start("the s3:// scale-out test") else { return };
    moto.boto(&["mb", "tiles"]);
    let (work, tmp) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    let input = work.path().join("scan.ppm");
    noise_ppm(&input, 300, 200, 1);
    let run = |args: &[&str]| {
        let out = moto.run(&[args, &SHARDED[..]].concat(), tmp.path());
        assert!(out.status.success(), "{args:?}: {}", stderr(&out));
    };
    let one = work.path().join("one.vtpk");
    run(&["split", s(&input), "--pack", s(&one)]);
    for i in 0..3 {
        run(&["split", s(&input), "--pack", "s3://tiles/parts/shard-{shard}.vtpk", "--shard", &format!("{i}/3")]);
    }
    let local_shard = work.path().join("shard-1.vtpk");
    run(&["split", s(&input), "--pack", s(&local_shard), "--shard", "1/3"]);
    assert!(
        object(&moto, "tiles", "parts/shard-1.vtpk") == std::fs::read(&local_shard).unwrap(),
        "the shard pack in the bucket differs from the local one"
    );
    let one = std::fs::read(&one).unwrap();

    // A prefix's objects, into the bucket.
    let out = moto.run(&["merge", "s3://tiles/parts/", "-o", "s3://tiles/merged.vtpk", "--json"], tmp.path());
    assert!(out.status.success(), "merge to s3: {}", stderr(&out));
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(report["shards"], 3, "{report}");
    assert_eq!(report["uploadedBytes"].as_u64(), Some(one.len() as u64), "{report}");
    assert!(object(&moto, "tiles", "merged.vtpk") == one, "the merged pack in the bucket is not the one-machine pack");

    // The objects named, in any order, and a local shard beside them, into a local file.
    let merged = work.path().join("merged.vtpk");
    let args = ["merge", "s3://tiles/parts/shard-2.vtpk", s(&local_shard), "s3://tiles/parts/shard-0.vtpk"];
    let out = moto.run(&[&args[..], &["-o", s(&merged), "-q"]].concat(), tmp.path());
    assert!(out.status.success(), "merge to a local file: {}", stderr(&out));
    assert!(std::fs::read(&merged).unwrap() == one, "the local merge is not the one-machine pack");

    assert!(moto.boto(&["uploads", "tiles"]).is_empty(), "a multipart upload was left open");
    assert_eq!(std::fs::read_dir(tmp.path()).unwrap().count(), 0, "TMPDIR keeps staged or downloaded files");
}

/// A shard that is not in the bucket, one cut from another input, a prefix missing a shard
/// and a server that is down: each refused with the object named, exit status 1, and no
/// merged pack in the bucket, on disk or half-uploaded.
#[test]
fn a_missing_or_foreign_shard_in_a_bucket_is_named_and_nothing_is_written() {
    let Some(mut moto) = Moto::start("the s3:// scale-out failure test") else { return };
    moto.boto(&["mb", "tiles"]);
    let (work, tmp) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    let (scan, other) = (work.path().join("scan.ppm"), work.path().join("other.ppm"));
    noise_ppm(&scan, 300, 200, 1);
    noise_ppm(&other, 300, 200, 2);
    let split = |input: &Path, url: &str, shard: &str| {
        let args = ["split", s(input), "--pack", url, "--shard", shard];
        let out = moto.run(&[&args[..], &SHARDED[..]].concat(), tmp.path());
        assert!(out.status.success(), "{url}: {}", stderr(&out));
    };
    split(&scan, "s3://tiles/a/shard-{shard}.vtpk", "0/2");
    split(&scan, "s3://tiles/a/shard-{shard}.vtpk", "1/2");
    split(&other, "s3://tiles/b/shard-{shard}.vtpk", "1/2");
    split(&scan, "s3://tiles/c/shard-{shard}.vtpk", "0/2");
    let local = work.path().join("m.vtpk");
    let merge_fails = |shards: &[&str], words: &[&str]| {
        for dest in ["s3://tiles/m.vtpk", s(&local)] {
            let out = moto.run(&[&["merge", "-o", dest][..], shards].concat(), tmp.path());
            let err = stderr(&out);
            assert_eq!(out.status.code(), Some(1), "{shards:?} into {dest}: {err}");
            assert!(words.iter().all(|w| err.contains(w)), "{shards:?} into {dest}: {err}");
            assert!(!err.contains("panicked") && !err.contains("vortex-s3-get"), "{err}");
        }
    };
    merge_fails(
        &["s3://tiles/a/shard-0.vtpk", "s3://tiles/a/shard-3.vtpk"],
        &["s3://tiles/a/shard-3.vtpk", "no such object"],
    );
    merge_fails(
        &["s3://tiles/a/shard-0.vtpk", "s3://tiles/b/shard-1.vtpk"],
        &["s3://tiles/b/shard-1.vtpk", "same input", "s3://tiles/a/shard-0.vtpk"],
    );
    merge_fails(&["s3://tiles/c/"], &["shard 1 of 2 missing", "s3://tiles/c/shard-0.vtpk"]);
    // An object that is no pack: named by its URL, not by the local copy it was read from.
    moto.boto(&["put", "tiles", "d/notes.txt", "my notes"]);
    merge_fails(&["s3://tiles/a/shard-0.vtpk", "s3://tiles/d/"], &["s3://tiles/d/notes.txt"]);
    merge_fails(&["s3://tiles/nothing/"], &["s3://tiles/nothing/", "no object"]);
    assert_eq!(moto.boto(&["count", "tiles", "m.vtpk"]), ["0"]);
    assert!(moto.boto(&["uploads", "tiles"]).is_empty(), "a multipart upload was left open");

    // The server down: the listing fails, naming the prefix and the reason.
    moto.stop();
    let out = moto.run(&["merge", "s3://tiles/a/", "-o", s(&local), "-q"], tmp.path());
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("s3://tiles/a") && err.contains("Connection refused"), "{err}");
    assert!(!local.exists(), "a merged pack was written");
    assert_eq!(std::fs::read_dir(work.path()).unwrap().count(), 2, "the work directory holds more than the inputs");
    assert_eq!(std::fs::read_dir(tmp.path()).unwrap().count(), 0, "TMPDIR keeps staged or downloaded files");
}

/// A pack of several parts (noise in raw tiles: some 27 MiB, parts of 8) is streamed to the
/// bucket as it is made, with nothing staged (the run's TMPDIR is a file, where no directory can
/// be made), and lands byte for byte as a local run writes it. The same run cut short by a
/// broken input, after parts were sent, leaves no object and no open multipart upload.
#[test]
fn a_pack_of_several_parts_is_streamed_and_a_failure_leaves_nothing() {
    let Some(moto) = Moto::start("the streamed pack test") else { return };
    moto.boto(&["mb", "tiles"]);
    let work = tempfile::tempdir().unwrap();
    let input = work.path().join("noise.ppm");
    noise_ppm(&input, 2400, 2400, 0);
    let local = work.path().join("p.vtpk");
    let pack = |input: &Path, dest: &str, tmpdir: &Path| {
        let args = ["split", s(input), "--pack", dest, "--codec", "raw", "-q"];
        moto.run(&args, tmpdir)
    };
    let out = pack(&input, s(&local), work.path());
    assert!(out.status.success(), "local run: {}", stderr(&out));
    let size = std::fs::metadata(&local).unwrap().len();
    assert!(size > 2 * (8 << 20), "{size} bytes: not several parts");
    let not_a_dir = work.path().join("not-a-dir");
    std::fs::write(&not_a_dir, "TMPDIR is a file: nothing can be staged").unwrap();
    let out = pack(&input, "s3://tiles/p.vtpk", &not_a_dir);
    assert!(out.status.success(), "s3 run: {}", stderr(&out));
    let got = tempfile::tempdir().unwrap();
    assert_eq!(moto.boto(&["get", "tiles", "p.vtpk", s(got.path())]), ["p.vtpk"]);
    assert!(std::fs::read(got.path().join("p.vtpk")).unwrap() == std::fs::read(&local).unwrap(), "the packs differ");

    // Broken after some 18 MiB of rows: parts are sent, then the run fails.
    let broken = work.path().join("broken.ppm");
    noise_ppm(&broken, 3000, 3000, 0);
    let bytes = std::fs::read(&broken).unwrap();
    std::fs::write(&broken, &bytes[..bytes.len() * 2 / 3]).unwrap();
    let out = pack(&broken, "s3://tiles/cut.vtpk", work.path());
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(!err.contains("panicked"), "{err}");
    assert_eq!(moto.boto(&["count", "tiles", "cut"]), ["0"], "the cut pack is visible");
    assert!(moto.boto(&["uploads", "tiles"]).is_empty(), "a multipart upload was left open");
}

/// A DICOM series (`--layout dicom`) at `s3://`: staged, then uploaded instance by instance
/// under the prefix, each object byte for byte the local run's file, the marker complete.
#[test]
fn a_dicom_series_in_a_bucket_equals_the_local_directory() {
    let Some(moto) = Moto::start("the s3:// DICOM test") else { return };
    moto.boto(&["mb", "tiles"]);
    let (work, tmp) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    let input = fixture("sample.png");
    let local = work.path().join("series");
    for dest in [s(&local), "s3://tiles/dicom/series"] {
        let args = ["split", s(&input), "--layout", "dicom", "-o", dest, "--pixel-size", "0.5um", "-q"];
        let out = moto.run(&args, tmp.path());
        assert!(out.status.success(), "{dest}: {}", stderr(&out));
    }
    let mut bucket = download(&moto, "tiles", "dicom/series");
    let marker = String::from_utf8(bucket.remove(".vortex-tiler").expect("no marker")).unwrap();
    assert!(marker.contains("\"state\":\"complete\"") && marker.contains("DICOM"), "{marker}");
    let local = files(&local);
    assert!(local.len() >= 2, "{:?}: not a series of instances", local.keys().collect::<Vec<_>>());
    assert_same_files(&bucket, &local, "dicom/series");
    assert!(moto.boto(&["uploads", "tiles"]).is_empty(), "a multipart upload was left open");
    assert_eq!(std::fs::read_dir(tmp.path()).unwrap().count(), 0, "TMPDIR keeps staged files");
}
