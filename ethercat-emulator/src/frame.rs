//! EtherCAT frames on Ethernet (ETG.1000.4): the Ethernet header with EtherType `0x88A4`, the
//! EtherCAT header (length, type 1: datagrams), then datagrams, each a 10-byte header, its data
//! and a working counter. A frame travels through every SubDevice in order and comes back
//! changed in place; [`walk`] is that pass.
//!
//! Nothing in a frame can make this panic: every length is checked against the bytes there
//! are, and a frame that does not add up is refused whole with what is wrong in it.

/// The EtherType of EtherCAT.
pub use ethercat_wire::ETHERTYPE;
/// Ethernet header: destination, source, EtherType.
pub const ETHERNET_HEADER: usize = 14;
/// EtherCAT header: 11 bits of length, a reserved bit, 4 bits of type.
pub const ECAT_HEADER: usize = 2;
/// A datagram's header: command, index, address, length and flags, interrupt.
pub const DATAGRAM_HEADER: usize = 10;
/// A datagram's working counter, after its data.
pub const WKC: usize = 2;

/// The datagram commands (ETG.1000.4, table "EtherCAT command types").
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Command {
    /// No operation.
    Nop,
    /// Auto-increment (position) read, write, read-write.
    Aprd,
    /// Auto-increment write.
    Apwr,
    /// Auto-increment read-write.
    Aprw,
    /// Configured address (station address) read.
    Fprd,
    /// Configured address write.
    Fpwr,
    /// Configured address read-write.
    Fprw,
    /// Broadcast read (the data is the OR over every SubDevice).
    Brd,
    /// Broadcast write.
    Bwr,
    /// Broadcast read-write.
    Brw,
    /// Logical read (through the FMMUs).
    Lrd,
    /// Logical write.
    Lwr,
    /// Logical read-write.
    Lrw,
    /// Auto-increment read, multiple write: the addressed one reads, every other writes.
    Armw,
    /// Configured-address read, multiple write.
    Frmw,
}

impl Command {
    /// The command of a code, if it is one.
    pub fn from_code(code: u8) -> Option<Self> {
        Some(match code {
            0 => Self::Nop,
            1 => Self::Aprd,
            2 => Self::Apwr,
            3 => Self::Aprw,
            4 => Self::Fprd,
            5 => Self::Fpwr,
            6 => Self::Fprw,
            7 => Self::Brd,
            8 => Self::Bwr,
            9 => Self::Brw,
            10 => Self::Lrd,
            11 => Self::Lwr,
            12 => Self::Lrw,
            13 => Self::Armw,
            14 => Self::Frmw,
            _ => return None,
        })
    }

    /// Whether it increments the position address on its way (auto-increment and broadcast).
    pub fn increments_position(self) -> bool {
        matches!(
            self,
            Self::Aprd | Self::Apwr | Self::Aprw | Self::Armw | Self::Brd | Self::Bwr | Self::Brw
        )
    }
}

/// What is wrong with a frame (the emulator drops it, as a SubDevice drops a frame it cannot
/// forward).
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum FrameError {
    /// Shorter than the Ethernet and EtherCAT headers.
    TooShort(usize),
    /// Another EtherType (not EtherCAT).
    NotEtherCat(u16),
    /// EtherCAT header type other than 1 (datagrams).
    NotDatagrams(u8),
    /// The EtherCAT header's length runs past the frame.
    LengthPastFrame {
        /// What the header says.
        declared: usize,
        /// What the frame holds after the headers.
        available: usize,
    },
    /// Datagram `index` (0-based) runs past the EtherCAT length.
    DatagramPastEnd {
        /// Its place in the frame.
        index: usize,
    },
    /// Datagram `index` has an unknown command code.
    UnknownCommand {
        /// Its place in the frame.
        index: usize,
        /// The code.
        code: u8,
    },
}

