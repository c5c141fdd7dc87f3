//! Sharded splits on a real scheduler: `scripts/slurm/local-cluster.sh` starts a single-node
//! Slurm cluster (Debian's slurm-wlm and munge); `scripts/slurm/smoke.sh` checks its jobs,
//! arrays and dependencies, and `scripts/slurm/submit-split.sh` runs `split --shard auto` as a
//! job array and `merge` as a job after it, which must give the one-machine pack byte for byte.
//! Needs root and the packages, which `.ci/run` installs; outside CI a missing part skips with
//! a note, under `CI=true` it fails.

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::Instant;

use crate::common::cli::{BIN, s};

/// Whether the Slurm tests can run here; if not, says why on stderr (a failure under `CI=true`).
fn slurm_usable() -> bool {
    let missing = ["slurmctld", "slurmd", "munged", "sbatch"]
        .into_iter()
        .find(|tool| !["/usr/sbin", "/usr/bin"].iter().any(|dir| Path::new(dir).join(tool).is_file()));
    let root = Command::new("id").arg("-u").output().is_ok_and(|o| o.stdout.starts_with(b"0\n"));
    let why = match (missing, root) {
        (Some(tool), _) => format!("no {tool} (apt-get install slurm-wlm munge)"),
        (None, false) => "not root: the daemons are started directly".to_string(),
        (None, true) => return true,
    };
    crate::common::skip_unless_ci("the Slurm test", &why);
    false
}

fn script(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("scripts/slurm").join(name)
}

