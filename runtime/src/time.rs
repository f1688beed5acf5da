//! `CLOCK_MONOTONIC` in nanoseconds, the one time base of a cell.

/// Nanoseconds per second.
pub const NS_PER_S: u64 = 1_000_000_000;

/// Now, in nanoseconds of `CLOCK_MONOTONIC`.
///
/// # Real-time
/// Served by the vDSO (about 16 ns here), no system call.
#[inline]
pub fn now_ns() -> u64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a valid, writable timespec; CLOCK_MONOTONIC always exists on Linux.
    unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts) };
    ts.tv_sec as u64 * NS_PER_S + ts.tv_nsec as u64
}

/// Nanoseconds to seconds.
#[inline]
pub fn secs(ns: u64) -> f64 {
    ns as f64 * 1e-9
}

/// Signed difference `a - b` in seconds.
#[inline]
pub fn diff_s(a: u64, b: u64) -> f64 {
    (a as i128 - b as i128) as f64 * 1e-9
}
