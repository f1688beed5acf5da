//! Events (seed 001's event function): one `<i>/events` service for the whole cell.
//!
//! Any process writes fixed-size [`EventV1`] records in its cycle, without allocation; the
//! supervisor reads them, prints them as they happen and puts them in its reports. Every
//! refusal, fault, drive state change and overrun burst is an event naming what happened,
//! where (source process, axis), the value and the limit it crossed. [`code`] lists every
//! code; [`CODES`] describes them (and `docs/events.md` is generated from it).

use crate::MAX_AXES;
use iceoryx2_bb_derive_macros::ZeroCopySend;
use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;

/// Bytes of [`EventV1::text`].
pub const EVENT_TEXT_LEN: usize = 64;

/// Source of an event that is not a real-time process: the supervisor.
pub const SOURCE_SUPERVISOR: u32 = 100;

wire_enum! {
    /// How bad an event is, in [`EventV1::severity`].
    #[derive(PartialOrd, Ord)]
    pub enum Severity: u32 {
        /// Something changed as asked (a drive state, power on).
        Info = 0 as "info",
        /// Something the user should look at; nothing was stopped by it.
        Warning = 1 as "warning",
        /// A refusal or a fault: power was cut, or a command was refused.
        Error = 2 as "error",
    }
}

/// One event, on `<i>/events`.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, ZeroCopySend)]
#[type_name("rtc::EventV1")]
pub struct EventV1 {
    /// +1 per event of this source since it started.
    pub seq: u64,
    /// When it happened (ns, `CLOCK_MONOTONIC`).
    pub stamp_ns: u64,
    /// The value that caused it (unit per code: see [`CODES`]).
    pub value: f64,
    /// The limit it was compared with (same unit), 0 when there is none.
    pub limit: f64,
    /// Source: the index of the process in the cell configuration's process table, or
    /// [`SOURCE_SUPERVISOR`] for the supervisor and the user's tools.
    pub source: u32,
    /// [`Severity`] as `u32`.
    pub severity: u32,
    /// One of [`code`].
    pub code: u32,
    /// Axis index, -1 for the whole cell.
    pub axis: i32,
    /// A short text, NUL-padded UTF-8 (a drive state's name, a cause).
    pub text: [u8; EVENT_TEXT_LEN],
}

impl Default for EventV1 {
    fn default() -> Self {
        Self {
            seq: 0,
            stamp_ns: 0,
            value: 0.0,
            limit: 0.0,
            source: 0,
            severity: 0,
            code: 0,
            axis: -1,
            text: [0; EVENT_TEXT_LEN],
        }
    }
}

impl EventV1 {
    /// An event of `code` (its severity from [`CODES`]) at `stamp_ns` on `axis` (-1 for
    /// none), with its text made of `parts` (truncated to fit).
    ///
    /// # Real-time
    /// Copies only; no allocation.
    pub fn new(
        stamp_ns: u64,
        code: u32,
        axis: i32,
        value: f64,
        limit: f64,
        parts: &[&str],
    ) -> Self {
        let text = text_of(parts);
        Self {
            seq: 0,
            stamp_ns,
            value,
            limit,
            source: 0,
            severity: info(code).map_or(Severity::Error, |i| i.severity) as u32,
            code,
            axis,
            text,
        }
    }

    /// The text.
    pub fn text(&self) -> &str {
        crate::str_of(&self.text)
    }
}

/// `parts` joined into a NUL-padded field of `N` bytes, truncated so that it ends in NUL and
/// never cuts a UTF-8 character in half.
///
/// # Real-time
/// Copies only; no allocation.
pub fn text_of<const N: usize>(parts: &[&str]) -> [u8; N] {
    let mut text = [0u8; N];
    let mut at = 0;
    'outer: for p in parts {
        for &b in p.as_bytes() {
            if at + 1 >= N {
                break 'outer;
            }
            text[at] = b;
            at += 1;
        }
    }
    while at > 0 && core::str::from_utf8(&text[..at]).is_err() {
        at -= 1;
        text[at] = 0;
    }
    text
}

/// Event codes. Hundreds group them: 1xx drives (device side), 2xx servo refusals and
/// faults, 3xx the arm's power, 4xx timing, 5xx the supervisor, 6xx the e-stop and health,
/// 7xx the named digital IO.
pub mod code {
    /// A drive took a CiA 402 transition; value: the transition number.
    pub const DRIVE_TRANSITION: u32 = 101;
    /// A drive raised a fault; value: its CiA 402 error code (0x603F).
    pub const DRIVE_FAULT: u32 = 102;
    /// A fault was injected into a simulated drive; value: the error code (0 = cleared).
    pub const FAULT_INJECTED: u32 = 103;
    /// A drive's command watchdog expired; value: time since the last command (s).
    pub const COMMAND_TIMEOUT: u32 = 104;
    /// A drive refused a command whose target is not finite; value: the axis' requested mode.
    pub const DRIVE_COMMAND_REFUSED: u32 = 105;

