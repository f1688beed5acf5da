//! The errors: of a computation in the cycle ([`KinError`]), of a kinematics' parameters
//! ([`ParamError`]) and of building one from a configuration ([`BuildError`]).

use alloc::string::String;
use core::fmt;

/// Why a kinematic computation has no answer. Every variant is `Copy` and built without
/// allocation: these are returned inside trajgen's cycle.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum KinError {
    /// An input value is NaN or infinite (or a result overflowed to infinity).
    NotFinite {
        /// What the value is: `"joint"`, `"coordinate"`, `"reference joint"`,
        /// `"Cartesian velocity"`, `"result"`.
        what: &'static str,
        /// Its index in the array (0-based; for a jacobian entry, column-major: joint ×
        /// `MAX_COORDS` + coordinate).
        index: usize,
        /// The value.
        value: f64,
    },
    /// The pose is beyond the mechanism: a distance outside the range its links span.
    OutOfReach {
        /// Which distance, e.g. `"the TCP's distance from the base"`.
        what: &'static str,
        /// The distance asked for (mm).
        distance: f64,
        /// The shortest the mechanism reaches (mm).
        min: f64,
        /// The longest the mechanism reaches (mm).
        max: f64,
    },
    /// The joint position gives no pose: two points that links must join are too far apart
    /// or too close (a five-bar whose crank ends T and W the links L3 and L4 cannot join).
    CannotAssemble {
        /// Which two points, e.g. `"the crank ends T and W"`.
        what: &'static str,
        /// Their distance (mm).
        distance: f64,
        /// The shortest distance the links join (mm).
        min: f64,
        /// The longest distance the links join (mm).
        max: f64,
    },
    /// Reachable in principle, but no solution exists for a reason the kinematics names
    /// (e.g. only in the other assembly mode of a five-bar).
    NoSolution {
        /// Why.
        reason: &'static str,
    },
    /// Every solution breaks a joint limit; this is the first limit that the solution nearest
    /// the reference breaks.
    JointLimit {
        /// The joint's index (0-based).
        joint: usize,
        /// The value it would need (the whole turn nearest its limits, for a rotary joint).
        value: f64,
        /// Its smallest valid value.
        min: f64,
        /// Its largest valid value.
        max: f64,
    },
    /// Every solution within the joint limits is singular (the mechanism loses a degree of
    /// freedom there), or the jacobian cannot be inverted at this joint position.
    Singular,
    /// A joint limit is NaN or has `min > max`.
    BadLimit {
        /// The joint's index (0-based).
        joint: usize,
        /// The given smallest value.
        min: f64,
        /// The given largest value.
        max: f64,
    },
    /// Fewer limits than joints were given.
    LimitCount {
        /// The kinematics' number of joints.
        joints: usize,
        /// The number of limits given.
        limits: usize,
    },
    /// Joint velocities need as many coordinates as joints (a square jacobian).
    NotSquare {
        /// The kinematics' number of joints.
        joints: usize,
        /// Its number of Cartesian coordinates.
        coords: usize,
    },
}

impl fmt::Display for KinError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            KinError::NotFinite { what, index, value } => write!(
                f,
                "{what} {index} is {value}, not a finite number: refused, not computed with"
            ),
            KinError::OutOfReach {
                what,
                distance,
                min,
                max,
            } => write!(
                f,
                "out of reach: {what} is {distance} mm, but the mechanism reaches only \
                 {min} to {max} mm"
            ),
            KinError::CannotAssemble {
                what,
                distance,
                min,
                max,
            } => write!(
                f,
                "the joint position does not assemble the mechanism: {what} are {distance} mm \
                 apart, but the links join only points {min} to {max} mm apart"
            ),
            KinError::NoSolution { reason } => write!(f, "no inverse solution: {reason}"),
            KinError::JointLimit {
                joint,
                value,
                min,
                max,
            } => write!(
                f,
                "joint limit: the nearest solution needs joint {joint} at {value}, outside its \
                 limits {min} to {max}"
            ),
            KinError::Singular => write!(
                f,
                "singular: every solution within the joint limits is at a singularity, where \
                 the mechanism loses a degree of freedom and joint velocities are unbounded"
            ),
            KinError::BadLimit { joint, min, max } => write!(
                f,
                "joint {joint}'s limits {min} to {max} are not a range (NaN, or min > max)"
            ),
            KinError::LimitCount { joints, limits } => write!(
                f,
                "{limits} joint limits given for a kinematics of {joints} joints: one per joint \
                 is needed"
            ),
            KinError::NotSquare { joints, coords } => write!(
                f,
                "joint velocities need as many Cartesian coordinates as joints; this kinematics \
                 has {coords} coordinates and {joints} joints"
            ),
        }
    }
}

