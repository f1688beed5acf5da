//! `supervisor web`: the cell in a browser (seed 004's view): a page that draws the machine
//! in 3D from its kinematics, moving live, with the program line, plots of following error and
//! wake-up latency, the process table, and e-stop / reset / start buttons (docs/web.md).
//!
//! An observer: a sampler thread attaches to the instance (and again after the cell goes down
//! and comes back up), reads the newest samples 30 times a second and turns them into one
//! JSON frame, broadcast to every WebSocket client. The page, its script and three.js are
//! compiled into the binary: nothing is fetched from the network. The buttons go through the
//! same paths as the CLI (`supervisor estop` straight on `<i>/estop`; `reset` and `start`
//! through the control channel).
//!
//! # Who may use it
//! Every request passes [`guard`] before anything is kept or done:
//! - **Local only by default** (`127.0.0.1:8080`): the `Host` header must name this machine's
//!   loopback (a DNS-rebinding page names its own host), and the connecting process must be
//!   the user who runs the view or root (read from the kernel's socket table, as the control
//!   channel reads `SO_PEERCRED`): another local user cannot use it to reach the cell.
//! - **Any other address needs `--token`**: every request carries it (`Authorization:
//!   Bearer`, `?token=`, or the `SameSite=Strict` cookie the page gets with it), the page and
//!   its scripts included.
//! - **Nothing changes the cell cross-site**: a `POST` needs the header `X-Rtc-Request: 1` (a
//!   page of another origin cannot send it without a CORS preflight, which is never granted),
//!   and a `POST` or a WebSocket upgrade whose `Origin` is not this server's is refused.

pub mod foxglove;

/// What a [`Feed`] answers with, and a [`View`]'s channel, for feeds of other crates.
pub use axum::http::StatusCode as HttpStatus;
pub use tokio::sync::broadcast;

use axum::Router;
use axum::extract::ws::{Message, WebSocket, WebSocketUpgrade};
use axum::extract::{ConnectInfo, Query, State};
use axum::http::{HeaderMap, HeaderValue, Method, StatusCode, header};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use control_plane::event::Axes;
use runtime::ipc::{self, Sub};
use serde_json::{Value, json};
use shm_schema::estop::HostStateV1;
use shm_schema::{
    CellConfigV6, InstanceName, LatencyHistogramV1, MAX_AXES, ProcessName, ProcessStatusV2,
    ServiceId, ServoStateV3, SetpointV2, str_of,
};
use std::net::SocketAddr;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// Frames per second sent to the page.
const RATE_HZ: u64 = 30;
/// No heartbeat this long: the cell is down (the sampler lets go and tries again).
const GONE: Duration = Duration::from_secs(2);

const INDEX: &str = include_str!("../web/index.html");
const APP: &str = include_str!("../web/app.js");
const THREE: &str = include_str!("../web/vendor/three.module.js");
const THREE_CORE: &str = include_str!("../web/vendor/three.core.js");
const ORBIT: &str = include_str!("../web/vendor/OrbitControls.js");

/// What `supervisor web` is asked to do.
#[derive(Clone, Debug)]
pub struct WebOptions {
    /// The instance to show.
    pub instance: InstanceName,
    /// Where to listen.
    pub listen: SocketAddr,
    /// Required of every client when set (`Authorization: Bearer …` or `?token=…`).
    pub token: Option<String>,
}

/// What a page shows: a view's messages, the cell's description (`hello`) and then its
/// frames.
#[derive(Clone, Debug)]
pub struct View {
    /// The frames, as they come (a slow page skips some).
    pub frames: broadcast::Sender<Arc<str>>,
    /// The cell's description (axes, kinematics, processes), for a page that connects.
    pub hello: Arc<Mutex<Option<Arc<str>>>>,
}

impl Default for View {
    fn default() -> Self {
        Self {
            frames: broadcast::channel(64).0,
            hello: Arc::new(Mutex::new(None)),
        }
    }
}

/// Where a page's view comes from, and what its buttons do: this host's instance
/// (`supervisor web`), or the cells of a line (`gateway line web`).
pub trait Feed: Send + Sync + 'static {
    /// The view a page asks for with `?cell=` (`None`: without it).
    fn view(&self, cell: Option<&str>) -> Result<View, String>;
    /// A button of a page (`estop`, `reset`, `start`) on its cell: the answer's words, or
    /// the HTTP status and why not.
    fn action(&self, what: &str, cell: Option<&str>) -> Result<String, (StatusCode, String)>;
}

