//! cyclictest's histogram file (`--histfile`), written and read back.
//!
//! The format, as rt-tests 2.x writes it (`cyclictest -h US --histfile FILE`):
//!
//! ```text
//! # Histogram
//! 000000 000000<TAB>000000     one line per µs bin: bin, then one tab-separated column
//! 000001 000012<TAB>000003     per thread (here: per series)
//! ...
//! # Total: 000009998 000009999    samples inside the range, per column
//! # Min Latencies: 00003 00003    µs, integer
//! # Avg Latencies: 00006 00005
//! # Max Latencies: 00123 00097
//! # Histogram Overflows: 00002 00001
//! # Histogram Overflow at cycle number:
//! # Thread 0: 00017 04711
//! # Thread 1: 00815
//! ```
//!
//! Comment lines before `# Histogram` are free (cyclictest puts its `/dev/cpu_dma_latency`
//! line there; we name the columns). A `# Thread` line lists the first overflow cycle numbers
//! and ends in `# NNNNN others` when there were more.

use crate::measure::Series;
use std::fmt::Write;

/// One column of a histogram file.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Column {
    /// Count per 1-µs bin.
    pub bins: Vec<u64>,
    /// Samples inside the range (`# Total`).
    pub total: u64,
    /// µs.
    pub min_us: u64,
    /// µs.
    pub avg_us: u64,
    /// µs.
    pub max_us: u64,
    /// Samples beyond the range.
    pub overflows: u64,
    /// The overflow cycle numbers listed.
    pub overflow_cycles: Vec<u64>,
    /// Overflows not listed (`# NNNNN others`).
    pub others: u64,
}

impl Column {
    /// The column of a measured series.
    pub fn of(s: &Series) -> Self {
        let h = &s.hist;
        Self {
            bins: s.linear.clone(),
            total: s.linear.iter().sum(),
            min_us: h.min_ns / 1000,
            avg_us: (h.mean_ns().unwrap_or(0.0) / 1000.0) as u64,
            max_us: h.max_ns / 1000,
            overflows: s.overflows,
            overflow_cycles: s.overflow_cycles.clone(),
            others: s.overflows - s.overflow_cycles.len() as u64,
        }
    }
}

/// Writes `columns` (all with the same number of bins) in cyclictest's format, after the
/// `comments` (each written as a `# ` line).
pub fn write(columns: &[Column], comments: &[String]) -> String {
    let mut out = String::new();
    for c in comments {
        let _ = writeln!(out, "# {c}");
    }
    out += "# Histogram\n";
    let bins = columns.first().map_or(0, |c| c.bins.len());
    for i in 0..bins {
        let _ = write!(out, "{i:06}");
        for (j, c) in columns.iter().enumerate() {
            let sep = if j == 0 { ' ' } else { '\t' };
            let _ = write!(out, "{sep}{:06}", c.bins[i]);
        }
        out.push('\n');
    }
    let row = |out: &mut String, title: &str, width: usize, f: &dyn Fn(&Column) -> u64| {
        out.push_str(title);
        for c in columns {
            let _ = write!(out, " {:0width$}", f(c));
        }
        out.push('\n');
    };
    row(&mut out, "# Total:", 9, &|c| c.total);
    row(&mut out, "# Min Latencies:", 5, &|c| c.min_us);
    row(&mut out, "# Avg Latencies:", 5, &|c| c.avg_us);
    row(&mut out, "# Max Latencies:", 5, &|c| c.max_us);
    row(&mut out, "# Histogram Overflows:", 5, &|c| c.overflows);
    out += "# Histogram Overflow at cycle number:\n";
    for (j, c) in columns.iter().enumerate() {
        let _ = write!(out, "# Thread {j}:");
        for n in &c.overflow_cycles {
            let _ = write!(out, " {n:05}");
        }
        if c.others > 0 {
            let _ = write!(out, " # {:05} others", c.others);
        }
        out.push('\n');
    }
    out.push('\n');
    out
}

