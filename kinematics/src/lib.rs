//! Forward and inverse kinematics a cell can choose, and a user can bring (`docs/kinematics.md`).
//!
//! The [`Kinematics`] trait follows seed 004's user-defined kinematics (CODESYS SoftMotion's
//! `MC_KIN_REF_SM3` and `ISMKinematicWithInfo2`): a name, the number of axes, each axis'
//! properties, `axes_to_cartesian`, every inverse solution, a singularity check and the
//! jacobian. Seed 001's rule (`LLI_reverseKine`) is [`cartesian_to_axes`]: of all the inverse
//! solutions, and for rotary joints of every whole turn of them, the one nearest a reference
//! joint position within the joint limits; when there is none, an error that says why (out of
//! reach, a joint limit, a singularity). [`joint_velocity`] maps a Cartesian velocity to joint
//! velocities through the jacobian.
//!
//! Built in: [`Gantry`] (seed 003's cell: the identity), [`Scara`] (two revolute links and a
//! wrist) and [`FiveBar`] (seed 004's parallel mechanism, IndraMotion type 12). A user's own
//! kinematics is a type implementing the trait in `src/user/` and one line in [`REGISTRY`];
//! [`user::polar::Polar`] is the example. A cell's configuration selects one by name with
//! numeric parameters through [`build`].
//!
//! # Units
//!
//! Joint values are in their axis' unit: mm for a [`JointKind::Linear`] joint, degrees for a
//! [`JointKind::Rotary`] one. Cartesian coordinates are mm (x, y) and degrees (θ). Velocities
//! are the same units per second. Radians exist only inside the computations.
//!
//! # Fixed sizes
//!
//! Joint positions and poses are fixed arrays ([`Joints`], [`Pose`]) of which the first
//! [`Kinematics::joints`] and `coords().len()` entries are used; the rest are ignored (never
//! read, even if they are not finite) and written as 0. Inverse solutions go to [`Solutions`],
//! a fixed array with a count. Nothing the cycle calls allocates: the trait's computing
//! methods, [`cartesian_to_axes`], [`joint_velocity`] and [`circle_circle_intersection`]. Only
//! [`build`] (setup) allocates, for the `Box` it returns.
//!
//! # Never a panic
//!
//! Every function the cycle calls returns an error rather than panic, whatever the input: a
//! value that is not finite is refused ([`KinError::NotFinite`]), never computed with.
#![no_std]
#![deny(missing_docs)]

extern crate alloc;

mod error;
mod five_bar;
mod gantry;
mod math;
mod registry;
mod scara;
mod solve;
pub mod user;

pub use error::{BuildError, KinError, ParamError};
pub use five_bar::{ASSEMBLY_CHECK, FiveBar, FiveBarPoints};
pub use gantry::Gantry;
pub use math::{Side, circle_circle_intersection};
pub use nalgebra;
pub use registry::{Boxed, Builder, Entry, Params, REGISTRY, build};
pub use scara::Scara;
pub use solve::{
    FD_STEP, LIMIT_SLACK, cartesian_to_axes, jacobian_by_differences, joint_velocity,
    singular_by_jacobian,
};

/// Largest number of joints (axes) a kinematics may have: shm-schema's `MAX_AXES`.
pub const MAX_JOINTS: usize = 8;
/// Largest number of Cartesian coordinates a kinematics may have (x, y, z and three angles).
pub const MAX_COORDS: usize = 6;
/// Largest number of inverse solutions one pose may have in [`Solutions`].
pub const MAX_SOLUTIONS: usize = 8;
/// How near a mechanism may come to losing a degree of freedom before it counts as singular:
/// a dimensionless ratio (a sine, or the jacobian's smallest to largest singular value).
/// 1e-3 is the sine of 0.057°.
pub const SINGULARITY_TOLERANCE: f64 = 1e-3;

/// A joint position: the first [`Kinematics::joints`] entries are used, in each joint's unit
/// (mm or degrees).
pub type Joints = [f64; MAX_JOINTS];
/// A Cartesian pose: the first `coords().len()` entries are used, in each coordinate's unit
/// (mm or degrees).
pub type Pose = [f64; MAX_COORDS];
/// The jacobian: entry `(i, j)` is ∂coordinate `i` / ∂joint `j`, in the coordinate's unit per
/// joint unit (mm/deg, deg/deg, mm/mm, …). Only the top-left `coords × joints` block is
/// meaningful; the rest is 0.
pub type Jacobian = nalgebra::SMatrix<f64, MAX_COORDS, MAX_JOINTS>;

/// A unit of a joint or a coordinate.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Unit {
    /// Millimetres.
    Millimetre,
    /// Degrees.
    Degree,
}

impl Unit {
    /// The symbol a configuration writes: `"mm"` or `"deg"`.
    pub const fn symbol(self) -> &'static str {
        match self {
            Unit::Millimetre => "mm",
            Unit::Degree => "deg",
        }
    }
}

