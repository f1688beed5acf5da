//! What the generator tests share: the Gantry UBA cell's parameters.

use motion_core::generator::Params;
use shm_schema::MAX_AXES;

/// The Gantry UBA's acceleration time (s).
pub const T_ACC: f64 = 0.525;

/// A cell's parameters: per joint its velocity, lowest and highest position; its Cartesian
/// coordinates `coord_vmax` (the joints themselves when `None`).
pub fn params(vmax: &[f64], min: &[f64], max: &[f64], coord_vmax: Option<&[f64]>) -> Params {
    let n = vmax.len();
    let mut p = Params {
        axes: n,
        coords: coord_vmax.map_or(n, <[f64]>::len),
        vmax: [1.0; MAX_AXES],
        coord_vmax: [1.0; MAX_AXES],
        min: [0.0; MAX_AXES],
        max: [0.0; MAX_AXES],
        t_acc: T_ACC,
    };
    p.vmax[..n].copy_from_slice(vmax);
    p.min[..n].copy_from_slice(min);
    p.max[..n].copy_from_slice(max);
    let c = coord_vmax.unwrap_or(vmax);
    p.coord_vmax[..c.len()].copy_from_slice(c);
    p
}

/// The Gantry UBA: x, y (0..200, 0..150 mm, 16 mm/s), theta (±180°, 30°/s), coordinates =
/// joints.
pub fn gantry_params() -> Params {
    params(
        &[16.0, 16.0, 30.0],
        &[0.0, 0.0, -180.0],
        &[200.0, 150.0, 180.0],
        None,
    )
}

/// The five-bar of seed 004, its joints limited to ±40° at 30°/s, its tool to 40 mm/s.
#[allow(dead_code)] // Not every test file has a five-bar.
pub fn five_bar() -> (Params, motion_core::generator::Kin) {
    let p = params(
        &[30.0, 30.0],
        &[-40.0, -40.0],
        &[40.0, 40.0],
        Some(&[40.0, 40.0]),
    );
    let k = kinematics::FiveBar::seed();
    (p, motion_core::generator::Kin(std::sync::Arc::new(k)))
}
