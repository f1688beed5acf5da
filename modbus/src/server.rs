//! The TCP side: a tokio runtime on a thread of its own, tokio-modbus' server, at most
//! `max_connections` clients at once (one more is closed as soon as it is accepted), each
//! closed after `idle_timeout` without a request (or without reading its answers), and the
//! address taken again every second while it is in use elsewhere.
//!
//! It answers from the newest [`Registers`] the cycle published and hands writes to the cycle
//! as [`Msg::Act`]; it never touches shared memory itself. A malformed frame ends its
//! connection (tokio-modbus' codec refuses it), nothing else.

use crate::map::Registers;
use crate::{Action, answer};
use std::future::Future;
use std::io;
use std::net::SocketAddr;
use std::pin::Pin;
use std::sync::mpsc::SyncSender;
use std::sync::{Arc, Mutex};
use std::task::{Context, Poll};
use std::time::Duration;
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::{OwnedSemaphorePermit, Semaphore};
use tokio::time::{Instant, Sleep};
use tokio_modbus::server::tcp::Server;
use tokio_modbus::{ExceptionCode, Response, SlaveRequest};

/// What the server tells the process' cycle.
#[derive(Debug)]
pub enum Msg {
    /// It listens on this address.
    Listening(SocketAddr),
    /// It cannot listen (why); it tries again every second.
    ListenFailed(String),
    /// A client asked for these (one request's).
    Act(Vec<Action>, SocketAddr),
}

/// The newest registers, shared by the cycle (writer) and the connections (readers).
pub type Shared = Arc<Mutex<Arc<Registers>>>;

/// `[modbus]`, as the server uses it.
#[derive(Clone, Copy, Debug)]
pub struct Settings {
    /// Where to listen.
    pub listen: SocketAddr,
    /// Connections at once.
    pub max_connections: usize,
    /// A connection without a request this long is closed.
    pub idle_timeout: Duration,
    /// Writes taken.
    pub writes: bool,
}

/// Starts the server on a thread of its own; it runs until the process exits.
pub fn spawn(settings: Settings, regs: Shared, tx: SyncSender<Msg>) -> io::Result<()> {
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()?;
    std::thread::Builder::new()
        .name("modbus-tcp".into())
        .spawn(move || rt.block_on(serve_forever(settings, regs, tx)))?;
    Ok(())
}

async fn serve_forever(settings: Settings, regs: Shared, tx: SyncSender<Msg>) {
    let mut told: Option<String> = None;
    loop {
        let why = match TcpListener::bind(settings.listen).await {
            Ok(listener) => {
                if let Ok(a) = listener.local_addr() {
                    let _ = tx.try_send(Msg::Listening(a));
                }
                told = None;
                match serve(listener, settings, &regs, &tx).await {
                    Ok(()) => return,
                    Err(e) => format!("{}: {e}", settings.listen),
                }
            }
            Err(e) => format!("{}: {e}", settings.listen),
        };
        // Told once per cause, not every second.
        if told.as_deref() != Some(&why) {
            let _ = tx.try_send(Msg::ListenFailed(why.clone()));
            told = Some(why);
        }
        tokio::time::sleep(Duration::from_secs(1)).await;
    }
}

async fn serve(
    listener: TcpListener,
    settings: Settings,
    regs: &Shared,
    tx: &SyncSender<Msg>,
) -> io::Result<()> {
    let permits = Arc::new(Semaphore::new(settings.max_connections));
    let on_connected = |stream: TcpStream, peer: SocketAddr| {
        let conn = match permits.clone().try_acquire_owned() {
            Ok(permit) => Some(Connection {
                regs: regs.clone(),
                tx: tx.clone(),
                peer,
                writes: settings.writes,
                _permit: permit,
            }),
            Err(_) => {
                tracing::debug!(
                    "modbus: {peer} refused: {} connections already",
                    settings.max_connections
                );
                None // dropping the stream closes it
            }
        };
        let idle = settings.idle_timeout;
        async move { Ok(conn.map(|c| (c, Idle::new(stream, idle)))) }
    };
    Server::new(listener)
        .serve(&on_connected, |e| {
            tracing::debug!("modbus: a connection ended: {e}");
        })
        .await
}

/// One client's service.
struct Connection {
    regs: Shared,
    tx: SyncSender<Msg>,
    peer: SocketAddr,
    writes: bool,
    /// Released when the connection ends.
    _permit: OwnedSemaphorePermit,
}

