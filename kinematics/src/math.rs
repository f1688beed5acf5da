//! Scalar maths without std (nalgebra's `ComplexField`/`RealField` over `libm`), degrees and
//! radians, and seed 004's circle-circle intersection.

use nalgebra::{ComplexField, Matrix2, RealField, Rotation2, Vector2};

/// Radians per degree.
pub(crate) const RAD_PER_DEG: f64 = core::f64::consts::PI / 180.0;

/// How far past ±1 a cosine from the law of cosines may come (rounding) and still count as a
/// tangent (one intersection point) rather than as no intersection. 1e-10 lets a point
/// about 1e-8 mm beyond a 200 mm link's reach count as on its circle.
const TANGENT_SLACK: f64 = 1e-10;

pub(crate) fn sqrt(x: f64) -> f64 {
    ComplexField::sqrt(x)
}
pub(crate) fn sin(x: f64) -> f64 {
    ComplexField::sin(x)
}
pub(crate) fn cos(x: f64) -> f64 {
    ComplexField::cos(x)
}
pub(crate) fn atan2(y: f64, x: f64) -> f64 {
    RealField::atan2(y, x)
}
pub(crate) fn hypot(x: f64, y: f64) -> f64 {
    ComplexField::hypot(x, y)
}
pub(crate) fn abs(x: f64) -> f64 {
    ComplexField::abs(x)
}
pub(crate) fn floor(x: f64) -> f64 {
    ComplexField::floor(x)
}
pub(crate) fn ceil(x: f64) -> f64 {
    ComplexField::ceil(x)
}
pub(crate) fn round(x: f64) -> f64 {
    ComplexField::round(x)
}
/// Degrees to radians.
pub(crate) fn rad(deg: f64) -> f64 {
    deg * RAD_PER_DEG
}
/// Radians to degrees.
pub(crate) fn deg(rad: f64) -> f64 {
    rad / RAD_PER_DEG
}
/// `v` within `lo..=hi`, never panicking (unlike `f64::clamp`); NaN stays NaN.
pub(crate) fn bound(v: f64, lo: f64, hi: f64) -> f64 {
    if v < lo {
        lo
    } else if v > hi {
        hi
    } else {
        v
    }
}
/// `angle` in degrees brought into `[-180, 180)`.
pub(crate) fn wrap180(angle: f64) -> f64 {
    angle - 360.0 * floor((angle + 180.0) / 360.0)
}

/// Which of the two intersection points of two circles (seed 004 appendix 5.1).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Side {
    /// The seed's sign +1: the point to the left of the directed line from the first centre
    /// to the second (the first centre's ray to the second, turned counter-clockwise by θ).
    Left,
    /// The seed's sign −1: the point to the right of that line (turned clockwise by θ).
    Right,
}

impl Side {
    /// Both sides, left first.
    pub const BOTH: [Side; 2] = [Side::Left, Side::Right];

    /// The seed's sign: +1 for left, −1 for right.
    pub const fn sign(self) -> f64 {
        match self {
            Side::Left => 1.0,
            Side::Right => -1.0,
        }
    }
}

/// One intersection point of the circle of radius `r0` around `c0` with the circle of radius
/// `r1` around `c1`: seed 004's `CircleCircle_Intersection` (appendix 5.1).
///
/// With `l` the distance between the centres, the law of cosines gives the angle θ at `c0`
/// between the line to `c1` and the line to the intersection point:
/// `cos θ = (l² + r0² − r1²) / (2 l r0)`. The point where the first circle crosses the
/// segment `c0 → c1`, `c0 + (c1 − c0) r0 / l`, is rotated about `c0` by +θ ([`Side::Left`])
/// or −θ ([`Side::Right`]), with `sin θ = √(1 − cos² θ)` from the Pythagorean identity: the
/// angle itself is never computed.
///
/// `None` when the circles do not meet (`|cos θ| > 1`: too far apart, or one inside the
/// other), when the centres coincide (`l = 0`, the seed's division by zero) or when any input
/// is not finite. Tangent circles (`|cos θ| = 1`, within rounding) meet in one point, which
/// both sides return. (The seed's condition (7), `0 < cos θ < 1`, would also refuse an
/// obtuse θ, whose circles do meet; this follows the geometry, `−1 ≤ cos θ ≤ 1`.)
///
/// # Real-time
///
/// Constant time, no allocation, never panics.
pub fn circle_circle_intersection(
    c0: Vector2<f64>,
    r0: f64,
    c1: Vector2<f64>,
    r1: f64,
    side: Side,
) -> Option<Vector2<f64>> {
    let d = c1 - c0;
    let l = hypot(d.x, d.y);
    if l <= 0.0 || !l.is_finite() || !c0.x.is_finite() || !c0.y.is_finite() {
        return None;
    }
    let cos_theta = (l * l + r0 * r0 - r1 * r1) / (2.0 * l * r0);
    if cos_theta.is_nan() || abs(cos_theta) > 1.0 + TANGENT_SLACK {
        return None;
    }
    let cos_theta = bound(cos_theta, -1.0, 1.0);
    let sin_theta = side.sign() * sqrt(1.0 - cos_theta * cos_theta);
    let rotation = Rotation2::from_matrix_unchecked(Matrix2::new(
        cos_theta, -sin_theta, //
        sin_theta, cos_theta,
    ));
    let point = c0 + rotation * (d * (r0 / l));
    (point.x.is_finite() && point.y.is_finite()).then_some(point)
}

/// `a` × `b`, the z of the 3-D cross product: positive when `b` turns counter-clockwise from
/// `a`.
pub(crate) fn cross(a: Vector2<f64>, b: Vector2<f64>) -> f64 {
    a.x * b.y - a.y * b.x
}

/// The sine of the angle between `a` and `b` (0 when either is zero or not finite).
pub(crate) fn sine_between(a: Vector2<f64>, b: Vector2<f64>) -> f64 {
    let n = hypot(a.x, a.y) * hypot(b.x, b.y);
    let s = cross(a, b) / n;
    if s.is_finite() { s } else { 0.0 }
}
