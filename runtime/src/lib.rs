//! The real-time cycle runtime shared by every process of a cell.
//!
//! - [`rt`]: `SCHED_FIFO`, `mlockall`, real-time-safe malloc, prefaulted stack and heap,
//!   `/dev/cpu_dma_latency` held at 0, CPU affinity. Refusals are warned about once.
//! - [`cycle`]: periodic wake-ups on absolute deadlines (`clock_nanosleep(TIMER_ABSTIME)`),
//!   the CS9 overrun rule and the cycle statistics every process publishes.
//! - [`fds`]: the open-files limit raised at start, a shortage said in words.
//! - [`ipc`]: iceoryx2 nodes and typed ports for the services of `shm-schema`.
//! - [`notify`]: readiness told on `NOTIFY_SOCKET` (systemd's `READY=1`).
//! - [`events`]: a process' publisher of events.
//! - [`estop`]: the cell's e-stop as a process sees it in its cycle (seed 002).
//! - [`health`]: seed 002's health detectors (leaky buckets).
//! - [`vclock`]: the cell's virtual clock, a barrier each process waits on instead of its
//!   deadline in a cell on virtual time (the supervisor owns it).
//! - [`process`]: the skeleton every real-time process runs: arguments, cell configuration,
//!   set-up, then the cycle until SIGTERM.
//!
//! # Real-time
//! Functions that run inside a cycle say so in a `# Real-time` section: no allocation of our
//! own, no lock, no formatted logging, no syscall but the one blocking wait and IPC calls.

pub mod alloc_count;
pub mod cycle;
pub mod estop;
pub mod events;
pub mod fds;
pub mod health;
pub mod ipc;
pub mod notify;
pub mod process;
pub mod rt;
pub mod signals;
pub mod snapshot;
pub mod stall;
pub mod time;
pub mod vclock;

/// Makes every panic of this process abort it once the panic's message is written, as
/// `panic = "abort"` would: called first in every binary of the cell. The release profile
/// unwinds, so that the test harnesses (which always unwind) and the binaries share one build
/// of the dependencies; a binary must still never unwind past a panic (a real-time process
/// with a thread gone would run on half dead, a supervisor with its control thread gone would
/// answer nothing). An abort is what the supervisor and the other processes already meet
/// when a process dies.
pub fn abort_on_panic() {
    let report = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        report(info);
        std::process::abort();
    }));
}