    /// A commanded position lies outside the joint range; value: position, limit: the bound.
    pub const POSITION_OUT_OF_RANGE: u32 = 201;
    /// A commanded velocity exceeds its limit (unit/s).
    pub const VELOCITY_OVER_LIMIT: u32 = 202;
    /// The commanded position moved further in one cycle than allowed (unit per period).
    pub const POSITION_STEP_OVER_LIMIT: u32 = 203;
    /// The commanded velocity changed more in one cycle than allowed (unit/s per period).
    pub const VELOCITY_STEP_OVER_LIMIT: u32 = 204;
    /// A value in a setpoint or command is not a finite number.
    pub const COMMAND_NOT_FINITE: u32 = 205;
    /// A value in the drives' feedback is not a finite number.
    pub const FEEDBACK_NOT_FINITE: u32 = 206;
    /// The following error exceeds its limit (axis unit): a device e-stop.
    pub const FOLLOWING_ERROR: u32 = 207;
    /// A drive reports Fault; value: its error code.
    pub const DRIVE_REPORTS_FAULT: u32 = 208;
    /// No new drive feedback for longer than the feedback timeout; value: its age (s).
    pub const FEEDBACK_STALE: u32 = 209;
    /// The enabling sequence did not complete within the enable timeout (s).
    pub const ENABLE_TIMEOUT: u32 = 210;
    /// A new source's first setpoint does not start where servo holds; refused, servo holds.
    /// value: its distance from where servo holds (axis unit), limit: how far it may be.
    pub const SETPOINT_JUMP: u32 = 211;
    /// A new source's first setpoint does not start at the velocity servo holds; refused,
    /// servo holds. value: the difference (axis unit/s), limit: the velocity step limit.
    pub const SETPOINT_VELOCITY_JUMP: u32 = 217;
    /// No fresh setpoint for longer than the setpoint timeout; value: its age (s). The
    /// reference comes to rest.
    pub const SETPOINT_STALE: u32 = 212;
    /// A request was refused; value: the request kind (1 enable, 2 disable, 3 reset).
    pub const REQUEST_REFUSED: u32 = 213;
    /// A drive left Operation enabled on its own; value: its statusword.
    pub const DRIVE_LOST_ENABLE: u32 = 214;
    /// The drives' feedback does not match the cell: its axis count, or a drive's mode
    /// display while enabled; value: what it reports, limit: what the cell expects.
    pub const FEEDBACK_MISMATCH: u32 = 216;
    /// trajgen refused a motion command and stopped the axes on their current target;
    /// value: the command's program line, limit: trajgen's fault code.
    pub const MOTION_COMMAND_REFUSED: u32 = 215;

    /// The enabling sequence started.
    pub const ENABLING: u32 = 301;
    /// Every axis is in Operation enabled.
    pub const ENABLED: u32 = 302;
    /// The disabling sequence started.
    pub const DISABLING: u32 = 303;
    /// Every axis is without power.
    pub const DISABLED: u32 = 304;
    /// Power was cut (quick stop, then disable) because of a fault; value: the fault's code.
    pub const POWER_CUT: u32 = 305;
    /// A latched fault was cleared by a reset request.
    pub const FAULT_CLEARED: u32 = 306;
    /// A tuning step offset the reference of an axis; value: the offset (axis unit).
    pub const TUNE_STEP: u32 = 307;

    /// A burst of overruns; value: overruns since the previous such event.
    pub const OVERRUN_BURST: u32 = 401;
    /// A cycle queued more events than its queue holds; value: events lost, limit: the
    /// queue's capacity.
    pub const EVENTS_DROPPED: u32 = 402;

    /// The supervisor sent a request or a command on the user's behalf.
    pub const SUPERVISOR_ACTION: u32 = 501;
    /// A process of the cell died or stopped cycling; value: its exit code or -1.
    pub const PROCESS_LOST: u32 = 502;
    /// A process of the cell was started again by its restart policy; value: restarts so far.
    pub const PROCESS_RESTARTED: u32 = 503;
    /// The supervisor's own heartbeat paused; value: the gap (s). The text says where it went.
    pub const SUPERVISOR_STALLED: u32 = 504;

    /// An e-stop was raised; value: its origin (1 device, 2 external, 3 host), limit: the
    /// cause's event code.
    pub const ESTOP_RAISED: u32 = 601;
    /// The e-stop was reset; value: resets so far.
    pub const ESTOP_RESET: u32 = 602;
    /// A process completed its e-stop reaction (servo: axes at rest, drives disabled or
    /// holding); value: time from the e-stop to this (s).
    pub const ESTOP_SAFE: u32 = 603;
    /// A health detector expired; value: its count, limit: its limit.
    pub const HEALTH_EXPIRED: u32 = 604;
    /// The supervisor's heartbeat stopped; value: its age (s), limit: the timeout (s).
    pub const SUPERVISOR_LOST: u32 = 605;

    /// A named digital IO changed (the text names it); value: its new value.
    pub const IO_CHANGED: u32 = 701;
    /// An e-stop input is open (the text names it).
    pub const ESTOP_INPUT: u32 = 702;
    /// A write of the IO was refused (the text names the entry and why).
    pub const IO_REFUSED: u32 = 703;

    /// A process serves on a network address (the text is the address: `127.0.0.1:1502`).
    pub const LISTENING: u32 = 801;
    /// A process cannot listen on its address (the text says why); it tries again every
    /// second.
    pub const LISTEN_FAILED: u32 = 802;
    /// A fieldbus client wrote a setting (the text names the register and the client);
    /// value: the value written.
    pub const FIELDBUS_WRITE: u32 = 803;
    /// A process that is not critical failed (lost, stalled, or a health detector expired;
    /// the text says which): a warning, never an e-stop; it restarts per its policy.
    pub const NOT_CRITICAL_FAILED: u32 = 804;

