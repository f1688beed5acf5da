//! CANopen over EtherCAT (ETG.1000.6, section 5.6): the mailbox protocol a drive speaks, with
//! its object dictionary. Here: the mailbox header, SDO upload (read) and download (write),
//! expedited and normal, and SDO aborts with their codes. A request that cannot be served is
//! answered with an abort naming why, never dropped; a malformed mailbox gets no answer (as
//! a SubDevice ignores it).

use std::collections::BTreeMap;

/// Mailbox type of CoE (low 4 bits of the mailbox header's type byte).
pub const MAILBOX_COE: u8 = 3;
/// The mailbox header: length, address, channel and priority, type and counter.
pub const MAILBOX_HEADER: usize = 6;
/// CoE service of an emergency.
const EMERGENCY: u8 = 1;
/// CoE service of an SDO request.
const SDO_REQUEST: u8 = 2;
/// CoE service of an SDO response.
const SDO_RESPONSE: u8 = 3;

/// SDO abort codes (ETG.1000.6 table "SDO abort codes").
pub mod abort {
    /// Client/server command specifier not valid or unknown.
    pub const COMMAND: u32 = 0x0504_0001;
    /// Attempt to write a read-only object.
    pub const READ_ONLY: u32 = 0x0601_0002;
    /// The object does not exist in the object dictionary.
    pub const NO_OBJECT: u32 = 0x0602_0000;
    /// Data type does not match, length of service parameter does not match.
    pub const LENGTH: u32 = 0x0607_0010;
    /// Subindex does not exist.
    pub const NO_SUBINDEX: u32 = 0x0609_0011;
    /// Object cannot be mapped to the PDO.
    pub const NOT_MAPPABLE: u32 = 0x0604_0041;
    /// The number and length of the objects to be mapped would exceed the PDO length.
    pub const MAPPING_LENGTH: u32 = 0x0604_0042;
    /// Value range of parameter exceeded (write access).
    pub const VALUE_RANGE: u32 = 0x0609_0030;
    /// Data cannot be transferred or stored because of the present device state.
    pub const STATE: u32 = 0x0800_0022;
}

/// One entry of the object dictionary: its bytes (little-endian) and whether the MainDevice
/// may write it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Entry {
    /// The value, as sent on the wire.
    pub data: Vec<u8>,
    /// Writable by SDO download.
    pub writable: bool,
}

/// A device's object dictionary: (index, subindex) to entry.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Dictionary {
    entries: BTreeMap<(u16, u8), Entry>,
}

impl Dictionary {
    /// An entry that the MainDevice may only read.
    pub fn constant(&mut self, index: u16, sub: u8, data: &[u8]) -> &mut Self {
        self.entries.insert(
            (index, sub),
            Entry {
                data: data.to_vec(),
                writable: false,
            },
        );
        self
    }

    /// An entry that the MainDevice may write (a value of the same size).
    pub fn variable(&mut self, index: u16, sub: u8, data: &[u8]) -> &mut Self {
        self.entries.insert(
            (index, sub),
            Entry {
                data: data.to_vec(),
                writable: true,
            },
        );
        self
    }

    /// The entry at `index`:`sub`.
    pub fn get(&self, index: u16, sub: u8) -> Option<&Entry> {
        self.entries.get(&(index, sub))
    }

    /// The device's own write of an entry (its inputs, its state), whatever its access; the
    /// length must be the entry's (else nothing changes).
    pub fn set(&mut self, index: u16, sub: u8, data: &[u8]) {
        if let Some(e) = self.entries.get_mut(&(index, sub))
            && e.data.len() == data.len()
        {
            e.data.copy_from_slice(data);
        }
    }

    fn bytes<const N: usize>(&self, index: u16) -> [u8; N] {
        let mut b = [0; N];
        if let Some(e) = self.get(index, 0)
            && e.data.len() == N
        {
            b.copy_from_slice(&e.data);
        }
        b
    }

    /// Subindex 0 of `index` as a UNSIGNED16 (0 if it is not one).
    pub fn u16(&self, index: u16) -> u16 {
        u16::from_le_bytes(self.bytes(index))
    }

