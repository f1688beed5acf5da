//! The cell's Modbus TCP server: a non-real-time process of its own that serves, to a PLC or an
//! HMI, what iobridge writes every cycle (the positions with the time they were measured, as
//! seed 000's synchronous task does), the cell's state and its named digital IO, and takes the
//! few writes that make sense from a fieldbus: the outputs, an e-stop request, the speed
//! override.
//!
//! - [`map`]: the register map, as data, and one consistent snapshot of it ([`map::Registers`]);
//! - [`answer`]: one request against a snapshot: the response or the exception, and what a
//!   write asks of the cell ([`Action`]);
//! - [`server`]: the TCP side (tokio-modbus): bounded connections, idle timeout, listening
//!   again when the address is taken;
//! - `main.rs`: the process: its cycle (after iobridge's, in the same period) builds the
//!   snapshot from the cell's services and applies the actions.
//!
//! Nothing here can disturb the real-time processes: the process runs under `SCHED_OTHER`,
//! talks to them only through the services any process uses, and is not critical: its loss
//! or lateness is a warning and a restart, never an e-stop.

pub mod map;
pub mod server;

use map::{HOLD_ESTOP, HOLD_SPEED, Registers};
use tokio_modbus::{ExceptionCode, Request, Response};

/// What a write asks of the cell; the process' cycle applies it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Action {
    /// Request the outputs in `mask` to the values in `values` (bit k = entry k).
    Io {
        /// Entries written.
        mask: u64,
        /// Their values.
        values: u64,
    },
    /// Raise the e-stop.
    Estop,
    /// Set the speed override (%), 1..=100.
    Speed(u16),
}

/// Largest quantities per request, as the Modbus specification bounds them.
const MAX_READ_BITS: u16 = 2000;
const MAX_READ_WORDS: u16 = 125;
const MAX_WRITE_BITS: usize = 1968;
const MAX_WRITE_WORDS: usize = 123;

/// `[start, start + n)` within `len`, with `n` in `1..=max`: the exception otherwise
/// (a quantity out of bounds is "illegal data value", an address "illegal data address").
fn range(
    start: u16,
    n: usize,
    max: usize,
    len: usize,
) -> Result<std::ops::Range<usize>, ExceptionCode> {
    if n == 0 || n > max {
        return Err(ExceptionCode::IllegalDataValue);
    }
    let start = start as usize;
    if start + n > len {
        return Err(ExceptionCode::IllegalDataAddress);
    }
    Ok(start..start + n)
}

/// The answer to `req` from `regs`: the response and what it asks of the cell, or the
/// exception (which changes nothing). `writes`: `[modbus] writes`.
pub fn answer(
    req: &Request<'_>,
    regs: &Registers,
    writes: bool,
) -> Result<(Response, Vec<Action>), ExceptionCode> {
    use Request as Q;
    if !regs.valid {
        // The cell is starting: no image yet.
        return Err(ExceptionCode::ServerDeviceBusy);
    }
    let bits = |r: std::ops::Range<usize>| r.map(|k| regs.io >> k & 1 == 1).collect::<Vec<_>>();
    let holding = [u16::from(regs.estop), regs.speed_percent];
    let is_write = matches!(
        req,
        Q::WriteSingleCoil(..)
            | Q::WriteMultipleCoils(..)
            | Q::WriteSingleRegister(..)
            | Q::WriteMultipleRegisters(..)
    );
    if is_write && !writes {
        return Err(ExceptionCode::IllegalFunction);
    }
    let io_len = regs.io_count as usize;
    match req {
        Q::ReadInputRegisters(a, n) => {
            let r = range(*a, *n as usize, MAX_READ_WORDS as usize, regs.input.len())?;
            Ok((Response::ReadInputRegisters(regs.input[r].to_vec()), vec![]))
        }
        Q::ReadDiscreteInputs(a, n) => {
            let r = range(*a, *n as usize, MAX_READ_BITS as usize, io_len)?;
            Ok((Response::ReadDiscreteInputs(bits(r)), vec![]))
        }
        Q::ReadCoils(a, n) => {
            let r = range(*a, *n as usize, MAX_READ_BITS as usize, io_len)?;
            Ok((Response::ReadCoils(bits(r)), vec![]))
        }
        Q::ReadHoldingRegisters(a, n) => {
            let r = range(*a, *n as usize, MAX_READ_WORDS as usize, holding.len())?;
            Ok((Response::ReadHoldingRegisters(holding[r].to_vec()), vec![]))
        }
        Q::WriteSingleCoil(a, v) => {
            let action = coils(regs, *a, &[*v])?;
            Ok((Response::WriteSingleCoil(*a, *v), vec![action]))
        }
        Q::WriteMultipleCoils(a, vs) => {
            let action = coils(regs, *a, vs)?;
            Ok((
                Response::WriteMultipleCoils(*a, vs.len() as u16),
                vec![action],
            ))
        }
        Q::WriteSingleRegister(a, v) => {
            let actions = registers(*a, &[*v])?;
            Ok((Response::WriteSingleRegister(*a, *v), actions))
        }
        Q::WriteMultipleRegisters(a, vs) => {
            let actions = registers(*a, vs)?;
            Ok((
                Response::WriteMultipleRegisters(*a, vs.len() as u16),
                actions,
            ))
        }
        _ => Err(ExceptionCode::IllegalFunction),
    }
}

/// A write of coils `a..a + vs.len()`: outputs only, none while iobridge holds them safe.
fn coils(regs: &Registers, a: u16, vs: &[bool]) -> Result<Action, ExceptionCode> {
    let r = range(a, vs.len(), MAX_WRITE_BITS, regs.io_count as usize)?;
    let mask = r.clone().fold(0u64, |m, k| m | 1 << k);
    if mask & !regs.outputs != 0 {
        return Err(ExceptionCode::IllegalDataAddress); // an input: the field sets it
    }
    if regs.outputs_safe {
        return Err(ExceptionCode::ServerDeviceBusy); // e-stop: outputs held safe
    }
    let values = r.zip(vs).fold(0u64, |m, (k, v)| m | u64::from(*v) << k);
    Ok(Action::Io { mask, values })
}

/// A write of holding registers `a..a + vs.len()`: every value checked before any is taken.
fn registers(a: u16, vs: &[u16]) -> Result<Vec<Action>, ExceptionCode> {
    let r = range(a, vs.len(), MAX_WRITE_WORDS, map::HOLDING.len())?;
    let mut actions = Vec::new();
    for (addr, v) in r.zip(vs) {
        match (addr as u16, *v) {
            (HOLD_ESTOP, 1) => actions.push(Action::Estop),
            (HOLD_ESTOP, 0) => {}
            (HOLD_SPEED, 1..=100) => actions.push(Action::Speed(*v)),
            _ => return Err(ExceptionCode::IllegalDataValue),
        }
    }
    Ok(actions)
}
