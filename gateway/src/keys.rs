//! The line's key space, version 1: every cell under `rtc/v1/<cell>/`.
//!
//! | key                     | what                                                      |
//! |-------------------------|-----------------------------------------------------------|
//! | `rtc/v1/<cell>/alive`   | the cell's presence (a liveliness token: gone with it)    |
//! | `rtc/v1/<cell>/status`  | `status --json`, downsampled; asked, the latest           |
//! | `rtc/v1/<cell>/events`  | each event, numbered, and any gap said                    |
//! | `rtc/v1/<cell>/control` | a signed command, answered with an acknowledgement or why |
//!
//! A cell's name is what its gateway publishes under: 1 to 32 of `a-z`, `0-9`, `-`, `_`,
//! starting with a letter or a digit, so that it is one chunk of a key expression and never a
//! wildcard.

use std::fmt;

/// The root of version 1 of the key space.
pub const ROOT: &str = "rtc/v1";

/// Every cell's presence token: what a control room subscribes to, to list the line.
pub const EVERY_CELL_ALIVE: &str = "rtc/v1/*/alive";

/// A cell's name on the line.
#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct CellName(String);

/// Why a name is not a cell's name.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct BadName {
    /// The name as given.
    pub name: String,
    /// What is wrong with it.
    pub why: &'static str,
}

impl fmt::Display for BadName {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{:?} is not a cell's name on the line: {} (1 to 32 of a-z, 0-9, '-', '_', starting with a letter or a digit)",
            self.name, self.why
        )
    }
}

impl std::error::Error for BadName {}

impl CellName {
    /// The longest name.
    pub const MAX_LEN: usize = 32;

    /// `name`, checked.
    pub fn new(name: &str) -> Result<Self, BadName> {
        let bad = |why| {
            Err(BadName {
                name: name.into(),
                why,
            })
        };
        if name.is_empty() {
            return bad("it is empty");
        }
        if name.len() > Self::MAX_LEN {
            return bad("it is longer than 32 characters");
        }
        if !name
            .bytes()
            .all(|b| b.is_ascii_lowercase() || b.is_ascii_digit() || b == b'-' || b == b'_')
        {
            return bad("it has a character other than a-z, 0-9, '-' and '_'");
        }
        if !name.as_bytes()[0].is_ascii_alphanumeric() {
            return bad("it starts with '-' or '_'");
        }
        Ok(Self(name.into()))
    }

    /// The name.
    pub fn as_str(&self) -> &str {
        &self.0
    }

    /// Its presence token's key.
    pub fn alive(&self) -> String {
        self.key("alive")
    }

    /// Its status' key.
    pub fn status(&self) -> String {
        self.key("status")
    }

    /// Its events' key.
    pub fn events(&self) -> String {
        self.key("events")
    }

    /// Its control queryable's key.
    pub fn control(&self) -> String {
        self.key("control")
    }

    fn key(&self, leaf: &str) -> String {
        format!("{ROOT}/{}/{leaf}", self.0)
    }

    /// The cell a key of version 1 is about (`rtc/v1/<cell>/...`), if it is one.
    pub fn of_key(key: &str) -> Option<Self> {
        let rest = key.strip_prefix(ROOT)?.strip_prefix('/')?;
        let (cell, _) = rest.split_once('/')?;
        Self::new(cell).ok()
    }
}

impl fmt::Display for CellName {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_name_is_one_chunk_of_a_key_never_a_wildcard() {
        for good in ["press-1", "a", "cell_2", "0line"] {
            let c = CellName::new(good).expect(good);
            assert_eq!(c.status(), format!("rtc/v1/{good}/status"));
            assert_eq!(CellName::of_key(&c.alive()), Some(c.clone()));
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
        assert_eq!(CellName::of_key("rtc/v2/a/status"), None);
        assert_eq!(CellName::of_key("rtc/v1/*/alive"), None);
    }
}
