//! The cell configuration: one TOML file (or the embedded default), validated whole before
//! anything starts. Every error names the file, line and column and says what is wrong.
//! `docs/config.md` documents every key.

use serde::Deserialize;
use serde_inline_default::serde_inline_default;
use shm_schema::config::MAX_CONFIGURED_FAULTS;
use shm_schema::drive::injected;
use shm_schema::{
    AxisConfigV2, CellConfigV6, ConfiguredFaultV1, EstopReaction, HealthConfigV1, MAX_AXES,
    MAX_PROCESSES, ProcessConfigV2, ProcessName, fixed_str,
};
use std::fmt;
use std::ops::Range;

pub mod ethercat;
pub mod io;
pub mod kinematics;
pub mod modbus;
pub mod network;
mod program;
mod read;
pub mod stability;

pub use program::find_program;

/// The embedded default cell (the Gantry UBA).
pub const DEFAULT_TOML: &str = include_str!("../../examples/gantry-uba.toml");
/// How the embedded default is named in messages.
pub const DEFAULT_NAME: &str = "<embedded default: examples/gantry-uba.toml>";

/// What is wrong with a configuration: every problem found, each where it is.
#[derive(Clone, Debug, PartialEq)]
pub struct ConfigError {
    /// File name as given.
    pub file: String,
    /// At least one, in the file's order.
    pub problems: Vec<Located>,
}

/// One problem and where it is.
#[derive(Clone, Debug, PartialEq)]
pub struct Located {
    /// 1-based line (0 when unknown).
    pub line: usize,
    /// 1-based column (0 when unknown).
    pub col: usize,
    /// What is wrong.
    pub message: String,
}

impl ConfigError {
    /// One problem at a known place (or at none: line 0).
    fn one(file: &str, line: usize, col: usize, message: String) -> Self {
        Self {
            file: file.into(),
            problems: vec![Located { line, col, message }],
        }
    }
}

/// Every problem on its own line: `file:line:col: message`.
impl fmt::Display for ConfigError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (k, p) in self.problems.iter().enumerate() {
            if k > 0 {
                f.write_str("\n")?;
            }
            if p.line > 0 {
                write!(f, "{}:{}:{}: {}", self.file, p.line, p.col, p.message)?;
            } else {
                write!(f, "{}: {}", self.file, p.message)?;
            }
        }
        Ok(())
    }
}

impl std::error::Error for ConfigError {}

/// `[cell]`.
#[derive(Clone, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CellMeta {
    /// Display name.
    #[serde(default)]
    pub name: String,
}

/// `[motion]`.
#[serde_inline_default]
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Motion {
    /// Acceleration time (s).
    pub t_acc: f64,
    /// Time the axes must stay in position to count as settled (s). Default 0.1.
    #[serde_inline_default(0.1)]
    pub settle_time: f64,
    /// Longest wait for settling after the motion (s). Default 5.
    #[serde_inline_default(5.0)]
    pub settle_timeout: f64,
    /// Servo extrapolates a late setpoint this long, then brings the reference to rest (s).
    /// Default 0.05.
    #[serde_inline_default(0.05)]
    pub setpoint_timeout: f64,
    /// On an e-stop, servo brings every axis from its vmax to rest within this time, then
    /// disables the drives (s). Default 0.5.
    #[serde_inline_default(0.5)]
    pub estop_stop_time: f64,
}

/// `[drives]`.
#[serde_inline_default]
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Drives {
    /// Command watchdog of the drives (s): a powered drive without a new command this long
    /// faults (0xFF01).
    pub command_timeout: f64,
    /// Servo cuts power when the drive feedback is older than this (s). Default 0.1.
    #[serde_inline_default(0.1)]
    pub feedback_timeout: f64,
    /// Longest enabling sequence (s). Default 0.5.
    #[serde_inline_default(0.5)]
    pub enable_timeout: f64,
    /// Integration steps of the simulated machine per cycle. Default 4.
    #[serde_inline_default(4)]
    pub substeps: u32,
    /// Faults the simulated drives raise at set times (`[[drives.inject]]`).
    #[serde(default)]
    pub inject: Vec<Inject>,
}

/// A configured fault: `[[drives.inject]]`.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Inject {
    /// Axis name.
    pub axis: String,
    /// `over-current`, `encoder-loss` or `following-error`.
    pub fault: FaultKind,
    /// Time after the axis' drive first reaches Operation enabled (s).
    pub at: f64,
    /// How long the condition lasts (s). Default 0: one drive cycle.
    #[serde(default)]
    pub duration: f64,
}

/// A fault the simulated drives can raise (`[[drives.inject]]`, `supervisor inject`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum FaultKind {
    /// The drive's over-current (CiA 402 error code 0x2310).
    OverCurrent,
    /// The encoder lost (0x7305).
    EncoderLoss,
    /// The drive's own following error (0x8611).
    FollowingError,
}

impl FaultKind {
    /// Every fault, in the order the messages list them.
    pub const ALL: [Self; 3] = [Self::OverCurrent, Self::EncoderLoss, Self::FollowingError];

    /// Its name in the configuration and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Self::OverCurrent => "over-current",
            Self::EncoderLoss => "encoder-loss",
            Self::FollowingError => "following-error",
        }
    }

    /// Its CiA 402 error code.
    pub fn code(self) -> u16 {
        match self {
            Self::OverCurrent => injected::OVER_CURRENT,
            Self::EncoderLoss => injected::ENCODER_LOSS,
            Self::FollowingError => injected::FOLLOWING_ERROR,
        }
    }

    /// The fault called `name`.
    pub fn named(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|f| f.name() == name)
    }

    /// Every name, for messages: `over-current, encoder-loss, following-error`.
    pub fn names() -> String {
        Self::ALL.map(Self::name).join(", ")
    }
}

/// `servo = { ... }` of an axis.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ServoGains {
    /// effort/unit
    pub kp: f64,
    /// effort/(unit·s)
    #[serde(default)]
    pub ki: f64,
    /// effort·s/unit
    #[serde(default)]
    pub kd: f64,
    /// effort·s/unit
    #[serde(default)]
    pub kvff: f64,
    /// effort·s²/unit
    #[serde(default)]
    pub kaff: f64,
    /// effort
    #[serde(default)]
    pub integral_limit: f64,
}

