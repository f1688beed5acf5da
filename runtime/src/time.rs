//! The one time base of a cell: `CLOCK_MONOTONIC` in nanoseconds, or, in a cell on the
//! virtual clock (`crate::vclock`), the clock's virtual instant.
//!
//! A process switches to virtual time once, at set-up, before its clock starts
//! ([`set_virtual_now`]); from then on [`now_ns`] and [`Moment`] read the instant the virtual
//! clock last granted (a process) or reached (the supervisor, which owns it), and
//! [`wall_ns`] still reads `CLOCK_MONOTONIC` for what is measured on the CPU (execution
//! times) and the clock's own wall-time watchdog.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Duration;

/// Nanoseconds per second.
pub const NS_PER_S: u64 = 1_000_000_000;

/// Whether this process reads the virtual clock.
static VIRTUAL: AtomicBool = AtomicBool::new(false);
/// The virtual instant (ns), when [`VIRTUAL`].
static VIRTUAL_NOW: AtomicU64 = AtomicU64::new(0);

/// Now, in nanoseconds of the cell's clock: `CLOCK_MONOTONIC`, or the virtual instant in a
/// cell on the virtual clock.
///
/// # Real-time
/// Served by the vDSO (about 16 ns here) or one atomic load, no system call.
#[inline]
pub fn now_ns() -> u64 {
    if VIRTUAL.load(Ordering::Relaxed) {
        VIRTUAL_NOW.load(Ordering::Acquire)
    } else {
        wall_ns()
    }
}

/// Whether this process reads the virtual clock ([`set_virtual_now`] was called).
#[inline]
pub fn is_virtual() -> bool {
    VIRTUAL.load(Ordering::Relaxed)
}

/// Sets the virtual instant (ns) and, the first time, turns this process to virtual time.
///
/// # Real-time
/// Two atomic stores.
#[inline]
pub fn set_virtual_now(t: u64) {
    VIRTUAL_NOW.store(t, Ordering::Release);
    VIRTUAL.store(true, Ordering::Relaxed);
}

/// Now, in nanoseconds of `CLOCK_MONOTONIC`, whatever clock the cell runs on.
///
/// # Real-time
/// Served by the vDSO, no system call.
#[inline]
pub fn wall_ns() -> u64 {
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

/// An instant of the cell's clock ([`now_ns`]), as `std::time::Instant` is of
/// `CLOCK_MONOTONIC`: what the supervisor's timeouts count, so that they count virtual time
/// in a cell on the virtual clock.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Moment(u64);

impl Moment {
    /// Now.
    pub fn now() -> Self {
        Self(now_ns())
    }

    /// Time since then (zero if it is in the future).
    pub fn elapsed(self) -> Duration {
        Self::now().saturating_duration_since(self)
    }

    /// Time from `earlier` to this one, zero if `earlier` is later.
    pub fn saturating_duration_since(self, earlier: Self) -> Duration {
        Duration::from_nanos(self.0.saturating_sub(earlier.0))
    }
}

impl std::ops::Add<Duration> for Moment {
    type Output = Moment;
    fn add(self, d: Duration) -> Moment {
        Self(
            self.0
                .saturating_add(u64::try_from(d.as_nanos()).unwrap_or(u64::MAX)),
        )
    }
}

impl std::ops::Sub<Moment> for Moment {
    type Output = Duration;
    fn sub(self, earlier: Moment) -> Duration {
        self.saturating_duration_since(earlier)
    }
}
