//! The gantry: the identity, as today's cell behaves.

use crate::common::{check_nearest_round_trip, config, joints, pose, within};
use kinematics::{Gantry, JointLimit, KinError, Kinematics, cartesian_to_axes, joint_velocity};
use proptest::prelude::*;

/// The default cell's axes (examples/gantry-uba.toml).
const LIMITS: [JointLimit; 3] = [
    JointLimit::new(0.0, 200.0),
    JointLimit::new(0.0, 150.0),
    JointLimit::new(-180.0, 180.0),
];

proptest! {
    #![proptest_config(config(500))]

    #[test]
    fn inverse_is_the_identity_and_the_nearest_valid_solution(
        x in within(LIMITS[0]),
        y in within(LIMITS[1]),
        theta in within(LIMITS[2]),
        rx in -50.0..250.0f64,
        ry in -50.0..200.0f64,
        rt in -400.0..400.0f64,
    ) {
        let k = Gantry::new(3).expect("3 axes");
        let reference = joints(&[rx, ry, rt]);
        check_nearest_round_trip(&k, &joints(&[x, y, theta]), &reference, &LIMITS)?;
        let q = cartesian_to_axes(&k, &pose(&[x, y, theta]), &reference, &LIMITS)
            .expect("within limits");
        prop_assert_eq!(&q[..3], &[x, y, theta][..], "exactly the identity");
        let v = joint_velocity(&k, &q, &pose(&[rx, ry, rt])).expect("never singular");
        prop_assert_eq!(&v[..3], &[rx, ry, rt][..]);
    }
}

#[test]
fn theta_never_wraps_so_a_program_keeps_todays_meaning() {
    let k = Gantry::new(3).expect("3 axes");
    // θ = 190 is outside -180..180: refused, not turned into -170 as a wrapping joint would.
    let err = cartesian_to_axes(
        &k,
        &pose(&[40.0, 40.0, 190.0]),
        &joints(&[40.0, 40.0, 0.0]),
        &LIMITS,
    )
    .expect_err("outside the limits");
    assert_eq!(
        err,
        KinError::JointLimit {
            joint: 2,
            value: 190.0,
            min: -180.0,
            max: 180.0
        }
    );
    // And with the reference at -170, θ = 170 stays 170.
    let q = cartesian_to_axes(
        &k,
        &pose(&[40.0, 40.0, 170.0]),
        &joints(&[40.0, 40.0, -170.0]),
        &LIMITS,
    )
    .expect("within");
    assert_eq!(q[2], 170.0);
}

#[test]
fn a_gantry_takes_one_to_three_axes() {
    for axes in 1..=3 {
        let k = Gantry::new(axes).expect("valid");
        assert_eq!(k.joints(), axes);
        assert_eq!(k.coords().len(), axes);
    }
    assert!(Gantry::new(0).is_err());
    assert!(Gantry::new(4).is_err());
    assert_eq!(Gantry::new(2).expect("valid").coords()[1].name, "y");
}
