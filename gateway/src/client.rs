//! `gateway line ...`: a control room's client of the line (what `supervisor cells` and the
//! commands' `--remote CELL` run): lists the cells, reads one's status and events, and sends
//! it a signed command.

use crate::survey::{Failure, PATIENCE, rows, statuses};
use cell_config::network::{Login, Mode, Tls, endpoint_problem, lease_problem};
use clap::{Parser, Subcommand};
use gateway::auth::{Envelope, now_ms};
use gateway::command::Command;
use gateway::keys::{CellKeys, CellName, EVERY_CELL_ALIVE, cell_of};
use gateway::link::{Access, Link, secret_file};
use gateway::wire::{Answer, EventMessage, Missed, RecordBatch, RecordFlushed, RecordTopics};
use recorder::{RecordOptions, Recorded, Writer};
use serde::Deserialize;
use serde_inline_default::serde_inline_default;
use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Duration;
use zenoh::Wait;

/// A control room's line file (TOML): how to join the line, and who this user is.
#[serde_inline_default]
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct LineFile {
    /// Endpoints of the line to connect to (the cells' or a router's).
    #[serde(default)]
    connect: Vec<String>,
    /// UDP multicast discovery of the line's peers.
    #[serde(default)]
    multicast: bool,
    /// `tcp/` endpoints (in the clear) allowed.
    #[serde(default)]
    plain: bool,
    /// A silent link is gone after this (s).
    #[serde_inline_default(3.0)]
    lease: f64,
    /// The user commands are signed as.
    #[serde(default)]
    user: Option<String>,
    /// The file holding the user's secret (one line, its owner's alone).
    #[serde(default)]
    secret_file: Option<PathBuf>,
    /// Certificates for `tls/` endpoints.
    #[serde(default)]
    tls: Option<Tls>,
    /// The links' user and password.
    #[serde(default)]
    login: Option<Login>,
    /// The line's cells: with them (and `[tls]`), Zenoh's access control lets only the cell
    /// whose certificate's common name is `C` publish, answer or be present under
    /// `rtc/v1/C/`.
    #[serde(default)]
    cells: Vec<String>,
}

#[derive(Parser, Debug)]
#[command(
    name = "gateway line",
    about = "A control room's client of a line of cells (docs/network.md)"
)]
struct Cli {
    /// The line file: endpoints, certificates, the user and their secret (default: the
    /// environment's RTC_LINE).
    #[arg(long, global = true)]
    line: Option<PathBuf>,
    /// JSON instead of text.
    #[arg(long, global = true)]
    json: bool,
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand, Debug)]
enum Cmd {
    /// Lists the cells on the line: name, host, state, program, e-stop.
    Cells {
        /// Instead: a line each time a cell comes onto the line or leaves it, until Ctrl-C.
        #[arg(long)]
        watch: bool,
        /// With --watch: stop after this many seconds.
        #[arg(long, requires = "watch")]
        seconds: Option<f64>,
    },
    /// A cell's status.
    Status {
        /// The cell's name on the line.
        cell: String,
    },
    /// A cell's events as they happen (until Ctrl-C), any loss said.
    Events {
        /// The cell's name on the line.
        cell: String,
        /// Stop after this many (s); default: never.
        #[arg(long)]
        seconds: Option<f64>,
    },
    /// Records every service of a cell into an MCAP file here, as `supervisor record` does on
    /// the cell's host: until Ctrl-C, `--duration`, or the cell leaving the line.
    Record {
        /// The cell's name on the line.
        cell: String,
        #[command(flatten)]
        args: recorder::RecordArgs,
    },
    /// Serves the web view of the line: the list of its cells, then the 3D view of the one
    /// chosen (`?cell=NAME`), until SIGINT or SIGTERM. It only shows: its buttons are refused
    /// (command a cell with `supervisor estop --remote CELL`).
    Web {
        /// Address to listen on (port 0: any free port, printed). Anything but a loopback
        /// address needs --token.
        #[arg(long, default_value = "127.0.0.1:8080")]
        listen: std::net::SocketAddr,
        /// A token every client must give (`?token=` in the page's address).
        #[arg(long)]
        token: Option<String>,
    },
    /// Sends a cell a command (pause, resume, abort, reset, start, speed, estop, exec).
    #[command(flatten)]
    Command(Remote),
}

