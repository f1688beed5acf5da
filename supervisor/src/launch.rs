//! Starting and stopping the cell's processes.
//!
//! Each process is started from its configured command line, so any of them can be replaced
//! by another program. Each runs in a process group of its own (so whatever it starts in the
//! background is stopped with it) and gets SIGTERM when the supervisor dies (the parent-death
//! signal; its runtime then brings the axes to rest and exits). [`Children`] stops whatever is
//! still running when it is dropped, so no error path leaves a process behind.

use cell_config::Process;
use nix::sys::signal::{Signal, killpg};
use nix::unistd::Pid;
use shm_schema::InstanceName;
use std::os::fd::{AsFd, BorrowedFd, FromRawFd, OwnedFd};
use std::os::unix::process::CommandExt;

use runtime::time::Moment;
use std::process::{Child, Command, ExitStatus, Stdio};
use std::time::Duration;

/// A running process of the cell.
#[derive(Debug)]
pub struct Running {
    /// Its name in the process table.
    pub name: String,
    /// Its index in the process table.
    pub index: usize,
    child: Child,
    /// A descriptor that becomes readable when the process exits (`pidfd_open`), so the
    /// supervisor's wait wakes at once.
    pidfd: Option<OwnedFd>,
}

impl Running {
    /// Operating-system process id.
    pub fn pid(&self) -> u32 {
        self.child.id()
    }
}

/// A process told to stop (SIGTERM to its group) that has not left yet.
#[derive(Debug)]
struct Leaving {
    p: Running,
    /// SIGKILL after this.
    deadline: Moment,
    /// It was past its deadline and got SIGKILL.
    killed: bool,
}

impl Leaving {
    /// SIGTERM to `p`'s group: it is to leave within `timeout`.
    fn tell(p: Running, timeout: Duration) -> Self {
        let _ = killpg(Pid::from_raw(p.pid() as i32), Signal::SIGTERM);
        Self {
            p,
            deadline: Moment::now() + timeout,
            killed: false,
        }
    }

    /// `Some` once it has left (and whatever it left in its group is killed), with the
    /// problem if it did not exit cleanly; SIGKILL once it is past its deadline. `timeout`
    /// is the one it was told with.
    fn poll(&mut self, timeout: Duration) -> Option<Option<String>> {
        let group = Pid::from_raw(self.p.pid() as i32);
        let killed = || {
            format!(
                "did not stop within {:.1} s of SIGTERM and was killed",
                timeout.as_secs_f64()
            )
        };
        match self.p.child.try_wait() {
            Ok(Some(status)) => {
                let _ = killpg(group, Signal::SIGKILL);
                Some(if self.killed {
                    Some(killed())
                } else {
                    (!status.success()).then(|| format!("exited with {status} after SIGTERM"))
                })
            }
            Ok(None) => {
                if Moment::now() >= self.deadline && !self.killed {
                    let _ = killpg(group, Signal::SIGKILL);
                    self.killed = true;
                }
                None
            }
            // It cannot be waited for: killed, and taken for gone.
            Err(_) => {
                let _ = killpg(group, Signal::SIGKILL);
                let _ = self.p.child.wait();
                Some(Some(killed()))
            }
        }
    }
}

/// A process that left after it was told to ([`Children::reap`]).
#[derive(Debug)]
pub struct Left {
    /// Its name in the process table.
    pub name: String,
    /// Its pid.
    pub pid: u32,
    /// `Some(problem)` if it did not exit cleanly (status 0) or was killed.
    pub problem: Option<String>,
}

/// The processes of one run; stops them all when dropped.
#[derive(Debug, Default)]
pub struct Children {
    procs: Vec<Running>,
    /// Told to stop ([`Children::dismiss`]), not gone yet.
    leaving: Vec<Leaving>,
    stop_timeout: Duration,
}

pub use cell_config::find_program;

impl Children {
    /// No process yet.
    pub fn new(stop_timeout: Duration) -> Self {
        // What `spawn` relies on to keep the supervisor's files out of its processes: a range
        // that holds no descriptor, marked close-on-exec, says whether the kernel has it (5.11).
        if cloexec_from(u32::MAX - 1) != 0 {
            tracing::warn!(
                "close_range(CLOSE_RANGE_CLOEXEC) is not available ({}): the cell's processes \
                 inherit the supervisor's iceoryx2 files",
                std::io::Error::last_os_error()
            );
        }
        Self {
            procs: Vec::new(),
            leaving: Vec::new(),
            stop_timeout,
        }
    }

