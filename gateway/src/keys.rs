//! The line's key space, version 1: every cell under `rtc/v1/<cell>/`.
//!
//! | key                     | what                                                      |
//! |-------------------------|-----------------------------------------------------------|
//! | `rtc/v1/<cell>/alive`   | the cell's presence (a liveliness token: gone with it)    |
//! | `rtc/v1/<cell>/status`  | `status --json`, downsampled; asked, the latest           |
//! | `rtc/v1/<cell>/events`  | each event, numbered, and any gap said                    |
//! | `rtc/v1/<cell>/control` | a signed command, answered with an acknowledgement or why |
//! | `rtc/v1/<cell>/record`  | the recording stream: every service's messages, in batches |
//! | `rtc/v1/<cell>/record/topics` | asked: the stream's topics and their JSON Schemas   |
//! | `rtc/v1/<cell>/record/flush`  | asked: the batch that holds all the cell published before |
//! | `rtc/v1/<cell>/view`    | the web view's messages (the cell's description, frames)  |
//!
//! A cell's name is what its gateway publishes under: 1 to 32 of `a-z`, `0-9`, `-`, `_`,
//! starting with a letter or a digit, so that it is one chunk of a key expression and never a
//! wildcard.

/// The root of version 1 of the key space.
pub const ROOT: &str = "rtc/v1";

/// Every cell's presence token: what a control room subscribes to, to list the line.
pub const EVERY_CELL_ALIVE: &str = "rtc/v1/*/alive";

pub use cell_config::network::{BadName, CellName};

/// A cell's keys.
pub trait CellKeys {
    /// Its presence token's key.
    fn alive(&self) -> String;
    /// Its status' key.
    fn status(&self) -> String;
    /// Its events' key.
    fn events(&self) -> String;
    /// Its control queryable's key.
    fn control(&self) -> String;
    /// Its recording stream's key.
    fn record(&self) -> String;
    /// Its recording topics' key.
    fn record_topics(&self) -> String;
    /// Its recording flush's key.
    fn record_flush(&self) -> String;
    /// Its web view's key.
    fn view(&self) -> String;
}

impl CellKeys for CellName {
    fn alive(&self) -> String {
        key(self, "alive")
    }

    fn status(&self) -> String {
        key(self, "status")
    }

    fn events(&self) -> String {
        key(self, "events")
    }

    fn control(&self) -> String {
        key(self, "control")
    }

    fn record(&self) -> String {
        key(self, "record")
    }

    fn record_topics(&self) -> String {
        key(self, "record/topics")
    }

    fn record_flush(&self) -> String {
        key(self, "record/flush")
    }

    fn view(&self) -> String {
        key(self, "view")
    }
}

fn key(cell: &CellName, leaf: &str) -> String {
    format!("{ROOT}/{cell}/{leaf}")
}

/// The cell a key of version 1 is about (`rtc/v1/<cell>/...`), if it is one.
pub fn cell_of(key: &str) -> Option<CellName> {
    let rest = key.strip_prefix(ROOT)?.strip_prefix('/')?;
    let (cell, _) = rest.split_once('/')?;
    CellName::new(cell).ok()
}
#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_name_is_one_chunk_of_a_key_never_a_wildcard() {
        for good in ["press-1", "a", "cell_2", "0line"] {
            let c = CellName::new(good).expect(good);
            assert_eq!(c.status(), format!("rtc/v1/{good}/status"));
            assert_eq!(cell_of(&c.alive()), Some(c.clone()));
        }
        for (bad, why) in [
            ("", "empty"),
            ("*", "character"),
            ("a/b", "character"),
            ("**", "character"),
            ("$x", "character"),
            ("Press", "character"),
            ("-a", "starts"),
            (&"x".repeat(33), "longer"),
        ] {
            let e = CellName::new(bad).expect_err(bad);
            assert!(e.to_string().contains(why), "{bad:?}: {e}");
        }
        assert_eq!(cell_of("rtc/v2/a/status"), None);
        assert_eq!(cell_of("rtc/v1/*/alive"), None);
    }
}
