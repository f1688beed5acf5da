//! `supervisor foxglove`: the cell live in Foxglove, over the Foxglove WebSocket protocol
//! (subprotocol `foxglove.websocket.v1`, or `foxglove.sdk.v1`, the same messages), with the
//! channels and schemas of the MCAP recorder: each topic a channel of JSON messages with a
//! JSON Schema, each message the one a recording writes (docs/recording.md), timestamped with
//! the sample's own time.
//!
//! An observer: while a client is connected, a reader thread runs the recorder's source
//! (`recorder::Source`, the one `supervisor record` uses) on the cell, and hands what it read
//! every 10 ms to the clients; nobody connected, nothing is read. The cell never waits: a client
//! slower than the cell skips batches and is told how many in a status message.
//!
//! # Who may use it
//! It only shows: the server declares no capability (no publishing, no services, no
//! parameters), so a client can subscribe and nothing else. Still, what it shows is the
//! cell's, so every connection passes [`admit`]:
//! - **local only by default** (`127.0.0.1:8765`): the `Host` must name this machine's
//!   loopback and the connecting process must be the user who runs the server (or root);
//! - **any other address needs `--token`**, which every connection carries (`?token=` in the
//!   URL, or `Authorization: Bearer`);
//! - a browser page may connect only from the Foxglove app's origins
//!   (`https://app.foxglove.dev`, `https://studio.foxglove.dev`) or one given with
//!   `--allow-origin`; a client without an `Origin` (the desktop app, a script) is not a page.

use crate::{Listening, WebError, loopback_host, loopback_peer_uid, query_pairs, same_secret};
use axum::Router;
use axum::extract::ws::{Message, WebSocket, WebSocketUpgrade};
use axum::extract::{ConnectInfo, State};
use axum::http::{HeaderMap, StatusCode, header};
use axum::response::{IntoResponse, Response};
use axum::routing::get;
use recorder::{Source, TopicInfo};
use serde_json::json;
use shm_schema::InstanceName;
use std::collections::HashMap;
use std::net::SocketAddr;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::time::Duration;
use tokio::sync::{broadcast, watch};

/// The subprotocols spoken, in the order preferred.
pub const SUBPROTOCOLS: [&str; 2] = ["foxglove.websocket.v1", "foxglove.sdk.v1"];

/// The Foxglove app's origins: its pages may connect.
pub const FOXGLOVE_ORIGINS: [&str; 2] = ["https://app.foxglove.dev", "https://studio.foxglove.dev"];

/// How often the reader hands its messages on.
const BATCH: Duration = Duration::from_millis(10);

/// Batches a client may fall behind by before it skips (about 2.5 s).
const BACKLOG: usize = 256;

/// What `supervisor foxglove` is asked to do.
#[derive(Clone, Debug)]
pub struct FoxgloveOptions {
    /// The instance to show.
    pub instance: InstanceName,
    /// Where to listen.
    pub listen: SocketAddr,
    /// Required of every client when set.
    pub token: Option<String>,
    /// Origins whose pages may connect, besides Foxglove's own.
    pub origins: Vec<String>,
}

/// One batch of messages: `(topic index, log time ns since the Unix epoch, the JSON)`.
type Batch = Arc<Vec<(usize, u64, Box<[u8]>)>>;

/// The topics shown now; a new generation when the reader's source changed them.
#[derive(Clone, Debug, Default)]
struct Topics {
    generation: u64,
    topics: Arc<Vec<TopicInfo>>,
}

#[derive(Clone)]
struct Shared {
    instance: InstanceName,
    token: Option<String>,
    origins: Arc<Vec<String>>,
    addr: SocketAddr,
    uid: u32,
    batches: broadcast::Sender<(u64, Batch)>,
    topics: watch::Receiver<Topics>,
    clients: Arc<AtomicUsize>,
}