    /// Starts process `index` of the table, `p`, as configured (`command` overrides its
    /// command line). Children inherit stderr; their log level defaults to warnings (`RTC_LOG`
    /// overrides). `NOTIFY_SOCKET` is the supervisor's own: no child says it is ready there.
    pub fn spawn(
        &mut self,
        p: &Process,
        index: usize,
        command: Option<&[String]>,
        instance: &InstanceName,
    ) -> Result<u32, String> {
        let command: Vec<String> = command
            .unwrap_or(&p.command)
            .iter()
            .map(|a| {
                a.replace("{instance}", instance.as_str())
                    .replace("{name}", &p.name)
            })
            .collect();
        let Some(first) = command.first() else {
            return Err(format!("process {}: empty command", p.name));
        };
        let program = find_program(first).map_err(|e| format!("cannot start {}: {e}", p.name))?;
        let mut cmd = Command::new(&program);
        cmd.args(&command[1..])
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .env_remove("NOTIFY_SOCKET")
            .process_group(0);
        // SAFETY: between fork and exec only async-signal-safe calls: prctl(PR_SET_PDEATHSIG)
        // and close_range(2), both plain system calls.
        unsafe {
            cmd.pre_exec(|| {
                nix::sys::prctl::set_pdeathsig(Signal::SIGTERM).map_err(std::io::Error::from)?;
                // Nothing of the supervisor's but stdio crosses the exec: iceoryx2 opens its
                // files without close-on-exec, and every process inherited the supervisor's
                // node (its liveness lock: a killed supervisor's node looked alive while its
                // processes ran) and a descriptor for each of its ports.
                // Close-on-exec, not closed: the standard library's exec-error pipe still works.
                cloexec_from(3);
                Ok(())
            });
        }
        if std::env::var_os("RTC_LOG").is_none() {
            cmd.env("RTC_LOG", "warn");
        }
        let child = cmd
            .spawn()
            .map_err(|e| format!("cannot start {} ({}): {e}", p.name, program.display()))?;
        let pid = child.id();
        self.procs.push(Running {
            name: p.name.clone(),
            index,
            child,
            pidfd: pidfd_open(pid),
        });
        Ok(pid)
    }

    /// The process of table index `index`, if it runs.
    pub fn get(&self, index: usize) -> Option<&Running> {
        self.procs.iter().find(|p| p.index == index)
    }

