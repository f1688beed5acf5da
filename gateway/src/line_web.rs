//! `gateway line web` (`supervisor web --line FILE`): the web view of a whole line, from a
//! host that runs no cell. The page of `supervisor web`, its views from the line: without
//! `?cell=`, the list of the line's cells (`{"kind": "cells", "cells": [...]}` every second,
//! as `cells --json` lists them); with `?cell=NAME`, that cell's description and frames as its
//! gateway publishes them on `rtc/v1/NAME/view`. It only shows: the page's buttons are
//! refused, with where to command from.

use crate::survey::{Failure, rows};
use gateway::keys::{CellKeys, CellName};
use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use std::time::Duration;
use web_view::{Feed, HttpStatus, View};
use zenoh::Wait;

/// The line as the page's feed.
struct Line {
    session: zenoh::Session,
    /// The list of cells.
    list: View,
    /// Each cell asked for: its view, fed by its subscriber (kept with it), and since when no
    /// page has looked at it.
    cells: Mutex<HashMap<String, Followed>>,
}

/// A cell whose view the room follows.
struct Followed {
    view: View,
    _subscriber: zenoh::pubsub::Subscriber<()>,
    unwatched_since: Option<std::time::Instant>,
}

/// How long a cell's view is followed after its last page left: its gateway samples the cell
/// only while someone follows.
const UNWATCHED: Duration = Duration::from_secs(10);

impl Line {
    /// Lets go of the views no page has looked at for [`UNWATCHED`].
    fn forget_unwatched(&self) {
        let Ok(mut cells) = self.cells.lock() else {
            return;
        };
        cells.retain(|_, f| {
            if f.view.frames.receiver_count() > 0 {
                f.unwatched_since = None;
                return true;
            }
            let since = *f
                .unwatched_since
                .get_or_insert_with(std::time::Instant::now);
            since.elapsed() < UNWATCHED
        });
    }
}

impl Feed for Line {
    fn view(&self, cell: Option<&str>) -> Result<View, String> {
        let Some(cell) = cell else {
            return Ok(self.list.clone());
        };
        let name = CellName::new(cell).map_err(|e| format!("cell {cell:?}: {e}"))?;
        let mut cells = self
            .cells
            .lock()
            .map_err(|_| "the feed failed".to_string())?;
        if let Some(f) = cells.get(cell) {
            return Ok(f.view.clone());
        }
        let view = View::default();
        let into = view.clone();
        let subscriber = self
            .session
            .declare_subscriber(name.view())
            .callback(move |sample| {
                let Ok(text) = sample.payload().try_to_string() else {
                    return;
                };
                let message: Arc<str> = Arc::from(text.as_ref());
                // The cell's description is kept for pages that connect later; frames go on.
                if serde_json::from_str::<serde_json::Value>(&message)
                    .is_ok_and(|m| m["kind"] == "hello")
                {
                    if let Ok(mut h) = into.hello.lock() {
                        *h = Some(message);
                    }
                } else {
                    let _ = into.frames.send(message);
                }
            })
            .wait()
            .map_err(|e| format!("cannot follow cell {cell}: {e}"))?;
        cells.insert(
            cell.to_string(),
            Followed {
                view: view.clone(),
                _subscriber: subscriber,
                unwatched_since: None,
            },
        );
        Ok(view)
    }

    fn action(&self, what: &str, cell: Option<&str>) -> Result<String, (HttpStatus, String)> {
        Err((
            HttpStatus::FORBIDDEN,
            format!(
                "the line's view only shows: {what} a cell with `supervisor {what} --remote {}` (signed, an operator's)",
                cell.unwrap_or("CELL")
            ),
        ))
    }
}

/// Serves the line's page on `listen` until SIGINT or SIGTERM.
pub fn serve(
    session: zenoh::Session,
    listen: std::net::SocketAddr,
    token: Option<String>,
) -> Result<u8, Failure> {
    runtime::signals::install().map_err(|e| (1, format!("cannot install signal handlers: {e}")))?;
    let line = Arc::new(Line {
        session: session.clone(),
        list: View::default(),
        cells: Mutex::new(HashMap::new()),
    });
    // The list, every second while the page is served; the views no page looks at any more
    // let go.
    {
        let (list, session, line) = (line.list.clone(), session.clone(), line.clone());
        std::thread::Builder::new()
            .name("line-list".into())
            .spawn(move || {
                while !runtime::signals::stop_requested() {
                    line.forget_unwatched();
                    if list.frames.receiver_count() > 0
                        && let Ok(cells) = rows(&session)
                    {
                        let m = serde_json::json!({"kind": "cells", "cells": cells});
                        let _ = list.frames.send(Arc::from(m.to_string()));
                    }
                    std::thread::sleep(Duration::from_secs(1));
                }
            })
            .map_err(|e| (1, format!("cannot start the list: {e}")))?;
    }
    let result = web_view::serve_page(listen, token, line, &mut |addr| {
        use std::io::Write;
        println!("serving the line on http://{addr}/");
        let _ = std::io::stdout().flush();
    });
    match result {
        Ok(()) => Ok(0),
        Err(e) => Err((if e.is_input() { 2 } else { 1 }, e.to_string())),
    }
}