/// The state the HTTP side shares.
#[derive(Clone)]
struct Shared {
    token: Option<String>,
    /// Where it listens (the connections' local end).
    addr: SocketAddr,
    /// The user it runs as.
    uid: u32,
    feed: Arc<dyn Feed>,
}

/// Why the web view did not start or stopped.
#[derive(Debug)]
pub enum WebError {
    /// `--listen` names an address other than loopback and no `--token` was given.
    TokenNeeded(SocketAddr),
    /// The same, for a server that only shows the cell (Foxglove live).
    TokenNeededToShow(SocketAddr),
    /// The token given is too short or holds characters a URL or a cookie cannot carry.
    BadToken(TokenError),
    /// The address cannot be listened on (in use, not this machine's).
    CannotListen(SocketAddr, std::io::Error),
    /// The server itself failed (its runtime, its thread, a socket).
    Server(std::io::Error),
}

impl WebError {
    /// Whether the user's input was wrong (nothing was started): the CLI exits 2, else 1.
    pub fn is_input(&self) -> bool {
        !matches!(self, Self::Server(_))
    }
}

impl std::fmt::Display for WebError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::TokenNeeded(a) => write!(
                f,
                "--listen {a} opens the cell's controls (e-stop, reset, start) to the network: give --token"
            ),
            Self::TokenNeededToShow(a) => write!(
                f,
                "--listen {a} shows the cell to the network: give --token"
            ),
            Self::BadToken(e) => e.fmt(f),
            Self::CannotListen(a, e) => write!(f, "web: cannot listen on {a}: {e}"),
            Self::Server(e) => write!(f, "web: {e}"),
        }
    }
}

impl std::error::Error for WebError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            Self::CannotListen(_, e) | Self::Server(e) => Some(e),
            Self::BadToken(e) => Some(e),
            Self::TokenNeeded(_) | Self::TokenNeededToShow(_) => None,
        }
    }
}

/// This host's instance, sampled by a thread of its own.
struct Local {
    instance: InstanceName,
    view: View,
}

impl Feed for Local {
    fn view(&self, cell: Option<&str>) -> Result<View, String> {
        match cell {
            None => Ok(self.view.clone()),
            Some(c) => Err(format!(
                "this view shows instance {} only, not cell {c:?} (`supervisor web --line`)",
                self.instance
            )),
        }
    }

    fn action(&self, what: &str, _cell: Option<&str>) -> Result<String, (StatusCode, String)> {
        use control_plane::{Reply, Request};
        let instance = self.instance;
        let req = match what {
            "estop" => {
                return cell_client::control::estop(
                    instance.as_str(),
                    "e-stop button of the web view",
                )
                .map_err(|e| (StatusCode::CONFLICT, e.to_string()));
            }
            "reset" => Request::Reset,
            "start" => Request::Start,
            other => return Err((StatusCode::NOT_FOUND, format!("no action {other:?}"))),
        };
        match control_plane::channel::call(&instance, &req) {
            Ok(Reply::Done(m)) => Ok(m),
            Ok(Reply::Refused(m)) => Err((StatusCode::CONFLICT, m.to_string())),
            Ok(Reply::Failed(failure)) => Err((StatusCode::CONFLICT, failure.to_string())),
            Ok(other) => Ok(format!("{other:?}")),
            Err(e) => Err((StatusCode::SERVICE_UNAVAILABLE, e.to_string())),
        }
    }
}

/// Serves the page until SIGINT or SIGTERM. `ready` gets the address it listens on.
pub fn web(opts: &WebOptions, ready: &mut dyn FnMut(SocketAddr)) -> Result<(), WebError> {
    let local = Arc::new(Local {
        instance: opts.instance,
        view: View::default(),
    });
    let stop = Arc::new(std::sync::atomic::AtomicBool::new(false));
    let sampler = {
        let (view, instance, stop) = (local.view.clone(), opts.instance, stop.clone());
        std::thread::Builder::new()
            .name("web-sampler".into())
            .spawn(move || sample(instance, &view, &stop))
            .map_err(WebError::Server)?
    };
    let result = serve_page(opts.listen, opts.token.clone(), local, ready);
    stop.store(true, std::sync::atomic::Ordering::Relaxed);
    let _ = sampler.join();
    result
}

