use cell_config::stability::*;

#[test]
fn a_pd_loop_is_stable_with_sane_gains_and_unstable_with_a_tiny_inertia() {
    // The default x axis at 1 kHz and at 4 kHz.
    for t in [1e-3, 250e-6] {
        let r = servo_radius(125.0, 1000.0, 1.4, 0.008, 0.02, t);
        assert!(r < 1.0, "radius {r} at {t}");
    }
    assert!(servo_radius(125.0, 1000.0, 1.4, 1e-300, 0.02, 1e-3) >= 1.0);
    // Far too much velocity gain for the inertia: kd T / J = 5.
    assert!(servo_radius(1.0, 0.0, 40.0, 0.008, 0.0, 1e-3) >= 1.0);
}

#[test]
fn a_velocity_loop_is_judged_without_the_position_integrator() {
    assert!(velocity_radius(10.0, 2.0, 0.008, 0.02, 250e-6) < 1.0);
    assert!(velocity_radius(0.0, 2.0, 0.008, 0.0, 250e-6) < 1.0);
    assert!(velocity_radius(0.0, 2.0, 1e-6, 0.0, 250e-6) >= 1.0);
}

#[test]
fn the_drive_loop_without_delay_tolerates_more_gain() {
    assert!(drive_radius(200.0, 0.0, 2.0, 0.008, 0.0, 250e-6) < 1.0);
    assert!(drive_radius(200.0, 0.0, 2.0, 1e-9, 0.0, 250e-6) >= 1.0);
}
