//! Garbage in (NaN, infinities, huge and tiny values): an error out, never a panic, and
//! never a result that is not finite.

use crate::common::config;
use kinematics::{
    JointLimit, Joints, KinError, MAX_COORDS, MAX_JOINTS, Params, Pose, REGISTRY, Solutions, build,
    cartesian_to_axes, joint_velocity,
};
use proptest::prelude::*;

/// The values that break arithmetic.
const SPECIAL: [f64; 8] = [
    f64::NAN,
    f64::INFINITY,
    f64::NEG_INFINITY,
    f64::MAX,
    -f64::MAX,
    0.0,
    f64::MIN_POSITIVE,
    -1e300,
];

/// `n` of any f64, weighted towards the values that break arithmetic (in a vector: arrays
/// of a union strategy overflow a debug build's test stack).
fn garbage(n: usize) -> impl Strategy<Value = Vec<f64>> {
    let one = prop_oneof![
        3 => any::<f64>(),
        3 => prop::sample::select(&SPECIAL[..]),
        3 => -1e3..1e3f64,
        1 => -1e300..1e300f64,
    ];
    prop::collection::vec(one, n)
}

fn array<const N: usize>(values: &[f64]) -> [f64; N] {
    let mut a = [0.0; N];
    a.copy_from_slice(values);
    a
}

/// Every registered kinematics, built from its example parameters.
fn every_kinematics() -> Vec<kinematics::Boxed> {
    REGISTRY
        .iter()
        .map(|e| e.build_example().expect("the example builds"))
        .collect()
}

fn all_finite(values: &[f64]) -> bool {
    values.iter().all(|v| v.is_finite())
}

proptest! {
    #![proptest_config(config(2000))]

    #[test]
    fn garbage_gives_errors_never_panics(values in garbage(MAX_JOINTS * 4 + MAX_COORDS)) {
        let (q, rest) = values.split_at(MAX_JOINTS);
        let (p, rest) = rest.split_at(MAX_COORDS);
        let (reference, bounds) = rest.split_at(MAX_JOINTS);
        let q: Joints = array(q);
        let p: Pose = array(p);
        let reference: Joints = array(reference);
        let limits: Vec<JointLimit> =
            bounds.chunks(2).map(|b| JointLimit::new(b[0], b[1])).collect();
        for k in every_kinematics() {
            let (n, m) = (k.joints(), k.coords().len());
            match k.axes_to_cartesian(&q) {
                Ok(pose) => {
                    prop_assert!(all_finite(&q[..n]), "{}: a pose from non-finite joints", k.name());
                    prop_assert!(all_finite(&pose[..m]), "{}: a non-finite pose", k.name());
                }
                Err(e) => prop_assert!(!e.to_string().is_empty()),
            }
            let mut s = Solutions::new();
            if k.solutions(&p, &mut s).is_ok() {
                prop_assert!(all_finite(&p[..m]), "{}: solutions of a non-finite pose", k.name());
            }
            let _ = k.is_singular(&q);
            if let Ok(j) = k.jacobian(&q) {
                prop_assert!(all_finite(j.as_slice()), "{}: a non-finite jacobian", k.name());
            }
            match cartesian_to_axes(&*k, &p, &reference, &limits) {
                Ok(solution) => {
                    prop_assert!(all_finite(&p[..m]) && all_finite(&reference[..n]));
                    prop_assert!(all_finite(&solution[..n]));
                    for i in 0..n {
                        prop_assert!(limits[i].contains(solution[i]));
                    }
                }
                Err(KinError::NotFinite { .. }) => {}
                Err(_) => prop_assert!(all_finite(&p[..m]) && all_finite(&reference[..n])),
            }
            if let Ok(v) = joint_velocity(&*k, &q, &p) {
                prop_assert!(all_finite(&q[..n]) && all_finite(&p[..m]) && all_finite(&v[..n]));
            }
        }
    }
}

#[test]
fn a_non_finite_input_is_named() {
    let k = build("scara", &Params(&[("l1", 250.0), ("l2", 150.0)])).expect("scara");
    let mut q = [0.0; MAX_JOINTS];
    q[1] = f64::NAN;
    let err = k.axes_to_cartesian(&q).expect_err("NaN");
    assert!(
        matches!(err, KinError::NotFinite { what: "joint", index: 1, value } if value.is_nan()),
        "{err:?}"
    );
    let mut p = [0.0; MAX_COORDS];
    p[0] = 300.0;
    p[2] = f64::INFINITY;
    let limits = [JointLimit::NONE; 3];
    let err = cartesian_to_axes(&*k, &p, &[0.0; MAX_JOINTS], &limits).expect_err("inf");
    assert_eq!(
        err,
        KinError::NotFinite {
            what: "coordinate",
            index: 2,
            value: f64::INFINITY
        }
    );
    assert!(err.to_string().contains("coordinate 2 is inf"), "{err}");
    // Entries past the used ones are never read.
    let mut p = [f64::NAN; MAX_COORDS];
    p[..3].copy_from_slice(&[300.0, 0.0, 0.0]);
    assert!(cartesian_to_axes(&*k, &p, &[0.0; MAX_JOINTS], &limits).is_ok());
}

#[test]
fn bad_limits_are_refused() {
    let k = build("scara", &Params(&[("l1", 250.0), ("l2", 150.0)])).expect("scara");
    let p = [300.0, 0.0, 0.0, 0.0, 0.0, 0.0];
    let err = cartesian_to_axes(&*k, &p, &[0.0; MAX_JOINTS], &[JointLimit::NONE; 2])
        .expect_err("two limits for three joints");
    assert_eq!(
        err,
        KinError::LimitCount {
            joints: 3,
            limits: 2
        }
    );
    let limits = [
        JointLimit::NONE,
        JointLimit::new(10.0, -10.0),
        JointLimit::NONE,
    ];
    let err = cartesian_to_axes(&*k, &p, &[0.0; MAX_JOINTS], &limits).expect_err("min > max");
    assert_eq!(
        err,
        KinError::BadLimit {
            joint: 1,
            min: 10.0,
            max: -10.0
        }
    );
}