/// Serves Foxglove until SIGINT or SIGTERM. `ready` gets the address it listens on.
pub fn foxglove(opts: &FoxgloveOptions, ready: &mut dyn FnMut(SocketAddr)) -> Result<(), WebError> {
    let server = Listening::on(
        opts.listen,
        opts.token.as_deref(),
        WebError::TokenNeededToShow,
    )?;
    let addr = server.addr;
    let (batches, _) = broadcast::channel(BACKLOG);
    let (topics_tx, topics) = watch::channel(Topics::default());
    let clients = Arc::new(AtomicUsize::new(0));
    let stop = Arc::new(AtomicBool::new(false));
    let reader = {
        let (batches, clients, stop, instance) = (
            batches.clone(),
            clients.clone(),
            stop.clone(),
            opts.instance,
        );
        std::thread::Builder::new()
            .name("foxglove-reader".into())
            .spawn(move || read(instance, &batches, &topics_tx, &clients, &stop))
            .map_err(WebError::Server)?
    };
    let shared = Shared {
        instance: opts.instance,
        token: opts.token.clone(),
        origins: Arc::new(opts.origins.clone()),
        addr,
        uid: nix::unistd::geteuid().as_raw(),
        batches,
        topics,
        clients,
    };
    let app = Router::new().route("/", get(upgrade)).with_state(shared);
    ready(addr);
    let result = server.serve(app);
    stop.store(true, Ordering::Relaxed);
    let _ = reader.join();
    result
}

/// Who may connect (see the module documentation); a refusal names why. Runs before the
/// upgrade: nothing of a refused connection is kept or sent.
fn admit(
    s: &Shared,
    peer: SocketAddr,
    query: Option<&str>,
    headers: &HeaderMap,
) -> Result<(), String> {
    let Some(host) = headers.get(header::HOST).and_then(|h| h.to_str().ok()) else {
        return Err("no Host header".into());
    };
    match &s.token {
        None => {
            if !loopback_host(host, s.addr.port()) {
                return Err(format!(
                    "Host {host:?} is not this machine's loopback: the server serves ws://127.0.0.1:{}/ (or localhost) only",
                    s.addr.port()
                ));
            }
            match loopback_peer_uid(s.addr, peer) {
                Some(uid) if uid == s.uid || uid == 0 => {}
                Some(uid) => {
                    return Err(format!(
                        "this server belongs to uid {}; uid {uid} may not use it",
                        s.uid
                    ));
                }
                None => return Err(format!("cannot tell which user connects from {peer}")),
            }
        }
        Some(token) => {
            let mut given: Vec<String> = query
                .and_then(|q| query_pairs(q).ok())
                .unwrap_or_default()
                .into_iter()
                .filter(|(k, _)| k == "token")
                .map(|(_, v)| v)
                .collect();
            given.extend(
                headers
                    .get(header::AUTHORIZATION)
                    .and_then(|v| v.to_str().ok())
                    .and_then(|v| v.strip_prefix("Bearer "))
                    .map(str::to_string),
            );
            if !given
                .iter()
                .any(|g| same_secret(g.as_bytes(), token.as_bytes()))
            {
                return Err("a token is needed (?token=...)".into());
            }
        }
    }
    if let Some(origin) = headers.get(header::ORIGIN) {
        let origin = origin.to_str().unwrap_or("");
        let known = FOXGLOVE_ORIGINS.contains(&origin) || s.origins.iter().any(|o| o == origin);
        if !known {
            return Err(format!(
                "a page of {origin:?} may not connect (the Foxglove app's origins may; others with --allow-origin)"
            ));
        }
    }
    let offered = headers
        .get(header::SEC_WEBSOCKET_PROTOCOL)
        .and_then(|v| v.to_str().ok())
        .unwrap_or("");
    if !offered.split(',').any(|p| SUBPROTOCOLS.contains(&p.trim())) {
        return Err(format!(
            "a Foxglove WebSocket server: ask for the subprotocol {} (offered: {offered:?})",
            SUBPROTOCOLS.join(" or ")
        ));
    }
    Ok(())
}

async fn upgrade(
    State(s): State<Shared>,
    ConnectInfo(peer): ConnectInfo<SocketAddr>,
    uri: axum::http::Uri,
    headers: HeaderMap,
    upgrade: WebSocketUpgrade,
) -> Response {
    if let Err(why) = admit(&s, peer, uri.query(), &headers) {
        tracing::warn!("foxglove: refused {peer}: {why}");
        return (StatusCode::FORBIDDEN, why).into_response();
    }
    tracing::info!("foxglove: {peer} connected");
    upgrade
        .protocols(SUBPROTOCOLS)
        .on_upgrade(move |socket| client(socket, s, peer))
}