    /// The EtherCAT bus is in OP and exchanging process data; value: SubDevices on it, limit:
    /// the working counter expected.
    pub const BUS_OP: u32 = 901;
    /// Frames of the EtherCAT bus came back late or not at all; value: frames lost in a row,
    /// limit: the frames that make the bus lost.
    pub const BUS_FRAMES_LOST: u32 = 902;
    /// The EtherCAT working counter differed from the expected one (a SubDevice did not take
    /// its process data); value: the working counter, limit: the expected one.
    pub const BUS_WKC_MISMATCH: u32 = 903;
    /// No frame came back for the SubDevices' process data watchdog: the bus is lost (a cable,
    /// a SubDevice powered off); value: frames lost in a row, limit: the frames allowed.
    pub const BUS_LOST: u32 = 904;
    /// A SubDevice of the EtherCAT bus is no longer in OP; value: its AL status (state and
    /// error bit), limit: its AL status code; the text names it (position and name).
    pub const SUBDEVICE_LEFT_OP: u32 = 905;
    /// A SubDevice sent a CoE emergency; value: its error code, limit: its error register;
    /// the text names it (position and name).
    pub const SUBDEVICE_EMERGENCY: u32 = 906;
    /// The EtherCAT bus process is bringing the bus up again from the scan (after
    /// `bus-lost`, or a SubDevice out of OP with the e-stop latched); value: how many times
    /// this process has done so, limit: 0.
    pub const BUS_RECOVERING: u32 = 907;
    /// SYNC0 events of the drives came without new outputs (the cycle's frame was not there
    /// before them); value: how many since the last such event, limit: 0.
    pub const SYNC0_LATE: u32 = 908;
    /// A SubDevice did not go from SAFE-OP to OP when the bus process' cycle asked for it;
    /// value: its AL status, limit: its AL status code; the text names it.
    pub const SUBDEVICE_NOT_OP: u32 = 909;
    /// Bringing the bus up again, the scan found other SubDevices than the configuration
    /// names (another product at a position, one missing, one more): the bus stays down.
    /// value: the product code found there (0: nothing answers), limit: the product code the
    /// configuration names there (0: none); the text names the position.
    pub const SUBDEVICE_MISMATCH: u32 = 910;
    /// The EtherCAT emulator, as it stops: how many SYNC0 events an emulated drive took;
    /// value: SYNC0 events, limit: those of them that found no new outputs (0x1C32:0B); the
    /// text names its position.
    pub const EMULATED_SYNC0: u32 = 911;
}

/// The unit of an event's `value` and `limit`: what a reader shows them as. Decisions on how
/// to show a value are taken on this, never on its words ([`Unit::text`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Unit {
    /// `value` and `limit` are not used.
    None,
    /// The axis' own unit (mm, deg).
    Axis,
    /// The axis' unit per second.
    AxisPerSecond,
    /// The axis' unit per servo period (a position step).
    AxisPerPeriod,
    /// The axis' unit per second per servo period (a velocity step).
    AxisPerSecondPerPeriod,
    /// Seconds.
    Seconds,
    /// Another event's code.
    EventCode,
    /// A code or a bit field, best read in hexadecimal; the words say which.
    Hex(&'static str),
    /// Any other number; the words say what it counts.
    Number(&'static str),
}

impl Unit {
    /// Its words, as `docs/events.md` gives them; empty for [`Unit::None`].
    pub const fn text(&self) -> &'static str {
        match self {
            Self::None => "",
            Self::Axis => "axis unit",
            Self::AxisPerSecond => "axis unit/s",
            Self::AxisPerPeriod => "axis unit per servo period",
            Self::AxisPerSecondPerPeriod => "axis unit/s per servo period",
            Self::Seconds => "s",
            Self::EventCode => "event code",
            Self::Hex(words) | Self::Number(words) => words,
        }
    }
}

/// What a code means, for documents and reports.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CodeInfo {
    /// The code.
    pub code: u32,
    /// Its short name (lower case, dashes).
    pub name: &'static str,
    /// Its severity.
    pub severity: Severity,
    /// Unit of `value` and `limit`: how to read and show them.
    pub unit: Unit,
    /// What it means and what follows.
    pub meaning: &'static str,
}

