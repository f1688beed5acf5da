//! The cycle's one frame: an LRW datagram over the whole process image (every SubDevice's
//! outputs written, its inputs read, through the FMMUs ethercrab configured), followed by an
//! FPRD of each SubDevice's AL status and status code, so that every cycle knows which
//! SubDevice is in which state, and an FPRD of the status of each send mailbox (SM1), so that
//! a CoE emergency waiting there is seen; the frame after one is seen carries a read of that
//! mailbox (one per frame). While the bus is being taken from SAFE-OP to OP, the frame ends
//! with a broadcast write of AL control asking every SubDevice for OP
//! ([`CyclicFrame::request_op`]): OP is reached with the cycle's own process data running, so
//! a SubDevice's process data watchdog never finds the bus silent in OP. With Distributed Clocks, two datagrams follow the LRW: an FPWR of
//! the reference clock's system time (0x0910) with the MainDevice's time, which keeps the
//! reference on the host's clock (its drift control follows what is written), and an FRMW of
//! it, which hands the reference's time to every other DC SubDevice and brings it back.
//! Built once at start-up; a cycle writes the outputs in place, sends, and takes the reply:
//! no allocation, bounded time.
//!
//! Layout (ETG.1000.4): Ethernet header (broadcast destination, EtherType 0x88A4), EtherCAT
//! header (length of the datagrams, type 1), then datagrams of a 10-byte header (command,
//! index, address, length with the "more follows" bit, IRQ), data and a 2-byte working
//! counter. The frame is padded to Ethernet's 60 bytes.

use shm_schema::ethercat::MAX_SUBDEVICES;

/// Logical read-write.
const LRW: u8 = 12;
/// Configured-address physical write.
const FPWR: u8 = 5;
/// Configured-address read, multiple write.
const FRMW: u8 = 14;
/// DC system time.
const DC_SYSTEM_TIME: u16 = 0x0910;
/// Bytes of the DC datagrams (FPWR and FRMW of the 64-bit system time).
const DC_BYTES: usize = 2 * (DGRAM + 8 + WKC);
/// Configured-address physical read.
pub const FPRD: u8 = 4;
/// Broadcast write.
const BWR: u8 = 8;
/// The AL control register: the state a SubDevice is asked for.
const AL_CONTROL: u16 = 0x0120;
/// AL control's request for OP.
const AL_OP: u16 = 0x0008;
/// SM1's status register (bit 3: the mailbox is full).
const SM1_STATUS: u16 = 0x080D;
/// Bytes of a mailbox read at most (a drive's SM1 is 128 bytes or less; the frame keeps room
/// for the largest).
pub const MAX_MAILBOX: usize = 512;
/// The AL status register (0x0130), its status code at 0x0134.
const AL_STATUS: u16 = 0x0130;
/// Bytes read from [`AL_STATUS`]: status, reserved, status code.
const AL_BYTES: usize = 6;
const ETH: usize = 14;
const ECAT: usize = 2;
const DGRAM: usize = 10;
const WKC: usize = 2;
/// The largest Ethernet frame without its FCS.
pub const MAX_FRAME: usize = 1514;
/// The source address of our frames (locally administered; the first SubDevice sets bit 1 of
/// the first byte in its reply, so a reply is never taken for a frame we sent).
const SOURCE: [u8; 6] = [0x10, 0x10, 0x10, 0x10, 0x10, 0x10];

/// Where one SubDevice's process data sits in the image, and its station address.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Slot {
    /// Configured station address.
    pub station: u16,
    /// Offset and length of its outputs in the image.
    pub outputs: (u16, u16),
    /// Offset and length of its inputs in the image.
    pub inputs: (u16, u16),
    /// Physical address and length of its send mailbox (SM1); length 0: none.
    pub mailbox_in: (u16, u16),
}