impl tokio_modbus::server::Service for Connection {
    type Request = SlaveRequest<'static>;
    type Response = Response;
    type Exception = ExceptionCode;
    type Future = std::future::Ready<Result<Response, ExceptionCode>>;

    /// Any unit id is this server.
    fn call(&self, req: Self::Request) -> Self::Future {
        let regs = self
            .regs
            .lock()
            .map_or_else(|p| p.into_inner().clone(), |g| g.clone());
        let result = answer(&req.request, &regs, self.writes).and_then(|(response, actions)| {
            if actions.is_empty() {
                return Ok(response);
            }
            // A bounded queue: a client writing faster than the cycle takes writes is told
            // to wait (exception 6), and nothing of that write is taken.
            match self.tx.try_send(Msg::Act(actions, self.peer)) {
                Ok(()) => Ok(response),
                Err(_) => Err(ExceptionCode::ServerDeviceBusy),
            }
        });
        std::future::ready(result)
    }
}

/// Checks the request frames as their bytes arrive, before tokio-modbus decodes them: its
/// decoder trusts a frame's byte count (a write of 16 coils with one data byte panics it, and
/// a panic aborts the process; slowtec/tokio-modbus#298). A frame that is not a well-formed
/// Modbus TCP request ends the connection. It also tells where each frame ends, for the idle
/// timeout.
#[derive(Debug, Default)]
struct Inspector {
    /// The start of the current frame: the MBAP header and the PDU's first 6 bytes.
    head: [u8; 13],
    have: usize,
    /// Bytes of the current frame still to come after `head` (once its length is known).
    rest: usize,
}

/// Bytes of the MBAP header (transaction, protocol, length, unit).
const MBAP: usize = 7;
/// Largest PDU of a request (Modbus application protocol §4.1).
const MAX_PDU: usize = 253;

impl Inspector {
    /// Takes `bytes`; the number of frames they complete, or why they are not Modbus.
    fn feed(&mut self, mut bytes: &[u8]) -> Result<usize, &'static str> {
        let mut frames = 0;
        while !bytes.is_empty() {
            if self.rest > 0 {
                let n = self.rest.min(bytes.len());
                self.rest -= n;
                bytes = &bytes[n..];
                if self.rest == 0 {
                    self.have = 0;
                    frames += 1;
                }
                continue;
            }
            // Never more than this frame's head: the next frame's bytes are the next's.
            let need = if self.have < MBAP {
                MBAP
            } else {
                MBAP + self.pdu()?.min(6)
            };
            let n = (need - self.have).min(bytes.len());
            self.head[self.have..self.have + n].copy_from_slice(&bytes[..n]);
            self.have += n;
            bytes = &bytes[n..];
            if self.have < MBAP {
                continue;
            }
            let pdu = self.pdu()?;
            if self.have < MBAP + pdu.min(6) {
                continue;
            }
            let p = &self.head[MBAP..self.have];
            let word = |i: usize| usize::from(u16::from_be_bytes([p[i], p[i + 1]]));
            match p[0] {
                // Write multiple coils / registers: a quantity, a byte count, the data.
                0x0F | 0x10 if pdu >= 6 => {
                    let q = word(3);
                    let count = usize::from(p[5]);
                    let want = if p[0] == 0x0F { q.div_ceil(8) } else { 2 * q };
                    if q == 0 || count != want || pdu != 6 + count {
                        return Err("byte count does not match the quantity");
                    }
                }
                0x0F | 0x10 => return Err("write request too short"),
                // Read/write multiple registers: not served, and its decoder trusts counts too.
                0x17 => return Err("function 23 is not served"),
                _ => {}
            }
            // The frame is sound; the rest of it passes.
            self.rest = pdu - (self.have - MBAP);
            if self.rest == 0 {
                self.have = 0;
                frames += 1;
            }
        }
        Ok(frames)
    }

    /// The PDU's length from the header in view (checked).
    fn pdu(&self) -> Result<usize, &'static str> {
        let h = &self.head;
        if h[2] != 0 || h[3] != 0 {
            return Err("protocol id is not 0");
        }
        let len = usize::from(u16::from_be_bytes([h[4], h[5]]));
        if len < 2 || len - 1 > MAX_PDU {
            return Err("length beyond a Modbus frame");
        }
        Ok(len - 1)
    }
}

