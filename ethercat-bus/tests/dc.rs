//! Distributed Clocks end to end: the bus' [`Master`] brings an EK1100 and a drive up with
//! the drive on SYNC0 (the EK1100 the reference clock), then the cycle's frame runs against
//! the emulated line in simulated time, a period at a time, with both quartzes off (the
//! reference 300 ppm fast, the drive 200 ppm slow). With the frame's DC datagrams the
//! reference keeps the host's clock and the drive the reference's: every SYNC0 comes half a
//! period after the bus process' wake-up, the drive applies each frame's outputs there (not
//! as the frame passes) and latches its inputs at the wake-up, and no SYNC0 finds its outputs
//! missing. Without them the drive's SYNC0 slides through the period and finds some missing.
//!
//! Bring-up runs on a veth pair in a network namespace of the test's own (root), the emulated
//! line answering on a thread of the test; the cycles then run in the test itself, the line's
//! time given with each frame (no wall clock: the figures do not depend on the machine).

mod common;

use cia402::pdo::{RxPdo, obj};
use common::{Line, config, drive_x};
use ethercat_bus::bringup::{Master, Timing};
use ethercat_bus::frame::{CyclicFrame, Reply};
use ethercat_emulator::bus::Bus;
use ethercat_emulator::drive::{self, Drive};
use ethercat_emulator::terminals::Terminal;
use shm_schema::ethercat::subdevice_flags;
use shm_schema::{EthercatSubDeviceV1, fixed_str};

const PERIOD: u64 = 1_000_000;
const PHASE: u64 = 100_000;
/// From the wake-up to the frame sent (the time it gives the reference clock), and to the
/// frame passing the line, in the simulated cycles.
const SENT: u64 = 10_000;
const TO_THE_LINE: u64 = 40_000;

fn the_drive(bus: &Bus) -> &Drive {
    match &bus.devices[1].terminal {
        Terminal::Drive(d) => d,
        _ => panic!("position 1 is the drive"),
    }
}

