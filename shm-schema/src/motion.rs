//! Motion commands into trajgen and the setpoints it publishes.

use crate::MAX_AXES;
use iceoryx2_bb_derive_macros::ZeroCopySend;
use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;

/// What a [`MotionCommandV1`] asks for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u32)]
pub enum CommandKind {
    /// Move towards `target`; the axes blend into the next segment without stopping there.
    Move = 1,
    /// Stop exactly on the previous target (the same as repeating it).
    Stop = 2,
    /// End of program: stop exactly on the last target, then report `Done`.
    End = 3,
}

impl CommandKind {
    /// Decodes the wire value.
    pub fn from_u32(v: u32) -> Option<Self> {
        [Self::Move, Self::Stop, Self::End]
            .into_iter()
            .find(|k| *k as u32 == v)
    }
}

/// One instruction of a motion program, sent by a client to `<i>/trajgen/command`.
///
/// trajgen takes commands into a fixed queue as they arrive (flow control: a client keeps at
/// most [`SetpointV1::queue_free`] commands in flight) and reads the next one only when the
/// motion needs it, at `t = T1 - t_acc` (seed 003 §2).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, ZeroCopySend)]
#[type_name("rtc::MotionCommandV1")]
pub struct MotionCommandV1 {
    /// Sequence number, 1 for the first command a client sends, +1 for each next one.
    pub seq: u64,
    /// Program this command belongs to (chosen by the client, echoed in setpoints).
    pub program_id: u32,
    /// Line of the command in its program source (1-based, for progress and errors).
    pub line: u32,
    /// [`CommandKind`] as `u32`.
    pub kind: u32,
    /// Number of axes the client believes the cell has; must equal the cell's.
    pub axes: u32,
    /// Target position per axis (axis unit); `Move` only.
    pub target: [f64; MAX_AXES],
    /// Segment time the user asks for (s), 0 for none: `T1 = max(axis times, 2 t_acc, this)`.
    pub user_time_s: f64,
}

/// What a [`MotionControlV1`] asks for. None of them is an e-stop: the axes stay enabled.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u32)]
pub enum ControlKind {
    /// Decelerate along the path to rest within the blend time `t_acc`, and hold there.
    Pause = 1,
    /// Go on along the same path, accelerating within `t_acc`.
    Resume = 2,
    /// Come to rest along the path within `t_acc`, then drop the rest of the program (the
    /// setpoint reports [`trajgen_fault::ABORTED`]).
    Abort = 3,
}

impl ControlKind {
    /// Decodes the wire value.
    pub fn from_u32(v: u32) -> Option<Self> {
        [Self::Pause, Self::Resume, Self::Abort]
            .into_iter()
            .find(|k| *k as u32 == v)
    }
}

/// A request that acts on the running motion at once (not queued behind the program's
/// commands), `<i>/trajgen/control`; trajgen takes it in its next cycle.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, ZeroCopySend)]
#[type_name("rtc::MotionControlV1")]
pub struct MotionControlV1 {
    /// Increasing per sender; trajgen echoes the last one it took in
    /// [`SetpointV1::control_seq`].
    pub seq: u64,
    /// [`ControlKind`] as `u32`.
    pub kind: u32,
    /// Reserved (0).
    pub reserved: u32,
}

/// trajgen's motion while it is paused, `<i>/trajgen/handover` (history 1), so that a new
/// trajgen (`supervisor swap trajgen` during a program) goes on along the same path from
/// where the old one left it: the segment being executed, where on it, and which command it
/// came from. trajgen publishes it every cycle while paused, and one record with `valid` 0
/// when it stops being paused.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, ZeroCopySend)]
#[type_name("rtc::TrajgenHandoverV1")]
pub struct TrajgenHandoverV1 {
    /// When it was published (ns, `CLOCK_MONOTONIC`).
    pub stamp_ns: u64,
    /// Sequence number of the command whose segment is being executed: the successor takes
    /// the commands after it.
    pub command_seq: u64,
    /// Start of the motion (ns): the successor's motion time goes on from it.
    pub motion_start_ns: u64,
    /// Program of the motion.
    pub program_id: u32,
    /// Program line of the segment.
    pub line: u32,
    /// 1 while the record describes a paused motion; 0 otherwise.
    pub valid: u32,
    /// Times the queue ran empty so far.
    pub starved: u32,
    /// Local time on the segment (s): where on it the axes rest.
    pub local_s: f64,
    /// Real time lost to pauses so far (s).
    pub lost_s: f64,
    /// Sum of the segment times so far (s).
    pub theoretical_s: f64,
    /// The segment (seed 003 §2): its `T1` (s) and acceleration time (s).
    pub t1_s: f64,
    /// Acceleration time of the segment (s).
    pub t_acc_s: f64,
    /// `A`, `B`, `C` of the segment per axis.
    pub a: [f64; MAX_AXES],
    /// `B`.
    pub b: [f64; MAX_AXES],
    /// `C`.
    pub c: [f64; MAX_AXES],
}

