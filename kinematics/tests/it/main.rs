//! The kinematics crate's tests, one binary: each built-in and the user example against
//! seed 001's rule (forward of the chosen inverse gives the pose back; the chosen inverse is
//! the nearest valid one, checked by brute force), their own cases, joint velocities, the
//! registry, and garbage input that must give errors, never panics.

mod common;
mod five_bar;
mod gantry;
mod garbage;
mod polar;
mod registry;
mod scara;
mod velocity;