/// What a joint is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum JointKind {
    /// A prismatic joint, in mm.
    Linear,
    /// A revolute joint, in degrees.
    Rotary,
}

impl JointKind {
    /// The joint's unit: mm for a linear joint, degrees for a rotary one.
    pub const fn unit(self) -> Unit {
        match self {
            JointKind::Linear => Unit::Millimetre,
            JointKind::Rotary => Unit::Degree,
        }
    }
}

/// One joint's properties (seed 004's `GetAxisProperties`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct JointInfo {
    /// The joint's name in the kinematics' own terms (`"j1"`, `"a0"`, …); the cell's axis
    /// names are the configuration's business.
    pub name: &'static str,
    /// Linear (mm) or rotary (degrees).
    pub kind: JointKind,
    /// Whether the inverse may add whole turns (k · 360°) to this joint to find the
    /// representation nearest the reference within the limits (seed 001's rule). Only
    /// meaningful for a rotary joint; false where the joint value is itself what a program
    /// commands (the gantry's θ: a program's θ = 350 means the axis at 350°, as today).
    pub wraps: bool,
}

impl JointInfo {
    /// What [`Kinematics::joint`] answers for an index past the last joint.
    pub const UNKNOWN: JointInfo = JointInfo {
        name: "?",
        kind: JointKind::Linear,
        wraps: false,
    };
}

/// One Cartesian coordinate.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Coord {
    /// `"x"`, `"y"`, `"theta"`, …
    pub name: &'static str,
    /// mm or degrees. A coordinate in degrees is an angle: two values 360° apart are the same
    /// pose.
    pub unit: Unit,
}

const X: Coord = Coord {
    name: "x",
    unit: Unit::Millimetre,
};
const Y: Coord = Coord {
    name: "y",
    unit: Unit::Millimetre,
};

/// The Cartesian coordinates x and y (mm).
pub const XY: &[Coord] = &[X, Y];

/// The Cartesian coordinates x, y (mm) and θ (degrees).
pub const XY_THETA: &[Coord] = &[
    X,
    Y,
    Coord {
        name: "theta",
        unit: Unit::Degree,
    },
];

/// One joint's software limits, in the joint's unit: a value is valid when
/// `min <= value <= max`. An infinite bound is no bound.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct JointLimit {
    /// Smallest valid value.
    pub min: f64,
    /// Largest valid value.
    pub max: f64,
}

impl JointLimit {
    /// No limit at all.
    pub const NONE: JointLimit = JointLimit {
        min: f64::NEG_INFINITY,
        max: f64::INFINITY,
    };

    /// The limits `min..=max`.
    pub const fn new(min: f64, max: f64) -> Self {
        JointLimit { min, max }
    }

    /// Whether `value` lies within the limits (false for NaN).
    pub fn contains(&self, value: f64) -> bool {
        self.min <= value && value <= self.max
    }
}

/// Every inverse solution of one pose: a fixed array and a count, no allocation.
#[derive(Clone, Copy, Debug)]
pub struct Solutions {
    q: [Joints; MAX_SOLUTIONS],
    len: usize,
}

impl Default for Solutions {
    fn default() -> Self {
        Self::new()
    }
}

impl Solutions {
    /// No solutions.
    pub const fn new() -> Self {
        Solutions {
            q: [[0.0; MAX_JOINTS]; MAX_SOLUTIONS],
            len: 0,
        }
    }

    /// Forgets every solution.
    ///
    /// # Real-time
    ///
    /// Constant time, no allocation.
    pub fn clear(&mut self) {
        self.len = 0;
    }

    /// Adds a solution; false (and nothing added) when [`MAX_SOLUTIONS`] are there already.
    ///
    /// # Real-time
    ///
    /// Constant time, no allocation.
    pub fn push(&mut self, q: Joints) -> bool {
        match self.q.get_mut(self.len) {
            Some(slot) => {
                *slot = q;
                self.len += 1;
                true
            }
            None => false,
        }
    }

    /// The solutions found, in no particular order.
    pub fn as_slice(&self) -> &[Joints] {
        self.q.get(..self.len).unwrap_or(&[])
    }

    /// How many solutions there are.
    pub fn len(&self) -> usize {
        self.len
    }

    /// Whether there is none.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }
}

/// A mechanism's kinematics, modelled on seed 004's interface (`MC_KIN_REF_SM3` with
/// `ISMKinematicWithInfo2`).
///
/// Implement the first six methods; [`is_singular`](Kinematics::is_singular) and
/// [`jacobian`](Kinematics::jacobian) have defaults derived from `axes_to_cartesian` (central
/// differences) that an analytic version may replace. Seed 001's nearest-solution rule is not
/// part of the trait: [`cartesian_to_axes`] applies it to any implementation, so every
/// kinematics chooses among its solutions the same way.
///
/// Contract of the computing methods (`axes_to_cartesian`, `solutions`, `is_singular`,
/// `jacobian`), which run inside trajgen's cycle: no allocation, no lock, no I/O, and never a
/// panic on any input: a value that is not finite, or a pose out of reach, is an error.
/// `axes_to_cartesian` must be continuous in the joints (do not wrap a rotary coordinate into
/// ±180°: the jacobian and velocity are derived from it).
pub trait Kinematics {
    /// The kinematics' name, as a configuration selects it (seed 004's `GetKinematicsName`).
    fn name(&self) -> &str;