/// The CoE emergency a mailbox carries (ETG.1000.6 5.6.4): its error code and error register,
/// or `None` for anything else.
///
/// # Real-time
/// Reads only.
pub fn coe_emergency(mailbox: &[u8]) -> Option<(u16, u8)> {
    // Mailbox header: length, address, channel and priority, type (low 4 bits; 3: CoE) and
    // counter; then the CoE header, its service in the top 4 bits (1: emergency).
    let len = usize::from(u16::from_le_bytes([*mailbox.first()?, *mailbox.get(1)?]));
    if mailbox.len() < 11 || len < 5 || mailbox[5] & 0x0F != 3 {
        return None;
    }
    if u16::from_le_bytes([mailbox[6], mailbox[7]]) >> 12 != 1 {
        return None;
    }
    Some((u16::from_le_bytes([mailbox[8], mailbox[9]]), mailbox[10]))
}

/// The process image of the bus: its logical address range and each SubDevice's place.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Layout {
    /// Logical address of the image's first byte.
    pub logical_start: u32,
    /// Bytes of the image.
    pub len: u16,
    /// SubDevices in wire order; the first `count` used.
    pub slots: [Slot; MAX_SUBDEVICES],
    /// SubDevices on the bus.
    pub count: usize,
    /// The LRW's working counter when every SubDevice takes its data: +1 for each that has
    /// inputs, +2 for each that has outputs.
    pub expected_wkc: u16,
}

/// What came back.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Reply {
    /// Not the reply to the frame sent last (another frame, a late one): ignored.
    NotOurs,
    /// The reply: the LRW's working counter, and how many SubDevices answered the AL status
    /// read.
    Ours {
        /// The LRW's working counter.
        wkc: u16,
        /// SubDevices whose AL status was read (their FPRD's working counter was 1).
        al_read: usize,
    },
}

/// The cycle's frame, built once.
#[derive(Clone, Debug)]
pub struct CyclicFrame {
    layout: Layout,
    buf: [u8; MAX_FRAME],
    len: usize,
    /// Inputs and the AL statuses as the last reply had them.
    reply: [u8; MAX_FRAME],
    index: u8,
    /// Bytes of the datagrams without a mailbox read (the EtherCAT header's length).
    datagrams: usize,
    /// The SubDevices with a send mailbox, in the order of their status reads.
    mailboxes: [u8; MAX_SUBDEVICES],
    /// How many.
    mailbox_count: usize,
    /// The SubDevice whose mailbox the next frame reads.
    read_next: Option<usize>,
    /// The SubDevice whose mailbox the frame sent last reads.
    read_sent: Option<usize>,
    /// Bytes of the DC datagrams ([`DC_BYTES`] with a reference clock, else 0).
    dc_len: usize,
    /// Whether each frame asks every SubDevice for OP ([`CyclicFrame::request_op`]).
    op_request: bool,
    /// Bytes of the datagrams the frame sent last carries after the fixed ones (a mailbox
    /// read, the request for OP).
    tail_sent: usize,
}