/// Every event code.
pub const CODES: &[CodeInfo] = &[
    CodeInfo {
        code: code::DRIVE_TRANSITION,
        name: "drive-transition",
        severity: Severity::Info,
        unit: Unit::Number("transition number"),
        meaning: "A drive took a CiA 402 state transition (numbers as in the profile, docs/drives.md); the text names the new state.",
    },
    CodeInfo {
        code: code::DRIVE_FAULT,
        name: "drive-fault",
        severity: Severity::Error,
        unit: Unit::Hex("error code (0x603F)"),
        meaning: "A drive raised a fault: transition 13, fault reaction (quick-stop ramp), then Fault. Power stays off until a fault reset and a new enable.",
    },
    CodeInfo {
        code: code::FAULT_INJECTED,
        name: "fault-injected",
        severity: Severity::Warning,
        unit: Unit::Hex("error code (0 = cleared)"),
        meaning: "A fault condition was injected into (or cleared from) a simulated drive, by configuration or by `supervisor inject`.",
    },
    CodeInfo {
        code: code::COMMAND_TIMEOUT,
        name: "command-timeout",
        severity: Severity::Error,
        unit: Unit::Seconds,
        meaning: "A drive received no new command for longer than `[drives] command_timeout`: fault 0xFF01, the motor stops and the power stage turns off.",
    },
    CodeInfo {
        code: code::DRIVE_COMMAND_REFUSED,
        name: "drive-command-refused",
        severity: Severity::Error,
        unit: Unit::Number("mode"),
        meaning: "A drive refused a command: a target that is not a finite number (it keeps its last valid target and faults: 0x6320, parameter error; value: the requested mode), a mode of operation it does not support (not taken: 0x6061 keeps showing the mode in effect; value: that mode), or a command for another number of axes (not taken at all; value: its axis count, limit: the drives'). Reported once until a valid command arrives.",
    },
    CodeInfo {
        code: code::POSITION_OUT_OF_RANGE,
        name: "position-out-of-range",
        severity: Severity::Error,
        unit: Unit::Axis,
        meaning: "Command validation: the commanded position lies outside [min, max]. Power is cut and the fault latched until reset.",
    },
    CodeInfo {
        code: code::VELOCITY_OVER_LIMIT,
        name: "velocity-over-limit",
        severity: Severity::Error,
        unit: Unit::AxisPerSecond,
        meaning: "Command validation: |commanded velocity| exceeds `limits.velocity`. Power is cut and the fault latched until reset.",
    },
    CodeInfo {
        code: code::POSITION_STEP_OVER_LIMIT,
        name: "position-step-over-limit",
        severity: Severity::Error,
        unit: Unit::AxisPerPeriod,
        meaning: "Command validation: the commanded position moved more than `limits.position_step` in one servo period (scaled by the real time since the previous cycle). Power is cut and the fault latched until reset.",
    },
    CodeInfo {
        code: code::VELOCITY_STEP_OVER_LIMIT,
        name: "velocity-step-over-limit",
        severity: Severity::Error,
        unit: Unit::AxisPerSecondPerPeriod,
        meaning: "Command validation: the commanded velocity changed more than `limits.velocity_step` in one servo period (scaled by the real time since the previous cycle). Power is cut and the fault latched until reset.",
    },
    CodeInfo {
        code: code::COMMAND_NOT_FINITE,
        name: "command-not-finite",
        severity: Severity::Error,
        unit: Unit::None,
        meaning: "A setpoint or the command servo computed holds a value that is not a finite number (NaN, infinity). Power is cut at once and the fault latched until reset.",
    },
    CodeInfo {
        code: code::FEEDBACK_NOT_FINITE,
        name: "feedback-not-finite",
        severity: Severity::Error,
        unit: Unit::None,
        meaning: "The drives' feedback holds a value that is not a finite number (a lost encoder, an unstable simulation). Power is cut at once and the fault latched until reset.",
    },
    CodeInfo {
        code: code::FOLLOWING_ERROR,
        name: "following-error",
        severity: Severity::Error,
        unit: Unit::Axis,
        meaning: "|commanded − measured position| exceeds `following_error_limit` (a device e-stop). Power is cut and the fault latched until reset.",
    },
    CodeInfo {
        code: code::DRIVE_REPORTS_FAULT,
        name: "drive-reports-fault",
        severity: Severity::Error,
        unit: Unit::Hex("error code (0x603F)"),
        meaning: "Servo sees a drive in Fault (or Fault reaction active). Every other axis is stopped and the fault latched until reset.",
    },
    CodeInfo {
        code: code::FEEDBACK_STALE,
        name: "feedback-stale",
        severity: Severity::Error,
        unit: Unit::Seconds,
        meaning: "No new drive feedback for longer than `[drives] feedback_timeout`: servo cannot close the loop. It commands a quick stop and latches the fault until reset.",
    },
    CodeInfo {
        code: code::ENABLE_TIMEOUT,
        name: "enable-timeout",
        severity: Severity::Error,
        unit: Unit::Seconds,
        meaning: "The enabling sequence did not reach Operation enabled on every axis within `[drives] enable_timeout`. Power is taken off again.",
    },
    CodeInfo {
        code: code::SETPOINT_JUMP,
        name: "setpoint-jump",
        severity: Severity::Warning,
        unit: Unit::Axis,
        meaning: "The first setpoint of a source (after enabling, after a stale spell, after trajgen restarted) lies further from where servo holds than the axis may start from (1.5 cycles at vmax plus the in-position band, at most one position step): it is refused and servo holds. trajgen restarts from where servo holds once at rest.",
    },
    CodeInfo {
        code: code::SETPOINT_VELOCITY_JUMP,
        name: "setpoint-velocity-jump",
        severity: Severity::Warning,
        unit: Unit::AxisPerSecond,
        meaning: "The first setpoint of a source (after enabling, after a stale spell, after trajgen restarted) starts at a velocity further from the one servo holds than the axis' velocity step limit allows (scaled by a late cycle): it is refused and servo holds, as for `setpoint-jump`.",
    },
    CodeInfo {
        code: code::SETPOINT_STALE,
        name: "setpoint-stale",
        severity: Severity::Warning,
        unit: Unit::Seconds,
        meaning: "No fresh setpoint for longer than `[motion] setpoint_timeout` while the arm is enabled (trajgen stalled or died): servo brings the reference to rest at the axis' stop deceleration and holds; only a setpoint that starts where it holds is taken again.",
    },
    CodeInfo {
        code: code::REQUEST_REFUSED,
        name: "request-refused",
        severity: Severity::Warning,
        unit: Unit::Number("request kind"),
        meaning: "A request was refused: enable while a fault is latched (reset first), or reset while its cause persists (the text says which).",
    },
    CodeInfo {
        code: code::DRIVE_LOST_ENABLE,
        name: "drive-lost-enable",
        severity: Severity::Error,
        unit: Unit::Hex("statusword"),
        meaning: "A drive left Operation enabled without being asked. Power is cut on every axis and the fault latched until reset.",
    },
    CodeInfo {
        code: code::MOTION_COMMAND_REFUSED,
        name: "motion-command-refused",
        severity: Severity::Error,
        unit: Unit::Number("program line (limit: trajgen fault code)"),
        meaning: "trajgen refused a motion command (axis count, a target outside the limits, a malformed or lost command, a full queue; the text says which): the queue is emptied and the axes stop on their current target.",
    },
    CodeInfo {
        code: code::FEEDBACK_MISMATCH,
        name: "feedback-mismatch",
        severity: Severity::Error,
        unit: Unit::Number("axis count, or mode of operation"),
        meaning: "The drives' feedback is not the cell's: it carries another number of axes, or a drive's mode of operation display (0x6061) is not the mode the axis is configured for while the arm is enabled (or when enabling would complete). Servo cannot trust it: power is cut and the fault latched until reset.",
    },
    CodeInfo {
        code: code::ENABLING,
        name: "enabling",
        severity: Severity::Info,
        unit: Unit::None,
        meaning: "An enable request started the enabling sequence (Shutdown, Switch on, Enable operation).",
    },
    CodeInfo {
        code: code::ENABLED,
        name: "enabled",
        severity: Severity::Info,
        unit: Unit::Seconds,
        meaning: "Every axis is in Operation enabled; value: how long enabling took.",
    },
    CodeInfo {
        code: code::DISABLING,
        name: "disabling",
        severity: Severity::Info,
        unit: Unit::None,
        meaning: "A disable request started the disabling sequence (it aborts a pending enable).",
    },
    CodeInfo {
        code: code::DISABLED,
        name: "disabled",
        severity: Severity::Info,
        unit: Unit::None,
        meaning: "Every axis is without power.",
    },
    CodeInfo {
        code: code::POWER_CUT,
        name: "power-cut",
        severity: Severity::Error,
        unit: Unit::EventCode,
        meaning: "Power was cut because of the fault whose code is the value: quick stop on every axis, then disable voltage. Latched until a reset request; then an enable request.",
    },
    CodeInfo {
        code: code::FAULT_CLEARED,
        name: "fault-cleared",
        severity: Severity::Info,
        unit: Unit::EventCode,
        meaning: "A reset request cleared the latched fault whose code is the value. Power stays off until an enable request.",
    },
    CodeInfo {
        code: code::TUNE_STEP,
        name: "tune-step",
        severity: Severity::Info,
        unit: Unit::Axis,
        meaning: "A `Step` request (`supervisor tune`) offset the reference of the axis by the value (0: the offset removed); servo took it as the one position step command validation lets through.",
    },
    CodeInfo {
        code: code::OVERRUN_BURST,
        name: "overrun-burst",
        severity: Severity::Warning,
        unit: Unit::Number("overruns"),
        meaning: "A process' cycle ran past its next deadline (the CS9 overrun rule); value: overruns since the previous such event of the process (at most one event per second).",
    },
    CodeInfo {
        code: code::EVENTS_DROPPED,
        name: "events-dropped",
        severity: Severity::Warning,
        unit: Unit::Number("events (limit: the queue's capacity)"),
        meaning: "A process' cycle queued more events than its fixed queue holds; the value says how many were lost since the previous such event. From the gateway (on the line only, not on the cell's own events): events of the cell it could not forward to the line.",
    },
    CodeInfo {
        code: code::SUPERVISOR_ACTION,
        name: "supervisor-action",
        severity: Severity::Info,
        unit: Unit::None,
        meaning: "The supervisor or one of its tools acted (a fault injection); the text says what. Best effort: a tool publishes it from a port it has just opened, and a subscriber can miss it; the effect (e.g. `fault-injected` from the drives) is what to rely on.",
    },
    CodeInfo {
        code: code::PROCESS_LOST,
        name: "process-lost",
        severity: Severity::Error,
        unit: Unit::Number("exit code (-1: killed by a signal or stalled)"),
        meaning: "A process of the cell exited or stopped cycling (its status did not advance for `heartbeat_timeout`); the text names it and why. An unrecoverable host e-stop follows: every process reacts, whatever `propagate_estop` says. A reset is refused until the process is cyclic again (its restart policy, or `supervisor restart`).",
    },
    CodeInfo {
        code: code::PROCESS_RESTARTED,
        name: "process-restarted",
        severity: Severity::Warning,
        unit: Unit::Number("restarts of this process so far"),
        meaning: "The supervisor started a process again after it was lost (`restart = \"on-failure\"`, or `supervisor restart`); the e-stop stays latched until `supervisor reset`.",
    },
    CodeInfo {
        code: code::SUPERVISOR_STALLED,
        name: "supervisor-stalled",
        severity: Severity::Warning,
        unit: Unit::Seconds,
        meaning: "Two of the supervisor's heartbeats were further apart than 100 ms (or a quarter of `supervisor_timeout`, if shorter); past the whole of `supervisor_timeout` every process takes the supervisor for lost and brings the axes to rest. The text splits the gap by the kernel's accounting: waiting for a CPU (a real-time process or other load held the CPUs), taken by the host (steal time of a virtual machine), running (the supervisor's own work), and the rest blocked in a call.",
    },
    CodeInfo {
        code: code::ESTOP_RAISED,
        name: "estop-raised",
        severity: Severity::Error,
        unit: Unit::Number("origin: 1 device, 2 external, 3 host (limit: the cause's code)"),
        meaning: "A process, the user or the host raised the e-stop (seed 002); the text is the reason. It is latched in every process that reads it in its cycle, and each process whose propagation rules and `network_estop_config` say so reacts: servo brings the axes to rest within `estop_stop_time` and disables the drives, trajgen drops the program, iobridge sets its outputs to their safe values. Cleared only by `supervisor reset`.",
    },
    CodeInfo {
        code: code::ESTOP_RESET,
        name: "estop-reset",
        severity: Severity::Info,
        unit: Unit::Number("resets so far"),
        meaning: "`supervisor reset` cleared the e-stop and servo's latched faults; the drives stay disabled until `supervisor start`.",
    },
    CodeInfo {
        code: code::ESTOP_SAFE,
        name: "estop-safe",
        severity: Severity::Info,
        unit: Unit::Seconds,
        meaning: "A process completed its e-stop reaction; the value is the time from the e-stop's raising to this cycle (for servo: from the request to every axis at rest and its drive disabled).",
    },
    CodeInfo {
        code: code::HEALTH_EXPIRED,
        name: "health-expired",
        severity: Severity::Error,
        unit: Unit::Number("counts"),
        meaning: "A health detector of seed 002 (pending_sequence_overrun, transport_overrun, thread_offset_variance; the text names it) reached its limit in the process named as the source: an unrecoverable host e-stop follows. docs/operations.md says how to tune `[health_config]`.",
    },
    CodeInfo {
        code: code::SUPERVISOR_LOST,
        name: "supervisor-lost",
        severity: Severity::Error,
        unit: Unit::Seconds,
        meaning: "A process has not seen the supervisor's heartbeat for `supervisor_timeout`: it reacts as to a host e-stop (servo brings the axes to rest and disables the drives) and exits, so no cell runs headless.",
    },
    CodeInfo {
        code: code::IO_CHANGED,
        name: "io-changed",
        severity: Severity::Info,
        unit: Unit::Number("0 or 1"),
        meaning: "A named digital IO (docs/io.md) changed to the value given: an input as the field reported it, an output as iobridge wrote it (on request, or to its safe value on an e-stop); the text names it.",
    },
    CodeInfo {
        code: code::ESTOP_INPUT,
        name: "estop-input",
        severity: Severity::Error,
        unit: Unit::None,
        meaning: "An e-stop input (an `[[io]]` entry with `estop = true`) opened: a button was pressed or its wire broke. iobridge raises the user's e-stop (external origin: `propagate_external_estop` applies) and raises it again after a reset for as long as the input stays open.",
    },
    CodeInfo {
        code: code::IO_REFUSED,
        name: "io-refused",
        severity: Severity::Warning,
        unit: Unit::None,
        meaning: "iobridge refused (part of) a write of the IO: an output requested while its e-stop reaction holds the outputs at their safe values (nothing of that request is taken), an input written as an output or the reverse, or a bit beyond the IO table (those bits are ignored, the others taken); the text names the first refused entry and why.",
    },
    CodeInfo {
        code: code::LISTENING,
        name: "listening",
        severity: Severity::Info,
        unit: Unit::None,
        meaning: "A process serves on a network address, which the text gives (the Modbus server: its `[modbus] listen`, with the port it got when that is 0; the gateway: the cell's name on the line and its endpoints). `supervisor status` shows it.",
    },
    CodeInfo {
        code: code::LISTEN_FAILED,
        name: "listen-failed",
        severity: Severity::Warning,
        unit: Unit::None,
        meaning: "A process cannot listen on its address (in use by another instance or program, not an address of this machine), or the gateway cannot join the line (an endpoint it cannot open, a certificate or password file it cannot read, a users file it refuses); the text says why. It tries again (the Modbus server every second, the gateway every 2 s unless its configuration is at fault); the cell runs on without it.",
    },
    CodeInfo {
        code: code::FIELDBUS_WRITE,
        name: "fieldbus-write",
        severity: Severity::Info,
        unit: Unit::Number("value written"),
        meaning: "A fieldbus client wrote a setting (the speed override register); the text names the register and the client.",
    },
    CodeInfo {
        code: code::NOT_CRITICAL_FAILED,
        name: "not-critical-failed",
        severity: Severity::Warning,
        unit: Unit::None,
        meaning: "A process with `critical = false` failed: it was lost or it stalled (the supervisor restarts it by its `restart` policy), or one of its health detectors expired (the process starts its detectors afresh); the text says which, value and limit as in `process-lost` or `health-expired`. No e-stop follows and no program ends.",
    },
    CodeInfo {
        code: code::BUS_OP,
        name: "bus-op",
        severity: Severity::Info,
        unit: Unit::Number("SubDevices"),
        meaning: "The EtherCAT bus process found every SubDevice of `[[ethercat.subdevice]]` at its place, mapped the drives, and every SubDevice reached OP: the set-up takes the bus to SAFE-OP, and the cycle's own frames ask for OP (so no SubDevice is ever in OP before the cycle runs, where its process data watchdog would take it out again); its cycle exchanges the process data from now on, and feedback reaches servo from this frame on. Limit: the working counter it expects of every frame; the text names the interface.",
    },
    CodeInfo {
        code: code::BUS_FRAMES_LOST,
        name: "bus-frames-lost",
        severity: Severity::Warning,
        unit: Unit::Number("frames"),
        meaning: "A bus cycle's frame did not come back within half a period (the first of a run of them, then at most one a second): that cycle publishes no drive feedback (never a last good value), and servo judges the gap by its `feedback_timeout`. A lost frame now and then is the host's (a VM's stall); many in a row are `bus-lost`.",
    },
    CodeInfo {
        code: code::BUS_WKC_MISMATCH,
        name: "bus-wkc-mismatch",
        severity: Severity::Error,
        unit: Unit::Number("working counter"),
        meaning: "The frame came back but a SubDevice did not read or write its process data (it left OP, its watchdog expired, it was replaced): the feedback of that cycle has every position NaN, which servo takes as a lost encoder and cuts power. The first of a run of them, then at most one a second.",
    },
    CodeInfo {
        code: code::BUS_LOST,
        name: "bus-lost",
        severity: Severity::Error,
        unit: Unit::Number("frames"),
        meaning: "No frame came back for as long as the SubDevices' process data watchdog (`[ethercat] pd_watchdog`, 100 ms if 0): the SubDevices have taken their outputs safe by themselves. The bus process raises the e-stop, publishes feedback with every position NaN and no state (servo cuts power at once), and from then on brings the bus up again from the scan (`bus-recovering`), about once a second, until it answers as the configuration says (`bus-op`), the drives left without power. A `reset` before that raises the e-stop again; after it, `reset` and `start` go on.",
    },
    CodeInfo {
        code: code::SUBDEVICE_LEFT_OP,
        name: "subdevice-left-op",
        severity: Severity::Error,
        unit: Unit::Number("AL status (limit: AL status code)"),
        meaning: "A SubDevice of the bus left OP (its AL status, read in every frame, says another state; 0x14 is SAFE-OP with the error bit): its watchdog expired (AL status code 0x001B), it lost its mailbox or sync configuration, or it was switched off and on. The text names its position and name. The bus process raises the e-stop (nothing on the bus runs on without one of its SubDevices); its process data is not taken while it is out of OP (`bus-wkc-mismatch`, and servo cuts power); once the e-stop has been latched for `estop_stop_time`, the bus process brings the bus up again (`bus-recovering`, `bus-op`), then `reset` and `start` go on.",
    },
    CodeInfo {
        code: code::SUBDEVICE_EMERGENCY,
        name: "subdevice-emergency",
        severity: Severity::Warning,
        unit: Unit::Hex("error code (limit: error register)"),
        meaning: "A SubDevice sent a CoE emergency message (ETG.1000.6): the bus reads every send mailbox found full, in OP one per cycle, at start-up before ethercrab can see it. Value: the emergency's error code (CiA 402's 0x603F codes for a drive: 0x2310 over-current, 0x7320 position sensor, 0x8611 following error, 0xFF01 the drive's command watchdog), limit: its error register; the text names the SubDevice (position and name). A drive's fault itself reaches servo through the statusword and 0x603F (`drive-fault`); the emergency says what the drive said when it happened.",
    },
    CodeInfo {
        code: code::BUS_RECOVERING,
        name: "bus-recovering",
        severity: Severity::Info,
        unit: Unit::Number("recoveries"),
        meaning: "The bus process brings the EtherCAT bus up again from the scan, as at start-up (the line compared with `[[ethercat.subdevice]]`, the drives mapped, SAFE-OP, OP), because it was lost (`bus-lost`), or a SubDevice stayed out of OP or did not take its data while the e-stop was latched for `estop_stop_time` (every drive has ramped down by then). Until it is back (`bus-op`, \"back in OP\") the feedback has every position NaN and no state, and a `reset` raises the e-stop again. An attempt that fails is tried again a second later, without end; the process' log says why each failed (a cable still out, another identity at a position).",
    },
    CodeInfo {
        code: code::SYNC0_LATE,
        name: "sync0-late",
        severity: Severity::Warning,
        unit: Unit::Number("SYNC0 events"),
        meaning: "Drives on Distributed Clocks (`sync = \"dc\"`) take their outputs at SYNC0, `sync0_shift` after the bus process wakes; this many SYNC0 events came with no new frame before them (the bus process woke late, a frame was lost, or two frames fell in one SYNC0 cycle), as the reference clock's time in the frames shows. At each, a drive keeps the previous outputs (a CSP drive holds its target for one more period: a step in the motion). The first, then at most one a second. Frequent: the wake-up latency of the bus process plus the frame's round trip is too close to `sync0_shift` (docs/ethercat.md, Distributed Clocks).",
    },
    CodeInfo {
        code: code::SUBDEVICE_NOT_OP,
        name: "subdevice-not-op",
        severity: Severity::Error,
        unit: Unit::Number("AL status (limit: AL status code)"),
        meaning: "A SubDevice did not go from SAFE-OP to OP when the bus process' cycle asked for it (at start-up, or when the bus came back): it refused (its AL status has the error bit; the AL status code says why: 0x001D invalid outputs, 0x0030 invalid DC synchronisation, ...) or was not there 10 s after the bus came up in SAFE-OP (AL status code 0). The text names its position and name. Nothing is published to servo meanwhile (no drive can be enabled); the bus process brings the bus up again from the scan (`bus-recovering`), about once a second, until every SubDevice reaches OP (`bus-op`).",
    },
    CodeInfo {
        code: code::SUBDEVICE_MISMATCH,
        name: "subdevice-mismatch",
        severity: Severity::Error,
        unit: Unit::Hex("product code found (limit: the one configured; 0: none)"),
        meaning: "Bringing the bus up again (`bus-recovering`), the scan found other SubDevices than the configuration's `[[ethercat.subdevice]]` list, in its order: another product at a position (a drive swapped for another model), nothing answering where the list names one, or one more than it names. The text names the position and the SubDevice the configuration names there; the log has the whole sentence, both identities. The bus stays down (nothing is published to servo, no drive can be enabled) and the bus process scans again every second, raising this event again only when what it finds changes, until the right SubDevices are back (`bus-op`). At start-up the same mismatch refuses the configuration.",
    },
    CodeInfo {
        code: code::EMULATED_SYNC0,
        name: "emulated-sync0",
        severity: Severity::Info,
        unit: Unit::Number("SYNC0 events (limit: those without new outputs, 0x1C32:0B)"),
        meaning: "The EtherCAT emulator (`ethercat-emulator --instance`, a cell's bus without hardware), as it stops: how many SYNC0 events an emulated drive on Distributed Clocks took over its life, and how many of them found no new outputs (its 0x1C32:0B). One per drive; the axis is the drive's, the text names its position. A drive that is not on SYNC0 says 0.",
    },
];