/// State of the motion in a [`SetpointV1`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u32)]
pub enum MotionState {
    /// No motion since start: the reference holds still.
    Idle = 0,
    /// A program is moving the axes.
    Moving = 1,
    /// The program reached its end; the reference is at rest on the last target.
    Done = 2,
    /// A command was refused (see [`SetpointV1::fault`]); the reference is at rest.
    Fault = 3,
}

impl MotionState {
    /// Decodes the wire value.
    pub fn from_u32(v: u32) -> Option<Self> {
        [Self::Idle, Self::Moving, Self::Done, Self::Fault]
            .into_iter()
            .find(|s| *s as u32 == v)
    }
}

/// trajgen fault codes in [`SetpointV1::fault`].
pub mod trajgen_fault {
    /// No fault.
    pub const NONE: u32 = 0;
    /// A command's `axes` differs from the cell's.
    pub const AXES_MISMATCH: u32 = 1;
    /// A target lies outside an axis' limits.
    pub const TARGET_OUT_OF_LIMITS: u32 = 2;
    /// A command kind is unknown or a value is not finite.
    pub const BAD_COMMAND: u32 = 3;
    /// A command arrived while the queue was full (the client ignored flow control).
    pub const QUEUE_OVERFLOW: u32 = 4;
    /// A command's sequence number skipped (a command was lost).
    pub const SEQUENCE_GAP: u32 = 5;
    /// An e-stop dropped the program; the reference rests where servo brought the axes.
    pub const ESTOP: u32 = 6;
    /// A client aborted the program ([`super::ControlKind::Abort`]): the axes came to rest
    /// along the path and the rest of the program was dropped.
    pub const ABORTED: u32 = 7;

    /// What a fault code means, in words.
    pub fn text(code: u32) -> &'static str {
        match code {
            NONE => "no fault",
            AXES_MISMATCH => "the command's axis count differs from the cell's",
            TARGET_OUT_OF_LIMITS => "the target lies outside the axis limits",
            BAD_COMMAND => "the command is malformed",
            QUEUE_OVERFLOW => "its command queue overflowed",
            SEQUENCE_GAP => "a command was lost (sequence gap)",
            ESTOP => "an e-stop dropped the program",
            ABORTED => "the program was aborted",
            _ => "unknown fault",
        }
    }
}

/// The reference trajgen publishes on `<i>/trajgen/setpoint` every cycle.
///
/// Position and velocity are the exact trajectory at [`Self::stamp_ns`]: trajgen evaluates it
/// against real elapsed time, so a consumer may extrapolate `position + velocity * dt`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, ZeroCopySend)]
#[type_name("rtc::SetpointV1")]
pub struct SetpointV1 {
    /// +1 per published setpoint since trajgen started.
    pub seq: u64,
    /// Time the reference was evaluated at (ns, `CLOCK_MONOTONIC`).
    pub stamp_ns: u64,
    /// Start of the current motion (ns, `CLOCK_MONOTONIC`), 0 before the first.
    pub motion_start_ns: u64,
    /// End of the current motion (ns, `CLOCK_MONOTONIC`): the stamp of its first `Done`
    /// setpoint; 0 while it runs.
    pub motion_end_ns: u64,
    /// Motion time: real time elapsed since `motion_start_ns` (s); 0 when idle, frozen at the
    /// motion's duration once it is done.
    pub motion_time_s: f64,
    /// Sum of the segment times T of the current motion so far (s): its theoretical duration
    /// once the state is `Done`.
    pub theoretical_s: f64,
    /// Time T of the segment being executed (s).
    pub segment_time_s: f64,
    /// Program of the current motion (from its commands).
    pub program_id: u32,
    /// Program line of the segment being executed, 0 for none.
    pub line: u32,
    /// [`MotionState`] as `u32`.
    pub state: u32,
    /// Number of axes in use.
    pub axes: u32,
    /// [`trajgen_fault`] code, 0 for none.
    pub fault: u32,
    /// Program line of the command that caused `fault`.
    pub fault_line: u32,
    /// Sequence number of the last command taken into the queue.
    pub commands_taken: u64,
    /// Free places in the command queue.
    pub queue_free: u32,
    /// Times the queue ran empty while a program was running (the axes stopped on the target).
    pub starved: u32,
    /// Path speed as a share of the programmed one, 0..=1: below 1 while a pause or an
    /// abort decelerates (0: paused at rest on the path) or a resume accelerates.
    pub path_speed: f64,
    /// Sequence number of the last [`MotionControlV1`] taken.
    pub control_seq: u64,
    /// Reference position per axis (axis unit).
    pub position: [f64; MAX_AXES],
    /// Reference velocity per axis (unit/s).
    pub velocity: [f64; MAX_AXES],
    /// Reference acceleration per axis (unit/s²), for feed-forward.
    pub acceleration: [f64; MAX_AXES],
}