    /// Descriptors that become readable when a process exits (a leaving one's too).
    pub fn fds(&self) -> Vec<BorrowedFd<'_>> {
        self.procs
            .iter()
            .chain(self.leaving.iter().map(|l| &l.p))
            .filter_map(|p| p.pidfd.as_ref().map(|f| f.as_fd()))
            .collect()
    }

    /// Tells the process with pid `pid` to stop (SIGTERM to its group) and lets it leave in
    /// the background: [`Children::reap`] takes it once it has exited, and kills it after the
    /// stop timeout. Nobody waits here, so the supervisor's loop goes on meanwhile (a swap's
    /// old process stopping, a failed new one). False if no such process runs.
    pub fn dismiss(&mut self, pid: u32) -> bool {
        let Some(k) = self.procs.iter().position(|p| p.pid() == pid) else {
            return false;
        };
        let p = self.procs.remove(k);
        self.leaving.push(Leaving::tell(p, self.stop_timeout));
        true
    }

    /// The process with pid `pid` was dismissed and has not left yet.
    pub fn is_leaving(&self, pid: u32) -> bool {
        self.leaving.iter().any(|l| l.p.pid() == pid)
    }

    /// Takes the dismissed processes that have left, and kills those past the stop timeout
    /// (they are taken on a later call, once gone).
    pub fn reap(&mut self) -> Vec<Left> {
        let mut left = Vec::new();
        let mut k = 0;
        while k < self.leaving.len() {
            match self.leaving[k].poll(self.stop_timeout) {
                Some(problem) => {
                    let l = self.leaving.remove(k);
                    left.push(Left {
                        name: l.p.name,
                        pid: l.p.child.id(),
                        problem,
                    });
                }
                None => k += 1,
            }
        }
        left
    }

    /// Kills the group of the process of table index `index` at once (a stalled process);
    /// its exit is then seen by [`Children::exited`].
    pub fn kill(&self, index: usize) {
        if let Some(p) = self.get(index) {
            let _ = killpg(Pid::from_raw(p.pid() as i32), Signal::SIGKILL);
        }
    }

    /// The running processes, in the order they were started.
    pub fn iter(&self) -> impl Iterator<Item = &Running> {
        self.procs.iter()
    }

    /// The first process that has exited, with its exit status; it is no longer a child.
    pub fn exited(&mut self) -> Option<(Running, ExitStatus)> {
        let k = self
            .procs
            .iter_mut()
            .position(|p| matches!(p.child.try_wait(), Ok(Some(_))))?;
        let mut p = self.procs.remove(k);
        let status = p.child.wait().ok()?;
        // Whatever it started in its group goes with it.
        let _ = killpg(Pid::from_raw(p.child.id() as i32), Signal::SIGKILL);
        Some((p, status))
    }

    /// Stops every process in reverse table order (the process graph's: the table is its
    /// start order), whatever order restarts and swaps left them in: SIGTERM to its group,
    /// then SIGKILL after the stop timeout; `tick` runs every few milliseconds meanwhile (the
    /// supervisor's heartbeat). Returns the processes that did not exit cleanly (status 0)
    /// with a description.
    pub fn stop_all(&mut self, tick: &mut dyn FnMut()) -> Vec<(String, String)> {
        let mut problems = Vec::new();
        // Stable: of two with one index (a swap under way), the newer stops first.
        self.procs.sort_by_key(|p| p.index);
        while let Some(mut p) = self.procs.pop() {
            if let Ok(Some(status)) = p.child.try_wait() {
                let _ = killpg(Pid::from_raw(p.pid() as i32), Signal::SIGKILL);
                if !status.success() {
                    problems.push((p.name, format!("had already exited ({status})")));
                }
                continue;
            }
            self.leaving.push(Leaving::tell(p, self.stop_timeout));
            self.wait_left(&mut problems, tick);
        }
        // What was dismissed before and is still leaving.
        self.wait_left(&mut problems, tick);
        problems
    }

    /// Waits until every process told to stop has left (killing those past their
    /// deadline), `tick` running every few milliseconds; their problems into `problems`.
    fn wait_left(&mut self, problems: &mut Vec<(String, String)>, tick: &mut dyn FnMut()) {
        loop {
            for l in self.reap() {
                if let Some(problem) = l.problem {
                    problems.push((l.name, problem));
                }
            }
            if self.leaving.is_empty() {
                return;
            }
            tick();
            std::thread::sleep(Duration::from_millis(5));
        }
    }
}

impl Drop for Children {
    fn drop(&mut self) {
        self.stop_all(&mut || {});
    }
}

/// A pidfd for `pid` (Linux 5.3), or `None` where the kernel has none: the supervisor's
/// tick then finds the exit within 10 ms instead of at once.
fn pidfd_open(pid: u32) -> Option<OwnedFd> {
    // SAFETY: pidfd_open takes a pid and flags and returns a new descriptor or -1.
    let fd = unsafe { libc::syscall(libc::SYS_pidfd_open, pid as libc::pid_t, 0) };
    // SAFETY: a non-negative return is a descriptor this process now owns.
    (fd >= 0).then(|| unsafe { OwnedFd::from_raw_fd(fd as i32) })
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

/// Marks every descriptor from `first` on close-on-exec (`close_range(2)` with
/// `CLOSE_RANGE_CLOEXEC`, Linux 5.11): 0, or -1 where the kernel does not have it. A plain
/// system call, async-signal-safe (no allocation): fit for between fork and exec.
fn cloexec_from(first: u32) -> libc::c_long {
    // SAFETY: a system call on this process' own descriptor table; nothing is closed.
    unsafe {
        libc::syscall(
            libc::SYS_close_range,
            first,
            u32::MAX,
            libc::CLOSE_RANGE_CLOEXEC,
        )
    }
}
