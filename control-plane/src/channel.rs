//! The control channel of a running cell: `supervisor up` (and `run`) serve it; `status`,
//! `exec`, `pause`, `resume`, `abort`, `reset`, `start`, `restart`, `swap` and `down` are its
//! clients.
//!
//! - **Transport**: a Unix stream socket in the abstract namespace, `@rtcell/<instance>`.
//!   It is local only (no file, no network), and binding it is the instance's lock: the kernel
//!   gives the name to one process and takes it back when that process dies, however it dies.
//!   So a second `up` of a running instance is refused at once (two starts within a
//!   millisecond included), and a supervisor killed with SIGKILL leaves no stale lock.
//! - **Who may talk**: the supervisor reads the peer's credentials (`SO_PEERCRED`) of every
//!   connection as it accepts it and serves only its own user and root; anyone else gets
//!   [`Reply::Refused`] written at once and the connection closed: nothing of theirs is kept,
//!   read or buffered.
//! - **Framing**: one request per connection: the client sends a frame (and may then shut its
//!   writing side), the server answers with one frame and closes. A frame is a little-endian
//!   `u32` length followed by that many bytes of a postcard-encoded [`Request`] (at most
//!   [`MAX_REQUEST`]) or [`Reply`] (at most [`MAX_FRAME`]). A request with anything after it,
//!   inside its frame or after it, is refused and nothing is done.
//! - **Bounds**: at most [`MAX_CONNECTIONS`] connections at once (more are refused "busy"), a
//!   request complete within [`REQUEST_TIMEOUT`] of connecting, at most [`MAX_BUFFERED`] bytes of
//!   requests held for all connections together (the rest waits in the kernel), at most 64
//!   connections accepted per tick (a flood never holds the loop). Whatever arrived with a
//!   request, in its frame or after it by the time it is complete, refuses it; bytes sent
//!   after the request was taken are not read. A client waits at most [`ANSWER_TIMEOUT`] for
//!   an answer, but for a program's end.
//!
//! The server never blocks: connections are non-blocking, read and written a piece per
//! supervisor tick; a client that does not read its answer only keeps its own connection open
//! (until it hangs up or the supervisor ends), it is never waited for.

use crate::{Refusal, Reply, Request};
use shm_schema::InstanceName;
use std::io::{ErrorKind, Read, Write};
use std::os::fd::{AsFd, BorrowedFd};
use std::os::linux::net::SocketAddrExt;
use std::os::unix::net::{SocketAddr, UnixListener, UnixStream};
use std::time::{Duration, Instant};

/// Largest answer a client accepts (a report with its trace and figures).
pub const MAX_FRAME: usize = 64 << 20;

/// Largest request the server accepts: a program's source
/// ([`motion_program::MAX_SOURCE_BYTES`]) with its name and room to spare.
pub const MAX_REQUEST: usize = motion_program::MAX_SOURCE_BYTES + (64 << 10);

/// Most connections served at once (a client's `exec --wait` holds one for the program's
/// length; observers hold none).
pub const MAX_CONNECTIONS: usize = 32;

/// Most bytes of incomplete requests held for all connections together.
pub const MAX_BUFFERED: usize = 2 * MAX_REQUEST;

/// A connection's request must be complete this long after it connected.
pub const REQUEST_TIMEOUT: Duration = Duration::from_secs(10);

/// How long a client waits for an answer (all but `exec --wait`).
pub const ANSWER_TIMEOUT: Duration = Duration::from_secs(60);

/// Most connections accepted in one poll: a flood of them never holds the loop.
const ACCEPTS_PER_POLL: usize = 64;

/// After accepting failed (no descriptor left), how long the listener rests.
const ACCEPT_PAUSE: Duration = Duration::from_millis(100);

/// Why a client could not get an answer. The supervisor's own refusals and failures are
/// answers ([`Reply::Refused`], [`Reply::Failed`]), not errors.
#[derive(Debug)]
pub enum CallError {
    /// No supervisor serves the instance.
    NotUp(InstanceName),
    /// The request is longer than the channel takes ([`MAX_REQUEST`]): it was not sent.
    TooLong {
        /// Its encoded length.
        bytes: usize,
    },
    /// Connecting failed for another reason than nobody listening.
    Connect {
        /// The instance asked.
        instance: InstanceName,
        /// Why.
        source: std::io::Error,
    },
    /// The connection broke before the answer was complete (the supervisor went away).
    Broke {
        /// The instance asked.
        instance: InstanceName,
        /// Why.
        source: std::io::Error,
    },
    /// The supervisor took the request and did not answer in time ([`ANSWER_TIMEOUT`], or
    /// the caller's patience).
    NoAnswer {
        /// The instance asked.
        instance: InstanceName,
        /// How long the client waited.
        waited: Duration,
    },
    /// The answer could not be decoded (a supervisor of another version?).
    Garbled(postcard::Error),
}