/// A stream that checks the frames ([`Inspector`]) and fails with `TimedOut` once no whole
/// request arrived (and nothing could be written) for its timeout: an idle, slow or stuck
/// client gives its connection back.
struct Idle {
    inner: TcpStream,
    timeout: Duration,
    deadline: Pin<Box<Sleep>>,
    inspector: Inspector,
}

impl Idle {
    fn new(inner: TcpStream, timeout: Duration) -> Self {
        let _ = inner.set_nodelay(true);
        Self {
            inner,
            timeout,
            deadline: Box::pin(tokio::time::sleep(timeout)),
            inspector: Inspector::default(),
        }
    }

    fn expired(&mut self, cx: &mut Context<'_>) -> Poll<io::Error> {
        self.deadline
            .as_mut()
            .poll(cx)
            .map(|()| io::Error::new(io::ErrorKind::TimedOut, "idle for too long"))
    }
}

impl AsyncRead for Idle {
    fn poll_read(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<io::Result<()>> {
        let this = &mut *self;
        let before = buf.filled().len();
        match Pin::new(&mut this.inner).poll_read(cx, buf) {
            Poll::Ready(Ok(())) => match this.inspector.feed(&buf.filled()[before..]) {
                // Bytes of a frame not yet whole: the deadline runs on (a client that
                // dribbles a frame slower than the timeout is idle too).
                Ok(0) if buf.filled().len() > before => match this.expired(cx) {
                    Poll::Ready(e) => Poll::Ready(Err(e)),
                    Poll::Pending => Poll::Ready(Ok(())),
                },
                Ok(_) => {
                    let next = Instant::now() + this.timeout;
                    this.deadline.as_mut().reset(next);
                    Poll::Ready(Ok(()))
                }
                Err(why) => Poll::Ready(Err(io::Error::new(io::ErrorKind::InvalidData, why))),
            },
            Poll::Ready(Err(e)) => Poll::Ready(Err(e)),
            Poll::Pending => this.expired(cx).map(Err),
        }
    }
}

impl AsyncWrite for Idle {
    fn poll_write(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<io::Result<usize>> {
        let this = &mut *self;
        match Pin::new(&mut this.inner).poll_write(cx, buf) {
            Poll::Pending => this.expired(cx).map(Err),
            r => r,
        }
    }

    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        let this = &mut *self;
        match Pin::new(&mut this.inner).poll_flush(cx) {
            Poll::Pending => this.expired(cx).map(Err),
            r => r,
        }
    }

    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.inner).poll_shutdown(cx)
    }
}

#[cfg(test)]
mod tests {
    use super::Inspector;

    fn frame(pdu: &[u8]) -> Vec<u8> {
        let mut f = vec![0, 1, 0, 0];
        f.extend((pdu.len() as u16 + 1).to_be_bytes());
        f.push(1);
        f.extend(pdu);
        f
    }

    #[test]
    fn sound_frames_pass_whole_or_in_pieces_and_are_counted() {
        let mut two = frame(&[4, 0, 0, 0, 56]);
        two.extend(frame(&[0x0F, 0, 0, 0, 10, 2, 0xFF, 0x03]));
        two.extend(frame(&[0x10, 0, 0, 0, 2, 4, 0, 1, 0, 50]));
        assert_eq!(Inspector::default().feed(&two), Ok(3));
        let mut i = Inspector::default();
        let total: usize = two.iter().map(|b| i.feed(&[*b]).expect("sound")).sum();
        assert_eq!(total, 3, "byte by byte");
    }

    #[test]
    fn frames_the_decoder_would_trust_wrongly_are_refused() {
        let bad = |pdu: &[u8]| Inspector::default().feed(&frame(pdu)).is_err();
        assert!(bad(&[0x0F, 0, 0, 0, 16, 1, 0xFF]), "16 coils, 1 byte");
        assert!(bad(&[0x10, 0, 0, 0, 2, 2, 0, 1]), "2 registers, 2 bytes");
        assert!(bad(&[0x10, 0, 0, 0, 0, 0]), "no register");
        assert!(bad(&[0x17, 0, 0, 0, 1, 0, 0, 0, 1, 2, 0, 0]), "function 23");
        assert!(bad(&[0x0F, 0, 0]), "short");
        let mut long = vec![0, 1, 0, 0, 0xFF, 0xFF, 1, 4];
        assert!(Inspector::default().feed(&long).is_err(), "65535 bytes");
        long[2] = 7;
        assert!(Inspector::default().feed(&long).is_err(), "protocol 7");
    }
}