/// The description of `code`.
pub fn info(code: u32) -> Option<&'static CodeInfo> {
    CODES.iter().find(|c| c.code == code)
}

/// A fixed-capacity queue of events a cycle fills and its process drains into the events
/// service after the cycle (so the cycle's library code needs no IPC).
#[derive(Clone, Copy, Debug)]
pub struct EventQueue {
    items: [EventV1; EVENT_QUEUE_CAP],
    len: usize,
    /// Events dropped because the queue was full.
    pub dropped: u64,
}

/// Capacity of an [`EventQueue`]: room for one event per axis and kind in a cycle.
pub const EVENT_QUEUE_CAP: usize = 4 * MAX_AXES;

impl Default for EventQueue {
    fn default() -> Self {
        Self {
            items: [EventV1::default(); EVENT_QUEUE_CAP],
            len: 0,
            dropped: 0,
        }
    }
}

impl EventQueue {
    /// Appends `e`; counts it as dropped when full.
    ///
    /// # Real-time
    /// A copy; no allocation.
    pub fn push(&mut self, e: EventV1) {
        if self.len < EVENT_QUEUE_CAP {
            self.items[self.len] = e;
            self.len += 1;
        } else {
            self.dropped += 1;
        }
    }

    /// The queued events, oldest first.
    pub fn as_slice(&self) -> &[EventV1] {
        &self.items[..self.len]
    }