impl core::error::Error for KinError {}

/// Why a kinematics' parameters are refused (its `new`, or the configuration's keys).
#[derive(Clone, Debug, PartialEq)]
pub enum ParamError {
    /// A required parameter is absent.
    Missing {
        /// Its name.
        name: &'static str,
    },
    /// A parameter this kinematics does not have (a typo in the configuration?).
    Unknown {
        /// The name given.
        name: String,
        /// The parameters it has.
        known: &'static [&'static str],
    },
    /// A parameter is given twice.
    Duplicate {
        /// Its name.
        name: String,
    },
    /// A parameter is NaN or infinite.
    NotFinite {
        /// Its name.
        name: &'static str,
        /// The value.
        value: f64,
    },
    /// A length is zero or negative.
    NotPositive {
        /// Its name.
        name: &'static str,
        /// The value.
        value: f64,
    },
    /// A parameter is not one of the values it may take.
    Invalid {
        /// Its name.
        name: &'static str,
        /// The value.
        value: f64,
        /// What it may be, e.g. `"1, 2 or 3"`.
        expected: &'static str,
    },
    /// A five-bar whose links can never close: the distances the cranks' ends T and W can
    /// be apart and the distances the links L3 and L4 can join do not overlap.
    CannotClose {
        /// |L1 − L5| (mm): the nearest T and W come.
        crank_min: f64,
        /// L1 + L5 (mm): the farthest T and W go.
        crank_max: f64,
        /// |L3 − L4| (mm): the shortest distance the links join.
        link_min: f64,
        /// L3 + L4 (mm): the longest distance the links join.
        link_max: f64,
    },
}

impl fmt::Display for ParamError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ParamError::Missing { name } => write!(f, "parameter `{name}` is required"),
            ParamError::Unknown { name, known } => {
                write!(f, "unknown parameter `{name}`; the parameters are ")?;
                list(f, known.iter().copied())
            }
            ParamError::Duplicate { name } => write!(f, "parameter `{name}` is given twice"),
            ParamError::NotFinite { name, value } => {
                write!(f, "parameter `{name}` is {value}, not a finite number")
            }
            ParamError::NotPositive { name, value } => {
                write!(
                    f,
                    "parameter `{name}` is {value}: a length must be positive"
                )
            }
            ParamError::Invalid {
                name,
                value,
                expected,
            } => write!(f, "parameter `{name}` is {value}; expected {expected}"),
            ParamError::CannotClose {
                crank_min,
                crank_max,
                link_min,
                link_max,
            } => write!(
                f,
                "the five-bar can never close: the crank ends T and W are {crank_min} to \
                 {crank_max} mm apart (|l1 - l5| to l1 + l5), but the links l3 and l4 join \
                 only points {link_min} to {link_max} mm apart (|l3 - l4| to l3 + l4)"
            ),
        }
    }
}

impl core::error::Error for ParamError {}

/// Why [`build`](crate::build) cannot make the kinematics a configuration asks for.
#[derive(Clone, Debug, PartialEq)]
pub enum BuildError {
    /// No kinematics of this name is in the [`REGISTRY`](crate::REGISTRY).
    UnknownType {
        /// The name given.
        name: String,
    },
    /// The kinematics refuses its parameters.
    Params {
        /// The kinematics' name.
        kinematics: &'static str,
        /// Why.
        error: ParamError,
    },
}

impl fmt::Display for BuildError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            BuildError::UnknownType { name } => {
                write!(f, "unknown kinematics type `{name}`; the types are ")?;
                list(f, crate::REGISTRY.iter().map(|entry| entry.name))
            }
            BuildError::Params { kinematics, error } => {
                write!(f, "kinematics `{kinematics}`: {error}")
            }
        }
    }
}

impl core::error::Error for BuildError {
    fn source(&self) -> Option<&(dyn core::error::Error + 'static)> {
        match self {
            BuildError::Params { error, .. } => Some(error),
            BuildError::UnknownType { .. } => None,
        }
    }
}

/// Writes `` `a`, `b`, `c` `` (or "none").
fn list<'a>(f: &mut fmt::Formatter<'_>, names: impl Iterator<Item = &'a str>) -> fmt::Result {
    let mut any = false;
    for (i, name) in names.enumerate() {
        if i > 0 {
            write!(f, ", ")?;
        }
        write!(f, "`{name}`")?;
        any = true;
    }
    if !any {
        write!(f, "none")?;
    }
    Ok(())
}