#[derive(Subcommand, Debug)]
enum Remote {
    /// Decelerate along the path to rest and hold.
    Pause { cell: String },
    /// Go on along the path.
    Resume { cell: String },
    /// Come to rest along the path and drop the rest of the program.
    Abort { cell: String },
    /// Clear the e-stop and what can be cleared.
    Reset { cell: String },
    /// Enable the drives, holding where they stand.
    Start { cell: String },
    /// The live speed override, 1..=100 %.
    Speed { cell: String, percent: f64 },
    /// The user's e-stop (a convenience: the cell's own e-stop circuit is its safety function).
    Estop {
        cell: String,
        /// Why, in a few words.
        #[arg(long, default_value = "remote e-stop")]
        reason: String,
    },
    /// Runs a program file on the cell.
    Exec { cell: String, program: PathBuf },
}

impl Remote {
    fn split(self) -> Result<(String, Command), String> {
        Ok(match self {
            Self::Pause { cell } => (cell, Command::Pause {}),
            Self::Resume { cell } => (cell, Command::Resume {}),
            Self::Abort { cell } => (cell, Command::Abort {}),
            Self::Reset { cell } => (cell, Command::Reset {}),
            Self::Start { cell } => (cell, Command::Start {}),
            Self::Speed { cell, percent } => (cell, Command::Speed { percent }),
            Self::Estop { cell, reason } => (cell, Command::Estop { reason }),
            Self::Exec { cell, program } => {
                let source = std::fs::read_to_string(&program)
                    .map_err(|e| format!("{}: {e}", program.display()))?;
                let name = program.file_name().map_or_else(
                    || program.display().to_string(),
                    |n| n.to_string_lossy().into_owned(),
                );
                (cell, Command::Exec { name, source })
            }
        })
    }
}

/// How long a client waits for a first link to the line.
const LINK_PATIENCE: Duration = Duration::from_secs(3);

pub fn main(args: impl Iterator<Item = OsString>) -> ExitCode {
    let cli = Cli::parse_from(std::iter::once(OsString::from("gateway line")).chain(args));
    match run(cli) {
        Ok(code) => ExitCode::from(code),
        Err((code, e)) => {
            eprintln!("error: {e}");
            ExitCode::from(code)
        }
    }
}

fn input(e: impl std::fmt::Display) -> Failure {
    (2, e.to_string())
}

fn load(path: Option<&Path>) -> Result<LineFile, Failure> {
    let path = path.ok_or_else(|| input("no line file: give --line FILE (or RTC_LINE)"))?;
    let text =
        std::fs::read_to_string(path).map_err(|e| input(format!("{}: {e}", path.display())))?;
    let file: LineFile =
        toml::from_str(&text).map_err(|e| input(format!("{}: {e}", path.display())))?;
    let problem = lease_problem(file.lease).or_else(|| {
        file.connect
            .iter()
            .find_map(|e| endpoint_problem("connect", e, file.plain, file.tls.is_some(), "[tls]"))
    });
    let problem = problem.or_else(|| {
        (!file.cells.is_empty() && file.tls.is_none()).then(|| {
            "cells: the access control knows the cells by their certificates: give [tls]"
                .to_string()
        })
    });
    let problem = problem.or_else(|| {
        file.cells
            .iter()
            .find_map(|c| CellName::new(c).err().map(|e| format!("cells: {c:?}: {e}")))
    });
    if let Some(p) = problem {
        return Err(input(format!("{}: {p}", path.display())));
    }
    Ok(file)
}

fn join(file: &LineFile) -> Result<zenoh::Session, Failure> {
    let cells: Vec<CellName> = file
        .cells
        .iter()
        .filter_map(|c| CellName::new(c).ok())
        .collect();
    Link {
        mode: Mode::Peer,
        listen: &[],
        connect: &file.connect,
        multicast: file.multicast,
        lease_s: file.lease,
        tls: file.tls.as_ref(),
        login: file.login.as_ref(),
        access: if cells.is_empty() {
            Access::Open
        } else {
            Access::Room { cells: &cells }
        },
    }
    .open()
    .map_err(|e| (1, e))
}

fn cell_name(cell: &str) -> Result<CellName, Failure> {
    CellName::new(cell).map_err(input)
}

