//! The emulated line under MainDevices in this process, one test binary: the drive
//! (`drive`), an emergency answering an SDO request (`emergency`), the line's mapping and
//! cycle under ethercrab (`line`), and the same over a veth pair (`on_a_veth`). `common` is the in-process
//! wire between ethercrab and the emulator.

mod common;
mod drive;
mod emergency;
mod line;
mod on_a_veth;
