//! Motion commands into trajgen and the setpoints it publishes.

use crate::MAX_AXES;
use iceoryx2_bb_derive_macros::ZeroCopySend;
use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;

wire_enum! {
    /// What a [`MotionCommandV2`] asks for.
    pub enum CommandKind: u32 {
        /// `MOVE`: towards the Cartesian `target`; the axes blend into the next segment.
        Move = 1,
        /// Stop exactly on the previous target (the same as repeating it).
        Stop = 2,
        /// End of program: stop exactly on the last target, then report `Done`.
        End = 3,
        /// `MOVEJ`: towards the joint `target`, blended in joint space.
        MoveJ = 4,
        /// `OUT`: set output `io` to `value` when the look-ahead reads it.
        Out = 5,
        /// `WAIT`: at rest, until input `io` reads `value` (`time_s` a timeout, 0 none).
        Wait = 6,
        /// `DELAY`: at rest for `time_s`.
        Delay = 7,
        /// `SPEED`: the moves that follow at `speed` (0.01..=1) of vmax.
        Speed = 8,
    }
}

/// One instruction of a motion program, sent by a client to `<i>/trajgen/command`.
///
/// trajgen takes commands into a fixed queue as they arrive (flow control: a client keeps at
/// most [`SetpointV2::queue_free`] commands in flight) and reads the next one only when the
/// motion needs it, at `t = T1 - t_acc` (seed 003 §2; `docs/language.md` says when each kind
/// takes effect).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, ZeroCopySend)]
#[type_name("rtc::MotionCommandV2")]
pub struct MotionCommandV2 {
    /// Sequence number, 1 for the first command a client sends, +1 for each next one.
    pub seq: u64,
    /// Program this command belongs to (chosen by the client, echoed in setpoints).
    pub program_id: u32,
    /// Line of the command in its program source (1-based, for progress and errors).
    pub line: u32,
    /// [`CommandKind`] as `u32`.
    pub kind: u32,
    /// `Move`: the Cartesian coordinates the client believes the cell has; `MoveJ`: its
    /// joints. Must equal the cell's.
    pub count: u32,
    /// `Out`, `Wait`: index of the IO in the cell's IO table.
    pub io: u32,
    /// `Out`, `Wait`: the value (0 or 1).
    pub value: u32,
    /// `Move`, `MoveJ`: the segment time asked for (s), 0 for none:
    /// `T1 = max(axis times, 2 t_acc, this)`. `Delay`: the time (s). `Wait`: the timeout
    /// (s), 0 for none.
    pub time_s: f64,
    /// `Speed`: the share of vmax for the moves that follow, 0.01..=1.
    pub speed: f64,
    /// `Move`: target per Cartesian coordinate; `MoveJ`: per joint.
    pub target: [f64; MAX_AXES],
}

wire_enum! {
    /// What a [`MotionControlV2`] asks for. None of them is an e-stop: the axes stay enabled.
    pub enum ControlKind: u32 {
        /// Decelerate along the path to rest within the blend time `t_acc`, and hold there.
        Pause = 1,
        /// Go on along the same path, accelerating within `t_acc` to the speed override.
        Resume = 2,
        /// Come to rest along the path within `t_acc`, then drop the rest of the program (the
        /// setpoint reports [`trajgen_fault::ABORTED`]).
        Abort = 3,
        /// The live speed override: the path is travelled at `value` (0.01..=1) of the
        /// programmed speed from now on, ramping within `t_acc`; the path itself never changes.
        Speed = 4,
    }
}

/// A request that acts on the running motion at once (not queued behind the program's
/// commands), `<i>/trajgen/control`; trajgen takes it in its next cycle.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, ZeroCopySend)]
#[type_name("rtc::MotionControlV2")]
pub struct MotionControlV2 {
    /// Increasing across senders: the sender's `CLOCK_MONOTONIC` time (ns), or one more
    /// than its previous number if that is larger; trajgen echoes the last one it took in
    /// [`SetpointV2::control_seq`], so a sender knows its request was taken once the echo
    /// reaches its number.
    pub seq: u64,
    /// [`ControlKind`] as `u32`.
    pub kind: u32,
    /// Reserved (0).
    pub reserved: u32,
    /// `Speed`: the override, 0.01..=1.
    pub value: f64,
}

