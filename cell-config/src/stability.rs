//! Refuses physically absurd axes: a loop that is unstable at the configured period.
//!
//! The axis is linearised (no Coulomb friction, no effort limit, no quantisation): a rigid body
//! `J dv/dt = u − b v`, held constant over each period (zero-order hold, integrated exactly).
//! Servo's loop (CST, CSV's outer loop) samples the position every servo period `T` and its
//! effort acts one period later (the machine applies the command at its next cycle: the
//! sense-to-command latency of the default phases). The drive's own loop runs at every
//! integration step without delay: in CSP its position loop, in CSV its velocity loop (CSV's
//! outer position loop in servo is not modelled). The loop is stable when every eigenvalue of its
//! discrete state matrix lies inside the unit circle; a configuration whose matrix has a
//! spectral radius of 1 or more is refused, with the radius. This is what caught an x inertia
//! of `1e-300`: accepted before, it made the simulation produce NaN.

use crate::axis::Axis;
use cia402::Mode;
use nalgebra::DMatrix;

/// Exact zero-order-hold integration of `J dv/dt = u − b v` over `t`: the coefficients of
/// `p' = p + c_pv v + c_pu u`, `v' = a v + c_vu u`.
fn zoh(j: f64, b: f64, t: f64) -> (f64, f64, f64, f64) {
    if b * t / j < 1e-9 {
        (1.0, t, t * t / (2.0 * j), t / j)
    } else {
        let a = (-b * t / j).exp();
        let tau = j / b;
        (a, tau * (1.0 - a), (t - tau * (1.0 - a)) / b, (1.0 - a) / b)
    }
}

/// The largest eigenvalue modulus of the `n`×`n` matrix `rows` (row-major); infinite when an
/// entry or an eigenvalue is not finite (an absurd configuration makes huge entries).
fn radius(n: usize, rows: &[f64]) -> f64 {
    if rows.iter().any(|v| !v.is_finite()) {
        return f64::INFINITY;
    }
    DMatrix::from_row_slice(n, n, rows)
        .complex_eigenvalues()
        .iter()
        .map(|z| z.norm())
        .fold(0.0, |r: f64, v| {
            if v.is_finite() {
                r.max(v)
            } else {
                f64::INFINITY
            }
        })
}

/// Spectral radius of servo's loop (CST): state `[p, v, I, u_prev]`, reference 0.
pub fn servo_radius(kp: f64, ki: f64, kd: f64, j: f64, b: f64, t: f64) -> f64 {
    let (a, c_pv, c_pu, c_vu) = zoh(j, b, t);
    // u_new = −kp p − kd v + I', I' = I − ki T p. Without integral action the integrator
    // state stays 0 (it is not a mode of the loop).
    let keep = if ki == 0.0 { 0.0 } else { 1.0 };
    #[rustfmt::skip]
    let m = [
        1.0, c_pv, 0.0, c_pu,
        0.0, a, 0.0, c_vu,
        -ki * t, 0.0, keep, 0.0,
        -kp - ki * t, -kd, keep, 0.0,
    ];
    radius(4, &m)
}

/// Spectral radius of a drive's own loop (CSP), without delay: state `[p, v, I]`.
pub fn drive_radius(kp: f64, ki: f64, kd: f64, j: f64, b: f64, t: f64) -> f64 {
    let (a, c_pv, c_pu, c_vu) = zoh(j, b, t);
    // u = −kp p − kd v + I', I' = I − ki T p, applied in the same step.
    let keep = if ki == 0.0 { 0.0 } else { 1.0 };
    let u = [-kp - ki * t, -kd, keep];
    #[rustfmt::skip]
    let m = [
        1.0 + c_pu * u[0], c_pv + c_pu * u[1], c_pu * u[2],
        c_vu * u[0], a + c_vu * u[1], c_vu * u[2],
        -ki * t, 0.0, keep,
    ];
    radius(3, &m)
}

/// Spectral radius of a drive's velocity loop (CSV), without delay: state `[v, I]`, with
/// `u = −kd v + I'` and `I' = I − ki T v` (the position integrates the velocity and is not a
/// mode of this loop).
pub fn velocity_radius(ki: f64, kd: f64, j: f64, b: f64, t: f64) -> f64 {
    let (a, _, _, c_vu) = zoh(j, b, t);
    let keep = if ki == 0.0 { 0.0 } else { 1.0 };
    radius(2, &[a + c_vu * (-kd - ki * t), c_vu * keep, -ki * t, keep])
}

/// Checks the loops of `a` in `mode`; the error says which loop, the radius and what to
/// change.
pub fn check(a: &Axis, mode: Mode, servo_period_s: f64, machine_step_s: f64) -> Result<(), String> {
    let (j, b) = (a.sim.inertia, a.sim.viscous);
    let (d, g) = (&a.drive, &a.servo);
    // The loop that closes the position (or velocity) of this axis, its radius and period.
    let (what, r, period_s, gains) = match mode {
        Mode::Csp => (
            "the drive's position loop",
            drive_radius(d.kp, d.ki, d.kd, j, b, machine_step_s),
            machine_step_s,
            "drive kp, ki, kd",
        ),
        Mode::Csv => (
            "the drive's velocity loop",
            velocity_radius(d.ki, d.kd, j, b, machine_step_s),
            machine_step_s,
            "drive kd",
        ),
        _ => (
            "servo's position loop",
            servo_radius(g.kp, g.ki, g.kd, j, b, servo_period_s),
            servo_period_s,
            "servo kp, ki, kd",
        ),
    };
    if !inside_unit_circle(r) {
        return Err(format!(
            "axis {}: sim inertia {} makes {what} unstable at its {:.0} µs period (spectral \
             radius {} ≥ 1, linearised with viscous {}): raise the inertia or lower {gains}",
            a.name,
            num(j),
            period_s * 1e6,
            num(r),
            num(b)
        ));
    }
    if !inside_unit_circle(b * machine_step_s / j) {
        return Err(format!(
            "axis {}: sim viscous {} over inertia {} reverses the velocity within one \
             integration step ({:.1} µs): raise the inertia, lower viscous or add substeps",
            a.name,
            num(b),
            num(j),
            machine_step_s * 1e6
        ));
    }
    Ok(())
}

/// True when `r` is a number below 1 (NaN is not).
fn inside_unit_circle(r: f64) -> bool {
    r < 1.0
}

/// A number as a person writes it: `0.008`, `1e-300`, `3.2e296`.
fn num(v: f64) -> String {
    if v != 0.0 && v.is_finite() && !(1e-4..1e6).contains(&v.abs()) {
        format!("{v:e}")
    } else {
        format!("{v}")
    }
}
