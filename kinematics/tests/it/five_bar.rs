//! Seed 004's five-bar (type 12): the seed's null posture by hand, the seed's inverse branch,
//! seed 001's rule across the workspace in both assembly modes, reach, assembly, singularity.

use crate::common::{
    brute_force_nearest, check_nearest_round_trip, config, joints, pose, within, wrap180,
};
use kinematics::{
    FiveBar, JointLimit, KinError, Kinematics, ParamError, Side, Solutions, cartesian_to_axes,
    circle_circle_intersection,
};
use nalgebra::Vector2;
use proptest::prelude::*;

/// The example cell's limits for the seed's mechanism (docs/kinematics.md): |a0 - a1| stays
/// 10 degrees short of the parallelogram's singularity at 90 degrees.
const SEED_LIMITS: [JointLimit; 2] = [JointLimit::new(-40.0, 40.0), JointLimit::new(-40.0, 40.0)];

/// A general (not parallelogram) five-bar, and limits wide enough to cross branches.
fn general(assembly: Side) -> FiveBar {
    FiveBar::new(200.0, 150.0, 100.0, 220.0, 120.0, assembly).expect("closes")
}
const GENERAL_LIMITS: [JointLimit; 2] = [
    JointLimit::new(-180.0, 180.0),
    JointLimit::new(-180.0, 180.0),
];

/// The seed's `CartesianToAxes`, literally: T with sign -1, W with sign +1, angles into
/// [-180, 180).
fn seed_cartesian_to_axes(k: &FiveBar, x: f64, y: f64) -> Option<(f64, f64)> {
    let [l1, l2, l3, l4, l5] = k.lengths();
    let tcp = Vector2::new(x, y);
    let t = circle_circle_intersection(Vector2::zeros(), l1, tcp, l2, Side::Right)?;
    let a0 = wrap180(t.y.atan2(t.x).to_degrees() - 180.0);
    let e = t + (tcp - t) * (l3 / l2);
    let w = circle_circle_intersection(Vector2::zeros(), l5, e, l4, Side::Left)?;
    let a1 = wrap180(w.y.atan2(w.x).to_degrees() - 270.0);
    Some((a0, a1))
}

#[test]
fn the_seeds_null_posture_matches_a_hand_computation() {
    // a0 = a1 = 0 with L1..L5 = 200, 150, 100, 200, 100:
    //   T = 200 (cos 180°, sin 180°) = (-200, 0)
    //   W = 100 (cos 270°, sin 270°) = (0, -100)
    //   |W - T| = sqrt(200² + 100²) = 223.607
    //   cos θ = (223.607² + 100² - 200²) / (2 · 223.607 · 100) = 20000 / 44721.4 = 0.447214
    //   sin θ = 0.894427
    //   T + (W - T) · 100 / 223.607 - T = (89.443, -44.721), turned by -θ (sign -1):
    //     (0.447214 · 89.443 + 0.894427 · -44.721, -0.894427 · 89.443 + 0.447214 · -44.721)
    //     = (0, -100)
    //   E = T + (0, -100) = (-200, -100)
    //   TCP = T + (E - T) · 150 / 100 = (-200, -150)
    let k = FiveBar::seed();
    let points = k.points(&joints(&[0.0, 0.0])).expect("assembles");
    let close = |v: Vector2<f64>, x: f64, y: f64| (v.x - x).abs() < 1e-9 && (v.y - y).abs() < 1e-9;
    assert!(close(points.t, -200.0, 0.0), "T = {}", points.t);
    assert!(close(points.w, 0.0, -100.0), "W = {}", points.w);
    assert!(close(points.e, -200.0, -100.0), "E = {}", points.e);
    assert!(close(points.tcp, -200.0, -150.0), "TCP = {}", points.tcp);
    let p = k
        .axes_to_cartesian(&joints(&[0.0, 0.0]))
        .expect("assembles");
    assert!(
        (p[0] + 200.0).abs() < 1e-9 && (p[1] + 150.0).abs() < 1e-9,
        "{p:?}"
    );
}

