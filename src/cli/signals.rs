//! Stopping cleanly on SIGINT, SIGTERM and SIGHUP: Ctrl-C, what `timeout` and systemd send,
//! and a closed terminal.
//!
//! The first signal only raises a flag: a writing command polls [`requested`] between tiles or
//! frames, returns `Interrupted`, and its temporaries are removed on the way out; the process
//! then exits with 128 + the signal's number, as a shell reports a death by that signal. A
//! second signal while cleaning up ends the process at once with the same code. Commands that
//! write nothing (`info`, `verify`) install nothing and keep the default (immediate) exit.

use std::sync::Arc;
use std::sync::OnceLock;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

use signal_hook::consts::{SIGHUP, SIGINT, SIGTERM};

/// The signal received, 0 while none.
static RECEIVED: OnceLock<Arc<AtomicUsize>> = OnceLock::new();

/// Installs the handlers (once; later calls do nothing).
pub fn install() -> std::io::Result<()> {
    if RECEIVED.get().is_some() {
        return Ok(());
    }
    let received = Arc::new(AtomicUsize::new(0));
    let seen = Arc::new(AtomicBool::new(false));
    for signal in [SIGINT, SIGTERM, SIGHUP] {
        // Actions run in the order registered: a signal that finds `seen` set (a second one)
        // exits at once, then the first one sets it.
        signal_hook::flag::register_conditional_shutdown(signal, exit_code(signal).into(), seen.clone())?;
        signal_hook::flag::register(signal, seen.clone())?;
        signal_hook::flag::register_usize(signal, received.clone(), signal as usize)?;
    }
    let _ = RECEIVED.set(received);
    Ok(())
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
