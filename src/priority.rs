//! Thread priorities: the encoders yield to the serial stages.
//!
//! `split` runs one chain of serial work (reading the source, the pyramid, the pack writer's
//! ordered store) beside a pool of encoders. On a machine with few cores the scheduler shares
//! each core equally between runnable threads, so the serial chain, the one stage that cannot
//! go faster with more threads, got two thirds of a core while the encoders it feeds ran dry
//! (issue 18). Lowering the pool's threads' priority lets the chain run whenever it has work;
//! the encoders take every cycle it leaves. Nothing else changes: the output is the same.

/// Nice value the pool's threads add to the process's: weight 110 against the serial
/// threads' 1024, so a serial thread sharing a core with an encoder gets 90% of it.
pub const ENCODER_NICENESS: i32 = 10;

/// Lowers the calling thread's priority by `by` nice steps (Linux; elsewhere nothing). A
/// failure leaves the priority as it was: it costs speed, never correctness.
#[expect(unsafe_code, reason = "libc's thread priority calls")]
pub fn lower_this_thread(by: i32) {
    #[cfg(target_os = "linux")]
    {
        // SAFETY: gettid, getpriority and setpriority take no pointers; PRIO_PROCESS with a
        // thread id addresses that one thread on Linux.
        unsafe {
            let tid = libc::gettid() as libc::id_t;
            *libc::__errno_location() = 0;
            let now = libc::getpriority(libc::PRIO_PROCESS, tid);
            if *libc::__errno_location() == 0 {
                libc::setpriority(libc::PRIO_PROCESS, tid, (now + by).min(19));
            }
        }
    }
    #[cfg(not(target_os = "linux"))]
    let _ = by;
}
