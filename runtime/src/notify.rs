//! Readiness, told as systemd's notification protocol (`sd_notify(3)`): a process started with
//! `NOTIFY_SOCKET` in its environment sends the datagram `READY=1` to that Unix socket once it
//! does what it is for (the emulator answers frames, a follower is subscribed). A unit of
//! `Type=notify`, a script or a test waits for that instead of reading words in a log.
//! Without `NOTIFY_SOCKET` nothing is sent.

use std::os::unix::net::UnixDatagram;

/// Says `READY=1` on `NOTIFY_SOCKET`, if the environment names one (a path, or `@name` for
/// an abstract socket). Returns why it could not, for the caller to log; `Ok` when there is
/// nobody to tell. Not for a real-time cycle (a system call).
pub fn ready() -> Result<(), String> {
    match std::env::var_os("NOTIFY_SOCKET") {
        Some(to) => ready_on(&to),
        None => Ok(()),
    }
}

/// Says `READY=1` on the socket `to` names (a path, or `@name`); an error names it.
pub fn ready_on(to: &std::ffi::OsStr) -> Result<(), String> {
    let socket = UnixDatagram::unbound().map_err(|e| format!("NOTIFY_SOCKET: {e}"))?;
    let sent = match to.to_str().and_then(|t| t.strip_prefix('@')) {
        Some(name) => {
            use std::os::linux::net::SocketAddrExt;
            std::os::unix::net::SocketAddr::from_abstract_name(name)
                .and_then(|a| socket.send_to_addr(b"READY=1", &a))
        }
        None => socket.send_to(b"READY=1", to),
    };
    sent.map(drop)
        .map_err(|e| format!("NOTIFY_SOCKET {}: {e}", to.to_string_lossy()))
}
