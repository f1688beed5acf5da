//! `servo`: the servo-layer process. See the crate documentation.

use runtime::cycle::{CycleClock, Wake};
use runtime::ipc::{Pub, Sub};
use runtime::process::{self, Context, SetupError, Task};
use servo::{Controller, Params};
use shm_schema::{
    DriveCommandV2, DriveFeedbackV2, EventQueue, Role, ServiceId, ServoRequestV1, ServoStateV2,
    SetpointV1,
};
use std::process::ExitCode;

struct Servo {
    controller: Controller,
    feedback: Option<DriveFeedbackV2>,
    requests: Sub<ServoRequestV1>,
    setpoints: Sub<SetpointV1>,
    drive_feedback: Sub<DriveFeedbackV2>,
    drive_commands: Pub<DriveCommandV2>,
    state: Pub<ServoStateV2>,
}

impl Servo {
    fn new(ctx: &Context) -> Result<Self, SetupError> {
        let i = &ctx.instance;
        Ok(Self {
            controller: Controller::new(Params::from_cell(&ctx.cell)),
            feedback: None,
            requests: Sub::new(&ctx.node, i, ServiceId::ServoRequest, 16)?,
            setpoints: Sub::new(&ctx.node, i, ServiceId::Setpoint, 8)?,
            drive_feedback: Sub::new(&ctx.node, i, ServiceId::DriveFeedback, 8)?,
            drive_commands: Pub::new(&ctx.node, i, ServiceId::DriveCommand)?,
            state: Pub::new(&ctx.node, i, ServiceId::ServoState)?,
        })
    }
}

impl Task for Servo {
    /// # Real-time
    /// IPC calls and [`Controller::cycle`]; nothing else.
    fn cycle(&mut self, wake: &Wake, _clock: &mut CycleClock, events: &mut EventQueue) {
        // One request per cycle, oldest first: each takes effect in its own cycle.
        let request = self.requests.next();
        let sp = self.setpoints.latest();
        if let Some(fb) = self.drive_feedback.latest() {
            self.feedback = Some(fb);
        }
        let (cmd, state) = self.controller.cycle(
            wake.actual_ns,
            request.as_ref(),
            sp.as_ref(),
            self.feedback.as_ref(),
            events,
        );
        self.drive_commands.send(&cmd);
        self.state.send(&state);
    }
}

fn main() -> ExitCode {
    process::run(
        Role::Servo,
        "servo layer over CiA 402 drives and the axes' position loops, running at all times",
        Servo::new,
    )
}
