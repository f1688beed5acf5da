//! A program run through the [`Generator`] in simulated time: the motion time trajgen will
//! take, every reference it will publish (for validation), and when each output is set.
//!
//! The simulation steps at the trajgen period and at every exact transition the generator
//! asks for, as trajgen does; a `WAIT` is taken as met at once (the prediction covers the
//! motion, the report subtracts the time spent waiting), a `DELAY` lasts its time.

use crate::generator::{Generator, Params, Phase};
use shm_schema::{MotionCommandV2, MotionState, SetpointV2};

/// An arbitrary `CLOCK_MONOTONIC` origin for the simulation (ns).
const T0: u64 = 1_000_000_000_000;

/// How a prediction ended.
#[derive(Clone, Debug, PartialEq)]
pub enum Outcome {
    /// The program reached `END`.
    Done,
    /// The generator refused a command (trajgen would too): its fault code and line.
    Fault {
        /// [`shm_schema::motion::trajgen_fault`] code.
        code: u32,
        /// Program line.
        line: u32,
    },
    /// The motion ran past the limit without ending.
    TooLong,
    /// Its caller stopped it ([`simulate_while`]).
    Stopped,
}

/// An output the program sets, and when (motion time, s).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OutputEvent {
    /// Motion time the look-ahead sets it, `WAIT`s excluded (s).
    pub t_s: f64,
    /// Bits written and their values.
    pub mask: u64,
    /// Values.
    pub values: u64,
    /// Program line of the `OUT`.
    pub line: u32,
}

/// What a simulated run gave.
#[derive(Clone, Debug, PartialEq)]
pub struct Prediction {
    /// How it ended.
    pub outcome: Outcome,
    /// Motion time from the first command to the end less the time in `WAIT`s (s).
    pub duration_s: f64,
    /// The sum of the segment and delay times (s).
    pub theoretical_s: f64,
    /// Setpoints computed.
    pub steps: u64,
    /// The outputs set, in order.
    pub outputs: Vec<OutputEvent>,
    /// Why the kinematics could not follow, for a fault `UNREACHABLE`.
    pub kin_error: Option<kinematics::KinError>,
}

/// Runs `commands` from rest on `start` (joint positions) with `p`, stepping at most `dt_s`
/// apart, until `END`, a fault, or `max_s` of motion time. `observe` sees every setpoint (in
/// the running segment's space, as the generator gives it).
pub fn simulate(
    p: Params,
    start: &[f64],
    commands: impl IntoIterator<Item = MotionCommandV2>,
    dt_s: f64,
    max_s: f64,
    observe: &mut dyn FnMut(&SetpointV2),
) -> Prediction {
    simulate_with(Generator::new(p, start), commands, dt_s, max_s, observe)
}

/// Like [`simulate`], with a generator built by the caller (with the cell's kinematics).
pub fn simulate_with(
    g: Generator,
    commands: impl IntoIterator<Item = MotionCommandV2>,
    dt_s: f64,
    max_s: f64,
    observe: &mut dyn FnMut(&SetpointV2),
) -> Prediction {
    simulate_while(g, commands, dt_s, max_s, observe, &|| true)
}

/// Steps between two asks of [`simulate_while`]'s `go_on` (about a millisecond's work).
const ASK_EVERY: u64 = 4096;

/// Like [`simulate_with`], asking `go_on` every few thousand steps: once it says no, the
/// simulation ends ([`Outcome::Stopped`]).
pub fn simulate_while(
    mut g: Generator,
    commands: impl IntoIterator<Item = MotionCommandV2>,
    dt_s: f64,
    max_s: f64,
    observe: &mut dyn FnMut(&SetpointV2),
    go_on: &dyn Fn() -> bool,
) -> Prediction {
    let mut commands = commands.into_iter().peekable();
    let dt_ns = ((dt_s.max(1e-5)) * 1e9) as u64;
    let mut now = T0;
    let mut free = crate::generator::QUEUE_CAP;
    let mut outputs = Vec::new();
    let mut steps = 0u64;
    // Inputs as waited for: whatever the running WAIT wants.
    let inputs = |g: &Generator| match g.phase() {
        Phase::Waiting { io, value, .. } => Some(u64::from(value) << io),
        _ => Some(0),
    };
    loop {
        // The client's flow control: never more in flight than the queue takes.
        while free > 1 {
            let Some(c) = commands.next() else { break };
            g.push_command(&c);
            free -= 1;
        }
        let sp = g.step(now, inputs(&g));
        steps += 1;
        free = sp.queue_free as usize;
        observe(&sp);
        if let Some(o) = g.take_outputs() {
            outputs.push(OutputEvent {
                t_s: sp.motion_time_s - sp.waited_s,
                mask: o.mask,
                values: o.values,
                line: o.line,
            });
        }
        let outcome = match MotionState::from_u32(sp.state) {
            Some(MotionState::Done) if commands.peek().is_none() => Some(Outcome::Done),
            Some(MotionState::Fault) => Some(Outcome::Fault {
                code: sp.fault,
                line: sp.fault_line,
            }),
            _ if sp.motion_time_s > max_s => Some(Outcome::TooLong),
            _ if steps.is_multiple_of(ASK_EVERY) && !go_on() => Some(Outcome::Stopped),
            _ => None,
        };
        if let Some(outcome) = outcome {
            return Prediction {
                outcome,
                duration_s: sp.motion_time_s - sp.waited_s,
                theoretical_s: sp.theoretical_s,
                steps,
                outputs,
                kin_error: g.kin_error(),
            };
        }
        let next = now + dt_ns;
        now = match g.next_transition_ns() {
            Some(t) if t > now && t < next => t,
            _ => next,
        };
    }
}
