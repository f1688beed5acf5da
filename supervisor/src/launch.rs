//! Starting and stopping the cell's processes.
//!
//! Each process is started from its configured command line, so any of them can be replaced
//! by another program. [`Children`] stops whatever is still running when it is dropped, so no
//! error path leaves a process behind.

use crate::config::Config;
use shm_schema::{InstanceName, Role};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

/// A running process of the cell.
#[derive(Debug)]
pub struct Running {
    /// Its role.
    pub role: Role,
    child: Child,
}

impl Running {
    /// Operating-system process id.
    pub fn pid(&self) -> u32 {
        self.child.id()
    }
}

/// The processes of one run; stops them all when dropped.
#[derive(Debug, Default)]
pub struct Children {
    procs: Vec<Running>,
    stop_timeout: Duration,
}

/// Where a bare command name is looked for first: the supervisor's own folder.
fn resolve(program: &str) -> PathBuf {
    if program.contains('/') {
        return PathBuf::from(program);
    }
    if let Some(dir) = std::env::current_exe()
        .ok()
        .and_then(|p| p.parent().map(Path::to_path_buf))
    {
        let candidate = dir.join(program);
        if candidate.is_file() {
            return candidate;
        }
    }
    PathBuf::from(program) // PATH lookup by the OS
}

impl Children {
    /// No process yet.
    pub fn new(stop_timeout: Duration) -> Self {
        Self {
            procs: Vec::new(),
            stop_timeout,
        }
    }

    /// Starts the process of `role` as configured. Children inherit stderr; their log level
    /// defaults to warnings (`RTC_LOG` overrides).
    pub fn spawn(
        &mut self,
        cfg: &Config,
        role: Role,
        instance: &InstanceName,
    ) -> Result<u32, String> {
        let command: Vec<String> = cfg
            .process
            .get(role)
            .command
            .iter()
            .map(|a| a.replace("{instance}", instance.as_str()))
            .collect();
        let program = resolve(&command[0]);
        let mut cmd = Command::new(&program);
        cmd.args(&command[1..])
            .stdin(Stdio::null())
            .stdout(Stdio::null());
        if std::env::var_os("RTC_LOG").is_none() {
            cmd.env("RTC_LOG", "warn");
        }
        let child = cmd
            .spawn()
            .map_err(|e| format!("cannot start {} ({}): {e}", role.name(), program.display()))?;
        let pid = child.id();
        self.procs.push(Running { role, child });
        Ok(pid)
    }

    /// The running processes, in start order.
    pub fn iter(&self) -> impl Iterator<Item = &Running> {
        self.procs.iter()
    }

    /// The first process that has exited, with its exit status.
    pub fn exited(&mut self) -> Option<(Role, u32, ExitStatus)> {
        for p in &mut self.procs {
            if let Ok(Some(status)) = p.child.try_wait() {
                return Some((p.role, p.child.id(), status));
            }
        }
        None
    }

    /// Stops every process in reverse start order: SIGTERM, then SIGKILL after the stop
    /// timeout. Returns the roles that did not exit cleanly (status 0) with a description.
    pub fn stop_all(&mut self) -> Vec<(Role, String)> {
        let mut problems = Vec::new();
        while let Some(mut p) = self.procs.pop() {
            if let Some(problem) = stop_one(&mut p, self.stop_timeout) {
                problems.push((p.role, problem));
            }
        }
        problems
    }
}

fn stop_one(p: &mut Running, timeout: Duration) -> Option<String> {
    if let Ok(Some(status)) = p.child.try_wait() {
        return (!status.success()).then(|| format!("had already exited ({status})"));
    }
    // SAFETY: plain kill(2) on our own child's pid.
    unsafe { libc::kill(p.child.id() as i32, libc::SIGTERM) };
    let deadline = Instant::now() + timeout;
    loop {
        match p.child.try_wait() {
            Ok(Some(status)) if status.success() => return None,
            Ok(Some(status)) => return Some(format!("exited with {status} after SIGTERM")),
            Ok(None) if Instant::now() < deadline => std::thread::sleep(Duration::from_millis(5)),
            _ => {
                let _ = p.child.kill();
                let _ = p.child.wait();
                return Some(format!(
                    "did not stop within {:.1} s of SIGTERM and was killed",
                    timeout.as_secs_f64()
                ));
            }
        }
    }
}

impl Drop for Children {
    fn drop(&mut self) {
        self.stop_all();
    }
}

/// CPU time (user + system) used by process `pid` so far, from `/proc/<pid>/stat` (s).
pub fn cpu_seconds(pid: u32) -> Option<f64> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    // Fields after the command name (which may contain spaces) start after the last ')'.
    let rest = &stat[stat.rfind(')')? + 2..];
    let fields: Vec<&str> = rest.split_whitespace().collect();
    let utime: f64 = fields.get(11)?.parse().ok()?;
    let stime: f64 = fields.get(12)?.parse().ok()?;
    // SAFETY: sysconf has no preconditions.
    let hz = unsafe { libc::sysconf(libc::_SC_CLK_TCK) } as f64;
    Some((utime + stime) / hz)
}
