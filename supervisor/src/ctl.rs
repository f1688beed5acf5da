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
//!   connection and answers only its own user and root; anyone else gets [`Reply::Refused`].
//! - **Framing**: one request per connection: the client sends a frame, the server answers
//!   with one frame and closes. A frame is a little-endian `u32` length followed by that
//!   many bytes of a postcard-encoded [`Request`] or [`Reply`] (at most [`MAX_FRAME`]).
//!
//! The server never blocks: connections are non-blocking, read and written a piece per
//! supervisor tick; a client that does not read its answer only keeps its own connection open
//! (until it hangs up or the supervisor ends), it is never waited for.

use serde::{Deserialize, Serialize};
use shm_schema::InstanceName;
use std::io::{ErrorKind, Read, Write};
use std::os::fd::{AsFd, BorrowedFd};
use std::os::linux::net::SocketAddrExt;
use std::os::unix::net::{SocketAddr, UnixListener, UnixStream};

/// Largest frame either side accepts (a program's source, a report with its trace).
pub const MAX_FRAME: usize = 64 << 20;

/// What a client asks a running cell.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub enum Request {
    /// The cell's own view: processes (pid, state, restarts), the arm, the e-stop, the job.
    /// Answered with [`Reply::Json`] (the `supervisor` part of `status --json`).
    Info,
    /// Validate and run a program. `wait`: answer when it ends, with its report.
    Exec {
        /// The program's name as the user gave it (for messages and the report).
        name: String,
        /// Its source, the file's bytes (checked, with line and column, by the cell).
        source: Vec<u8>,
        /// Answer when the program ends (with [`Reply::Report`]), not when it starts.
        wait: bool,
        /// With `wait`: include the trace (CSV) in the report.
        trace: bool,
        /// With `wait`: include the figures (`--plot`) in the report.
        figures: bool,
    },
    /// Decelerate along the path to rest and hold.
    Pause,
    /// Go on along the path.
    Resume,
    /// Come to rest along the path and drop the rest of the program.
    Abort,
    /// The live speed override: the path at `percent` (1..=100) of its programmed speed.
    Speed {
        /// 1..=100.
        percent: f64,
    },
    /// Clear the e-stop and what can be cleared.
    Reset,
    /// Enable the drives, holding where they stand.
    Start,
    /// Stop a process of the table and start it again.
    Restart {
        /// Its name in the table.
        process: String,
    },
    /// Replace a process of the table by a new one (its command, or `command`).
    Swap {
        /// Its name in the table.
        process: String,
        /// The new command line; `None` runs the configured one again (a new build).
        command: Option<Vec<String>>,
    },
    /// Stop the cell.
    Down,
}

/// What the cell answers.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub enum Reply {
    /// Done; a line for the user.
    Done(String),
    /// Not done, nothing changed: bad input or a state that does not allow it (exit 2).
    Refused(String),
    /// Tried and failed (exit 1).
    Failed(String),
    /// A JSON document (`Info`).
    Json(String),
    /// A program's end: `ok`, the report as JSON (`run --json`'s document: the report, or
    /// `{"ok": false, "error": …, "events": …}`), as text, and its trace.
    Report {
        /// The program completed and settled.
        ok: bool,
        /// The report, JSON.
        json: String,
        /// The summary `run` prints (or the error).
        text: String,
        /// The trace as CSV (`run --trace`), when asked for and the program completed.
        trace_csv: Option<String>,
        /// What `--plot` draws, when asked for and the program completed.
        figures: Option<Box<crate::figures::Figures>>,
    },
}

/// Why a client could not get an answer.
#[derive(Debug)]
pub enum CtlError {
    /// No supervisor serves the instance.
    NotUp(InstanceName),
    /// The connection failed or broke (the supervisor went away mid-answer).
    Io(String),
}

