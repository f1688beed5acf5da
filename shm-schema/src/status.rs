//! Process names and the status every real-time process publishes each cycle.

use iceoryx2_bb_derive_macros::ZeroCopySend;
use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;

/// Most processes a cell runs (entries of [`crate::CellConfigV6::process`]).
pub const MAX_PROCESSES: usize = 16;

/// Bytes of a process name.
pub const PROCESS_NAME_LEN: usize = 16;

/// A process' name: 1 to 15 of `[a-z0-9_-]`, starting with a letter. It names the process'
/// entry in the cell configuration and its services (`<i>/<name>/status`, ...).
#[derive(Clone, Copy, PartialEq, Eq, Hash)]
pub struct ProcessName {
    bytes: [u8; PROCESS_NAME_LEN],
}

/// Why a process name was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ProcessNameError {
    /// Empty, or longer than 15 bytes.
    Length(usize),
    /// A character outside `[a-z0-9_-]`, or a first character that is not a letter.
    BadChar(char),
}

impl core::fmt::Display for ProcessNameError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Length(n) => write!(f, "a process name has 1 to 15 bytes, not {n}"),
            Self::BadChar(c) => write!(
                f,
                "a process name is a lower-case letter followed by [a-z0-9_-]; {c:?} is not allowed"
            ),
        }
    }
}

impl ProcessName {
    /// Validates `name`.
    pub fn new(name: &str) -> Result<Self, ProcessNameError> {
        if name.is_empty() || name.len() >= PROCESS_NAME_LEN {
            return Err(ProcessNameError::Length(name.len()));
        }
        for (i, c) in name.chars().enumerate() {
            let ok =
                c.is_ascii_lowercase() || (i > 0 && (c.is_ascii_digit() || c == '_' || c == '-'));
            if !ok {
                return Err(ProcessNameError::BadChar(c));
            }
        }
        Ok(Self {
            bytes: crate::fixed_str(name),
        })
    }

    /// Reads a NUL-padded name field of a payload; `None` if it is not a valid name.
    pub fn from_field(field: &[u8; PROCESS_NAME_LEN]) -> Option<Self> {
        Self::new(crate::str_of(field)).ok()
    }

    /// The name as text.
    pub fn as_str(&self) -> &str {
        crate::str_of(&self.bytes)
    }

    /// The NUL-padded field of a payload.
    pub fn field(&self) -> [u8; PROCESS_NAME_LEN] {
        self.bytes
    }
}

impl core::fmt::Debug for ProcessName {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "{:?}", self.as_str())
    }
}

impl core::fmt::Display for ProcessName {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(self.as_str())
    }
}

wire_enum! {
    /// Life-cycle state of a process, in [`ProcessStatusV1::state`].
    pub enum ProcState: u32 {
        /// Set up, not yet running its cycle.
        Starting = 0,
        /// Running its periodic cycle.
        Cyclic = 1,
        /// Asked to stop; leaving the cycle.
        Stopping = 2,
        /// Stopped on an error it cannot recover from.
        Fault = 3,
    }
}

/// Timing of a periodic loop, like LinuxCNC's `.time`/`.tmax` pins.
///
/// Wake-up latency is actual minus planned wake time. Overruns follow the CS9 rule: a cycle
/// whose work ends after the next deadline completes, the next period is skipped, the
/// overrun flag is set for the following cycle and counted.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, ZeroCopySend)]
#[type_name("rtc::CycleStatsV1")]
pub struct CycleStatsV1 {
    /// Cycle period (ns).
    pub period_ns: u64,
    /// Cycles run since start.
    pub cycles: u64,
    /// Cycles whose work ran past the next deadline.
    pub overruns: u64,
    /// Periods skipped because of overruns.
    pub skipped: u64,
    /// Wake-up latency of the latest cycle (ns).
    pub wakeup_latency_ns: u64,
    /// Largest wake-up latency since start (ns).
    pub max_wakeup_latency_ns: u64,
    /// Execution time of the latest complete cycle, wake-up to end of work (ns).
    pub exec_ns: u64,
    /// Largest execution time since start (ns).
    pub max_exec_ns: u64,
    /// 1 when the previous cycle overran (the CS9 overrun flag), else 0.
    pub overrun_flag: u32,
    /// Reserved, 0.
    pub reserved: u32,
}

