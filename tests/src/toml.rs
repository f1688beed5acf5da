//! A cell's configuration edited as TOML (toml_edit), not as text: each edit names the key it
//! changes by its path, and fails the test when the key is not where it says (a renamed or
//! moved key cannot make an edit silently change nothing). Comments and layout are kept, so a
//! configuration error's line still points into a file a user would recognise.
//!
//! A path is keys separated by dots; a key of an array of tables (`axis`, `process`, `io`) is
//! followed by the element's `name` in brackets, or `*` for every element:
//! `motion.t_acc`, `process[iobridge].command`, `axis[*].following_error_limit`.

use std::path::PathBuf;
use toml_edit::{DocumentMut, Item, Table, TableLike, Value};

/// A cell's configuration being edited.
#[derive(Clone, Debug)]
pub struct CellToml(DocumentMut);

impl CellToml {
    /// `src` parsed; it must be TOML.
    pub fn parse(src: &str) -> Self {
        Self(src.parse().unwrap_or_else(|e| panic!("not TOML: {e}")))
    }

    /// The file `examples/<name>`.
    pub fn example(name: &str) -> Self {
        let path = crate::examples().join(name);
        Self::parse(
            &std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display())),
        )
    }

    /// Sets the existing key at `path` (in every element a `*` selects) to `value`.
    pub fn set(mut self, path: &str, value: impl Into<Value>) -> Self {
        let value = value.into();
        let (tables, key) = self.tables(path);
        for t in tables {
            let item = t
                .get_mut(key)
                .unwrap_or_else(|| panic!("{path}: no key {key:?} there"));
            let decor = item.as_value().map(|v| v.decor().clone());
            let mut v = value.clone();
            if let Some(d) = decor {
                *v.decor_mut() = d;
            }
            *item = Item::Value(v);
        }
        self
    }

    /// Adds `path`, a key that is not there yet, with `value`.
    pub fn add(mut self, path: &str, value: impl Into<Value>) -> Self {
        let value = value.into();
        let (tables, key) = self.tables(path);
        for t in tables {
            assert!(!t.contains_key(key), "{path}: {key:?} is there already");
            t.insert(key, Item::Value(value.clone()));
        }
        self
    }

    /// Appends `table` to the array of tables at `path` (made when there is none).
    pub fn push(mut self, path: &str, table: Table) -> Self {
        let (parents, key) = self.tables(path);
        for t in parents {
            let array = t
                .entry(key)
                .or_insert(Item::ArrayOfTables(Default::default()));
            array
                .as_array_of_tables_mut()
                .unwrap_or_else(|| panic!("{path}: not an array of tables"))
                .push(table.clone());
        }
        self
    }

    /// Adds the table `key` at the top (`network`), which must not be there yet.
    pub fn table(mut self, key: &str, table: Table) -> Self {
        assert!(!self.0.contains_key(key), "{key:?} is there already");
        self.0.insert(key, Item::Table(table));
        self
    }

    /// Removes the element `name` of the array of tables `array` (`process`, `io`, ...).
    pub fn remove(mut self, array: &str, name: &str) -> Self {
        let a = self
            .0
            .get_mut(array)
            .and_then(Item::as_array_of_tables_mut)
            .unwrap_or_else(|| panic!("no array of tables {array:?}"));
        let k = a
            .iter()
            .position(|t| named(t, name))
            .unwrap_or_else(|| panic!("{array}: no element named {name:?}"));
        a.remove(k);
        self
    }

    /// Written into a scratch file of `test` called `name`.
    pub fn write(&self, test: &str, name: &str) -> PathBuf {
        crate::scratch(test, name, &self.to_string())
    }

    /// The tables that hold the last key of `path`, and that key.
    fn tables<'a, 'p>(&'a mut self, path: &'p str) -> (Vec<&'a mut dyn TableLike>, &'p str) {
        let mut parts: Vec<&str> = path.split('.').collect();
        let key = parts.pop().unwrap_or_else(|| panic!("an empty path"));
        let mut at: Vec<&mut dyn TableLike> = vec![self.0.as_table_mut()];
        for part in parts {
            let (name, which) = match part.split_once('[') {
                Some((n, rest)) => (n, Some(rest.trim_end_matches(']'))),
                None => (part, None),
            };
            let mut next = Vec::new();
            for t in at {
                let item = t
                    .get_mut(name)
                    .unwrap_or_else(|| panic!("{path}: no {name:?} there"));
                match which {
                    None => next.push(
                        item.as_table_like_mut()
                            .unwrap_or_else(|| panic!("{path}: {name:?} is not a table")),
                    ),
                    Some(sel) => {
                        let array = item.as_array_of_tables_mut().unwrap_or_else(|| {
                            panic!("{path}: {name:?} is not an array of tables")
                        });
                        let before = next.len();
                        next.extend(
                            array
                                .iter_mut()
                                .filter(|t| sel == "*" || named(t, sel))
                                .map(|t| t as &mut dyn TableLike),
                        );
                        assert!(next.len() > before, "{path}: no {name} named {sel:?}");
                    }
                }
            }
            at = next;
        }
        (at, key)
    }
}

/// `t` has `name = "<name>"`.
fn named(t: &Table, name: &str) -> bool {
    t.get("name").and_then(Item::as_str) == Some(name)
}

impl std::fmt::Display for CellToml {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        self.0.fmt(f)
    }
}

/// A TOML array of strings (a process' `command`).
pub fn strings(items: &[&str]) -> Value {
    Value::Array(items.iter().copied().collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    const SRC: &str = "[motion]\nt_acc = 0.5 # s\n\n[[axis]]\nname = \"x\"\nvmax = 1.0\n\n\
                       [[axis]]\nname = \"y\"\nvmax = 2.0\n";

    #[test]
    fn a_set_keeps_the_comment_and_reaches_the_named_or_every_element() {
        let t = CellToml::parse(SRC)
            .set("motion.t_acc", 0.25)
            .set("axis[y].vmax", 3.0);
        let s = t.to_string();
        assert!(s.contains("t_acc = 0.25 # s"), "{s}");
        assert!(s.contains("vmax = 1.0") && s.contains("vmax = 3.0"), "{s}");
        let s = CellToml::parse(SRC).set("axis[*].vmax", 9.0).to_string();
        assert_eq!(s.matches("vmax = 9.0").count(), 2, "{s}");
    }

    #[test]
    #[should_panic(expected = "no key \"t_dec\"")]
    fn a_key_that_is_not_there_fails_the_test() {
        let _ = CellToml::parse(SRC).set("motion.t_dec", 1.0);
    }

    #[test]
    #[should_panic(expected = "no axis named \"z\"")]
    fn an_element_that_is_not_there_fails_the_test() {
        let _ = CellToml::parse(SRC).set("axis[z].vmax", 1.0);
    }

    #[test]
    fn add_push_and_remove() {
        let mut inject = Table::new();
        inject.insert("axis", toml_edit::value("y"));
        let s = CellToml::parse(SRC)
            .add("motion.t_dec", 1.0)
            .remove("axis", "x")
            .push("motion.inject", inject)
            .to_string();
        assert!(s.contains("t_dec = 1.0"), "{s}");
        assert!(!s.contains("name = \"x\""), "{s}");
        assert!(s.contains("[[motion.inject]]\naxis = \"y\""), "{s}");
    }
}