/// trajgen's motion while it is paused, `<i>/trajgen/handover` (history 1), so that a new
/// trajgen (`supervisor swap trajgen` during a program) goes on along the same path from
/// where the old one left it: the segment being executed, where on it, and which command it
/// came from. trajgen publishes it every cycle while paused, and one record with `valid` 0
/// when it stops being paused.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, ZeroCopySend)]
#[type_name("rtc::TrajgenHandoverV2")]
pub struct TrajgenHandoverV2 {
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
    /// The live speed override in effect (0.01..=1).
    pub speed_override: f64,
    /// The program's `SPEED` in effect (0.01..=1).
    pub program_speed: f64,
    /// Real time spent in `WAIT`s so far (s).
    pub waited_s: f64,
    /// The segment's space: 0 Cartesian, 1 joint.
    pub space: u32,
    /// Reserved, 0.
    pub reserved: u32,
}

wire_enum! {
    /// State of the motion in a [`SetpointV2`].
    pub enum MotionState: u32 {
        /// No motion since start: the reference holds still.
        Idle = 0,
        /// A program is moving the axes.
        Moving = 1,
        /// The program reached its end; the reference is at rest on the last target.
        Done = 2,
        /// A command was refused (see [`SetpointV2::fault`]); the reference is at rest.
        Fault = 3,
    }
}

/// trajgen fault codes in [`SetpointV2::fault`].
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
    /// A `WAIT` timed out: the input did not reach its value in time.
    pub const WAIT_TIMEOUT: u32 = 8;
    /// A target has no joint solution within the joint limits (the kinematics say why in
    /// the event), or the move changes space where the kinematics cannot follow.
    pub const UNREACHABLE: u32 = 9;

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
            WAIT_TIMEOUT => "a WAIT timed out",
            UNREACHABLE => "a target is out of the kinematics' reach",
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
#[type_name("rtc::SetpointV2")]
pub struct SetpointV2 {
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
    /// Number of axes (joints) in use.
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
    /// Sequence number of the last [`MotionControlV2`] taken.
    pub control_seq: u64,
    /// The live speed override (0.01..=1) the path speed ramps to when not paused.
    pub speed_override: f64,
    /// The program's `SPEED` for the moves that follow (0.01..=1).
    pub program_speed: f64,
    /// What the program holds at rest for: [`hold`] code.
    pub hold: u32,
    /// `hold` WAIT: the input's index in the IO table.
    pub hold_io: u32,
    /// The space of the segment being executed: 0 Cartesian (`MOVE`), 1 joint (`MOVEJ`).
    pub space: u32,
    /// Number of Cartesian coordinates in use.
    pub coords: u32,
    /// Real time spent in `WAIT`s in the current motion (s): the motion time less this is
    /// what the program's prediction covers.
    pub waited_s: f64,
    /// Reference position per axis (joint; axis unit): what servo follows.
    pub position: [f64; MAX_AXES],
    /// Reference velocity per axis (unit/s).
    pub velocity: [f64; MAX_AXES],
    /// Reference acceleration per axis (unit/s²), for feed-forward.
    pub acceleration: [f64; MAX_AXES],
    /// The same reference in Cartesian coordinates (x, y in mm, θ in degrees, as the
    /// kinematics names them), for viewers and the recorder.
    pub cartesian: [f64; MAX_AXES],
    /// Cartesian velocity (unit/s).
    pub cartesian_velocity: [f64; MAX_AXES],
}

/// What a program holds at rest for, in [`SetpointV2::hold`].
pub mod hold {
    /// Nothing: moving, or at rest with nothing to wait for.
    pub const NONE: u32 = 0;
    /// A `WAIT` for an input.
    pub const WAIT: u32 = 1;
    /// A `DELAY`.
    pub const DELAY: u32 = 2;
}
