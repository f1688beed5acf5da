//! The motion language (`docs/language.md`): seed 003's `MOVE`, `STOP`, `END` and `T=`, with
//! joint moves, named positions, digital IO, waits, delays, a speed override and loops.
//!
//! ```text
//! P1 = (140, 40, 0)        // a named position
//! SPEED(50)                // the moves that follow at 50 % of vmax
//! REPEAT 3
//!   MOVE(P1)               // linear in Cartesian space, blended
//!   OUT(gripper, 1)        // set a named output (at the blend, see docs/language.md)
//!   WAIT(gripper_closed, 1, 2.0)  // at rest, until the input is 1; 2 s timeout
//!   MOVEJ(40, 40, 0, T=4)  // the same blending in joint space
//!   DELAY(0.5)             // at rest for 0.5 s
//! ENDREPEAT
//! END
//! ```
//!
//! Keywords are case-insensitive; names (positions, IO) are case-sensitive; `//` starts a
//! comment. A program is checked whole (syntax, coordinate counts, names, bounds) before
//! anything is sent, and every error names its line and column and what was expected, so a
//! bad program moves nothing. The parser never panics, whatever the bytes.

use shm_schema::MAX_AXES;
use std::fmt;

mod commands;
mod parse;
pub mod timing;

pub use commands::{Commands, IterationStart};
pub use parse::parse;
pub use timing::segment_time;

/// Largest source accepted (bytes).
pub const MAX_SOURCE_BYTES: usize = 1 << 20;
/// Largest segment time `T` (s).
pub const MAX_SEGMENT_TIME_S: f64 = 3600.0;
/// Largest `DELAY` and `WAIT` timeout (s).
pub const MAX_WAIT_S: f64 = 86_400.0;
/// Largest `REPEAT` count.
pub const MAX_REPEAT: u32 = 1_000_000;
/// Deepest nesting of `REPEAT`.
pub const MAX_NESTING: usize = 8;
/// Longest name (positions, IO).
pub const MAX_NAME_LEN: usize = 31;

/// The space a move is blended in (its wire value is `SetpointV2::space`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Space {
    /// `MOVE`: linear in Cartesian space (the tool's coordinates).
    Cartesian = 0,
    /// `MOVEJ`: linear in joint space (the axes' positions).
    Joint = 1,
}

/// What an instruction does.
#[derive(Clone, Debug, PartialEq)]
pub enum Op {
    /// `MOVE` or `MOVEJ`: towards `target`, blending into the next segment.
    Move {
        /// Cartesian or joint.
        space: Space,
        /// Target per coordinate (Cartesian) or per joint; entries past the count are 0.
        target: [f64; MAX_AXES],
        /// Column of each coordinate (of the position's name when one was used).
        cols: [u32; MAX_AXES],
        /// Segment time asked for by the user (s).
        user_time_s: Option<f64>,
    },
    /// Stop exactly on the previous target.
    Stop,
    /// Set output `io` (its index in the cell's IO table) to `value`.
    Out {
        /// Index in the IO table.
        io: u32,
        /// Value to set.
        value: bool,
    },
    /// At rest, hold until input `io` reads `value`; past `timeout_s` the program faults.
    Wait {
        /// Index in the IO table.
        io: u32,
        /// Value waited for.
        value: bool,
        /// Longest wait (s); `None` waits for ever.
        timeout_s: Option<f64>,
    },
    /// At rest, hold for `seconds`.
    Delay {
        /// Seconds to hold.
        seconds: f64,
    },
    /// The moves that follow run at `percent` of the axes' vmax (and their `T` stretched).
    Speed {
        /// 1..=100.
        percent: f64,
    },
    /// `REPEAT n … ENDREPEAT`, or for ever without `n`.
    Repeat {
        /// Times to run `body`; `None` for ever.
        count: Option<u32>,
        /// The instructions repeated.
        body: Vec<Instruction>,
    },
    /// End of program.
    End,
}

/// One instruction and where it was written.
#[derive(Clone, Debug, PartialEq)]
pub struct Instruction {
    /// 1-based line.
    pub line: u32,
    /// 1-based column of the keyword.
    pub col: u32,
    /// The instruction.
    pub op: Op,
}

/// What a program may name on a cell: the coordinates of `MOVE`, the joints of `MOVEJ`, the
/// outputs of `OUT` and the inputs of `WAIT`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CellSpec {
    /// Cartesian coordinates (`x`, `y`, `theta`), with their units.
    pub coords: Vec<(String, String)>,
    /// Joints (the cell's axes), with their units.
    pub joints: Vec<(String, String)>,
    /// Outputs by name, with their index in the IO table.
    pub outputs: Vec<(String, u32)>,
    /// Inputs by name, with their index in the IO table.
    pub inputs: Vec<(String, u32)>,
}

impl CellSpec {
    /// A cell whose joints are its Cartesian coordinates (the gantry), without IO.
    pub fn cartesian(axes: &[(&str, &str)]) -> Self {
        let named: Vec<(String, String)> = axes
            .iter()
            .map(|(n, u)| (n.to_string(), u.to_string()))
            .collect();
        Self {
            coords: named.clone(),
            joints: named,
            ..Self::default()
        }
    }
}

/// A parsed program, ending in `END`.
#[derive(Clone, Debug, PartialEq)]
pub struct Program {
    /// Number of coordinates of each `MOVE`.
    pub coords: usize,
    /// Number of joints of each `MOVEJ`.
    pub joints: usize,
    /// The instructions in order; the last is `END`.
    pub instructions: Vec<Instruction>,
}

impl Program {
    /// True when the program runs for ever (a `REPEAT` without a count).
    pub fn forever(&self) -> bool {
        fn any(body: &[Instruction]) -> bool {
            body.iter().any(|i| match &i.op {
                Op::Repeat { count: None, .. } => true,
                Op::Repeat { body, .. } => any(body),
                _ => false,
            })
        }
        any(&self.instructions)
    }

    /// The program as trajgen commands (`program_id`, `seq` from 1), loops unrolled as the
    /// iterator is drawn: a program that runs for ever gives commands for ever.
    pub fn commands(&self, program_id: u32) -> Commands {
        Commands::new(std::sync::Arc::new(self.clone()), program_id)
    }

    /// Every instruction, loop bodies once each, in source order.
    pub fn flat(&self) -> Vec<&Instruction> {
        fn walk<'a>(body: &'a [Instruction], out: &mut Vec<&'a Instruction>) {
            for i in body {
                out.push(i);
                if let Op::Repeat { body, .. } = &i.op {
                    walk(body, out);
                }
            }
        }
        let mut out = Vec::new();
        walk(&self.instructions, &mut out);
        out
    }
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

/// At most `max` characters of `s`, with `…` when cut: user text quoted in a message never
/// floods it.
pub fn cut(s: &str, max: usize) -> String {
    match s.char_indices().nth(max) {
        Some((at, _)) => format!("{}…", &s[..at]),
        None => s.to_string(),
    }
}
