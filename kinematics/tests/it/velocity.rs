//! Joint velocities: the jacobian's solution agrees with finite differences of the inverse
//! along a short Cartesian path, and near a singularity it is an error, not a panic.

use crate::common::{config, joints, pose};
use kinematics::user::polar::Polar;
use kinematics::{
    FiveBar, JointLimit, Joints, KinError, Kinematics, Pose, Scara, cartesian_to_axes,
    joint_velocity,
};
use proptest::prelude::*;

/// Moves along `p + v t` for t = ±h from `q` (inverse with `q` as reference) and compares
/// the central difference of the joints with `joint_velocity(q, v)`.
fn check_against_the_inverse(
    k: &dyn Kinematics,
    q: &Joints,
    v: &Pose,
) -> Result<(), TestCaseError> {
    const H: f64 = 1e-4; // s
    let n = k.joints();
    let limits = vec![JointLimit::NONE; n];
    let p = k
        .axes_to_cartesian(q)
        .map_err(|e| TestCaseError::reject(e.to_string()))?;
    let at = |t: f64| {
        let mut pt = p;
        for i in 0..k.coords().len() {
            pt[i] += v[i] * t;
        }
        cartesian_to_axes(k, &pt, q, &limits)
    };
    let (ahead, behind) = match (at(H), at(-H)) {
        (Ok(a), Ok(b)) => (a, b),
        _ => return Err(TestCaseError::reject("the short path leaves the workspace")),
    };
    let qdot = joint_velocity(k, q, v).map_err(|e| TestCaseError::fail(e.to_string()))?;
    let scale = 1.0 + (0..n).map(|i| qdot[i].abs()).fold(0.0, f64::max);
    for i in 0..n {
        let fd = (ahead[i] - behind[i]) / (2.0 * H);
        prop_assert!(
            (fd - qdot[i]).abs() <= 1e-3 * scale,
            "joint {i}: jacobian {} vs differences {fd} at {q:?}, v {v:?}",
            qdot[i]
        );
    }
    Ok(())
}

proptest! {
    #![proptest_config(config(500))]

    #[test]
    fn scara_joint_velocity_matches_the_inverse_along_a_path(
        j1 in -180.0..180.0f64, j2 in -170.0..170.0f64, j3 in -180.0..180.0f64,
        vx in -100.0..100.0f64, vy in -100.0..100.0f64, vt in -30.0..30.0f64,
    ) {
        prop_assume!(j2.to_radians().sin().abs() > 0.05);
        let k = Scara::new(250.0, 150.0).expect("valid");
        check_against_the_inverse(&k, &joints(&[j1, j2, j3]), &pose(&[vx, vy, vt]))?;
    }

    #[test]
    fn five_bar_joint_velocity_matches_the_inverse_along_a_path(
        a0 in -40.0..40.0f64, a1 in -40.0..40.0f64,
        vx in -100.0..100.0f64, vy in -100.0..100.0f64,
    ) {
        let k = FiveBar::seed();
        check_against_the_inverse(&k, &joints(&[a0, a1]), &pose(&[vx, vy]))?;
    }

    #[test]
    fn polar_joint_velocity_matches_the_inverse_along_a_path(
        phi in -180.0..180.0f64, r in 10.0..300.0f64,
        vx in -100.0..100.0f64, vy in -100.0..100.0f64,
    ) {
        let k = Polar::new(0.0).expect("valid");
        check_against_the_inverse(&k, &joints(&[phi, r]), &pose(&[vx, vy]))?;
    }
}

#[test]
fn near_a_singularity_joint_velocity_is_an_error() {
    let v = pose(&[10.0, 10.0, 0.0]);
    let scara = Scara::new(250.0, 150.0).expect("valid");
    for j2 in [0.0, 0.01, -0.05, 180.0, 179.99] {
        assert_eq!(
            joint_velocity(&scara, &joints(&[20.0, j2, 0.0]), &v),
            Err(KinError::Singular),
            "j2 = {j2}"
        );
    }
    let five_bar = FiveBar::seed();
    assert_eq!(
        joint_velocity(&five_bar, &joints(&[45.0, -45.0]), &v),
        Err(KinError::Singular)
    );
    assert_eq!(
        joint_velocity(&five_bar, &joints(&[45.01, -44.99]), &v),
        Err(KinError::Singular)
    );
    let polar = Polar::new(0.0).expect("valid");
    assert_eq!(
        joint_velocity(&polar, &joints(&[10.0, 0.0]), &v),
        Err(KinError::Singular)
    );
    assert_eq!(
        joint_velocity(&polar, &joints(&[10.0, 1e-3]), &v),
        Err(KinError::Singular)
    );
}
