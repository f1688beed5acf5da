//! A budget of log lines: a flood of commands from the network (a viewer polling, a stranger
//! trying secrets) must not flood the cell's log. So many lines in a window, the rest counted
//! and said in one line when the next window opens.

/// So many lines per window; what is held back is counted.
#[derive(Debug)]
pub struct LogBudget {
    per_window: u32,
    window_ms: u64,
    /// When the current window opened (ms); `None` before the first line.
    opened_ms: Option<u64>,
    used: u32,
    held: u64,
}

/// What to do with one line.
#[derive(Debug, PartialEq, Eq)]
pub struct Verdict {
    /// Log it.
    pub log: bool,
    /// Lines held back in the window before this one's (to say before it), if any.
    pub held_before: Option<u64>,
}

impl LogBudget {
    /// `per_window` lines each `window_ms`.
    pub fn new(per_window: u32, window_ms: u64) -> Self {
        Self {
            per_window,
            window_ms,
            opened_ms: None,
            used: 0,
            held: 0,
        }
    }

    /// One line at `now_ms`: whether to log it, and what the previous window held back.
    pub fn take(&mut self, now_ms: u64) -> Verdict {
        let mut held_before = None;
        let open = self
            .opened_ms
            .is_some_and(|t| now_ms.saturating_sub(t) < self.window_ms);
        if !open {
            if self.held > 0 {
                held_before = Some(self.held);
            }
            self.opened_ms = Some(now_ms);
            self.used = 0;
            self.held = 0;
        }
        let log = self.used < self.per_window;
        if log {
            self.used += 1;
        } else {
            self.held += 1;
        }
        Verdict { log, held_before }
    }

    /// The window's length (s), for the line that says what was held back.
    pub fn window_s(&self) -> f64 {
        self.window_ms as f64 / 1000.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_flood_logs_its_first_lines_and_then_how_many_it_held_back() {
        let mut b = LogBudget::new(10, 10_000);
        let logged = (0..25).filter(|k| b.take(1_000 + k).log).count();
        assert_eq!(logged, 10);
        // The next window: the 15 held back are said, and it logs again.
        assert_eq!(
            b.take(11_000),
            Verdict {
                log: true,
                held_before: Some(15)
            }
        );
        // A quiet window after it holds nothing back and says nothing.
        assert_eq!(
            b.take(30_000),
            Verdict {
                log: true,
                held_before: None
            }
        );
    }
}
