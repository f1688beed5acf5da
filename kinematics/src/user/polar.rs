//! An example of a user-defined kinematics: a polar (R-θ) arm.
//!
//! This file is all a user writes for a mechanism of their own, besides `pub mod polar;` in
//! `user/mod.rs` and one line in [`REGISTRY`](crate::REGISTRY): the type, its parameter
//! names and an example of them, its builder, the six required methods of [`Kinematics`].
//! The jacobian and the singularity check are the trait's defaults (central differences of
//! `axes_to_cartesian`, and the jacobian's singular values); a mechanism whose singularities
//! are known analytically may override them. The crate is `no_std`: scalar maths comes from
//! `crate::math` (sin, cos, atan2, hypot, sqrt, … over nalgebra's `libm`), never `f64::sin`.

use crate::math::{atan2, cos, deg, hypot, rad, sin};
use crate::{
    Boxed, Coord, JointInfo, JointKind, Joints, KinError, Kinematics, MAX_COORDS, MAX_JOINTS,
    ParamError, Params, Pose, Solutions, XY, check_finite,
};
use alloc::boxed::Box;

const JOINTS: [JointInfo; 2] = [
    JointInfo {
        name: "phi",
        kind: JointKind::Rotary,
        wraps: true,
    },
    JointInfo {
        name: "r",
        kind: JointKind::Linear,
        wraps: false,
    },
];

/// A polar arm: a rotary joint `phi` (degrees) at the origin turns a linear radial joint
/// `r` (mm) whose tool sits at radius `offset + r`:
///
/// ```text
/// x = (offset + r) cos phi
/// y = (offset + r) sin phi
/// ```
///
/// Two solutions for every pose but the pole: `phi = atan2(y, x)`, `r = ρ − offset`, and,
/// reaching through the pole, `phi + 180°`, `r = −ρ − offset` (ρ = √(x² + y²)); the joint
/// limits decide whether the second is usable. Singular at the pole (radius 0), where `phi`
/// moves nothing.
///
/// Parameters: `offset` (mm, optional, default 0): the radius of the tool at `r = 0`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Polar {
    offset: f64,
}

impl Polar {
    /// The parameter names a configuration may give.
    pub const PARAMS: &'static [&'static str] = &["offset"];

    /// Parameters that make a working one (the registry's tests build it with them):
    /// `examples/polar.toml`'s.
    pub const EXAMPLE: &'static [(&'static str, f64)] = &[("offset", 100.0)];

    /// A polar arm whose tool is at radius `offset` (mm) when `r = 0`.
    ///
    /// # Errors
    ///
    /// [`ParamError::NotFinite`] for an `offset` that is not finite.
    pub fn new(offset: f64) -> Result<Self, ParamError> {
        if offset.is_finite() {
            Ok(Polar { offset })
        } else {
            Err(ParamError::NotFinite {
                name: "offset",
                value: offset,
            })
        }
    }
}

/// Builds a [`Polar`] from a cell configuration's `[kinematics]` parameters: the function
/// [`REGISTRY`](crate::REGISTRY)'s line names.
///
/// # Errors
///
/// As [`Polar::new`].
pub fn build(params: &Params<'_>) -> Result<Boxed, ParamError> {
    Ok(Box::new(Polar::new(params.get("offset").unwrap_or(0.0))?))
}

impl Kinematics for Polar {
    fn name(&self) -> &str {
        "polar"
    }

    fn joint_infos(&self) -> &[JointInfo] {
        &JOINTS
    }

    fn coords(&self) -> &'static [Coord] {
        XY
    }

    /// # Real-time
    ///
    /// Constant time, no allocation, never panics.
    fn axes_to_cartesian(&self, q: &Joints) -> Result<Pose, KinError> {
        check_finite(q, JOINTS.len(), "joint")?;
        let radius = self.offset + q[1];
        let phi = rad(q[0]);
        let mut p = [0.0; MAX_COORDS];
        p[0] = radius * cos(phi);
        p[1] = radius * sin(phi);
        check_finite(&p, 2, "result")?;
        Ok(p)
    }

    /// # Real-time
    ///
    /// Constant time, no allocation, never panics.
    fn solutions(&self, p: &Pose, out: &mut Solutions) -> Result<(), KinError> {
        out.clear();
        check_finite(p, 2, "coordinate")?;
        let rho = hypot(p[0], p[1]);
        if !rho.is_finite() {
            return Err(KinError::NotFinite {
                what: "result",
                index: 1,
                value: rho,
            });
        }
        let phi = deg(atan2(p[1], p[0]));
        let mut q = [0.0; MAX_JOINTS];
        q[0] = phi;
        q[1] = rho - self.offset;
        out.push(q);
        if rho > 0.0 {
            q[0] = phi + 180.0;
            q[1] = -rho - self.offset;
            out.push(q);
        }
        Ok(())
    }
}