    /// Subindex 0 of `index` as an INTEGER8.
    pub fn i8(&self, index: u16) -> i8 {
        i8::from_le_bytes(self.bytes(index))
    }

    /// Subindex 0 of `index` as an INTEGER16.
    pub fn i16(&self, index: u16) -> i16 {
        i16::from_le_bytes(self.bytes(index))
    }

    /// Subindex 0 of `index` as an INTEGER32.
    pub fn i32(&self, index: u16) -> i32 {
        i32::from_le_bytes(self.bytes(index))
    }

    fn index_exists(&self, index: u16) -> bool {
        self.entries
            .range((index, 0)..=(index, u8::MAX))
            .next()
            .is_some()
    }

    /// An SDO upload of `index`:`sub`: its bytes, or the abort code.
    pub fn upload(&self, index: u16, sub: u8) -> Result<&[u8], u32> {
        match self.get(index, sub) {
            Some(e) => Ok(&e.data),
            None if self.index_exists(index) => Err(abort::NO_SUBINDEX),
            None => Err(abort::NO_OBJECT),
        }
    }

    /// An SDO download of `data` to `index`:`sub`, or the abort code.
    pub fn download(&mut self, index: u16, sub: u8, data: &[u8]) -> Result<(), u32> {
        let exists = self.index_exists(index);
        match self.entries.get_mut(&(index, sub)) {
            None if exists => Err(abort::NO_SUBINDEX),
            None => Err(abort::NO_OBJECT),
            Some(e) if !e.writable => Err(abort::READ_ONLY),
            Some(e) if e.data.len() != data.len() => Err(abort::LENGTH),
            Some(e) => {
                e.data.copy_from_slice(data);
                Ok(())
            }
        }
    }
}

/// Answers one CoE mailbox `request` (header included) from `dictionary`, within a reply
/// mailbox of `capacity` bytes; `None` for a mailbox that is not a CoE SDO request one can
/// answer (malformed, another protocol, another CoE service).
pub fn answer(dictionary: &mut Dictionary, request: &[u8], capacity: usize) -> Option<Vec<u8>> {
    let (kind, sdo) = sdo_request(request)?;
    let command = sdo[0];
    let index = u16::from_le_bytes([sdo[1], sdo[2]]);
    let sub = sdo[3];
    let complete_access = command & 0x10 != 0;
    let reply_sdo: Vec<u8> = if complete_access {
        abort_sdo(index, sub, abort::COMMAND)
    } else {
        match command >> 5 {
            // Upload (read).
            2 => match dictionary.upload(index, sub) {
                Ok(data) if !data.is_empty() && data.len() <= 4 => {
                    let mut r = vec![0x43 | ((4 - data.len() as u8) << 2)];
                    r.extend_from_slice(&index.to_le_bytes());
                    r.push(sub);
                    let mut d = data.to_vec();
                    d.resize(4, 0);
                    r.extend_from_slice(&d);
                    r
                }
                Ok(data) if MAILBOX_HEADER + 2 + 8 + data.len() <= capacity => {
                    let mut r = vec![0x41];
                    r.extend_from_slice(&index.to_le_bytes());
                    r.push(sub);
                    r.extend_from_slice(&(data.len() as u32).to_le_bytes());
                    r.extend_from_slice(data);
                    r
                }
                // Segmented transfer is not offered: too long for the mailbox.
                Ok(_) => abort_sdo(index, sub, abort::STATE),
                Err(code) => abort_sdo(index, sub, code),
            },
            // Download (write).
            1 => match download_data(sdo).map(|d| dictionary.download(index, sub, d)) {
                Some(Ok(())) => {
                    let mut r = vec![0x60];
                    r.extend_from_slice(&index.to_le_bytes());
                    r.push(sub);
                    r.extend_from_slice(&[0; 4]);
                    r
                }
                Some(Err(code)) => abort_sdo(index, sub, code),
                None => abort_sdo(index, sub, abort::LENGTH),
            },
            _ => abort_sdo(index, sub, abort::COMMAND),
        }
    };
    Some(sdo_response(kind, &reply_sdo))
}