fn run(cli: Cli) -> Result<u8, Failure> {
    let line = cli
        .line
        .or_else(|| std::env::var_os("RTC_LINE").map(PathBuf::from));
    let file = load(line.as_deref())?;
    let json = cli.json;
    // A command is checked (its program read) before the line is joined.
    let ask = match cli.cmd {
        Cmd::Command(r) => Ask::Command(r.split().map_err(input)?),
        Cmd::Cells { watch: false, .. } => Ask::Cells,
        Cmd::Cells {
            watch: true,
            seconds,
        } => Ask::Watch(seconds),
        Cmd::Status { cell } => Ask::Status(cell_name(&cell)?),
        Cmd::Events { cell, seconds } => Ask::Events(cell_name(&cell)?, seconds),
        Cmd::Web { listen, token } => {
            if let Some(t) = &token {
                web_view::check_token(t).map_err(input)?;
            }
            Ask::Web(listen, token)
        }
        Cmd::Record { cell, args } => {
            Ask::Record(cell_name(&cell)?, args.options().map_err(input)?)
        }
    };
    let session = join(&file)?;
    // Let the links come up before asking (a get on a line not yet joined hears nothing):
    // a first peer, for at most LINK_PATIENCE, then a moment for the others.
    let info = session.info();
    let linked = || info.peers_zid().wait().count() + info.routers_zid().wait().count();
    let start = std::time::Instant::now();
    let expect_links = !file.connect.is_empty() || file.multicast;
    while expect_links && linked() == 0 && start.elapsed() < LINK_PATIENCE {
        std::thread::sleep(Duration::from_millis(50));
    }
    std::thread::sleep(Duration::from_millis(300));
    if linked() == 0 && !file.connect.is_empty() {
        return Err((
            1,
            format!(
                "no endpoint of the line let this client in ({}): the line is down, or it refused this client's certificate or password",
                file.connect.join(", ")
            ),
        ));
    }
    match ask {
        Ask::Command((cell, command)) => send(&session, &file, &cell_name(&cell)?, command, json),
        Ask::Cells => cells(&session, json),
        Ask::Watch(seconds) => watch(&session, seconds, json),
        Ask::Status(cell) => status(&session, &cell, json),
        Ask::Events(cell, seconds) => events(&session, &cell, seconds, json),
        Ask::Record(cell, opts) => record(&session, &cell, &opts, file.lease),
        Ask::Web(listen, token) => crate::line_web::serve(session, listen, token),
    }
}

/// What the command line asks, checked.
enum Ask {
    Command((String, Command)),
    Cells,
    Watch(Option<f64>),
    Status(CellName),
    Events(CellName, Option<f64>),
    Record(CellName, RecordOptions),
    Web(std::net::SocketAddr, Option<String>),
}

/// The end of a watch of `seconds`, if it has one.
fn deadline(seconds: Option<f64>) -> Option<std::time::Instant> {
    seconds.and_then(|s| {
        std::time::Instant::now().checked_add(Duration::try_from_secs_f64(s.max(0.0)).ok()?)
    })
}

/// How long to wait for the next sample before `end` (half a second with no end); `None`
/// once it has passed.
fn until(end: Option<std::time::Instant>) -> Option<Duration> {
    match end {
        Some(e) => e.checked_duration_since(std::time::Instant::now()),
        None => Some(Duration::from_millis(500)),
    }
}

/// `cells --watch`: the line's cells as they come and go (their presence tokens), from the
/// ones there now, until Ctrl-C or `seconds`.
fn watch(session: &zenoh::Session, seconds: Option<f64>, json: bool) -> Result<u8, Failure> {
    use zenoh::sample::SampleKind;
    let sub = session
        .liveliness()
        .declare_subscriber(EVERY_CELL_ALIVE)
        .history(true)
        .wait()
        .map_err(|e| (1, format!("cannot watch the line: {e}")))?;
    let start = std::time::Instant::now();
    let end = deadline(seconds);
    loop {
        let Some(wait) = until(end) else {
            return Ok(0);
        };
        let Ok(Some(sample)) = sub.recv_timeout(wait) else {
            continue;
        };
        let Some(cell) = cell_of(sample.key_expr().as_str()) else {
            continue;
        };
        let alive = sample.kind() == SampleKind::Put;
        let t_s = start.elapsed().as_secs_f64();
        if json {
            println!(
                "{}",
                serde_json::json!({
                    "t_s": t_s,
                    "time_ms": now_ms(),
                    "cell": cell.as_str(),
                    "alive": alive
                })
            );
        } else {
            println!("{t_s:9.3} s  {} {cell}", if alive { "+" } else { "-" });
        }
    }
}