impl std::fmt::Display for CallError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::NotUp(i) => write!(
                f,
                "instance {i} is not up (no supervisor serves it; start it with `supervisor up --instance {i}`)"
            ),
            Self::TooLong { bytes } => write!(
                f,
                "the request is {bytes} bytes: at most {MAX_REQUEST} are accepted (a program's \
                 source is at most {} bytes)",
                motion_program::MAX_SOURCE_BYTES
            ),
            Self::Connect { instance, source } => write!(f, "instance {instance}: {source}"),
            Self::Broke { instance, source } => write!(
                f,
                "instance {instance}: the supervisor's control channel broke: {source}"
            ),
            Self::NoAnswer { instance, waited } => write!(
                f,
                "instance {instance}: the supervisor took the request but did not answer within \
                 {:.1} s (is it stuck? its log says where)",
                waited.as_secs_f64()
            ),
            Self::Garbled(e) => write!(
                f,
                "a garbled answer ({e}): a supervisor of another version?"
            ),
        }
    }
}

impl CallError {
    /// The CLI's exit status for it: 2 when the request cannot have been taken (no
    /// supervisor, too long, no connection), 1 when it may have been (the supervisor broke off
    /// or did not answer: it may have started and failed).
    pub fn exit_code(&self) -> u8 {
        match self {
            Self::NotUp(_) | Self::TooLong { .. } | Self::Connect { .. } => 2,
            Self::Broke { .. } | Self::NoAnswer { .. } | Self::Garbled(_) => 1,
        }
    }
}

impl std::error::Error for CallError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            Self::Connect { source, .. } | Self::Broke { source, .. } => Some(source),
            Self::Garbled(e) => Some(e),
            _ => None,
        }
    }
}

fn address(instance: &InstanceName) -> std::io::Result<SocketAddr> {
    SocketAddr::from_abstract_name(format!("rtcell/{instance}").as_bytes())
}

fn frame(bytes: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(bytes.len() + 4);
    out.extend_from_slice(&(bytes.len() as u32).to_le_bytes());
    out.extend_from_slice(bytes);
    out
}

/// Sends `req` to the cell of `instance` and waits for its answer (as long as it takes:
/// `exec --wait` answers when the program ends).
pub fn call(instance: &InstanceName, req: &Request) -> Result<Reply, CallError> {
    // Every answer comes within a tick or a bounded wait (a start, a swap, a reset), except
    // a program's: its validation (seconds per hour of motion, longer on a slow host) and,
    // with `--wait`, its end. A supervisor that does not answer is named, not waited for
    // forever.
    let waits_for_program = matches!(req, Request::Exec { .. });
    call_within(
        instance,
        req,
        (!waits_for_program).then_some(ANSWER_TIMEOUT),
    )
}

/// [`call`], waiting at most `patience` for the answer (`None`: as long as it takes); then
/// [`CallError::NoAnswer`].
pub fn call_within(
    instance: &InstanceName,
    req: &Request,
    patience: Option<Duration>,
) -> Result<Reply, CallError> {
    let connect = |source| CallError::Connect {
        instance: *instance,
        source,
    };
    let addr = address(instance).map_err(connect)?;
    let mut s = match UnixStream::connect_addr(&addr) {
        Ok(s) => s,
        Err(e) if e.kind() == ErrorKind::ConnectionRefused => {
            return Err(CallError::NotUp(*instance));
        }
        Err(e) => return Err(connect(e)),
    };
    // Requests are plain data: encoding them cannot fail but for want of memory.
    let bytes = postcard::to_allocvec(req).map_err(CallError::Garbled)?;
    if bytes.len() > MAX_REQUEST {
        return Err(CallError::TooLong { bytes: bytes.len() });
    }
    // A refusal (another user) may be written and the connection closed before the request
    // is even read: read the answer whatever the write did.
    if patience.is_some() {
        let _ = s.set_read_timeout(patience);
    }
    let wrote = s
        .write_all(&frame(&bytes))
        .and_then(|()| s.shutdown(std::net::Shutdown::Write));
    match read_frame(&mut s) {
        Ok(body) => postcard::from_bytes(&body).map_err(CallError::Garbled),
        Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => {
            Err(CallError::NoAnswer {
                instance: *instance,
                waited: patience.unwrap_or_default(),
            })
        }
        Err(e) => Err(CallError::Broke {
            instance: *instance,
            source: wrote.err().unwrap_or(e),
        }),
    }
}

