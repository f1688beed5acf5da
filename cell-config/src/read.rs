//! The configuration's TOML read into its types with every problem found at once, each where
//! it is.
//!
//! The parser reports every syntax error it recovers from. serde stops at the first problem of
//! a document (a value of the wrong type, an unknown key, a missing one), so [`read`] reads the
//! document again without the value it named (the innermost key or array element whose place
//! holds the error), until the rest reads. A problem of a table from which a value was taken
//! away ("missing field" once the bad value is gone) is the removal's doing, not the user's,
//! and is not reported.

use serde::de::DeserializeOwned;
use std::ops::Range;
use toml::Spanned;
use toml::de::{DeArray, DeTable, DeValue};

/// One problem: its place in the source (bytes), when the parser knows it, and what is wrong.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Problem {
    /// Where, in bytes of the source.
    pub span: Option<Range<usize>>,
    /// What is wrong, in the parser's or serde's words.
    pub message: String,
}

/// A value's place in the document: keys and array indexes from the root.
#[derive(Clone, Debug, PartialEq)]
enum Step {
    Key(String),
    Index(usize),
}

/// At most this many problems of types are reported (each costs one more reading).
const MOST: usize = 64;

/// `src` as a `T`, or every problem found in it, in the order found.
pub(crate) fn read<T: DeserializeOwned>(src: &str) -> Result<T, Vec<Problem>> {
    let (doc, syntax) = DeTable::parse_recoverable(src);
    if !syntax.is_empty() {
        return Err(syntax.iter().map(problem).collect());
    }
    let span = doc.span();
    let mut doc = Spanned::new(span, DeValue::Table(doc.into_inner()));
    let mut found: Vec<Problem> = Vec::new();
    let mut removed: Vec<Vec<Step>> = Vec::new();
    while found.len() < MOST {
        let e = match T::deserialize(toml::de::ValueDeserializer::from(doc.clone())) {
            Ok(t) if found.is_empty() => return Ok(t),
            Ok(_) => break,
            Err(e) => e,
        };
        let path = e
            .span()
            .map_or_else(Vec::new, |s| innermost(doc.get_ref(), &s));
        // A table from which a bad value was taken: its problem now is that value's absence.
        let caused_by_us = removed.iter().any(|r| r.starts_with(&path));
        if !caused_by_us {
            found.push(problem(&e));
        }
        if path.is_empty() || !remove(doc.get_mut(), &path) {
            break;
        }
        removed.push(path);
    }
    Err(found)
}

fn problem(e: &toml::de::Error) -> Problem {
    Problem {
        span: e.span(),
        message: e.message().trim().to_string(),
    }
}

/// Whether `outer` holds `inner`.
fn holds(outer: &Range<usize>, inner: &Range<usize>) -> bool {
    outer.start <= inner.start && inner.end <= outer.end
}

/// The path of the deepest key (its name or its value) or array element whose place holds
/// `span`; empty when none does (the whole document's problem). A table's own place is its
/// header only (`[motion]`), so every value is looked at, not only those inside a match.
fn innermost(root: &DeValue<'_>, span: &Range<usize>) -> Vec<Step> {
    fn walk(at: &DeValue<'_>, span: &Range<usize>, path: &mut Vec<Step>, best: &mut Vec<Step>) {
        let children: Vec<(Step, &Spanned<DeValue<'_>>, bool)> = match at {
            DeValue::Table(t) => t
                .iter()
                .map(|(k, v)| {
                    (
                        Step::Key(k.get_ref().to_string()),
                        v,
                        holds(&k.span(), span),
                    )
                })
                .collect(),
            DeValue::Array(a) => (a.iter().enumerate())
                .map(|(i, v)| (Step::Index(i), v, false))
                .collect(),
            _ => Vec::new(),
        };
        for (step, value, on_key) in children {
            path.push(step);
            if (on_key || holds(&value.span(), span)) && path.len() > best.len() {
                *best = path.clone();
            }
            if !on_key {
                walk(value.get_ref(), span, path, best);
            }
            path.pop();
        }
    }
    let mut best = Vec::new();
    walk(root, span, &mut Vec::new(), &mut best);
    best
}

/// Takes the value at `path` out of the document; false when it is not there.
fn remove(mut at: &mut DeValue<'_>, path: &[Step]) -> bool {
    let Some((last, parents)) = path.split_last() else {
        return false;
    };
    for step in parents {
        let next = match (step, at) {
            (Step::Key(k), DeValue::Table(t)) => t.get_mut(k.as_str()),
            (Step::Index(i), DeValue::Array(a)) => a.get_mut(*i),
            _ => None,
        };
        let Some(next) = next else { return false };
        at = next.get_mut();
    }
    match (last, at) {
        (Step::Key(k), DeValue::Table(t)) => t.remove(k.as_str()).is_some(),
        (Step::Index(i), DeValue::Array(a)) if *i < a.len() => {
            let all = std::mem::replace(a, DeArray::new());
            for (j, v) in all.iter().enumerate() {
                if j != *i {
                    a.push(v.clone());
                }
            }
            true
        }
        _ => false,
    }
}
