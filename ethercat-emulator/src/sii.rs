//! The SubDevice Information Interface: the EEPROM every SubDevice carries (ETG.2010), built
//! word by word: the header (configuration, its checksum, identity, mailboxes), then the
//! categories a MainDevice reads to configure the device without asking it: strings, general
//! (name, CoE support), FMMU usage, SyncManagers, TxPDOs and RxPDOs.

/// Vendor, product, revision, serial (words 0x0008 to 0x000F; CoE object 0x1018 too).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Identity {
    /// Vendor id (0x2: Beckhoff).
    pub vendor: u32,
    /// Product code.
    pub product: u32,
    /// Revision.
    pub revision: u32,
    /// Serial number.
    pub serial: u32,
}

impl std::fmt::Display for Identity {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "vendor {:#x}, product {:#010x}, revision {:#010x}",
            self.vendor, self.product, self.revision
        )
    }
}

/// The standard mailbox: where the MainDevice writes (receive) and reads (send) it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Mailbox {
    /// Physical start of the mailbox the MainDevice writes (SM0).
    pub receive_offset: u16,
    /// Its size.
    pub receive_size: u16,
    /// Physical start of the mailbox the MainDevice reads (SM1).
    pub send_offset: u16,
    /// Its size.
    pub send_size: u16,
    /// Protocols, as word 0x001C codes them (bit 2: CoE).
    pub protocols: u16,
}

/// What a SyncManager is for (category 41's type byte).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub enum SmKind {
    /// The mailbox the MainDevice writes.
    MailboxOut = 1,
    /// The mailbox the MainDevice reads.
    MailboxIn = 2,
    /// Process data the MainDevice writes (outputs).
    Outputs = 3,
    /// Process data the MainDevice reads (inputs).
    Inputs = 4,
}

/// One SyncManager's default configuration.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Sm {
    /// Physical start address.
    pub start: u16,
    /// Length in bytes.
    pub length: u16,
    /// Control byte (mode and direction), as register 0x0804 + 8n takes it.
    pub control: u8,
    /// Enabled by default.
    pub enable: bool,
    /// What it is for.
    pub kind: SmKind,
}

/// One entry of a PDO: an object's index, subindex and size.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PdoEntry {
    /// Object index.
    pub index: u16,
    /// Subindex.
    pub subindex: u8,
    /// Bits.
    pub bits: u8,
    /// CoE data type code (1 BOOL, 5 UINT8, 6 UINT16, 3 INT16, 4 INT32, 7 UINT32 ...).
    pub data_type: u8,
}

/// A process data object: its index, the SyncManager it goes through, its entries.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Pdo {
    /// 0x1600.. (RxPDO, outputs) or 0x1A00.. (TxPDO, inputs).
    pub index: u16,
    /// The SyncManager it is assigned to.
    pub sm: u8,
    /// Its entries in order.
    pub entries: Vec<PdoEntry>,
}

impl Pdo {
    /// Its size in bits.
    pub fn bits(&self) -> u32 {
        self.entries.iter().map(|e| u32::from(e.bits)).sum()
    }
}

/// Everything an EEPROM holds, to be built into its words.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Sii {
    /// The identity.
    pub identity: Identity,
    /// The station alias (word 0x0004).
    pub alias: u16,
    /// Its order number, the type (general category), e.g. `EL2008`: what MainDevices
    /// (ethercrab, SOEM, TwinCAT) show as the device's name.
    pub order: String,
    /// Its group (general category), e.g. `DigOut`.
    pub group: String,
    /// Its description (the general category's "name"), e.g. `EL2008 8Ch. Dig. Output
    /// 24V, 0.5A`.
    pub name: String,
    /// The standard mailbox, if it has one (then CoE).
    pub mailbox: Option<Mailbox>,
    /// Per FMMU, its use: 1 outputs, 2 inputs, 3 SyncManager status.
    pub fmmus: Vec<u8>,
    /// The SyncManagers.
    pub sms: Vec<Sm>,
    /// PDOs the device sends (inputs).
    pub tx_pdos: Vec<Pdo>,
    /// PDOs the device receives (outputs).
    pub rx_pdos: Vec<Pdo>,
}

/// CRC-8 of the configuration area (words 0 to 6): polynomial 0x07, initial value 0xFF, not
/// reflected, no final xor (ETG.2010). Checked against the stored checksum of six real
/// devices' EEPROM dumps (EK1100, EL2828, EL2889, EL2262, a Kollmorgen AKD and its variant;
/// ethercrab's repository, read for the check, not kept here): all six agree.
pub fn checksum(bytes: &[u8]) -> u8 {
    crc8(0xFF, bytes)
}

/// CRC-8, polynomial 0x07, most significant bit first, from `init`.
fn crc8(init: u8, bytes: &[u8]) -> u8 {
    let mut crc = init;
    for b in bytes {
        crc ^= b;
        for _ in 0..8 {
            crc = if crc & 0x80 != 0 {
                (crc << 1) ^ 0x07
            } else {
                crc << 1
            };
        }
    }
    crc
}

