//! A program run through the [`Generator`] in simulated time: the motion time trajgen will
//! take, every reference it will publish (for validation), and when each output is set.
//!
//! The simulation steps at the trajgen period and at every exact transition the generator
//! asks for, as trajgen does; a `WAIT` is taken as met at once (the prediction covers the
//! motion, the report subtracts the time spent waiting), a `DELAY` lasts its time.
//!
//! A program's loop is run only until two of its iterations begin alike
//! ([`simulate_program`]): the generator is then in the same state but for the time and the
//! sequence numbers ([`Generator::period_since`]), so every iteration that follows is the one
//! just run, later; they are passed over ([`Generator::fast_forward`]) but for the last, which
//! blends into what follows the loop. A 23-hour `REPEAT` is validated in the time of its first
//! iterations, and a path out of limits anywhere in it is found all the same.

use crate::generator::{Generator, Params, Phase};
use motion_program::{Commands, IterationStart};
use shm_schema::{MotionCommandV2, MotionState, SetpointV2};
use std::collections::VecDeque;

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
    /// Setpoints computed (none for the iterations passed over).
    pub steps: u64,
    /// The outputs set, in order.
    pub outputs: Vec<OutputEvent>,
    /// Why the kinematics could not follow, for a fault `UNREACHABLE`.
    pub kin_error: Option<kinematics::KinError>,
    /// Loop iterations found alike and passed over ([`simulate_program`]).
    pub passed_over: u64,
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
    g: Generator,
    commands: impl IntoIterator<Item = MotionCommandV2>,
    dt_s: f64,
    max_s: f64,
    observe: &mut dyn FnMut(&SetpointV2),
    go_on: &dyn Fn() -> bool,
) -> Prediction {
    let mut source = Plain(commands.into_iter());
    run(g, &mut source, dt_s, max_s, observe, go_on)
}

/// Like [`simulate_while`], for a program's own commands: each loop runs until two of its
/// iterations begin alike, then the iterations that would repeat them are passed over (see
/// the module's documentation); `observe` sees the setpoints of those that ran.
pub fn simulate_program(
    g: Generator,
    commands: Commands,
    dt_s: f64,
    max_s: f64,
    observe: &mut dyn FnMut(&SetpointV2),
    go_on: &dyn Fn() -> bool,
) -> Prediction {
    let p = g.params();
    let vmax = p.vmax[..p.axes].iter().fold(0.0f64, |m, v| m.max(*v));
    let mut source = Looping {
        commands,
        begun: VecDeque::new(),
        marks: Vec::new(),
        // Two states are sampled at most a step after their iteration began: their joints
        // are at most that far apart, unless the inverse kinematics took another branch.
        joint_slack: 2.0 * vmax * dt_s + 1e-9,
        max_s,
    };
    run(g, &mut source, dt_s, max_s, observe, go_on)
}

/// What a simulation has gathered so far.
#[derive(Default)]
struct Gathered {
    outputs: Vec<OutputEvent>,
    steps: u64,
    passed_over: u64,
}

/// Where a simulation draws its commands from.
trait Source {
    /// The next command, if any.
    fn draw(&mut self) -> Option<MotionCommandV2>;
    /// After each step (`sp` its setpoint): may move the generator and the clock `now_ns` on.
    fn stepped(
        &mut self,
        _g: &mut Generator,
        _sp: &SetpointV2,
        _now_ns: &mut u64,
        _gathered: &mut Gathered,
    ) {
    }
}

/// Any commands, run one by one.
struct Plain<I>(I);

impl<I: Iterator<Item = MotionCommandV2>> Source for Plain<I> {
    fn draw(&mut self) -> Option<MotionCommandV2> {
        self.0.next()
    }
}

fn run(
    mut g: Generator,
    source: &mut dyn Source,
    dt_s: f64,
    max_s: f64,
    observe: &mut dyn FnMut(&SetpointV2),
    go_on: &dyn Fn() -> bool,
) -> Prediction {
    let dt_ns = ((dt_s.max(1e-5)) * 1e9) as u64;
    let mut now = T0;
    let mut free = crate::generator::QUEUE_CAP;
    let mut gathered = Gathered::default();
    // A command drawn to learn whether any is left, not sent yet.
    let mut drawn: Option<MotionCommandV2> = None;
    // Inputs as waited for: whatever the running WAIT wants.
    let inputs = |g: &Generator| match g.phase() {
        Phase::Waiting { io, value, .. } => Some(u64::from(value) << io),
        _ => Some(0),
    };
    loop {
        // The client's flow control: never more in flight than the queue takes.
        while free > 1 {
            let Some(c) = drawn.take().or_else(|| source.draw()) else {
                break;
            };
            g.push_command(&c);
            free -= 1;
        }
        let sp = g.step(now, inputs(&g));
        gathered.steps += 1;
        free = sp.queue_free as usize;
        observe(&sp);
        if let Some(o) = g.take_outputs() {
            gathered.outputs.push(OutputEvent {
                t_s: sp.motion_time_s - sp.waited_s,
                mask: o.mask,
                values: o.values,
                line: o.line,
            });
        }
        let mut none_left = || {
            drawn = drawn.or_else(|| source.draw());
            drawn.is_none()
        };
        // Too long before done: a DELAY's end, reached in one step, may be the program's.
        let outcome = match MotionState::from_wire(sp.state) {
            Some(MotionState::Fault) => Some(Outcome::Fault {
                code: sp.fault,
                line: sp.fault_line,
            }),
            _ if sp.motion_time_s > max_s => Some(Outcome::TooLong),
            Some(MotionState::Done) if none_left() => Some(Outcome::Done),
            _ if gathered.steps.is_multiple_of(ASK_EVERY) && !go_on() => Some(Outcome::Stopped),
            _ => None,
        };
        if let Some(outcome) = outcome {
            return Prediction {
                outcome,
                duration_s: sp.motion_time_s - sp.waited_s,
                theoretical_s: sp.theoretical_s,
                steps: gathered.steps,
                outputs: gathered.outputs,
                kin_error: g.kin_error(),
                passed_over: gathered.passed_over,
            };
        }
        source.stepped(&mut g, &sp, &mut now, &mut gathered);
        let next = now + dt_ns;
        now = match g.next_transition_ns() {
            Some(t) if t > now && t < next => t,
            // Nothing moves during a DELAY: straight to its end, the step trajgen takes there
            // too. The samples in between would repeat this one (a day's DELAY was 86.4
            // million of them, 7.7 s of `supervisor check`).
            Some(t) if t > now && matches!(g.phase(), Phase::Delaying { .. }) => t,
            _ => next,
        };
    }
}