/// Serves the page, its views from `feed`, until SIGINT or SIGTERM (local only without a
/// token, see the module's documentation). `ready` gets the address it listens on.
pub fn serve_page(
    listen: SocketAddr,
    token: Option<String>,
    feed: Arc<dyn Feed>,
    ready: &mut dyn FnMut(SocketAddr),
) -> Result<(), WebError> {
    let server = Listening::on(listen, token.as_deref(), WebError::TokenNeeded)?;
    let addr = server.addr;
    let shared = Shared {
        token,
        addr,
        uid: nix::unistd::geteuid().as_raw(),
        feed,
    };
    let app = Router::new()
        .route(
            "/",
            get(|| async { page("text/html; charset=utf-8", INDEX) }),
        )
        .route("/app.js", get(|| async { page(JS, APP) }))
        .route("/vendor/three.module.js", get(|| async { page(JS, THREE) }))
        .route(
            "/vendor/three.core.js",
            get(|| async { page(JS, THREE_CORE) }),
        )
        .route(
            "/vendor/OrbitControls.js",
            get(|| async { page(JS, ORBIT) }),
        )
        .route("/favicon.ico", get(|| async { StatusCode::NO_CONTENT }))
        .route("/ws", get(ws))
        .route("/api/{action}", post(action))
        .layer(axum::middleware::from_fn_with_state(shared.clone(), guard))
        .with_state(shared);
    ready(addr);
    server.serve(app)
}

/// A server that may start: `--listen` and `--token` acceptable, its socket bound, its
/// runtime built.
struct Listening {
    rt: tokio::runtime::Runtime,
    listener: tokio::net::TcpListener,
    /// Where it listens (the port chosen, for port 0).
    addr: SocketAddr,
}

impl Listening {
    /// Binds `listen`; anything but loopback needs a token (`needed` says so), a token must
    /// be one [`check_token`] takes.
    fn on(
        listen: SocketAddr,
        token: Option<&str>,
        needed: fn(SocketAddr) -> WebError,
    ) -> Result<Self, WebError> {
        if !listen.ip().is_loopback() && token.is_none() {
            return Err(needed(listen));
        }
        if let Some(t) = token {
            check_token(t).map_err(WebError::BadToken)?;
        }
        let rt = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .map_err(WebError::Server)?;
        let listener = rt
            .block_on(tokio::net::TcpListener::bind(listen))
            .map_err(|e| WebError::CannotListen(listen, e))?;
        let addr = listener.local_addr().map_err(WebError::Server)?;
        Ok(Self { rt, listener, addr })
    }

    /// Serves `app` until SIGINT or SIGTERM.
    fn serve(self, app: Router) -> Result<(), WebError> {
        let serve = axum::serve(
            self.listener,
            app.into_make_service_with_connect_info::<SocketAddr>(),
        )
        .with_graceful_shutdown(async {
            while !runtime::signals::stop_requested() {
                tokio::time::sleep(Duration::from_millis(50)).await;
            }
        });
        self.rt
            .block_on(async { serve.await })
            .map_err(WebError::Server)
    }
}

const JS: &str = "text/javascript; charset=utf-8";

fn page(kind: &'static str, body: &'static str) -> Response {
    ([(header::CONTENT_TYPE, kind)], body).into_response()
}

/// A token the view accepts: at least 8 characters, each a letter, a digit or `-_.~` (it
/// travels in a URL and a cookie as it is).
pub fn check_token(token: &str) -> Result<(), TokenError> {
    if token.chars().count() < 8 {
        return Err(TokenError::TooShort);
    }
    if !token
        .chars()
        .all(|c| c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.' | '~'))
    {
        return Err(TokenError::BadCharacter);
    }
    Ok(())
}

/// What is wrong with a `--token`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TokenError {
    /// Fewer than 8 characters.
    TooShort,
    /// A character other than a letter, a digit or `- _ . ~`.
    BadCharacter,
}