    /// Empties the queue.
    pub fn clear(&mut self) {
        self.len = 0;
    }

    /// True when nothing is queued.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn codes_are_unique_and_described() {
        for (i, c) in CODES.iter().enumerate() {
            assert!(
                CODES[..i]
                    .iter()
                    .all(|d| d.code != c.code && d.name != c.name)
            );
            assert!(!c.meaning.is_empty());
        }
        assert_eq!(
            EventV1::new(0, code::FOLLOWING_ERROR, 0, 1.5, 1.0, &[]).severity,
            Severity::Error as u32
        );
    }

    #[test]
    fn text_is_truncated_on_a_character_boundary() {
        let long = "é".repeat(40);
        let e = EventV1::new(1, code::DRIVE_TRANSITION, 2, 4.0, 0.0, &["x: ", &long]);
        assert!(e.text().starts_with("x: é"));
        assert!(e.text().len() < EVENT_TEXT_LEN);
        assert_eq!(e.text[EVENT_TEXT_LEN - 1], 0);
    }

    #[test]
    fn the_queue_counts_what_it_drops() {
        let mut q = EventQueue::default();
        for k in 0..EVENT_QUEUE_CAP + 3 {
            q.push(EventV1::new(k as u64, code::ENABLED, -1, 0.0, 0.0, &[]));
        }
        assert_eq!((q.as_slice().len(), q.dropped), (EVENT_QUEUE_CAP, 3));
        q.clear();
        assert!(q.is_empty());
    }
}