impl std::fmt::Display for CtlError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            CtlError::NotUp(i) => write!(
                f,
                "instance {i} is not up (no supervisor serves it; start it with `supervisor up --instance {i}`)"
            ),
            CtlError::Io(e) => f.write_str(e),
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
pub fn call(instance: &InstanceName, req: &Request) -> Result<Reply, CtlError> {
    let addr = address(instance).map_err(|e| CtlError::Io(e.to_string()))?;
    let mut s = match UnixStream::connect_addr(&addr) {
        Ok(s) => s,
        Err(e) if e.kind() == ErrorKind::ConnectionRefused => {
            return Err(CtlError::NotUp(*instance));
        }
        Err(e) => return Err(CtlError::Io(format!("instance {instance}: {e}"))),
    };
    let bytes = postcard::to_allocvec(req).map_err(|e| CtlError::Io(e.to_string()))?;
    let broke = |e: std::io::Error| {
        CtlError::Io(format!(
            "instance {instance}: the supervisor's control channel broke: {e}"
        ))
    };
    // A refusal (another user) may be written and the connection closed before the request
    // is even read: read the answer whatever the write did.
    let wrote = s.write_all(&frame(&bytes));
    match read_frame(&mut s) {
        Ok(body) => {
            postcard::from_bytes(&body).map_err(|e| CtlError::Io(format!("a garbled answer: {e}")))
        }
        Err(e) => Err(broke(wrote.err().unwrap_or(e))),
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
    input: Vec<u8>,
    output: Vec<u8>,
    written: usize,
    /// A request was taken from it (so no second one is read).
    asked: bool,
    /// The answer to whatever it asks (another user: refused). Given once its request is
    /// read, so the connection closes with nothing unread and the client reads the answer.
    refusal: Option<Reply>,
}

/// The serving side: the instance's lock and its connections.
#[derive(Debug)]
pub struct Server {
    listener: UnixListener,
    conns: Vec<Conn>,
    next_id: u64,
    uid: u32,
}

/// A connection's handle, to answer it later.
pub type ConnId = u64;

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
        })
    }

    /// The descriptors to wait on (the listener and every connection with work pending).
    pub fn fds(&self) -> Vec<BorrowedFd<'_>> {
        let mut v = vec![self.listener.as_fd()];
        v.extend(
            self.conns
                .iter()
                .filter(|c| !c.asked)
                .map(|c| c.stream.as_fd()),
        );
        v
    }

    /// Accepts new connections, reads what arrived, writes what is pending; returns the
    /// requests that are complete. A connection from another user is answered
    /// [`Reply::Refused`] here and never reaches the caller; a garbled request likewise.
    pub fn poll(&mut self) -> Vec<(ConnId, Request)> {
        while let Ok((stream, _)) = self.listener.accept() {
            let _ = stream.set_nonblocking(true);
            let id = self.next_id;
            self.next_id += 1;
            let mut conn = Conn {
                id,
                stream,
                input: Vec::new(),
                output: Vec::new(),
                written: 0,
                asked: false,
                refusal: None,
            };
            let peer = nix::sys::socket::getsockopt(
                &conn.stream,
                nix::sys::socket::sockopt::PeerCredentials,
            );
            match peer {
                Ok(c) if c.uid() == self.uid || c.uid() == 0 => {}
                Ok(c) => {
                    tracing::warn!(
                        "control: refused a connection from uid {} (pid {})",
                        c.uid(),
                        c.pid()
                    );
                    conn.refusal = Some(Reply::Refused(format!(
                        "refused: this cell belongs to uid {}; uid {} may not control it",
                        self.uid,
                        c.uid()
                    )));
                }
                Err(e) => {
                    conn.refusal = Some(Reply::Refused(format!(
                        "refused: cannot read the peer's credentials: {e}"
                    )));
                }
            }
            self.conns.push(conn);
        }
        let mut out = Vec::new();
        for c in &mut self.conns {
            if !c.asked {
                match c.read_request() {
                    Ok(Some(_)) if c.refusal.is_some() => {
                        c.asked = true;
                        let r = c.refusal.take().expect("checked");
                        c.set_reply(&r);
                    }
                    Ok(Some(r)) => {
                        c.asked = true;
                        out.push((c.id, r));
                    }
                    Ok(None) => {}
                    Err(why) => {
                        c.asked = true;
                        c.set_reply(&Reply::Refused(why));
                    }
                }
            }
        }
        self.flush();
        out
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
    pub fn drain(&mut self, patience: std::time::Duration) {
        let start = std::time::Instant::now();
        while self.conns.iter().any(|c| !c.output.is_empty()) && start.elapsed() < patience {
            self.flush();
            std::thread::sleep(std::time::Duration::from_millis(2));
        }
    }
}

impl Conn {
    fn set_reply(&mut self, r: &Reply) {
        let mut bytes = postcard::to_allocvec(r).unwrap_or_default();
        // A report too long for a frame (a very long trace) goes without its trace and
        // figures, saying so, rather than as an answer the client must refuse.
        if bytes.len() > MAX_FRAME
            && let Reply::Report { ok, json, text, .. } = r
        {
            let text = format!(
                "{text}\n  the trace and figures asked for were left out: {} bytes, more than \
                 an answer may hold ({MAX_FRAME})",
                bytes.len()
            );
            let short = Reply::Report {
                ok: *ok,
                json: json.clone(),
                text,
                trace_csv: None,
                figures: None,
            };
            bytes = postcard::to_allocvec(&short).unwrap_or_default();
        }
        self.output = frame(&bytes);
        self.written = 0;
    }

    /// Reads what is there; a complete request once it has all arrived.
    fn read_request(&mut self) -> Result<Option<Request>, String> {
        let mut buf = [0u8; 16 * 1024];
        loop {
            match self.stream.read(&mut buf) {
                Ok(0) => break,
                Ok(n) => self.input.extend_from_slice(&buf[..n]),
                Err(e) if e.kind() == ErrorKind::WouldBlock => break,
                Err(e) => return Err(format!("read: {e}")),
            }
            if self.input.len() > MAX_FRAME + 4 {
                return Err(format!("a request longer than {MAX_FRAME} bytes"));
            }
        }
        if self.input.len() < 4 {
            return Ok(None);
        }
        let len = u32::from_le_bytes([self.input[0], self.input[1], self.input[2], self.input[3]])
            as usize;
        if len > MAX_FRAME {
            return Err(format!(
                "a request of {len} bytes is longer than {MAX_FRAME}"
            ));
        }
        if self.input.len() < 4 + len {
            return Ok(None);
        }
        postcard::from_bytes(&self.input[4..4 + len])
            .map(Some)
            .map_err(|e| format!("a garbled request ({e}): not a supervisor of this version?"))
    }

    /// Writes what it can; false once the connection is finished or broken.
    fn pump(&mut self) -> bool {
        while self.written < self.output.len() {
            match self.stream.write(&self.output[self.written..]) {
                Ok(0) => return false,
                Ok(n) => self.written += n,
                Err(e) if e.kind() == ErrorKind::WouldBlock => return true,
                Err(_) => return false,
            }
        }
        if !self.output.is_empty() {
            return false; // answered: close
        }
        // Waiting for a request or for its answer: a client that hung up is gone.
        let mut probe = [0u8; 1];
        use nix::sys::socket::{MsgFlags, recv};
        use std::os::fd::AsRawFd;
        !matches!(
            recv(
                self.stream.as_raw_fd(),
                &mut probe,
                MsgFlags::MSG_PEEK | MsgFlags::MSG_DONTWAIT
            ),
            Ok(0)
        )
    }
}