fn read_frame(s: &mut UnixStream) -> std::io::Result<Vec<u8>> {
    let mut len = [0u8; 4];
    s.read_exact(&mut len)?;
    let len = u32::from_le_bytes(len) as usize;
    if len > MAX_FRAME {
        return Err(std::io::Error::other(format!(
            "an answer of {len} bytes is too long"
        )));
    }
    let mut body = vec![0u8; len];
    s.read_exact(&mut body)?;
    Ok(body)
}

/// True when a supervisor serves `instance`.
pub fn is_up(instance: &InstanceName) -> bool {
    address(instance).is_ok_and(|a| UnixStream::connect_addr(&a).is_ok())
}

/// A connection being served; see the module documentation.
#[derive(Debug)]
struct Conn {
    id: u64,
    stream: UnixStream,
    /// When it was accepted: a request must be complete within [`REQUEST_TIMEOUT`].
    opened: Instant,
    input: Vec<u8>,
    /// The client half-closed (or closed) its side: nothing more will arrive.
    eof: bool,
    output: Vec<u8>,
    written: usize,
    /// A request was taken from it (so no second one is read).
    asked: bool,
    /// Nothing to answer (it left without a word): closed at the next flush.
    silent: bool,
}

/// The serving side: the instance's lock and its connections.
#[derive(Debug)]
pub struct Server {
    listener: UnixListener,
    conns: Vec<Conn>,
    next_id: u64,
    uid: u32,
    /// Accepting failed for want of descriptors: the listener is left out of the wait until
    /// then (else a pending connection would wake the loop at once, again and again).
    accept_paused_until: Option<Instant>,
    /// Connections refused since the last log line about them, and when that was.
    refused: (u64, Option<Instant>),
}

/// A connection's handle, to answer it later.
pub type ConnId = u64;

/// Why the server closes a connection without taking a request from it.
fn refuse_now(stream: &UnixStream, reply: &Reply) {
    // One non-blocking write of a small frame: the client reads it (it stays in the client's
    // queue after the close), or it went away; either way nothing is kept here.
    if let Ok(bytes) = postcard::to_allocvec(reply) {
        use nix::sys::socket::{MsgFlags, send};
        use std::os::fd::AsRawFd;
        let _ = send(
            stream.as_raw_fd(),
            &frame(&bytes),
            MsgFlags::MSG_DONTWAIT | MsgFlags::MSG_NOSIGNAL,
        );
    }
}

impl Server {
    /// Takes the instance's name: fails with `AddrInUse` when another supervisor serves it.
    pub fn bind(instance: &InstanceName) -> std::io::Result<Self> {
        let listener = UnixListener::bind_addr(&address(instance)?)?;
        listener.set_nonblocking(true)?;
        Ok(Self {
            listener,
            conns: Vec::new(),
            next_id: 1,
            uid: nix::unistd::geteuid().as_raw(),
            accept_paused_until: None,
            refused: (0, None),
        })
    }

