//! `machine-sim`: the simulated machine process. See the crate documentation.

use machine_sim::Machine;
use runtime::cycle::{CycleClock, Wake};
use runtime::ipc::{Pub, Sub};
use runtime::process::{self, Context, LATENCY_PUBLISH_INTERVAL_NS, SetupError, Task};
use shm_schema::{
    DriveCommandV2, DriveFeedbackV2, EventQueue, FaultInjectionV1, LatencyHistogramV1, Role,
    ServiceId,
};
use std::process::ExitCode;

struct Sim {
    machine: Machine,
    /// Sense-to-command latency of every applied command since start.
    sense_to_command: Box<LatencyHistogramV1>,
    last_published_ns: u64,
    commands: Sub<DriveCommandV2>,
    injections: Sub<FaultInjectionV1>,
    feedback: Pub<DriveFeedbackV2>,
    sense_to_command_pub: Pub<LatencyHistogramV1>,
}

impl Sim {
    fn publish_latency(&mut self, now_ns: u64) {
        self.sense_to_command.stamp_ns = now_ns;
        self.sense_to_command_pub.send(&self.sense_to_command);
        self.last_published_ns = now_ns;
    }
}

impl Task for Sim {
    /// # Real-time
    /// IPC calls, [`Machine::cycle`] and a histogram record; nothing else.
    fn cycle(&mut self, wake: &Wake, _clock: &mut CycleClock, events: &mut EventQueue) {
        let cmd = self.commands.latest();
        let inject = self.injections.next();
        let fb = self
            .machine
            .cycle(wake.actual_ns, cmd.as_ref(), inject.as_ref(), events);
        self.feedback.send(&fb);
        if fb.sense_to_command_ns > 0 {
            self.sense_to_command.record(fb.sense_to_command_ns);
        }
        if wake.actual_ns.saturating_sub(self.last_published_ns) >= LATENCY_PUBLISH_INTERVAL_NS {
            self.publish_latency(wake.actual_ns);
        }
    }

    fn stop(&mut self, now_ns: u64, _events: &mut EventQueue) {
        self.publish_latency(now_ns);
    }
}

fn main() -> ExitCode {
    process::run(
        Role::Machine,
        "simulated CiA 402 drives and mechanics",
        |ctx: &Context| {
            let i = &ctx.instance;
            Ok::<_, SetupError>(Sim {
                machine: Machine::new(&ctx.cell),
                sense_to_command: Box::default(),
                last_published_ns: 0,
                commands: Sub::new(&ctx.node, i, ServiceId::DriveCommand, 8)?,
                injections: Sub::new(&ctx.node, i, ServiceId::FaultInjection, 16)?,
                feedback: Pub::new(&ctx.node, i, ServiceId::DriveFeedback)?,
                sense_to_command_pub: Pub::new(&ctx.node, i, ServiceId::SenseToCommand)?,
            })
        },
    )
}