fn cells(session: &zenoh::Session, json: bool) -> Result<u8, Failure> {
    let rows = rows(session)?;
    if json {
        println!("{}", serde_json::to_string(&rows).unwrap_or_default());
    } else {
        println!(
            "{:<16} {:<16} {:<10} {:<24} e-stop",
            "cell", "host", "state", "program"
        );
        let dash = |o: &Option<String>| o.clone().unwrap_or_else(|| "-".into());
        for r in &rows {
            println!(
                "{:<16} {:<16} {:<10} {:<24} {}",
                r.cell,
                dash(&r.host),
                dash(&r.state),
                dash(&r.program),
                match r.estop {
                    Some(true) => "latched",
                    Some(false) => "clear",
                    None => "-",
                }
            );
        }
    }
    Ok(0)
}

fn status(session: &zenoh::Session, cell: &CellName, json: bool) -> Result<u8, Failure> {
    let mut found = statuses(session, &cell.status())?;
    let m = found
        .remove(cell.as_str())
        .ok_or_else(|| (1, format!("cell {cell} does not answer on the line")))?;
    if json {
        println!("{}", serde_json::to_string(&m.status).unwrap_or_default());
    } else {
        print!("{}", control_plane::compose::human(&m.status));
    }
    Ok(0)
}

fn events(
    session: &zenoh::Session,
    cell: &CellName,
    seconds: Option<f64>,
    json: bool,
) -> Result<u8, Failure> {
    let sub = session
        .declare_subscriber(cell.events())
        .wait()
        .map_err(|e| (1, format!("cannot subscribe: {e}")))?;
    // A round trip to the cell's gateway after the subscription: on the link between them it
    // went out first, so once the cell answers it knows of it, and nothing it publishes from
    // then on is missed. Said on stderr and, for a script or a unit that waits for it, as
    // `READY=1` on `NOTIFY_SOCKET` (not said while the cell does not answer).
    if statuses(session, &cell.status())?.contains_key(cell.as_str()) {
        eprintln!("following {cell}'s events");
        if let Err(e) = runtime::notify::ready() {
            eprintln!("warning: cannot say it is ready: {e}");
        }
    } else {
        eprintln!("following {cell}'s events (it does not answer on the line yet)");
    }
    let end = deadline(seconds);
    let mut last: Option<EventMessage> = None;
    loop {
        let Some(wait) = until(end) else {
            return Ok(0);
        };
        let Ok(Some(sample)) = sub.recv_timeout(wait) else {
            continue;
        };
        let Ok(m) = serde_json::from_slice::<EventMessage>(&sample.payload().to_bytes()) else {
            continue;
        };
        let said = match m.missed_since(last.as_ref()) {
            Missed::Nothing => None,
            Missed::Events(n) => Some((n.to_string(), format!("... {n} events lost"))),
            Missed::Restarted(n) => Some((
                "\"unknown\"".into(),
                format!(
                    "... the cell's gateway started again: the events while it was away are not known{}",
                    if n > 0 {
                        format!(", and {n} lost since")
                    } else {
                        String::new()
                    }
                ),
            )),
        };
        if let Some((count, words)) = said {
            if json {
                println!("{{\"lost\": {count}}}");
            } else {
                println!("{words}");
            }
        }
        if json {
            println!("{}", serde_json::to_string(&m.event).unwrap_or_default());
        } else {
            let e = &m.event;
            println!(
                "{:>9.3} s  {:<10} {:<8} {} {}",
                e.t_s,
                e.source,
                format!("{:?}", e.severity).to_lowercase(),
                e.name,
                e.text
            );
        }
        last = Some(m);
    }
}

