//! `trajgen`: the trajectory generator process. See the crate documentation.

use runtime::cycle::{CycleClock, Wake};
use runtime::ipc::{Notifier, Pub, Sub};
use runtime::process::{self, Context, SetupError, Task};
use shm_schema::drive::servo_status;
use shm_schema::event::code;
use shm_schema::motion::trajgen_fault;
use shm_schema::{EventQueue, EventV1};
use shm_schema::{MotionCommandV1, Role, ServiceId, ServoStateV2, SetpointV1};
use std::process::ExitCode;
use trajgen::generator::{Generator, Params, QUEUE_CAP};

struct Trajgen {
    params: Params,
    /// `None` until servo's commanded position is known: the motion starts where servo is.
    generator: Option<Generator>,
    commands: Sub<MotionCommandV1>,
    servo: Sub<ServoStateV2>,
    setpoints: Pub<SetpointV1>,
    /// Wakes event-driven consumers after each setpoint (none in the default cell: servo
    /// runs on its own phase of the shared grid).
    ready: Notifier,
    /// The fault last reported as an event.
    reported_fault: u32,
}

impl Trajgen {
    fn new(ctx: &Context) -> Result<Self, SetupError> {
        let i = &ctx.instance;
        Ok(Self {
            params: Params::from_cell(&ctx.cell),
            generator: None,
            commands: Sub::new(&ctx.node, i, ServiceId::MotionCommand, QUEUE_CAP)?,
            servo: Sub::new(&ctx.node, i, ServiceId::ServoState, 4)?,
            setpoints: Pub::new(&ctx.node, i, ServiceId::Setpoint)?,
            ready: Notifier::new(&ctx.node, i, ServiceId::SetpointReady)?,
            reported_fault: trajgen_fault::NONE,
        })
    }
}

impl Task for Trajgen {
    /// # Real-time
    /// IPC calls, then [`Generator::step`]; nothing else.
    fn cycle(&mut self, wake: &Wake, clock: &mut CycleClock, events: &mut EventQueue) {
        // Servo's commanded position, once servo has drive feedback.
        let servo = self
            .servo
            .latest()
            .filter(|s| s.status & servo_status::NO_FEEDBACK == 0);
        let generator = match (&mut self.generator, servo) {
            (Some(g), Some(s))
                if s.status & (servo_status::SETPOINT_JUMP | servo_status::ENABLED)
                    != servo_status::ENABLED =>
            {
                // Servo does not follow us (the arm is not enabled, or it refused our
                // setpoint as a jump because it restarted or the machine moved): at rest,
                // start again from where servo holds.
                g.resync(&s.cmd_position);
                g
            }
            (Some(g), _) => g,
            (None, Some(s)) => self
                .generator
                .insert(Generator::new(self.params, &s.cmd_position)),
            // No servo yet: nothing to start from, publish nothing.
            (None, None) => return,
        };
        while let Some(c) = self.commands.next() {
            generator.push_command(&c);
        }
        let sp = generator.step(wake.actual_ns);
        self.setpoints.send(&sp);
        if sp.fault != self.reported_fault {
            self.reported_fault = sp.fault;
            if sp.fault != trajgen_fault::NONE {
                events.push(EventV1::new(
                    wake.actual_ns,
                    code::MOTION_COMMAND_REFUSED,
                    -1,
                    sp.fault_line as f64,
                    sp.fault as f64,
                    &[trajgen_fault::text(sp.fault)],
                ));
            }
        }
        self.ready.notify();
        // Read the next command at exactly t = T1 - t_acc, not at the next period.
        if let Some(t) = generator.next_transition_ns() {
            clock.request_wake_at(t);
        }
    }
}

fn main() -> ExitCode {
    process::run(
        Role::Trajgen,
        "trajectory generator (seed 003 §2): blend zones against real elapsed time",
        Trajgen::new,
    )
}
