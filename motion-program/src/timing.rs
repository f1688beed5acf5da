//! The segment-time rule of seed 003 §2, equation (1).

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
