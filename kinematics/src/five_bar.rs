//! Seed 004's parallel mechanism: IndraMotion kinematic type 12, CODESYS `MC_KIN_TYPE_12_XY`.

use crate::math::{
    Side, abs, atan2, circle_circle_intersection, cos, deg, hypot, rad, sin, sine_between, wrap180,
};
use crate::scara::length;
use crate::{
    Coord, JointInfo, JointKind, Joints, KinError, Kinematics, MAX_COORDS, MAX_JOINTS, ParamError,
    Params, Pose, SINGULARITY_TOLERANCE, Solutions, XY, check_finite, registry::Boxed,
};
use alloc::boxed::Box;
use nalgebra::Vector2;

const JOINTS: [JointInfo; 2] = [
    JointInfo {
        name: "a0",
        kind: JointKind::Rotary,
        wraps: true,
    },
    JointInfo {
        name: "a1",
        kind: JointKind::Rotary,
        wraps: true,
    },
];

/// How near the forward kinematics of an inverse candidate must come back to the pose asked
/// for (mm) for the candidate to belong to the configured assembly mode.
pub const ASSEMBLY_CHECK: f64 = 1e-6;

/// Seed 004's five-bar parallel mechanism (IndraMotion type 12, `MC_KIN_TYPE_12_XY`), exactly.
///
/// Two motors on one axis at the origin O turn the cranks: axis `a0` the crank of length L1
/// to T, axis `a1` the crank of length L5 to W (degrees; at a0 = a1 = 0, the seed's null
/// posture, T points along −x and W along −y). A link of length L4 joins W to the elbow E; a
/// link from T through E carries the TCP, E at L3 from T and the TCP at L2 from T:
///
/// ```text
/// T   = L1 (cos(a0 + 180°), sin(a0 + 180°))
/// W   = L5 (cos(a1 + 270°), sin(a1 + 270°))
/// E   = circle_circle_intersection(T, L3, W, L4, assembly)     (the seed: sign −1)
/// TCP = T + (E − T) L2 / L3
/// ```
///
/// The assembly mode is which of the two points where the circles around T and W meet is
/// the elbow: the seed's −1 ([`Side::Right`], the default) puts E to the right of the line
/// from T to W.
///
/// The inverse follows the seed's `CartesianToAxes`: T where the circle of radius L1 around O
/// meets the circle of radius L2 around the TCP, E on the line from T to the TCP at L3, W
/// where the circle of radius L5 around O meets the circle of radius L4 around E, then the
/// angles. The seed takes one side of each intersection (−1 for T, +1 for W); here both sides
/// of each are tried (up to four candidates) and only those whose forward kinematics, in the
/// configured assembly mode, gives back the pose within [`ASSEMBLY_CHECK`] are solutions.
/// That keeps the inverse consistent with the forward kinematics whatever the assembly mode;
/// seed 001's rule then picks the nearest.
///
/// Singular ([`Kinematics::is_singular`]) when the link T–E lines up with the crank O–T or
/// with the link W–E, or the link W–E with the crank O–W: the sine of the angle between them
/// below [`SINGULARITY_TOLERANCE`].
///
/// Parameters: `l1` … `l5` (mm, positive) and `assembly` (optional: −1, the seed's and the
/// default, or +1).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FiveBar {
    l1: f64,
    l2: f64,
    l3: f64,
    l4: f64,
    l5: f64,
    assembly: Side,
}

/// The mechanism's points at one joint position (mm).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FiveBarPoints {
    /// The end of crank L1.
    pub t: Vector2<f64>,
    /// The end of crank L5.
    pub w: Vector2<f64>,
    /// The elbow, where links L3 and L4 meet.
    pub e: Vector2<f64>,
    /// The tool centre point.
    pub tcp: Vector2<f64>,
}