impl std::fmt::Display for TokenError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::TooShort => "--token must have at least 8 characters",
            Self::BadCharacter => {
                "--token may hold letters, digits and - _ . ~ only (it travels in a URL and a cookie)"
            }
        })
    }
}

impl std::error::Error for TokenError {}

/// The cookie that carries the token for the page's own requests (its scripts, its
/// WebSocket), one per port.
fn cookie_name(s: &Shared) -> String {
    format!("rtc_token_{}", s.addr.port())
}

/// `a` equals `b`, compared in a time that does not depend on where they differ.
fn same_secret(a: &[u8], b: &[u8]) -> bool {
    let mut diff = a.len() ^ b.len();
    for (i, x) in a.iter().enumerate() {
        diff |= usize::from(x ^ b.get(i).copied().unwrap_or(!x));
    }
    diff == 0
}

/// The token the request carries, if any: `Authorization: Bearer`, `?token=`, the cookie.
fn token_of(s: &Shared, headers: &HeaderMap, query: Option<&str>) -> Vec<String> {
    let mut found = Vec::new();
    if let Some(b) = headers
        .get(header::AUTHORIZATION)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.strip_prefix("Bearer "))
    {
        found.push(b.to_string());
    }
    if let Some(q) = query
        && let Ok(q) = query_pairs(q)
    {
        found.extend(q.into_iter().filter(|(k, _)| k == "token").map(|(_, v)| v));
    }
    let name = cookie_name(s);
    for v in headers.get_all(header::COOKIE) {
        for pair in v.to_str().unwrap_or("").split(';') {
            if let Some((k, v)) = pair.trim().split_once('=')
                && k == name
            {
                found.push(v.to_string());
            }
        }
    }
    found
}

/// `k=v&k=v` of a query string, percent-decoded.
fn query_pairs(q: &str) -> Result<Vec<(String, String)>, ()> {
    let query: Query<Vec<(String, String)>> =
        Query::try_from_uri(&format!("/?{q}").parse().map_err(|_| ())?).map_err(|_| ())?;
    Ok(query.0)
}

/// Whether `host` (a `Host` header) names this machine's loopback at `port`.
fn loopback_host(host: &str, port: u16) -> bool {
    let (name, p) = match host.rsplit_once(':') {
        Some((n, p)) if !n.ends_with(']') || n.starts_with('[') => (n, p.parse::<u16>().ok()),
        _ => (host, Some(80)),
    };
    if p != Some(port) {
        return false;
    }
    let name = name.trim_start_matches('[').trim_end_matches(']');
    name.eq_ignore_ascii_case("localhost")
        || name
            .parse::<std::net::IpAddr>()
            .is_ok_and(|ip| ip.is_loopback())
}

/// The uid of the process at the other end of a loopback TCP connection: the kernel's socket
/// table (`/proc/net/tcp`, `/proc/net/tcp6`) lists the client's socket, local address =
/// `peer`, remote = `server`, with its owner's uid.
pub fn loopback_peer_uid(server: SocketAddr, peer: SocketAddr) -> Option<u32> {
    fn hex(a: SocketAddr) -> String {
        let ip = match a.ip() {
            std::net::IpAddr::V4(v4) => format!("{:08X}", u32::from_ne_bytes(v4.octets())),
            std::net::IpAddr::V6(v6) => v6
                .octets()
                .chunks(4)
                .map(|c| format!("{:08X}", u32::from_ne_bytes([c[0], c[1], c[2], c[3]])))
                .collect(),
        };
        format!("{ip}:{:04X}", a.port())
    }
    let (want_local, want_remote) = (hex(peer), hex(server));
    for table in ["/proc/net/tcp", "/proc/net/tcp6"] {
        let Ok(text) = std::fs::read_to_string(table) else {
            continue;
        };
        for line in text.lines().skip(1) {
            let f: Vec<&str> = line.split_whitespace().collect();
            // Only a socket a process still holds (inode not 0): the row of one already
            // closed says uid 0 in time-wait, and orphaned on kernels before about 6.15, and
            // must not pass for root. (Not testable here: this kernel keeps an orphan's uid
            // and the guard reads the table before the server's close makes a time-wait.)
            if f.len() > 9 && f[1] == want_local && f[2] == want_remote && f[9] != "0" {
                return f[7].parse().ok();
            }
        }
    }
    None
}