impl CyclicFrame {
    /// The frame for `layout` (with the DC datagrams when the bus has a reference clock, at
    /// station address `reference`), or why it does not fit in one Ethernet frame.
    pub fn new(layout: Layout, reference: Option<u16>) -> Result<Self, String> {
        let n = layout.count.min(MAX_SUBDEVICES);
        let mut mailboxes = [0u8; MAX_SUBDEVICES];
        let mut mailbox_count = 0;
        let mut largest = 0;
        for (k, s) in layout.slots[..n].iter().enumerate() {
            if s.mailbox_in.1 > 0 {
                mailboxes[mailbox_count] = k as u8;
                mailbox_count += 1;
                largest = largest.max(usize::from(s.mailbox_in.1));
            }
        }
        if largest > MAX_MAILBOX {
            return Err(format!(
                "a send mailbox of {largest} bytes is more than the cycle reads ({MAX_MAILBOX})"
            ));
        }
        let dc_len = if reference.is_some() { DC_BYTES } else { 0 };
        let datagrams = DGRAM
            + usize::from(layout.len)
            + WKC
            + dc_len
            + n * (DGRAM + AL_BYTES + WKC)
            + mailbox_count * (DGRAM + 1 + WKC);
        let len = ETH + ECAT + datagrams;
        let longest = len
            + if largest > 0 {
                DGRAM + largest + WKC
            } else {
                0
            };
        if longest > MAX_FRAME || usize::from(layout.len) > 0x7FF {
            return Err(format!(
                "the process image ({} bytes), {n} AL status reads and {mailbox_count} mailboxes do not fit one frame ({longest} of {MAX_FRAME} bytes)",
                layout.len
            ));
        }
        let mut buf = [0u8; MAX_FRAME];
        buf[0..6].copy_from_slice(&[0xFF; 6]);
        buf[6..12].copy_from_slice(&SOURCE);
        buf[12..14].copy_from_slice(&ethercat_wire::ETHERTYPE.to_be_bytes());
        buf[14..16].copy_from_slice(&((datagrams as u16) | (1 << 12)).to_le_bytes());
        let mut at = ETH + ECAT;
        let reads = n + mailbox_count;
        let mut datagram =
            |buf: &mut [u8; MAX_FRAME], cmd: u8, address: u32, len: usize, more: bool| {
                buf[at] = cmd;
                buf[at + 2..at + 6].copy_from_slice(&address.to_le_bytes());
                let flags = (len as u16) | if more { 1 << 15 } else { 0 };
                buf[at + 6..at + 8].copy_from_slice(&flags.to_le_bytes());
                at += DGRAM + len + WKC;
            };
        datagram(
            &mut buf,
            LRW,
            layout.logical_start,
            usize::from(layout.len),
            reads > 0 || reference.is_some(),
        );
        if let Some(station) = reference {
            let address = u32::from(station) | (u32::from(DC_SYSTEM_TIME) << 16);
            datagram(&mut buf, FPWR, address, 8, true);
            datagram(&mut buf, FRMW, address, 8, reads > 0);
        }
        for (k, s) in layout.slots[..n].iter().enumerate() {
            let address = u32::from(s.station) | (u32::from(AL_STATUS) << 16);
            datagram(&mut buf, FPRD, address, AL_BYTES, k + 1 < reads);
        }
        for (j, &k) in mailboxes[..mailbox_count].iter().enumerate() {
            let s = &layout.slots[usize::from(k)];
            let address = u32::from(s.station) | (u32::from(SM1_STATUS) << 16);
            datagram(&mut buf, FPRD, address, 1, n + j + 1 < reads);
        }
        Ok(Self {
            layout,
            buf,
            len: len.max(60),
            reply: [0; MAX_FRAME],
            index: 0,
            datagrams,
            mailboxes,
            mailbox_count,
            read_next: None,
            read_sent: None,
            dc_len,
            op_request: false,
            tail_sent: 0,
        })
    }

    /// The layout it was built for.
    pub fn layout(&self) -> &Layout {
        &self.layout
    }

    fn image_at() -> usize {
        ETH + ECAT + DGRAM
    }

    /// SubDevice `k`'s outputs in the frame to send (empty if it has none).
    pub fn outputs_mut(&mut self, k: usize) -> &mut [u8] {
        let (off, len) = self.layout.slots.get(k).map_or((0, 0), |s| s.outputs);
        let at = Self::image_at() + usize::from(off);
        &mut self.buf[at..at + usize::from(len)]
    }

    /// SubDevice `k`'s inputs as the last reply brought them (empty if it has none).
    pub fn inputs(&self, k: usize) -> &[u8] {
        let (off, len) = self.layout.slots.get(k).map_or((0, 0), |s| s.inputs);
        let at = Self::image_at() + usize::from(off);
        &self.reply[at..at + usize::from(len)]
    }

    /// Where the datagrams after the LRW start.
    fn after_lrw(&self) -> usize {
        Self::image_at() + usize::from(self.layout.len) + WKC
    }

    /// Where the AL status reads start.
    fn al_reads_at(&self) -> usize {
        self.after_lrw() + self.dc_len
    }

    /// Whether the frame carries the DC datagrams.
    pub fn has_dc(&self) -> bool {
        self.dc_len > 0
    }

    /// Writes `t` (ns, DC system time) as the MainDevice's time the next frame gives the
    /// reference clock.
    ///
    /// # Real-time
    /// Copies only.
    pub fn set_master_time(&mut self, t: u64) {
        if self.dc_len > 0 {
            let at = self.after_lrw() + DGRAM;
            self.buf[at..at + 8].copy_from_slice(&t.to_le_bytes());
        }
    }