/// The type byte (with its counter) and the SDO part of a CoE SDO request mailbox; `None`
/// for anything else, or one that does not add up.
fn sdo_request(request: &[u8]) -> Option<(u8, &[u8])> {
    let length = usize::from(u16::from_le_bytes([*request.first()?, *request.get(1)?]));
    let kind = *request.get(5)?;
    if kind & 0x0F != MAILBOX_COE || length < 2 + 8 {
        return None;
    }
    let body = request.get(MAILBOX_HEADER..MAILBOX_HEADER + length)?;
    (body[1] >> 4 == SDO_REQUEST).then(|| (kind, &body[2..]))
}

/// The data of an SDO download request's SDO part (expedited or normal).
fn download_data(sdo: &[u8]) -> Option<&[u8]> {
    if sdo[0] & 0x02 != 0 {
        let size = if sdo[0] & 0x01 != 0 {
            4 - usize::from((sdo[0] >> 2) & 0x03)
        } else {
            4
        };
        sdo.get(4..4 + size)
    } else {
        let size = u32::from_le_bytes(sdo.get(4..8)?.try_into().ok()?) as usize;
        sdo.get(8..8usize.checked_add(size)?)
    }
}

/// A CoE mailbox of `service` carrying `data`, its type byte's counter bits `counter`.
fn coe_mailbox(service: u8, counter: u8, data: &[u8]) -> Vec<u8> {
    let mut m = Vec::with_capacity(MAILBOX_HEADER + 2 + data.len());
    m.extend_from_slice(&((2 + data.len()) as u16).to_le_bytes());
    m.extend_from_slice(&[0, 0]); // address
    m.push(0); // channel, priority
    m.push(MAILBOX_COE | (counter & 0x70));
    m.extend_from_slice(&(u16::from(service) << 12).to_le_bytes());
    m.extend_from_slice(data);
    m
}

/// A mailbox with the SDO response `sdo`, answering a request whose type byte was `kind`
/// (its counter kept).
fn sdo_response(kind: u8, sdo: &[u8]) -> Vec<u8> {
    coe_mailbox(SDO_RESPONSE, kind, sdo)
}

/// A CoE emergency mailbox (ETG.1000.6 5.6.4): error code, error register, five bytes of
/// the manufacturer's; `counter` 1..=7 (the mailbox counter).
pub fn emergency(code: u16, register: u8, data: [u8; 5], counter: u8) -> Vec<u8> {
    let mut body = code.to_le_bytes().to_vec();
    body.push(register);
    body.extend_from_slice(&data);
    coe_mailbox(EMERGENCY, (counter & 0x07) << 4, &body)
}

/// What an SDO download `request` would write: index, subindex and data (`None` for
/// anything else, or a malformed request).
pub fn download_target(request: &[u8]) -> Option<(u16, u8, &[u8])> {
    let (_, sdo) = sdo_request(request)?;
    if sdo[0] >> 5 != 1 || sdo[0] & 0x10 != 0 {
        return None;
    }
    Some((
        u16::from_le_bytes([sdo[1], sdo[2]]),
        sdo[3],
        download_data(sdo)?,
    ))
}

/// The abort `code` of `index`:`sub` as the answer to `request` (its counter kept).
pub fn abort_reply(request: &[u8], index: u16, sub: u8, code: u32) -> Option<Vec<u8>> {
    Some(sdo_response(*request.get(5)?, &abort_sdo(index, sub, code)))
}

fn abort_sdo(index: u16, sub: u8, code: u32) -> Vec<u8> {
    let mut r = vec![0x80];
    r.extend_from_slice(&index.to_le_bytes());
    r.push(sub);
    r.extend_from_slice(&code.to_le_bytes());
    r
}

#[cfg(test)]
mod tests {
    use super::*;