/// Who may ask what (see the module documentation); a refusal names why. Runs before any
/// handler: nothing of a refused request is kept or done.
fn check(
    s: &Shared,
    peer: SocketAddr,
    method: &Method,
    path: &str,
    query: Option<&str>,
    headers: &HeaderMap,
) -> Result<Option<HeaderValue>, (StatusCode, String)> {
    let refuse = |code, why: String| Err((code, why));
    let Some(host) = headers.get(header::HOST).and_then(|h| h.to_str().ok()) else {
        return refuse(StatusCode::BAD_REQUEST, "no Host header".into());
    };
    let mut set_cookie = None;
    match &s.token {
        None => {
            if !loopback_host(host, s.addr.port()) {
                return refuse(
                    StatusCode::FORBIDDEN,
                    format!(
                        "Host {host:?} is not this machine's loopback: the view serves \
                         http://127.0.0.1:{}/ (or localhost) only",
                        s.addr.port()
                    ),
                );
            }
            match loopback_peer_uid(s.addr, peer) {
                Some(uid) if uid == s.uid || uid == 0 => {}
                Some(uid) => {
                    return refuse(
                        StatusCode::FORBIDDEN,
                        format!(
                            "refused: this view belongs to uid {}; uid {uid} may not use it",
                            s.uid
                        ),
                    );
                }
                None => {
                    return refuse(
                        StatusCode::FORBIDDEN,
                        format!("refused: cannot tell which user connects from {peer}"),
                    );
                }
            }
        }
        Some(token) => {
            let given = token_of(s, headers, query);
            if !given
                .iter()
                .any(|g| same_secret(g.as_bytes(), token.as_bytes()))
            {
                return refuse(StatusCode::UNAUTHORIZED, "a token is needed".into());
            }
            // The page's own requests (its scripts) carry it from now on.
            set_cookie = HeaderValue::from_str(&format!(
                "{}={token}; HttpOnly; SameSite=Strict; Path=/",
                cookie_name(s)
            ))
            .ok();
        }
    }
    let upgrade = path == "/ws";
    if *method != Method::GET && *method != Method::HEAD || upgrade {
        if let Some(origin) = headers.get(header::ORIGIN) {
            let own = format!("http://{host}");
            if origin.to_str().ok() != Some(own.as_str()) {
                return refuse(
                    StatusCode::FORBIDDEN,
                    format!(
                        "refused: a request from {origin:?}, another origin than {own} \
                         (a cross-site request)"
                    ),
                );
            }
        }
        if !upgrade && headers.get("x-rtc-request").and_then(|v| v.to_str().ok()) != Some("1") {
            return refuse(
                StatusCode::FORBIDDEN,
                "refused: a request that changes the cell needs the header X-Rtc-Request: 1 \
                 (the page sends it; a page of another site cannot)"
                    .into(),
            );
        }
    }
    Ok(set_cookie)
}

/// Every request passes here first: [`check`].
async fn guard(
    State(s): State<Shared>,
    ConnectInfo(peer): ConnectInfo<SocketAddr>,
    req: axum::extract::Request,
    next: Next,
) -> Response {
    let checked = check(
        &s,
        peer,
        req.method(),
        req.uri().path(),
        req.uri().query(),
        req.headers(),
    );
    match checked {
        Ok(cookie) => {
            let mut r = next.run(req).await;
            if let Some(c) = cookie {
                r.headers_mut().append(header::SET_COOKIE, c);
            }
            r
        }
        Err((code, why)) => {
            tracing::warn!("web: {code} for {peer}: {why}");
            (code, why).into_response()
        }
    }
}

/// The cell a page asks for (`?cell=NAME`), if any.
fn cell_of(query: &Query<Vec<(String, String)>>) -> Option<String> {
    query
        .0
        .iter()
        .find(|(k, _)| k == "cell")
        .map(|(_, v)| v.clone())
}

async fn ws(
    State(s): State<Shared>,
    query: Query<Vec<(String, String)>>,
    upgrade: WebSocketUpgrade,
) -> Response {
    let cell = cell_of(&query);
    let feed = s.feed.clone();
    let view = tokio::task::spawn_blocking(move || feed.view(cell.as_deref())).await;
    match view {
        Ok(Ok(view)) => upgrade.on_upgrade(move |socket| client(socket, view)),
        Ok(Err(why)) => (StatusCode::NOT_FOUND, why).into_response(),
        Err(e) => (StatusCode::INTERNAL_SERVER_ERROR, e.to_string()).into_response(),
    }
}