    /// The reference clock's system time as the last reply's FRMW read it, and how many DC
    /// SubDevices took part (the FRMW's working counter); `None` without DC or when the
    /// reference did not answer.
    ///
    /// # Real-time
    /// Reads only.
    pub fn reference_time(&self) -> Option<(u64, u16)> {
        if self.dc_len == 0 {
            return None;
        }
        let at = self.after_lrw() + DGRAM + 8 + WKC + DGRAM;
        let r = &self.reply;
        let wkc = u16::from_le_bytes([r[at + 8], r[at + 9]]);
        let t = u64::from_le_bytes(r[at..at + 8].try_into().ok()?);
        (wkc > 0).then_some((t, wkc))
    }

    /// SubDevice `k`'s AL status (state and error bit) and AL status code, as the last reply
    /// brought them.
    pub fn al_status(&self, k: usize) -> (u16, u16) {
        let at = self.al_reads_at() + k * (DGRAM + AL_BYTES + WKC) + DGRAM;
        let r = &self.reply;
        (
            u16::from_le_bytes([r[at], r[at + 1]]),
            u16::from_le_bytes([r[at + 4], r[at + 5]]),
        )
    }

    /// Where the status read of the `j`-th send mailbox starts.
    fn mailbox_status_at(&self, j: usize) -> usize {
        self.al_reads_at()
            + self.layout.count.min(MAX_SUBDEVICES) * (DGRAM + AL_BYTES + WKC)
            + j * (DGRAM + 1 + WKC)
    }