/// `sim = { ... }` of an axis.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SimAxis {
    /// effort·s²/unit
    pub inertia: f64,
    /// effort·s/unit
    #[serde(default)]
    pub viscous: f64,
    /// effort
    #[serde(default)]
    pub coulomb: f64,
    /// effort
    pub effort_limit: f64,
    /// unit/count
    pub encoder_resolution: f64,
}

/// `[[axis]]`.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Axis {
    /// Name (`x`).
    pub name: String,
    /// Unit (`mm`, `deg`).
    pub unit: String,
    /// Lowest position.
    pub min: f64,
    /// Highest position.
    pub max: f64,
    /// Largest velocity (unit/s).
    pub vmax: f64,
    /// Start of the simulated machine.
    pub start: f64,
    /// Following-error limit.
    pub following_error_limit: f64,
    /// In-position band.
    pub in_position: f64,
    /// Settled needs |velocity| at most this (unit/s). Default 10 × `in_position` per s.
    #[serde(default)]
    pub settle_velocity: Option<f64>,
    /// Servo gains.
    pub servo: ServoGains,
    /// Command validation limits (defaults derived from vmax, t_acc and the servo period).
    #[serde(default)]
    pub limits: Limits,
    /// The drive: mode of operation and its own loop.
    #[serde(default)]
    pub drive: DriveSettings,
    /// Simulated mechanics.
    pub sim: SimAxis,
}

impl Axis {
    /// Command validation: largest |commanded velocity| (unit/s).
    pub fn velocity_limit(&self) -> f64 {
        self.limits.velocity.unwrap_or(1.1 * self.vmax)
    }

    /// Command validation: largest position step per servo period (unit).
    pub fn position_step_limit(&self, servo_period_s: f64) -> f64 {
        self.limits
            .position_step
            .unwrap_or(1.5 * self.vmax * servo_period_s)
    }

    /// Command validation: largest velocity step per servo period (unit/s).
    pub fn velocity_step_limit(&self, servo_period_s: f64, t_acc: f64) -> f64 {
        self.limits
            .velocity_step
            .unwrap_or(3.0 * self.vmax / t_acc * servo_period_s)
    }

    /// Deceleration of servo's reference when setpoints stop (unit/s²).
    pub fn stop_deceleration(&self, t_acc: f64) -> f64 {
        self.limits.stop_deceleration.unwrap_or(self.vmax / t_acc)
    }

    /// The drive's quick-stop deceleration (unit/s²).
    pub fn quick_stop_deceleration(&self, t_acc: f64) -> f64 {
        self.drive
            .quick_stop_deceleration
            .unwrap_or(4.0 * self.vmax / t_acc)
    }

    /// Settled needs |velocity| at most this (unit/s).
    pub fn settle_velocity(&self) -> f64 {
        self.settle_velocity.unwrap_or(10.0 * self.in_position)
    }
}

/// `limits = { ... }` of an axis: command validation (seed 001's `LLI_set` rule). Each
/// omitted key takes the default documented in `docs/drives.md`.
#[derive(Clone, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Limits {
    /// Largest |commanded velocity| (unit/s). Default 1.1 × vmax.
    pub velocity: Option<f64>,
    /// Largest position step per servo period (unit). Default 1.5 × vmax × period.
    pub position_step: Option<f64>,
    /// Largest velocity step per servo period (unit/s). Default 3 × vmax / t_acc × period.
    pub velocity_step: Option<f64>,
    /// Deceleration of the reference when setpoints stop (unit/s²). Default vmax / t_acc.
    pub stop_deceleration: Option<f64>,
}

/// `drive = { ... }` of an axis.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DriveSettings {
    /// `"cst"` (servo closes the position loop; default), `"csp"` (the drive does) or `"csv"`.
    pub mode: DriveMode,
    /// The drive's position gain (CSP; effort/unit).
    pub kp: f64,
    /// The drive's integral gain (CSP, CSV).
    pub ki: f64,
    /// The drive's velocity gain (CSP, CSV; effort·s/unit).
    pub kd: f64,
    /// Quick stop option code (0x605A): 0, 1, 2 (default) or 6.
    pub quick_stop_option: i32,
    /// Quick-stop deceleration (0x6085; unit/s²). Default 4 × vmax / t_acc.
    pub quick_stop_deceleration: Option<f64>,
}

impl Default for DriveSettings {
    fn default() -> Self {
        Self {
            mode: DriveMode::Cst,
            kp: 0.0,
            ki: 0.0,
            kd: 0.0,
            quick_stop_option: 2,
            quick_stop_deceleration: None,
        }
    }
}

/// Who closes an axis' position loop: its CiA 402 mode of operation.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum DriveMode {
    /// Cyclic synchronous torque: servo closes the loop.
    Cst,
    /// Cyclic synchronous position: the drive closes it with its own gains.
    Csp,
    /// Cyclic synchronous velocity: servo closes the position loop, the drive the velocity's.
    Csv,
}

impl DriveMode {
    /// Its name in the configuration.
    pub fn name(self) -> &'static str {
        match self {
            Self::Cst => "cst",
            Self::Csp => "csp",
            Self::Csv => "csv",
        }
    }
}

impl From<DriveMode> for cia402::Mode {
    fn from(m: DriveMode) -> Self {
        match m {
            DriveMode::Cst => Self::Cst,
            DriveMode::Csp => Self::Csp,
            DriveMode::Csv => Self::Csv,
        }
    }
}

/// The processes the cell needs by name: their services carry the cell's data (the others
/// of a table are the user's own).
pub const REQUIRED_PROCESSES: [&str; 3] = ["drives", "servo", "trajgen"];

/// What the supervisor does when a process dies (`restart`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum RestartPolicy {
    /// Leave it dead: the e-stop stays until `supervisor restart` and `reset`.
    Never,
    /// Start it again after a back-off (doubling from `[supervisor] restart_backoff`), at most
    /// `restart_limit` times in a row.
    OnFailure,
}

