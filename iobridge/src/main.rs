//! `iobridge`: the IO bridge process. See the crate documentation.

use iobridge::digital::DigitalIo;
use iobridge::write_image;
use runtime::health::Freshness;
use runtime::ipc::{Pub, Sub};
use runtime::process::{self, Context, Cycle, SetupError, Task};
use shm_schema::event::code;
use shm_schema::{
    DigitalIoV1, EstopOrigin, EventV1, FieldbusImageV1, IoWriteV1, ServiceId, ServoStateV3,
};
use std::process::ExitCode;
use std::time::{Duration, Instant};

/// How long set-up waits for a predecessor's IO image.
const ADOPT_WAIT: Duration = Duration::from_millis(50);

struct Bridge {
    /// Fieldbus images written.
    seq: u64,
    cycles: u64,
    servo: Sub<ServoStateV3>,
    last: Option<ServoStateV3>,
    /// Servo's states arrive every servo period.
    servo_fresh: Freshness,
    output: Pub<FieldbusImageV1>,
    io: DigitalIo,
    field: Sub<IoWriteV1>,
    requests: Sub<IoWriteV1>,
    io_state: Pub<DigitalIoV1>,
}

impl Task for Bridge {
    /// # Real-time
    /// IPC calls, [`write_image`], [`DigitalIo`] and a read of the clock
    /// (`runtime::time::now_ns`, the vDSO's: no system call); nothing else.
    fn cycle(&mut self, cx: &mut Cycle<'_>) {
        let now = cx.now_ns();
        if let Some(s) = self.servo.latest() {
            self.last = Some(s);
        }
        cx.pending_overruns(self.servo_fresh.check(now, self.last.map(|s| s.stamp_ns)));
        if let Some(s) = &self.last {
            self.seq += 1;
            // Stamped as it is written, not at the wake-up: iobridge runs below the drives and
            // servo, and a state servo published while this cycle waited for the CPU holds
            // positions measured after the wake-up. The image's age is never negative.
            let written = runtime::time::now_ns();
            self.output.send(&write_image(self.seq, written, s));
        }
        // The field first, then the e-stop reaction, then the requests: a request never
        // overrides a safe value in the cycle that set it.
        while let Some(w) = self.field.next() {
            self.io.field(&w, now, cx.events);
        }
        // Leaving during a swap (no e-stop, a handover announced): the successor takes over
        // the outputs as they are, so the old one must not switch them to their safe values.
        let swapped_out = !cx.estop.latched && cx.handover;
        self.io.react(cx.estop.react.is_some() && !swapped_out);
        while let Some(w) = self.requests.next() {
            self.io.request(&w, now, cx.events);
        }
        if !cx.estop.latched
            && let Some(k) = self.io.open_estop_input()
        {
            let name = self.io.name(k);
            let why = ["e-stop input ", name, " is open"];
            cx.events
                .push(EventV1::new(now, code::ESTOP_INPUT, -1, 0.0, 0.0, &why));
            cx.raise_estop(EstopOrigin::External, code::ESTOP_INPUT, &why);
        }
        self.cycles += 1;
        let image = self.io.image(self.cycles, now, cx.events);
        self.io_state.send(&image);
    }
}

impl Bridge {
    /// The bridge with its IO taken over from a predecessor, if any, and its ports opened.
    /// Set-up only.
    fn new(ctx: &Context) -> Result<Self, SetupError> {
        let i = &ctx.instance;
        let io_seen = Sub::<DigitalIoV1>::new(&ctx.node, i, ServiceId::IoState, 1)?;
        let mut io = DigitalIo::new(&ctx.cell);
        // A predecessor's image (it still runs during a swap or a requested restart; its
        // publisher keeps the last one): its IO carries over, so a swap neither drops the
        // gripper's part nor forgets an open e-stop circuit. Its publisher delivers the image
        // on its next cycle, which a host stall can hold off: with a predecessor alive (a
        // publisher on the service) this waits for it, however long the stall, up to the
        // configuration's timeout, and refuses to start blind past it. Without one (a cell
        // starting, a crashed iobridge's node already cleaned) there is nothing to wait for
        // beyond a moment.
        let predecessor = runtime::ipc::io_state_publishers(&ctx.node, i)? > 0;
        let wait = if predecessor {
            process::CONFIG_TIMEOUT
        } else {
            ADOPT_WAIT
        };
        let until = Instant::now() + wait;
        let mut adopted = false;
        while Instant::now() < until {
            if let Some(image) = io_seen.latest() {
                adopted = io.adopt(&image);
                if adopted {
                    tracing::info!("took over the IO of the previous iobridge's image");
                }
                break;
            }
            std::thread::sleep(Duration::from_millis(2));
        }
        if predecessor && !adopted {
            return Err(format!(
                "another iobridge runs and its IO image did not come in {} s (or does not fit \
                 this cell's IO table): not taking over its outputs blind",
                wait.as_secs()
            )
            .into());
        }
        drop(io_seen);
        Ok(Self {
            seq: 0,
            cycles: 0,
            servo: Sub::new(&ctx.node, i, ServiceId::ServoState, 8)?,
            last: None,
            servo_fresh: Freshness::new(ctx.period_of("servo")?),
            output: Pub::new(&ctx.node, i, ServiceId::FieldbusOutput)?,
            io,
            field: Sub::new(&ctx.node, i, ServiceId::FieldInputs, 64)?,
            requests: Sub::new(&ctx.node, i, ServiceId::IoRequest, 64)?,
            io_state: Pub::new(&ctx.node, i, ServiceId::IoState)?,
        })
    }
}

fn main() -> ExitCode {
    process::run(
        "iobridge",
        "fieldbus output image with measurement timestamps, and the named digital IO",
        Bridge::new,
    )
}
