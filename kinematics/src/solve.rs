//! What every kinematics shares: seed 001's nearest-solution rule ([`cartesian_to_axes`]),
//! joint velocities ([`joint_velocity`]), and the trait's default jacobian and singularity
//! check.

use crate::math::{abs, bound, ceil, floor, round, wrap180};
use crate::{
    Jacobian, JointLimit, Joints, KinError, Kinematics, MAX_COORDS, MAX_JOINTS,
    SINGULARITY_TOLERANCE, Solutions, Unit, check_finite,
};
use nalgebra::{SMatrix, SVD, SVector};

/// The step of [`jacobian_by_differences`], in joint units (mm or degrees). Its truncation
/// error is of order step² (about 1e-6 relative for a 1e-3° step), its rounding error of
/// order 1e-16 × |coordinate| / step.
pub const FD_STEP: f64 = 1e-3;

/// How far outside its limits (joint units, mm or degrees) a solution's joint may come by
/// rounding and still count as within them; [`cartesian_to_axes`] then returns it on the
/// limit itself, so a result never leaves the limits. A pose taught at a joint limit
/// comes back from the inverse some 1e-14 beyond it.
pub const LIMIT_SLACK: f64 = 1e-9;

/// Seed 001's inverse (`LLI_reverseKine`): the joint position that reaches pose `p` nearest
/// `reference`, within `limits`.
///
/// Candidates are every solution of [`Kinematics::solutions`] and, for every joint that
/// [wraps](crate::JointInfo::wraps), every whole turn `angle + k·360°` of it. Since the
/// distance adds up joint by joint, the turn of each joint is chosen on its own: the one
/// nearest the reference's value among those within the joint's limits. A candidate is
/// dropped when a joint is outside its limits (`min <= value <= max`, inclusive, give or
/// take [`LIMIT_SLACK`]) or when it is [singular](Kinematics::is_singular); of the rest, the nearest wins, the first found on
/// a tie.
///
/// **The metric** is the Euclidean distance in joint units, `√Σ (qᵢ − refᵢ)²`, over the used
/// joints: one mm of a linear joint weighs as much as one degree of a rotary joint.
///
/// `limits` holds one entry per joint (entries past the last joint are ignored); an infinite
/// bound is no bound.
///
/// # Errors
///
/// - [`KinError::NotFinite`]: a used coordinate of `p` or joint of `reference` is not finite.
/// - [`KinError::LimitCount`], [`KinError::BadLimit`]: fewer limits than joints, or a limit
///   that is NaN or has `min > max`.
/// - Whatever [`Kinematics::solutions`] answers, e.g. [`KinError::OutOfReach`] when there is
///   no solution at all; [`KinError::NoSolution`] if it finds none without saying why.
/// - [`KinError::Singular`]: the only candidates within the limits are singular.
/// - [`KinError::JointLimit`]: no candidate is within the limits; it names the first joint
///   whose limit the nearest candidate breaks.
///
/// # Real-time
///
/// Called in trajgen's cycle: no allocation (the solutions live on the stack), bounded time
/// (at most [`MAX_SOLUTIONS`](crate::MAX_SOLUTIONS) candidates, no loop over turns), never a
/// panic.
pub fn cartesian_to_axes<K: Kinematics + ?Sized>(
    k: &K,
    p: &crate::Pose,
    reference: &Joints,
    limits: &[JointLimit],
) -> Result<Joints, KinError> {
    let n = k.joints().min(MAX_JOINTS);
    check_finite(p, k.coords().len(), "coordinate")?;
    check_finite(reference, n, "reference joint")?;
    if limits.len() < n {
        return Err(KinError::LimitCount {
            joints: n,
            limits: limits.len(),
        });
    }
    for (joint, limit) in limits.iter().take(n).enumerate() {
        if limit.min.is_nan() || limit.max.is_nan() || limit.min > limit.max {
            return Err(KinError::BadLimit {
                joint,
                min: limit.min,
                max: limit.max,
            });
        }
    }

    let mut solutions = Solutions::new();
    k.solutions(p, &mut solutions)?;
    if solutions.is_empty() {
        return Err(KinError::NoSolution {
            reason: "the kinematics found no joint position for this pose",
        });
    }

    let mut best: Option<(f64, Joints)> = None;
    let mut singular = false;
    // The nearest candidate that breaks a limit: (distance, joint, value, limit).
    let mut broken: Option<(f64, usize, f64, JointLimit)> = None;
    for solution in solutions.as_slice() {
        let mut q = [0.0; MAX_JOINTS];
        let mut distance2 = 0.0;
        let mut first_broken: Option<(usize, f64)> = None;
        for (i, ((value, slot), (limit, &r))) in solution
            .iter()
            .zip(q.iter_mut())
            .zip(limits.iter().zip(reference.iter()))
            .take(n)
            .enumerate()
        {
            let widened = JointLimit::new(limit.min - LIMIT_SLACK, limit.max + LIMIT_SLACK);
            let mut chosen = if k.joint(i).wraps {
                nearest_turn(*value, &widened, r)
            } else {
                *value
            };
            if widened.contains(chosen) {
                chosen = bound(chosen, limit.min, limit.max);
            } else if first_broken.is_none() {
                first_broken = Some((i, chosen));
            }
            *slot = chosen;
            distance2 += (chosen - r) * (chosen - r);
        }
        if !distance2.is_finite() {
            // A solution the kinematics computed badly (or a turn that overflowed): never
            // chosen, and not worth naming.
            continue;
        }
        if let Some((joint, value)) = first_broken {
            if broken.is_none_or(|(d, ..)| distance2 < d) {
                let limit = limits.get(joint).copied().unwrap_or(JointLimit::NONE);
                broken = Some((distance2, joint, value, limit));
            }
            continue;
        }
        if best.is_some_and(|(d, _)| distance2 >= d) {
            continue;
        }
        if k.is_singular(&q) {
            singular = true;
            continue;
        }
        best = Some((distance2, q));
    }

    match (best, singular, broken) {
        (Some((_, q)), _, _) => Ok(q),
        (None, true, _) => Err(KinError::Singular),
        (None, false, Some((_, joint, value, limit))) => Err(KinError::JointLimit {
            joint,
            value,
            min: limit.min,
            max: limit.max,
        }),
        (None, false, None) => Err(KinError::NoSolution {
            reason: "no candidate is finite (a solution or its distance overflows)",
        }),
    }
}

