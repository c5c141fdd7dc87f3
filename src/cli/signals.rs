//! Stopping cleanly on SIGINT, SIGTERM and SIGHUP: Ctrl-C, what `timeout` and systemd send,
//! and a closed terminal.
//!
//! The first signal only raises a flag: a writing command polls [`requested`] between tiles or
//! frames, returns `Interrupted`, and its temporaries are removed on the way out; the process
//! then exits with 128 + the signal's number, as a shell reports a death by that signal. A
//! second signal (the run did not stop: a read blocked, say) ends the process at once with the
//! code of that signal, after removing this process's temporaries of the destinations claimed
//! ([`remove_on_forced_exit`]): the run is gone, and what it was writing must go too. Commands
//! that write nothing (`info`, `verify`) install nothing and keep the default (immediate) exit.

use std::io::Read;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, OnceLock};

use signal_hook::consts::{SIGHUP, SIGINT, SIGTERM};
use vortex_tiler::output;

/// The signal received last, 0 while none.
static RECEIVED: OnceLock<Arc<AtomicUsize>> = OnceLock::new();

/// The destinations whose temporaries a forced exit removes.
static DESTINATIONS: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

/// Installs the handlers (once; later calls do nothing).
pub fn install() -> std::io::Result<()> {
    if RECEIVED.get().is_some() {
        return Ok(());
    }
    let received = Arc::new(AtomicUsize::new(0));
    // Each signal also writes a byte to a socket that a thread waits on: on the second, that
    // thread (not the handler, which may only do what is async-signal-safe) cleans up and exits.
    let (mut wakeups, wake) = std::os::unix::net::UnixStream::pair()?;
    for signal in [SIGINT, SIGTERM, SIGHUP] {
        signal_hook::flag::register_usize(signal, received.clone(), signal as usize)?;
        signal_hook::low_level::pipe::register(signal, wake.try_clone()?)?;
    }
    let last = received.clone();
    std::thread::Builder::new().name("vortex-signals".into()).spawn(move || {
        let mut byte = [0u8; 2];
        // Both bytes read (maybe in two reads): a second signal came.
        if wakeups.read_exact(&mut byte).is_ok() {
            remove_temporaries();
            std::process::exit(exit_code(last.load(Ordering::SeqCst) as i32).into());
        }
    })?;
    let _ = RECEIVED.set(received);
    Ok(())
}

/// Has a forced exit (a second signal) remove this process's temporaries of `dest`: the
/// staging directory or file `.NAME.partial-PID` and the pack writer's `.NAME.tmp-PID`.
pub fn remove_on_forced_exit(dest: &Path) {
    if let Ok(mut destinations) = DESTINATIONS.lock() {
        destinations.push(dest.to_path_buf());
    }
}

fn remove_temporaries() {
    let Ok(destinations) = DESTINATIONS.lock() else { return };
    for dest in destinations.iter() {
        let pack = vortex_pack::temporary_path(dest);
        for path in [output::partial_path(dest), pack] {
            // The run's other threads may still be adding tiles to a staging directory: a few
            // tries, then what is left is for the next run's clean-up (`output::remove_stale`).
            for _ in 0..5 {
                let removed = match std::fs::symlink_metadata(&path) {
                    Ok(meta) if meta.is_dir() => std::fs::remove_dir_all(&path),
                    Ok(_) => std::fs::remove_file(&path),
                    Err(_) => break,
                };
                if removed.is_ok() {
                    break;
                }
            }
        }
    }
}

/// The signal that asked the run to stop, if one has.
pub fn requested() -> Option<i32> {
    match RECEIVED.get()?.load(Ordering::SeqCst) {
        0 => None,
        s => Some(s as i32),
    }
}

/// The exit status for a run stopped by `signal`: 130 for SIGINT, 143 for SIGTERM, 129 for
/// SIGHUP.
pub fn exit_code(signal: i32) -> u8 {
    (128 + signal).clamp(0, 255) as u8
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exit_codes_are_the_shells() {
        assert_eq!(exit_code(SIGINT), 130);
        assert_eq!(exit_code(SIGTERM), 143);
        assert_eq!(exit_code(SIGHUP), 129);
    }
}