/// Scheduling result bits in [`ProcessStatusV1::rt_flags`].
pub mod rt_flags {
    /// The requested real-time policy and priority were applied.
    pub const SCHED: u32 = 1;
    /// `mlockall` succeeded.
    pub const MLOCK: u32 = 2;
    /// `/dev/cpu_dma_latency` is held at 0.
    pub const DMA_LATENCY: u32 = 4;
    /// The requested CPU affinity was applied.
    pub const AFFINITY: u32 = 8;
}

/// One health detector of seed 002 (a leaky bucket), as a process reports it.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, ZeroCopySend)]
#[type_name("rtc::DetectorV1")]
pub struct DetectorV1 {
    /// The bucket's count now: +1 per overrun, -1 per leak time.
    pub level: f32,
    /// The count at which it expires (a host e-stop); 0 while snoozed after a start.
    pub limit: f32,
    /// Overruns counted since the process started.
    pub total: u64,
}

/// Bits of [`ProcessStatusV2::estop`].
pub mod estop_seen {
    /// The cell's e-stop is latched (any source), as this process read it in its own cycle.
    pub const LATCHED: u32 = 1;
    /// This process reacts to it (propagation rules and its `network_estop_config`).
    pub const REACTING: u32 = 2;
    /// Its reaction is complete (servo: axes at rest and drives disabled; trajgen: program
    /// dropped; iobridge: outputs at their safe values).
    pub const SAFE: u32 = 4;
    /// This process raised an e-stop itself (a device e-stop), since the last reset.
    pub const RAISED: u32 = 8;
}

/// The name of a [`ProcessStatusV2::policy`] value.
pub fn policy_name(policy: u32) -> &'static str {
    match policy {
        1 => "SCHED_FIFO",
        2 => "SCHED_RR",
        _ => "SCHED_OTHER",
    }
}

/// What every real-time process publishes on `<i>/<name>/status` each cycle.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, ZeroCopySend)]
#[type_name("rtc::ProcessStatusV2")]
pub struct ProcessStatusV2 {
    /// Operating-system process id.
    pub pid: u32,
    /// Index of the process in the cell configuration's process table.
    pub index: u32,
    /// [`ProcState`] as `u32`.
    pub state: u32,
    /// Scheduling policy in effect: 0 `SCHED_OTHER`, 1 `SCHED_FIFO`, 2 `SCHED_RR`.
    pub policy: u32,
    /// Real-time priority in effect (0 under `SCHED_OTHER`).
    pub priority: i32,
    /// CPU the process is pinned to, -1 for none.
    pub cpu: i32,
    /// [`rt_flags`] bits.
    pub rt_flags: u32,
    /// Fault code of the process, 0 for none (meaning per process; see `docs/services.md`).
    pub fault: u32,
    /// Wake-up time of the cycle that published this (ns, `CLOCK_MONOTONIC`).
    pub stamp_ns: u64,
    /// Cycle timing.
    pub stats: CycleStatsV1,
    /// The process' name, NUL-padded.
    pub name: [u8; PROCESS_NAME_LEN],
    /// Pending-sequence overruns: a sample that did not reach its consumer by the next cycle.
    pub pending_sequence: DetectorV1,
    /// Transport overruns: an IPC call that failed, a sample lost.
    pub transport: DetectorV1,
    /// Thread offset variance: a wake-up later than the configured share of the period.
    pub thread_offset: DetectorV1,
    /// [`estop_seen`] bits.
    pub estop: u32,
    /// Reserved, 0.
    pub reserved: u32,
}