/// The whole turn `angle + k·360°` nearest `reference` within `limit` or, when no turn lies
/// within it (a range narrower than a turn), the turn nearest the range. Constant time: the
/// distance to the reference is convex in `k`, so the best `k` is the reference's nearest,
/// bounded to the turns within the limits.
fn nearest_turn(angle: f64, limit: &JointLimit, reference: f64) -> f64 {
    let k_reference = round((reference - angle) / 360.0);
    let k_low = ceil((limit.min - angle) / 360.0);
    let k_high = floor((limit.max - angle) / 360.0);
    if k_low <= k_high {
        return angle + 360.0 * bound(k_reference, k_low, k_high);
    }
    // No turn within the limits: angle + k_high·360 lies below min, angle + k_low·360 above
    // max; name the nearer.
    let below = angle + 360.0 * k_high;
    let above = angle + 360.0 * k_low;
    if limit.min - below <= above - limit.max {
        below
    } else {
        above
    }
}

/// Joint velocities `q̇` that move the pose at `cartesian_velocity` from joint position `q`:
/// the solution of `J(q) · q̇ = ẋ` (an LU decomposition of the jacobian). Units: each joint's
/// unit per second, for each coordinate's unit per second.
///
/// # Errors
///
/// [`KinError::NotFinite`] for a used input that is not finite; [`KinError::NotSquare`] when
/// the kinematics has fewer or more coordinates than joints; [`KinError::Singular`] when
/// `q` [is singular](Kinematics::is_singular) or the jacobian cannot be inverted; whatever
/// [`Kinematics::jacobian`] answers.
///
/// # Real-time
///
/// Called in trajgen's cycle: no allocation (fixed 8 × 8 matrices on the stack), constant
/// time, never a panic.
pub fn joint_velocity<K: Kinematics + ?Sized>(
    k: &K,
    q: &Joints,
    cartesian_velocity: &crate::Pose,
) -> Result<Joints, KinError> {
    let n = k.joints().min(MAX_JOINTS);
    let m = k.coords().len().min(MAX_COORDS);
    check_finite(q, n, "joint")?;
    check_finite(cartesian_velocity, m, "Cartesian velocity")?;
    if m != n {
        return Err(KinError::NotSquare {
            joints: n,
            coords: m,
        });
    }
    if k.is_singular(q) {
        return Err(KinError::Singular);
    }
    let j = k.jacobian(q)?;
    // The used n × n block, and the identity beside it so the 8 × 8 system stays regular.
    let mut a = SMatrix::<f64, MAX_JOINTS, MAX_JOINTS>::identity();
    let mut b = SVector::<f64, MAX_JOINTS>::zeros();
    for row in 0..n {
        for col in 0..n {
            a[(row, col)] = j[(row, col)];
        }
        b[row] = cartesian_velocity[row];
    }
    if a.iter().any(|v| !v.is_finite()) {
        return Err(KinError::Singular);
    }
    let Some(x) = a.lu().solve(&b) else {
        return Err(KinError::Singular);
    };
    let mut qdot = [0.0; MAX_JOINTS];
    for (slot, v) in qdot.iter_mut().zip(x.iter()).take(n) {
        *slot = *v;
    }
    check_finite(&qdot, n, "result").map_err(|_| KinError::Singular)?;
    Ok(qdot)
}

