//! `supervisor web`: the cell in a browser (seed 004's view): a page that draws the machine
//! in 3D from its kinematics, moving live, with the program line, plots of following error and
//! wake-up latency, the process table, and e-stop / reset / start buttons (docs/web.md).
//!
//! An observer: a sampler thread attaches to the instance (and again after the cell goes down
//! and comes back up), reads the newest samples 30 times a second and turns them into one
//! JSON frame, broadcast to every WebSocket client. The page, its script and three.js are
//! compiled into the binary: nothing is fetched from the network. The buttons go through the
//! same paths as the CLI (`supervisor estop` straight on `<i>/estop`; `reset` and `start`
//! through the control channel). Local only by default; any other address needs a token.

use crate::events::Axes;
use crate::run::RunError;
use axum::Router;
use axum::extract::ws::{Message, WebSocket, WebSocketUpgrade};
use axum::extract::{Query, State};
use axum::http::{HeaderMap, StatusCode, header};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use runtime::ipc::{self, Sub};
use serde_json::{Value, json};
use shm_schema::estop::HostStateV1;
use shm_schema::{
    CellConfigV6, InstanceName, LatencyHistogramV1, MAX_AXES, ProcessName, ProcessStatusV2,
    ServiceId, ServoStateV3, SetpointV2, str_of,
};
use std::collections::HashMap;
use std::net::SocketAddr;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use tokio::sync::broadcast;

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

/// The state the HTTP side shares.
#[derive(Clone)]
struct Shared {
    instance: InstanceName,
    token: Option<String>,
    frames: broadcast::Sender<Arc<str>>,
    /// The cell's description (axes, kinematics, processes), for a client that connects.
    hello: Arc<Mutex<Option<Arc<str>>>>,
}

