//! The TCP side: a tokio runtime on a thread of its own, tokio-modbus' server, at most
//! `max_connections` clients at once (one more is closed as soon as it is accepted), each
//! closed after `idle_timeout` without a request (or without reading its answers), and the
//! address taken again every second while it is in use elsewhere.
//!
//! It answers from the newest [`Registers`] the cycle published and hands writes to the cycle
//! as [`Msg::Act`]; it never touches shared memory itself. Each request frame is held back
//! until it is whole and judged ([`judge`]): a malformed one ends its connection, a function
//! tokio-modbus' codec must not see (128 and above, 23, 43) is answered here with exception 1,
//! and the rest goes on to tokio-modbus.

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

/// Bytes of the MBAP header (transaction, protocol, length, unit).
const MBAP: usize = 7;
/// Largest PDU of a request (Modbus application protocol §4.1).
const MAX_PDU: usize = 253;
/// The exception code of a function this server does not serve.
const ILLEGAL_FUNCTION: u8 = 0x01;
/// Bytes of this server's own answers a client may leave unread before its connection ends.
const MAX_UNWRITTEN: usize = 4096;

/// What becomes of a whole request frame ([`judge`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Verdict {
    /// tokio-modbus decodes it and [`answer`] answers it.
    Serve,
    /// A function tokio-modbus' decoder must not see, and this server does not serve: answered
    /// here with exception 1 (Illegal function), the connection kept.
    Unserved,
}

/// The length of the frame at the start of `bytes` once its MBAP header is there (checked), or
/// `None` before.
fn frame_len(bytes: &[u8]) -> Result<Option<usize>, &'static str> {
    if bytes.len() < MBAP {
        return Ok(None);
    }
    if bytes[2] != 0 || bytes[3] != 0 {
        return Err("protocol id is not 0");
    }
    let len = usize::from(u16::from_be_bytes([bytes[4], bytes[5]]));
    if len < 2 || len - 1 > MAX_PDU {
        return Err("length beyond a Modbus frame");
    }
    Ok(Some(MBAP - 1 + len))
}

/// Judges a whole request frame before tokio-modbus decodes it: its decoder trusts a frame's
/// byte count (a write of 16 coils with one data byte panics it, and a panic aborts the
/// process; slowtec/tokio-modbus#298), and it fails the connection on a function code of 128
/// or more, on function 23 (whose counts it trusts as well) and on function 43 with a MEI type
/// other than 14. Those functions this server does not serve: they are answered with
/// exception 1, as the Modbus application protocol asks (§7), and the connection goes on. A
/// frame that is not a well-formed Modbus TCP request ends the connection.
fn judge(frame: &[u8]) -> Result<Verdict, &'static str> {
    let p = &frame[MBAP..];
    let word = |i: usize| usize::from(u16::from_be_bytes([p[i], p[i + 1]]));
    match p[0] {
        // Write multiple coils / registers: a quantity, a byte count, the data.
        0x0F | 0x10 if p.len() >= 6 => {
            let q = word(3);
            let count = usize::from(p[5]);
            let want = if p[0] == 0x0F { q.div_ceil(8) } else { 2 * q };
            if q == 0 || count != want || p.len() != 6 + count {
                return Err("byte count does not match the quantity");
            }
            Ok(Verdict::Serve)
        }
        0x0F | 0x10 => Err("write request too short"),
        0x17 | 0x2B | 0x80.. => Ok(Verdict::Unserved),
        _ => Ok(Verdict::Serve),
    }
}

/// The exception-1 answer to `frame`: its transaction and unit, its function code with the
/// exception bit.
fn illegal_function(frame: &[u8]) -> [u8; MBAP + 2] {
    let mut a = [0u8; MBAP + 2];
    a[..2].copy_from_slice(&frame[..2]);
    a[4..6].copy_from_slice(&3u16.to_be_bytes());
    a[6] = frame[6];
    a[7] = frame[MBAP] | 0x80;
    a[8] = ILLEGAL_FUNCTION;
    a
}

/// Request bytes held back until their frame is whole and judged ([`judge`]): the served
/// frames go on to tokio-modbus, the unserved ones are answered here.
#[derive(Debug, Default)]
struct Frames {
    /// Bytes read from the client and not yet handed on.
    held: Vec<u8>,
    /// The first bytes of `held` that belong to frames judged `Serve`.
    ready: usize,
    /// Answers of this server's own (exceptions) not yet written.
    answers: Vec<u8>,
}

impl Frames {
    /// Takes `bytes` from the client; how many frames they completed, or why they are not
    /// Modbus.
    fn feed(&mut self, bytes: &[u8]) -> Result<usize, &'static str> {
        self.held.extend_from_slice(bytes);
        let mut frames = 0;
        while let Some(len) = frame_len(&self.held[self.ready..])? {
            let at = self.ready;
            if self.held.len() < at + len {
                break;
            }
            frames += 1;
            match judge(&self.held[at..at + len])? {
                Verdict::Serve => self.ready += len,
                Verdict::Unserved => {
                    let answer = illegal_function(&self.held[at..at + len]);
                    self.answers.extend_from_slice(&answer);
                    self.held.drain(at..at + len);
                    if self.answers.len() > MAX_UNWRITTEN {
                        return Err("the client does not read its answers");
                    }
                }
            }
        }
        Ok(frames)
    }

    /// Hands the served bytes on into `buf`, as many as fit; how many.
    fn take(&mut self, buf: &mut ReadBuf<'_>) -> usize {
        let n = self.ready.min(buf.remaining());
        buf.put_slice(&self.held[..n]);
        self.held.drain(..n);
        self.ready -= n;
        n
    }
}