#[test]
fn the_seeds_inverse_of_the_null_posture_is_the_null_posture() {
    let k = FiveBar::seed();
    let (a0, a1) = seed_cartesian_to_axes(&k, -200.0, -150.0).expect("reachable");
    assert!(a0.abs() < 1e-9 && a1.abs() < 1e-9, "({a0}, {a1})");
    let q = cartesian_to_axes(
        &k,
        &pose(&[-200.0, -150.0]),
        &joints(&[0.0, 0.0]),
        &SEED_LIMITS,
    )
    .expect("reachable");
    assert!(q[0].abs() < 1e-9 && q[1].abs() < 1e-9, "{q:?}");
}

proptest! {
    #![proptest_config(config(1000))]

    #[test]
    fn the_inverse_reproduces_the_seeds_branch_near_the_null_posture(
        a0 in -30.0..30.0f64,
        a1 in -30.0..30.0f64,
        r0 in -5.0..5.0f64,
        r1 in -5.0..5.0f64,
    ) {
        let k = FiveBar::seed();
        let p = k.axes_to_cartesian(&joints(&[a0, a1])).expect("assembles near null");
        let (s0, s1) = seed_cartesian_to_axes(&k, p[0], p[1]).expect("the seed reaches it");
        let reference = joints(&[r0, r1]);
        let (_, nearest) = brute_force_nearest(&k, &p, &reference, &GENERAL_LIMITS)
            .expect("a valid solution");
        // Near the null posture the seed's branch is the nearest valid solution (brute
        // force), and ours is the seed's.
        prop_assert!((nearest[0] - s0).abs() < 1e-6 && (nearest[1] - s1).abs() < 1e-6,
            "the seed's ({s0}, {s1}) is not the nearest {nearest:?}");
        let q = cartesian_to_axes(&k, &p, &reference, &GENERAL_LIMITS).expect("solution");
        prop_assert!((q[0] - s0).abs() < 1e-9 && (q[1] - s1).abs() < 1e-9,
            "ours {q:?}, the seed's ({s0}, {s1})");
        // ... and both are the sampled posture.
        prop_assert!((q[0] - a0).abs() < 1e-9 && (q[1] - a1).abs() < 1e-9);
    }

    #[test]
    fn seed_mechanism_inverse_round_trips_and_is_the_nearest_valid_solution(
        a0 in within(SEED_LIMITS[0]),
        a1 in within(SEED_LIMITS[1]),
        r0 in -60.0..60.0f64,
        r1 in -60.0..60.0f64,
    ) {
        let k = FiveBar::seed();
        check_nearest_round_trip(&k, &joints(&[a0, a1]), &joints(&[r0, r1]), &SEED_LIMITS)?;
    }

    #[test]
    fn general_mechanism_inverse_round_trips_in_both_assembly_modes(
        a0 in within(GENERAL_LIMITS[0]),
        a1 in within(GENERAL_LIMITS[1]),
        r0 in -200.0..200.0f64,
        r1 in -200.0..200.0f64,
        left in any::<bool>(),
    ) {
        let k = general(if left { Side::Left } else { Side::Right });
        let sample = joints(&[a0, a1]);
        prop_assume!(k.axes_to_cartesian(&sample).is_ok() && !k.is_singular(&sample));
        check_nearest_round_trip(&k, &sample, &joints(&[r0, r1]), &GENERAL_LIMITS)?;
    }
}

#[test]
fn every_solution_belongs_to_the_configured_assembly_mode() {
    for side in Side::BOTH {
        let k = general(side);
        let p = k
            .axes_to_cartesian(&joints(&[10.0, -20.0]))
            .expect("assembles");
        let mut s = Solutions::new();
        k.solutions(&p, &mut s).expect("reachable");
        assert!(!s.is_empty());
        for q in s.as_slice() {
            let back = k.axes_to_cartesian(q).expect("assembles");
            assert!((back[0] - p[0]).abs() < 1e-6 && (back[1] - p[1]).abs() < 1e-6);
        }
    }
}

