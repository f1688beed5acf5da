//! A program as the stream of commands trajgen takes, loops unrolled lazily.

use crate::{Instruction, Op, Program, Space};
use shm_schema::{CommandKind, MotionCommandV2};
use std::sync::Arc;

/// The commands of a program, in execution order (`seq` from 1), unrolling `REPEAT` as they
/// are drawn: a program that runs for ever is an endless iterator. It owns its program, so a
/// job can keep drawing from it for hours.
#[derive(Clone, Debug)]
pub struct Commands {
    program: Arc<Program>,
    program_id: u32,
    seq: u64,
    /// Per nesting level: the index of its `REPEAT` in the enclosing body (none for the
    /// program), the next index in its body, the iterations left after this one (`None`:
    /// for ever) and the iteration running (from 1).
    stack: Vec<Frame>,
    forever_as: Option<u32>,
    /// Loop instances entered so far (each frame's identity).
    instances: u64,
}

#[derive(Clone, Copy, Debug)]
struct Frame {
    at: Option<usize>,
    next: usize,
    left: Option<u32>,
    iteration: u64,
    /// Which run of its `REPEAT` this is (unique within the iterator).
    instance: u64,
    /// The `seq` of its iteration's first command, once drawn.
    first_seq: Option<u64>,
}

/// A loop iteration a command begins ([`Commands::iterations_begun`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct IterationStart {
    /// Nesting level of the loop (1: a `REPEAT` of the program's own body).
    pub depth: usize,
    /// Which run of that `REPEAT` (a loop inside another is run again in each of the outer
    /// one's iterations): unique within the iterator.
    pub instance: u64,
    /// The iteration, from 1.
    pub iteration: u64,
}

impl Commands {
    /// The commands of `program` (see [`Program::commands`]).
    pub fn new(program: Arc<Program>, program_id: u32) -> Self {
        Self::bounded(program, program_id, None)
    }

    /// Like [`Commands::new`], with every `REPEAT` without a count run `forever_as` times
    /// (`None`: for ever): a prediction covers a finite number of iterations.
    pub fn bounded(program: Arc<Program>, program_id: u32, forever_as: Option<u32>) -> Self {
        Self {
            program,
            forever_as,
            program_id,
            seq: 0,
            stack: vec![Frame {
                at: None,
                next: 0,
                left: Some(0),
                iteration: 1,
                instance: 0,
                first_seq: None,
            }],
            instances: 0,
        }
    }

