//! The cell's e-stop (seed 002) and the supervisor's heartbeat.
//!
//! Any process of the cell, the supervisor and a user's tool publish [`EstopV1`] records on
//! `<i>/estop`: a trigger (a device, the user or the host raises the e-stop) or a reset (only
//! the supervisor, on `supervisor reset`). Every real-time process reads that service in its
//! own cycle, before its work, so an e-stop reaches it within one of its periods whoever raised
//! it, and whether the supervisor is slow or dead. Each process applies seed 002's propagation
//! rules itself (`propagate_estop`, `propagate_external_estop`, the `network_estop_config` of
//! its process table entry: [`crate::EstopReaction`]).
//!
//! The supervisor publishes [`HostStateV1`] on `<i>/host/state` every tick (10 ms) with
//! history 1: its heartbeat, and the latched e-stop as it holds it, so a process started
//! while the e-stop is latched sees it at once. A process whose supervisor stops beating for
//! the cell's `supervisor_timeout` reacts as to an unrecoverable host e-stop, brings the axes
//! to rest and exits: no cell runs headless.

use iceoryx2_bb_derive_macros::ZeroCopySend;
use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;

/// Bytes of [`EstopV1::reason`].
pub const REASON_LEN: usize = 64;

wire_enum! {
    /// What an [`EstopV1`] record does.
    pub enum EstopKind: u32 {
        /// Raises the e-stop (latched until a reset).
        Trigger = 1,
        /// Clears it (the supervisor only, after checking that every cause is gone).
        Reset = 2,
    }
}

wire_enum! {
    /// Who raised an e-stop: seed 002's three sources.
    pub enum EstopOrigin: u32 {
        /// A process of the cell, about itself (servo's following error, a drive fault): it has
        /// reacted already; the others react only with `propagate_estop`.
        Device = 1 as "device",
        /// The user: `supervisor estop` (seed 002's `trigger_estop`), an e-stop input. The others
        /// react with `propagate_estop` or `propagate_external_estop`.
        External = 2 as "external",
        /// The host: a process died or stalled, a health detector expired, the supervisor
        /// stopped beating. Always propagated, whatever the configuration.
        Host = 3 as "host",
    }
}

impl EstopOrigin {
    /// Whether a process other than the source reacts to an e-stop of this origin, given the
    /// cell's `propagate_estop` and `propagate_external_estop` (seed 002).
    pub fn propagates(self, propagate_estop: bool, propagate_external_estop: bool) -> bool {
        match self {
            Self::Device => propagate_estop,
            Self::External => propagate_estop || propagate_external_estop,
            Self::Host => true,
        }
    }
}

/// One e-stop record on `<i>/estop`.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, ZeroCopySend)]
#[type_name("rtc::EstopV1")]
pub struct EstopV1 {
    /// When it was raised (ns, `CLOCK_MONOTONIC`).
    pub stamp_ns: u64,
    /// [`EstopKind`] as `u32`.
    pub kind: u32,
    /// [`EstopOrigin`] as `u32` (0 for a reset).
    pub origin: u32,
    /// Index of the raising process in the process table, or
    /// [`crate::event::SOURCE_SUPERVISOR`] for the supervisor and the user's tools.
    pub source: u32,
    /// The event code of the cause (`docs/events.md`), 0 for none.
    pub code: u32,
    /// A short reason, NUL-padded UTF-8 (`"following error on x"`, `"operator"`).
    pub reason: [u8; REASON_LEN],
}

impl Default for EstopV1 {
    fn default() -> Self {
        Self {
            stamp_ns: 0,
            kind: 0,
            origin: 0,
            source: 0,
            code: 0,
            reason: [0; REASON_LEN],
        }
    }
}

impl EstopV1 {
    /// A trigger, its reason made of `parts` (truncated to fit).
    ///
    /// # Real-time
    /// Copies only.
    pub fn trigger(
        stamp_ns: u64,
        origin: EstopOrigin,
        source: u32,
        code: u32,
        parts: &[&str],
    ) -> Self {
        Self {
            stamp_ns,
            kind: EstopKind::Trigger as u32,
            origin: origin as u32,
            source,
            code,
            reason: crate::event::text_of(parts),
        }
    }

    /// A reset.
    pub fn reset(stamp_ns: u64, source: u32) -> Self {
        Self {
            stamp_ns,
            kind: EstopKind::Reset as u32,
            source,
            ..Self::default()
        }
    }
}

wire_enum! {
    /// State of the cell's e-stop, in [`HostStateV1::estop`].
    pub enum EstopState: u32 {
        /// No e-stop.
        Clear = 0,
        /// Latched: raised and not reset.
        Latched = 1,
    }
}

/// The supervisor's heartbeat and the latched e-stop, on `<i>/host/state` every tick.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, ZeroCopySend)]
#[type_name("rtc::HostStateV1")]
pub struct HostStateV1 {
    /// When it was published (ns, `CLOCK_MONOTONIC`): the heartbeat.
    pub stamp_ns: u64,
    /// +1 per tick.
    pub beat: u64,
    /// Resets since the cell came up: a process that saw fewer has an e-stop to clear.
    pub resets: u64,
    /// The supervisor's process id.
    pub pid: u32,
    /// [`EstopState`] as `u32`.
    pub estop: u32,
    /// The first trigger since the last reset (its `kind` is 0 while clear).
    pub cause: EstopV1,
    /// A process of the table is being replaced (`restart`, `swap`): bit `k` for process
    /// index `k`. While any bit is set, consumers do not count missing samples as
    /// pending-sequence overruns (the handover would trip them otherwise).
    pub handover: u32,
    /// Reserved (0).
    pub reserved: u32,
}

impl Default for HostStateV1 {
    fn default() -> Self {
        Self {
            stamp_ns: 0,
            beat: 0,
            resets: 0,
            pid: 0,
            estop: EstopState::Clear as u32,
            cause: EstopV1::default(),
            handover: 0,
            reserved: 0,
        }
    }
}
