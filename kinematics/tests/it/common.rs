//! Helpers shared by the tests: arrays from slices, distances, the brute-force nearest
//! solution, and the round-trip property every kinematics must satisfy.

use kinematics::{
    JointLimit, Joints, Kinematics, MAX_COORDS, MAX_JOINTS, Pose, Solutions, Unit,
    cartesian_to_axes,
};
use proptest::prelude::*;
use proptest::test_runner::{Config, RngSeed};

/// A proptest configuration with `cases` cases, a fixed seed (CI runs the same cases each
/// time; set `KINEMATICS_RANDOM_SEED=1` to explore) and no regression files.
pub fn config(cases: u32) -> Config {
    Config {
        cases,
        failure_persistence: None,
        rng_seed: if std::env::var_os("KINEMATICS_RANDOM_SEED").is_some() {
            RngSeed::Random
        } else {
            RngSeed::Fixed(0x5eed_0001)
        },
        ..Config::default()
    }
}

/// A joint position from its used values.
pub fn joints(values: &[f64]) -> Joints {
    let mut q = [0.0; MAX_JOINTS];
    q[..values.len()].copy_from_slice(values);
    q
}

/// A pose from its used values.
pub fn pose(values: &[f64]) -> Pose {
    let mut p = [0.0; MAX_COORDS];
    p[..values.len()].copy_from_slice(values);
    p
}

/// `angle` brought into [-180, 180).
pub fn wrap180(angle: f64) -> f64 {
    (angle + 180.0).rem_euclid(360.0) - 180.0
}

/// The largest difference between two poses' used coordinates; angles compare modulo 360°.
pub fn pose_error(k: &dyn Kinematics, a: &Pose, b: &Pose) -> f64 {
    k.coords()
        .iter()
        .enumerate()
        .map(|(i, c)| {
            let d = a[i] - b[i];
            if c.unit == Unit::Degree {
                wrap180(d).abs()
            } else {
                d.abs()
            }
        })
        .fold(0.0, f64::max)
}

/// Seed 001's metric: the Euclidean distance over the used joints.
pub fn distance(k: &dyn Kinematics, a: &Joints, b: &Joints) -> f64 {
    (0..k.joints())
        .map(|i| (a[i] - b[i]).powi(2))
        .sum::<f64>()
        .sqrt()
}

/// The nearest valid candidate by brute force: every solution, every wrapping joint at
/// every turn from -4 to +4, within the limits, not singular.
pub fn brute_force_nearest(
    k: &dyn Kinematics,
    p: &Pose,
    reference: &Joints,
    limits: &[JointLimit],
) -> Option<(f64, Joints)> {
    let mut solutions = Solutions::new();
    k.solutions(p, &mut solutions).ok()?;
    let n = k.joints();
    let mut best: Option<(f64, Joints)> = None;
    for solution in solutions.as_slice() {
        // Each joint's in-limit values.
        let choices: Vec<Vec<f64>> = (0..n)
            .map(|i| {
                let turns = if k.joint(i).wraps { -4..=4 } else { 0..=0 };
                turns
                    .map(|t| solution[i] + 360.0 * f64::from(t))
                    .filter(|v| limits[i].contains(*v))
                    .collect()
            })
            .collect();
        let mut index = vec![0usize; n];
        'product: loop {
            if choices.iter().any(Vec::is_empty) {
                break;
            }
            let mut q = [0.0; MAX_JOINTS];
            for i in 0..n {
                q[i] = choices[i][index[i]];
            }
            if !k.is_singular(&q) {
                let d = distance(k, &q, reference);
                if best.is_none_or(|(b, _)| d < b) {
                    best = Some((d, q));
                }
            }
            for i in 0..n {
                index[i] += 1;
                if index[i] < choices[i].len() {
                    continue 'product;
                }
                index[i] = 0;
            }
            break;
        }
    }
    best
}

/// Seed 001's rule for one sampled joint position `sample` (within `limits`, not
/// singular): the inverse of its pose with `reference` succeeds, its forward kinematics
/// gives the pose back within 1e-6, it lies within the limits, is not singular, and no
/// valid candidate is nearer the reference.
pub fn check_nearest_round_trip(
    k: &dyn Kinematics,
    sample: &Joints,
    reference: &Joints,
    limits: &[JointLimit],
) -> Result<(), TestCaseError> {
    let p = k
        .axes_to_cartesian(sample)
        .map_err(|e| TestCaseError::reject(format!("no pose: {e}")))?;
    let q = cartesian_to_axes(k, &p, reference, limits)
        .map_err(|e| TestCaseError::fail(format!("inverse of {p:?} from {sample:?}: {e}")))?;
    let back = k
        .axes_to_cartesian(&q)
        .map_err(|e| TestCaseError::fail(e.to_string()))?;
    let error = pose_error(k, &back, &p);
    prop_assert!(
        error < 1e-6,
        "forward(inverse(p)) misses p by {error}: {q:?} for {p:?}"
    );
    for i in 0..k.joints() {
        prop_assert!(
            limits[i].contains(q[i]),
            "joint {i} = {} outside {:?}",
            q[i],
            limits[i]
        );
    }
    prop_assert!(!k.is_singular(&q), "chose a singular {q:?}");
    let (best, best_q) = brute_force_nearest(k, &p, reference, limits)
        .ok_or_else(|| TestCaseError::fail("brute force found nothing"))?;
    let d = distance(k, &q, reference);
    prop_assert!(
        d <= best + 1e-9 * (1.0 + best),
        "chose {q:?} at {d} from {reference:?}, but {best_q:?} is at {best}"
    );
    Ok(())
}

/// A strategy for one joint value within `limit` (finite bounds).
pub fn within(limit: JointLimit) -> impl Strategy<Value = f64> {
    limit.min..=limit.max
}