/// One page: the cell's description (again whenever it changes), then every frame.
async fn client(mut socket: WebSocket, s: View) {
    let mut frames = s.frames.subscribe();
    let mut sent_hello: Option<Arc<str>> = None;
    loop {
        let hello = s.hello.lock().map_or(None, |h| h.clone());
        if let Some(h) = hello
            && sent_hello.as_ref() != Some(&h)
        {
            if socket
                .send(Message::Text(h.to_string().into()))
                .await
                .is_err()
            {
                return;
            }
            sent_hello = Some(h);
        }
        match frames.recv().await {
            Ok(f) => {
                if socket
                    .send(Message::Text(f.to_string().into()))
                    .await
                    .is_err()
                {
                    return;
                }
            }
            // A slow page skips frames; it never holds the others back.
            Err(broadcast::error::RecvError::Lagged(_)) => {}
            Err(broadcast::error::RecvError::Closed) => return,
        }
    }
}

/// `POST /api/estop|reset|start`: the feed's (this host's: the CLI's paths).
async fn action(
    State(s): State<Shared>,
    axum::extract::Path(what): axum::extract::Path<String>,
    query: Query<Vec<(String, String)>>,
) -> Response {
    let cell = cell_of(&query);
    let feed = s.feed.clone();
    let result = tokio::task::spawn_blocking(move || feed.action(&what, cell.as_deref())).await;
    match result {
        Ok(Ok(m)) => (StatusCode::OK, m).into_response(),
        Ok(Err((code, m))) => (code, m).into_response(),
        Err(e) => (StatusCode::INTERNAL_SERVER_ERROR, e.to_string()).into_response(),
    }
}

/// The sampler: attached while the cell is up, waiting for it while it is not, until `stop`.
/// Its messages go to `view`: the cell's description, then 30 frames a second.
pub fn sample(instance: InstanceName, view: &View, stop: &std::sync::atomic::AtomicBool) {
    ipc::quiet_iceoryx2_log();
    let started = Instant::now();
    // A cell on the virtual clock: where its clock last stood (it does not pass while the cell
    // is down).
    let mut virtual_t = None;
    while !stop.load(std::sync::atomic::Ordering::Relaxed) {
        if !ipc::live_node_pids(&instance)
            .unwrap_or_default()
            .is_empty()
            && let Err(e) = attached(instance, view, stop, started, &mut virtual_t)
        {
            tracing::debug!("web: {e}");
        }
        let t = virtual_t.unwrap_or_else(|| started.elapsed().as_secs_f64());
        let down = json!({"kind": "frame", "up": false, "t": t});
        let _ = view.frames.send(Arc::from(down.to_string()));
        std::thread::sleep(Duration::from_millis(500));
    }
}

