//! The simulated field's digital devices: an input that `follows` an output (`[[io]]`,
//! docs/io.md) is a two-position device with a position sensor, such as the Gantry UBA's
//! solenoid gripper: `switch_time` after its output changes, its sensor reports the new
//! position. The machine reads the outputs from iobridge's IO image and reports the sensors as
//! a field device does, on `<i>/field/inputs`.

use shm_schema::{CellConfigV6, IoDirection, IoWriteV1, MAX_IO};

/// Sensors report again at least this often (ns), so a restarted iobridge learns them.
pub const REFRESH_NS: u64 = 100_000_000;

/// The devices of a cell and where each one is.
#[derive(Clone, Copy, Debug)]
pub struct Field {
    /// Per input that follows an output: (input, output, switching time ns).
    devices: [(u8, u8, u64); MAX_IO],
    count: usize,
    /// Bits of the inputs this field drives.
    mask: u64,
    /// The sensors' values.
    values: u64,
    /// Per device: the output value it is moving to and when it gets there.
    moving: [Option<(bool, u64)>; MAX_IO],
    last_sent_ns: Option<u64>,
    source: u32,
}

impl Field {
    /// The devices of `cell`; every sensor starts at its input's `sim` value. `source` is the
    /// machine's index in the process table (who reports the sensors).
    pub fn new(cell: &CellConfigV6, source: u32) -> Self {
        let mut f = Self {
            devices: [(0, 0, 0); MAX_IO],
            count: 0,
            mask: 0,
            values: 0,
            moving: [None; MAX_IO],
            last_sent_ns: None,
            source,
        };
        for (k, e) in cell.io().iter().enumerate() {
            let input = IoDirection::from_wire(e.direction) == Some(IoDirection::Input);
            if let (true, Ok(out)) = (input, usize::try_from(e.follows))
                && out < MAX_IO
            {
                f.devices[f.count] = (k as u8, out as u8, e.switch_time_ns);
                f.count += 1;
                f.mask |= 1 << k;
                if e.sim != 0 {
                    f.values |= 1 << k;
                }
            }
        }
        f
    }

    /// True when the cell has such devices.
    pub fn is_empty(&self) -> bool {
        self.count == 0
    }

    /// Moves the devices on to `now_ns` with the outputs `outputs` (bit `k`: entry `k`, as
    /// iobridge wrote them; `None` before its first image); returns the sensors' report when
    /// one changed or the last report is [`REFRESH_NS`] old.
    ///
    /// # Real-time
    /// Arithmetic only.
    pub fn step(&mut self, now_ns: u64, outputs: Option<u64>) -> Option<IoWriteV1> {
        let before = self.values;
        for d in 0..self.count {
            let (input, output, switch_ns) = self.devices[d];
            let at = self.values & (1 << input) != 0;
            if let Some(out) = outputs {
                let want = out & (1 << output) != 0;
                match self.moving[d] {
                    Some((to, _)) if to == want => {}
                    _ if want == at => self.moving[d] = None,
                    _ => self.moving[d] = Some((want, now_ns + switch_ns)),
                }
            }
            if let Some((to, when)) = self.moving[d]
                && now_ns >= when
            {
                if to {
                    self.values |= 1 << input;
                } else {
                    self.values &= !(1 << input);
                }
                self.moving[d] = None;
            }
        }
        let due = self
            .last_sent_ns
            .is_none_or(|t| now_ns.saturating_sub(t) >= REFRESH_NS);
        if self.is_empty() || (self.values == before && !due) {
            return None;
        }
        self.last_sent_ns = Some(now_ns);
        Some(IoWriteV1 {
            stamp_ns: now_ns,
            mask: self.mask,
            values: self.values,
            source: self.source,
            line: 0,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use shm_schema::{IoConfigV1, fixed_str};

    #[test]
    fn a_sensor_follows_its_output_after_the_switching_time() {
        let mut c = CellConfigV6::default();
        c.io[0] = IoConfigV1 {
            name: fixed_str("gripper"),
            direction: IoDirection::Output as u32,
            follows: -1,
            ..Default::default()
        };
        c.io[1] = IoConfigV1 {
            name: fixed_str("gripper_closed"),
            direction: IoDirection::Input as u32,
            follows: 0,
            switch_time_ns: 80_000_000,
            ..Default::default()
        };
        c.io_count = 2;
        let mut f = Field::new(&c, 0);
        let ms = 1_000_000;
        assert_eq!(f.step(0, None).map(|w| (w.mask, w.values)), Some((0b10, 0)));
        assert_eq!(f.step(ms, Some(0)), None);
        // Closed at 10 ms: the sensor reports it at 90 ms, not before.
        assert_eq!(f.step(10 * ms, Some(0b01)), None);
        assert_eq!(f.step(89 * ms, Some(0b01)), None);
        assert_eq!(f.step(90 * ms, Some(0b01)).map(|w| w.values), Some(0b10));
        // Opened and closed again before it got there: it never left.
        assert_eq!(f.step(100 * ms, Some(0)), None);
        assert_eq!(f.step(150 * ms, Some(0b01)), None);
        assert_eq!(f.step(185 * ms, Some(0b01)), None);
        // And it reports again every REFRESH_NS.
        assert_eq!(f.step(190 * ms, Some(0b01)).map(|w| w.values), Some(0b10));
    }
}