/// Reads a histogram file back (ours or cyclictest's). Errors name the line.
pub fn parse(text: &str) -> Result<Vec<Column>, String> {
    let mut lines = text.lines().enumerate().map(|(i, l)| (i + 1, l));
    // Free comments until "# Histogram".
    loop {
        match lines.next() {
            Some((_, "# Histogram")) => break,
            Some((_, l)) if l.starts_with('#') || l.trim().is_empty() => {}
            Some((n, l)) => return Err(format!("line {n}: {l:?} before \"# Histogram\"")),
            None => return Err("no \"# Histogram\" line".into()),
        }
    }
    let mut columns: Vec<Column> = Vec::new();
    let numbers = |n: usize, rest: &str| -> Result<Vec<u64>, String> {
        rest.split_whitespace()
            .map(|w| {
                w.parse::<u64>()
                    .map_err(|_| format!("line {n}: {w:?} is not a count"))
            })
            .collect()
    };
    let mut footer = Vec::new();
    for (n, l) in lines.by_ref() {
        if l.starts_with('#') {
            footer.push((n, l));
            break;
        }
        let v = numbers(n, l)?;
        let (bin, counts) = v.split_first().ok_or(format!("line {n}: empty"))?;
        if columns.is_empty() {
            columns = vec![Column::default(); counts.len()];
        }
        if counts.len() != columns.len() {
            return Err(format!(
                "line {n}: {} columns, {} expected",
                counts.len(),
                columns.len()
            ));
        }
        if *bin != columns[0].bins.len() as u64 {
            return Err(format!(
                "line {n}: bin {bin}, {} expected",
                columns[0].bins.len()
            ));
        }
        for (c, v) in columns.iter_mut().zip(counts) {
            c.bins.push(*v);
        }
    }
    footer.extend(lines.filter(|(_, l)| !l.trim().is_empty()));
    let mut footer = footer.into_iter();
    let mut field = |title: &str, set: &dyn Fn(&mut Column, u64)| -> Result<(), String> {
        let (n, l) = footer
            .next()
            .ok_or_else(|| format!("missing \"{title}\""))?;
        let rest = l
            .strip_prefix(title)
            .ok_or_else(|| format!("line {n}: \"{title}\" expected"))?;
        let v = numbers(n, rest)?;
        // -H adds a summary column; ignore it.
        if v.len() < columns.len() {
            return Err(format!(
                "line {n}: {} values, {} expected",
                v.len(),
                columns.len()
            ));
        }
        for (c, x) in columns.iter_mut().zip(v) {
            set(c, x);
        }
        Ok(())
    };
    field("# Total:", &|c, x| c.total = x)?;
    field("# Min Latencies:", &|c, x| c.min_us = x)?;
    field("# Avg Latencies:", &|c, x| c.avg_us = x)?;
    field("# Max Latencies:", &|c, x| c.max_us = x)?;
    field("# Histogram Overflows:", &|c, x| c.overflows = x)?;
    match footer.next() {
        Some((_, "# Histogram Overflow at cycle number:")) => {}
        Some((n, l)) => return Err(format!("line {n}: {l:?}: overflow cycle list expected")),
        None => return Err("missing \"# Histogram Overflow at cycle number:\"".into()),
    }
    for (j, c) in columns.iter_mut().enumerate() {
        let title = format!("# Thread {j}:");
        let (n, l) = footer
            .next()
            .ok_or_else(|| format!("missing \"{title}\""))?;
        let rest = l
            .strip_prefix(&title)
            .ok_or_else(|| format!("line {n}: \"{title}\" expected"))?;
        let (listed, others) = match rest.split_once('#') {
            Some((a, b)) => (a, b.trim().strip_suffix("others").map(str::trim)),
            None => (rest, None),
        };
        c.overflow_cycles = numbers(n, listed)?;
        c.others = match others {
            Some(o) => o
                .parse()
                .map_err(|_| format!("line {n}: {o:?} is not a count"))?,
            None => 0,
        };
    }
    Ok(columns)
}
