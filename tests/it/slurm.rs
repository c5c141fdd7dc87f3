//! The scheduler issue 15 will shard `split` on: `scripts/slurm/local-cluster.sh` starts a real
//! single-node Slurm cluster (Debian's slurm-wlm and munge), and `scripts/slurm/smoke.sh` runs
//! a job, a 4-task job array, a job that depends on the array, and a dependent of a failing
//! job (never run), then stops the cluster. Needs root and the packages, which `.ci/run`
//! installs; outside CI a missing part skips with a note, under `CI=true` it fails.

use std::path::Path;
use std::process::Command;

#[test]
fn a_local_slurm_cluster_runs_job_arrays_and_dependencies() {
    let missing = ["slurmctld", "slurmd", "munged", "sbatch"]
        .into_iter()
        .find(|tool| !["/usr/sbin", "/usr/bin"].iter().any(|dir| Path::new(dir).join(tool).is_file()));
    let root = Command::new("id").arg("-u").output().is_ok_and(|o| o.stdout.starts_with(b"0\n"));
    let why = match (missing, root) {
        (Some(tool), _) => Some(format!("no {tool} (apt-get install slurm-wlm munge)")),
        (None, false) => Some("not root: the daemons are started directly".to_string()),
        (None, true) => None,
    };
    if let Some(why) = why {
        assert!(std::env::var("CI").map_or(true, |v| v != "true"), "CI=true and {why}");
        eprintln!("note: skipping the Slurm test: {why}");
        return;
    }
    let smoke = Path::new(env!("CARGO_MANIFEST_DIR")).join("scripts/slurm/smoke.sh");
    let out = Command::new("bash").arg(&smoke).output().expect("bash runs");
    assert!(
        out.status.success(),
        "{}: {}\n{}",
        smoke.display(),
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    let passed = String::from_utf8_lossy(&out.stdout).lines().filter(|l| l.starts_with("ok ")).count();
    assert_eq!(passed, 5, "{}", String::from_utf8_lossy(&out.stdout));
}