/// The reader: a source on the cell while anyone is connected, its messages handed on.
fn read(
    instance: InstanceName,
    batches: &broadcast::Sender<(u64, Batch)>,
    topics: &watch::Sender<Topics>,
    clients: &AtomicUsize,
    stop: &AtomicBool,
) {
    let name = format!("foxglove-{}", std::process::id());
    let mut source: Option<Source> = None;
    let mut said = String::new();
    while !stop.load(Ordering::Relaxed) {
        if clients.load(Ordering::Relaxed) == 0 {
            source = None;
            std::thread::sleep(Duration::from_millis(50));
            continue;
        }
        let Some(s) = source.as_mut() else {
            match Source::open(&instance, &name) {
                Ok(s) => {
                    let now = s.topics();
                    topics.send_if_modified(|t| {
                        if *t.topics == now {
                            return false;
                        }
                        t.generation += 1;
                        t.topics = Arc::new(now);
                        true
                    });
                    tracing::info!("foxglove: reading instance {instance}");
                    said.clear();
                    source = Some(s);
                }
                Err(e) => {
                    let why = e.to_string();
                    if why != said {
                        tracing::warn!("foxglove: {why}; trying again");
                        said = why;
                    }
                    std::thread::sleep(Duration::from_millis(500));
                }
            }
            continue;
        };
        let mut batch = Vec::new();
        let drained = s.drain(&mut |k, t, data| {
            batch.push((k, t, data.into()));
            Ok(())
        });
        if let Err(e) = drained {
            tracing::warn!("foxglove: {e}");
        }
        if !batch.is_empty() {
            let generation = topics.borrow().generation;
            let _ = batches.send((generation, Arc::new(batch)));
        }
        if !s.cell_alive() {
            tracing::info!("foxglove: instance {instance} went down; waiting for it");
            source = None;
        }
        std::thread::sleep(BATCH);
    }
}

/// Counts a client for as long as it is connected.
struct Connected(Arc<AtomicUsize>);

impl Drop for Connected {
    fn drop(&mut self) {
        self.0.fetch_sub(1, Ordering::Relaxed);
    }
}

/// One client: the server's info, the channels (again whenever they change), and the
/// messages of the channels it subscribed to.
async fn client(mut socket: WebSocket, mut s: Shared, peer: SocketAddr) {
    s.clients.fetch_add(1, Ordering::Relaxed);
    let _counted = Connected(s.clients.clone());
    let mut batches = s.batches.subscribe();
    let info = json!({
        "op": "serverInfo",
        "name": format!("rtc cell {}", s.instance),
        "capabilities": [],
        "metadata": {"instance": s.instance.as_str()},
        "sessionId": format!("{}-{}", std::process::id(), s.addr.port()),
    });
    if send_json(&mut socket, &info).await.is_err() {
        return;
    }
    // Channel id = topic index + 1, for the topics of `shown`.
    let mut shown = Topics::default();
    // Subscription id per channel id, and back.
    let mut subscribed: HashMap<u32, u32> = HashMap::new();
    s.topics.mark_changed();
    loop {
        tokio::select! {
            changed = s.topics.changed() => {
                if changed.is_err() {
                    return;
                }
                let now = s.topics.borrow_and_update().clone();
                if !shown.topics.is_empty() {
                    let ids: Vec<u32> = (1..=shown.topics.len() as u32).collect();
                    subscribed.clear();
                    if send_json(&mut socket, &json!({"op": "unadvertise", "channelIds": ids})).await.is_err() {
                        return;
                    }
                }
                if !now.topics.is_empty() && send_json(&mut socket, &advertise(&now.topics)).await.is_err() {
                    return;
                }
                shown = now;
            }
            batch = batches.recv() => match batch {
                Ok((generation, batch)) if generation == shown.generation => {
                    for (k, t, data) in batch.iter() {
                        let Some(sub) = subscribed.get(&(*k as u32 + 1)) else {
                            continue;
                        };
                        let mut frame = Vec::with_capacity(13 + data.len());
                        frame.push(1);
                        frame.extend_from_slice(&sub.to_le_bytes());
                        frame.extend_from_slice(&t.to_le_bytes());
                        frame.extend_from_slice(data);
                        if socket.send(Message::Binary(frame.into())).await.is_err() {
                            return;
                        }
                    }
                }
                Ok(_) => {}
                Err(broadcast::error::RecvError::Lagged(n)) => {
                    let m = format!("this client fell behind the cell: {n} batches of messages skipped");
                    if send_json(&mut socket, &json!({"op": "status", "level": 1, "message": m})).await.is_err() {
                        return;
                    }
                }
                Err(broadcast::error::RecvError::Closed) => return,
            },
            message = socket.recv() => match message {
                Some(Ok(Message::Text(text))) => {
                    if let Some(why) = request(&text, shown.topics.len(), &mut subscribed)
                        && send_json(&mut socket, &json!({"op": "status", "level": 2, "message": why})).await.is_err()
                    {
                        return;
                    }
                }
                Some(Ok(Message::Binary(_))) => {
                    let why = "this server takes no client messages (no clientPublish capability)";
                    if send_json(&mut socket, &json!({"op": "status", "level": 2, "message": why})).await.is_err() {
                        return;
                    }
                }
                Some(Ok(_)) => {}
                Some(Err(_)) | None => {
                    tracing::info!("foxglove: {peer} left");
                    return;
                }
            },
        }
    }
}

