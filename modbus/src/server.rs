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
use std::sync::mpsc::Sender;
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
    /// A client asked for this.
    Act(Action, SocketAddr),
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
pub fn spawn(settings: Settings, regs: Shared, tx: Sender<Msg>) -> io::Result<()> {
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()?;
    std::thread::Builder::new()
        .name("modbus-tcp".into())
        .spawn(move || rt.block_on(serve_forever(settings, regs, tx)))?;
    Ok(())
}

async fn serve_forever(settings: Settings, regs: Shared, tx: Sender<Msg>) {
    let mut told: Option<String> = None;
    loop {
        let why = match TcpListener::bind(settings.listen).await {
            Ok(listener) => {
                if let Ok(a) = listener.local_addr() {
                    let _ = tx.send(Msg::Listening(a));
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
            let _ = tx.send(Msg::ListenFailed(why.clone()));
            told = Some(why);
        }
        tokio::time::sleep(Duration::from_secs(1)).await;
    }
}

async fn serve(
    listener: TcpListener,
    settings: Settings,
    regs: &Shared,
    tx: &Sender<Msg>,
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
    tx: Sender<Msg>,
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
        let result = answer(&req.request, &regs, self.writes).map(|(response, actions)| {
            for a in actions {
                let _ = self.tx.send(Msg::Act(a, self.peer));
            }
            response
        });
        std::future::ready(result)
    }
}

/// A stream that fails with `TimedOut` once nothing was read (and nothing could be written)
/// for its timeout: an idle or stuck client gives its connection back.
struct Idle {
    inner: TcpStream,
    timeout: Duration,
    deadline: Pin<Box<Sleep>>,
}

impl Idle {
    fn new(inner: TcpStream, timeout: Duration) -> Self {
        let _ = inner.set_nodelay(true);
        Self {
            inner,
            timeout,
            deadline: Box::pin(tokio::time::sleep(timeout)),
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
        match Pin::new(&mut this.inner).poll_read(cx, buf) {
            Poll::Ready(r) => {
                let next = Instant::now() + this.timeout;
                this.deadline.as_mut().reset(next);
                Poll::Ready(r)
            }
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
