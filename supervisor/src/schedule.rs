//! Faults at instants of the virtual clock (`supervisor run --virtual-time --fault AT:WHAT`,
//! docs/virtual-time.md): a process held off its cycles for a while, a process killed, the
//! user's e-stop. On the virtual clock they happen at the same instant in every run, so what
//! follows (stale feedback, the e-stop's reaction, a restart) happens exactly.

use cell_config::Config;

/// One fault and its instant.
#[derive(Clone, Debug, PartialEq)]
pub struct ScheduledFault {
    /// Seconds of the cell's clock since it started (the events' `t_s`).
    pub at_s: f64,
    /// What happens.
    pub what: Fault,
}

/// What a scheduled fault does.
#[derive(Clone, Debug, PartialEq)]
pub enum Fault {
    /// The process gets no cycle for `ms` milliseconds of virtual time from the instant: its
    /// deadlines in between are granted late, all at the end, as a host's stall would let them
    /// run (the cycle's overrun rule then skips what it ran into).
    Hold {
        /// Its name in the process table.
        process: String,
        /// For how long (ms).
        ms: f64,
    },
    /// The process is killed (SIGKILL) at the instant, before any cycle of it at or after it.
    Kill {
        /// Its name in the process table.
        process: String,
    },
    /// The user's e-stop, raised by the supervisor's first tick at or after the instant (its
    /// ticks are every 10 ms of the clock).
    Estop,
}

impl std::str::FromStr for ScheduledFault {
    type Err = String;

    /// `AT:hold:PROCESS:MS`, `AT:kill:PROCESS` or `AT:estop`; the error names the part that is
    /// wrong.
    fn from_str(s: &str) -> Result<Self, String> {
        let parts: Vec<&str> = s.split(':').collect();
        let at_s: f64 = parts[0].parse().map_err(|_| {
            format!(
                "{s:?}: {:?} is not an instant (seconds of the cell's clock)",
                parts[0]
            )
        })?;
        if !(at_s.is_finite() && at_s >= 0.0) {
            return Err(format!(
                "{s:?}: the instant {at_s} is not a time from the start"
            ));
        }
        let what = match parts.get(1).copied() {
            Some("hold") => {
                let [_, _, process, ms] = parts[..] else {
                    return Err(format!("{s:?}: a hold is AT:hold:PROCESS:MS"));
                };
                let ms: f64 = ms
                    .parse()
                    .ok()
                    .filter(|v: &f64| v.is_finite() && *v > 0.0)
                    .ok_or_else(|| format!("{s:?}: {ms:?} is not a positive number of ms"))?;
                Fault::Hold {
                    process: process.to_string(),
                    ms,
                }
            }
            Some("kill") => {
                let [_, _, process] = parts[..] else {
                    return Err(format!("{s:?}: a kill is AT:kill:PROCESS"));
                };
                Fault::Kill {
                    process: process.to_string(),
                }
            }
            Some("estop") if parts.len() == 2 => Fault::Estop,
            Some("estop") => return Err(format!("{s:?}: an e-stop is AT:estop")),
            other => {
                return Err(format!(
                    "{s:?}: {:?} is no fault (hold, kill or estop)",
                    other.unwrap_or("")
                ));
            }
        };
        Ok(Self { at_s, what })
    }
}

/// A fault checked against the cell, on its clock: a process as its index in the table,
/// instants in ns of the virtual clock.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Planned {
    /// [`Fault::Hold`] from `from_ns` until `until_ns`.
    Hold {
        /// The process' index in the table.
        index: u32,
        /// From.
        from_ns: u64,
        /// Until.
        until_ns: u64,
    },
    /// [`Fault::Kill`] at `at_ns`.
    Kill {
        /// The process' index in the table.
        index: u32,
        /// When.
        at_ns: u64,
    },
    /// [`Fault::Estop`] at `at_ns`.
    Estop {
        /// When.
        at_ns: u64,
    },
}

/// `faults` checked against `cfg` before anything starts: they need the cell on the virtual
/// clock and name processes of its table; the error says what is wrong.
pub fn plan(faults: &[ScheduledFault], cfg: &Config) -> Result<Vec<Planned>, String> {
    if !faults.is_empty() && cfg.cell.clock != cell_config::Clock::Virtual {
        return Err(
            "--fault needs the virtual clock (--virtual-time, or [cell] clock = \"virtual\")"
                .into(),
        );
    }
    let index_of = |name: &str| {
        cfg.process
            .iter()
            .position(|p| p.name == name)
            .map(|k| k as u32)
            .ok_or_else(|| {
                format!(
                    "--fault: the cell has no process {name:?} (its table: {})",
                    cfg.process
                        .iter()
                        .map(|p| p.name.as_str())
                        .collect::<Vec<_>>()
                        .join(", ")
                )
            })
    };
    faults
        .iter()
        .map(|f| {
            let at_ns = runtime::vclock::EPOCH_NS + (f.at_s * 1e9).round() as u64;
            Ok(match &f.what {
                Fault::Hold { process, ms } => Planned::Hold {
                    index: index_of(process)?,
                    from_ns: at_ns,
                    until_ns: at_ns + (ms * 1e6).round() as u64,
                },
                Fault::Kill { process } => Planned::Kill {
                    index: index_of(process)?,
                    at_ns,
                },
                Fault::Estop => Planned::Estop { at_ns },
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn faults_are_read_and_bad_ones_named() {
        assert_eq!(
            "5.25:hold:servo:60".parse(),
            Ok(ScheduledFault {
                at_s: 5.25,
                what: Fault::Hold {
                    process: "servo".into(),
                    ms: 60.0
                }
            })
        );
        assert_eq!(
            "1:kill:trajgen".parse::<ScheduledFault>().map(|f| f.what),
            Ok(Fault::Kill {
                process: "trajgen".into()
            })
        );
        assert_eq!(
            "2.5:estop".parse::<ScheduledFault>().map(|f| f.what),
            Ok(Fault::Estop)
        );
        for (bad, names) in [
            ("x:estop", "\"x\""),
            ("-1:estop", "-1"),
            ("1:hold:servo", "AT:hold:PROCESS:MS"),
            ("1:hold:servo:0", "\"0\""),
            ("1:kill", "AT:kill:PROCESS"),
            ("1:estop:now", "AT:estop"),
            ("1:melt:servo", "\"melt\""),
        ] {
            let e = bad.parse::<ScheduledFault>().expect_err(bad);
            assert!(e.contains(names), "{bad}: {e}");
        }
    }
}