impl std::fmt::Display for FrameError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::TooShort(n) => write!(f, "a frame of {n} bytes: shorter than its headers"),
            Self::NotEtherCat(t) => {
                write!(f, "EtherType {t:#06x}, not EtherCAT ({ETHERTYPE:#06x})")
            }
            Self::NotDatagrams(t) => write!(f, "EtherCAT header type {t}, not datagrams (1)"),
            Self::LengthPastFrame {
                declared,
                available,
            } => write!(
                f,
                "the EtherCAT header declares {declared} bytes; the frame holds {available}"
            ),
            Self::DatagramPastEnd { index } => {
                write!(f, "datagram {index} runs past the EtherCAT length")
            }
            Self::UnknownCommand { index, code } => {
                write!(f, "datagram {index}: unknown command code {code}")
            }
        }
    }
}

impl std::error::Error for FrameError {}

/// One datagram as a SubDevice sees it on its way: the command, the address fields as they
/// arrive (the position is incremented between SubDevices), the data and the working counter.
#[derive(Debug)]
pub struct Datagram<'a> {
    /// Its command.
    pub command: Command,
    /// Position or configured address (ADP), or the low half of a logical address.
    pub adp: u16,
    /// Register offset (ADO), or the high half of a logical address.
    pub ado: u16,
    /// The data, changed in place.
    pub data: &'a mut [u8],
    /// The working counter, incremented by each SubDevice that did its part.
    pub wkc: u16,
}

impl Datagram<'_> {
    /// The logical address of a logical command.
    pub fn logical(&self) -> u32 {
        u32::from(self.adp) | (u32::from(self.ado) << 16)
    }
}

