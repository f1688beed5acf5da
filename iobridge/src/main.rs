//! `iobridge`: the IO bridge process. See the crate documentation.

use iobridge::write_image;
use runtime::cycle::{CycleClock, Wake};
use runtime::ipc::{Pub, Sub};
use runtime::process::{self, Context, SetupError, Task};
use shm_schema::EventQueue;
use shm_schema::{FieldbusImageV1, Role, ServiceId, ServoStateV2};
use std::process::ExitCode;

struct Bridge {
    seq: u64,
    servo: Sub<ServoStateV2>,
    last: Option<ServoStateV2>,
    output: Pub<FieldbusImageV1>,
}

impl Task for Bridge {
    /// # Real-time
    /// IPC calls and [`write_image`]; nothing else.
    fn cycle(&mut self, wake: &Wake, _clock: &mut CycleClock, _events: &mut EventQueue) {
        if let Some(s) = self.servo.latest() {
            self.last = Some(s);
        }
        if let Some(s) = &self.last {
            self.seq += 1;
            self.output.send(&write_image(self.seq, wake.actual_ns, s));
        }
    }
}

fn main() -> ExitCode {
    process::run(
        Role::Iobridge,
        "fieldbus output image with measurement timestamps",
        |ctx: &Context| {
            let i = &ctx.instance;
            Ok::<_, SetupError>(Bridge {
                seq: 0,
                servo: Sub::new(&ctx.node, i, ServiceId::ServoState, 8)?,
                last: None,
                output: Pub::new(&ctx.node, i, ServiceId::FieldbusOutput)?,
            })
        },
    )
}
