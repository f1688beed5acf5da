//! The bus process' cycle without the wire: the outputs written from servo's command into the
//! cycle's frame, the frame as a line of SubDevices would return it, the feedback read back.
//! Units both ways, what the bus sends by itself (Disable voltage before servo's first
//! command, Quick stop once servo is silent, never bit 7), NaN when a SubDevice did not take
//! its data, a reply to another frame ignored, a CoE emergency read from a full send mailbox
//! in the next frame (and not read twice); and none of it allocates.

use cia402::pdo::{PDO_BYTES, RxPdo, TxPdo};
use ethercat_bus::Drives;
use ethercat_bus::frame::{CyclicFrame, Layout, Reply, Slot, coe_emergency};
use runtime::alloc_count::{CountingAllocator, count};
use shm_schema::ethercat::MAX_SUBDEVICES;
use shm_schema::{DriveCommandV2, EthercatConfigV1, EthercatSubDeviceV1, EventQueue, fixed_str};

#[global_allocator]
static A: CountingAllocator = CountingAllocator;

/// An EK1100, then drives for axes 1 and 0 (the order on the wire is not the axes').
fn bus() -> (EthercatConfigV1, Layout) {
    let mut c = EthercatConfigV1 {
        interface: fixed_str("m0"),
        count: 3,
        ..EthercatConfigV1::default()
    };
    c.subdevice[0] = EthercatSubDeviceV1 {
        name: fixed_str("EK1100"),
        axis: -1,
        ..EthercatSubDeviceV1::default()
    };
    for (k, axis, name) in [(1, 1, "y"), (2, 0, "x")] {
        c.subdevice[k] = EthercatSubDeviceV1 {
            name: fixed_str(name),
            axis,
            counts_per_unit: 1000.0,
            rated_effort: 10.0,
            ..EthercatSubDeviceV1::default()
        };
    }
    let p = PDO_BYTES as u16;
    let mut slots = [Slot::default(); MAX_SUBDEVICES];
    slots[0].station = 0x1000;
    slots[1] = Slot {
        station: 0x1001,
        outputs: (0, p),
        inputs: (p, p),
        mailbox_in: (0x1080, MAILBOX),
    };
    slots[2] = Slot {
        station: 0x1002,
        outputs: (2 * p, p),
        inputs: (3 * p, p),
        mailbox_in: (0x1080, MAILBOX),
    };
    let layout = Layout {
        logical_start: 0,
        len: 4 * p,
        slots,
        count: 3,
        expected_wkc: 6,
    };
    (c, layout)
}

/// Bytes of each drive's send mailbox.
const MAILBOX: u16 = 128;

/// A CoE emergency of `code` as a drive's send mailbox holds it.
fn emergency(code: u16) -> [u8; MAILBOX as usize] {
    let mut m = [0u8; MAILBOX as usize];
    m[0..2].copy_from_slice(&10u16.to_le_bytes());
    m[5] = 0x13; // CoE, counter 1
    m[6..8].copy_from_slice(&(1u16 << 12).to_le_bytes()); // emergency
    m[8..10].copy_from_slice(&code.to_le_bytes());
    m[10] = 0x01;
    m
}

/// The frame as the line returns it: the source marked, the drives' inputs filled (their
/// position `x_counts` and `y_counts`), the working counter `wkc`, each AL status OP, x's send
/// mailbox full if `x_full`, and a mailbox read (if the frame has one) answered with
/// `mailbox`.
fn reply(sent: &[u8], wkc: u16, x_counts: i32, y_counts: i32) -> Vec<u8> {
    reply_with(sent, wkc, x_counts, y_counts, false, &[0; MAILBOX as usize])
}

fn reply_with(
    sent: &[u8],
    wkc: u16,
    x_counts: i32,
    y_counts: i32,
    x_full: bool,
    mailbox: &[u8],
) -> Vec<u8> {
    let mut r = sent.to_vec();
    r[6] |= 0x02;
    let image = 14 + 2 + 10;
    let p = PDO_BYTES;
    for (at, counts) in [(p, y_counts), (3 * p, x_counts)] {
        let mut i = [0u8; PDO_BYTES];
        i[0..2].copy_from_slice(&0x0237u16.to_le_bytes()); // Operation enabled
        i[2] = 8;
        i[5..9].copy_from_slice(&counts.to_le_bytes());
        r[image + at..image + at + p].copy_from_slice(&i);
    }
    let wkc_at = image + 4 * p;
    r[wkc_at..wkc_at + 2].copy_from_slice(&wkc.to_le_bytes());
    let mut at = wkc_at + 2;
    for _ in 0..3 {
        r[at + 10..at + 12].copy_from_slice(&0x0008u16.to_le_bytes());
        r[at + 16..at + 18].copy_from_slice(&1u16.to_le_bytes());
        at += 18;
    }
    // SM1 status of y (position 1), then of x (position 2).
    for full in [false, x_full] {
        r[at + 10] = if full { 0x08 } else { 0 };
        r[at + 11..at + 13].copy_from_slice(&1u16.to_le_bytes());
        at += 13;
    }
    if r.len() >= at + 10 + mailbox.len() + 2 && r[at] == 4 {
        r[at + 10..at + 10 + mailbox.len()].copy_from_slice(mailbox);
        let w = at + 10 + mailbox.len();
        r[w..w + 2].copy_from_slice(&1u16.to_le_bytes());
    }
    r
}

