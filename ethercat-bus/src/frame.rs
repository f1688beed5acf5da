//! The cycle's one frame: an LRW datagram over the whole process image (every SubDevice's
//! outputs written, its inputs read, through the FMMUs ethercrab configured), followed by an
//! FPRD of each SubDevice's AL status and status code, so that every cycle knows which
//! SubDevice is in which state. Built once at start-up; a cycle writes the outputs in place,
//! sends, and takes the reply: no allocation, constant time.
//!
//! Layout (ETG.1000.4): Ethernet header (broadcast destination, EtherType 0x88A4), EtherCAT
//! header (length of the datagrams, type 1), then datagrams of a 10-byte header (command,
//! index, address, length with the "more follows" bit, IRQ), data and a 2-byte working
//! counter. The frame is padded to Ethernet's 60 bytes.

use shm_schema::ethercat::MAX_SUBDEVICES;

/// Logical read-write.
const LRW: u8 = 12;
/// Configured-address physical read.
const FPRD: u8 = 4;
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
    /// Bytes of the datagrams (the EtherCAT header's length).
    datagrams: usize,
}

impl CyclicFrame {
    /// The frame for `layout`, or why it does not fit in one Ethernet frame.
    pub fn new(layout: Layout) -> Result<Self, String> {
        let n = layout.count.min(MAX_SUBDEVICES);
        let datagrams = DGRAM + usize::from(layout.len) + WKC + n * (DGRAM + AL_BYTES + WKC);
        let len = ETH + ECAT + datagrams;
        if len > MAX_FRAME || usize::from(layout.len) > 0x7FF {
            return Err(format!(
                "the process image ({} bytes) and {n} AL status reads do not fit one frame ({len} of {MAX_FRAME} bytes)",
                layout.len
            ));
        }
        let mut buf = [0u8; MAX_FRAME];
        buf[0..6].copy_from_slice(&[0xFF; 6]);
        buf[6..12].copy_from_slice(&SOURCE);
        buf[12..14].copy_from_slice(&ethercat_wire::ETHERTYPE.to_be_bytes());
        buf[14..16].copy_from_slice(&((datagrams as u16) | (1 << 12)).to_le_bytes());
        let mut at = ETH + ECAT;
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
            n > 0,
        );
        for (k, s) in layout.slots[..n].iter().enumerate() {
            let address = u32::from(s.station) | (u32::from(AL_STATUS) << 16);
            datagram(&mut buf, FPRD, address, AL_BYTES, k + 1 < n);
        }
        Ok(Self {
            layout,
            buf,
            len: len.max(60),
            reply: [0; MAX_FRAME],
            index: 0,
            datagrams,
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

    /// SubDevice `k`'s AL status (state and error bit) and AL status code, as the last reply
    /// brought them.
    pub fn al_status(&self, k: usize) -> (u16, u16) {
        let at = Self::image_at()
            + usize::from(self.layout.len)
            + WKC
            + k * (DGRAM + AL_BYTES + WKC)
            + DGRAM;
        let r = &self.reply;
        (
            u16::from_le_bytes([r[at], r[at + 1]]),
            u16::from_le_bytes([r[at + 4], r[at + 5]]),
        )
    }

    /// The next frame to send: a new index, working counters 0.
    ///
    /// # Real-time
    /// Copies only.
    pub fn next_frame(&mut self) -> &[u8] {
        self.index = self.index.wrapping_add(1);
        let mut at = ETH + ECAT;
        let n = self.layout.count.min(MAX_SUBDEVICES);
        for k in 0..=n {
            let len = if k == 0 {
                usize::from(self.layout.len)
            } else {
                AL_BYTES
            };
            self.buf[at + 1] = self.index;
            if k > 0 {
                self.buf[at + DGRAM..at + DGRAM + len].fill(0);
            }
            self.buf[at + DGRAM + len..at + DGRAM + len + WKC].fill(0);
            at += DGRAM + len + WKC;
        }
        &self.buf[..self.len]
    }

    /// Takes `frame` if it is the reply to the frame sent last.
    ///
    /// # Real-time
    /// Copies only.
    pub fn take_reply(&mut self, frame: &[u8]) -> Reply {
        let end = ETH + ECAT + self.datagrams;
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
        let mut at = wkc_at + WKC;
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
