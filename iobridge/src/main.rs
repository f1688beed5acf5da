//! `iobridge`: the IO bridge process. See the crate documentation.

use iobridge::write_image;
use runtime::health::Freshness;
use runtime::ipc::{Pub, Sub};
use runtime::process::{self, Context, Cycle, SetupError, Task};
use shm_schema::{FieldbusImageV1, ServiceId, ServoStateV3};
use std::process::ExitCode;

struct Bridge {
    seq: u64,
    servo: Sub<ServoStateV3>,
    last: Option<ServoStateV3>,
    /// Servo's states arrive every servo period.
    servo_fresh: Freshness,
    output: Pub<FieldbusImageV1>,
}

impl Task for Bridge {
    /// # Real-time
    /// IPC calls and [`write_image`]; nothing else.
    fn cycle(&mut self, cx: &mut Cycle<'_>) {
        let now = cx.now_ns();
        if let Some(s) = self.servo.latest() {
            self.last = Some(s);
        }
        cx.pending_overruns(self.servo_fresh.check(now, self.last.map(|s| s.stamp_ns)));
        if let Some(s) = &self.last {
            self.seq += 1;
            self.output.send(&write_image(self.seq, now, s));
        }
    }
}

fn main() -> ExitCode {
    process::run(
        "iobridge",
        "fieldbus output image with measurement timestamps",
        |ctx: &Context| {
            let i = &ctx.instance;
            Ok::<_, SetupError>(Bridge {
                seq: 0,
                servo: Sub::new(&ctx.node, i, ServiceId::ServoState, 8)?,
                last: None,
                servo_fresh: Freshness::new(
                    ctx.cell.period_of("servo").unwrap_or(ctx.own.period_ns),
                ),
                output: Pub::new(&ctx.node, i, ServiceId::FieldbusOutput)?,
            })
        },
    )
}
