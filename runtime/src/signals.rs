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

/// Exit code of a process that met [`explain_sigbus`]'s SIGBUS.
const SIGBUS_EXIT: i32 = 1;

/// Makes a SIGBUS say why instead of killing the process silently. In this project's
/// processes a SIGBUS comes from a page of shared memory that cannot be backed: `/dev/shm` is
/// full (iceoryx2 maps its segments there; a full tmpfs refuses the page on first touch, not
/// at mmap). The handler writes `error: shared memory is full (/dev/shm: N MB free)` to stderr
/// and exits with [`SIGBUS_EXIT`].
pub fn explain_sigbus() -> nix::Result<()> {
    use nix::sys::signal::{SaFlags, SigAction, SigHandler, SigSet, Signal, sigaction};
    let action = SigAction::new(
        SigHandler::Handler(on_sigbus),
        SaFlags::empty(),
        SigSet::empty(),
    );
    // SAFETY: the handler only makes async-signal-safe calls (statvfs, write, _exit) and
    // formats into a stack buffer.
    unsafe { sigaction(Signal::SIGBUS, &action) }.map(|_| ())
}

/// The SIGBUS handler of [`explain_sigbus`]. Async-signal-safe: raw `statvfs(2)`, `write(2)`
/// and `_exit(2)` (nix's wrappers may allocate a path), no allocation, no lock.
extern "C" fn on_sigbus(_: libc::c_int) {
    let mut buf = [0u8; 160];
    let mut n = 0;
    let mut put = |bytes: &[u8]| {
        let k = bytes.len().min(buf.len() - n);
        buf[n..n + k].copy_from_slice(&bytes[..k]);
        n += k;
    };
    put(b"error: shared memory is full (/dev/shm: ");
    // SAFETY: a zeroed statvfs is valid; the path is a NUL-terminated literal.
    let free_mb = unsafe {
        let mut st: libc::statvfs = std::mem::zeroed();
        (libc::statvfs(c"/dev/shm".as_ptr(), &mut st) == 0)
            .then(|| st.f_bavail as u64 * st.f_frsize as u64 / 1_000_000)
    };
    match free_mb {
        Some(mb) => {
            let mut digits = [0u8; 20];
            let mut k = digits.len();
            let mut v = mb;
            loop {
                k -= 1;
                digits[k] = b'0' + (v % 10) as u8;
                v /= 10;
                if v == 0 {
                    break;
                }
            }
            put(&digits[k..]);
        }
        None => put(b"?"),
    }
    put(b" MB free): a page of shared memory could not be backed (SIGBUS)\n");
    // SAFETY: write(2) and _exit(2) are async-signal-safe.
    unsafe {
        libc::write(2, buf.as_ptr().cast(), n);
        libc::_exit(SIGBUS_EXIT);
    }
}
