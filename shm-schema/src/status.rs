//! Process roles and the status every real-time process publishes each cycle.

use iceoryx2_bb_derive_macros::ZeroCopySend;
use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;

/// The processes of a cell. The value is the index into [`crate::CellConfigV2::process`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[repr(u32)]
pub enum Role {
    /// Trajectory generator.
    Trajgen = 0,
    /// Axis position loops.
    Servo = 1,
    /// Fieldbus data.
    Iobridge = 2,
    /// The machine: simulated drives and mechanics (a real drive interface later).
    Machine = 3,
}

/// Number of [`Role`]s.
pub const ROLE_COUNT: usize = 4;

impl Role {
    /// Every role, in start order (the machine first: servo needs its feedback).
    pub const ALL: [Role; ROLE_COUNT] = [Role::Machine, Role::Servo, Role::Trajgen, Role::Iobridge];

    /// The role's name, as used in service names and the configuration (`[process.<name>]`).
    pub fn name(self) -> &'static str {
        match self {
            Self::Trajgen => "trajgen",
            Self::Servo => "servo",
            Self::Iobridge => "iobridge",
            Self::Machine => "machine",
        }
    }

    /// The role with this name.
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|r| r.name() == name)
    }

    /// Index into per-role arrays.
    pub fn index(self) -> usize {
        self as usize
    }

    pub(crate) fn status_suffix(self) -> &'static str {
        match self {
            Self::Trajgen => "trajgen/status",
            Self::Servo => "servo/status",
            Self::Iobridge => "iobridge/status",
            Self::Machine => "machine/status",
        }
    }

    pub(crate) fn exec_time_suffix(self) -> &'static str {
        match self {
            Self::Trajgen => "trajgen/exec_time",
            Self::Servo => "servo/exec_time",
            Self::Iobridge => "iobridge/exec_time",
            Self::Machine => "machine/exec_time",
        }
    }

    pub(crate) fn latency_suffix(self) -> &'static str {
        match self {
            Self::Trajgen => "trajgen/latency",
            Self::Servo => "servo/latency",
            Self::Iobridge => "iobridge/latency",
            Self::Machine => "machine/latency",
        }
    }
}

/// Life-cycle state of a process, in [`ProcessStatusV1::state`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u32)]
pub enum ProcState {
    /// Set up, not yet running its cycle.
    Starting = 0,
    /// Running its periodic cycle.
    Cyclic = 1,
    /// Asked to stop; leaving the cycle.
    Stopping = 2,
    /// Stopped on an error it cannot recover from.
    Fault = 3,
}

impl ProcState {
    /// Decodes the wire value.
    pub fn from_u32(v: u32) -> Option<Self> {
        [Self::Starting, Self::Cyclic, Self::Stopping, Self::Fault]
            .into_iter()
            .find(|s| *s as u32 == v)
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

/// What every real-time process publishes on `<i>/<role>/status` each cycle.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, ZeroCopySend)]
#[type_name("rtc::ProcessStatusV1")]
pub struct ProcessStatusV1 {
    /// Operating-system process id.
    pub pid: u32,
    /// [`Role`] as `u32`.
    pub role: u32,
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
    /// Fault code of the process, 0 for none (meaning per role; see `docs/services.md`).
    pub fault: u32,
    /// Wake-up time of the cycle that published this (ns, `CLOCK_MONOTONIC`).
    pub stamp_ns: u64,
    /// Cycle timing.
    pub stats: CycleStatsV1,
}
