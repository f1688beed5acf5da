//! One segment of Paul's via-point method (seed 003 §2; R. P. Paul, *Robot Manipulators*,
//! 1981, ch. 5).
//!
//! Local time `t` runs from `-t_acc` to `T1 - t_acc`. The segment leaves point `A` (on the
//! previous segment, `t_acc` before its end point `B`) and heads for `C`:
//!
//! - blend zone `-t_acc <= t < t_acc`, `h = (t + t_acc) / (2 t_acc)`, `ΔA = A - B`,
//!   `ΔC = C - B`:
//!   `q(t) = ((ΔC t_acc / T1 + ΔA)(2 - h) h² - 2 ΔA) h + B + ΔA`;
//! - linear part `t_acc <= t <= T1 - t_acc`: `q(t) = B + ΔC t / T1`.
//!
//! The quartic joins the incoming velocity `(B - A) / t_acc` to the outgoing one `ΔC / T1`
//! with continuous position, velocity and (zero-ended) acceleration at both zone
//! boundaries. The axes pass near `B`, not through it; `C = B` (a STOP or a repeated target)
//! makes them stop exactly on `B` at `t = t_acc`.

use nalgebra::SVector;
use shm_schema::MAX_AXES;

/// A position or velocity of every axis (unused axes stay 0).
pub type Axes = SVector<f64, MAX_AXES>;

/// One segment, from `A` (via the blend around `B`) towards `C`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Segment {
    /// Where the blend zone starts (the position at the previous transition).
    pub a: Axes,
    /// The via point the blend rounds.
    pub b: Axes,
    /// The segment's target.
    pub c: Axes,
    /// Segment time T1 (s), at least `2 t_acc`.
    pub t1: f64,
    /// Acceleration time (s); the blend zone lasts `2 t_acc`.
    pub t_acc: f64,
}

impl Segment {
    /// Local time at which the next target must be read: `T1 - t_acc`.
    #[inline]
    pub fn transition_time(&self) -> f64 {
        self.t1 - self.t_acc
    }

    /// True for a segment that brings the axes to rest on `B` (`C = B`).
    #[inline]
    pub fn stops(&self) -> bool {
        self.c == self.b
    }

    /// Position and velocity at local time `t` (clamped to `[-t_acc, T1 - t_acc]`).
    ///
    /// # Real-time
    /// Arithmetic on stack vectors only.
    #[inline]
    pub fn eval(&self, t: f64) -> (Axes, Axes) {
        let tau = self.t_acc;
        let t = t.clamp(-tau, self.transition_time());
        let dc = self.c - self.b;
        if t < tau {
            let da = self.a - self.b;
            let h = (t + tau) / (2.0 * tau);
            let k = dc * (tau / self.t1) + da;
            let pos = (k * ((2.0 - h) * h * h) - da * 2.0) * h + self.b + da;
            let dq_dh = k * (6.0 * h * h - 4.0 * h * h * h) - da * 2.0;
            (pos, dq_dh / (2.0 * tau))
        } else {
            (self.b + dc * (t / self.t1), dc / self.t1)
        }
    }