/// The jacobian by central differences of [`Kinematics::axes_to_cartesian`]: column `j` is
/// `(f(q + h eⱼ) − f(q − h eⱼ)) / 2h` with `h` = [`FD_STEP`]. The difference of an angle
/// coordinate is taken modulo 360° (within ±180°), so a forward kinematics that wraps θ
/// still gives the right slope. The default of [`Kinematics::jacobian`].
///
/// # Errors
///
/// [`KinError::NotFinite`] for a used joint that is not finite (or an entry that overflows);
/// whatever `axes_to_cartesian` answers at a step beside `q`.
///
/// # Real-time
///
/// 2 × joints forward computations, no allocation, never a panic.
pub fn jacobian_by_differences<K: Kinematics + ?Sized>(
    k: &K,
    q: &Joints,
) -> Result<Jacobian, KinError> {
    let n = k.joints().min(MAX_JOINTS);
    let coords = k.coords();
    check_finite(q, n, "joint")?;
    let mut jacobian = Jacobian::zeros();
    for col in 0..n {
        let mut plus = *q;
        let mut minus = *q;
        plus[col] += FD_STEP;
        minus[col] -= FD_STEP;
        let forward = k.axes_to_cartesian(&plus)?;
        let backward = k.axes_to_cartesian(&minus)?;
        for (row, coord) in coords.iter().take(MAX_COORDS).enumerate() {
            let mut d = forward[row] - backward[row];
            if coord.unit == Unit::Degree {
                d = wrap180(d);
            }
            let entry = d / (2.0 * FD_STEP);
            if !entry.is_finite() {
                return Err(KinError::NotFinite {
                    what: "jacobian entry",
                    index: col * MAX_COORDS + row,
                    value: entry,
                });
            }
            jacobian[(row, col)] = entry;
        }
    }
    Ok(jacobian)
}

/// Whether the jacobian at `q` has lost rank: its used `coords × joints` block's
/// `min(coords, joints)`-th singular value is at most [`SINGULARITY_TOLERANCE`] times its
/// largest (a condition number of 1000 or more). True too when the jacobian cannot be
/// computed (no pose at or beside `q`, a joint not finite). The default of
/// [`Kinematics::is_singular`].
///
/// The ratio mixes units (mm and degrees weigh alike), so a kinematics whose singularities
/// have a geometric meaning does better to say so analytically, as [`Scara`](crate::Scara)
/// and [`FiveBar`](crate::FiveBar) do.
///
/// # Real-time
///
/// A jacobian and a 6 × 8 SVD (at most 100 iterations) on the stack: no allocation, never a
/// panic.
pub fn singular_by_jacobian<K: Kinematics + ?Sized>(k: &K, q: &Joints) -> bool {
    let n = k.joints().min(MAX_JOINTS);
    let m = k.coords().len().min(MAX_COORDS);
    let rank = n.min(m);
    if rank == 0 {
        return false;
    }
    let Ok(j) = k.jacobian(q) else {
        return true;
    };
    let mut used = Jacobian::zeros();
    for row in 0..m {
        for col in 0..n {
            used[(row, col)] = j[(row, col)];
        }
    }
    if used.iter().any(|v| !v.is_finite()) {
        return true;
    }
    let Some(svd) = SVD::try_new_unordered(used, false, false, f64::EPSILON, 100) else {
        return true;
    };
    let mut sigma = [0.0; MAX_COORDS];
    for (slot, s) in sigma.iter_mut().zip(svd.singular_values.iter()) {
        *slot = abs(*s);
    }
    // Descending; the zeros of the unused rows and columns sort last.
    sigma.sort_unstable_by(|a, b| b.total_cmp(a));
    let largest = sigma[0];
    let smallest_used = sigma.get(rank - 1).copied().unwrap_or(0.0);
    !(largest > 0.0 && smallest_used > SINGULARITY_TOLERANCE * largest)
}
