//! The segment-time rule of seed 003 §2, equation (1), and the theoretical duration of a
//! program that follows from it.

use crate::{Op, Program};

/// Time to run the segment from `b` to `c` (s):
/// `T1 = max(max_i |c_i - b_i| / vmax_i, 2 t_acc, user_time)`.
///
/// The axes move coordinated: every axis takes the same T1, so the slowest one sets it.
/// A zero-length segment (`b == c`, a STOP or a repeated target) takes `2 t_acc`, which
/// brings the axes to rest exactly on the point.
///
/// # Real-time
/// Arithmetic only; trajgen calls it in its cycle.
#[inline]
pub fn segment_time(b: &[f64], c: &[f64], vmax: &[f64], t_acc: f64, user_time_s: f64) -> f64 {
    let mut t = (2.0 * t_acc).max(user_time_s);
    for i in 0..b.len().min(c.len()).min(vmax.len()) {
        t = t.max((c[i] - b[i]).abs() / vmax[i]);
    }
    t
}

/// Theoretical duration of `program` started at rest at `start` (s): the sum of its segment
/// times, as trajgen runs it. Each `MOVE` and `STOP` is one segment; `END` adds a stopping
/// segment (`2 t_acc`) unless the axes are already coming to rest on the last target;
/// `STOP`/`END` before the first `MOVE` add nothing.
pub fn theoretical_time(program: &Program, start: &[f64], vmax: &[f64], t_acc: f64) -> f64 {
    let n = program.axes;
    let mut b = start[..n].to_vec();
    let mut moving = false;
    let mut at_rest_segment = true;
    let mut total = 0.0;
    for ins in &program.instructions {
        match ins.op {
            Op::Move {
                target,
                user_time_s,
                ..
            } => {
                total += segment_time(&b, &target[..n], vmax, t_acc, user_time_s.unwrap_or(0.0));
                at_rest_segment = b[..] == target[..n];
                b.copy_from_slice(&target[..n]);
                moving = true;
            }
            Op::Stop | Op::End if !moving => {}
            Op::Stop => {
                total += segment_time(&b, &b, vmax, t_acc, 0.0);
                at_rest_segment = true;
            }
            Op::End => {
                if !at_rest_segment {
                    total += segment_time(&b, &b, vmax, t_acc, 0.0);
                }
                break;
            }
        }
    }
    total
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::parse;

    #[test]
    fn t1_is_the_largest_of_axis_times_two_t_acc_and_user_time() {
        let v = [10.0, 5.0];
        // Axis 2 is slowest: 20 / 5 = 4 s.
        assert_eq!(segment_time(&[0.0, 0.0], &[30.0, -20.0], &v, 0.5, 0.0), 4.0);
        // Short move: 2 t_acc wins.
        assert_eq!(segment_time(&[0.0, 0.0], &[1.0, 1.0], &v, 0.5, 0.0), 1.0);
        // The user asks for longer.
        assert_eq!(segment_time(&[0.0, 0.0], &[30.0, -20.0], &v, 0.5, 7.0), 7.0);
        // A user time shorter than the axes allow is overruled.
        assert_eq!(segment_time(&[0.0, 0.0], &[30.0, -20.0], &v, 0.5, 1.0), 4.0);
        // Zero-length segment.
        assert_eq!(segment_time(&[3.0, 3.0], &[3.0, 3.0], &v, 0.25, 0.0), 0.5);
    }

    #[test]
    fn the_seed_triangle_on_the_default_cell_takes_the_papers_19_10_s() {
        let p = parse(include_str!("../../examples/triangle.prog"), 3).expect("parses");
        let t = theoretical_time(&p, &[40.0, 40.0, 0.0], &[16.0, 16.0, 30.0], 0.525);
        // 1.05 (MOVE to the start point) + 6.25 + 5.375 + 5.375 + 1.05 (STOP)
        assert!((t - 19.10).abs() < 1e-9, "{t}");
    }

    #[test]
    fn end_adds_a_stop_unless_already_stopping() {
        let v = [1.0];
        let t = |src: &str| theoretical_time(&parse(src, 1).expect("parses"), &[0.0], &v, 0.5);
        assert_eq!(t("MOVE(4)\nEND"), 4.0 + 1.0);
        assert_eq!(t("MOVE(4)\nSTOP\nEND"), 4.0 + 1.0);
        assert_eq!(t("MOVE(4)\nMOVE(4)\nEND"), 4.0 + 1.0);
        assert_eq!(t("STOP\nEND"), 0.0);
        assert_eq!(t("END"), 0.0);
        assert_eq!(t("MOVE(4, T=6)\nEND"), 6.0 + 1.0);
    }
}