    /// The joints (axes) it drives, in order, each one's properties; at most [`MAX_JOINTS`].
    fn joint_infos(&self) -> &[JointInfo];

    /// The number of joints (seed 004's `NumAxes`).
    fn joints(&self) -> usize {
        self.joint_infos().len()
    }

    /// Joint `i`'s properties, for `i < joints()` (seed 004's `GetAxisProperties`); past the
    /// last joint, [`JointInfo::UNKNOWN`].
    fn joint(&self, i: usize) -> JointInfo {
        self.joint_infos()
            .get(i)
            .copied()
            .unwrap_or(JointInfo::UNKNOWN)
    }

    /// The Cartesian coordinates, in the order of a [`Pose`]; at most [`MAX_COORDS`].
    fn coords(&self) -> &'static [Coord];

    /// Forward kinematics: the pose of joint position `q` (seed 004's `AxesToCartesian`).
    ///
    /// # Errors
    ///
    /// [`KinError::NotFinite`] for a joint value that is not finite; an error of the
    /// mechanism when `q` gives no pose (a five-bar whose links cannot meet:
    /// [`KinError::CannotAssemble`]).
    ///
    /// # Real-time
    ///
    /// Called in trajgen's cycle: no allocation, no panic.
    fn axes_to_cartesian(&self, q: &Joints) -> Result<Pose, KinError>;

    /// Every inverse solution of pose `p` (up to [`MAX_SOLUTIONS`], e.g. both SCARA elbows),
    /// in no particular order, into `out` (cleared first). Rotary joints may come in any
    /// turn: [`cartesian_to_axes`] adds the whole turns and applies the limits.
    ///
    /// # Errors
    ///
    /// [`KinError::NotFinite`] for a coordinate that is not finite; [`KinError::OutOfReach`]
    /// when `p` is beyond the mechanism; any other [`KinError`] that says why there is none.
    ///
    /// # Real-time
    ///
    /// Called in trajgen's cycle: no allocation, no panic.
    fn solutions(&self, p: &Pose, out: &mut Solutions) -> Result<(), KinError>;

    /// Whether `q` is a singular posture, where the mechanism loses a degree of freedom and
    /// joint velocities would be unbounded (seed 004's `IsSingularity`). The default,
    /// [`singular_by_jacobian`], judges the jacobian's singular values; a `q` that is not
    /// finite or has no pose counts as singular.
    ///
    /// # Real-time
    ///
    /// Called in trajgen's cycle: no allocation, no panic.
    fn is_singular(&self, q: &Joints) -> bool {
        singular_by_jacobian(self, q)
    }

    /// The jacobian at `q`. The default, [`jacobian_by_differences`], takes central
    /// differences of `axes_to_cartesian` with a step of [`FD_STEP`] joint units.
    ///
    /// # Errors
    ///
    /// Whatever `axes_to_cartesian` answers at `q` or at a step beside it.
    ///
    /// # Real-time
    ///
    /// Called in trajgen's cycle: no allocation, no panic.
    fn jacobian(&self, q: &Joints) -> Result<Jacobian, KinError> {
        jacobian_by_differences(self, q)
    }
}

impl<K: Kinematics + ?Sized> Kinematics for alloc::boxed::Box<K> {
    fn name(&self) -> &str {
        (**self).name()
    }
    fn joint_infos(&self) -> &[JointInfo] {
        (**self).joint_infos()
    }
    fn coords(&self) -> &'static [Coord] {
        (**self).coords()
    }
    fn axes_to_cartesian(&self, q: &Joints) -> Result<Pose, KinError> {
        (**self).axes_to_cartesian(q)
    }
    fn solutions(&self, p: &Pose, out: &mut Solutions) -> Result<(), KinError> {
        (**self).solutions(p, out)
    }
    fn is_singular(&self, q: &Joints) -> bool {
        (**self).is_singular(q)
    }
    fn jacobian(&self, q: &Joints) -> Result<Jacobian, KinError> {
        (**self).jacobian(q)
    }
}

/// Refuses the first of `values[..n]` that is not finite, naming it as `what`.
///
/// # Real-time
///
/// Allocation-free, never panics (`n` past the array is cut to its length).
pub fn check_finite(values: &[f64], n: usize, what: &'static str) -> Result<(), KinError> {
    for (index, &value) in values.iter().take(n).enumerate() {
        if !value.is_finite() {
            return Err(KinError::NotFinite { what, index, value });
        }
    }
    Ok(())
}
