//! The built binary run as a user runs it, for the command-line tests.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

pub const BIN: &str = env!("CARGO_BIN_EXE_vortex-tiler");

/// Runs the tool with plain output (`NO_COLOR`). `render` gets lavapipe where it is installed
/// and no Vulkan driver is chosen, as the GPU tests do.
pub fn run(args: &[&str]) -> Output {
    let mut cmd = Command::new(BIN);
    cmd.args(args).env("NO_COLOR", "1");
    cmd.envs(vortex_vt_wgpu::device::lavapipe_env());
    cmd.output().expect("binary runs")
}

/// Runs the tool as [`run`] does and measures its peak resident set: the kernel's
/// `ru_maxrss` of that one child (through `wait4`), in bytes. (`getrusage(RUSAGE_CHILDREN)`
/// would give the largest of every child this test process ever waited for.)
pub fn run_measuring_rss(args: &[&str]) -> (Output, u64) {
    // Measured through a small launcher, not as our own child: Linux carries the larger of a
    // process's peak and the peak of the memory it had before `exec` into `ru_maxrss`, and a
    // child forked from this test process (hundreds of MiB while the suite runs in parallel)
    // would report this process's size. The launcher is small when it forks the binary.
    const LAUNCH: &str = "import os, sys\n\
        pid = os.fork()\n\
        if pid == 0:\n    os.execv(sys.argv[2], sys.argv[2:])\n\
        _, status, usage = os.wait4(pid, 0)\n\
        open(sys.argv[1], 'w').write(str(usage.ru_maxrss))\n\
        sys.exit(os.waitstatus_to_exitcode(status) % 256 if os.WIFEXITED(status) else 128 + os.WTERMSIG(status))\n";
    let dir = tempfile::tempdir().expect("temporary directory");
    let report = dir.path().join("maxrss");
    let output = Command::new("python3")
        .args(["-c", LAUNCH])
        .arg(&report)
        .arg(BIN)
        .args(args)
        .env("NO_COLOR", "1")
        .stdin(std::process::Stdio::null())
        .output()
        .expect("python3 runs the binary");
    let kib: u64 = std::fs::read_to_string(&report)
        .unwrap_or_else(|e| panic!("no peak from the launcher ({e}): {}", String::from_utf8_lossy(&output.stderr)))
        .trim()
        .parse()
        .expect("a number of KiB");
    // Linux counts ru_maxrss in KiB.
    (output, kib * 1024)
}

/// A run that must succeed; its standard output.
pub fn ok(args: &[&str]) -> String {
    let out = run(args);
    assert!(out.status.success(), "{args:?}: {}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// Asserts a failure with exit code 1, no panic, and an error that mentions every `needle`.
pub fn fails_with(out: &Output, needles: &[&str]) {
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "expected exit 1, got {:?}; stderr: {err}", out.status);
    assert!(err.starts_with("error: "), "{err}");
    assert!(!err.contains("panicked"), "{err}");
    for n in needles {
        assert!(err.contains(n), "stderr lacks {n:?}: {err}");
    }
}

/// A file of `fixtures/`.
pub fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures").join(name)
}

pub fn s(p: &Path) -> &str {
    p.to_str().expect("a UTF-8 path")
}

/// `wait()` for the process `pid` (e.g. `child.wait_with_output()`), killing it and failing if it
/// is still running after two minutes: a fail-safe against a hang that no working run comes
/// near, not a timing.
pub fn wait_or_kill<T: Send>(pid: u32, what: &str, wait: impl FnOnce() -> T + Send) -> T {
    std::thread::scope(|scope| {
        let (done, result) = std::sync::mpsc::channel();
        scope.spawn(move || done.send(wait()));
        match result.recv_timeout(std::time::Duration::from_secs(120)) {
            Ok(out) => out,
            Err(_) => {
                // The waiting thread returns once the process is gone; the scope then ends.
                let _ = Command::new("kill").args(["-KILL", &pid.to_string()]).status();
                panic!("{what}: still running after two minutes");
            }
        }
    })
}
