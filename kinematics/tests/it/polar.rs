//! The user-defined example, a polar arm: seed 001's rule through the trait's default
//! jacobian and singularity check.

use crate::common::{check_nearest_round_trip, config, joints, pose, within};
use kinematics::user::polar::Polar;
use kinematics::{JointLimit, KinError, Kinematics, cartesian_to_axes};
use proptest::prelude::*;

/// The radial joint may pass through the pole, so both solutions can be valid.
const LIMITS: [JointLimit; 2] = [
    JointLimit::new(-270.0, 270.0),
    JointLimit::new(-300.0, 300.0),
];

proptest! {
    #![proptest_config(config(1000))]

    #[test]
    fn inverse_round_trips_and_is_the_nearest_valid_solution(
        phi in within(LIMITS[0]),
        r in within(LIMITS[1]),
        rphi in -300.0..300.0f64,
        rr in -320.0..320.0f64,
        offset in -50.0..50.0f64,
    ) {
        let k = Polar::new(offset).expect("finite");
        let sample = joints(&[phi, r]);
        prop_assume!((offset + r).abs() > 1.0);
        check_nearest_round_trip(&k, &sample, &joints(&[rphi, rr]), &LIMITS)?;
    }
}

#[test]
fn the_reference_chooses_whether_to_reach_through_the_pole() {
    let k = Polar::new(0.0).expect("finite");
    let p = pose(&[0.0, 100.0]);
    let q = cartesian_to_axes(&k, &p, &joints(&[80.0, 90.0]), &LIMITS).expect("reachable");
    assert!(
        (q[0] - 90.0).abs() < 1e-9 && (q[1] - 100.0).abs() < 1e-9,
        "{q:?}"
    );
    let q = cartesian_to_axes(&k, &p, &joints(&[-80.0, -90.0]), &LIMITS).expect("reachable");
    assert!(
        (q[0] + 90.0).abs() < 1e-9 && (q[1] + 100.0).abs() < 1e-9,
        "{q:?}"
    );
    // A radial joint that cannot go negative leaves only the direct one.
    let limits = [LIMITS[0], JointLimit::new(0.0, 300.0)];
    let q = cartesian_to_axes(&k, &p, &joints(&[-80.0, -90.0]), &limits).expect("reachable");
    assert!((q[1] - 100.0).abs() < 1e-9, "{q:?}");
}

#[test]
fn the_pole_is_singular_by_the_default_check() {
    let k = Polar::new(0.0).expect("finite");
    assert!(k.is_singular(&joints(&[30.0, 0.0])));
    assert!(!k.is_singular(&joints(&[30.0, 10.0])));
    let err = cartesian_to_axes(&k, &pose(&[0.0, 0.0]), &joints(&[]), &LIMITS).expect_err("pole");
    assert_eq!(err, KinError::Singular);
}