/// Checks `frame` and passes each of its datagrams to `each` in order (the SubDevices'
/// pass), writing back the position address and the working counter; the source address gets
/// the locally administered bit, as an ESC's port 0 sets it on the way back. On an error the
/// frame may be partly changed and must be dropped.
pub fn walk(
    frame: &mut [u8],
    mut each: impl FnMut(&mut Datagram<'_>),
) -> Result<usize, FrameError> {
    if frame.len() < ETHERNET_HEADER + ECAT_HEADER {
        return Err(FrameError::TooShort(frame.len()));
    }
    let ethertype = u16::from_be_bytes([frame[12], frame[13]]);
    if ethertype != ETHERTYPE {
        return Err(FrameError::NotEtherCat(ethertype));
    }
    let header = u16::from_le_bytes([frame[14], frame[15]]);
    let length = usize::from(header & 0x07FF);
    let kind = (header >> 12) as u8;
    if kind != 1 {
        return Err(FrameError::NotDatagrams(kind));
    }
    let body = &mut frame[ETHERNET_HEADER + ECAT_HEADER..];
    if length > body.len() {
        return Err(FrameError::LengthPastFrame {
            declared: length,
            available: body.len(),
        });
    }
    let body = &mut body[..length];
    let mut at = 0usize;
    let mut index = 0usize;
    loop {
        let Some(h) = body.get(at..at + DATAGRAM_HEADER) else {
            return Err(FrameError::DatagramPastEnd { index });
        };
        let code = h[0];
        let adp = u16::from_le_bytes([h[2], h[3]]);
        let ado = u16::from_le_bytes([h[4], h[5]]);
        let flags = u16::from_le_bytes([h[6], h[7]]);
        let len = usize::from(flags & 0x07FF);
        let more = flags & 0x8000 != 0;
        let command = Command::from_code(code).ok_or(FrameError::UnknownCommand { index, code })?;
        let data_at = at + DATAGRAM_HEADER;
        let wkc_at = data_at + len;
        if wkc_at + WKC > body.len() {
            return Err(FrameError::DatagramPastEnd { index });
        }
        let wkc = u16::from_le_bytes([body[wkc_at], body[wkc_at + 1]]);
        let mut d = Datagram {
            command,
            adp,
            ado,
            data: &mut body[data_at..wkc_at],
            wkc,
        };
        each(&mut d);
        let (adp, wkc) = (d.adp, d.wkc);
        body[at + 2..at + 4].copy_from_slice(&adp.to_le_bytes());
        body[wkc_at..wkc_at + 2].copy_from_slice(&wkc.to_le_bytes());
        at = wkc_at + WKC;
        index += 1;
        if !more {
            break;
        }
    }
    // The reply comes from port 0 of the first SubDevice: source address with the locally
    // administered bit (a MainDevice tells its own frames from the replies by it).
    frame[6] |= 0x02;
    Ok(index)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(datagrams: &[(u8, u16, u16, &[u8], bool)]) -> Vec<u8> {
        let mut body = Vec::new();
        for (i, (cmd, adp, ado, data, more)) in datagrams.iter().enumerate() {
            body.push(*cmd);
            body.push(i as u8);
            body.extend_from_slice(&adp.to_le_bytes());
            body.extend_from_slice(&ado.to_le_bytes());
            let flags = data.len() as u16 | if *more { 0x8000 } else { 0 };
            body.extend_from_slice(&flags.to_le_bytes());
            body.extend_from_slice(&[0, 0]);
            body.extend_from_slice(data);
            body.extend_from_slice(&[0, 0]);
        }
        let mut f = vec![0xFF; 6];
        f.extend_from_slice(&[0x10; 6]);
        f.extend_from_slice(&ETHERTYPE.to_be_bytes());
        f.extend_from_slice(&((body.len() as u16) | 0x1000).to_le_bytes());
        f.extend_from_slice(&body);
        f
    }

    #[test]
    fn every_datagram_is_seen_and_its_counter_and_position_written_back() {
        let mut f = frame(&[
            (7, 0, 0x0130, &[0, 0], true),
            (2, 0xFFFF, 0x10, &[1, 2], false),
        ]);
        let mut seen = Vec::new();
        let n = walk(&mut f, |d| {
            seen.push((d.command, d.adp, d.ado, d.data.to_vec()));
            d.wkc += 3;
            d.adp = d.adp.wrapping_add(1);
        })
        .expect("a good frame");
        assert_eq!(n, 2);
        assert_eq!(seen[0], (Command::Brd, 0, 0x0130, vec![0, 0]));
        assert_eq!(seen[1], (Command::Apwr, 0xFFFF, 0x10, vec![1, 2]));
        // Source MAC marked as the reply, counters and positions written.
        assert_eq!(f[6], 0x12);
        let wkc0 = 16 + 10 + 2;
        assert_eq!(u16::from_le_bytes([f[wkc0], f[wkc0 + 1]]), 3);
        assert_eq!(u16::from_le_bytes([f[18], f[19]]), 1);
    }

    #[test]
    fn frames_that_do_not_add_up_are_refused_without_a_panic() {
        let good = frame(&[(4, 0x1000, 0x0130, &[0, 0], false)]);
        assert_eq!(
            walk(&mut good[..10].to_vec(), |_| {}),
            Err(FrameError::TooShort(10))
        );
        let mut other = good.clone();
        other[12] = 0x08;
        other[13] = 0x00;
        assert_eq!(
            walk(&mut other, |_| {}),
            Err(FrameError::NotEtherCat(0x0800))
        );
        let mut long = good.clone();
        long[14] = 0xFF;
        assert!(matches!(
            walk(&mut long, |_| {}),
            Err(FrameError::LengthPastFrame { .. })
        ));
        let mut more = good.clone();
        more[16 + 7] |= 0x80; // says another datagram follows: there is none
        assert_eq!(
            walk(&mut more, |_| {}),
            Err(FrameError::DatagramPastEnd { index: 1 })
        );
        let mut unknown = good.clone();
        unknown[16] = 99;
        assert_eq!(
            walk(&mut unknown, |_| {}),
            Err(FrameError::UnknownCommand { index: 0, code: 99 })
        );
        // Arbitrary bytes never panic.
        let mut x: u32 = 12345;
        for len in 0..400 {
            let mut f: Vec<u8> = (0..len)
                .map(|_| {
                    x = x.wrapping_mul(1_103_515_245).wrapping_add(12345);
                    (x >> 16) as u8
                })
                .collect();
            if f.len() > 14 {
                f[12] = 0x88;
                f[13] = 0xA4;
            }
            let _ = walk(&mut f, |d| d.wkc = d.wkc.wrapping_add(1));
        }
    }
}