    /// Acceleration at local time `t` (for feed-forward and tests).
    #[inline]
    pub fn accel(&self, t: f64) -> Axes {
        let tau = self.t_acc;
        let t = t.clamp(-tau, self.transition_time());
        if t < tau {
            let h = (t + tau) / (2.0 * tau);
            let k = (self.c - self.b) * (tau / self.t1) + (self.a - self.b);
            k * ((12.0 * h - 12.0 * h * h) / (4.0 * tau * tau))
        } else {
            Axes::zeros()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn axes(v: &[f64]) -> Axes {
        let mut a = Axes::zeros();
        a.as_mut_slice()[..v.len()].copy_from_slice(v);
        a
    }

    fn close(a: &Axes, b: &Axes, tol: f64) -> bool {
        (a - b).abs().max() <= tol
    }

    /// The segment following `s` towards `d`, per seed 003: A = X(T1 - t_acc), B = C.
    fn next(s: &Segment, d: Axes, t1: f64) -> Segment {
        Segment {
            a: s.eval(s.transition_time()).0,
            b: s.c,
            c: d,
            t1,
            t_acc: s.t_acc,
        }
    }

    #[test]
    fn from_rest_the_blend_starts_at_rest_and_joins_the_line() {
        let p = axes(&[40.0, 40.0]);
        let s = Segment {
            a: p,
            b: p,
            c: axes(&[140.0, 40.0]),
            t1: 6.25,
            t_acc: 0.5,
        };
        let (q0, v0) = s.eval(-0.5);
        assert!(close(&q0, &p, 1e-12) && close(&v0, &Axes::zeros(), 1e-12));
        // At t = t_acc the blend meets the line B + ΔC t / T1 with its velocity ΔC / T1.
        let (q, v) = s.eval(0.5);
        assert!(close(&q, &axes(&[40.0 + 100.0 * 0.5 / 6.25, 40.0]), 1e-12));
        assert!(close(&v, &axes(&[16.0, 0.0]), 1e-12));
    }

    #[test]
    fn a_stop_segment_rests_exactly_on_the_point() {
        let s0 = Segment {
            a: axes(&[0.0]),
            b: axes(&[0.0]),
            c: axes(&[10.0]),
            t1: 5.0,
            t_acc: 0.4,
        };
        let stop = next(&s0, s0.c, 0.8);
        assert!(stop.stops());
        let (q, v) = stop.eval(stop.transition_time());
        assert_eq!(q[0], 10.0);
        assert_eq!(v[0], 0.0);
    }

    #[test]
    fn acceleration_is_zero_at_both_zone_boundaries_and_matches_velocity() {
        let s = Segment {
            a: axes(&[1.0, 2.0]),
            b: axes(&[3.0, 2.0]),
            c: axes(&[3.0, 9.0]),
            t1: 2.0,
            t_acc: 0.3,
        };
        assert!(close(&s.accel(-0.3), &Axes::zeros(), 1e-12));
        assert!(close(&s.accel(0.3 - 1e-12), &Axes::zeros(), 1e-9));
        // Finite differences of velocity give the acceleration.
        for t in [-0.25, -0.1, 0.0, 0.17] {
            let dt = 1e-6;
            let fd = (s.eval(t + dt).1 - s.eval(t - dt).1) / (2.0 * dt);
            assert!(close(&fd, &s.accel(t), 1e-5), "t = {t}");
        }
    }

    proptest! {
        /// Position and velocity are continuous at every zone boundary of a chain of
        /// segments, and the blend satisfies the closed form in between.
        #[test]
        fn chains_are_continuous_in_position_and_velocity(
            pts in proptest::collection::vec(proptest::collection::vec(-100.0f64..100.0, 3), 2..6),
            t_acc in 0.05f64..1.0,
            extra in proptest::collection::vec(0.0f64..3.0, 6),
        ) {
            let vmax = [10.0, 20.0, 30.0];
            let mut s = {
                let b = axes(&[0.0, 0.0, 0.0]);
                let c = axes(&pts[0]);
                let t1 = motion_program::segment_time(&[0.0; 3], &pts[0], &vmax, t_acc, 0.0) + extra[0];
                Segment { a: b, b, c, t1, t_acc }
            };
            for (i, p) in pts.iter().enumerate().skip(1) {
                let t1 = motion_program::segment_time(&s.c.as_slice()[..3], p, &vmax, t_acc, 0.0) + extra[i];
                let n = next(&s, axes(p), t1);
                // Transition: old segment at T1 - t_acc equals new segment at -t_acc.
                let (q_old, v_old) = s.eval(s.transition_time());
                let (q_new, v_new) = n.eval(-t_acc);
                prop_assert!(close(&q_old, &q_new, 1e-9));
                prop_assert!(close(&v_old, &v_new, 1e-9));
                // Blend end: quartic at t_acc (from below) equals the line at t_acc.
                let eps = 1e-9;
                let (q_in, v_in) = n.eval(t_acc - eps);
                let line_q = n.b + (n.c - n.b) * (t_acc / n.t1);
                let line_v = (n.c - n.b) / n.t1;
                prop_assert!(close(&q_in, &line_q, 1e-6));
                prop_assert!(close(&v_in, &line_v, 1e-6));
                // No axis exceeds its vmax on the line (T1 respects every axis' time).
                for (ax, vm) in vmax.iter().enumerate() {
                    prop_assert!(line_v[ax].abs() <= vm + 1e-9);
                }
                s = n;
            }
        }
    }
}
