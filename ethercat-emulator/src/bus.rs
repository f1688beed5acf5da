//! A line of SubDevices as the frame meets them: each datagram passes every SubDevice in
//! order; each reads, writes or ignores it by its addressing (position, station address,
//! broadcast, logical through its FMMUs) and counts its part in the working counter.

use crate::esc::Esc;
use crate::frame::{Command, Datagram, FrameError, walk};
use crate::terminals::Terminal;

/// One SubDevice: its ESC and what sits behind it.
#[derive(Debug)]
pub struct SubDevice {
    /// The controller.
    pub esc: Esc,
    /// The device behind it.
    pub terminal: Terminal,
    /// Mailboxes the device has written and the MainDevice not yet read (an emergency, an
    /// answer behind it), oldest first: each goes into the send mailbox (SM1) once it is empty.
    outbox: std::collections::VecDeque<Vec<u8>>,
}

impl SubDevice {
    /// A terminal with its ESC.
    pub fn new(terminal: Terminal) -> Self {
        Self {
            esc: terminal.esc(),
            terminal,
            outbox: std::collections::VecDeque::new(),
        }
    }

    /// Its part of one datagram, then the device's answer to a mailbox it completed (behind
    /// what the device had to say first: an emergency), then the next mailbox out if SM1 is
    /// free.
    fn datagram(&mut self, d: &mut Datagram<'_>) {
        self.access(d);
        if let Some(request) = self.esc.take_mailbox() {
            let capacity = self.esc.mailbox_capacity();
            let al = self.esc.al_state();
            let answer = self.terminal.mailbox(&request, capacity, al);
            self.outbox.extend(answer);
            self.esc.set_needs_sync0(self.terminal.on_sync0());
        }
        self.post();
    }

    /// The device's emergencies into the outbox, and the oldest mailbox out into SM1 if it is
    /// free. (A real drive's mailbox holds a few; this one holds 16, the oldest dropped.)
    fn post(&mut self) {
        self.outbox.extend(self.terminal.emergencies());
        while self.outbox.len() > 16 {
            self.outbox.pop_front();
        }
        if let Some(m) = self.outbox.front()
            && self.esc.put_mailbox(m)
        {
            self.outbox.pop_front();
        }
    }

    fn access(&mut self, d: &mut Datagram<'_>) {
        let esc = &mut self.esc;
        match d.command {
            Command::Nop => {}
            Command::Aprd | Command::Apwr | Command::Aprw => {
                if d.adp == 0 {
                    d.wkc = d
                        .wkc
                        .wrapping_add(access(esc, d.command, d.ado, d.data, false));
                }
                d.adp = d.adp.wrapping_add(1);
            }
            Command::Fprd | Command::Fpwr | Command::Fprw => {
                if d.adp == esc.station_address() {
                    d.wkc = d
                        .wkc
                        .wrapping_add(access(esc, d.command, d.ado, d.data, false));
                }
            }
            Command::Brd | Command::Bwr | Command::Brw => {
                d.wkc = d
                    .wkc
                    .wrapping_add(access(esc, d.command, d.ado, d.data, true));
                d.adp = d.adp.wrapping_add(1);
            }
            Command::Lrd | Command::Lwr | Command::Lrw => {
                let logical = d.logical();
                let read = d.command != Command::Lwr;
                let write = d.command != Command::Lrd;
                d.wkc = d
                    .wkc
                    .wrapping_add(esc.logical(logical, d.data, read, write));
            }
            Command::Armw | Command::Frmw => {
                let addressed = if d.command == Command::Armw {
                    d.adp == 0
                } else {
                    d.adp == esc.station_address()
                };
                let done = if addressed {
                    esc.read(d.ado, d.data, false)
                } else {
                    esc.write(d.ado, d.data)
                };
                d.wkc = d.wkc.wrapping_add(u16::from(done));
                if d.command == Command::Armw {
                    d.adp = d.adp.wrapping_add(1);
                }
            }
        }
    }
}

/// A register access of an addressed SubDevice; its working-counter increment (read +1,
/// write +1, read-write +1 and +2).
fn access(esc: &mut Esc, command: Command, ado: u16, data: &mut [u8], broadcast: bool) -> u16 {
    match command {
        Command::Aprd | Command::Fprd | Command::Brd => u16::from(esc.read(ado, data, broadcast)),
        Command::Apwr | Command::Fpwr | Command::Bwr => u16::from(esc.write(ado, data)),
        _ => {
            // Read-write: the old content goes back in the frame, the frame's is written.
            let written = data.to_vec();
            let read = esc.read(ado, data, broadcast);
            let wrote = esc.write(ado, &written);
            u16::from(read) + 2 * u16::from(wrote)
        }
    }
}

/// The SubDevices of one line, in wire order.
#[derive(Debug, Default)]
pub struct Bus {
    /// In the order a frame meets them (position 0 first).
    pub devices: Vec<SubDevice>,
}

impl Bus {
    /// A line of `terminals` in that order.
    pub fn new(terminals: impl IntoIterator<Item = Terminal>) -> Self {
        let mut bus = Self {
            devices: terminals.into_iter().map(SubDevice::new).collect(),
        };
        let n = bus.devices.len();
        for (k, d) in bus.devices.iter_mut().enumerate() {
            d.esc.set_links(true, k + 1 < n);
        }
        bus
    }

    /// Cable redundancy: the last SubDevice's port 1 is cabled (back to the MainDevice's
    /// second port), so it has a link and its loop is open, as on the others (DL status).
    pub fn close_ring(&mut self) {
        if let Some(last) = self.devices.last_mut() {
            last.esc.set_links(true, true);
        }
    }

    /// One frame through the line, changed in place into the reply: the devices first put
    /// their inputs in their ESCs, then every datagram passes every SubDevice, then the
    /// devices take their outputs. A frame that does not add up is refused (and dropped: the
    /// MainDevice sees a lost frame).
    pub fn handle(&mut self, frame: &mut [u8]) -> Result<usize, FrameError> {
        self.handle_at(frame, crate::now_ns())
    }

    /// [`Bus::handle`] at host time `now` (ns, `CLOCK_MONOTONIC`): what the ESCs' clocks,
    /// watchdogs and the devices' models take as the frame's time.
    pub fn handle_at(&mut self, frame: &mut [u8], now: u64) -> Result<usize, FrameError> {
        for d in &mut self.devices {
            d.esc.set_time(now);
            d.esc.check_watchdog(now);
            d.terminal.inputs(&mut d.esc, now);
        }
        let devices = &mut self.devices;
        let n = walk(frame, |dg| {
            for d in devices.iter_mut() {
                d.datagram(dg);
            }
        })?;
        for d in &mut self.devices {
            d.terminal.outputs(&mut d.esc, now);
            d.post();
        }
        Ok(n)
    }

    /// Between frames (the emulator's idle ticks): the SyncManager watchdogs count, the
    /// drives' models run on.
    pub fn idle(&mut self) {
        self.idle_at(crate::now_ns());
    }

    /// [`Bus::idle`] at host time `now`.
    pub fn idle_at(&mut self, now: u64) {
        for d in &mut self.devices {
            d.esc.set_time(now);
            d.esc.check_watchdog(now);
            d.terminal.idle(&d.esc, now);
            d.post();
        }
    }
}
