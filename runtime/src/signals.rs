//! SIGTERM / SIGINT as a stop request, and [`WAKE_SIGNAL`] to interrupt one thread's wait.
//!
//! The handlers only set a flag (or nothing). They are installed without `SA_RESTART`, so a
//! blocking wait (`clock_nanosleep`, a listener's `sem_wait`) returns `EINTR` and the loop
//! sees the request at once.

use std::sync::atomic::{AtomicBool, Ordering};

static STOP: AtomicBool = AtomicBool::new(false);

extern "C" fn on_signal(_: libc::c_int) {
    STOP.store(true, Ordering::SeqCst);
}

extern "C" fn on_wake(_: libc::c_int) {}

/// The signal [`wake_thread`] sends: `SIGUSR1`, handled by doing nothing.
pub const WAKE_SIGNAL: libc::c_int = libc::SIGUSR1;

/// Installs the handler for SIGTERM and SIGINT (a stop request) and for [`WAKE_SIGNAL`]
/// (nothing but interrupting a wait).
pub fn install() -> std::io::Result<()> {
    for (sig, handler) in [
        (libc::SIGTERM, on_signal as extern "C" fn(libc::c_int)),
        (libc::SIGINT, on_signal),
        (WAKE_SIGNAL, on_wake),
    ] {
        // SAFETY: a zeroed sigaction is valid; the handler is async-signal-safe (one atomic
        // store) and lives for the whole program.
        unsafe {
            let mut sa: libc::sigaction = std::mem::zeroed();
            sa.sa_sigaction = handler as *const () as usize;
            libc::sigemptyset(&mut sa.sa_mask);
            sa.sa_flags = 0;
            if libc::sigaction(sig, &sa, std::ptr::null_mut()) != 0 {
                return Err(std::io::Error::last_os_error());
            }
        }
    }
    Ok(())
}

/// Interrupts the blocking wait of `thread` (of this process) with [`WAKE_SIGNAL`], so it
/// can look at its stop condition. A thread about to wait may miss it: repeat until the
/// thread has ended.
pub fn wake_thread(thread: libc::pthread_t) {
    // SAFETY: plain call; an ended thread only makes it fail with ESRCH.
    unsafe { libc::pthread_kill(thread, WAKE_SIGNAL) };
}

/// True once SIGTERM or SIGINT arrived.
///
/// # Real-time
/// One atomic load.
#[inline]
pub fn stop_requested() -> bool {
    STOP.load(Ordering::SeqCst)
}