    /// The loop iterations the command drawn last begins (outermost first): a command can
    /// begin an iteration of several nested loops at once.
    pub fn iterations_begun(&self) -> impl Iterator<Item = IterationStart> + '_ {
        self.stack
            .iter()
            .enumerate()
            .skip(1)
            .filter(|(_, f)| f.first_seq == Some(self.seq))
            .map(|(depth, f)| IterationStart {
                depth,
                instance: f.instance,
                iteration: f.iteration,
            })
    }

    /// Iterations of the loop at `depth` not drawn yet, if the iterator is still within its
    /// run `instance` (`None` otherwise, or for a loop that runs for ever).
    pub fn iterations_left(&self, depth: usize, instance: u64) -> Option<u32> {
        let f = self.stack.get(depth).filter(|_| depth > 0)?;
        (f.instance == instance).then_some(f.left).flatten()
    }

    /// Passes over `n` iterations of the loop at `depth` without drawing them, as if they had
    /// been: the commands after keep their `seq`. For a prediction that has found the loop's
    /// iterations alike. Returns the commands passed over; `None` (and nothing done) when
    /// fewer than `n` are left or their count overflows.
    pub fn skip_iterations(&mut self, depth: usize, n: u32) -> Option<u64> {
        let f = *self.stack.get(depth).filter(|_| depth > 0)?;
        if f.left? < n {
            return None;
        }
        let per = self.per_iteration(depth)?;
        let skipped = per.checked_mul(u64::from(n))?;
        let f = &mut self.stack[depth];
        f.left = f.left.map(|l| l - n);
        f.iteration += u64::from(n);
        self.seq += skipped;
        if let Some(first) = &mut f.first_seq {
            *first += skipped;
        }
        Some(skipped)
    }

    /// Commands in one iteration of the loop the iterator is in at `depth`, its inner loops
    /// unrolled; `None` for ever or past `u64`.
    pub fn per_iteration(&self, depth: usize) -> Option<u64> {
        (depth > 0 && depth < self.stack.len()).then(|| self.count(self.body(depth)))?
    }

    /// Commands in one pass of `body`, its loops unrolled; `None` for ever or past `u64`.
    fn count(&self, body: &[Instruction]) -> Option<u64> {
        body.iter().try_fold(0u64, |sum, i| {
            let n = match &i.op {
                Op::Repeat { count, body } => {
                    let times = count.or(self.forever_as)?;
                    self.count(body)?.checked_mul(u64::from(times))?
                }
                _ => 1,
            };
            sum.checked_add(n)
        })
    }

    /// The body of nesting level `depth` (0: the program's).
    fn body(&self, depth: usize) -> &[Instruction] {
        let mut body: &[Instruction] = &self.program.instructions;
        for f in &self.stack[1..=depth.min(self.stack.len().saturating_sub(1))] {
            match f.at.and_then(|k| body.get(k)).map(|i| &i.op) {
                Some(Op::Repeat { body: inner, .. }) => body = inner,
                _ => return &[],
            }
        }
        body
    }

    /// Commands drawn so far.
    pub fn drawn(&self) -> u64 {
        self.seq
    }

    /// The iteration of each enclosing loop of the command drawn last (outermost first).
    pub fn iterations(&self) -> Vec<u64> {
        self.stack.iter().skip(1).map(|f| f.iteration).collect()
    }

    fn command(&mut self, ins: &Instruction) -> MotionCommandV2 {
        let (coords, joints) = (self.program.coords as u32, self.program.joints as u32);
        self.seq += 1;
        for f in &mut self.stack {
            f.first_seq.get_or_insert(self.seq);
        }
        let mut c = MotionCommandV2 {
            seq: self.seq,
            program_id: self.program_id,
            line: ins.line,
            ..MotionCommandV2::default()
        };
        match &ins.op {
            Op::Move {
                space,
                target,
                user_time_s,
                ..
            } => {
                let (kind, count) = match space {
                    Space::Cartesian => (CommandKind::Move, coords),
                    Space::Joint => (CommandKind::MoveJ, joints),
                };
                c.kind = kind as u32;
                c.count = count;
                c.target = *target;
                c.time_s = user_time_s.unwrap_or(0.0);
            }
            Op::Stop => c.kind = CommandKind::Stop as u32,
            Op::End => c.kind = CommandKind::End as u32,
            Op::Out { io, value } => {
                c.kind = CommandKind::Out as u32;
                c.io = *io;
                c.value = u32::from(*value);
            }
            Op::Wait {
                io,
                value,
                timeout_s,
            } => {
                c.kind = CommandKind::Wait as u32;
                c.io = *io;
                c.value = u32::from(*value);
                c.time_s = timeout_s.unwrap_or(0.0);
            }
            Op::Delay { seconds } => {
                c.kind = CommandKind::Delay as u32;
                c.time_s = *seconds;
            }
            Op::Speed { percent } => {
                c.kind = CommandKind::Speed as u32;
                c.speed = percent / 100.0;
            }
            // Not a command: the iterator enters the body.
            Op::Repeat { .. } => {}
        }
        c
    }
}

impl Iterator for Commands {
    type Item = MotionCommandV2;

    fn next(&mut self) -> Option<MotionCommandV2> {
        loop {
            let depth = self.stack.len().checked_sub(1)?;
            let frame = self.stack[depth];
            let Some(ins) = self.body(depth).get(frame.next).cloned() else {
                // The end of a body: again, or back out.
                match frame.left {
                    Some(0) => {
                        self.stack.pop();
                    }
                    left => {
                        let f = &mut self.stack[depth];
                        f.left = left.map(|n| n - 1);
                        f.next = 0;
                        f.iteration += 1;
                        f.first_seq = None;
                    }
                }
                continue;
            };
            self.stack[depth].next += 1;
            match &ins.op {
                Op::Repeat { count, body } => {
                    let count = count.or(self.forever_as);
                    if count != Some(0) && !body.is_empty() {
                        self.instances += 1;
                        self.stack.push(Frame {
                            at: Some(frame.next),
                            next: 0,
                            left: count.map(|n| n - 1),
                            iteration: 1,
                            instance: self.instances,
                            first_seq: None,
                        });
                    }
                }
                Op::End => {
                    let c = self.command(&ins);
                    self.stack.clear();
                    return Some(c);
                }
                _ => return Some(self.command(&ins)),
            }
        }
    }
}