/// A program's commands, watched for loop iterations that begin alike.
struct Looping {
    commands: Commands,
    /// Iterations begun by commands sent but not yet read by the generator, with the `seq`
    /// of the command that begins each, in order.
    begun: VecDeque<(u64, IterationStart)>,
    /// Per nesting level: the generator as the latest iteration there began.
    marks: Vec<Option<Mark>>,
    /// How far apart the joints of two alike states may be (see [`simulate_program`]).
    joint_slack: f64,
    /// The longest motion simulated: no loop is passed over far beyond it.
    max_s: f64,
}

/// The generator as an iteration began, and what had been gathered by then.
struct Mark {
    at: IterationStart,
    seq: u64,
    generator: Box<Generator>,
    outputs: usize,
}

impl Source for Looping {
    fn draw(&mut self) -> Option<MotionCommandV2> {
        let c = self.commands.next()?;
        for at in self.commands.iterations_begun() {
            self.begun.push_back((c.seq, at));
        }
        Some(c)
    }

    fn stepped(
        &mut self,
        g: &mut Generator,
        sp: &SetpointV2,
        now_ns: &mut u64,
        gathered: &mut Gathered,
    ) {
        let read = g.commands_read();
        while let Some(&(seq, at)) = self.begun.front() {
            if seq > read {
                break;
            }
            self.begun.pop_front();
            if self.began(g, sp, seq, at, now_ns, gathered) {
                // Moved on: the iterations still ahead were renumbered.
                return;
            }
        }
    }
}

impl Looping {
    /// The generator has read the command `seq` that begins iteration `at`: if it is in the
    /// state the previous iteration began in, moved on by one period, passes over every
    /// iteration but the last (returns true); otherwise remembers this state.
    fn began(
        &mut self,
        g: &mut Generator,
        sp: &SetpointV2,
        seq: u64,
        at: IterationStart,
        now_ns: &mut u64,
        gathered: &mut Gathered,
    ) -> bool {
        let d = at.depth;
        if self.marks.len() <= d {
            self.marks.resize_with(d + 1, || None);
        }
        if let Some(prev) = &self.marks[d]
            && prev.at.instance == at.instance
            && prev.at.iteration + 1 == at.iteration
            && let commands = seq - prev.seq
            && self.commands.per_iteration(d) == Some(commands)
            && let Some(period) = g.period_since(&prev.generator, commands)
            && period.joints_apart <= self.joint_slack
            && let Some(left) = self.commands.iterations_left(d, at.instance)
        {
            // Never far past the longest motion: the prediction ends there.
            let to_max = ((self.max_s - sp.motion_time_s).max(0.0) / period.path_s).ceil();
            let n = left.min((to_max.min(f64::from(u32::MAX - 1))) as u32 + 1);
            if n > 0
                && let Some(skipped) = self.commands.skip_iterations(d, n)
            {
                let path_ns = (f64::from(n) * period.path_s * 1e9).round() as u64;
                g.fast_forward(&period, n, skipped, path_ns);
                *now_ns += path_ns;
                let one = prev.outputs..gathered.outputs.len();
                for k in 1..=n {
                    for i in one.clone() {
                        let mut o = gathered.outputs[i];
                        // Motion time less the time in WAITs, as every output's.
                        o.t_s += f64::from(k) * (period.path_s - period.waited_s);
                        gathered.outputs.push(o);
                    }
                }
                gathered.passed_over += u64::from(n);
                for (s, b) in &mut self.begun {
                    *s += skipped;
                    if (b.depth, b.instance) == (d, at.instance) {
                        b.iteration += u64::from(n);
                    }
                }
                self.marks[d] = None;
                return true;
            }
        }
        self.marks[d] = Some(Mark {
            at,
            seq,
            generator: Box::new(g.clone()),
            outputs: gathered.outputs.len(),
        });
        false
    }
}
