//! The SCARA: seed 001's rule across its workspace, both elbows, reach, limits, singularity.

use crate::common::{check_nearest_round_trip, config, joints, pose, pose_error, within};
use kinematics::{JointLimit, KinError, Kinematics, Scara, Solutions, cartesian_to_axes};
use proptest::prelude::*;

const LIMITS: [JointLimit; 3] = [
    JointLimit::new(-170.0, 170.0),
    JointLimit::new(-150.0, 150.0),
    JointLimit::new(-360.0, 360.0),
];

fn arm() -> Scara {
    Scara::new(250.0, 150.0).expect("valid lengths")
}

proptest! {
    #![proptest_config(config(1500))]

    #[test]
    fn inverse_round_trips_and_is_the_nearest_valid_solution(
        j1 in within(LIMITS[0]),
        j2 in within(LIMITS[1]),
        j3 in within(LIMITS[2]),
        r1 in -200.0..200.0f64,
        r2 in -200.0..200.0f64,
        r3 in -400.0..400.0f64,
    ) {
        let k = arm();
        let sample = joints(&[j1, j2, j3]);
        prop_assume!(j2.to_radians().sin().abs() > 0.01);
        check_nearest_round_trip(&k, &sample, &joints(&[r1, r2, r3]), &LIMITS)?;
    }
}

#[test]
fn both_elbows_are_solutions() {
    let k = arm();
    let p = k
        .axes_to_cartesian(&joints(&[30.0, 60.0, 10.0]))
        .expect("a pose");
    let mut s = Solutions::new();
    k.solutions(&p, &mut s).expect("reachable");
    assert_eq!(s.len(), 2);
    let mut elbows: Vec<f64> = s.as_slice().iter().map(|q| q[1]).collect();
    elbows.sort_by(f64::total_cmp);
    assert!(
        (elbows[0] + 60.0).abs() < 1e-9 && (elbows[1] - 60.0).abs() < 1e-9,
        "{elbows:?}"
    );
    for q in s.as_slice() {
        let back = k.axes_to_cartesian(q).expect("a pose");
        assert!(pose_error(&k, &back, &p) < 1e-9);
    }
}

#[test]
fn the_reference_chooses_the_elbow() {
    let k = arm();
    let up = joints(&[30.0, 60.0, 10.0]);
    let p = k.axes_to_cartesian(&up).expect("a pose");
    let q = cartesian_to_axes(&k, &p, &joints(&[20.0, 50.0, 0.0]), &LIMITS).expect("solution");
    assert!((q[1] - 60.0).abs() < 1e-9, "{q:?}");
    // The other elbow: j1 turned by the shoulder angle, j2 negative.
    let q = cartesian_to_axes(&k, &p, &joints(&[60.0, -50.0, 0.0]), &LIMITS).expect("solution");
    assert!((q[1] + 60.0).abs() < 1e-9, "{q:?}");
}

#[test]
fn a_point_beyond_reach_names_its_distance_and_the_reach() {
    let k = arm();
    let err = cartesian_to_axes(&k, &pose(&[410.0, 0.0, 0.0]), &joints(&[]), &LIMITS)
        .expect_err("beyond reach");
    assert_eq!(
        err,
        KinError::OutOfReach {
            what: "the tool's distance from the shoulder",
            distance: 410.0,
            min: 100.0,
            max: 400.0,
        }
    );
    let message = err.to_string();
    assert!(
        message.contains("410") && message.contains("100 to 400"),
        "{message}"
    );
    // Inside the hole |l1 - l2| too.
    let err = cartesian_to_axes(&k, &pose(&[0.0, 50.0, 0.0]), &joints(&[]), &LIMITS)
        .expect_err("inside the hole");
    assert!(
        matches!(err, KinError::OutOfReach { distance: 50.0, .. }),
        "{err:?}"
    );
}

#[test]
fn a_limit_that_excludes_one_elbow_picks_the_other() {
    let k = arm();
    let p = k
        .axes_to_cartesian(&joints(&[30.0, 60.0, 10.0]))
        .expect("a pose");
    // The reference sits at the positive elbow, but the elbow may only bend negative.
    let limits = [LIMITS[0], JointLimit::new(-150.0, 0.0), LIMITS[2]];
    let q = cartesian_to_axes(&k, &p, &joints(&[30.0, 60.0, 10.0]), &limits).expect("other");
    assert!((q[1] + 60.0).abs() < 1e-9, "{q:?}");
    let back = k.axes_to_cartesian(&q).expect("a pose");
    assert!(pose_error(&k, &back, &p) < 1e-9);
}

#[test]
fn limits_that_exclude_both_elbows_name_the_nearest_ones_broken_limit() {
    let k = arm();
    let p = k
        .axes_to_cartesian(&joints(&[30.0, 60.0, 10.0]))
        .expect("a pose");
    let limits = [LIMITS[0], JointLimit::new(-10.0, 10.0), LIMITS[2]];
    let err = cartesian_to_axes(&k, &p, &joints(&[30.0, 60.0, 10.0]), &limits)
        .expect_err("both elbows excluded");
    match err {
        KinError::JointLimit {
            joint: 1,
            value,
            min: -10.0,
            max: 10.0,
        } => {
            assert!((value - 60.0).abs() < 1e-9, "{err}");
        }
        other => panic!("expected a limit on joint 1, got {other:?}"),
    }
}

#[test]
fn the_stretched_and_folded_arm_is_singular() {
    let k = arm();
    assert!(k.is_singular(&joints(&[10.0, 0.0, 0.0])));
    assert!(k.is_singular(&joints(&[10.0, 180.0, 0.0])));
    assert!(
        k.is_singular(&joints(&[10.0, 0.05, 0.0])),
        "within 0.057 degrees"
    );
    assert!(!k.is_singular(&joints(&[10.0, 0.1, 0.0])));
    let err = cartesian_to_axes(&k, &pose(&[400.0, 0.0, 0.0]), &joints(&[]), &LIMITS)
        .expect_err("stretched");
    assert_eq!(err, KinError::Singular);
}

#[test]
fn rotary_joints_take_the_turn_nearest_the_reference_within_the_limits() {
    let k = arm();
    let p = k
        .axes_to_cartesian(&joints(&[30.0, 60.0, 10.0]))
        .expect("a pose");
    // One elbow only, so that j3's turn decides alone.
    let limits = [LIMITS[0], JointLimit::new(0.0, 150.0), LIMITS[2]];
    // j3 = 10 + k 360: -350 is nearest -300.
    let q = cartesian_to_axes(&k, &p, &joints(&[30.0, 60.0, -300.0]), &limits).expect("one");
    assert!((q[2] + 350.0).abs() < 1e-9, "j3 = {}", q[2]);
    // 370 would be nearest 300, but the limit is 360: 10.
    let q = cartesian_to_axes(&k, &p, &joints(&[30.0, 60.0, 300.0]), &limits).expect("one");
    assert!((q[2] - 10.0).abs() < 1e-9, "j3 = {}", q[2]);
    let wide = [LIMITS[0], limits[1], JointLimit::new(-720.0, 720.0)];
    let q = cartesian_to_axes(&k, &p, &joints(&[30.0, 60.0, 300.0]), &wide).expect("one");
    assert!((q[2] - 370.0).abs() < 1e-9, "j3 = {}", q[2]);
}
