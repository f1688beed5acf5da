//! The motion language of seed 003 and the segment-time rule of its §2.
//!
//! ```text
//! MOVE(40,40,0)        // one coordinate per axis of the cell, in axis units
//! MOVE(140,40,0, T=8)  // optional user time T (s) for this segment
//! STOP                 // stop exactly on the previous target
//! END                  // end of program (stops on the last target)
//! ```
//!
//! Keywords are case-insensitive; `//` starts a comment; blank lines are allowed; after `END`
//! only comments and blank lines may follow. Every error names its line and column, and a
//! program is checked whole (syntax, axis count, limits) before anything is sent, so a bad
//! program moves nothing.

use shm_schema::MAX_AXES;
use std::fmt;

mod parse;
pub mod timing;

pub use parse::parse;
pub use timing::{segment_time, theoretical_time};

/// What an instruction does.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Op {
    /// Move towards `target`, blending into the next segment.
    Move {
        /// Target per axis (axis unit); entries past the cell's axes are 0.
        target: [f64; MAX_AXES],
        /// Column of each coordinate, for error messages.
        cols: [u32; MAX_AXES],
        /// Segment time asked for by the user (s).
        user_time_s: Option<f64>,
    },
    /// Stop exactly on the previous target.
    Stop,
    /// End of program.
    End,
}

/// One instruction and where it was written.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Instruction {
    /// 1-based line.
    pub line: u32,
    /// 1-based column of the keyword.
    pub col: u32,
    /// The instruction.
    pub op: Op,
}

/// A parsed program, ending in `END`.
#[derive(Clone, Debug, PartialEq)]
pub struct Program {
    /// Number of coordinates of each `MOVE`.
    pub axes: usize,
    /// The instructions in order; the last is `END`.
    pub instructions: Vec<Instruction>,
}

/// Limits of one axis, for [`Program::check_limits`] and the timing rule.
#[derive(Clone, Debug, PartialEq)]
pub struct AxisSpec {
    /// Axis name (`x`).
    pub name: String,
    /// Unit (`mm`).
    pub unit: String,
    /// Lowest allowed position.
    pub min: f64,
    /// Highest allowed position.
    pub max: f64,
    /// Largest velocity (unit/s).
    pub vmax: f64,
}

/// A problem in a program, with its place.
#[derive(Clone, Debug, PartialEq)]
pub struct ProgramError {
    /// 1-based line.
    pub line: u32,
    /// 1-based column.
    pub col: u32,
    /// What is wrong, in words a user can act on.
    pub message: String,
}

impl fmt::Display for ProgramError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "line {}, column {}: {}",
            self.line, self.col, self.message
        )
    }
}

impl std::error::Error for ProgramError {}

impl Program {
    /// Checks every `MOVE` target against the axes' limits, before anything moves.
    pub fn check_limits(&self, axes: &[AxisSpec]) -> Result<(), ProgramError> {
        for ins in &self.instructions {
            if let Op::Move { target, cols, .. } = &ins.op {
                for (i, ax) in axes.iter().enumerate() {
                    let v = target[i];
                    if v < ax.min || v > ax.max {
                        return Err(ProgramError {
                            line: ins.line,
                            col: cols[i],
                            message: format!(
                                "{} = {} {} is outside the axis limits {} .. {} {}",
                                ax.name, v, ax.unit, ax.min, ax.max, ax.unit
                            ),
                        });
                    }
                }
            }
        }
        Ok(())
    }
}

impl Program {
    /// The program as trajgen commands, numbered from `first_seq`.
    pub fn to_commands(&self, program_id: u32, first_seq: u64) -> Vec<shm_schema::MotionCommandV1> {
        use shm_schema::CommandKind;
        self.instructions
            .iter()
            .enumerate()
            .map(|(i, ins)| {
                let (kind, target, user) = match ins.op {
                    Op::Move {
                        target,
                        user_time_s,
                        ..
                    } => (CommandKind::Move, target, user_time_s.unwrap_or(0.0)),
                    Op::Stop => (CommandKind::Stop, [0.0; MAX_AXES], 0.0),
                    Op::End => (CommandKind::End, [0.0; MAX_AXES], 0.0),
                };
                shm_schema::MotionCommandV1 {
                    seq: first_seq + i as u64,
                    program_id,
                    line: ins.line,
                    kind: kind as u32,
                    axes: self.axes as u32,
                    target,
                    user_time_s: user,
                }
            })
            .collect()
    }
}
