//! What the generator tests share: the Gantry UBA cell's parameters.

use motion_core::generator::Params;
use shm_schema::MAX_AXES;

/// The Gantry UBA's acceleration time (s).
pub const T_ACC: f64 = 0.525;

/// The Gantry UBA: x, y (0..200, 0..150 mm, 16 mm/s), theta (±180°, 30°/s), coordinates =
/// joints.
pub fn gantry_params() -> Params {
    let mut p = Params {
        axes: 3,
        coords: 3,
        vmax: [1.0; MAX_AXES],
        coord_vmax: [1.0; MAX_AXES],
        min: [0.0; MAX_AXES],
        max: [0.0; MAX_AXES],
        t_acc: T_ACC,
    };
    p.vmax[..3].copy_from_slice(&[16.0, 16.0, 30.0]);
    p.coord_vmax = p.vmax;
    p.min[..3].copy_from_slice(&[0.0, 0.0, -180.0]);
    p.max[..3].copy_from_slice(&[200.0, 150.0, 180.0]);
    p
}
