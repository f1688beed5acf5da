//! The cell's recording on the line (`rtc/v1/<cell>/record`): while anyone subscribes to the
//! stream, or asked for its topics a moment ago, a recorder source (`recorder::Source`, the
//! one `supervisor record` uses on the cell's host) reads every service of the cell, and its
//! messages go out in numbered batches. Nobody listening: no source, no subscriber ports taken
//! in the cell, nothing sent.
//!
//! # Not real-time
//! A thread of the gateway's own, at the ordinary priority. The stream is reliable and
//! blocks when the network or a room's recorder is slower than the cell: the source then
//! falls behind, and what the cell's shared memory no longer holds is counted per topic as
//! lost, as a local recording counts it. The cell never waits.

use crate::OnTheLine;
use gateway::keys::CellKeys;
use gateway::wire::{RecordBatch, RecordFlushed, RecordTopics};
use recorder::Source;
use serde_json::value::RawValue;
use std::time::{Duration, Instant};
use zenoh::Wait;
use zenoh::qos::CongestionControl;

/// How often the source's messages go out.
const BATCH: Duration = Duration::from_millis(10);

/// An empty batch at least this often while the source runs: the room knows the cell is there.
const HEARTBEAT: Duration = Duration::from_millis(500);

/// How long a stream's source stays without a subscriber after the last one left (or after
/// a question for the recording's topics, which comes before the subscription's first
/// batch).
const LINGER: Duration = Duration::from_secs(2);

/// Whether a stream of the line is wanted: someone subscribed (or asked) within [`LINGER`].
/// What the recording and the web view's streams share: their sources run only then.
#[derive(Debug, Default)]
pub struct Demand {
    last: Option<Instant>,
}

impl Demand {
    /// `asked`: a subscriber matches, or a question came, now.
    pub fn wanted(&mut self, asked: bool) -> bool {
        let now = Instant::now();
        if asked {
            self.last = Some(now);
        }
        self.last.is_some_and(|t| now.duration_since(t) < LINGER)
    }
}

/// The messages of one batch, in bytes, at most (one message larger goes alone): well below
/// the largest message the line takes ([`gateway::link::MAX_MESSAGE`]).
const BATCH_BYTES: usize = gateway::link::MAX_MESSAGE / 4;

/// Topic questions waiting at most.
const QUESTIONS: usize = 16;

/// A running source and its stream's numbering.
struct Running {
    source: Source,
    topics: RecordTopics,
    seq: u64,
    sent: Instant,
}

/// Serves the recording stream until the gateway leaves the line or the process is asked to
/// stop, or the session fails.
pub fn serve(line: OnTheLine<'_>) -> zenoh::Result<()> {
    let OnTheLine {
        session,
        instance,
        name,
        ..
    } = line;
    // Reliable (Zenoh's default), and blocking rather than dropping.
    let stream = session
        .declare_publisher(name.record())
        .congestion_control(CongestionControl::Block)
        .wait()?;
    let questions = session
        .declare_queryable(name.record_topics())
        .with(zenoh::handlers::RingChannel::new(QUESTIONS))
        .wait()?;
    let flushes = session
        .declare_queryable(name.record_flush())
        .with(zenoh::handlers::RingChannel::new(QUESTIONS))
        .wait()?;
    let topics_key = name.record_topics();
    let flush_key = name.record_flush();
    let node_name = format!("gateway-record-{}", std::process::id());
    let mut running: Option<Running> = None;
    let mut demand = Demand::default();
    // A source that cannot open is said once, and tried again a second later.
    let mut said = String::new();
    let mut retry_at: Option<Instant> = None;
    loop {
        if line.over() {
            return Ok(());
        }
        let now = Instant::now();
        let mut asked = Vec::new();
        while let Ok(Some(q)) = questions.try_recv() {
            asked.push(q);
        }
        // Asked before this turn's drain: answered after it, with the batch that holds it.
        let mut flush = Vec::new();
        while let Ok(Some(q)) = flushes.try_recv() {
            flush.push(q);
        }
        let matched = stream.matching_status().wait().is_ok_and(|m| m.matching());
        let wanted = demand.wanted(matched || !asked.is_empty());
        if !wanted && running.take().is_some() {
            tracing::info!("the recording on the line stopped: nobody reads it");
        }
        if wanted && running.is_none() && retry_at.is_none_or(|t| now >= t) {
            match Source::open(instance, &node_name) {
                Ok(source) => {
                    let topics = RecordTopics {
                        source_started_ms: gateway::auth::now_ms(),
                        topics: source.topics(),
                    };
                    tracing::info!(
                        "recording the cell on the line ({} topics)",
                        topics.topics.len()
                    );
                    said.clear();
                    running = Some(Running {
                        source,
                        topics,
                        seq: 0,
                        sent: now,
                    });
                }
                Err(e) => {
                    // Not again at once: an attempt may wait 2 s for the configuration.
                    retry_at = Some(now + Duration::from_secs(1));
                    let why = format!("the cell cannot be recorded: {e}");
                    if why != said {
                        tracing::warn!("{why}");
                        said = why;
                    }
                }
            }
        }
        for q in asked {
            let _ = match &running {
                Some(r) => q
                    .reply(
                        &topics_key,
                        serde_json::to_vec(&r.topics).unwrap_or_default(),
                    )
                    .wait(),
                None => q.reply_err(said.clone()).wait(),
            };
        }
        if let Some(r) = &mut running {
            let mut messages = Vec::new();
            let drained = r.source.drain(&mut |k, t, data| {
                let text = String::from_utf8(data.to_vec()).map_err(|e| e.to_string())?;
                let raw = RawValue::from_string(text).map_err(|e| e.to_string())?;
                messages.push((k as u32, t, raw));
                Ok(())
            });
            if let Err(e) = drained {
                tracing::warn!("the recording on the line: {e}");
            }
            if !messages.is_empty() || r.sent.elapsed() >= HEARTBEAT {
                let lost: Vec<u64> = r.source.counts().into_iter().map(|c| c.2).collect();
                // At most BATCH_BYTES of messages a batch (after a stall the source holds
                // many): far below what the line takes in one message.
                let mut messages = messages.into_iter().peekable();
                loop {
                    let mut batch = Vec::new();
                    let mut bytes = 0;
                    while let Some(m) =
                        messages.next_if(|m| bytes == 0 || bytes + m.2.get().len() <= BATCH_BYTES)
                    {
                        bytes += m.2.get().len();
                        batch.push(m);
                    }
                    r.seq += 1;
                    let batch = RecordBatch {
                        source_started_ms: r.topics.source_started_ms,
                        seq: r.seq,
                        messages: batch,
                        lost: lost.clone(),
                    };
                    stream
                        .put(serde_json::to_vec(&batch).unwrap_or_default())
                        .wait()?;
                    if messages.peek().is_none() {
                        break;
                    }
                }
                r.sent = Instant::now();
            }
        }
        for q in flush {
            let _ = match &running {
                Some(r) => q
                    .reply(
                        &flush_key,
                        serde_json::to_vec(&RecordFlushed {
                            source_started_ms: r.topics.source_started_ms,
                            seq: r.seq,
                        })
                        .unwrap_or_default(),
                    )
                    .wait(),
                None => q.reply_err("no recording runs").wait(),
            };
        }
        std::thread::sleep(BATCH);
    }
}