/// The `advertise` message of `topics`, channel id = index + 1.
fn advertise(topics: &[TopicInfo]) -> serde_json::Value {
    let channels: Vec<serde_json::Value> = topics
        .iter()
        .enumerate()
        .map(|(k, t)| {
            json!({
                "id": k + 1,
                "topic": t.topic,
                "encoding": "json",
                "schemaName": t.schema_name,
                "schema": t.schema.to_string(),
                "schemaEncoding": "jsonschema",
            })
        })
        .collect();
    json!({"op": "advertise", "channels": channels})
}

/// A client's `subscribe` or `unsubscribe`, applied to `subscribed` (channel id →
/// subscription id); what was wrong with it, if anything, in words.
fn request(text: &str, channels: usize, subscribed: &mut HashMap<u32, u32>) -> Option<String> {
    let v: serde_json::Value = match serde_json::from_str(text) {
        Ok(v) => v,
        Err(e) => return Some(format!("not JSON: {e}")),
    };
    match v["op"].as_str() {
        Some("subscribe") => {
            let mut wrong = Vec::new();
            for s in v["subscriptions"].as_array().into_iter().flatten() {
                let (Some(id), Some(channel)) = (s["id"].as_u64(), s["channelId"].as_u64()) else {
                    wrong.push(format!("{s}: needs an id and a channelId"));
                    continue;
                };
                let (id, channel) = (id as u32, channel as u32);
                if channel == 0 || channel as usize > channels {
                    wrong.push(format!("no channel {channel}"));
                } else if subscribed.values().any(|s| *s == id) {
                    wrong.push(format!("subscription id {id} is in use"));
                } else {
                    subscribed.insert(channel, id);
                }
            }
            (!wrong.is_empty()).then(|| format!("subscribe: {}", wrong.join("; ")))
        }
        Some("unsubscribe") => {
            for id in v["subscriptionIds"].as_array().into_iter().flatten() {
                let id = id.as_u64().unwrap_or(u64::MAX) as u32;
                subscribed.retain(|_, s| *s != id);
            }
            None
        }
        Some(op) => Some(format!(
            "{op:?} is not supported: this server only shows (subscribe, unsubscribe)"
        )),
        None => Some("a message without \"op\"".into()),
    }
}

async fn send_json(socket: &mut WebSocket, v: &serde_json::Value) -> Result<(), axum::Error> {
    socket.send(Message::Text(v.to_string().into())).await
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn subscriptions_name_advertised_channels_and_ids_not_in_use() {
        let mut subs = HashMap::new();
        assert_eq!(
            request(
                r#"{"op":"subscribe","subscriptions":[{"id":7,"channelId":2}]}"#,
                3,
                &mut subs
            ),
            None
        );
        assert_eq!(subs.get(&2), Some(&7));
        let why = request(
            r#"{"op":"subscribe","subscriptions":[{"id":7,"channelId":3},{"id":8,"channelId":4}]}"#,
            3,
            &mut subs,
        )
        .expect("refused");
        assert!(
            why.contains("subscription id 7 is in use") && why.contains("no channel 4"),
            "{why}"
        );
        assert_eq!(
            request(
                r#"{"op":"unsubscribe","subscriptionIds":[7]}"#,
                3,
                &mut subs
            ),
            None
        );
        assert!(subs.is_empty());
        let why =
            request(r#"{"op":"setParameters","parameters":[]}"#, 3, &mut subs).expect("refused");
        assert!(why.contains("only shows"), "{why}");
    }
}
