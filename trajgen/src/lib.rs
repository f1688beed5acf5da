//! Trajectory generator of the cell (seed 003 §2): linear segments joined by Paul's blend
//! zones, `T1 = max(max_i |C_i - B_i| / vmax_i, 2 t_acc, T_user)`, every reference computed
//! from real elapsed time.
//!
//! The motion itself is [`motion_core`]'s generator, the one the supervisor predicts with;
//! `main.rs` binds it to the cell's services: commands and controls in, setpoints out, the
//! program's outputs to iobridge and its inputs from iobridge's image.