impl FiveBar {
    /// The parameter names a configuration may give.
    pub const PARAMS: &'static [&'static str] = &["l1", "l2", "l3", "l4", "l5", "assembly"];

    /// Parameters that make a working one: `examples/five-bar.toml`'s.
    pub const EXAMPLE: &'static [(&'static str, f64)] = &[
        ("l1", 200.0),
        ("l2", 150.0),
        ("l3", 100.0),
        ("l4", 200.0),
        ("l5", 100.0),
        ("assembly", -1.0),
    ];

    /// The seed's lengths L1 … L5 (mm): `MC_KIN_TYPE_12_XY`'s defaults. With L1 = L4 and
    /// L3 = L5 they make O, T, E, W a parallelogram (`docs/kinematics.md`).
    pub const SEED_LENGTHS: [f64; 5] = [200.0, 150.0, 100.0, 200.0, 100.0];

    /// A five-bar of links `l1` … `l5` (mm) in assembly mode `assembly`.
    ///
    /// # Errors
    ///
    /// [`ParamError::NotFinite`] or [`ParamError::NotPositive`] naming the length;
    /// [`ParamError::CannotClose`] when no joint position assembles the mechanism (the
    /// distances T and W can be apart, `|l1 − l5|..=l1 + l5`, and the distances the links
    /// join, `|l3 − l4|..=l3 + l4`, do not overlap in more than a point).
    pub fn new(
        l1: f64,
        l2: f64,
        l3: f64,
        l4: f64,
        l5: f64,
        assembly: Side,
    ) -> Result<Self, ParamError> {
        let five_bar = FiveBar {
            l1: length("l1", l1)?,
            l2: length("l2", l2)?,
            l3: length("l3", l3)?,
            l4: length("l4", l4)?,
            l5: length("l5", l5)?,
            assembly,
        };
        let (crank_min, crank_max) = (abs(l1 - l5), l1 + l5);
        let (link_min, link_max) = (abs(l3 - l4), l3 + l4);
        if crank_min.max(link_min) < crank_max.min(link_max) {
            Ok(five_bar)
        } else {
            Err(ParamError::CannotClose {
                crank_min,
                crank_max,
                link_min,
                link_max,
            })
        }
    }

    /// The seed's mechanism: [`SEED_LENGTHS`](Self::SEED_LENGTHS), assembly mode −1.
    pub fn seed() -> Self {
        let [l1, l2, l3, l4, l5] = Self::SEED_LENGTHS;
        FiveBar {
            l1,
            l2,
            l3,
            l4,
            l5,
            assembly: Side::Right,
        }
    }

    /// From a configuration's parameters (see [`FiveBar`]).
    ///
    /// # Errors
    ///
    /// [`ParamError::Missing`] for an absent length, [`ParamError::Invalid`] for an
    /// `assembly` other than −1 or +1, else as [`FiveBar::new`].
    pub fn from_params(params: &Params<'_>) -> Result<Self, ParamError> {
        let assembly = match params.get("assembly") {
            None => Side::Right,
            Some(-1.0) => Side::Right,
            Some(1.0) => Side::Left,
            Some(value) => {
                return Err(ParamError::Invalid {
                    name: "assembly",
                    value,
                    expected: "-1 (the seed's) or 1",
                });
            }
        };
        Self::new(
            params.require("l1")?,
            params.require("l2")?,
            params.require("l3")?,
            params.require("l4")?,
            params.require("l5")?,
            assembly,
        )
    }

    /// The lengths L1 … L5 (mm).
    pub fn lengths(&self) -> [f64; 5] {
        [self.l1, self.l2, self.l3, self.l4, self.l5]
    }

    /// The assembly mode.
    pub fn assembly(&self) -> Side {
        self.assembly
    }

    /// The mechanism's points at joint position `q` (the seed's `AxesToCartesian`).
    ///
    /// # Errors
    ///
    /// As [`Kinematics::axes_to_cartesian`].
    ///
    /// # Real-time
    ///
    /// Constant time, no allocation, never panics.
    pub fn points(&self, q: &Joints) -> Result<FiveBarPoints, KinError> {
        check_finite(q, JOINTS.len(), "joint")?;
        let (a0, a1) = (rad(q[0] + 180.0), rad(q[1] + 270.0));
        let t = Vector2::new(self.l1 * cos(a0), self.l1 * sin(a0));
        let w = Vector2::new(self.l5 * cos(a1), self.l5 * sin(a1));
        let Some(e) = circle_circle_intersection(t, self.l3, w, self.l4, self.assembly) else {
            return Err(KinError::CannotAssemble {
                what: "the crank ends T and W",
                distance: hypot(w.x - t.x, w.y - t.y),
                min: abs(self.l3 - self.l4),
                max: self.l3 + self.l4,
            });
        };
        let tcp = t + (e - t) * (self.l2 / self.l3);
        Ok(FiveBarPoints { t, w, e, tcp })
    }
}

/// The registry's builder.
pub(crate) fn build(params: &Params<'_>) -> Result<Boxed, ParamError> {
    Ok(Box::new(FiveBar::from_params(params)?))
}

impl Kinematics for FiveBar {
    fn name(&self) -> &str {
        "five-bar"
    }

    fn joint_infos(&self) -> &[JointInfo] {
        &JOINTS
    }