fn send(
    session: &zenoh::Session,
    file: &LineFile,
    cell: &CellName,
    command: Command,
    json: bool,
) -> Result<u8, Failure> {
    let user = file
        .user
        .clone()
        .ok_or_else(|| input("the line file names no user: commands are signed by one"))?;
    let secret_path = file
        .secret_file
        .as_deref()
        .ok_or_else(|| input("the line file has no secret_file for its user"))?;
    let secret = secret_file(secret_path).map_err(input)?;
    let time_ms = now_ms();
    let (payload, signature) = Envelope {
        user,
        cell: cell.to_string(),
        time_ms,
        nonce: u64::from(std::process::id()) << 32 ^ time_ms,
        command,
    }
    .signed(secret.as_bytes());
    let replies = session
        .get(cell.control())
        .payload(payload)
        .attachment(signature)
        .timeout(Duration::from_secs(60))
        .wait()
        .map_err(|e| (1, format!("cannot ask the line: {e}")))?;
    let Ok(reply) = replies.recv() else {
        return Err((
            1,
            format!("cell {cell} did not answer (not on the line, or the line refused the query)"),
        ));
    };
    let sample = reply
        .result()
        .map_err(|e| (1, format!("cell {cell}: {:?}", e.payload().try_to_string())))?;
    if sample.key_expr().as_str() != cell.control() {
        return Err((
            1,
            format!("an answer on {} is not cell {cell}'s", sample.key_expr()),
        ));
    }
    let answer: Answer = serde_json::from_slice(&sample.payload().to_bytes())
        .map_err(|e| (1, format!("cell {cell} answered something else: {e}")))?;
    if json {
        println!("{}", serde_json::to_string(&answer).unwrap_or_default());
    } else {
        match &answer {
            Answer::Done { message } => println!("{message}"),
            Answer::Refused { by, reason } => eprintln!("refused ({by}): {reason}"),
            Answer::Failed { reason } => eprintln!("failed: {reason}"),
            Answer::Status { status } => print!("{}", control_plane::compose::human(status)),
        }
    }
    Ok(answer.exit_code())
}

/// How long a stopping recording waits for the cell's gateway to say which batch ends it: the
/// gateway answers once it has sent what it read before, which a loaded host (or a slow room)
/// may hold up for seconds.
const FLUSH_PATIENCE: Duration = Duration::from_secs(30);

/// The recording stream's topics, asked of the cell's gateway (which starts its source).
fn record_topics(session: &zenoh::Session, cell: &CellName) -> Result<RecordTopics, Failure> {
    let mut why = String::from("no answer");
    // The source starts on the question: a few tries while it does.
    for _ in 0..3 {
        let replies = session
            .get(cell.record_topics())
            .timeout(PATIENCE)
            .wait()
            .map_err(|e| (1, format!("cannot ask the line: {e}")))?;
        while let Ok(reply) = replies.recv() {
            match reply.result() {
                Ok(sample) => {
                    return serde_json::from_slice(&sample.payload().to_bytes()).map_err(|e| {
                        (
                            1,
                            format!("cell {cell} answered its topics with something else: {e}"),
                        )
                    });
                }
                Err(e) => {
                    why = e
                        .payload()
                        .try_to_string()
                        .map_or_else(|_| "an error".into(), |s| s.to_string());
                }
            }
        }
        std::thread::sleep(Duration::from_millis(500));
    }
    Err((
        1,
        format!("cell {cell} cannot be recorded from the line: {why}"),
    ))
}

/// A stopping recording's question to the cell's gateway: asked, or answered.
enum Flush {
    Asked(std::sync::mpsc::Receiver<Option<RecordFlushed>>),
    Answered(Option<RecordFlushed>),
}

/// The batch of `cell`'s recording stream that holds everything it published before now
/// (`None` when its gateway does not say).
fn flushed(session: &zenoh::Session, cell: &CellName) -> Option<RecordFlushed> {
    let replies = session
        .get(cell.record_flush())
        .timeout(FLUSH_PATIENCE)
        .wait()
        .ok()?;
    let reply = replies.recv().ok()?;
    serde_json::from_slice(&reply.result().ok()?.payload().to_bytes()).ok()
}