#[test]
fn a_pose_beyond_the_cranks_is_out_of_reach() {
    let k = FiveBar::seed();
    let err = cartesian_to_axes(&k, &pose(&[400.0, 0.0]), &joints(&[]), &SEED_LIMITS)
        .expect_err("beyond L1 + L2");
    assert_eq!(
        err,
        KinError::OutOfReach {
            what: "the TCP's distance from the base",
            distance: 400.0,
            min: 50.0,
            max: 350.0,
        }
    );
    let err = cartesian_to_axes(&k, &pose(&[0.0, 10.0]), &joints(&[]), &SEED_LIMITS)
        .expect_err("inside |L1 - L2|");
    assert!(
        matches!(err, KinError::OutOfReach { distance: 10.0, .. }),
        "{err:?}"
    );
}

#[test]
fn joints_whose_links_cannot_meet_do_not_assemble() {
    // a0 = a1 + 90: T and W point the same way, 200 - 120 = 80 mm apart; L3 and L4 join
    // only 120 to 320 mm.
    let k = general(Side::Right);
    let err = k
        .axes_to_cartesian(&joints(&[90.0, 0.0]))
        .expect_err("cannot assemble");
    match err {
        KinError::CannotAssemble {
            distance, min, max, ..
        } => {
            assert!(
                (distance - 80.0).abs() < 1e-9 && min == 120.0 && max == 320.0,
                "{err}"
            );
        }
        other => panic!("expected CannotAssemble, got {other:?}"),
    }
    assert!(
        k.is_singular(&joints(&[90.0, 0.0])),
        "no pose counts as singular"
    );
}

#[test]
fn the_parallelogram_is_singular_where_its_cranks_line_up() {
    let k = FiveBar::seed();
    assert!(k.is_singular(&joints(&[45.0, -45.0])));
    assert!(k.is_singular(&joints(&[-45.0, 45.0])));
    assert!(!k.is_singular(&joints(&[40.0, -40.0])));
    assert!(!k.is_singular(&joints(&[0.0, 0.0])));
}

#[test]
fn a_five_bar_that_can_never_close_is_refused() {
    let err = FiveBar::new(10.0, 150.0, 100.0, 300.0, 10.0, Side::Right).expect_err("no close");
    assert_eq!(
        err,
        ParamError::CannotClose {
            crank_min: 0.0,
            crank_max: 20.0,
            link_min: 200.0,
            link_max: 400.0
        }
    );
    assert!(err.to_string().contains("can never close"), "{err}");
    let err = FiveBar::new(200.0, 150.0, 0.0, 200.0, 100.0, Side::Right).expect_err("l3 = 0");
    assert_eq!(
        err,
        ParamError::NotPositive {
            name: "l3",
            value: 0.0
        }
    );
}

#[test]
fn the_seeds_default_workspace() {
    // The reachable workspace of the example cell (docs/kinematics.md): the image of
    // |a0|, |a1| <= 40, every pose of it reached back, and its extent.
    let k = FiveBar::seed();
    let (mut min_x, mut max_x, mut min_y, mut max_y) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    let (mut min_r, mut max_r) = (f64::MAX, f64::MIN);
    for i in 0..=80 {
        for j in 0..=80 {
            let q = joints(&[f64::from(i) - 40.0, f64::from(j) - 40.0]);
            let p = k
                .axes_to_cartesian(&q)
                .expect("assembles within the limits");
            assert!(!k.is_singular(&q));
            let back = cartesian_to_axes(&k, &p, &q, &SEED_LIMITS).expect("reached back");
            assert!((back[0] - q[0]).abs() < 1e-9 && (back[1] - q[1]).abs() < 1e-9);
            min_x = min_x.min(p[0]);
            max_x = max_x.max(p[0]);
            min_y = min_y.min(p[1]);
            max_y = max_y.max(p[1]);
            let r = p[0].hypot(p[1]);
            min_r = min_r.min(r);
            max_r = max_r.max(r);
        }
    }
    println!("x {min_x:.1}..{max_x:.1}, y {min_y:.1}..{max_y:.1}, r {min_r:.1}..{max_r:.1}");
    assert!(min_r > 50.0 && max_r < 350.0);
}