    /// The descriptors to wait on: the listener (unless accepting is paused) and every
    /// connection whose request is still arriving.
    pub fn fds(&self) -> Vec<BorrowedFd<'_>> {
        let paused = self.accept_paused_until.is_some_and(|t| Instant::now() < t);
        let mut v = Vec::new();
        if !paused {
            v.push(self.listener.as_fd());
        }
        // Requests wait in the kernel while the budget is spent: not woken for them.
        if self.buffered() < MAX_BUFFERED {
            v.extend(
                self.conns
                    .iter()
                    .filter(|c| !c.asked && !c.eof)
                    .map(|c| c.stream.as_fd()),
            );
        }
        v
    }

    /// Accepts new connections, reads what arrived, writes what is pending; returns the
    /// requests that are complete. A connection from another user is answered
    /// [`Reply::Refused`] and closed as it is accepted (nothing of it is kept or read); a
    /// connection beyond [`MAX_CONNECTIONS`], a garbled, oversized or late request likewise.
    pub fn poll(&mut self) -> Vec<(ConnId, Request)> {
        self.accept();
        let mut out = Vec::new();
        let mut budget = MAX_BUFFERED.saturating_sub(self.buffered());
        for c in &mut self.conns {
            if c.asked {
                continue;
            }
            match c.read_request(&mut budget) {
                Ok(Some(r)) => {
                    c.asked = true;
                    out.push((c.id, r));
                }
                Ok(None) if c.eof && c.input.is_empty() => {
                    // Connected and left without a word (`is_up`): nothing to answer.
                    c.asked = true;
                    c.silent = true;
                }
                Ok(None) if c.eof => {
                    c.asked = true;
                    c.set_reply(&Reply::Refused(Refusal::Incomplete {
                        bytes: c.input.len(),
                    }));
                }
                Ok(None) if c.opened.elapsed() > REQUEST_TIMEOUT => {
                    c.asked = true;
                    c.set_reply(&Reply::Refused(Refusal::Slow {
                        seconds: REQUEST_TIMEOUT.as_secs(),
                    }));
                }
                Ok(None) => {}
                Err(refusal) => {
                    c.asked = true;
                    c.set_reply(&Reply::Refused(refusal));
                }
            }
            if c.asked {
                c.input = Vec::new();
            }
        }
        self.flush();
        out
    }

    /// Bytes of requests held, all connections together.
    fn buffered(&self) -> usize {
        self.conns.iter().map(|c| c.input.len()).sum()
    }

    fn accept(&mut self) {
        if self.accept_paused_until.is_some_and(|t| Instant::now() < t) {
            return;
        }
        self.accept_paused_until = None;
        for _ in 0..ACCEPTS_PER_POLL {
            let stream = match self.listener.accept() {
                Ok((stream, _)) => stream,
                Err(e) if e.kind() == ErrorKind::WouldBlock => return,
                Err(e) => {
                    // EMFILE, ENFILE, ENOBUFS: the connection waits in the backlog; try
                    // again after a while instead of spinning on a readable listener.
                    tracing::warn!("control: cannot accept a connection: {e}");
                    self.accept_paused_until = Some(Instant::now() + ACCEPT_PAUSE);
                    return;
                }
            };
            let peer =
                nix::sys::socket::getsockopt(&stream, nix::sys::socket::sockopt::PeerCredentials);
            let refusal = match peer {
                Ok(c) if c.uid() == self.uid || c.uid() == 0 => None,
                Ok(c) => Some((
                    format!("uid {} (pid {})", c.uid(), c.pid()),
                    Refusal::ForeignUser {
                        owner: self.uid,
                        uid: c.uid(),
                    },
                )),
                Err(e) => Some((
                    "an unknown peer".into(),
                    Refusal::UnknownPeer {
                        error: e.to_string(),
                    },
                )),
            };
            let refusal = refusal.or_else(|| {
                (self.conns.len() >= MAX_CONNECTIONS).then(|| {
                    (
                        "a client over the limit".into(),
                        Refusal::Connections {
                            limit: MAX_CONNECTIONS,
                        },
                    )
                })
            });
            if let Some((who, why)) = refusal {
                refuse_now(&stream, &Reply::Refused(why));
                self.note_refusal(&who);
                continue;
            }
            if stream.set_nonblocking(true).is_err() {
                continue;
            }
            let id = self.next_id;
            self.next_id += 1;
            self.conns.push(Conn {
                id,
                stream,
                opened: Instant::now(),
                input: Vec::new(),
                eof: false,
                output: Vec::new(),
                written: 0,
                asked: false,
                silent: false,
            });
        }
    }

    /// Logs refused connections: the first at once, then a count at most once a second (a
    /// flood of them must not flood the log).
    fn note_refusal(&mut self, who: &str) {
        self.refused.0 += 1;
        let due = self
            .refused
            .1
            .is_none_or(|t| t.elapsed() >= Duration::from_secs(1));
        if due {
            tracing::warn!(
                "control: refused {} connection(s), the last from {who}",
                self.refused.0
            );
            self.refused = (0, Some(Instant::now()));
        }
    }

    /// Answers connection `id` (dropped silently if the client went away).
    pub fn reply(&mut self, id: ConnId, reply: &Reply) {
        if let Some(c) = self.conns.iter_mut().find(|c| c.id == id) {
            c.set_reply(reply);
        }
        self.flush();
    }

    /// Writes what is pending; drops finished, closed and stuck connections.
    fn flush(&mut self) {
        self.conns.retain_mut(|c| c.pump());
    }

    /// Writes the pending answers for up to `patience` (on the way down).
    pub fn drain(&mut self, patience: Duration) {
        let start = Instant::now();
        while self.conns.iter().any(|c| !c.output.is_empty()) && start.elapsed() < patience {
            self.flush();
            std::thread::sleep(Duration::from_millis(2));
        }
    }
}