/// Samples the cell until it goes down (or the server stops). Its frames' time `t` (s) is the
/// cell's: the seconds since `started` on the wall clock, its clock's instant on the virtual
/// clock (also kept in `virtual_t`).
fn attached(
    instance: InstanceName,
    view: &View,
    stop: &std::sync::atomic::AtomicBool,
    started: Instant,
    virtual_t: &mut Option<f64>,
) -> Result<(), String> {
    let (frames, hello) = (&view.frames, &view.hello);
    let f = |e: ipc::IpcError| e.to_string();
    let node = ipc::node(&instance, &format!("web-{}", std::process::id())).map_err(f)?;
    let result = (|| {
        let cell_sub =
            Sub::<CellConfigV6>::new(&node, &instance, ServiceId::CellConfig, 1).map_err(f)?;
        let t0 = Instant::now();
        let cell = loop {
            if let Some(c) = cell_sub.latest() {
                break Box::new(c);
            }
            if t0.elapsed() > GONE {
                return Err("no cell configuration".to_string());
            }
            std::thread::sleep(Duration::from_millis(10));
        };
        let mut clock = if cell.clock == shm_schema::CellClock::Virtual as u32 {
            Some(runtime::vclock::Observer::new(&node, &instance).map_err(|e| e.to_string())?)
        } else {
            *virtual_t = None;
            None
        };
        let kin = motion_core::generator::Kin::of_cell(&cell).map_err(|e| e.to_string())?;
        let axes = Axes::of_cell(&cell);
        let mut statuses = Vec::new();
        let mut latencies = Vec::new();
        for p in cell.processes() {
            if let Some(name) = ProcessName::from_field(&p.name) {
                statuses.push((
                    name.to_string(),
                    Sub::<ProcessStatusV2>::new(&node, &instance, ServiceId::Status(name), 8)
                        .map_err(f)?,
                    None::<ProcessStatusV2>,
                ));
                // A process without a histogram service (one of another language) is left out.
                if let Ok(sub) = Sub::new(&node, &instance, ServiceId::Latency(name), 1) {
                    latencies.push(LatencyWatch {
                        name: name.to_string(),
                        sub,
                        last: None,
                    });
                }
            }
        }
        let servo =
            Sub::<ServoStateV3>::new(&node, &instance, ServiceId::ServoState, 64).map_err(f)?;
        let setpoint =
            Sub::<SetpointV2>::new(&node, &instance, ServiceId::Setpoint, 16).map_err(f)?;
        let host = Sub::<HostStateV1>::new(&node, &instance, ServiceId::HostState, 1).map_err(f)?;
        let description = describe(&cell, &axes, kin.as_ref());
        if let Ok(mut h) = hello.lock() {
            *h = Some(Arc::from(description.to_string()));
        }
        let (mut last_servo, mut last_sp, mut heard) = (None, None, Instant::now());
        // The supervisor's newest heartbeat, kept: a frame between two of them (the
        // supervisor stalled a moment) still shows the e-stop it latched.
        let mut beat = None;
        let mut peak_fe = [0.0f64; MAX_AXES];
        let n = axes.axes.len();
        let mut count = 0u64;
        while !stop.load(std::sync::atomic::Ordering::Relaxed) {
            count += 1;
            // Every servo state since the last frame: the largest following error among them.
            while let Some(s) = servo.next() {
                for (k, p) in peak_fe.iter_mut().enumerate().take(n) {
                    if s.following_error[k].abs() > p.abs() {
                        *p = s.following_error[k];
                    }
                }
                last_servo = Some(s);
            }
            if let Some(sp) = setpoint.latest() {
                last_sp = Some(sp);
            }
            if let Some(b) = host.latest() {
                beat = Some(b);
                heard = Instant::now();
            }
            if heard.elapsed() > GONE {
                return Ok(()); // the cell went down
            }
            for (_, sub, last) in &mut statuses {
                if let Some(s) = sub.latest() {
                    *last = Some(s);
                }
            }
            let t = match &mut clock {
                Some(c) => *virtual_t.insert(runtime::time::secs(c.now_ns())),
                None => started.elapsed().as_secs_f64(),
            };
            let frame = frame(
                t,
                n,
                kin.as_ref(),
                last_servo.as_ref(),
                last_sp.as_ref(),
                beat,
                &statuses,
                &peak_fe,
            );
            let mut frame = frame;
            // The latency histograms about once a second (the processes publish them every
            // 100 ms; they change slowly).
            if count % RATE_HZ == 1 {
                for l in &mut latencies {
                    if let Some(h) = l.sub.latest() {
                        l.last = Some(Box::new(h));
                    }
                }
                frame["latency"] = latency_json(&latencies);
            }
            peak_fe = [0.0; MAX_AXES];
            let _ = frames.send(Arc::from(frame.to_string()));
            std::thread::sleep(Duration::from_millis(1000 / RATE_HZ));
        }
        Ok(())
    })();
    drop(node);
    ipc::cleanup_after_client(&instance);
    result
}

/// One process' latency histogram service and the newest histogram it published.
struct LatencyWatch {
    name: String,
    sub: Sub<LatencyHistogramV1>,
    last: Option<Box<LatencyHistogramV1>>,
}

/// Each process' wake-up latency histogram since it started, as `--plot` draws it: bins of
/// 1/8 octave (µs), its p99 and its largest.
fn latency_json(latencies: &[LatencyWatch]) -> Value {
    latencies
        .iter()
        .filter_map(|l| {
            let h = l.last.as_deref().filter(|h| h.count > 0)?;
            let f = control_plane::figures::ProcessLatency::of(&l.name, h);
            Some(json!({
                "name": f.process,
                "samples": h.count,
                "overflows": h.overflows,
                "p99_us": f.p99_us,
                "max_us": f.max_us,
                "bins": f.bins,
            }))
        })
        .collect()
}

