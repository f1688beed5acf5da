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

/// Whether a file can be written at `path` (`flag` names it in the error): its directory
/// exists and this user may write there, and it is not a directory or a file this user may
/// not write. Checked before anything starts, so a run is never lost to a typo in an
/// output's name.
pub fn writable(path: &std::path::Path, flag: &str) -> Result<(), String> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => std::path::Path::new("."),
    };
    if !dir.is_dir() {
        return Err(format!(
            "{flag} {}: the directory {} does not exist",
            path.display(),
            dir.display()
        ));
    }
    if path.is_dir() {
        return Err(format!("{flag} {}: is a directory", path.display()));
    }
    use nix::unistd::{AccessFlags, access};
    let (what, check) = if path.exists() {
        ("the file", path)
    } else {
        ("the directory", dir)
    };
    access(check, AccessFlags::W_OK).map_err(|e| {
        format!(
            "{flag} {}: {what} {} cannot be written ({})",
            path.display(),
            check.display(),
            e.desc()
        )
    })
}