/// A stream that checks the frames ([`Frames`]), answers those tokio-modbus must not see, and
/// fails with `TimedOut` once no whole request arrived (and nothing could be written) for its
/// timeout: an idle, slow or stuck client gives its connection back.
struct Idle {
    inner: TcpStream,
    timeout: Duration,
    deadline: Pin<Box<Sleep>>,
    frames: Frames,
}

impl Idle {
    fn new(inner: TcpStream, timeout: Duration) -> Self {
        let _ = inner.set_nodelay(true);
        Self {
            inner,
            timeout,
            deadline: Box::pin(tokio::time::sleep(timeout)),
            frames: Frames::default(),
        }
    }

    fn expired(&mut self, cx: &mut Context<'_>) -> Poll<io::Error> {
        self.deadline
            .as_mut()
            .poll(cx)
            .map(|()| io::Error::new(io::ErrorKind::TimedOut, "idle for too long"))
    }

    /// Writes this server's own answers as far as the socket takes them.
    fn write_answers(&mut self, cx: &mut Context<'_>) -> io::Result<()> {
        while !self.frames.answers.is_empty() {
            match Pin::new(&mut self.inner).poll_write(cx, &self.frames.answers) {
                Poll::Ready(Ok(0)) => return Err(io::ErrorKind::WriteZero.into()),
                Poll::Ready(Ok(n)) => {
                    self.frames.answers.drain(..n);
                }
                Poll::Ready(Err(e)) => return Err(e),
                Poll::Pending => break,
            }
        }
        Ok(())
    }
}

impl AsyncRead for Idle {
    fn poll_read(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<io::Result<()>> {
        let this = &mut *self;
        if buf.remaining() == 0 {
            return Poll::Ready(Ok(()));
        }
        loop {
            this.write_answers(cx)?;
            if this.frames.take(buf) > 0 {
                return Poll::Ready(Ok(()));
            }
            let mut bytes = [0u8; 512];
            let mut read = ReadBuf::new(&mut bytes);
            match Pin::new(&mut this.inner).poll_read(cx, &mut read) {
                // The end of the stream (with a frame not yet whole: it never will be).
                Poll::Ready(Ok(())) if read.filled().is_empty() => return Poll::Ready(Ok(())),
                Poll::Ready(Ok(())) => match this.frames.feed(read.filled()) {
                    // Bytes of a frame not yet whole: the deadline runs on (a client that
                    // dribbles a frame slower than the timeout is idle too).
                    Ok(0) => {
                        if let Poll::Ready(e) = this.expired(cx) {
                            return Poll::Ready(Err(e));
                        }
                    }
                    Ok(_) => {
                        let next = Instant::now() + this.timeout;
                        this.deadline.as_mut().reset(next);
                    }
                    Err(why) => {
                        return Poll::Ready(Err(io::Error::new(io::ErrorKind::InvalidData, why)));
                    }
                },
                Poll::Ready(Err(e)) => return Poll::Ready(Err(e)),
                Poll::Pending => return this.expired(cx).map(Err),
            }
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
    use super::{Frames, illegal_function};

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
        let mut f = Frames::default();
        assert_eq!(f.feed(&two), Ok(3));
        assert_eq!(
            (f.ready, f.held.len()),
            (two.len(), two.len()),
            "all served"
        );
        let mut f = Frames::default();
        let total: usize = two.iter().map(|b| f.feed(&[*b]).expect("sound")).sum();
        assert_eq!(total, 3, "byte by byte");
        assert_eq!(f.held, two, "held back and handed on in order");
    }

    #[test]
    fn frames_the_decoder_would_trust_wrongly_are_refused() {
        let bad = |pdu: &[u8]| Frames::default().feed(&frame(pdu)).is_err();
        assert!(bad(&[0x0F, 0, 0, 0, 16, 1, 0xFF]), "16 coils, 1 byte");
        assert!(bad(&[0x10, 0, 0, 0, 2, 2, 0, 1]), "2 registers, 2 bytes");
        assert!(bad(&[0x10, 0, 0, 0, 0, 0]), "no register");
        assert!(bad(&[0x0F, 0, 0]), "short");
        let mut long = vec![0, 1, 0, 0, 0xFF, 0xFF, 1, 4];
        assert!(Frames::default().feed(&long).is_err(), "65535 bytes");
        long[2] = 7;
        assert!(Frames::default().feed(&long).is_err(), "protocol 7");
    }

    #[test]
    fn functions_the_decoder_must_not_see_are_answered_illegal_function_here() {
        // Function 23 (well formed), 43 with MEI 13 and 14, 0x85 and 0xFF: each answered with
        // its own transaction, unit and function code with the exception bit, exception 1;
        // the read between them is served, in its place.
        let mut bytes = Vec::new();
        let unserved: [&[u8]; 5] = [
            &[0x17, 0, 0, 0, 1, 0, 0, 0, 1, 2, 0, 0],
            &[0x2B, 0x0D, 0],
            &[0x2B, 0x0E, 9, 0],
            &[0x85, 0],
            &[0xFF],
        ];
        for (k, pdu) in unserved.iter().enumerate() {
            let mut f = frame(pdu);
            f[1] = k as u8;
            bytes.extend(f);
        }
        let read = frame(&[4, 0, 0, 0, 56]);
        bytes.extend(&read);
        let mut f = Frames::default();
        assert_eq!(f.feed(&bytes), Ok(6));
        assert_eq!(f.held, read, "only the read goes on");
        let mut want = Vec::new();
        for (k, pdu) in unserved.iter().enumerate() {
            want.extend([0, k as u8, 0, 0, 0, 3, 1, pdu[0] | 0x80, 1]);
        }
        assert_eq!(f.answers, want);
        assert_eq!(
            illegal_function(&frame(&[0x41, 1]))[7..],
            [0xC1, 1],
            "function 65"
        );
    }
}
