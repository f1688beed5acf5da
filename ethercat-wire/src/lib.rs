//! EtherCAT on a network interface: a raw packet socket (`AF_PACKET`) bound to one
//! interface and to EtherType 0x88A4. The bus process sends its frames and takes their
//! replies through it; the emulator takes a MainDevice's frames and sends them back changed.
//! Frames this host sent itself are never handed back (`PACKET_OUTGOING`).
//!
//! Opening needs root or `CAP_NET_RAW`. `send` and `receive` are one system call each and
//! allocate nothing: they are the bus process' IPC inside its cycle.

/// The EtherType of EtherCAT.
pub const ETHERTYPE: u16 = 0x88A4;
use nix::sys::socket::{
    AddressFamily, LinkAddr, MsgFlags, SockFlag, SockProtocol, SockType, SockaddrLike, bind,
    recvfrom, send, setsockopt, socket, sockopt,
};
use std::os::fd::{AsRawFd, OwnedFd};
use std::time::Duration;

/// A frame the kernel hands back as sent by this host (`PACKET_OUTGOING`): our own replies.
const PACKET_OUTGOING: u8 = 4;

/// The socket of one interface.
#[derive(Debug)]
pub struct Wire {
    fd: OwnedFd,
    interface: String,
}

/// What one wait for a frame brought.
#[derive(Debug)]
pub enum Received {
    /// A frame of `n` bytes from the other end.
    Frame(usize),
    /// Nothing within the poll interval (or a frame that is not for us).
    Nothing,
}

impl Wire {
    /// Opens the socket on `interface`; [`Wire::receive`] waits at most `poll` for a frame
    /// (so a stop request is seen, a lost frame noticed).
    pub fn open(interface: &str, poll: Duration) -> Result<Self, String> {
        let at = |what: &str, e: nix::Error| format!("interface {interface:?}: {what}: {e}");
        let index =
            nix::net::if_::if_nametoindex(interface).map_err(|e| at("no such interface", e))?;
        let fd = socket(
            AddressFamily::Packet,
            SockType::Raw,
            SockFlag::SOCK_CLOEXEC,
            SockProtocol::EthAll,
        )
        .map_err(|e| at("raw socket (root or CAP_NET_RAW needed)", e))?;
        // SAFETY: sockaddr_ll is plain data; zeroed is valid and every field used is set.
        let mut sll: libc::sockaddr_ll = unsafe { std::mem::zeroed() };
        sll.sll_family = libc::AF_PACKET as u16;
        sll.sll_protocol = ETHERTYPE.to_be();
        sll.sll_ifindex = index as i32;
        let len = std::mem::size_of::<libc::sockaddr_ll>() as libc::socklen_t;
        // SAFETY: a valid sockaddr_ll of its own size.
        let addr = unsafe {
            LinkAddr::from_raw(std::ptr::from_ref(&sll).cast::<libc::sockaddr>(), Some(len))
        }
        .ok_or_else(|| format!("interface {interface:?}: cannot form its link address"))?;
        bind(fd.as_raw_fd(), &addr).map_err(|e| at("bind", e))?;
        let timeout =
            nix::sys::time::TimeVal::new(poll.as_secs() as i64, i64::from(poll.subsec_micros()));
        setsockopt(&fd, sockopt::ReceiveTimeout, &timeout).map_err(|e| at("receive timeout", e))?;
        Ok(Self {
            fd,
            interface: interface.to_string(),
        })
    }

    /// Sets how long [`Wire::receive`] waits.
    pub fn set_timeout(&self, poll: Duration) -> Result<(), String> {
        let timeout =
            nix::sys::time::TimeVal::new(poll.as_secs() as i64, i64::from(poll.subsec_micros()));
        setsockopt(&self.fd, sockopt::ReceiveTimeout, &timeout)
            .map_err(|e| format!("interface {:?}: receive timeout: {e}", self.interface))
    }

    /// Waits for the next frame from the other end into `buf`.
    ///
    /// # Real-time
    /// One `recvfrom`; no allocation but the error's text.
    pub fn receive(&self, buf: &mut [u8]) -> Result<Received, String> {
        match recvfrom::<LinkAddr>(self.fd.as_raw_fd(), buf) {
            Ok((n, Some(from))) if from.pkttype() != PACKET_OUTGOING => Ok(Received::Frame(n)),
            Ok(_) => Ok(Received::Nothing),
            // ENETDOWN: the link went down (a cable pulled): the socket reports it once.
            Err(nix::Error::EAGAIN | nix::Error::EINTR | nix::Error::ENETDOWN) => {
                Ok(Received::Nothing)
            }
            Err(e) => Err(format!("interface {:?}: receive: {e}", self.interface)),
        }
    }

    /// Sends `frame` out of the interface.
    ///
    /// # Real-time
    /// One `send`; no allocation but the error's text.
    pub fn send(&self, frame: &[u8]) -> Result<(), String> {
        send(self.fd.as_raw_fd(), frame, MsgFlags::empty())
            .map(|_| ())
            .map_err(|e| format!("interface {:?}: send: {e}", self.interface))
    }
}