fn show(out: &Output) -> String {
    format!("{}\n{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr))
}

/// The local cluster, shared with every `smoke.sh` and other test run as `smoke.sh` shares it:
/// a shared lock on `users.lock` while in use; `started-by-smoke` marks a cluster that one of
/// them started; the last one out stops such a cluster, holding the lock exclusively meanwhile
/// (so nobody starts using it while it stops). `VORTEX_SLURM_KEEP=1` leaves it running. The
/// two tests here run side by side on one cluster: together they take as long as `smoke.sh`.
struct Cluster {
    /// `flock -s users.lock`, holding the shared lock until its standard input closes (also
    /// when this process dies).
    holder: Child,
    dir: PathBuf,
    conf: String,
}

impl Cluster {
    fn start() -> Cluster {
        let dir = PathBuf::from(std::env::var("VORTEX_SLURM_DIR").unwrap_or_else(|_| "/tmp/vortex-slurm".into()));
        std::fs::create_dir_all(&dir).unwrap();
        let mut holder = Command::new("flock")
            .args(["-s", "-o", s(&dir.join("users.lock")), "sh", "-c", "echo held && exec cat >/dev/null"])
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .spawn()
            .expect("flock (util-linux) runs");
        let mut line = String::new();
        BufReader::new(holder.stdout.take().unwrap()).read_line(&mut line).unwrap();
        assert_eq!(line, "held\n", "flock -s {}/users.lock", dir.display());
        let lc = script("local-cluster.sh");
        if !Command::new(&lc).arg("status").output().unwrap().status.success() {
            std::fs::write(dir.join("started-by-smoke"), b"").unwrap();
        }
        // From here on, a failure stops what was started (Drop).
        let mut cluster = Cluster { holder, dir, conf: String::new() };
        let out = Command::new(&lc).arg("start").stdin(Stdio::null()).output().unwrap();
        assert!(out.status.success(), "local-cluster.sh start: {}", show(&out));
        let env = Command::new(&lc).arg("env").output().unwrap();
        let env = String::from_utf8(env.stdout).unwrap();
        cluster.conf = env.trim().strip_prefix("export SLURM_CONF=").expect("export SLURM_CONF=...").to_string();
        cluster
    }
}

impl Drop for Cluster {
    fn drop(&mut self) {
        drop(self.holder.stdin.take());
        let _ = self.holder.wait();
        let mark = self.dir.join("started-by-smoke");
        if !mark.exists() || std::env::var("VORTEX_SLURM_KEEP").is_ok_and(|v| v == "1") {
            return;
        }
        // Exit 75: another user holds the shared lock and stops the cluster when done.
        let stop = format!("{} stop && rm -f {}", script("local-cluster.sh").display(), mark.display());
        let out = Command::new("flock")
            .args(["-n", "-x", "-o", "-E", "75", s(&self.dir.join("users.lock")), "sh", "-c", &stop])
            .output();
        match out {
            Ok(out) if out.status.success() || out.status.code() == Some(75) => {}
            Ok(out) => eprintln!("warning: local-cluster.sh stop failed: {}", show(&out)),
            Err(e) => eprintln!("warning: flock for local-cluster.sh stop: {e}"),
        }
    }
}

/// A 900x700 RGB PPM with gradients, a checkerboard and a disc: 5 LODs of 64-texel pages with
/// border 2 (60-texel payloads, 15 x 12 pages at LOD 0).
fn write_ppm(path: &Path) {
    let (w, h) = (900u32, 700u32);
    let mut bytes = format!("P6\n{w} {h}\n255\n").into_bytes();
    for y in 0..h {
        for x in 0..w {
            let (dx, dy) = (x as i64 - 450, y as i64 - 350);
            let disc = dx * dx + dy * dy < 200 * 200;
            let check = ((x / 37 + y / 23) % 2) as u8;
            bytes.extend_from_slice(&[(x * 255 / w) as u8, (y * 255 / h) as u8 ^ (disc as u8 * 0x80), check * 200]);
        }
    }
    std::fs::write(path, bytes).unwrap();
}

#[test]
fn a_local_slurm_cluster_runs_job_arrays_and_dependencies() {
    if !slurm_usable() {
        return;
    }
    let smoke = script("smoke.sh");
    let out = Command::new("bash").arg(&smoke).output().expect("bash runs");
    assert!(out.status.success(), "{}: {}", smoke.display(), show(&out));
    let passed = String::from_utf8_lossy(&out.stdout).lines().filter(|l| l.starts_with("ok ")).count();
    assert_eq!(passed, 5, "{}", String::from_utf8_lossy(&out.stdout));
}

#[test]
fn submit_split_on_slurm_merges_the_pack_one_machine_makes() {
    if !slurm_usable() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let p = |name: &str| dir.path().join(name);
    write_ppm(&p("scan.ppm"));
    let options = ["--tile-size", "64", "--border", "2"];
    let one = Command::new(BIN)
        .args(["split", s(&p("scan.ppm")), "--pack", s(&p("one.vtpk")), "--json"])
        .args(options)
        .output()
        .unwrap();
    assert!(one.status.success(), "one-machine split: {}", show(&one));
    let summary: serde_json::Value = serde_json::from_slice(&one.stdout).unwrap();
    assert_eq!(summary["lodCount"], 5, "{summary}");

    // A tiler that fails in task 1 of an array, to see --wait report it (2 shards: the node
    // runs 2 tasks at a time, about one round a second).
    let failing = p("failing-tiler");
    let body = format!(
        "#!/bin/sh\n[ \"$SLURM_ARRAY_TASK_ID\" != 1 ] || {{ echo 'task 1 breaks' >&2; exit 7; }}\nexec '{BIN}' \"$@\"\n"
    );
    std::fs::write(&failing, body).unwrap();
    std::fs::set_permissions(&failing, std::os::unix::fs::PermissionsExt::from_mode(0o755)).unwrap();

    let started = Instant::now();
    let cluster = Cluster::start();
    let up = started.elapsed();
    // Both submitted first, then waited for (each waits for its own merge job).
    let submit = |tiler: &Path, output: &str, shards: &str| {
        Command::new("bash")
            .arg(script("submit-split.sh"))
            .args([s(&p("scan.ppm")), s(&p(output)), "--shards", shards, "--wait", "--timeout", "120", "--"])
            .args(options)
            .env("VORTEX_TILER", tiler)
            .env("SLURM_CONF", &cluster.conf)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap()
    };
    let good = submit(Path::new(BIN), "merged.vtpk", "4");
    let bad = submit(&failing, "broken.vtpk", "2");
    let (good, bad) = (good.wait_with_output().unwrap(), bad.wait_with_output().unwrap());
    let done = started.elapsed();
    drop(cluster);
    eprintln!(
        "Slurm: cluster up in {:.1} s, both submissions done {:.1} s later, cluster stopped {:.1} s later",
        up.as_secs_f64(),
        (done - up).as_secs_f64(),
        (started.elapsed() - done).as_secs_f64()
    );

    assert!(good.status.success(), "submit-split.sh: {}", show(&good));
    let ids = String::from_utf8_lossy(&good.stdout);
    let numbers: Vec<&str> = ids.split_whitespace().collect();
    assert!(numbers.len() == 2 && numbers.iter().all(|n| n.parse::<u64>().is_ok()), "not 'ARRAYJOB MERGEJOB': {ids}");
    for i in 0..4 {
        assert!(p(&format!("merged.parts/shard-{i}.vtpk")).is_file(), "shard {i}: {}", show(&good));
    }
    // The tasks took their index from the job array (--shard auto), and said so in their logs.
    let log = p(&format!("merged.parts/logs/split-{}_3.log", numbers[0]));
    let log = std::fs::read_to_string(&log).unwrap_or_else(|e| panic!("{}: {e}", log.display()));
    assert!(log.contains("shard 3 of 4 (from SLURM_ARRAY_TASK_ID=3"), "{log}");
    let (expected, merged) = (std::fs::read(p("one.vtpk")).unwrap(), std::fs::read(p("merged.vtpk")).unwrap());
    assert!(
        expected == merged,
        "the merged pack ({} bytes) differs from the one-machine pack ({} bytes)",
        merged.len(),
        expected.len()
    );

    assert_eq!(bad.status.code(), Some(1), "a failing task: {}", show(&bad));
    let err = String::from_utf8_lossy(&bad.stderr);
    assert!(err.contains("task 1 (job") && err.contains("task 1 breaks"), "the failed task's log: {err}");
    assert!(err.contains("1 of 2 split tasks") && !p("broken.vtpk").exists(), "{err}");
}

/// `local-cluster.sh start` on a machine where Slurm's own port 6817 is taken (here by a
/// listener of this test; the shared test cluster, if up, takes it too) starts on another pair
/// of ports, which the generated slurm.conf names, instead of failing with slurmctld's
/// "Address already in use". A cluster of its own in a scratch directory, started and stopped
/// here while holding the shared cluster's lock exclusively, so that no other test's cluster
/// starts or stops meanwhile.
#[test]
fn a_cluster_moves_off_a_taken_port() {
    if !slurm_usable() {
        return;
    }
    let shared = PathBuf::from(std::env::var("VORTEX_SLURM_DIR").unwrap_or_else(|_| "/tmp/vortex-slurm".into()));
    std::fs::create_dir_all(&shared).unwrap();
    let mut holder = Command::new("flock")
        .args(["-x", "-o", s(&shared.join("users.lock")), "sh", "-c", "echo held && exec cat >/dev/null"])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .spawn()
        .expect("flock (util-linux) runs");
    let mut line = String::new();
    BufReader::new(holder.stdout.take().unwrap()).read_line(&mut line).unwrap();
    assert_eq!(line, "held\n");
    // Taken by us, or already by someone else: either way slurmctld cannot bind it.
    let _stranger = std::net::TcpListener::bind("0.0.0.0:6817");
    let dir = tempfile::tempdir().unwrap();
    let lc = script("local-cluster.sh");
    let run = |command: &str| {
        Command::new(&lc)
            .arg(command)
            .env("VORTEX_SLURM_DIR", dir.path())
            .env_remove("VORTEX_SLURMCTLD_PORT")
            .env_remove("VORTEX_SLURMD_PORT")
            .stdin(Stdio::null())
            .output()
            .unwrap()
    };
    let started = run("start");
    let conf = std::fs::read_to_string(dir.path().join("etc/slurm.conf")).unwrap_or_default();
    let stopped = run("stop");
    drop(holder.stdin.take());
    let _ = holder.wait();
    assert!(started.status.success(), "local-cluster.sh start: {}", show(&started));
    assert!(stopped.status.success(), "local-cluster.sh stop: {}", show(&stopped));
    assert!(show(&started).contains("is taken; trying another pair"), "{}", show(&started));
    let port = conf.lines().find_map(|l| l.strip_prefix("SlurmctldPort=")).unwrap_or_default();
    assert!(!port.is_empty() && port != "6817", "slurm.conf: {conf}");
}
