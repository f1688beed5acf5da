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

mod axis;
pub mod ethercat;
pub mod io;
pub mod kinematics;
pub mod modbus;
pub mod network;
mod problem;
mod program;
mod read;
pub mod stability;

pub use axis::{Axis, DriveMode, DriveSettings, Limits, ServoGains, SimAxis};
use axis::{AxisAt, axis_drive, axis_gains, axis_model, axis_range};
pub use problem::{ConfigError, Located};
use problem::{Problem, Seg, located, non_negative, placed, positive};
pub use program::find_program;

/// The embedded default cell (the Gantry UBA).
pub const DEFAULT_TOML: &str = include_str!("../../examples/gantry-uba.toml");
/// How the embedded default is named in messages.
pub const DEFAULT_NAME: &str = "<embedded default: examples/gantry-uba.toml>";

/// `[cell]`.
#[derive(Clone, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CellMeta {
    /// Display name.
    #[serde(default)]
    pub name: String,
    /// The clock the cell runs on: `"wall"` (default) or `"virtual"`
    /// (`docs/virtual-time.md`; `supervisor run --virtual-time` sets it too).
    #[serde(default)]
    pub clock: Clock,
    /// On the virtual clock, at most this many virtual seconds per wall second; 0 as fast as
    /// the CPUs allow. Default: 0 for `run`, 1 (real time) for `up`, whose clients watch it.
    #[serde(default)]
    pub pace: Option<f64>,
}

/// `[cell] clock`: which clock the cell's processes wait on.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Clock {
    /// Each process sleeps until its absolute deadline of `CLOCK_MONOTONIC`.
    #[default]
    Wall,
    /// The supervisor's virtual clock: the same run every time, as fast as the CPUs allow.
    Virtual,
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
            placed(src, file, problems.into_iter().map(|p| (p.span, p.message)))
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
        found.extend(self.clock_problem());
        found.extend(self.pace_problem());
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

    /// `[cell] clock = "virtual"` with a bus that cannot be stepped: an EtherCAT bus (real or
    /// emulated) runs on the wire's time, the cell stays on the wall clock.
    fn pace_problem(&self) -> Option<Problem> {
        self.cell
            .pace
            .filter(|p| !(p.is_finite() && *p >= 0.0))
            .map(|p| {
                (
                    vec![Seg::Key("cell"), Seg::Key("pace")],
                    format!(
                        "pace = {p}: virtual seconds per wall second, 0 (as fast as the CPUs \
                         allow) or more"
                    ),
                )
            })
    }

    fn clock_problem(&self) -> Option<Problem> {
        (self.cell.clock == Clock::Virtual && self.ethercat.is_some()).then(|| {
            (
                vec![Seg::Key("cell"), Seg::Key("clock")],
                "a cell with [ethercat] runs on the wall clock: its bus cannot be stepped by a \
                 virtual clock (the drives' Distributed Clocks and watchdogs keep the wire's time)"
                    .into(),
            )
        })
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
            clock: match self.cell.clock {
                Clock::Wall => shm_schema::CellClock::Wall as u32,
                Clock::Virtual => shm_schema::CellClock::Virtual as u32,
            },
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
