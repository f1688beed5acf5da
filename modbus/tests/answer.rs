//! The register map and the answers, without a network: every request kind, every exception,
//! and writes that are all or nothing.

use modbus::map::{AXIS, AXIS_BASE, AXIS_WORDS, HEADER, HOLDING, Registers, Samples, input_len};
use modbus::{Action, answer};
use shm_schema::drive::FIELDBUS_IMAGE_LEN;
use shm_schema::{
    CellConfigV6, DigitalIoV1, EstopOrigin, EstopV1, FieldbusImageV1, IoConfigV1, IoDirection,
    ServoStateV3, SetpointV2, fixed_str,
};
use std::borrow::Cow;
use tokio_modbus::{ExceptionCode as E, Request as Q, Response as R};

/// Two axes; IO: an input, two outputs.
fn cell() -> CellConfigV6 {
    let mut c = CellConfigV6 {
        axes: 2,
        io_count: 3,
        ..Default::default()
    };
    for (k, (name, dir)) in [
        ("door", IoDirection::Input),
        ("gripper", IoDirection::Output),
        ("lamp", IoDirection::Output),
    ]
    .into_iter()
    .enumerate()
    {
        c.io[k] = IoConfigV1 {
            name: fixed_str(name),
            direction: dir as u32,
            ..Default::default()
        };
    }
    c
}

fn samples() -> Samples {
    let mut image = [0u8; FIELDBUS_IMAGE_LEN];
    image[..8].copy_from_slice(&1_234_567u64.to_le_bytes());
    image[8..12].copy_from_slice(&(-40_001i32).to_le_bytes());
    image[12..16].copy_from_slice(&(150_000i32).to_le_bytes());
    let mut servo = ServoStateV3 {
        seq: 77,
        power: 2,
        status: 1 | 128,
        axes: 2,
        ..Default::default()
    };
    servo.cmd_position[..2].copy_from_slice(&[-40.0, 150.0005]);
    servo.following_error[..2].copy_from_slice(&[0.001, -0.0004]);
    servo.act_velocity[..2].copy_from_slice(&[-12.5, 0.0]);
    Samples {
        image: Some(FieldbusImageV1 {
            seq: 0x0001_0002_0003_0004,
            written_ns: 1_235_000_000,
            measured_ns: 1_234_567_000,
            source_seq: 77,
            len: 16,
            axes: 2,
            image,
        }),
        servo: Some(servo),
        setpoint: Some(SetpointV2 {
            state: 1,
            program_id: 3,
            line: 70_000,
            speed_override: 0.4,
            hold: 1,
            ..Default::default()
        }),
        estop: None,
        io: Some(DigitalIoV1 {
            values: 0b011,
            count: 3,
            ..Default::default()
        }),
    }
}

fn regs() -> Registers {
    Registers::build(&cell(), &samples())
}

fn u(r: &[u16], at: usize, words: usize) -> u64 {
    r[at..at + words]
        .iter()
        .fold(0, |v, w| v << 16 | u64::from(*w))
}

#[test]
fn the_map_has_no_overlap_and_fits_its_blocks() {
    for (block, end) in [(HEADER, AXIS_BASE), (AXIS, AXIS_WORDS), (HOLDING, 2)] {
        let mut used = vec![false; end as usize];
        for f in block {
            for a in f.addr..f.addr + f.kind.words() {
                assert!(a < end, "{} past its block", f.name);
                assert!(!used[a as usize], "{} overlaps", f.name);
                used[a as usize] = true;
            }
        }
    }
    assert_eq!(input_len(3), 56);
}

#[test]
fn the_registers_carry_the_image_the_servo_cycle_and_the_program() {
    let r = regs();
    let i = &r.input;
    assert_eq!(i.len(), 48);
    assert_eq!(u(i, 0, 4), 0x0001_0002_0003_0004, "high word first");
    assert_eq!(u(i, 4, 4), 1_234_567, "measured µs");
    assert_eq!(u(i, 8, 4), 1_235_000, "written µs");
    assert_eq!(
        (i[12], i[13], i[14], i[15], i[16], i[17]),
        (2, 0, 0, 2, 129, 1)
    );
    assert_eq!((u(i, 18, 2), u(i, 20, 2)), (3, 70_000));
    assert_eq!(
        (i[22], i[23], u(i, 24, 4), i[28], i[29]),
        (40, 1, 0b011, 3, 0)
    );
    let axis = |k: usize, off: usize| u(i, 32 + 8 * k + off, 2) as u32 as i32;
    assert_eq!(
        [axis(0, 0), axis(0, 2), axis(0, 4), axis(0, 6)],
        [-40_001, -40_000, 1, -12_500]
    );
    assert_eq!([axis(1, 0), axis(1, 2), axis(1, 4)], [150_000, 150_001, 0]);
    assert_eq!(r.outputs, 0b110);
}

