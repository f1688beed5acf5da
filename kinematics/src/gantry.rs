//! The Cartesian gantry of seed 003 (the Gantry UBA): every axis is a Cartesian coordinate.

use crate::{
    Coord, Jacobian, JointInfo, JointKind, Joints, KinError, Kinematics, MAX_COORDS, ParamError,
    Params, Pose, Solutions, XY_THETA, check_finite, registry::Boxed,
};
use alloc::boxed::Box;

const JOINTS: [JointInfo; 3] = [
    JointInfo {
        name: "x",
        kind: JointKind::Linear,
        wraps: false,
    },
    JointInfo {
        name: "y",
        kind: JointKind::Linear,
        wraps: false,
    },
    JointInfo {
        name: "theta",
        kind: JointKind::Rotary,
        wraps: false,
    },
];

/// A Cartesian gantry: joint `i` is coordinate `i` (x and y in mm, θ in degrees), the
/// identity both ways. Today's cell (seed 003), unchanged in behaviour: one solution, never
/// singular, and θ never wraps: a pose's θ is the axis position itself.
///
/// Parameters: `axes` (optional, default 3): 1 (x), 2 (x, y) or 3 (x, y, θ).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Gantry {
    axes: usize,
}

impl Gantry {
    /// The parameter names a configuration may give.
    pub const PARAMS: &'static [&'static str] = &["axes"];

    /// Parameters that make a working one: the default cell's three axes.
    pub const EXAMPLE: &'static [(&'static str, f64)] = &[("axes", 3.0)];

    /// A gantry of `axes` axes: x, then y, then θ.
    ///
    /// # Errors
    ///
    /// [`ParamError::Invalid`] unless `axes` is 1, 2 or 3.
    pub fn new(axes: usize) -> Result<Self, ParamError> {
        if (1..=JOINTS.len()).contains(&axes) {
            Ok(Gantry { axes })
        } else {
            Err(ParamError::Invalid {
                name: "axes",
                value: axes as f64,
                expected: "1, 2 or 3 (x, y, theta)",
            })
        }
    }

    /// From a configuration's parameters (see [`Gantry`]).
    ///
    /// # Errors
    ///
    /// [`ParamError::Invalid`] for an `axes` that is not 1, 2 or 3.
    pub fn from_params(params: &Params<'_>) -> Result<Self, ParamError> {
        let axes = params.get("axes").unwrap_or(3.0);
        if axes == 1.0 || axes == 2.0 || axes == 3.0 {
            Self::new(axes as usize)
        } else {
            Err(ParamError::Invalid {
                name: "axes",
                value: axes,
                expected: "1, 2 or 3 (x, y, theta)",
            })
        }
    }
}

/// The registry's builder.
pub(crate) fn build(params: &Params<'_>) -> Result<Boxed, ParamError> {
    Ok(Box::new(Gantry::from_params(params)?))
}

impl Kinematics for Gantry {
    fn name(&self) -> &str {
        "gantry"
    }

    fn joint_infos(&self) -> &[JointInfo] {
        JOINTS.get(..self.axes).unwrap_or(&JOINTS)
    }

    fn coords(&self) -> &'static [Coord] {
        XY_THETA.get(..self.axes).unwrap_or(XY_THETA)
    }

    /// The identity.
    ///
    /// # Real-time
    ///
    /// Constant time, no allocation, never panics.
    fn axes_to_cartesian(&self, q: &Joints) -> Result<Pose, KinError> {
        check_finite(q, self.axes, "joint")?;
        let mut p = [0.0; MAX_COORDS];
        for (slot, v) in p.iter_mut().zip(q.iter()).take(self.axes) {
            *slot = *v;
        }
        Ok(p)
    }

    /// The one solution: the identity.
    ///
    /// # Real-time
    ///
    /// Constant time, no allocation, never panics.
    fn solutions(&self, p: &Pose, out: &mut Solutions) -> Result<(), KinError> {
        out.clear();
        check_finite(p, self.axes, "coordinate")?;
        let mut q = [0.0; crate::MAX_JOINTS];
        for (slot, v) in q.iter_mut().zip(p.iter()).take(self.axes) {
            *slot = *v;
        }
        out.push(q);
        Ok(())
    }

    /// Never at a finite position: a gantry has no singularity (seed 003 §2).
    fn is_singular(&self, q: &Joints) -> bool {
        check_finite(q, self.axes, "joint").is_err()
    }

    /// The identity block.
    fn jacobian(&self, q: &Joints) -> Result<Jacobian, KinError> {
        check_finite(q, self.axes, "joint")?;
        let mut j = Jacobian::zeros();
        for i in 0..self.axes {
            j[(i, i)] = 1.0;
        }
        Ok(j)
    }
}
