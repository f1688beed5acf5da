//! What is wrong with a configuration and where: the key paths validation names, placed in
//! the file (line and column) for the user.

use std::fmt;
use std::ops::Range;

/// What is wrong with a configuration: every problem found, each where it is.
#[derive(Clone, Debug, PartialEq)]
pub struct ConfigError {
    /// File name as given.
    pub file: String,
    /// At least one, in the file's order.
    pub problems: Vec<Located>,
}

/// One problem and where it is.
#[derive(Clone, Debug, PartialEq)]
pub struct Located {
    /// 1-based line (0 when unknown).
    pub line: usize,
    /// 1-based column (0 when unknown).
    pub col: usize,
    /// What is wrong.
    pub message: String,
}

impl ConfigError {
    /// One problem at a known place (or at none: line 0).
    pub(crate) fn one(file: &str, line: usize, col: usize, message: String) -> Self {
        Self {
            file: file.into(),
            problems: vec![Located { line, col, message }],
        }
    }
}

/// Every problem on its own line: `file:line:col: message`.
impl fmt::Display for ConfigError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (k, p) in self.problems.iter().enumerate() {
            if k > 0 {
                f.write_str("\n")?;
            }
            if p.line > 0 {
                write!(f, "{}:{}:{}: {}", self.file, p.line, p.col, p.message)?;
            } else {
                write!(f, "{}: {}", self.file, p.message)?;
            }
        }
        Ok(())
    }
}

impl std::error::Error for ConfigError {}

/// One step of a key path, to find where a value is written.
#[derive(Clone, Copy, Debug)]
pub(crate) enum Seg {
    Key(&'static str),
    Index(usize),
}

pub(crate) fn locate(src: &str, path: &[Seg]) -> Option<Range<usize>> {
    let doc = toml_edit::Document::parse(src).ok()?;
    let mut table: &dyn toml_edit::TableLike = doc.as_table();
    let mut span = None;
    let mut segs = path.iter().peekable();
    while let Some(seg) = segs.next() {
        let Seg::Key(k) = *seg else { break };
        let Some((key, item)) = table.get_key_value(k) else {
            break;
        };
        // The key's own place is the most telling; fall back to its value's.
        span = key.span().or_else(|| item.span()).or(span);
        match segs.peek() {
            Some(Seg::Index(i)) => {
                segs.next();
                let Some(t) = item.as_array_of_tables().and_then(|a| a.get(*i)) else {
                    break;
                };
                span = t.span().or(span);
                table = t;
            }
            Some(Seg::Key(_)) => match item.as_table_like() {
                Some(t) => table = t,
                None => break,
            },
            None => {}
        }
    }
    span
}

/// A problem found by validation: the key path where it is, and what is wrong.
pub(crate) type Problem = (Vec<Seg>, String);

pub(crate) fn positive(v: f64) -> bool {
    v.is_finite() && v > 0.0
}

pub(crate) fn non_negative(v: f64) -> bool {
    v.is_finite() && v >= 0.0
}

/// `problems` (at least one) placed in `src` by their key paths, in the file's order.
pub(crate) fn located(src: &str, file: &str, problems: Vec<Problem>) -> ConfigError {
    placed(
        src,
        file,
        problems
            .into_iter()
            .map(|(path, message)| (locate(src, &path), message)),
    )
}

/// `problems` (at least one) at their bytes of `src` (none: line 0), in the file's order.
pub(crate) fn placed(
    src: &str,
    file: &str,
    problems: impl IntoIterator<Item = (Option<Range<usize>>, String)>,
) -> ConfigError {
    let mut problems: Vec<Located> = problems
        .into_iter()
        .map(|(span, message)| {
            let (line, col) = span.map_or((0, 0), |s| line_col(src, s.start));
            Located { line, col, message }
        })
        .collect();
    problems.sort_by_key(|p| (p.line, p.col));
    ConfigError {
        file: file.into(),
        problems,
    }
}

fn line_col(src: &str, offset: usize) -> (usize, usize) {
    let before = &src[..offset.min(src.len())];
    let line = before.matches('\n').count() + 1;
    let col = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
    (line, col)
}
