//! The cell's web view on the line (`rtc/v1/<cell>/view`): while anyone subscribes, the web
//! view's own sampler (`web_view::sample`, the one `supervisor web` runs on the cell's host)
//! reads the cell, and its messages go out as they come: the cell's description (`hello`,
//! again every two seconds for a late joiner) and 30 frames a second. Nobody subscribed:
//! nothing is read or sent.
//!
//! # Not real-time
//! A thread of the gateway's own at the ordinary priority; the frames are dropped rather than
//! queued when the network is slower (the next one says everything again).

use crate::OnTheLine;
use gateway::keys::CellKeys;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};
use web_view::View;
use web_view::broadcast::error::TryRecvError;
use zenoh::Wait;
use zenoh::qos::CongestionControl;

/// How often the thread looks for frames and subscribers.
const TICK: Duration = Duration::from_millis(10);

/// The cell's description again this often, for a late joiner.
const HELLO_AGAIN: Duration = Duration::from_secs(2);

/// A running sampler.
struct Sampling {
    view: View,
    frames: web_view::broadcast::Receiver<Arc<str>>,
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
    hello: Option<(Arc<str>, Instant)>,
}

impl Drop for Sampling {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// Serves the view until the gateway leaves the line or the process is asked to stop, or the
/// session fails.
pub fn serve(line: OnTheLine<'_>) -> zenoh::Result<()> {
    let stream = line
        .session
        .declare_publisher(line.name.view())
        .congestion_control(CongestionControl::Drop)
        .wait()?;
    let mut sampling: Option<Sampling> = None;
    // The sampler runs on a moment after the last subscriber left, as the recording does.
    let mut demand = crate::recording::Demand::default();
    loop {
        if line.over() {
            return Ok(());
        }
        let wanted = demand.wanted(stream.matching_status().wait().is_ok_and(|m| m.matching()));
        if !wanted {
            sampling = None;
        } else if sampling.is_none() {
            let view = View::default();
            let stop = Arc::new(AtomicBool::new(false));
            let (v, i, s) = (view.clone(), *line.instance, stop.clone());
            let thread = std::thread::Builder::new()
                .name("view".into())
                .spawn(move || web_view::sample(i, &v, &s))
                .map_err(|e| format!("cannot start the view's sampler: {e}"))?;
            sampling = Some(Sampling {
                frames: view.frames.subscribe(),
                view,
                stop,
                thread: Some(thread),
                hello: None,
            });
        }
        if let Some(s) = &mut sampling {
            let hello = s.view.hello.lock().ok().and_then(|h| h.clone());
            if let Some(h) = hello {
                let again = match &s.hello {
                    Some((sent, at)) => *sent != h || at.elapsed() >= HELLO_AGAIN,
                    None => true,
                };
                if again {
                    stream.put(h.as_bytes().to_vec()).wait()?;
                    s.hello = Some((h, Instant::now()));
                }
            }
            loop {
                match s.frames.try_recv() {
                    Ok(f) => stream.put(f.as_bytes().to_vec()).wait()?,
                    Err(TryRecvError::Lagged(_)) => {}
                    Err(_) => break,
                }
            }
        }
        std::thread::sleep(TICK);
    }
}