#[test]
fn reads_answer_within_their_tables_and_refuse_past_them() {
    let r = regs();
    let ok = |q: Q<'_>| answer(&q, &r, true).map(|(resp, a)| (resp, a.len()));
    assert_eq!(
        ok(Q::ReadInputRegisters(46, 2)),
        Ok((R::ReadInputRegisters(r.input[46..48].to_vec()), 0))
    );
    assert_eq!(ok(Q::ReadInputRegisters(47, 2)), Err(E::IllegalDataAddress));
    assert_eq!(ok(Q::ReadInputRegisters(0, 0)), Err(E::IllegalDataValue));
    assert_eq!(ok(Q::ReadInputRegisters(0, 126)), Err(E::IllegalDataValue));
    assert_eq!(
        ok(Q::ReadDiscreteInputs(0, 3)),
        Ok((R::ReadDiscreteInputs(vec![true, true, false]), 0))
    );
    assert_eq!(ok(Q::ReadCoils(2, 2)), Err(E::IllegalDataAddress));
    assert_eq!(
        ok(Q::ReadHoldingRegisters(0, 2)),
        Ok((R::ReadHoldingRegisters(vec![0, 40]), 0))
    );
    assert_eq!(
        ok(Q::ReadHoldingRegisters(1, 2)),
        Err(E::IllegalDataAddress)
    );
    assert_eq!(ok(Q::ReportServerId), Err(E::IllegalFunction));
    // Before the first image: busy, for everything.
    let none = Registers::default();
    assert_eq!(
        answer(&Q::ReadHoldingRegisters(0, 1), &none, true).map(|_| ()),
        Err(E::ServerDeviceBusy)
    );
}

#[test]
fn coil_writes_request_outputs_only_and_never_while_they_are_held_safe() {
    let r = regs();
    assert_eq!(
        answer(&Q::WriteSingleCoil(2, true), &r, true),
        Ok((
            R::WriteSingleCoil(2, true),
            vec![Action::Io {
                mask: 0b100,
                values: 0b100
            }]
        ))
    );
    let both = Q::WriteMultipleCoils(1, Cow::Owned(vec![false, true]));
    assert_eq!(
        answer(&both, &r, true).map(|(_, a)| a),
        Ok(vec![Action::Io {
            mask: 0b110,
            values: 0b100
        }])
    );
    // One input among them: nothing is taken.
    let with_input = Q::WriteMultipleCoils(0, Cow::Owned(vec![true, true]));
    assert_eq!(answer(&with_input, &r, true), Err(E::IllegalDataAddress));
    assert_eq!(
        answer(&Q::WriteSingleCoil(3, true), &r, true),
        Err(E::IllegalDataAddress)
    );
    let safe = Registers {
        outputs_safe: true,
        ..regs()
    };
    assert_eq!(
        answer(&Q::WriteSingleCoil(1, true), &safe, true),
        Err(E::ServerDeviceBusy)
    );
    assert_eq!(
        answer(&Q::WriteSingleCoil(1, true), &r, false),
        Err(E::IllegalFunction)
    );
}

#[test]
fn register_writes_are_the_estop_and_the_override_checked_whole() {
    let r = regs();
    let w = |a: u16, v: &[u16]| {
        answer(
            &Q::WriteMultipleRegisters(a, Cow::Owned(v.to_vec())),
            &r,
            true,
        )
        .map(|(_, a)| a)
    };
    assert_eq!(w(0, &[1, 55]), Ok(vec![Action::Estop, Action::Speed(55)]));
    assert_eq!(w(0, &[0]), Ok(vec![]), "0 is no reset");
    assert_eq!(w(0, &[1, 0]), Err(E::IllegalDataValue), "no e-stop either");
    assert_eq!(w(1, &[101]), Err(E::IllegalDataValue));
    assert_eq!(w(0, &[1, 50, 1]), Err(E::IllegalDataAddress));
    assert_eq!(
        answer(&Q::WriteSingleRegister(1, 100), &r, true).map(|(_, a)| a),
        Ok(vec![Action::Speed(100)])
    );
    assert_eq!(
        answer(&Q::WriteSingleRegister(0, 1), &r, false),
        Err(E::IllegalFunction)
    );
}

#[test]
fn a_latched_estop_reads_with_its_origin() {
    let mut s = samples();
    s.estop = Some(EstopV1 {
        origin: EstopOrigin::External as u32,
        ..Default::default()
    });
    let r = Registers::build(&cell(), &s);
    assert_eq!((r.input[13], r.input[14]), (1, 2));
    assert_eq!(
        answer(&Q::ReadHoldingRegisters(0, 1), &r, true).map(|(x, _)| x),
        Ok(R::ReadHoldingRegisters(vec![1]))
    );
}