/// `record`: the cell's recording stream into MCAP files here, the same channels and
/// messages as a recording on the cell's host.
/// Records `cell` as `opts` say. Without a batch of the recording stream (its heartbeat is
/// every half second) for the line's `lease` (s), the cell is taken for gone (a link as
/// silent is dropped); once asked to end, the stream is waited for up to `FLUSH_PATIENCE`
/// (the gateway sends what it read before: a loaded host holds it up).
fn record(
    session: &zenoh::Session,
    cell: &CellName,
    opts: &RecordOptions,
    lease: f64,
) -> Result<u8, Failure> {
    let gone = Duration::from_secs_f64(lease);
    runtime::signals::install().map_err(|e| (1, format!("cannot install signal handlers: {e}")))?;
    // Subscribed first: the gateway runs its source while anyone does, and every batch from
    // the topics' answer on reaches this subscriber.
    let stream = session
        .declare_subscriber(cell.record())
        .wait()
        .map_err(|e| (1, format!("cannot subscribe: {e}")))?;
    let mut topics = record_topics(session, cell)?;
    let names: Vec<String> = topics.topics.iter().map(|t| t.topic.clone()).collect();
    let file = |e: String| (1, e);
    let mut out = Writer::create(&opts.out, opts.rotate, topics.topics.clone()).map_err(file)?;
    {
        use std::io::Write;
        println!("recording cell {cell} to {}", out.path().display());
        let _ = std::io::stdout().flush();
    }
    let mut written = vec![0u64; names.len()];
    // Per topic: lost by the sources before the current one, and by the current one.
    let mut lost_before = vec![0u64; names.len()];
    let mut lost_now = vec![0u64; names.len()];
    // Batches lost on the way, and sources started again (the messages between unknown).
    let mut missed_batches = 0u64;
    let mut restarts = 0u64;
    let mut last_seq: Option<u64> = None;
    let began = std::time::Instant::now();
    let mut heard = std::time::Instant::now();
    // Once asked to end: why, and the batch that holds all the cell published before, asked
    // on a thread of its own while the stream goes on being read (the gateway answers after
    // sending what it has: not reading meanwhile could hold it up).
    let mut ending: Option<(String, Flush)> = None;
    let ended = loop {
        if ending.is_none() {
            let why = if runtime::signals::stop_requested() {
                Some("stopped".to_string())
            } else if opts.duration.is_some_and(|d| began.elapsed() >= d) {
                Some("its duration is over".to_string())
            } else {
                None
            };
            if let Some(why) = why {
                let (tx, rx) = std::sync::mpsc::channel();
                let (s, c) = (session.clone(), cell.clone());
                std::thread::spawn(move || {
                    let _ = tx.send(flushed(&s, &c));
                });
                ending = Some((why, Flush::Asked(rx)));
            }
        }
        if let Some((why, flush)) = &mut ending {
            if let Flush::Asked(rx) = flush
                && let Ok(answer) = rx.try_recv()
            {
                *flush = Flush::Answered(answer);
            }
            let caught_up = match flush {
                Flush::Asked(_) => false,
                Flush::Answered(Some(f)) => {
                    f.source_started_ms != topics.source_started_ms || last_seq >= Some(f.seq)
                }
                Flush::Answered(None) => true,
            };
            if caught_up {
                break why.clone();
            }
        }
        let patience = if ending.is_some() {
            FLUSH_PATIENCE
        } else {
            gone
        };
        if heard.elapsed() > patience {
            break format!("cell {cell} left the line");
        }
        out.maybe_rotate().map_err(file)?;
        let Ok(Some(sample)) = stream.recv_timeout(Duration::from_millis(100)) else {
            continue;
        };
        let Ok(batch) = serde_json::from_slice::<RecordBatch>(&sample.payload().to_bytes()) else {
            continue;
        };
        heard = std::time::Instant::now();
        if batch.source_started_ms != topics.source_started_ms {
            // The gateway started its source again (it was restarted, or its source had
            // stopped): the same topics go on in the same file; other topics end it.
            let again = record_topics(session, cell)?;
            if again.source_started_ms != batch.source_started_ms {
                continue;
            }
            if again.topics != topics.topics {
                break format!("cell {cell}'s topics changed");
            }
            topics = again;
            restarts += 1;
            for (b, n) in lost_before.iter_mut().zip(&mut lost_now) {
                *b += std::mem::take(n);
            }
            last_seq = Some(0);
        }
        if let Some(prev) = last_seq {
            missed_batches += batch.seq.saturating_sub(prev + 1);
        }
        last_seq = Some(batch.seq);
        for (k, t, message) in &batch.messages {
            let k = *k as usize;
            if k < names.len() {
                out.write(k, *t, message.get().as_bytes()).map_err(file)?;
                written[k] += 1;
            }
        }
        for (l, n) in lost_now.iter_mut().zip(&batch.lost) {
            *l = *n;
        }
    };
    let mut ended = ended;
    if ending
        .as_ref()
        .is_some_and(|(_, f)| matches!(f, Flush::Answered(None)))
    {
        ended += "; the cell's gateway did not say which batch ends the recording: what was on its way is missing";
    }
    if missed_batches > 0 {
        ended += &format!("; {missed_batches} batches of messages missed on the line");
    }
    if restarts > 0 {
        ended += &format!(
            "; the cell's gateway started its recording again {restarts} times (what came between is missing)"
        );
    }
    let recorded = Recorded {
        files: out.finish().map_err(file)?,
        topics: names
            .into_iter()
            .zip(written)
            .zip(lost_before.iter().zip(&lost_now))
            .map(|((t, n), (b, l))| (t, n, b + l))
            .collect(),
        ended,
    };
    print!("{}", recorded.text());
    Ok(0)
}
