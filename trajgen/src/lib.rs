//! Trajectory generator of the cell (seed 003 §2): linear segments joined by Paul's blend
//! zones, `T1 = max(max_i |C_i - B_i| / vmax_i, 2 t_acc, T_user)`, every reference computed
//! from real elapsed time.
//!
//! [`blend`] is the maths of one segment, [`generator`] the real-time state machine that
//! chains segments from a command queue; `main.rs` binds them to the cell's services.

pub mod blend;
pub mod generator;