    /// The SubDevices whose send mailbox the last reply found full, in status order.
    ///
    /// # Real-time
    /// Reads only.
    pub fn full_mailboxes(&self) -> impl Iterator<Item = usize> + '_ {
        (0..self.mailbox_count).filter_map(|j| {
            let at = self.mailbox_status_at(j);
            let read = u16::from_le_bytes([self.reply[at + DGRAM + 1], self.reply[at + DGRAM + 2]]);
            (read == 1 && self.reply[at + DGRAM] & 0x08 != 0)
                .then_some(usize::from(self.mailboxes[j]))
        })
    }

    /// Makes the next frame read SubDevice `k`'s send mailbox (whole, which empties it).
    pub fn read_mailbox(&mut self, k: usize) {
        if self.layout.slots.get(k).is_some_and(|s| s.mailbox_in.1 > 0) {
            self.read_next = Some(k);
        }
    }

    /// Makes every next frame ask all SubDevices for OP (a broadcast write of AL control), or
    /// no longer. A SubDevice in OP takes the request as nothing; one with its error flag set
    /// ignores it (its error waits for an acknowledgement the cycle never gives).
    ///
    /// # Real-time
    /// A store only.
    pub fn request_op(&mut self, on: bool) {
        self.op_request = on;
    }

    /// The SubDevice whose mailbox the frame sent last reads.
    pub fn mailbox_read(&self) -> Option<usize> {
        self.read_sent
    }

    /// The mailbox the last reply read, and whose it was; `None` if it read none, or its
    /// SubDevice did not answer.
    pub fn mailbox(&self) -> Option<(usize, &[u8])> {
        let k = self.read_sent?;
        let len = usize::from(self.layout.slots[k].mailbox_in.1);
        let at = ETH + ECAT + self.datagrams + DGRAM;
        let wkc = u16::from_le_bytes([self.reply[at + len], self.reply[at + len + 1]]);
        (wkc == 1).then(|| (k, &self.reply[at..at + len]))
    }

    /// The next frame to send: a new index, working counters 0, and the mailbox read asked
    /// for by [`CyclicFrame::read_mailbox`], if any.
    ///
    /// # Real-time
    /// Copies only.
    pub fn next_frame(&mut self) -> &[u8] {
        self.index = self.index.wrapping_add(1);
        let n = self.layout.count.min(MAX_SUBDEVICES);
        // The LRW: its index and working counter (its data are the outputs).
        let mut at = ETH + ECAT;
        let lrw_len = usize::from(self.layout.len);
        self.buf[at + 1] = self.index;
        self.buf[at + DGRAM + lrw_len..at + DGRAM + lrw_len + WKC].fill(0);
        let mut last = at;
        at += DGRAM + lrw_len + WKC;
        if self.dc_len > 0 {
            // The FPWR keeps the time written into it; the FRMW's data is read.
            for read in [false, true] {
                self.buf[at + 1] = self.index;
                if read {
                    self.buf[at + DGRAM..at + DGRAM + 8].fill(0);
                }
                self.buf[at + DGRAM + 8..at + DGRAM + 8 + WKC].fill(0);
                last = at;
                at += DGRAM + 8 + WKC;
            }
        }
        for k in 0..n + self.mailbox_count {
            let len = if k < n { AL_BYTES } else { 1 };
            self.buf[at + 1] = self.index;
            self.buf[at + DGRAM..at + DGRAM + len + WKC].fill(0);
            last = at;
            at += DGRAM + len + WKC;
        }
        self.read_sent = self.read_next.take();
        let mut datagrams = self.datagrams;
        // The datagram after `last`, at `at`, with `len` bytes of data.
        let mut append = |buf: &mut [u8; MAX_FRAME], last: &mut usize, at: &mut usize, len| {
            buf[*last + 7] |= 0x80; // more follows
            buf[*at + 1] = self.index;
            buf[*at + 6..*at + 8].copy_from_slice(&(len as u16).to_le_bytes());
            buf[*at + 8..*at + DGRAM].fill(0);
            buf[*at + DGRAM + len..*at + DGRAM + len + WKC].fill(0);
            *last = *at;
            *at += DGRAM + len + WKC;
            datagrams += DGRAM + len + WKC;
        };
        self.buf[last + 7] &= 0x7F;
        if let Some(k) = self.read_sent {
            let s = self.layout.slots[k];
            let len = usize::from(s.mailbox_in.1);
            let here = at;
            append(&mut self.buf, &mut last, &mut at, len);
            self.buf[here] = FPRD;
            self.buf[here + 2..here + 4].copy_from_slice(&s.station.to_le_bytes());
            self.buf[here + 4..here + 6].copy_from_slice(&s.mailbox_in.0.to_le_bytes());
            self.buf[here + DGRAM..here + DGRAM + len].fill(0);
        }
        if self.op_request {
            let here = at;
            append(&mut self.buf, &mut last, &mut at, 2);
            self.buf[here] = BWR;
            self.buf[here + 2..here + 4].fill(0);
            self.buf[here + 4..here + 6].copy_from_slice(&AL_CONTROL.to_le_bytes());
            self.buf[here + DGRAM..here + DGRAM + 2].copy_from_slice(&AL_OP.to_le_bytes());
        }
        self.tail_sent = datagrams - self.datagrams;
        self.buf[14..16].copy_from_slice(&((datagrams as u16) | (1 << 12)).to_le_bytes());
        let len = (ETH + ECAT + datagrams).max(60);
        if len > self.len {
            // Padding a shorter frame left behind.
            self.buf[ETH + ECAT + datagrams..len].fill(0);
        }
        self.len = len;
        &self.buf[..len]
    }

    /// Takes `frame` if it is the reply to the frame sent last.
    ///
    /// # Real-time
    /// Copies only.
    pub fn take_reply(&mut self, frame: &[u8]) -> Reply {
        let end = ETH + ECAT + self.datagrams + self.tail_sent;
        if frame.len() < end
            || frame[12..14] != ethercat_wire::ETHERTYPE.to_be_bytes()
            || frame[6] & 0x02 == 0
            || frame[ETH + ECAT] != LRW
            || frame[ETH + ECAT + 1] != self.index
        {
            return Reply::NotOurs;
        }
        self.reply[..end].copy_from_slice(&frame[..end]);
        let wkc_at = Self::image_at() + usize::from(self.layout.len);
        let wkc = u16::from_le_bytes([frame[wkc_at], frame[wkc_at + 1]]);
        let mut al_read = 0;
        let mut at = self.al_reads_at();
        for _ in 0..self.layout.count.min(MAX_SUBDEVICES) {
            let w = at + DGRAM + AL_BYTES;
            if u16::from_le_bytes([frame[w], frame[w + 1]]) == 1 {
                al_read += 1;
            }
            at = w + WKC;
        }
        Reply::Ours { wkc, al_read }
    }
}
