//! `[[axis]]`: an axis' keys, the limits derived from them, and the checks of each of its
//! parts.

use crate::problem::{Problem, Seg, non_negative, positive};
use serde::Deserialize;

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

/// The key path of axis `i`'s keys.
#[derive(Clone, Copy)]
pub(crate) struct AxisAt(pub(crate) usize);

impl AxisAt {
    /// `axis[i].k`.
    pub(crate) fn key(self, k: &'static str) -> Vec<Seg> {
        vec![Seg::Key("axis"), Seg::Index(self.0), Seg::Key(k)]
    }

    /// `axis[i].table.k`.
    pub(crate) fn sub(self, table: &'static str, k: &'static str) -> Vec<Seg> {
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
pub(crate) fn axis_range(a: &Axis, at: AxisAt) -> Result<(), Problem> {
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
pub(crate) fn axis_gains(a: &Axis, at: AxisAt) -> Result<(), Problem> {
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
pub(crate) fn axis_model(a: &Axis, at: AxisAt) -> Result<(), Problem> {
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
pub(crate) fn axis_drive(a: &Axis, at: AxisAt) -> Result<(), Problem> {
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
