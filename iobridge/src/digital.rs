//! The cell's named digital IO as iobridge keeps it (`shm_schema::io`, docs/io.md): inputs as
//! the field reports them, outputs as requested, the outputs' safe values on an e-stop, and the
//! e-stop inputs. No IPC here: iobridge's cycle feeds it the samples it received.

use shm_schema::event::code;
use shm_schema::{
    CellConfigV6, DigitalIoV1, EventQueue, EventV1, IoConfigV1, IoDirection, IoWriteV1, MAX_IO,
    SafeValue, str_of,
};

/// The IO image and what changes it.
#[derive(Clone, Copy, Debug)]
pub struct DigitalIo {
    entries: [IoConfigV1; MAX_IO],
    count: usize,
    inputs: u64,
    outputs: u64,
    estop_inputs: u64,
    values: u64,
    published: u64,
    taken: u64,
    refused: u64,
    outputs_safe: bool,
}

fn bit(k: usize) -> u64 {
    1u64 << k
}

impl DigitalIo {
    /// The IO of `cell`: inputs at their simulated field values until a field device reports
    /// them, outputs off.
    pub fn new(cell: &CellConfigV6) -> Self {
        let mut io = Self {
            entries: cell.io,
            count: cell.io().len(),
            inputs: 0,
            outputs: 0,
            estop_inputs: 0,
            values: 0,
            published: 0,
            taken: 0,
            refused: 0,
            outputs_safe: false,
        };
        for (k, e) in cell.io().iter().enumerate() {
            match IoDirection::from_wire(e.direction) {
                Some(IoDirection::Input) => {
                    io.inputs |= bit(k);
                    if e.estop != 0 {
                        io.estop_inputs |= bit(k);
                    }
                    if e.sim != 0 {
                        io.values |= bit(k);
                    }
                }
                Some(IoDirection::Output) => io.outputs |= bit(k),
                None => {}
            }
        }
        io.published = io.values;
        io
    }

    /// Takes over the IO of a predecessor's image (`<i>/io/state`, a swap or a restart while
    /// the image is still there), so replacing iobridge changes no output and forgets no
    /// input. An image of another IO table is ignored; returns whether it was taken.
    pub fn adopt(&mut self, image: &DigitalIoV1) -> bool {
        if image.count as usize != self.count {
            return false;
        }
        let known = self.inputs | self.outputs;
        self.values = image.values & known;
        self.published = self.values;
        true
    }

    /// The name of entry `k`.
    pub fn name(&self, k: usize) -> &str {
        self.entries.get(k).map_or("?", |e| str_of(&e.name))
    }

    /// The current values (bit `k`: entry `k`).
    pub fn values(&self) -> u64 {
        self.values
    }

    /// Refuses the bits of `w` that are not `want` (inputs for a field write, outputs for a
    /// request); returns the bits that are.
    fn admit(
        &mut self,
        w: &IoWriteV1,
        want: u64,
        what: &str,
        now_ns: u64,
        ev: &mut EventQueue,
    ) -> u64 {
        let wrong = w.mask & !want;
        if wrong != 0 {
            self.refuse(wrong, &[": not ", what], now_ns, ev);
        }
        w.mask & want
    }

    /// Counts a refused write of the bits `bits` and says why, naming the first.
    fn refuse(&mut self, bits: u64, why: &[&str; 2], now_ns: u64, ev: &mut EventQueue) {
        self.refused += 1;
        let k = bits.trailing_zeros() as usize;
        let name = if k < self.count {
            self.name(k)
        } else {
            "a bit beyond the IO table"
        };
        let text = [name, why[0], why[1]];
        ev.push(EventV1::new(now_ns, code::IO_REFUSED, -1, 0.0, 0.0, &text));
    }

    /// Takes a field device's report of some inputs.
    ///
    /// # Real-time
    /// Arithmetic and at most one event.
    pub fn field(&mut self, w: &IoWriteV1, now_ns: u64, ev: &mut EventQueue) {
        let m = self.admit(w, self.inputs, "an input", now_ns, ev);
        self.values = (self.values & !m) | (w.values & m);
    }

    /// Takes an output request, unless the e-stop holds the outputs at their safe values.
    ///
    /// # Real-time
    /// Arithmetic and at most one event.
    pub fn request(&mut self, w: &IoWriteV1, now_ns: u64, ev: &mut EventQueue) {
        let m = self.admit(w, self.outputs, "an output", now_ns, ev);
        if m == 0 {
            return;
        }
        if self.outputs_safe {
            let why = [": the e-stop holds the outputs at their safe values", ""];
            self.refuse(m, &why, now_ns, ev);
            return;
        }
        self.taken += 1;
        self.values = (self.values & !m) | (w.values & m);
    }

    /// iobridge's e-stop reaction: while `react`, the outputs are at their safe values and
    /// requests are refused; when it ends (a reset), the outputs stay as they are.
    ///
    /// # Real-time
    /// Arithmetic only.
    pub fn react(&mut self, react: bool) {
        if react && !self.outputs_safe {
            for k in 0..self.count {
                if self.outputs & bit(k) == 0 {
                    continue;
                }
                match SafeValue::from_wire(self.entries[k].safe) {
                    Some(SafeValue::On) => self.values |= bit(k),
                    Some(SafeValue::Hold) => {}
                    Some(SafeValue::Off) | None => self.values &= !bit(k),
                }
            }
        }
        self.outputs_safe = react;
    }

    /// The first e-stop input that is open (0), if any.
    pub fn open_estop_input(&self) -> Option<usize> {
        let open = self.estop_inputs & !self.values;
        (open != 0).then(|| open.trailing_zeros() as usize)
    }

