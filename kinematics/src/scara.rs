//! A planar SCARA: two revolute links and a revolute wrist.

use crate::math::{RAD_PER_DEG, abs, atan2, bound, cos, deg, hypot, rad, sin, sqrt};
use crate::{
    Coord, Jacobian, JointInfo, JointKind, Joints, KinError, Kinematics, MAX_COORDS, MAX_JOINTS,
    ParamError, Params, Pose, SINGULARITY_TOLERANCE, Solutions, XY_THETA, check_finite,
    registry::Boxed,
};
use alloc::boxed::Box;

const JOINTS: [JointInfo; 3] = [
    JointInfo {
        name: "j1",
        kind: JointKind::Rotary,
        wraps: true,
    },
    JointInfo {
        name: "j2",
        kind: JointKind::Rotary,
        wraps: true,
    },
    JointInfo {
        name: "j3",
        kind: JointKind::Rotary,
        wraps: true,
    },
];

/// How far past ±1 the elbow's cosine may come (rounding) and still count as the stretched or
/// folded arm rather than out of reach.
const REACH_SLACK: f64 = 1e-10;

/// A planar SCARA: the shoulder j1 at the origin turns a link of length `l1`, the elbow j2 a
/// link of length `l2`, the wrist j3 the tool (all in degrees, counter-clockwise):
///
/// ```text
/// x = l1 cos j1 + l2 cos(j1 + j2)
/// y = l1 sin j1 + l2 sin(j1 + j2)
/// θ = j1 + j2 + j3
/// ```
///
/// The inverse has two solutions, the elbows `j2 = ±acos((r² − l1² − l2²) / (2 l1 l2))` with
/// `r = √(x² + y²)`; the workspace is the annulus `|l1 − l2| <= r <= l1 + l2`. Singular when
/// the arm is stretched (j2 = 0) or folded (j2 = 180°): `|sin j2|` below
/// [`SINGULARITY_TOLERANCE`], i.e. j2 within 0.057° of either.
///
/// Parameters: `l1`, `l2` (mm, positive).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Scara {
    l1: f64,
    l2: f64,
}

impl Scara {
    /// The parameter names a configuration may give.
    pub const PARAMS: &'static [&'static str] = &["l1", "l2"];

    /// Parameters that make a working one: `examples/scara.toml`'s arm.
    pub const EXAMPLE: &'static [(&'static str, f64)] = &[("l1", 200.0), ("l2", 150.0)];

    /// A SCARA with upper arm `l1` and forearm `l2` (mm).
    ///
    /// # Errors
    ///
    /// [`ParamError::NotFinite`] or [`ParamError::NotPositive`] naming the length.
    pub fn new(l1: f64, l2: f64) -> Result<Self, ParamError> {
        Ok(Scara {
            l1: length("l1", l1)?,
            l2: length("l2", l2)?,
        })
    }

    /// From a configuration's parameters (see [`Scara`]).
    ///
    /// # Errors
    ///
    /// [`ParamError::Missing`] for an absent length, else as [`Scara::new`].
    pub fn from_params(params: &Params<'_>) -> Result<Self, ParamError> {
        Self::new(params.require("l1")?, params.require("l2")?)
    }

    /// The shortest and longest distance from the shoulder the tool reaches (mm).
    pub fn reach(&self) -> (f64, f64) {
        (abs(self.l1 - self.l2), self.l1 + self.l2)
    }
}

/// Refuses a length that is not a finite positive number, naming it.
pub(crate) fn length(name: &'static str, value: f64) -> Result<f64, ParamError> {
    if !value.is_finite() {
        Err(ParamError::NotFinite { name, value })
    } else if value <= 0.0 {
        Err(ParamError::NotPositive { name, value })
    } else {
        Ok(value)
    }
}

/// The registry's builder.
pub(crate) fn build(params: &Params<'_>) -> Result<Boxed, ParamError> {
    Ok(Box::new(Scara::from_params(params)?))
}

impl Kinematics for Scara {
    fn name(&self) -> &str {
        "scara"
    }

    fn joint_infos(&self) -> &[JointInfo] {
        &JOINTS
    }