    fn request(counter: u8, sdo: &[u8]) -> Vec<u8> {
        let mut m = ((2 + sdo.len()) as u16).to_le_bytes().to_vec();
        m.extend_from_slice(&[0, 0, 0, MAILBOX_COE | (counter << 4)]);
        m.extend_from_slice(&(u16::from(SDO_REQUEST) << 12).to_le_bytes());
        m.extend_from_slice(sdo);
        m
    }

    fn dictionary() -> Dictionary {
        let mut d = Dictionary::default();
        d.constant(0x1018, 0, &[4])
            .constant(0x1018, 1, &2u32.to_le_bytes())
            .constant(0x1008, 0, b"a drive of the emulator")
            .variable(0x6060, 0, &[0]);
        d
    }

    #[test]
    fn uploads_expedited_and_normal_downloads_and_aborts() {
        let mut d = dictionary();
        let r = answer(&mut d, &request(1, &[0x40, 0x18, 0x10, 1, 0, 0, 0, 0]), 128)
            .expect("an answer");
        assert_eq!(r[5], MAILBOX_COE | 0x10, "the request's counter");
        assert_eq!(
            &r[8..16],
            &[0x43, 0x18, 0x10, 1, 2, 0, 0, 0],
            "4 bytes expedited"
        );
        let r = answer(&mut d, &request(2, &[0x40, 0x18, 0x10, 0, 0, 0, 0, 0]), 128).expect("");
        assert_eq!(r[8], 0x4F, "1 byte expedited");
        let r = answer(&mut d, &request(3, &[0x40, 0x08, 0x10, 0, 0, 0, 0, 0]), 128).expect("");
        assert_eq!(r[8], 0x41, "normal upload");
        assert_eq!(&r[12..16], &23u32.to_le_bytes());
        assert_eq!(&r[16..39], b"a drive of the emulator");
        // A 1-byte expedited download of the mode of operation, then read back.
        let r = answer(&mut d, &request(4, &[0x2F, 0x60, 0x60, 0, 8, 0, 0, 0]), 128).expect("");
        assert_eq!(r[8], 0x60);
        assert_eq!(d.get(0x6060, 0).expect("mode").data, [8]);
        for (sdo, code) in [
            ([0x40, 0x00, 0x20, 0, 0, 0, 0, 0], abort::NO_OBJECT),
            ([0x40, 0x18, 0x10, 9, 0, 0, 0, 0], abort::NO_SUBINDEX),
            ([0x2F, 0x18, 0x10, 0, 1, 0, 0, 0], abort::READ_ONLY),
            ([0x2B, 0x60, 0x60, 0, 1, 0, 0, 0], abort::LENGTH),
            ([0xE0, 0x60, 0x60, 0, 0, 0, 0, 0], abort::COMMAND),
        ] {
            let r = answer(&mut d, &request(5, &sdo), 128).expect("an abort");
            assert_eq!(r[8], 0x80, "{sdo:x?}");
            assert_eq!(&r[12..16], &code.to_le_bytes(), "{sdo:x?}");
        }
        assert_eq!(d.get(0x6060, 0).expect("mode").data, [8], "nothing changed");
    }

    #[test]
    fn malformed_mailboxes_get_no_answer_and_never_panic() {
        let mut d = dictionary();
        assert_eq!(answer(&mut d, &[], 128), None);
        assert_eq!(
            answer(&mut d, &[200, 0, 0, 0, 0, 3, 0, 0x20], 128),
            None,
            "too long"
        );
        let mut other = request(1, &[0x40, 0x18, 0x10, 1, 0, 0, 0, 0]);
        other[5] = 4; // FoE
        assert_eq!(answer(&mut d, &other, 128), None);
        let mut x: u32 = 7;
        for len in 0..300 {
            let mut m: Vec<u8> = (0..len)
                .map(|_| {
                    x = x.wrapping_mul(1_103_515_245).wrapping_add(12345);
                    (x >> 16) as u8
                })
                .collect();
            if m.len() > 7 {
                m[5] = MAILBOX_COE;
                m[7] = 0x20;
            }
            let _ = answer(&mut d, &m, 128);
        }
    }
}