#[test]
fn sync0_keeps_the_bus_process_grid_through_quartz_drift_and_takes_the_outputs_there() {
    let (axis, scaling) = drive::standalone();
    let line = Line::new(
        "dc",
        Bus::new([
            Terminal::Ek1100,
            Terminal::Drive(Box::new(Drive::new("x", &axis, scaling, 300_000_000))),
        ]),
    );
    let coupler = EthercatSubDeviceV1 {
        name: fixed_str("EK1100"),
        vendor: 2,
        product: 0x044C_2C52,
        axis: -1,
        ..EthercatSubDeviceV1::default()
    };
    let cfg = config(&[coupler, drive_x(subdevice_flags::SYNC0)]);
    let mut axes = [axis];
    axes[0].mode = 8;
    let timing = Timing {
        period_ns: PERIOD,
        phase_ns: PHASE,
    };
    let up = line
        .on_m0(move |wire| {
            let mut master = Master::new().expect("the process' MainDevice");
            master.bring_up(&cfg, &axes, timing, wire, &|| false)
        })
        .expect("the bus in OP");
    let dc = up.dc.expect("Distributed Clocks set up");
    assert_eq!(
        (dc.reference, dc.on_sync0, dc.cycle_ns, dc.shift_ns),
        (0, 0b10, PERIOD, PERIOD / 2),
        "the EK1100 the reference, the drive on SYNC0 half a period after the wake-up"
    );
    assert_eq!(
        dc.latch_shift_ns,
        PERIOD / 2,
        "its inputs latched at the next wake-up"
    );
    let mut bus = line.stop();
    bus.devices[0].esc.set_drift(-300.0);
    bus.devices[1].esc.set_drift(200.0);

    // The cycles, on the bus process' grid from the next wake-up on (SYNC0 starts 300 ms
    // after the bring-up: the first cycles come before it).
    let start = (runtime::time::now_ns() / PERIOD + 1) * PERIOD + PHASE;
    let cycle = |frame: &mut CyclicFrame, bus: &mut Bus, k: u64| {
        let wake = start + k * PERIOD;
        let out = RxPdo {
            target_position: k as i32,
            mode: 8,
            ..RxPdo::default()
        };
        out.write(frame.outputs_mut(1));
        frame.set_master_time((wake + SENT).wrapping_add(dc.epoch_ns));
        let mut f = frame.next_frame().to_vec();
        bus.handle_at(&mut f, wake + TO_THE_LINE)
            .expect("the line takes the frame");
        f[6] |= 0x02; // the first SubDevice's mark, as on the wire
        assert!(
            matches!(frame.take_reply(&f), Reply::Ours { wkc: 3, .. }),
            "the drive took its data in cycle {k}"
        );
        wake
    };

    // The bus came up in SAFE-OP: the cycle's first frame asks for OP (after its AL status
    // reads), and the reply to the second finds every SubDevice there.
    let mut frame = CyclicFrame::new(up.layout, Some(dc.station)).expect("one frame");
    assert_eq!(
        frame.al_status(1),
        (0, 0),
        "nothing read before the first frame"
    );
    frame.request_op(true);
    cycle(&mut frame, &mut bus, 0);
    assert_eq!(
        (frame.al_status(0).0, frame.al_status(1).0),
        (0x04, 0x04),
        "both read in SAFE-OP by the first frame"
    );
    cycle(&mut frame, &mut bus, 1);
    assert_eq!(
        (frame.al_status(0).0, frame.al_status(1).0),
        (0x08, 0x08),
        "both in OP by the second frame"
    );
    frame.request_op(false);
    let cycles = 20_000; // 20 s
    let settle = 2_000;
    let missed_before = the_drive(&bus).sm_events_missed();
    let mut leads = Vec::new();
    for k in 2..cycles {
        let wake = cycle(&mut frame, &mut bus, k);
        let (r, dc_subdevices) = frame.reference_time().expect("the FRMW read the reference");
        assert_eq!(dc_subdevices, 2, "the EK1100 read, the drive took its time");
        let Some((latch, lead)) = dc.around(r) else {
            continue;
        };
        // Outputs applied at SYNC0: as the frame of cycle k passed, the drive's target is
        // still cycle k - 1's.
        let target = the_drive(&bus).dictionary().i32(obj::TARGET_POSITION);
        assert_eq!(
            i64::from(target),
            k as i64 - 1,
            "cycle {k}: the drive took the outputs at SYNC0"
        );
        if k >= settle {
            leads.push(lead);
            let latched_at = latch.wrapping_sub(dc.epoch_ns) as i64 - wake as i64;
            assert!(
                latched_at.abs() < 20_000,
                "cycle {k}: inputs latched {latched_at} ns from the wake-up"
            );
        }
    }
    let (lo, hi) = (
        *leads.iter().min().expect("leads"),
        *leads.iter().max().expect("leads"),
    );
    // The reference keeps the time the frame brings as the frame passes it: the line's DC
    // time runs the frame's way to the line behind the host's, SYNC0 comes half a period
    // after the frame was sent.
    let expected = PERIOD / 2 - SENT;
    assert!(
        lo + 20_000 > expected && hi < expected + 20_000,
        "SYNC0 came {lo}..{hi} ns after the frame, {expected} expected"
    );
    assert_eq!(
        the_drive(&bus).sm_events_missed(),
        missed_before,
        "no SYNC0 without new outputs"
    );

    // The same without the DC datagrams: nothing keeps the clocks on the host's.
    let mut free = CyclicFrame::new(up.layout, None).expect("one frame");
    let before = the_drive(&bus).sm_events_missed();
    for k in cycles..2 * cycles {
        cycle(&mut free, &mut bus, k);
    }
    let missed = the_drive(&bus).sm_events_missed() - before;
    assert!(
        missed > 0,
        "a drive 200 ppm fast has 4 SYNC0 more than frames in 20 s: some find no new outputs"
    );
    eprintln!(
        "with the DC datagrams: SYNC0 {lo}..{hi} ns after the frame, no SYNC0 missed; without: {missed} missed in 20 s"
    );
}
