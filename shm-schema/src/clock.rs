//! The cell's virtual clock: a barrier every process of a cell on virtual time waits on
//! instead of its absolute-deadline sleep (`docs/virtual-time.md`).
//!
//! The supervisor owns the clock. A process joins by reporting its first deadline
//! ([`ClockReportV1`], kind [`ClockReport::Join`]) on `<i>/clock/report` and notifying the
//! event service of the same name; it then blocks on its own event service
//! `<i>/clock/go/<pid>` until the clock grants it a cycle ([`ClockGrantV1`] on
//! `<i>/clock/grant`, its pid in it: the newest grant when it wakes is its own). It runs the
//! cycle at the grant's `now_ns`, publishes what it publishes, and reports
//! [`ClockReport::Done`] with its next deadline. The clock moves to the earliest next
//! deadline only once the process it granted has reported: one process runs at a time, in
//! deadline order, ties in the order of the process table, so a cycle's messages are
//! published before any later cycle reads them. A process that leaves reports
//! [`ClockReport::Leave`].

use iceoryx2_bb_derive_macros::ZeroCopySend;
use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;

wire_enum! {
    /// Which clock a cell runs on, in [`crate::CellConfigV6::clock`].
    pub enum CellClock: u32 {
        /// `CLOCK_MONOTONIC`: every process sleeps until its own absolute deadline.
        Wall = 0 as "wall",
        /// The supervisor's virtual clock: every process waits for its grant.
        Virtual = 1 as "virtual",
    }
}

wire_enum! {
    /// What a [`ClockReportV1`] says.
    pub enum ClockReport: u32 {
        /// A process takes part from its first deadline on.
        Join = 1,
        /// The granted cycle is done; the process' next deadline follows.
        Done = 2,
        /// The process leaves the clock (it exits): never grant it again.
        Leave = 3,
    }
}

/// A cycle granted by the clock, on `<i>/clock/grant` (history 1). A grant with `pid` 0
/// grants nobody: it says where the clock stands (a process about to join reads it).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, ZeroCopySend)]
#[type_name("rtc::ClockGrantV1")]
pub struct ClockGrantV1 {
    /// The virtual instant of the cycle (ns): the process' deadline.
    pub now_ns: u64,
    /// +1 per grant.
    pub seq: u64,
    /// The process granted (0: nobody).
    pub pid: u32,
    /// Reserved, 0.
    pub reserved: u32,
}

/// A process' report to the clock, on `<i>/clock/report`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, ZeroCopySend)]
#[type_name("rtc::ClockReportV1")]
pub struct ClockReportV1 {
    /// The process' next deadline (ns of virtual time): its next grid point or an extra
    /// wake-up it asked for. Unused for a leave.
    pub next_ns: u64,
    /// The grant this report ends ([`ClockGrantV1::seq`]; 0 for a join).
    pub seq: u64,
    /// The reporting process.
    pub pid: u32,
    /// Its index in the process table (orders processes due at the same instant).
    pub index: u32,
    /// [`ClockReport`] as `u32`.
    pub kind: u32,
    /// Reserved, 0.
    pub reserved: u32,
}
