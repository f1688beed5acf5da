//! `trajgen`: the trajectory generator process. See the crate documentation.

use motion_core::generator::{Generator, Kin, Params, QUEUE_CAP};
use runtime::ipc::{Notifier, Pub, Sub};
use runtime::process::{self, Context, Cycle, SetupError, Task};
use shm_schema::EventV1;
use shm_schema::drive::servo_status;
use shm_schema::event::code;
use shm_schema::motion::trajgen_fault;
use shm_schema::{
    DigitalIoV1, IoWriteV1, MotionCommandV2, MotionControlV2, ServiceId, ServoStateV3, SetpointV2,
    TrajgenHandoverV2,
};
use std::process::ExitCode;

struct Trajgen {
    params: Params,
    /// The cell's kinematics (`None`: the gantry, coordinates = joints).
    kin: Option<Kin>,
    /// `None` until servo's commanded position is known: the motion starts where servo is.
    generator: Option<Generator>,
    commands: Sub<MotionCommandV2>,
    /// Pause, resume, abort: taken at once, not queued.
    control: Sub<MotionControlV2>,
    servo: Sub<ServoStateV3>,
    setpoints: Pub<SetpointV2>,
    /// Wakes event-driven consumers after each setpoint (none in the default cell: servo
    /// runs on its own phase of the shared grid).
    ready: Notifier,
    /// The fault last reported as an event.
    reported_fault: u32,
    /// Servo's newest state.
    last_servo: Option<ServoStateV3>,
    /// The paused motion, for a successor (and from a predecessor, at start).
    handover_pub: Pub<TrajgenHandoverV2>,
    handover_sub: Sub<TrajgenHandoverV2>,
    /// A valid handover record is the newest published.
    handing_over: bool,
    /// The program's outputs, to iobridge; its inputs, from iobridge's image.
    io_requests: Pub<IoWriteV1>,
    io_state: Sub<DigitalIoV1>,
    inputs: Option<u64>,
    index: u32,
}

impl Trajgen {
    fn new(ctx: &Context) -> Result<Self, SetupError> {
        let i = &ctx.instance;
        let kin = Kin::of_cell(&ctx.cell).map_err(|e| format!("kinematics: {e}"))?;
        Ok(Self {
            kin,
            params: Params::from_cell(&ctx.cell),
            generator: None,
            commands: Sub::new(&ctx.node, i, ServiceId::MotionCommand, QUEUE_CAP)?,
            control: Sub::new(&ctx.node, i, ServiceId::MotionControl, 8)?,
            servo: Sub::new(&ctx.node, i, ServiceId::ServoState, 4)?,
            setpoints: Pub::new(&ctx.node, i, ServiceId::Setpoint)?,
            ready: Notifier::new(&ctx.node, i, ServiceId::SetpointReady)?,
            reported_fault: trajgen_fault::NONE,
            last_servo: None,
            handover_pub: Pub::new(&ctx.node, i, ServiceId::TrajgenHandover)?,
            handover_sub: Sub::new(&ctx.node, i, ServiceId::TrajgenHandover, 1)?,
            handing_over: false,
            io_requests: Pub::new(&ctx.node, i, ServiceId::IoRequest)?,
            io_state: Sub::new(&ctx.node, i, ServiceId::IoState, 1)?,
            inputs: None,
            index: ctx.index as u32,
        })
    }
}

impl Task for Trajgen {
    /// # Real-time
    /// IPC calls, then [`Generator::step`]; nothing else.
    fn cycle(&mut self, cx: &mut Cycle<'_>) {
        let now = cx.now_ns();
        // Servo's commanded position, once servo has drive feedback.
        let servo = self
            .servo
            .latest()
            .filter(|s| s.status & servo_status::NO_FEEDBACK == 0);
        if let Some(s) = servo {
            self.last_servo = Some(s);
        }
        let servo = self.last_servo;
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
            (None, Some(s)) => {
                let successor = self
                    .handover_sub
                    .latest()
                    .and_then(|h| successor(&h, &s, now, self.params, self.kin.clone()));
                let g = match successor {
                    // A predecessor paused a motion where servo holds: go on with it.
                    Some(g) => g,
                    // A process is being replaced: this may be the successor, and the
                    // supervisor's offer may not have reached us yet. Wait for it (or for
                    // the handover to end), publishing nothing.
                    None if cx.handover => return,
                    None => {
                        Generator::with_kinematics(self.params, self.kin.clone(), &s.cmd_position)
                    }
                };
                self.generator.insert(g)
            }
            // No servo yet: nothing to start from, publish nothing.
            (None, None) => return,
        };
        if cx.estop.react.is_some() {
            // E-stop: the program is dropped, commands are refused until it is reset; the
            // reference rests where servo brings the axes.
            while self.commands.next().is_some() {}
            while self.control.next().is_some() {}
            if let Some(s) = servo {
                generator.abort(&s.cmd_position);
            }
        } else {
            while let Some(c) = self.commands.next() {
                generator.push_command(&c);
            }
            while let Some(c) = self.control.next() {
                generator.control(&c, now);
            }
        }
        if let Some(io) = self.io_state.latest() {
            self.inputs = Some(io.values);
        }
        let sp = generator.step(now, self.inputs);
        self.setpoints.send(&sp);
        if let Some(o) = generator.take_outputs() {
            self.io_requests.send(&IoWriteV1 {
                stamp_ns: now,
                mask: o.mask,
                values: o.values,
                source: self.index,
                line: o.line,
            });
        }
        match generator.handover(now) {
            Some(h) => {
                self.handover_pub.send(&h);
                self.handing_over = true;
            }
            None if self.handing_over => {
                self.handover_pub.send(&TrajgenHandoverV2::default());
                self.handing_over = false;
            }
            None => {}
        }
        if sp.fault != self.reported_fault {
            self.reported_fault = sp.fault;
            // Leaving (a stop request) drops the program too, but is no fault to report.
            if sp.fault != trajgen_fault::NONE
                && (sp.fault != trajgen_fault::ESTOP || cx.estop.latched)
                && sp.fault != trajgen_fault::ABORTED
            {
                cx.events.push(EventV1::new(
                    now,
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
            cx.clock.request_wake_at(t);
        }
    }
}

/// The generator that goes on with `h`, a predecessor's paused motion, if `h` is valid,
/// recent, and rests where servo holds (so its first setpoint is no jump).
fn successor(
    h: &TrajgenHandoverV2,
    s: &ServoStateV3,
    now: u64,
    p: Params,
    kin: Option<Kin>,
) -> Option<Generator> {
    const RECENT_NS: u64 = 30_000_000_000;
    if h.valid != 1 || now.saturating_sub(h.stamp_ns) > RECENT_NS {
        return None;
    }
    let g = Generator::resume_from(p, kin, h, now, &s.cmd_position);
    let rest = g.rest_position();
    (0..p.axes)
        .all(|i| (rest[i] - s.cmd_position[i]).abs() < 1e-3)
        .then_some(g)
}

fn main() -> ExitCode {
    process::run(
        "trajgen",
        "trajectory generator (seed 003 §2): blend zones against real elapsed time",
        Trajgen::new,
    )
}