    fn coords(&self) -> &'static [Coord] {
        XY
    }

    /// The seed's `AxesToCartesian`.
    ///
    /// # Errors
    ///
    /// [`KinError::NotFinite`]; [`KinError::CannotAssemble`] when the links L3 and L4 cannot
    /// join T and W (the seed's `SMC_IPR_DIVISION_BY_ZERO`).
    ///
    /// # Real-time
    ///
    /// Constant time, no allocation, never panics.
    fn axes_to_cartesian(&self, q: &Joints) -> Result<Pose, KinError> {
        let tcp = self.points(q)?.tcp;
        let mut p = [0.0; MAX_COORDS];
        p[0] = tcp.x;
        p[1] = tcp.y;
        Ok(p)
    }

    /// The seed's `CartesianToAxes` with both sides of each intersection, kept when they
    /// belong to the configured assembly mode (see [`FiveBar`]); angles in `[-180, 180)`.
    ///
    /// # Errors
    ///
    /// [`KinError::NotFinite`]; [`KinError::OutOfReach`] when no T exists (the TCP's
    /// distance from O outside `|L1 − L2|..=L1 + L2`) or no W for any T (the elbow's
    /// distance from O outside `|L5 − L4|..=L5 + L4`); [`KinError::NoSolution`] when the
    /// pose is reachable only in the other assembly mode; [`KinError::Singular`] for the TCP
    /// on O when L1 = L2 (every T fits).
    ///
    /// # Real-time
    ///
    /// Constant time (at most four candidates), no allocation, never panics.
    fn solutions(&self, p: &Pose, out: &mut Solutions) -> Result<(), KinError> {
        out.clear();
        check_finite(p, 2, "coordinate")?;
        let tcp = Vector2::new(p[0], p[1]);
        let origin = Vector2::zeros();
        let mut any_t = false;
        let mut any_w = false;
        let mut elbow_distance = 0.0;
        for side_t in Side::BOTH {
            let Some(t) = circle_circle_intersection(origin, self.l1, tcp, self.l2, side_t) else {
                continue;
            };
            any_t = true;
            let e = t + (tcp - t) * (self.l3 / self.l2);
            elbow_distance = hypot(e.x, e.y);
            for side_w in Side::BOTH {
                let Some(w) = circle_circle_intersection(origin, self.l5, e, self.l4, side_w)
                else {
                    continue;
                };
                any_w = true;
                let mut q = [0.0; MAX_JOINTS];
                q[0] = wrap180(deg(atan2(t.y, t.x)) - 180.0);
                q[1] = wrap180(deg(atan2(w.y, w.x)) - 270.0);
                let Ok(back) = self.axes_to_cartesian(&q) else {
                    continue;
                };
                let miss = hypot(back[0] - tcp.x, back[1] - tcp.y);
                let known = out
                    .as_slice()
                    .iter()
                    .any(|s| abs(s[0] - q[0]) < 1e-9 && abs(s[1] - q[1]) < 1e-9);
                if miss <= ASSEMBLY_CHECK && !known {
                    out.push(q);
                }
            }
        }
        if !out.is_empty() {
            return Ok(());
        }
        let distance = hypot(tcp.x, tcp.y);
        if !any_t {
            if distance == 0.0 && self.l1 == self.l2 {
                return Err(KinError::Singular);
            }
            return Err(KinError::OutOfReach {
                what: "the TCP's distance from the base",
                distance,
                min: abs(self.l1 - self.l2),
                max: self.l1 + self.l2,
            });
        }
        if !any_w {
            return Err(KinError::OutOfReach {
                what: "the elbow E's distance from the base",
                distance: elbow_distance,
                min: abs(self.l5 - self.l4),
                max: self.l5 + self.l4,
            });
        }
        Err(KinError::NoSolution {
            reason: "the pose is reachable only in the other assembly mode",
        })
    }

    /// The link T–E in line with the crank O–T or with the link W–E, or the link W–E in line
    /// with the crank O–W: the sine of the angle between them below
    /// [`SINGULARITY_TOLERANCE`]. True where `q` assembles nothing or is not finite.
    fn is_singular(&self, q: &Joints) -> bool {
        let Ok(FiveBarPoints { t, w, e, .. }) = self.points(q) else {
            return true;
        };
        let sines = [
            sine_between(t, e - t),
            sine_between(e - t, e - w),
            sine_between(w, e - w),
        ];
        sines
            .iter()
            .any(|s| s.is_nan() || abs(*s) < SINGULARITY_TOLERANCE)
    }
}
