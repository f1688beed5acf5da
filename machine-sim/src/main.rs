//! `machine-sim`: the simulated machine process. See the crate documentation.

use machine_sim::Machine;
use machine_sim::field::Field;
use runtime::health::Freshness;
use runtime::ipc::{Pub, Sub};
use runtime::process::{self, Context, Cycle, SetupError, Task};
use runtime::snapshot::SenseToCommand;
use shm_schema::{
    DigitalIoV1, DriveCommandV2, DriveFeedbackV2, EventQueue, FaultInjectionV1, IoWriteV1,
    ServiceId,
};
use std::process::ExitCode;

struct Sim {
    machine: Machine,
    sense_to_command: SenseToCommand,
    /// Servo's commands arrive every servo period.
    command_fresh: Freshness,
    last_command_ns: Option<u64>,
    commands: Sub<DriveCommandV2>,
    injections: Sub<FaultInjectionV1>,
    feedback: Pub<DriveFeedbackV2>,
    /// The simulated two-position devices (the gripper) and their sensors.
    field: Field,
    io_state: Sub<DigitalIoV1>,
    sensors: Pub<IoWriteV1>,
}

impl Task for Sim {
    /// # Real-time
    /// IPC calls, [`Machine::cycle`] and a histogram record; nothing else.
    fn cycle(&mut self, cx: &mut Cycle<'_>) {
        let now = cx.now_ns();
        let cmd = self.commands.latest();
        if let Some(c) = &cmd {
            self.last_command_ns = Some(c.stamp_ns);
        }
        cx.pending_overruns(self.command_fresh.check(now, self.last_command_ns));
        let inject = self.injections.next();
        let fb = self
            .machine
            .cycle(now, cmd.as_ref(), inject.as_ref(), cx.events);
        // Safe (for leaving, for an e-stop) once no drive has its power stage on: servo
        // disabled them, or their watchdog did.
        cx.set_safe(!self.machine.powered());
        self.feedback.send(&fb);
        self.sense_to_command
            .step(now, Some(fb.sense_to_command_ns).filter(|&ns| ns > 0));
        if !self.field.is_empty() {
            let outputs = self.io_state.latest().map(|s| s.values);
            if let Some(w) = self.field.step(now, outputs) {
                self.sensors.send(&w);
            }
        }
    }

    fn stop(&mut self, now_ns: u64, _events: &mut EventQueue) {
        self.sense_to_command.finish(now_ns);
    }
}

impl Sim {
    /// The drives and mechanics of the cell, their ports opened. Set-up only.
    fn new(ctx: &Context) -> Result<Self, SetupError> {
        let i = &ctx.instance;
        Ok(Self {
            machine: Machine::new(&ctx.cell, ctx.own.period_ns),
            sense_to_command: SenseToCommand::new(&ctx.node, i)?,
            command_fresh: Freshness::new(ctx.period_of("servo")?),
            last_command_ns: None,
            commands: Sub::new(&ctx.node, i, ServiceId::DriveCommand, 8)?,
            injections: Sub::new(&ctx.node, i, ServiceId::FaultInjection, 16)?,
            feedback: Pub::new(&ctx.node, i, ServiceId::DriveFeedback)?,
            field: Field::new(&ctx.cell, ctx.index as u32),
            io_state: Sub::new(&ctx.node, i, ServiceId::IoState, 1)?,
            sensors: Pub::new(&ctx.node, i, ServiceId::FieldInputs)?,
        })
    }
}

fn main() -> ExitCode {
    process::run("drives", "simulated CiA 402 drives and mechanics", Sim::new)
}