/// One `[[process]]` entry.
#[serde_inline_default]
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Process {
    /// Its name: a lower-case letter, then up to 14 of `[a-z0-9_-]`.
    pub name: String,
    /// Program and arguments; `{instance}` and `{name}` are replaced.
    pub command: Vec<String>,
    /// Cycle period (µs).
    pub period_us: u64,
    /// Deadline offset within the period (µs). Default 0.
    #[serde(default)]
    pub phase_us: u64,
    /// `SCHED_FIFO` priority, 0 for `SCHED_OTHER`.
    pub priority: i32,
    /// CPU to pin to. Default: none.
    #[serde(default)]
    pub cpu: Option<i32>,
    /// `"never"` or `"on-failure"` (default).
    #[serde_inline_default(RestartPolicy::OnFailure)]
    pub restart: RestartPolicy,
    /// Its reaction to an e-stop it did not raise (seed 002): `"stop"` (default), `"hold"`,
    /// `"ignore"`.
    #[serde(default)]
    pub network_estop_config: Reaction,
    /// Whether the cell's safety depends on it (default true). `false`: its loss, stall or
    /// health detectors are warnings and restarts, never an e-stop (a fieldbus server for an
    /// HMI, a logger). drives, servo and trajgen are always critical.
    #[serde_inline_default(true)]
    pub critical: bool,
}

/// A process' reaction to an e-stop it did not raise (seed 002's `network_estop_config`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Reaction {
    /// Bring its part to rest and make it safe (servo: rest, then disable).
    #[default]
    Stop,
    /// Bring its part to rest and stay enabled.
    Hold,
    /// Go on.
    Ignore,
}

impl From<Reaction> for EstopReaction {
    fn from(r: Reaction) -> Self {
        match r {
            Reaction::Stop => Self::Stop,
            Reaction::Hold => Self::Hold,
            Reaction::Ignore => Self::Ignore,
        }
    }
}

impl Process {
    /// The period (s).
    pub fn period_s(&self) -> f64 {
        self.period_us as f64 * 1e-6
    }
}

/// `[behaviour]`: seed 002's e-stop propagation.
#[derive(Clone, Copy, Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Behaviour {
    /// A process' own e-stop is propagated to every process. Default true.
    pub propagate_estop: bool,
    /// A user's e-stop (`supervisor estop`, an e-stop input) is propagated even when
    /// `propagate_estop` is false. Default false.
    pub propagate_external_estop: bool,
}

impl Default for Behaviour {
    fn default() -> Self {
        Self {
            propagate_estop: true,
            propagate_external_estop: false,
        }
    }
}