impl Conn {
    fn set_reply(&mut self, r: &Reply) {
        let mut bytes = postcard::to_allocvec(r).unwrap_or_default();
        // A report too long for a frame (a very long trace) goes without its trace and
        // figures, saying so, rather than as an answer the client must refuse.
        if bytes.len() > MAX_FRAME
            && let Reply::Report { outcome, text, .. } = r
        {
            let text = format!(
                "{text}\n  the trace and figures asked for were left out: {} bytes, more than \
                 an answer may hold ({MAX_FRAME})",
                bytes.len()
            );
            let short = Reply::Report {
                outcome: outcome.clone(),
                text,
                trace_csv: None,
                figures: None,
            };
            bytes = postcard::to_allocvec(&short).unwrap_or_default();
        }
        self.output = frame(&bytes);
        self.written = 0;
    }

    /// Reads what is there (at most `budget` bytes, taken from it); a complete request once
    /// it has all arrived. Whatever follows the frame, inside it or after it, refuses it.
    fn read_request(&mut self, budget: &mut usize) -> Result<Option<Request>, Refusal> {
        let mut buf = [0u8; 16 * 1024];
        while !self.eof && *budget > 0 {
            let want = buf.len().min(*budget);
            match self.stream.read(&mut buf[..want]) {
                Ok(0) => self.eof = true,
                Ok(n) => {
                    self.input.extend_from_slice(&buf[..n]);
                    *budget -= n;
                }
                Err(e) if e.kind() == ErrorKind::WouldBlock => break,
                Err(e) if e.kind() == ErrorKind::Interrupted => {}
                Err(e) => {
                    return Err(Refusal::Malformed {
                        error: format!("read: {e}"),
                    });
                }
            }
            if self.input.len() >= 4 {
                let len = frame_len(&self.input);
                if len > MAX_REQUEST {
                    return Err(Refusal::TooLong {
                        bytes: len,
                        limit: MAX_REQUEST,
                    });
                }
                if self.input.len() > 4 + len {
                    return Err(Refusal::AfterFrame {
                        bytes: self.input.len() - 4 - len,
                    });
                }
            }
        }
        if self.input.len() < 4 || self.input.len() < 4 + frame_len(&self.input) {
            return Ok(None);
        }
        match postcard::take_from_bytes::<Request>(&self.input[4..]) {
            Ok((r, [])) => Ok(Some(r)),
            Ok((_, rest)) => Err(Refusal::AfterRequest { bytes: rest.len() }),
            Err(e) => Err(Refusal::Malformed {
                error: format!("a garbled request ({e}): not a supervisor of this version?"),
            }),
        }
    }

    /// Writes what it can; false once the connection is finished or broken.
    fn pump(&mut self) -> bool {
        while self.written < self.output.len() {
            match self.stream.write(&self.output[self.written..]) {
                Ok(0) => return false,
                Ok(n) => self.written += n,
                Err(e) if e.kind() == ErrorKind::WouldBlock => return true,
                Err(e) if e.kind() == ErrorKind::Interrupted => {}
                Err(_) => return false,
            }
        }
        if !self.output.is_empty() {
            return false; // answered: close
        }
        if self.silent {
            return false;
        }
        // Waiting for its request or its answer: a client that closed its socket is gone.
        // One that only half-closed it (it sent its request and shut its writing side)
        // still reads its answer.
        !self.peer_closed()
    }

    /// The peer closed its socket entirely (`POLLHUP`; a half-close only raises `POLLRDHUP`).
    fn peer_closed(&self) -> bool {
        use nix::poll::{PollFd, PollFlags, PollTimeout, poll};
        let mut fds = [PollFd::new(self.stream.as_fd(), PollFlags::empty())];
        matches!(poll(&mut fds, PollTimeout::ZERO), Ok(n) if n > 0)
            && fds[0]
                .revents()
                .is_some_and(|r| r.intersects(PollFlags::POLLHUP | PollFlags::POLLERR))
    }
}

fn frame_len(input: &[u8]) -> usize {
    u32::from_le_bytes([input[0], input[1], input[2], input[3]]) as usize
}