/// The cell as the page draws it: axes, kinematics and its parameters, the tool's
/// coordinates (the axes themselves for a gantry), processes.
fn describe(cell: &CellConfigV6, axes: &Axes, kin: Option<&motion_core::generator::Kin>) -> Value {
    let k = &cell.kinematics;
    let kind = str_of(&k.type_name);
    let params: serde_json::Map<String, Value> = k.params
        [..(k.param_count as usize).min(k.params.len())]
        .iter()
        .map(|p| (str_of(&p.name).to_string(), json!(p.value)))
        .collect();
    json!({
        "kind": "hello",
        "kinematics": if kind.is_empty() { "gantry" } else { kind },
        "params": params,
        "axes": cell.axes().iter().map(|a| json!({
            "name": str_of(&a.name), "unit": str_of(&a.unit), "min": a.min, "max": a.max,
        })).collect::<Vec<_>>(),
        "coords": match kin {
            Some(k) => k.0.coords().iter()
                .map(|c| json!({"name": c.name, "unit": c.unit.symbol()}))
                .collect::<Vec<_>>(),
            None => cell.axes().iter()
                .map(|a| json!({"name": str_of(&a.name), "unit": str_of(&a.unit)}))
                .collect(),
        },
        "processes": axes.processes,
    })
}

/// One frame: where the machine is (measured, and the tool through the kinematics; the
/// commanded tool likewise), the program, the e-stop, each process' newest wake-up latency.
#[allow(clippy::too_many_arguments)]
fn frame(
    t: f64,
    n: usize,
    kin: Option<&motion_core::generator::Kin>,
    servo: Option<&ServoStateV3>,
    sp: Option<&SetpointV2>,
    host: Option<HostStateV1>,
    statuses: &[(String, Sub<ProcessStatusV2>, Option<ProcessStatusV2>)],
    peak_fe: &[f64; MAX_AXES],
) -> Value {
    let joints: Option<Vec<f64>> = servo.map(|s| s.act_position[..n].to_vec());
    let tool = servo.and_then(|s| cell_client::figures::tool_of(kin, &s.act_position, n));
    // The commanded tool is trajgen's own, on the program's path whatever the host's
    // stalls did to servo's extrapolation; through the kinematics from servo's command when
    // the setpoint does not carry it (a trajgen of another language may not).
    let command_tool = match sp.filter(|sp| sp.coords > 0) {
        Some(sp) => Some(sp.cartesian[..(sp.coords as usize).min(MAX_AXES)].to_vec()),
        None => servo.and_then(|s| cell_client::figures::tool_of(kin, &s.cmd_position, n)),
    };
    let estop = host
        .filter(|h| h.estop != 0)
        .map(|h| json!({"origin": h.cause.origin, "reason": str_of(&h.cause.reason)}));
    json!({
        "kind": "frame",
        "up": true,
        "t": t,
        "joints": joints,
        "command": servo.map(|s| s.cmd_position[..n].to_vec()),
        "tool": tool,
        "command_tool": command_tool,
        "following_error": peak_fe[..n].to_vec(),
        "enabled": servo.map(|s| s.status & shm_schema::drive::servo_status::ENABLED != 0),
        "estop": estop,
        "program": sp.map(|sp| json!({
            "id": sp.program_id, "line": sp.line, "state": sp.state,
            "motion_time_s": sp.motion_time_s, "path_speed": sp.path_speed,
            "speed_override": sp.speed_override,
        })),
        "processes": statuses.iter().map(|(name, _, s)| json!({
            "name": name,
            "state": s.map(|s| s.state),
            "cycles": s.map(|s| s.stats.cycles),
            "wakeup_us": s.map(|s| s.stats.wakeup_latency_ns as f64 / 1000.0),
            "max_wakeup_us": s.map(|s| s.stats.max_wakeup_latency_ns as f64 / 1000.0),
            "overruns": s.map(|s| s.stats.overruns),
        })).collect::<Vec<_>>(),
    })
}