impl Sii {
    /// The EEPROM's content, as words.
    pub fn words(&self) -> Vec<u16> {
        let mut w = vec![0u16; 0x40];
        w[4] = self.alias;
        let mut config = Vec::new();
        for x in &w[..7] {
            config.extend_from_slice(&x.to_le_bytes());
        }
        w[7] = u16::from(checksum(&config));
        let id = self.identity;
        for (at, v) in [
            (8, id.vendor),
            (10, id.product),
            (12, id.revision),
            (14, id.serial),
        ] {
            w[at] = v as u16;
            w[at + 1] = (v >> 16) as u16;
        }
        if let Some(m) = self.mailbox {
            // The bootstrap mailbox is the standard one (no firmware update here).
            w[0x14] = m.receive_offset;
            w[0x15] = m.receive_size;
            w[0x16] = m.send_offset;
            w[0x17] = m.send_size;
            w[0x18] = m.receive_offset;
            w[0x19] = m.receive_size;
            w[0x1A] = m.send_offset;
            w[0x1B] = m.send_size;
            w[0x1C] = m.protocols;
        }
        // EEPROM size in KiBit minus one (2 KiB), format version 1.
        w[0x3E] = 15;
        w[0x3F] = 1;

        // As real devices have them: the type first (SOEM names a device by string 1,
        // ethercrab by the order index), then the group, then the description.
        let mut strings = vec![self.order.clone(), self.group.clone(), self.name.clone()];
        let string_index = |s: &str, strings: &mut Vec<String>| -> u8 {
            match strings.iter().position(|x| x == s) {
                Some(i) => (i + 1) as u8,
                None => {
                    strings.push(s.to_string());
                    strings.len() as u8
                }
            }
        };
        // PDO names are the PDOs' own ("Channel 1" …): kept short.
        let pdo_bytes = |pdos: &[Pdo], strings: &mut Vec<String>| -> Vec<u8> {
            let mut b = Vec::new();
            for (k, p) in pdos.iter().enumerate() {
                let name = string_index(&format!("Channel {}", k + 1), strings);
                b.extend_from_slice(&p.index.to_le_bytes());
                b.push(p.entries.len() as u8);
                b.push(p.sm);
                b.push(0); // DC sync
                b.push(name);
                b.extend_from_slice(&0u16.to_le_bytes()); // flags
                for e in &p.entries {
                    b.extend_from_slice(&e.index.to_le_bytes());
                    b.push(e.subindex);
                    b.push(0); // name
                    b.push(e.data_type);
                    b.push(e.bits);
                    b.extend_from_slice(&0u16.to_le_bytes());
                }
            }
            b
        };
        let tx = pdo_bytes(&self.tx_pdos, &mut strings);
        let rx = pdo_bytes(&self.rx_pdos, &mut strings);

        let mut general = vec![0u8; 32];
        general[0] = 2; // group: string 2
        general[1] = 0; // image
        general[2] = 1; // order: string 1
        general[3] = 3; // name: string 3
        // CoE details: SDO (bit 0), PDO assign (2), PDO config (3); not SDO information (1),
        // upload at start-up (4) nor complete access (5), which `coe` does not serve.
        general[5] = if self.mailbox.is_some() { 0x0D } else { 0 };
        general[14] = 1;

        let mut string_bytes = vec![strings.len() as u8];
        for s in &strings {
            let s = &s.as_bytes()[..s.len().min(255)];
            string_bytes.push(s.len() as u8);
            string_bytes.extend_from_slice(s);
        }
        let mut sm_bytes = Vec::new();
        for sm in &self.sms {
            sm_bytes.extend_from_slice(&sm.start.to_le_bytes());
            sm_bytes.extend_from_slice(&sm.length.to_le_bytes());
            sm_bytes.push(sm.control);
            sm_bytes.push(0);
            sm_bytes.push(u8::from(sm.enable));
            sm_bytes.push(sm.kind as u8);
        }

        let mut push = |kind: u16, bytes: &[u8]| {
            if bytes.is_empty() {
                return;
            }
            let mut bytes = bytes.to_vec();
            if bytes.len() % 2 == 1 {
                bytes.push(0);
            }
            w.push(kind);
            w.push((bytes.len() / 2) as u16);
            w.extend(bytes.chunks(2).map(|c| u16::from_le_bytes([c[0], c[1]])));
        };
        push(10, &string_bytes);
        push(30, &general);
        push(40, &self.fmmus);
        push(41, &sm_bytes);
        push(50, &tx);
        push(51, &rx);
        w.push(0xFFFF);
        w
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_checksum_is_etg_2010s_crc8() {
        // From 0 it is the catalogued CRC-8/SMBUS, whose check value is 0xF4; from 0xFF (the
        // SII's) the check value is 0xFB (computed here by a separate implementation too).
        assert_eq!(crc8(0, b"123456789"), 0xF4);
        assert_eq!(checksum(b"123456789"), 0xFB);
    }

    #[test]
    fn the_identity_and_the_categories_are_where_the_standard_puts_them() {
        let sii = Sii {
            identity: Identity {
                vendor: 2,
                product: 0x07D8_3052,
                revision: 0x0010_0000,
                serial: 7,
            },
            alias: 0,
            order: "EL2008".into(),
            group: "DigOut".into(),
            name: "EL2008 8Ch. Dig. Output 24V, 0.5A".into(),
            mailbox: None,
            fmmus: vec![1],
            sms: vec![Sm {
                start: 0x0F00,
                length: 1,
                control: 0x44,
                enable: true,
                kind: SmKind::Outputs,
            }],
            tx_pdos: vec![],
            rx_pdos: vec![],
        };
        let w = sii.words();
        assert_eq!((w[8], w[9]), (2, 0));
        assert_eq!((w[10], w[11]), (0x3052, 0x07D8));
        assert_eq!(w[0x40], 10, "strings first");
        let mut bytes = Vec::new();
        for x in &w[..7] {
            bytes.extend_from_slice(&x.to_le_bytes());
        }
        assert_eq!(w[7], u16::from(checksum(&bytes)));
        assert_eq!(*w.last().expect("end"), 0xFFFF);
    }
}
