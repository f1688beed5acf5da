//! Users' own kinematics, one module each.
//!
//! To add yours (`docs/kinematics.md`, "Adding your own kinematics"): write a type
//! implementing [`Kinematics`](crate::Kinematics) in a file here, with its parameter names
//! (`PARAMS`), an example of them (`EXAMPLE`) and a `build` function from
//! [`Params`](crate::Params); declare the module below; add one line to
//! [`REGISTRY`](crate::REGISTRY); select it in the cell's configuration with
//! `[kinematics] type = "your-name"`. [`polar`] is the example.

pub mod polar;
