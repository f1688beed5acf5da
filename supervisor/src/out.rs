//! Lines for the user on stderr (a run's events and progress) that never block the
//! supervisor: once [`set`] is called they go through a lossy, non-blocking writer (a full
//! pipe or a paused terminal loses lines, never cycles of the supervisor's loop); before that,
//! straight to stderr.

use std::io::Write;
use std::sync::{Mutex, OnceLock};

static WRITER: OnceLock<Mutex<tracing_appender::non_blocking::NonBlocking>> = OnceLock::new();

/// Routes [`line`] and [`text`] through `w` from now on.
pub fn set(w: tracing_appender::non_blocking::NonBlocking) {
    let _ = WRITER.set(Mutex::new(w));
}

/// Writes `s` as is.
pub fn text(s: &str) {
    match WRITER.get() {
        Some(w) => {
            if let Ok(mut w) = w.lock() {
                let _ = w.write_all(s.as_bytes());
            }
        }
        None => eprint!("{s}"),
    }
}

/// Writes `s` and a newline.
pub fn line(s: &str) {
    text(&format!("{s}\n"));
}
