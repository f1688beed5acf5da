//! `supervisor latency`: its options, their checks, its progress and its output files.

use crate::{Options, Results, Test, Threads, histfile, report};
use runtime::signals;
use shm_schema::InstanceName;
use std::io::{IsTerminal, Write};
use std::path::PathBuf;
use std::time::{Duration, Instant};

/// The hidden subcommand that runs a hop's sender (see `latency::peer`).
pub const PEER_SUBCOMMAND: &str = "latency-peer";

/// The command line of `supervisor latency`.
#[derive(Clone, Debug, clap::Args)]
pub struct LatencyArgs {
    /// Period of the measuring loops (µs).
    #[arg(long, short = 'i', default_value_t = 1000)]
    pub interval_us: u64,
    /// Phase of the loops on the grid of CLOCK_MONOTONIC (µs), as a process' phase in the
    /// cell; default half the interval. 0 puts every wake-up on a whole millisecond,
    /// together with the kernel's tick.
    #[arg(long)]
    pub phase_us: Option<u64>,
    /// How long each test runs: seconds, or 30s, 5m, 2h, 1d. Default: until Ctrl-C.
    #[arg(long, short = 'D')]
    pub duration: Option<String>,
    /// Timer threads, pinned round-robin over the CPUs (default: one per CPU, as --smp).
    #[arg(long, short = 't', conflicts_with = "smp")]
    pub threads: Option<usize>,
    /// One timer thread per CPU, each pinned to its CPU (cyclictest -S); the default.
    #[arg(long, short = 'S')]
    pub smp: bool,
    /// SCHED_FIFO priority of every measuring thread (0: SCHED_OTHER).
    #[arg(long, short = 'p', default_value_t = 80)]
    pub priority: i32,
    /// Range of the 1-µs histogram (cyclictest -h); larger samples count as overflows.
    #[arg(long, default_value_t = 1000)]
    pub histogram_us: usize,
    /// Write the histogram in cyclictest's --histfile format.
    #[arg(long)]
    pub histfile: Option<PathBuf>,
    /// Print one JSON object on stdout instead of the text lines.
    #[arg(long)]
    pub json: bool,
    /// Write a PNG of the histogram.
    #[arg(long)]
    pub plot: Option<PathBuf>,
    /// Tests to run, in order, comma-separated: timer, ipc, and the baselines of the IPC
    /// hop: pipe (a raw pipe) and unix (a raw Unix datagram socket).
    #[arg(long = "test", default_value = "timer,ipc")]
    pub tests: String,
    /// Instance name of the IPC hop's services (default latency-<pid>).
    #[arg(long)]
    pub instance: Option<String>,
    /// No progress on stderr.
    #[arg(long, short = 'q')]
    pub quiet: bool,
}

/// Why `supervisor latency` failed.
#[derive(Debug)]
pub enum LatencyError {
    /// A bad option; nothing was measured. Exit code 2.
    Input(String),
    /// The measurement failed. Exit code 1.
    Failed(String),
}

impl std::fmt::Display for LatencyError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Input(e) | Self::Failed(e) => f.write_str(e),
        }
    }
}

impl std::error::Error for LatencyError {}

/// Parses a duration like cyclictest's `-D`: seconds, or a number with `s`, `m`, `h` or `d`.
pub fn parse_duration(text: &str) -> Result<Duration, String> {
    let t = text.trim();
    let (num, unit) = match t.char_indices().last() {
        Some((i, c)) if c.is_ascii_alphabetic() => (&t[..i], c),
        _ => (t, 's'),
    };
    let scale = match unit {
        's' => 1.0,
        'm' => 60.0,
        'h' => 3600.0,
        'd' => 86400.0,
        _ => return Err(format!("--duration {text:?}: unit must be s, m, h or d")),
    };
    match num.parse::<f64>() {
        Ok(v) if v.is_finite() && v > 0.0 && v * scale < 1e9 => {
            Ok(Duration::from_secs_f64(v * scale))
        }
        _ => Err(format!(
            "--duration {text:?}: a positive number of seconds expected (or 30s, 5m, 2h, 1d)"
        )),
    }
}

impl LatencyArgs {
    /// Checks every option and builds the run's options; errors name the option.
    pub fn options(&self) -> Result<Options, String> {
        if !(20..=1_000_000).contains(&self.interval_us) {
            return Err(format!(
                "--interval-us {}: must be 20 to 1000000 µs",
                self.interval_us
            ));
        }
        let phase_us = self.phase_us.unwrap_or(self.interval_us / 2);
        if phase_us >= self.interval_us {
            return Err(format!(
                "--phase-us {phase_us}: must be below the interval ({} µs)",
                self.interval_us
            ));
        }
        if !(0..=99).contains(&self.priority) {
            return Err(format!(
                "--priority {}: must be 0 (SCHED_OTHER) to 99",
                self.priority
            ));
        }
        if !(1..=1_000_000).contains(&self.histogram_us) {
            return Err(format!(
                "--histogram-us {}: must be 1 to 1000000",
                self.histogram_us
            ));
        }
        let threads = match self.threads {
            None => Threads::Smp,
            Some(n) if (1..=256).contains(&n) => Threads::Count(n),
            Some(n) => return Err(format!("--threads {n}: must be 1 to 256")),
        };
        let mut tests = Vec::new();
        for name in self.tests.split(',').map(str::trim) {
            let t = Test::from_name(name).ok_or_else(|| {
                format!(
                    "--test {name:?}: unknown; choose from timer, ipc, pipe, unix (comma-separated)"
                )
            })?;
            if !tests.contains(&t) {
                tests.push(t);
            }
        }
        let duration = self.duration.as_deref().map(parse_duration).transpose()?;
        let name = self
            .instance
            .clone()
            .unwrap_or_else(|| format!("latency-{}", std::process::id()));
        let instance = InstanceName::new(&name).map_err(|e| format!("--instance {name:?}: {e}"))?;
        for (path, what) in [(&self.histfile, "--histfile"), (&self.plot, "--plot")] {
            if let Some(p) = path
                && let Some(dir) = p.parent().filter(|d| !d.as_os_str().is_empty())
                && !dir.is_dir()
            {
                return Err(format!(
                    "{what} {}: no folder {}",
                    p.display(),
                    dir.display()
                ));
            }
        }
        let peer_exe = std::env::current_exe()
            .map_err(|e| format!("cannot find the supervisor's own program: {e}"))?;
        Ok(Options {
            interval_us: self.interval_us,
            phase_us,
            duration,
            threads,
            priority: self.priority,
            histogram_us: self.histogram_us,
            tests,
            instance,
            peer_exe,
            peer_args: vec![PEER_SUBCOMMAND.to_string()],
        })
    }
}