    /// The image of this cycle, with an event per entry that changed since the last one.
    ///
    /// # Real-time
    /// Arithmetic and events.
    pub fn image(&mut self, seq: u64, now_ns: u64, ev: &mut EventQueue) -> DigitalIoV1 {
        let changed = self.values ^ self.published;
        let mut rest = changed;
        while rest != 0 {
            let k = rest.trailing_zeros() as usize;
            rest &= rest - 1;
            let v = u32::from(self.values & bit(k) != 0);
            ev.push(EventV1::new(
                now_ns,
                code::IO_CHANGED,
                -1,
                f64::from(v),
                0.0,
                &[self.name(k), if v == 1 { " = 1" } else { " = 0" }],
            ));
        }
        self.published = self.values;
        DigitalIoV1 {
            seq,
            stamp_ns: now_ns,
            values: self.values,
            changed,
            taken: self.taken,
            refused: self.refused,
            count: self.count as u32,
            outputs_safe: u32::from(self.outputs_safe),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use shm_schema::fixed_str;

    fn cell() -> CellConfigV6 {
        let mut c = CellConfigV6::default();
        let entry =
            |name: &str, dir: IoDirection, safe: SafeValue, estop: u32, sim: u32| IoConfigV1 {
                name: fixed_str(name),
                direction: dir as u32,
                safe: safe as u32,
                estop,
                sim,
                follows: -1,
                ..Default::default()
            };
        c.io[0] = entry("estop_ok", IoDirection::Input, SafeValue::Off, 1, 1);
        c.io[1] = entry("gripper", IoDirection::Output, SafeValue::Hold, 0, 0);
        c.io[2] = entry("beacon", IoDirection::Output, SafeValue::Off, 0, 0);
        c.io[3] = entry("brake", IoDirection::Output, SafeValue::On, 0, 0);
        c.io_count = 4;
        c
    }

    fn write(mask: u64, values: u64) -> IoWriteV1 {
        IoWriteV1 {
            mask,
            values,
            ..Default::default()
        }
    }

    #[test]
    fn an_estop_sets_each_output_to_its_safe_value_and_refuses_requests_until_reset() {
        let mut io = DigitalIo::new(&cell());
        let mut ev = EventQueue::default();
        assert_eq!(io.values(), 0b0001, "the e-stop circuit starts closed");
        io.request(&write(0b0110, 0b0110), 0, &mut ev);
        assert_eq!(io.values(), 0b0111);
        io.react(true);
        // gripper holds, beacon off, brake on.
        assert_eq!(io.values(), 0b1011);
        io.request(&write(0b0100, 0b0100), 0, &mut ev);
        assert_eq!(io.values(), 0b1011, "refused while safe");
        let img = io.image(1, 0, &mut ev);
        assert_eq!((img.taken, img.refused, img.outputs_safe), (1, 1, 1));
        io.react(false);
        assert_eq!(io.values(), 0b1011, "a reset changes no output");
        io.request(&write(0b0100, 0b0100), 0, &mut ev);
        assert_eq!(io.values(), 0b1111);
    }

    #[test]
    fn a_successor_takes_over_the_outputs_and_inputs_of_its_predecessors_image() {
        let mut old = DigitalIo::new(&cell());
        let mut ev = EventQueue::default();
        old.request(&write(0b0010, 0b0010), 0, &mut ev);
        old.field(&write(0b0001, 0), 0, &mut ev);
        let image = old.image(7, 0, &mut ev);
        let mut new = DigitalIo::new(&cell());
        assert!(new.adopt(&image));
        assert_eq!(new.values(), 0b0010, "gripper closed, e-stop circuit open");
        let mut ev = EventQueue::default();
        assert_eq!(new.image(1, 0, &mut ev).changed, 0);
        assert!(ev.is_empty(), "nothing changed");
        let other = DigitalIoV1 { count: 3, ..image };
        assert!(!DigitalIo::new(&cell()).adopt(&other));
    }

    #[test]
    fn an_open_estop_input_is_found_and_writes_of_the_wrong_direction_are_refused() {
        let mut io = DigitalIo::new(&cell());
        let mut ev = EventQueue::default();
        assert_eq!(io.open_estop_input(), None);
        io.field(&write(0b0001, 0), 0, &mut ev);
        assert_eq!(io.open_estop_input(), Some(0));
        let before = io.values();
        io.field(&write(0b0010, 0b0010), 0, &mut ev);
        io.request(&write(0b0001, 0b0001), 0, &mut ev);
        io.request(&write(1 << 40, 1 << 40), 0, &mut ev);
        assert_eq!(io.values(), before);
        let texts: Vec<&str> = ev.as_slice().iter().map(|e| str_of(&e.text)).collect();
        assert_eq!(
            texts,
            [
                "gripper: not an input",
                "estop_ok: not an output",
                "a bit beyond the IO table: not an output"
            ]
        );
        // One event per change, naming the entry.
        let mut ev = EventQueue::default();
        io.field(&write(0b0001, 1), 0, &mut ev);
        let img = io.image(2, 5, &mut ev);
        assert_eq!(img.changed, 0);
        io.field(&write(0b0001, 0), 0, &mut ev);
        let img = io.image(3, 6, &mut ev);
        assert_eq!(img.changed, 0b0001);
        let e = ev.as_slice().last().expect("event");
        assert_eq!((e.code, e.value), (code::IO_CHANGED, 0.0));
        assert_eq!(str_of(&e.text), "estop_ok = 0");
    }
}