/// Serves the page until SIGINT or SIGTERM. `ready` gets the address it listens on.
pub fn web(opts: &WebOptions, ready: &mut dyn FnMut(SocketAddr)) -> Result<(), RunError> {
    if !opts.listen.ip().is_loopback() && opts.token.is_none() {
        return Err(RunError::Input(format!(
            "--listen {} opens the cell's controls (e-stop, reset, start) to the network: give --token",
            opts.listen
        )));
    }
    let (frames, _) = broadcast::channel(64);
    let shared = Shared {
        instance: opts.instance,
        token: opts.token.clone(),
        frames: frames.clone(),
        hello: Arc::new(Mutex::new(None)),
    };
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .map_err(|e| RunError::failed(format!("web: {e}")))?;
    let listener = rt
        .block_on(tokio::net::TcpListener::bind(opts.listen))
        .map_err(|e| RunError::Input(format!("web: cannot listen on {}: {e}", opts.listen)))?;
    let addr = listener
        .local_addr()
        .map_err(|e| RunError::failed(format!("web: {e}")))?;
    let sampler = {
        let (hello, instance) = (shared.hello.clone(), opts.instance);
        std::thread::Builder::new()
            .name("web-sampler".into())
            .spawn(move || sample_forever(instance, &frames, &hello))
            .map_err(|e| RunError::failed(format!("web: {e}")))?
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
        .with_state(shared);
    ready(addr);
    let serve = axum::serve(listener, app).with_graceful_shutdown(async {
        while !runtime::signals::stop_requested() {
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
    });
    let result = rt
        .block_on(async { serve.await })
        .map_err(|e| RunError::failed(format!("web: {e}")));
    STOP.store(true, std::sync::atomic::Ordering::Relaxed);
    let _ = sampler.join();
    result
}

const JS: &str = "text/javascript; charset=utf-8";

static STOP: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

fn page(kind: &'static str, body: &'static str) -> Response {
    ([(header::CONTENT_TYPE, kind)], body).into_response()
}

/// Whether a request carries the token (or none is needed).
fn allowed(s: &Shared, headers: &HeaderMap, query: &HashMap<String, String>) -> bool {
    let Some(token) = &s.token else {
        return true;
    };
    let bearer = headers
        .get(header::AUTHORIZATION)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.strip_prefix("Bearer "));
    bearer == Some(token.as_str()) || query.get("token") == Some(token)
}

async fn ws(
    State(s): State<Shared>,
    headers: HeaderMap,
    Query(q): Query<HashMap<String, String>>,
    upgrade: WebSocketUpgrade,
) -> Response {
    if !allowed(&s, &headers, &q) {
        return (StatusCode::UNAUTHORIZED, "a token is needed").into_response();
    }
    upgrade.on_upgrade(move |socket| client(socket, s))
}

/// One page: the cell's description (again whenever it changes), then every frame.
async fn client(mut socket: WebSocket, s: Shared) {
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

/// `POST /api/estop|reset|start`: the CLI's paths.
async fn action(
    State(s): State<Shared>,
    axum::extract::Path(what): axum::extract::Path<String>,
    headers: HeaderMap,
    Query(q): Query<HashMap<String, String>>,
) -> Response {
    if !allowed(&s, &headers, &q) {
        return (StatusCode::UNAUTHORIZED, "a token is needed").into_response();
    }
    let instance = s.instance;
    let result = tokio::task::spawn_blocking(move || -> Result<String, (StatusCode, String)> {
        use crate::ctl::{Reply, Request};
        let req = match what.as_str() {
            "estop" => {
                return crate::control::estop(instance.as_str(), "e-stop button of the web view")
                    .map_err(|e| (StatusCode::CONFLICT, e.to_string()));
            }
            "reset" => Request::Reset,
            "start" => Request::Start,
            other => return Err((StatusCode::NOT_FOUND, format!("no action {other:?}"))),
        };
        match crate::ctl::call(&instance, &req) {
            Ok(Reply::Done(m)) => Ok(m),
            Ok(Reply::Refused(m) | Reply::Failed(m)) => Err((StatusCode::CONFLICT, m)),
            Ok(other) => Ok(format!("{other:?}")),
            Err(e) => Err((StatusCode::SERVICE_UNAVAILABLE, e.to_string())),
        }
    })
    .await;
    match result {
        Ok(Ok(m)) => (StatusCode::OK, m).into_response(),
        Ok(Err((code, m))) => (code, m).into_response(),
        Err(e) => (StatusCode::INTERNAL_SERVER_ERROR, e.to_string()).into_response(),
    }
}

/// The sampler: attached while the cell is up, waiting for it while it is not.
fn sample_forever(
    instance: InstanceName,
    frames: &broadcast::Sender<Arc<str>>,
    hello: &Mutex<Option<Arc<str>>>,
) {
    ipc::quiet_iceoryx2_log();
    let started = Instant::now();
    while !STOP.load(std::sync::atomic::Ordering::Relaxed) {
        if !ipc::live_node_pids(&instance)
            .unwrap_or_default()
            .is_empty()
            && let Err(e) = attached(instance, frames, hello, started)
        {
            tracing::debug!("web: {e}");
        }
        let down = json!({"kind": "frame", "up": false, "t": started.elapsed().as_secs_f64()});
        let _ = frames.send(Arc::from(down.to_string()));
        std::thread::sleep(Duration::from_millis(500));
    }
}

/// Samples the cell until it goes down (or the server stops).
fn attached(
    instance: InstanceName,
    frames: &broadcast::Sender<Arc<str>>,
    hello: &Mutex<Option<Arc<str>>>,
    started: Instant,
) -> Result<(), String> {
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
        let mut peak_fe = [0.0f64; MAX_AXES];
        let n = axes.axes.len();
        let mut count = 0u64;
        while !STOP.load(std::sync::atomic::Ordering::Relaxed) {
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
            let beat = host.latest();
            if beat.is_some() {
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
            let frame = frame(
                started.elapsed().as_secs_f64(),
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
            let f = crate::figures::ProcessLatency::of(&l.name, h);
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
    let tool = servo.and_then(|s| crate::figures::tool_of(kin, &s.act_position, n));
    // The commanded tool is trajgen's own, on the program's path whatever the host's
    // stalls did to servo's extrapolation; through the kinematics from servo's command when
    // the setpoint does not carry it (a trajgen of another language may not).
    let command_tool = match sp.filter(|sp| sp.coords > 0) {
        Some(sp) => Some(sp.cartesian[..(sp.coords as usize).min(MAX_AXES)].to_vec()),
        None => servo.and_then(|s| crate::figures::tool_of(kin, &s.cmd_position, n)),
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
