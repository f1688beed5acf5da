//! File descriptors: the soft limit raised to what the system allows at start, and a shortage
//! said in words. iceoryx2 holds a descriptor for every segment and port it opens, and a
//! failure for want of one reaches us as its own error (`UnableToCreateServiceTag`, ...),
//! never as "too many open files".

use nix::sys::resource::{Resource, getrlimit, setrlimit};

/// A process' open descriptors this close to its limit are a shortage (iceoryx2 opens several
/// for one port and closes them again when it fails).
const MARGIN: u64 = 32;

/// Raises this process' soft limit of open files to its hard limit (a shell's 1024 is too few
/// for a cell of many ports; the hard limit is what the administrator allows). What its
/// children inherit too.
pub fn raise_limit() {
    if let Ok((soft, hard)) = getrlimit(Resource::RLIMIT_NOFILE)
        && soft < hard
    {
        let _ = setrlimit(Resource::RLIMIT_NOFILE, hard, hard);
    }
}

/// When this process is out of file descriptors (or within a few of its limit): the words
/// that say so, for an error that would not.
pub fn shortage() -> Option<String> {
    let (limit, _) = getrlimit(Resource::RLIMIT_NOFILE).ok()?;
    let words = |open: &str| {
        format!(
            "too many open files: {open} of this process' limit of {limit} are open \
             (raise it: `ulimit -n`, `LimitNOFILE=` of a systemd unit)"
        )
    };
    match std::fs::read_dir("/proc/self/fd") {
        Ok(dir) => {
            // Less the folder's own.
            let open = (dir.count() as u64).saturating_sub(1);
            (open + MARGIN >= limit).then(|| words(&open.to_string()))
        }
        Err(e) if e.raw_os_error() == Some(libc::EMFILE) => Some(words("all")),
        Err(_) => None,
    }
}
