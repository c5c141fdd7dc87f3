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
#[expect(unsafe_code, reason = "wait4, the kernel's account of one child's peak memory")]
pub fn run_measuring_rss(args: &[&str]) -> (Output, u64) {
    use std::io::Read;
    use std::os::unix::process::ExitStatusExt;
    use std::process::Stdio;
    let mut cmd = Command::new(BIN);
    cmd.args(args).env("NO_COLOR", "1").stdin(Stdio::null()).stdout(Stdio::piped()).stderr(Stdio::piped());
    let mut child = cmd.spawn().expect("binary runs");
    let drain = |mut pipe: Box<dyn Read + Send>| {
        std::thread::spawn(move || {
            let mut bytes = Vec::new();
            pipe.read_to_end(&mut bytes).map(|_| bytes)
        })
    };
    let stdout = drain(Box::new(child.stdout.take().expect("piped")));
    let stderr = drain(Box::new(child.stderr.take().expect("piped")));
    let pid = child.id() as libc::pid_t;
    let mut status = 0;
    let usage = loop {
        // SAFETY: an all-zero `rusage` is a valid value of the plain C struct wait4 fills.
        let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
        // SAFETY: `status` and `usage` are valid and writable; `pid` is our own child, which
        // nothing else waits for (`child` is never waited on: it is dropped below).
        let waited = unsafe { libc::wait4(pid, &mut status, 0, &mut usage) };
        if waited == pid {
            break usage;
        }
        let e = std::io::Error::last_os_error();
        assert_eq!(e.kind(), std::io::ErrorKind::Interrupted, "wait4: {e}");
    };
    drop(child);
    let output = Output {
        status: std::process::ExitStatus::from_raw(status),
        stdout: stdout.join().expect("stdout reader").expect("stdout"),
        stderr: stderr.join().expect("stderr reader").expect("stderr"),
    };
    // Linux counts ru_maxrss in KiB.
    (output, usage.ru_maxrss as u64 * 1024)
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