/// Declares `[health_config]` from one list: each key with its meaning, its default and the
/// largest value it may take; its `Default`, its range check and its shared-memory form
/// (`HealthConfigV1`, whose fields have the keys' names) follow from the list.
macro_rules! health_settings {
    ($( $(#[doc = $doc:literal])* $key:ident: default $default:literal, at most $max:literal; )*) => {
        /// `[health_config]`: seed 002's detectors, with the seed's keys and defaults.
        #[derive(Clone, Copy, Debug, Deserialize)]
        #[serde(deny_unknown_fields, default)]
        pub struct HealthSettings {
            $( $(#[doc = $doc])* pub $key: f64, )*
        }

        impl Default for HealthSettings {
            fn default() -> Self {
                Self { $( $key: $default, )* }
            }
        }

        impl HealthSettings {
            /// Each key, its value and the largest value it may take (the least is 0).
            fn entries(&self) -> Vec<(&'static str, f64, f64)> {
                vec![ $( (stringify!($key), self.$key, $max), )* ]
            }

            fn to_shm(self) -> HealthConfigV1 {
                HealthConfigV1 { $( $key: self.$key, )* }
            }
        }
    };
}

// A stall's skipped periods count at once when it ends: above 100 % a detector forgives a
// stall longer than a second, so the two rates that see stalls may go to 1000 %.
health_settings! {
    /// % of the process' rate.
    pending_sequence_overrun_percent_limit: default 1.0, at most 1000.0;
    /// s.
    pending_sequence_overrun_leak_time_s: default 0.25, at most 3600.0;
    /// s.
    pending_sequence_overrun_start_snooze_s: default 1.0, at most 3600.0;
    /// % of the process' rate.
    transport_overrun_percent_limit: default 0.5, at most 100.0;
    /// s.
    transport_overrun_leak_time_s: default 0.25, at most 3600.0;
    /// % of the period.
    thread_offset_variance_percent: default 1.0, at most 1000.0;
    /// % of the process' rate.
    thread_offset_variance_overrun_percent_limit: default 5.0, at most 100.0;
    /// s.
    thread_offset_variance_overrun_leak_time_s: default 0.25, at most 3600.0;
    /// s.
    thread_offset_variance_start_snooze_s: default 2.0, at most 3600.0;
}

/// `[supervisor]`.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SupervisorSettings {
    /// Longest a process may take to start (s). Default 10.
    pub startup_timeout: f64,
    /// A process whose cycle count does not advance this long is stalled (s). Default 1.
    pub heartbeat_timeout: f64,
    /// Longest a process may take to stop after SIGTERM before SIGKILL (s). Default 3.
    pub stop_timeout: f64,
    /// A process that has not seen the supervisor's heartbeat this long brings the axes to
    /// rest and exits (s). Default 0.5.
    pub supervisor_timeout: f64,
    /// Wait before the first restart of a process; doubles with each restart in a row (s).
    /// Default 0.5.
    pub restart_backoff: f64,
    /// Restarts in a row after which a process is left dead. Default 3.
    pub restart_limit: u32,
    /// `SCHED_FIFO` priority of the supervisor's loop, which publishes the heartbeat; below
    /// every real-time process of the table; 0 for `SCHED_OTHER`. Default 10.
    pub priority: i32,
}

impl Default for SupervisorSettings {
    fn default() -> Self {
        Self {
            startup_timeout: 10.0,
            heartbeat_timeout: 1.0,
            stop_timeout: 3.0,
            supervisor_timeout: 0.5,
            restart_backoff: 0.5,
            restart_limit: 3,
            priority: 10,
        }
    }
}

/// A whole, validated cell configuration.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Config {
    /// `[cell]`
    #[serde(default)]
    pub cell: CellMeta,
    /// `[motion]`
    pub motion: Motion,
    /// `[drives]`
    pub drives: Drives,
    /// `[[axis]]`
    pub axis: Vec<Axis>,
    /// `[[process]]`, in start order.
    pub process: Vec<Process>,
    /// `[behaviour]`
    #[serde(default)]
    pub behaviour: Behaviour,
    /// `[health_config]`
    #[serde(default)]
    pub health_config: HealthSettings,
    /// `[supervisor]`
    #[serde(default)]
    pub supervisor: SupervisorSettings,
    /// `[[io]]`: the named digital IO.
    #[serde(default)]
    pub io: Vec<io::Io>,
    /// `[kinematics]`: the gantry unless given.
    #[serde(default)]
    pub kinematics: kinematics::KinematicsSettings,
    /// `[modbus]`: the Modbus TCP server's settings (served by the `modbus` process).
    #[serde(default)]
    pub modbus: modbus::ModbusSettings,
    /// `[ethercat]`: the cell's EtherCAT bus, when its drives are real (or emulated) ones.
    #[serde(default)]
    pub ethercat: Option<ethercat::EthercatSettings>,
    /// `[network]`: the cell on a line of cells (served by the `gateway` process); none, off
    /// the network.
    #[serde(default)]
    pub network: Option<network::NetworkSettings>,
}

/// One step of a key path, to find where a value is written.
#[derive(Clone, Copy, Debug)]
enum Seg {
    Key(&'static str),
    Index(usize),
}

fn locate(src: &str, path: &[Seg]) -> Option<Range<usize>> {
    let doc = toml_edit::Document::parse(src).ok()?;
    let mut table: &dyn toml_edit::TableLike = doc.as_table();
    let mut span = None;
    let mut segs = path.iter().peekable();
    while let Some(seg) = segs.next() {
        let Seg::Key(k) = *seg else { break };
        let Some((key, item)) = table.get_key_value(k) else {
            break;
        };
        // The key's own place is the most telling; fall back to its value's.
        span = key.span().or_else(|| item.span()).or(span);
        match segs.peek() {
            Some(Seg::Index(i)) => {
                segs.next();
                let Some(t) = item.as_array_of_tables().and_then(|a| a.get(*i)) else {
                    break;
                };
                span = t.span().or(span);
                table = t;
            }
            Some(Seg::Key(_)) => match item.as_table_like() {
                Some(t) => table = t,
                None => break,
            },
            None => {}
        }
    }
    span
}

/// The key path of axis `i`'s keys.
#[derive(Clone, Copy)]
struct AxisAt(usize);

impl AxisAt {
    /// `axis[i].k`.
    fn key(self, k: &'static str) -> Vec<Seg> {
        vec![Seg::Key("axis"), Seg::Index(self.0), Seg::Key(k)]
    }

    /// `axis[i].table.k`.
    fn sub(self, table: &'static str, k: &'static str) -> Vec<Seg> {
        vec![
            Seg::Key("axis"),
            Seg::Index(self.0),
            Seg::Key(table),
            Seg::Key(k),
        ]
    }
}

/// An axis' range (min below max, the start within) and its positive figures (vmax, the
/// following-error limit, the in-position band, narrower than the limit).
fn axis_range(a: &Axis, at: AxisAt) -> Result<(), Problem> {
    if !(a.min.is_finite() && a.max.is_finite() && a.min < a.max) {
        return Err((
            at.key("max"),
            format!(
                "axis {}: max ({}) must be greater than min ({})",
                a.name, a.max, a.min
            ),
        ));
    }
    if !(a.start >= a.min && a.start <= a.max) {
        return Err((
            at.key("start"),
            format!(
                "axis {}: start {} lies outside {} .. {}",
                a.name, a.start, a.min, a.max
            ),
        ));
    }
    for (k, v) in [
        ("vmax", a.vmax),
        ("following_error_limit", a.following_error_limit),
        ("in_position", a.in_position),
    ] {
        if !positive(v) {
            return Err((
                at.key(k),
                format!("axis {}: {k} = {v} must be positive", a.name),
            ));
        }
    }
    if a.in_position >= a.following_error_limit {
        return Err((
            at.key("in_position"),
            format!(
                "axis {}: in_position must be smaller than following_error_limit",
                a.name
            ),
        ));
    }
    if let Some(v) = a.settle_velocity
        && !positive(v)
    {
        return Err((
            at.key("settle_velocity"),
            format!("axis {}: settle_velocity = {v} must be positive", a.name),
        ));
    }
    Ok(())
}

/// An axis' servo gains: 0 or more.
fn axis_gains(a: &Axis, at: AxisAt) -> Result<(), Problem> {
    let g = &a.servo;
    bounded(
        a,
        at,
        "servo",
        &[
            ("kp", g.kp, false),
            ("ki", g.ki, false),
            ("kd", g.kd, false),
            ("kvff", g.kvff, false),
            ("kaff", g.kaff, false),
            ("integral_limit", g.integral_limit, false),
        ],
    )
}

/// An axis' simulated mechanics: inertia, effort limit and encoder resolution positive,
/// friction 0 or more.
fn axis_model(a: &Axis, at: AxisAt) -> Result<(), Problem> {
    let s = &a.sim;
    bounded(
        a,
        at,
        "sim",
        &[
            ("inertia", s.inertia, true),
            ("viscous", s.viscous, false),
            ("coulomb", s.coulomb, false),
            ("effort_limit", s.effort_limit, true),
            ("encoder_resolution", s.encoder_resolution, true),
        ],
    )
}

/// The first of `values` of an axis' table out of its bound: positive (`true`) or 0 or more.
fn bounded(
    a: &Axis,
    at: AxisAt,
    table: &'static str,
    values: &[(&'static str, f64, bool)],
) -> Result<(), Problem> {
    for &(k, v, pos) in values {
        if !(if pos { positive(v) } else { non_negative(v) }) {
            let need = if pos { "positive" } else { "0 or more" };
            return Err((
                at.sub(table, k),
                format!("axis {}: {table} {k} = {v} must be {need}", a.name),
            ));
        }
    }
    Ok(())
}

/// An axis' drive: a quick stop option CiA 402 has, its gains 0 or more, a velocity gain for
/// the modes in which the drive closes a loop.
fn axis_drive(a: &Axis, at: AxisAt) -> Result<(), Problem> {
    let d = &a.drive;
    if cia402::QuickStopOption::from_i16(d.quick_stop_option as i16).is_none()
        || !(0..=8).contains(&d.quick_stop_option)
    {
        return Err((
            at.sub("drive", "quick_stop_option"),
            format!(
                "axis {}: drive quick_stop_option = {} must be 0, 1, 2 or 6",
                a.name, d.quick_stop_option
            ),
        ));
    }
    bounded(
        a,
        at,
        "drive",
        &[
            ("kp", d.kp, false),
            ("ki", d.ki, false),
            ("kd", d.kd, false),
        ],
    )?;
    if d.mode != DriveMode::Cst && d.kd <= 0.0 {
        return Err((
            at.sub("drive", "kd"),
            format!(
                "axis {}: drive mode {} needs the drive's own velocity gain kd > 0",
                a.name,
                d.mode.name()
            ),
        ));
    }
    Ok(())
}

/// A problem found by validation: the key path where it is, and what is wrong.
type Problem = (Vec<Seg>, String);

fn positive(v: f64) -> bool {
    v.is_finite() && v > 0.0
}

fn non_negative(v: f64) -> bool {
    v.is_finite() && v >= 0.0
}

/// `problems` (at least one) placed in `src`, in the file's order.
fn located(src: &str, file: &str, problems: Vec<Problem>) -> ConfigError {
    let mut problems: Vec<Located> = problems
        .into_iter()
        .map(|(path, message)| {
            let (line, col) = locate(src, &path).map_or((0, 0), |s| line_col(src, s.start));
            Located { line, col, message }
        })
        .collect();
    problems.sort_by_key(|p| (p.line, p.col));
    ConfigError {
        file: file.into(),
        problems,
    }
}

fn line_col(src: &str, offset: usize) -> (usize, usize) {
    let before = &src[..offset.min(src.len())];
    let line = before.matches('\n').count() + 1;
    let col = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
    (line, col)
}

impl Config {
    /// What the motion language may name on this cell: its coordinates, joints and named IO.
    pub fn cell_spec(&self) -> motion_program::CellSpec {
        let named = |dir: io::Direction| -> Vec<(String, u32)> {
            self.io
                .iter()
                .enumerate()
                .filter(|(_, e)| e.direction == dir)
                .map(|(k, e)| (e.name.clone(), k as u32))
                .collect()
        };
        motion_program::CellSpec {
            coords: self.kinematics.coords(&self.axis),
            joints: self
                .axis
                .iter()
                .map(|a| (a.name.clone(), a.unit.clone()))
                .collect(),
            outputs: named(io::Direction::Output),
            inputs: named(io::Direction::Input),
        }
    }

    /// Parses and validates `src` (named `file` in messages), and checks that every process'
    /// program can be started (what `run`, `up` and `check-config` load).
    pub fn parse_and_find_programs(src: &str, file: &str) -> Result<Self, ConfigError> {
        let cfg = Self::parse(src, file)?;
        let missing: Vec<Problem> = cfg
            .process
            .iter()
            .enumerate()
            .filter_map(|(j, p)| {
                let why = find_program(&p.command[0]).err()?;
                let path = vec![Seg::Key("process"), Seg::Index(j), Seg::Key("command")];
                Some((path, format!("process {}: {why}", p.name)))
            })
            .collect();
        if missing.is_empty() {
            Ok(cfg)
        } else {
            Err(located(src, file, missing))
        }
    }

    /// Parses and validates `src` (named `file` in messages).
    pub fn parse(src: &str, file: &str) -> Result<Self, ConfigError> {
        let cfg: Config = read::read(src).map_err(|problems| {
            let mut problems: Vec<Located> = problems
                .into_iter()
                .map(|p| {
                    let (line, col) = p.span.map_or((0, 0), |s| line_col(src, s.start));
                    Located {
                        line,
                        col,
                        message: p.message,
                    }
                })
                .collect();
            problems.sort_by_key(|p| (p.line, p.col));
            ConfigError {
                file: file.into(),
                problems,
            }
        })?;
        let problems = cfg.validate();
        if problems.is_empty() {
            Ok(cfg)
        } else {
            Err(located(src, file, problems))
        }
    }

    /// The embedded default.
    pub fn default_cell() -> Self {
        Self::parse(DEFAULT_TOML, DEFAULT_NAME)
            .expect("the embedded default configuration is valid")
    }

    /// Loads `path`, or the embedded default for `None`, and checks that every process'
    /// program can be started.
    pub fn load(path: Option<&std::path::Path>) -> Result<Self, ConfigError> {
        match path {
            None => Self::parse_and_find_programs(DEFAULT_TOML, DEFAULT_NAME),
            Some(p) => {
                let file = p.display().to_string();
                let src = std::fs::read_to_string(p)
                    .map_err(|e| ConfigError::one(&file, 0, 0, format!("cannot read: {e}")))?;
                Self::parse_and_find_programs(&src, &file)
            }
        }
    }

    /// Every problem of the configuration, each at its key path: the sections and the entries
    /// are checked independently (an entry stops at its first problem, an axis at the first
    /// of each of its parts), and what depends on the process table (the periods) only once
    /// the table is sound.
    fn validate(&self) -> Vec<Problem> {
        let mut found: Vec<Problem> = Vec::new();
        found.extend(self.validate_motion());
        found.extend(io::validate(&self.io));
        found.extend(kinematics::validate(&self.kinematics, &self.axis));
        found.extend(modbus::validate(&self.modbus));
        match &self.ethercat {
            Some(bus) => {
                let drives_period = self.process_named("drives").map(Process::period_s);
                found.extend(ethercat::validate(bus, &self.axis, &self.io, drives_period));
            }
            None => found.extend(ethercat::io_without_bus(&self.io)),
        }
        let gateway = self.process_named("gateway").is_some();
        match &self.network {
            Some(n) => {
                let axes: Vec<_> = (self.axis.iter())
                    .map(|a| (a.name.as_str(), a.unit.as_str()))
                    .collect();
                found.extend(network::validate(n, &self.cell.name, &axes, gateway));
            }
            None if gateway => found.push((
                vec![Seg::Key("process")],
                "a process named \"gateway\" serves [network], which the cell does not have".into(),
            )),
            None => {}
        }
        let table = self.validate_processes();
        let table_sound = table.is_empty();
        found.extend(table);
        if table_sound {
            found.extend(self.validate_periods().err());
        }
        found.extend(self.validate_inject());
        if self.axis.is_empty() || self.axis.len() > MAX_AXES {
            found.push((
                vec![Seg::Key("axis")],
                format!(
                    "the cell has {} axes; 1..={MAX_AXES} allowed",
                    self.axis.len()
                ),
            ));
        } else {
            for i in 0..self.axis.len() {
                found.extend(self.validate_axis(i, table_sound));
            }
        }
        found.extend(self.validate_supervisor());
        found
    }

    /// `[motion]` on its own: each key's problem, all of them.
    fn validate_motion(&self) -> Vec<Problem> {
        use Seg::Key as K;
        let m = &self.motion;
        let at = |k: &'static str| vec![K("motion"), K(k)];
        let mut found = Vec::new();
        if !positive(m.t_acc) {
            found.push((
                at("t_acc"),
                format!("t_acc = {} s must be positive", m.t_acc),
            ));
        }
        if !non_negative(m.settle_time) {
            found.push((at("settle_time"), "settle_time must be 0 s or more".into()));
        }
        if !(m.estop_stop_time.is_finite() && (0.01..=60.0).contains(&m.estop_stop_time)) {
            found.push((
                at("estop_stop_time"),
                format!(
                    "estop_stop_time = {} s must be 0.01..=60 s",
                    m.estop_stop_time
                ),
            ));
        }
        if !positive(m.settle_timeout) {
            found.push((
                at("settle_timeout"),
                "settle_timeout must be positive".into(),
            ));
        }
        found
    }

    /// What the processes' periods bound: the setpoint timeout, `[drives]`' timeouts and
    /// sub-steps.
    fn validate_periods(&self) -> Result<(), Problem> {
        use Seg::Key as K;
        let m = &self.motion;
        let trajgen_period_s = self.period_s("trajgen");
        if !(m.setpoint_timeout.is_finite() && m.setpoint_timeout >= 2.0 * trajgen_period_s) {
            return Err((
                vec![K("motion"), K("setpoint_timeout")],
                format!(
                    "setpoint_timeout = {} s must be at least 2 trajgen periods ({} s)",
                    m.setpoint_timeout,
                    2.0 * trajgen_period_s
                ),
            ));
        }
        let servo_period_s = self.period_s("servo");
        let d = &self.drives;
        if !(d.command_timeout.is_finite() && d.command_timeout >= 3.0 * servo_period_s) {
            return Err((
                vec![K("drives"), K("command_timeout")],
                format!(
                    "command_timeout = {} s must be at least 3 servo periods ({} s)",
                    d.command_timeout,
                    3.0 * servo_period_s
                ),
            ));
        }
        if !(1..=1000).contains(&d.substeps) {
            return Err((
                vec![K("drives"), K("substeps")],
                "substeps must be 1..=1000".into(),
            ));
        }
        let machine_period_s = self.period_s("drives");
        for (k, v, min) in [
            (
                "feedback_timeout",
                d.feedback_timeout,
                3.0 * machine_period_s,
            ),
            ("enable_timeout", d.enable_timeout, 5.0 * servo_period_s),
        ] {
            if !(v.is_finite() && v >= min) {
                return Err((
                    vec![K("drives"), K(k)],
                    format!("{k} = {v} s must be at least {min} s"),
                ));
            }
        }
        Ok(())
    }

    /// `[[drives.inject]]`: each configured fault names an axis and a fault.
    fn validate_inject(&self) -> Vec<Problem> {
        use Seg::{Index as Idx, Key as K};
        let inject = &self.drives.inject;
        if inject.len() > MAX_CONFIGURED_FAULTS {
            return vec![(
                vec![K("drives"), K("inject")],
                format!(
                    "{} configured faults; at most {MAX_CONFIGURED_FAULTS}",
                    inject.len()
                ),
            )];
        }
        let mut found = Vec::new();
        for (j, f) in inject.iter().enumerate() {
            let at = |k: &'static str| vec![K("drives"), K("inject"), Idx(j), K(k)];
            if !self.axis.iter().any(|a| a.name == f.axis) {
                found.push((at("axis"), format!("inject: there is no axis {:?}", f.axis)));
            } else if !(non_negative(f.at) && non_negative(f.duration) && f.at + f.duration <= 1e6)
            {
                found.push((
                    at("at"),
                    "inject: at and duration must be 0 s or more, together at most 1e6 s".into(),
                ));
            }
        }
        found
    }

    /// Axis `i`: every problem of its name, range, gains, model and drive (each part stops at
    /// its first: a later check of a part depends on the earlier ones); then, with `periods`
    /// (the process table is sound) and only if none was found (they derive from all of it),
    /// what the servo period bounds and the loop's stability.
    fn validate_axis(&self, i: usize, periods: bool) -> Vec<Problem> {
        let a = &self.axis[i];
        let at = AxisAt(i);
        let found: Vec<Problem> = [
            self.axis_name(i, at),
            axis_range(a, at),
            axis_gains(a, at),
            axis_model(a, at),
            axis_drive(a, at),
        ]
        .into_iter()
        .filter_map(Result::err)
        .collect();
        if !found.is_empty() || !periods {
            return found;
        }
        self.axis_limits(a, at).err().into_iter().collect()
    }

    /// An axis' name (unique) and unit.
    fn axis_name(&self, i: usize, at: AxisAt) -> Result<(), Problem> {
        let a = &self.axis[i];
        let valid = |c: char| c.is_ascii_alphanumeric() || c == '_';
        if a.name.is_empty() || a.name.len() > 15 || !a.name.chars().all(valid) {
            return Err((
                at.key("name"),
                format!(
                    "axis name {:?} must be 1 to 15 letters, digits or '_'",
                    a.name
                ),
            ));
        }
        if self.axis[..i].iter().any(|b| b.name == a.name) {
            return Err((
                at.key("name"),
                format!("axis name {:?} is used twice", a.name),
            ));
        }
        if a.unit.is_empty() || a.unit.len() > 7 {
            return Err((
                at.key("unit"),
                format!("unit {:?} must be 1 to 7 bytes", a.unit),
            ));
        }
        Ok(())
    }

    /// What the servo period and t_acc make of an axis' limits (each must be positive, the
    /// velocity limit at least vmax, a stop within the velocity step), and the stability of
    /// its loop at the servo period.
    fn axis_limits(&self, a: &Axis, at: AxisAt) -> Result<(), Problem> {
        let servo_period_s = self.period_s("servo");
        let t_acc = self.motion.t_acc;
        if !positive(t_acc) {
            return Ok(()); // [motion] says so; the limits derive from it
        }
        for (k, v) in [
            ("velocity", a.velocity_limit()),
            ("position_step", a.position_step_limit(servo_period_s)),
            (
                "velocity_step",
                a.velocity_step_limit(servo_period_s, t_acc),
            ),
            ("stop_deceleration", a.stop_deceleration(t_acc)),
        ] {
            if !positive(v) {
                return Err((
                    at.sub("limits", k),
                    format!("axis {}: limits {k} = {v} must be positive", a.name),
                ));
            }
        }
        if a.velocity_limit() < a.vmax {
            return Err((
                at.sub("limits", "velocity"),
                format!(
                    "axis {}: limits velocity = {} is below vmax = {}: every move would be refused",
                    a.name,
                    a.velocity_limit(),
                    a.vmax
                ),
            ));
        }
        if a.stop_deceleration(t_acc) * servo_period_s
            > a.velocity_step_limit(servo_period_s, t_acc)
        {
            return Err((
                at.sub("limits", "stop_deceleration"),
                format!(
                    "axis {}: stop_deceleration = {} changes the velocity by more than limits velocity_step = {} per servo period: coming to rest would cut power",
                    a.name,
                    a.stop_deceleration(t_acc),
                    a.velocity_step_limit(servo_period_s, t_acc)
                ),
            ));
        }
        if !positive(a.quick_stop_deceleration(t_acc)) {
            return Err((
                at.sub("drive", "quick_stop_deceleration"),
                format!(
                    "axis {}: drive quick_stop_deceleration must be positive",
                    a.name
                ),
            ));
        }
        let machine_step_s = self.period_s("drives") / self.drives.substeps.max(1) as f64;
        stability::check(a, a.drive.mode.into(), servo_period_s, machine_step_s)
            .map_err(|why| (at.sub("sim", "inertia"), why))
    }

    /// `[supervisor]` and `[health_config]`: each value within its range.
    fn validate_supervisor(&self) -> Vec<Problem> {
        use Seg::Key as K;
        let mut found = Vec::new();
        let s = &self.supervisor;
        for (k, v, lo, hi) in [
            ("startup_timeout", s.startup_timeout, 0.1, 600.0),
            ("heartbeat_timeout", s.heartbeat_timeout, 0.01, 60.0),
            ("stop_timeout", s.stop_timeout, 0.1, 60.0),
            ("supervisor_timeout", s.supervisor_timeout, 0.05, 60.0),
            ("restart_backoff", s.restart_backoff, 0.0, 60.0),
        ] {
            if !(v.is_finite() && (lo..=hi).contains(&v)) {
                found.push((
                    vec![K("supervisor"), K(k)],
                    format!("{k} = {v} s must be {lo}..={hi} s"),
                ));
            }
        }
        if s.restart_limit > 1000 {
            found.push((
                vec![K("supervisor"), K("restart_limit")],
                format!("restart_limit = {} must be 0..=1000", s.restart_limit),
            ));
        }
        if !(0..=99).contains(&s.priority) {
            found.push((
                vec![K("supervisor"), K("priority")],
                format!("priority = {} must be 0..=99 (0: SCHED_OTHER)", s.priority),
            ));
        } else if s.priority > 0
            && let Some(p) = self
                .process
                .iter()
                .filter(|p| p.priority > 0)
                .min_by_key(|p| p.priority)
            && p.priority <= s.priority
        {
            // At or above a process's priority, the loop's work (a request, a report) would
            // delay that process's cycle.
            found.push((
                vec![K("supervisor"), K("priority")],
                format!(
                    "priority = {} must be below every real-time process's: process {} has {}",
                    s.priority, p.name, p.priority
                ),
            ));
        }
        for (k, v, hi) in self.health_config.entries() {
            if !(v.is_finite() && v >= 0.0 && v <= hi) {
                found.push((
                    vec![K("health_config"), K(k)],
                    format!("{k} = {v} must be 0..={hi}"),
                ));
            }
        }
        found
    }

    /// The period of the process called `name` (s); one of [`REQUIRED_PROCESSES`] always is.
    pub fn period_s(&self, name: &str) -> f64 {
        self.process_named(name).map_or(1e-3, Process::period_s)
    }

    /// The `[[process]]` entry called `name`.
    pub fn process_named(&self, name: &str) -> Option<&Process> {
        self.process.iter().find(|p| p.name == name)
    }

    /// The process table: its size, each entry (name, command, period, priority, CPU), the
    /// processes the cell needs.
    fn validate_processes(&self) -> Vec<Problem> {
        use Seg::{Index as Idx, Key as K};
        if self.process.is_empty() || self.process.len() > MAX_PROCESSES {
            return vec![(
                vec![K("process")],
                format!(
                    "the cell has {} processes; 1..={MAX_PROCESSES} allowed",
                    self.process.len()
                ),
            )];
        }
        let mut found: Vec<Problem> = (0..self.process.len())
            .filter_map(|j| self.validate_process(j).err())
            .collect();
        if let Some(k) = self.process.iter().position(|p| p.name == "machine") {
            found.push((
                vec![K("process"), Idx(k), K("name")],
                "the drives' process is called \"drives\" (it was \"machine\"): rename this entry"
                    .to_string(),
            ));
        }
        for required in REQUIRED_PROCESSES {
            if self.process_named(required).is_none() {
                found.push((
                    vec![K("process")],
                    format!(
                        "the cell needs a process called {required:?} (its services carry the cell's data)"
                    ),
                ));
            }
        }
        found
    }

    /// Process `j` of the table.
    fn validate_process(&self, j: usize) -> Result<(), Problem> {
        use Seg::{Index as Idx, Key as K};
        let p = &self.process[j];
        let at = |k: &'static str| vec![K("process"), Idx(j), K(k)];
        let name = &p.name;
        if let Err(e) = ProcessName::new(name) {
            return Err((at("name"), format!("process name {name:?}: {e}")));
        }
        if self.process[..j].iter().any(|q| q.name == *name) {
            return Err((at("name"), format!("process name {name:?} is used twice")));
        }
        if !p.critical && REQUIRED_PROCESSES.contains(&name.as_str()) {
            return Err((
                at("critical"),
                format!(
                    "process {name}: critical = false is not allowed (the cell's motion depends on it)"
                ),
            ));
        }
        if p.command.is_empty() || p.command[0].is_empty() {
            return Err((at("command"), format!("process {name}: command is empty")));
        }
        if !(50..=1_000_000).contains(&p.period_us) {
            return Err((
                at("period_us"),
                format!(
                    "process {name}: period_us = {} must be 50..=1000000",
                    p.period_us
                ),
            ));
        }
        if p.phase_us >= p.period_us {
            return Err((
                at("phase_us"),
                format!("process {name}: phase_us must be smaller than period_us"),
            ));
        }
        if !(0..=99).contains(&p.priority) {
            return Err((
                at("priority"),
                format!(
                    "process {name}: priority {} must be 0..=99 (0: SCHED_OTHER)",
                    p.priority
                ),
            ));
        }
        let cpus = std::thread::available_parallelism().map_or(1, |n| n.get()) as i32;
        if let Some(cpu) = p.cpu
            && !(0..cpus).contains(&cpu)
        {
            return Err((
                at("cpu"),
                format!(
                    "process {name}: cpu {cpu} does not exist (this machine has CPUs 0..{})",
                    cpus - 1
                ),
            ));
        }
        Ok(())
    }

    /// The configuration as every process reads it from shared memory.
    pub fn to_shm(&self) -> CellConfigV6 {
        let ns = |s: f64| (s * 1e9) as u64;
        let mut c = CellConfigV6 {
            axes: self.axis.len() as u32,
            machine_substeps: self.drives.substeps,
            t_acc_s: self.motion.t_acc,
            drive_command_timeout_ns: ns(self.drives.command_timeout),
            setpoint_timeout_ns: ns(self.motion.setpoint_timeout),
            feedback_timeout_ns: ns(self.drives.feedback_timeout),
            enable_timeout_ns: ns(self.drives.enable_timeout),
            settle_time_ns: ns(self.motion.settle_time),
            estop_stop_time_ns: ns(self.motion.estop_stop_time),
            supervisor_timeout_ns: ns(self.supervisor.supervisor_timeout),
            propagate_estop: u32::from(self.behaviour.propagate_estop),
            propagate_external_estop: u32::from(self.behaviour.propagate_external_estop),
            process_count: self.process.len() as u32,
            reserved: 0,
            health: self.health_config.to_shm(),
            process: [ProcessConfigV2::default(); MAX_PROCESSES],
            axis: [AxisConfigV2::default(); MAX_AXES],
            inject: [ConfiguredFaultV1::default(); MAX_CONFIGURED_FAULTS],
            io_count: self.io.len() as u32,
            reserved2: 0,
            io: io::to_shm(&self.io),
            kinematics: self.kinematics.to_shm(&self.axis),
            modbus: self.modbus.to_shm(),
        };
        for (j, f) in self.drives.inject.iter().enumerate() {
            c.inject[j] = ConfiguredFaultV1 {
                at_ns: ns(f.at),
                duration_ns: ns(f.duration),
                axis: self.axis.iter().position(|a| a.name == f.axis).unwrap_or(0) as u32,
                code: u32::from(f.fault.code()),
            };
        }
        let servo_period_s = self.period_s("servo");
        let t_acc = self.motion.t_acc;
        for (j, p) in self.process.iter().enumerate() {
            c.process[j] = ProcessConfigV2 {
                name: fixed_str(&p.name),
                period_ns: p.period_us * 1000,
                phase_ns: p.phase_us * 1000,
                priority: p.priority,
                cpu: p.cpu.unwrap_or(-1),
                network_estop_config: EstopReaction::from(p.network_estop_config) as u32,
                flags: if p.critical {
                    0
                } else {
                    shm_schema::process_flags::NOT_CRITICAL
                },
            };
        }
        for (i, a) in self.axis.iter().enumerate() {
            c.axis[i] = AxisConfigV2 {
                name: fixed_str(&a.name),
                unit: fixed_str(&a.unit),
                min: a.min,
                max: a.max,
                vmax: a.vmax,
                start: a.start,
                following_error_limit: a.following_error_limit,
                in_position: a.in_position,
                settle_velocity: a.settle_velocity(),
                velocity_limit: a.velocity_limit(),
                position_step_limit: a.position_step_limit(servo_period_s),
                velocity_step_limit: a.velocity_step_limit(servo_period_s, t_acc),
                stop_deceleration: a.stop_deceleration(t_acc),
                mode: cia402::Mode::from(a.drive.mode) as i32,
                quick_stop_option: a.drive.quick_stop_option,
                drive_kp: a.drive.kp,
                drive_ki: a.drive.ki,
                drive_kd: a.drive.kd,
                quick_stop_deceleration: a.quick_stop_deceleration(t_acc),
                kp: a.servo.kp,
                ki: a.servo.ki,
                kd: a.servo.kd,
                kvff: a.servo.kvff,
                kaff: a.servo.kaff,
                integral_limit: a.servo.integral_limit,
                inertia: a.sim.inertia,
                viscous: a.sim.viscous,
                coulomb: a.sim.coulomb,
                effort_limit: a.sim.effort_limit,
                encoder_resolution: a.sim.encoder_resolution,
            };
        }
        c
    }
}