fn command(seq: u64, x: f64, y: f64) -> DriveCommandV2 {
    let mut c = DriveCommandV2 {
        seq,
        axes: 2,
        ..DriveCommandV2::default()
    };
    c.controlword[..2].fill(0x000F);
    c.mode[..2].fill(8);
    c.target_position[0] = x;
    c.target_position[1] = y;
    c.torque_offset[0] = 2.5;
    c
}

#[test]
fn the_cycle_converts_both_ways_sends_only_safe_words_by_itself_and_never_allocates() {
    let (cfg, layout) = bus();
    let mut frame = CyclicFrame::new(layout, None).expect("fits a frame");
    let mut drives = Drives::new(&cfg, 2, &[8, 8]);
    let mut events = EventQueue::default();
    let out = |f: &mut CyclicFrame, k: usize| {
        let o = f.outputs_mut(k);
        (
            u16::from_le_bytes([o[0], o[1]]),
            i32::from_le_bytes([o[3], o[4], o[5], o[6]]),
            i16::from_le_bytes([o[17], o[18]]),
        )
    };

    // Before servo's first command: Disable voltage, in the axis' mode.
    drives.write(None, false, &mut frame);
    assert_eq!(out(&mut frame, 2).0, 0);
    // Servo's command, in counts and thousandths, each drive its own axis.
    drives.write(Some(&command(1, 40.0004, -12.3456)), false, &mut frame);
    assert_eq!(out(&mut frame, 2), (0x000F, 40_000, 250), "x at position 2");
    assert_eq!(out(&mut frame, 1).1, -12_346, "y at position 1");
    // A target that is not finite holds the drive where it last was (0 counts so far).
    drives.write(Some(&command(2, f64::NAN, 1.0)), false, &mut frame);
    assert_eq!(out(&mut frame, 2).1, 0);
    // Servo silent: Quick stop, bit 7 never.
    drives.write(Some(&command(2, 40.0, 1.0)), true, &mut frame);
    assert_eq!(out(&mut frame, 2).0, ethercat_bus::QUICK_STOP);
    assert_eq!(out(&mut frame, 1).0 & 0x80, 0);

    // The reply, read back in the axes' units.
    let sent = frame.next_frame().to_vec();
    assert_eq!(
        frame.take_reply(&sent),
        Reply::NotOurs,
        "our own frame, unmarked"
    );
    assert_eq!(
        frame.take_reply(&reply(&sent, 6, 40_123, -5)),
        Reply::Ours { wkc: 6, al_read: 3 }
    );
    assert_eq!(frame.al_status(1), (0x0008, 0));
    let fb = drives.read(7, 1, true, &frame, &mut events);
    assert_eq!((fb.position[0], fb.position[1]), (40.123, -0.005));
    assert_eq!(fb.statusword[0] & 0x6F, 0x27);
    assert!(
        !events.as_slice().is_empty(),
        "the drives' first states are events"
    );
    // A SubDevice that did not take its data: every position NaN, never a last good value.
    let fb = drives.read(8, 2, false, &frame, &mut events);
    assert!(fb.position[..2].iter().all(|p| p.is_nan()));
    // A late reply to an earlier frame is not taken for this one.
    let old = sent.clone();
    let _ = frame.next_frame();
    assert_eq!(frame.take_reply(&reply(&old, 6, 1, 1)), Reply::NotOurs);

    // x's send mailbox full: the next frame reads it (and only it), and its emergency is
    // there; the frame after has no mailbox read.
    let sent = frame.next_frame().to_vec();
    let _ = frame.take_reply(&reply_with(&sent, 6, 1, 1, true, &[0; 128]));
    assert_eq!(frame.full_mailboxes().collect::<Vec<_>>(), [2]);
    assert_eq!(frame.mailbox(), None, "no mailbox read in that frame");
    frame.read_mailbox(2);
    let sent = frame.next_frame().to_vec();
    assert_eq!(
        sent.len(),
        14 + 2 + 10 + 4 * PDO_BYTES + 2 + 3 * 18 + 2 * 13 + 10 + 128 + 2
    );
    let _ = frame.take_reply(&reply_with(&sent, 6, 1, 1, true, &emergency(0x7320)));
    let (k, m) = frame.mailbox().expect("the mailbox read");
    assert_eq!((k, coe_emergency(m)), (2, Some((0x7320, 0x01))));
    assert_eq!(frame.mailbox_read(), Some(2));
    let sent = frame.next_frame().to_vec();
    assert_eq!(
        sent.len(),
        14 + 2 + 10 + 4 * PDO_BYTES + 2 + 3 * 18 + 2 * 13
    );
    assert_eq!(
        sent[14 + 2 + 10 + 4 * PDO_BYTES + 2 + 3 * 18 + 13 + 7] & 0x80,
        0,
        "last"
    );
    assert_eq!(
        coe_emergency(&[0u8; 128]),
        None,
        "an empty mailbox is no emergency"
    );
    let _ = frame.take_reply(&reply(&sent, 6, 1, 1));

    // Asking for OP: the frame ends with a broadcast write of AL control (0x0120) = OP, after
    // a mailbox read when there is one; the reply is still taken, the mailbox still read.
    let fixed = 14 + 2 + 10 + 4 * PDO_BYTES + 2 + 3 * 18 + 2 * 13;
    frame.request_op(true);
    frame.read_mailbox(2);
    let sent = frame.next_frame().to_vec();
    assert_eq!(sent.len(), fixed + 10 + 128 + 2 + 10 + 2 + 2);
    let bwr = fixed + 10 + 128 + 2;
    assert_eq!(
        sent[fixed + 7] & 0x80,
        0x80,
        "the mailbox read is not the last"
    );
    assert_eq!(
        (
            sent[bwr],
            &sent[bwr + 2..bwr + 8],
            &sent[bwr + 10..bwr + 12]
        ),
        (8, &[0, 0, 0x20, 0x01, 2, 0][..], &[8, 0][..]),
        "BWR of AL control, 2 bytes, OP; the last datagram"
    );
    let _ = frame.take_reply(&reply_with(&sent, 6, 1, 1, true, &emergency(0x7320)));
    let (k, m) = frame
        .mailbox()
        .expect("the mailbox read beside the request");
    assert_eq!((k, coe_emergency(m)), (2, Some((0x7320, 0x01))));
    let sent = frame.next_frame().to_vec();
    assert_eq!(sent.len(), fixed + 10 + 2 + 2, "the request alone");
    assert_eq!(sent[fixed], 8);
    assert!(matches!(
        frame.take_reply(&reply(&sent, 6, 1, 1)),
        Reply::Ours { wkc: 6, al_read: 3 }
    ));
    frame.request_op(false);
    let sent = frame.next_frame().to_vec();
    assert_eq!(sent.len(), fixed, "no request once in OP");
    assert_eq!(sent[fixed - 13 + 7] & 0x80, 0, "last");
    let _ = frame.take_reply(&reply(&sent, 6, 1, 1));

    // 10 000 cycles, none allocating.
    let mut cmd = command(10, 40.0, 1.0);
    let mut rx = RxPdo::default();
    let mbx = emergency(0xFF01);
    let (mut mailboxes, mut emergencies) = (0, 0);
    let ((), n) = count(|| {
        for k in 0..10_000u64 {
            cmd.seq = 10 + k;
            cmd.target_position[0] = 40.0 + k as f64 * 1e-3;
            drives.write(Some(&cmd), false, &mut frame);
            let o = frame.outputs_mut(2);
            rx.controlword = u16::from_le_bytes([o[0], o[1]]);
            // Every 100th cycle x's mailbox is full, and read in the next frame.
            let full = frame.full_mailboxes().next();
            if let Some(k) = full {
                frame.read_mailbox(k);
            }
            let sent = frame.next_frame();
            let len = sent.len();
            let mut back = [0u8; 1514];
            back[..len].copy_from_slice(sent);
            back[6] |= 0x02;
            let wkc_at = 26 + 4 * PDO_BYTES;
            back[wkc_at..wkc_at + 2].copy_from_slice(&6u16.to_le_bytes());
            let x_status = wkc_at + 2 + 3 * 18 + 13;
            back[x_status + 10] = if k % 100 == 0 { 0x08 } else { 0 };
            back[x_status + 11..x_status + 13].copy_from_slice(&1u16.to_le_bytes());
            if len > x_status + 13 {
                back[x_status + 13 + 10..x_status + 13 + 10 + 128].copy_from_slice(&mbx);
                back[x_status + 13 + 10 + 128] = 1;
                mailboxes += 1;
            }
            let _ = frame.take_reply(&back[..len]);
            if let Some((_, m)) = frame.mailbox() {
                emergencies += usize::from(coe_emergency(m).is_some());
            }
            events.clear();
            let _ = drives.read(k, k, true, &frame, &mut events);
            let _ = TxPdo::read(frame.inputs(2));
        }
    });
    assert_eq!(n, 0, "allocations in the cycle");
    assert_eq!(
        (mailboxes, emergencies),
        (100, 100),
        "each full mailbox read once"
    );
    assert_eq!(rx.controlword, 0x000F);
}