    fn coords(&self) -> &'static [Coord] {
        XY_THETA
    }

    /// # Real-time
    ///
    /// Constant time, no allocation, never panics.
    fn axes_to_cartesian(&self, q: &Joints) -> Result<Pose, KinError> {
        check_finite(q, JOINTS.len(), "joint")?;
        let [j1, j2, j3, ..] = *q;
        let a1 = rad(j1);
        let a12 = rad(j1 + j2);
        let mut p = [0.0; MAX_COORDS];
        p[0] = self.l1 * cos(a1) + self.l2 * cos(a12);
        p[1] = self.l1 * sin(a1) + self.l2 * sin(a12);
        p[2] = j1 + j2 + j3;
        check_finite(&p, 3, "result")?;
        Ok(p)
    }

    /// Both elbows (one when the arm is stretched or folded).
    ///
    /// # Errors
    ///
    /// [`KinError::NotFinite`]; [`KinError::OutOfReach`] with the distance from the shoulder
    /// and the annulus `|l1 − l2|..=l1 + l2`.
    ///
    /// # Real-time
    ///
    /// Constant time, no allocation, never panics.
    fn solutions(&self, p: &Pose, out: &mut Solutions) -> Result<(), KinError> {
        out.clear();
        check_finite(p, 3, "coordinate")?;
        let [x, y, theta, ..] = *p;
        let r = hypot(x, y);
        let c2 = (r * r - self.l1 * self.l1 - self.l2 * self.l2) / (2.0 * self.l1 * self.l2);
        if c2.is_nan() || abs(c2) > 1.0 + REACH_SLACK {
            let (min, max) = self.reach();
            return Err(KinError::OutOfReach {
                what: "the tool's distance from the shoulder",
                distance: r,
                min,
                max,
            });
        }
        let c2 = bound(c2, -1.0, 1.0);
        let s2 = sqrt(1.0 - c2 * c2);
        let direction = atan2(y, x);
        for s in [s2, -s2] {
            let j2 = atan2(s, c2);
            let j1 = direction - atan2(self.l2 * s, self.l1 + self.l2 * c2);
            let (j1, j2) = (deg(j1), deg(j2));
            let mut q = [0.0; MAX_JOINTS];
            q[0] = j1;
            q[1] = j2;
            q[2] = theta - j1 - j2;
            out.push(q);
            if s2 == 0.0 {
                break;
            }
        }
        Ok(())
    }

    /// Stretched or folded: `|sin j2| < SINGULARITY_TOLERANCE` (j2 within 0.057° of 0 or
    /// 180°), where the jacobian's determinant `l1 l2 sin j2` vanishes. True for a joint
    /// value that is not finite.
    fn is_singular(&self, q: &Joints) -> bool {
        if check_finite(q, JOINTS.len(), "joint").is_err() {
            return true;
        }
        abs(sin(rad(q[1]))) < SINGULARITY_TOLERANCE
    }

    /// Analytic: the x and y rows in mm per degree, θ's row all 1.
    fn jacobian(&self, q: &Joints) -> Result<Jacobian, KinError> {
        check_finite(q, JOINTS.len(), "joint")?;
        let a1 = rad(q[0]);
        let a12 = rad(q[0] + q[1]);
        let (s1, c1, s12, c12) = (sin(a1), cos(a1), sin(a12), cos(a12));
        let mut j = Jacobian::zeros();
        j[(0, 0)] = -(self.l1 * s1 + self.l2 * s12) * RAD_PER_DEG;
        j[(0, 1)] = -self.l2 * s12 * RAD_PER_DEG;
        j[(1, 0)] = (self.l1 * c1 + self.l2 * c12) * RAD_PER_DEG;
        j[(1, 1)] = self.l2 * c12 * RAD_PER_DEG;
        j[(2, 0)] = 1.0;
        j[(2, 1)] = 1.0;
        j[(2, 2)] = 1.0;
        if let Some(index) = j.iter().position(|v| !v.is_finite()) {
            // Joints so large their sum overflows.
            return Err(KinError::NotFinite {
                what: "jacobian entry",
                index,
                value: j.iter().nth(index).copied().unwrap_or(f64::NAN),
            });
        }
        Ok(j)
    }
}
