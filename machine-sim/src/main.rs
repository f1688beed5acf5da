//! `machine-sim`: the simulated machine process. See the crate documentation.

use machine_sim::Machine;
use runtime::cycle::{CycleClock, Wake};
use runtime::ipc::{Pub, Sub};
use runtime::process::{self, Context, SetupError, Task};
use shm_schema::{DriveCommandV1, DriveFeedbackV1, Role, ServiceId};
use std::process::ExitCode;

struct Sim {
    machine: Machine,
    commands: Sub<DriveCommandV1>,
    feedback: Pub<DriveFeedbackV1>,
}

impl Task for Sim {
    /// # Real-time
    /// IPC calls and [`Machine::cycle`]; nothing else.
    fn cycle(&mut self, wake: &Wake, _clock: &mut CycleClock) {
        let cmd = self.commands.latest();
        let fb = self.machine.cycle(wake.actual_ns, cmd.as_ref());
        self.feedback.send(&fb);
    }
}

fn main() -> ExitCode {
    process::run(
        Role::Machine,
        "simulated drives and mechanics",
        |ctx: &Context| {
            let i = &ctx.instance;
            Ok::<_, SetupError>(Sim {
                machine: Machine::new(&ctx.cell),
                commands: Sub::new(&ctx.node, i, ServiceId::DriveCommand, 8)?,
                feedback: Pub::new(&ctx.node, i, ServiceId::DriveFeedback)?,
            })
        },
    )
}