/// Runs `supervisor latency`: prints the figures (text or JSON) on stdout, writes the files.
pub fn latency(args: &LatencyArgs) -> Result<(), LatencyError> {
    let opts = args.options().map_err(LatencyError::Input)?;
    runtime::ipc::quiet_iceoryx2_log();
    if !runtime::ipc::live_node_pids(&opts.instance)
        .unwrap_or_default()
        .is_empty()
    {
        return Err(LatencyError::Input(format!(
            "instance {} is in use; choose another --instance",
            opts.instance
        )));
    }
    signals::install().map_err(|e| LatencyError::Failed(format!("signal handlers: {e}")))?;
    let tty = std::io::stderr().is_terminal();
    let every = Duration::from_secs(if tty { 1 } else { 10 });
    let mut last = Instant::now();
    let mut shown = false;
    if !args.quiet {
        let per = opts.duration.map_or("until Ctrl-C".to_string(), |d| {
            format!("{:.0} s each", d.as_secs_f64())
        });
        eprintln!(
            "latency: {} at {} µs, priority {}, {per}; Ctrl-C prints the figures so far",
            opts.tests
                .iter()
                .map(|t| t.name())
                .collect::<Vec<_>>()
                .join(", "),
            opts.interval_us,
            opts.priority
        );
    }
    let mut ready = false;
    let results = crate::run(&opts, |running, elapsed| {
        // Under systemd or a script: READY=1 once every thread of the first test measured.
        if !ready
            && running
                .iter()
                .all(|r| r.live.cycles.load(std::sync::atomic::Ordering::Relaxed) > 0)
        {
            ready = true;
            if let Err(e) = runtime::notify::ready() {
                eprintln!("latency: {e}");
            }
        }
        if args.quiet || last.elapsed() < every {
            return;
        }
        last = Instant::now();
        let line = report::progress_line(running, elapsed);
        if tty {
            eprint!("\r\x1b[2K{line}");
            shown = true;
        } else {
            eprintln!("{line}");
        }
    });
    if shown {
        eprintln!();
    }
    let results = results.map_err(LatencyError::Failed)?;
    if args.json {
        println!(
            "{}",
            serde_json::to_string_pretty(&report::to_json(&results, &opts)).unwrap_or_default()
        );
    } else {
        print!("{}", report::text(&results, &opts));
    }
    write_files(args, &opts, &results).map_err(LatencyError::Failed)
}

fn write_files(args: &LatencyArgs, opts: &Options, r: &Results) -> Result<(), String> {
    if let Some(path) = &args.histfile {
        let columns: Vec<histfile::Column> = r.series.iter().map(histfile::Column::of).collect();
        let names: Vec<String> = r.series.iter().map(|s| s.label()).collect();
        let comments = vec![
            format!(
                "supervisor latency: interval {} us, phase {} us, priority {}, 1-us bins",
                opts.interval_us, opts.phase_us, opts.priority
            ),
            format!("columns: {}", names.join(", ")),
        ];
        std::fs::write(path, histfile::write(&columns, &comments))
            .map_err(|e| format!("--histfile {}: {e}", path.display()))?;
    }
    if let Some(path) = &args.plot {
        let series: Vec<(String, Vec<u64>)> = r
            .series
            .iter()
            .map(|s| (s.label(), s.linear.clone()))
            .collect();
        let title = format!(
            "supervisor latency: interval {} \u{b5}s, SCHED_FIFO {}",
            opts.interval_us, opts.priority
        );
        let png = plot::png(&title, &series).map_err(|e| format!("--plot: {e}"))?;
        std::fs::File::create(path)
            .and_then(|mut f| f.write_all(&png))
            .map_err(|e| format!("--plot {}: {e}", path.display()))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn durations_read_like_cyclictest() {
        assert_eq!(parse_duration("10"), Ok(Duration::from_secs(10)));
        assert_eq!(parse_duration("2.5s"), Ok(Duration::from_millis(2500)));
        assert_eq!(parse_duration("5m"), Ok(Duration::from_secs(300)));
        assert_eq!(parse_duration("1h"), Ok(Duration::from_secs(3600)));
        assert!(parse_duration("0").is_err());
        assert!(parse_duration("-3").is_err());
        assert!(parse_duration("3w").expect_err("weeks").contains("unit"));
    }
}
