//! A thread's stalls: a beat that did not come for a while, and where that time went. The
//! supervisor's heartbeat (so that a process's `supervisor-lost` can be told apart from a
//! bug), and the integration tests' watch of the machine (a failure while the machine held
//! real-time work off the CPUs is the machine's, not the test's).
//!
//! The supervisor runs under `SCHED_OTHER`; its heartbeat is what every process of the cell
//! watches (`supervisor_timeout`). When two beats are further apart than the threshold (for
//! the supervisor, 100 ms, or a quarter of that timeout if shorter), [`StallWatch::beat`]
//! returns a [`Stall`] that splits the gap four ways, from the kernel's own accounting:
//!
//! - **running**: the thread itself was on a CPU (`/proc/thread-self/schedstat`, its run
//!   time, of the thread that made the watch): its own work held the beat back;
//! - **waiting for a CPU**: the thread was runnable but another task ran (its run delay): a
//!   real-time process or another load took the CPUs;
//! - **taken by the host**: the vCPUs were not running at all (`/proc/stat`, steal);
//! - **blocked**: the rest, the thread slept in a call (a file, a pipe, a lock).

use std::fs::File;
use std::os::unix::fs::FileExt;
use std::time::{Duration, Instant};

/// The main thread's run time and run-queue delay and the host's steal time, read without
/// opening a file.
#[derive(Debug)]
struct Counters {
    schedstat: Option<File>,
    stat: Option<File>,
    /// Clock ticks per second, the unit of `/proc/stat`.
    ticks_per_s: Option<u64>,
    buf: [u8; 512],
}

impl Counters {
    fn open() -> Self {
        Self {
            schedstat: File::open("/proc/thread-self/schedstat").ok(),
            stat: File::open("/proc/stat").ok(),
            ticks_per_s: nix::unistd::sysconf(nix::unistd::SysconfVar::CLK_TCK)
                .ok()
                .flatten()
                .and_then(|hz| u64::try_from(hz).ok())
                .filter(|&hz| hz > 0),
            buf: [0; 512],
        }
    }

    /// Time the thread spent on a CPU and runnable but not running, ns.
    fn schedstat_ns(&mut self) -> Option<(u64, u64)> {
        let n = self.schedstat.as_ref()?.read_at(&mut self.buf, 0).ok()?;
        let text = std::str::from_utf8(&self.buf[..n]).ok()?;
        let mut fields = text.split_ascii_whitespace();
        Some((fields.next()?.parse().ok()?, fields.next()?.parse().ok()?))
    }

    /// Steal time of all CPUs, ns (the first line of `/proc/stat`, its 8th number).
    fn steal_ns(&mut self) -> Option<u64> {
        let n = self.stat.as_ref()?.read_at(&mut self.buf, 0).ok()?;
        let line = self.buf[..n].split(|&b| b == b'\n').next()?;
        let line = std::str::from_utf8(line).ok()?;
        let ticks: u64 = line.split_ascii_whitespace().nth(8)?.parse().ok()?;
        Some(ticks.saturating_mul(1_000_000_000) / self.ticks_per_s?)
    }
}

/// A gap between two heartbeats and where it went.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Stall {
    /// Time between the two beats.
    pub gap: Duration,
    /// Of it, on a CPU (`None`: the kernel does not say).
    pub running: Option<Duration>,
    /// Of it, runnable but not running (`None`: the kernel does not say).
    pub waiting_for_cpu: Option<Duration>,
    /// Of it, the host ran something else than this machine's vCPUs (all CPUs summed).
    pub host_steal: Option<Duration>,
}

impl Stall {
    /// The machine's share of the gap: waiting for a CPU and taken by the host (what the
    /// kernel does not say counts as none).
    pub fn machine_share(&self) -> Duration {
        self.waiting_for_cpu.unwrap_or_default() + self.host_steal.unwrap_or_default()
    }

    /// Where the time went, in words: `"412 ms waiting for a CPU, 0 ms taken by the host,
    /// 3 ms running, the rest blocked in a call"`.
    pub fn cause(&self) -> String {
        let ms = |d: Option<Duration>| {
            d.map_or("? ms".into(), |d| {
                format!("{:.0} ms", d.as_secs_f64() * 1e3)
            })
        };
        format!(
            "{} waiting for a CPU, {} taken by the host, {} running, the rest blocked in a call",
            ms(self.waiting_for_cpu),
            ms(self.host_steal),
            ms(self.running)
        )
    }
}

/// Watches the gaps between heartbeats.
#[derive(Debug)]
pub struct StallWatch {
    threshold: Duration,
    last: Instant,
    schedstat_ns: Option<(u64, u64)>,
    steal_ns: Option<u64>,
    counters: Counters,
}

impl StallWatch {
    /// Reports gaps longer than `threshold`.
    pub fn new(threshold: Duration) -> Self {
        let mut counters = Counters::open();
        Self {
            threshold,
            last: Instant::now(),
            schedstat_ns: counters.schedstat_ns(),
            steal_ns: counters.steal_ns(),
            counters,
        }
    }

    /// A heartbeat goes out now: the stall before it, if the gap since the last one is over
    /// the threshold. Two small reads of `/proc` files kept open.
    pub fn beat(&mut self) -> Option<Stall> {
        let now = Instant::now();
        let gap = now - self.last;
        self.last = now;
        let schedstat = self.counters.schedstat_ns();
        let steal = self.counters.steal_ns();
        let delta = |new: Option<u64>, old: Option<u64>| {
            Some(Duration::from_nanos(new?.saturating_sub(old?)).min(gap))
        };
        let stall = (gap > self.threshold).then(|| Stall {
            gap,
            running: delta(schedstat.map(|s| s.0), self.schedstat_ns.map(|s| s.0)),
            waiting_for_cpu: delta(schedstat.map(|s| s.1), self.schedstat_ns.map(|s| s.1)),
            host_steal: delta(steal, self.steal_ns),
        });
        self.schedstat_ns = schedstat;
        self.steal_ns = steal;
        stall
    }
}
