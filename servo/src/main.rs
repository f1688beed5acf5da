//! `servo`: the servo-layer process. See the crate documentation.

use runtime::health::Freshness;
use runtime::ipc::{Pub, Sub};
use runtime::process::{self, Context, Cycle, SetupError, Task};
use servo::{Controller, Params};
use shm_schema::{
    DriveCommandV2, DriveFeedbackV2, EstopOrigin, ServiceId, ServoRequestV1, ServoStateV3,
    SetpointV2,
};
use std::process::ExitCode;

struct Servo {
    controller: Controller,
    feedback: Option<DriveFeedbackV2>,
    /// Stamp of the newest setpoint.
    setpoint_ns: Option<u64>,
    setpoint_fresh: Freshness,
    feedback_fresh: Freshness,
    /// A device e-stop was raised for the fault latched now.
    raised: bool,
    requests: Sub<ServoRequestV1>,
    setpoints: Sub<SetpointV2>,
    drive_feedback: Sub<DriveFeedbackV2>,
    drive_commands: Pub<DriveCommandV2>,
    state: Pub<ServoStateV3>,
}

impl Servo {
    fn new(ctx: &Context) -> Result<Self, SetupError> {
        let i = &ctx.instance;
        let trajgen_ns = ctx.period_of("trajgen")?;
        Ok(Self {
            controller: Controller::new(Params::from_cell(
                &ctx.cell,
                ctx.own.period_ns,
                trajgen_ns,
            )),
            feedback: None,
            setpoint_ns: None,
            setpoint_fresh: Freshness::new(trajgen_ns),
            feedback_fresh: Freshness::new(ctx.period_of("drives")?),
            raised: false,
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
    fn cycle(&mut self, cx: &mut Cycle<'_>) {
        let now = cx.now_ns();
        self.controller.set_estop(now, cx.estop.react, cx.events);
        // One request per cycle, oldest first: each takes effect in its own cycle.
        let request = self.requests.next();
        let sp = self.setpoints.latest();
        if let Some(s) = &sp {
            self.setpoint_ns = Some(s.stamp_ns);
        }
        if let Some(fb) = self.drive_feedback.latest() {
            self.feedback = Some(fb);
        }
        cx.pending_overruns(
            self.setpoint_fresh.check(now, self.setpoint_ns)
                + self
                    .feedback_fresh
                    .check(now, self.feedback.map(|f| f.stamp_ns)),
        );
        let (cmd, state) = self.controller.cycle(
            now,
            request.as_ref(),
            sp.as_ref(),
            self.feedback.as_ref(),
            cx.events,
        );
        self.drive_commands.send(&cmd);
        self.state.send(&state);
        // A latched fault is a device e-stop of servo (seed 002): raised once per latch.
        match self.controller.latched() {
            Some(l) if !self.raised => {
                self.raised = true;
                let name = shm_schema::event::info(l.code).map_or("fault", |i| i.name);
                cx.raise_estop(EstopOrigin::Device, l.code, &["servo: ", name]);
            }
            None => self.raised = false,
            _ => {}
        }
        cx.set_safe(self.controller.estop_safe());
    }
}

fn main() -> ExitCode {
    process::run(
        "servo",
        "servo layer over CiA 402 drives and the axes' position loops, running at all times",
        Servo::new,
    )
}
