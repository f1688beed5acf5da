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
        let t = shm_schema::bound(t, -tau, self.transition_time());
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
        let t = shm_schema::bound(t, -tau, self.transition_time());
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

    /// A small deterministic generator for the sweep below (xorshift64*).
    struct Rng(u64);
    impl Rng {
        fn unit(&mut self) -> f64 {
            self.0 ^= self.0 >> 12;
            self.0 ^= self.0 << 25;
            self.0 ^= self.0 >> 27;
            (self.0.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 11) as f64 / (1u64 << 53) as f64
        }
        fn range(&mut self, lo: f64, hi: f64) -> f64 {
            lo + (hi - lo) * self.unit()
        }
    }

    /// Property, over 2000 random chains of 2 to 6 targets: position and velocity are
    /// continuous at every zone boundary, the blend meets the closed-form line at `t_acc`, and
    /// no axis exceeds its vmax on a line.
    #[test]
    fn chains_are_continuous_in_position_and_velocity() {
        let vmax = [10.0, 20.0, 30.0];
        let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
        for case in 0..2000 {
            let t_acc = rng.range(0.05, 1.0);
            let n = 2 + (rng.unit() * 5.0) as usize;
            let mut prev = axes(&[0.0, 0.0, 0.0]);
            let mut s: Option<Segment> = None;
            for _ in 0..n {
                let p = [
                    rng.range(-100.0, 100.0),
                    rng.range(-100.0, 100.0),
                    rng.range(-100.0, 100.0),
                ];
                let extra = rng.range(0.0, 3.0);
                let t1 = motion_program::segment_time(&prev.as_slice()[..3], &p, &vmax, t_acc, 0.0)
                    + extra;
                let seg = match &s {
                    None => Segment {
                        a: prev,
                        b: prev,
                        c: axes(&p),
                        t1,
                        t_acc,
                    },
                    Some(old) => {
                        let n = next(old, axes(&p), t1);
                        let (q_old, v_old) = old.eval(old.transition_time());
                        let (q_new, v_new) = n.eval(-t_acc);
                        assert!(close(&q_old, &q_new, 1e-9), "case {case}: position jumps");
                        assert!(close(&v_old, &v_new, 1e-9), "case {case}: velocity jumps");
                        n
                    }
                };
                let (q_in, v_in) = seg.eval(t_acc - 1e-9);
                let line_q = seg.b + (seg.c - seg.b) * (t_acc / seg.t1);
                let line_v = (seg.c - seg.b) / seg.t1;
                assert!(
                    close(&q_in, &line_q, 1e-6),
                    "case {case}: blend misses the line"
                );
                assert!(
                    close(&v_in, &line_v, 1e-6),
                    "case {case}: blend velocity misses the line"
                );
                for (ax, vm) in vmax.iter().enumerate() {
                    assert!(
                        line_v[ax].abs() <= vm + 1e-9,
                        "case {case}: axis {ax} over vmax"
                    );
                }
                prev = seg.c;
                s = Some(seg);
            }
        }
    }
}
