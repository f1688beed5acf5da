//! Why a run, a start or a tuning session failed, as the CLI reports it (exit 2, 1 or 130).

use control_plane::Failure;
use control_plane::event::Event;

/// Why a run failed.
#[derive(Debug)]
pub enum RunError {
    /// Bad input (program, configuration, instance): nothing was started. Exit code 2.
    Input(String),
    /// The run started and failed. Exit code 1.
    Failed {
        /// What went wrong.
        failure: Box<Failure>,
        /// The events of the run up to the failure (`docs/events.md`).
        events: Vec<Event>,
        /// A program's figures up to the failure (`--plot`), when it had started.
        figures: Option<Box<control_plane::figures::Figures>>,
    },
    /// Ctrl-C / SIGTERM. Exit code 130.
    Interrupted,
}

impl RunError {
    /// A started run failed (its events are attached when the run ends).
    pub fn failed(failure: Failure) -> Self {
        Self::Failed {
            failure: Box::new(failure),
            events: Vec::new(),
            figures: None,
        }
    }

    /// The supervisor's own means failed (shared memory, a file, a signal handler): `what`,
    /// with the system's words.
    pub fn system(what: impl Into<String>) -> Self {
        Self::failed(Failure::System { what: what.into() })
    }

    /// Why it failed, as the control channel and `run --json` carry it: a started run's
    /// failure, or (bad input, an interruption) the system's words.
    pub fn cause(&self) -> Failure {
        match self {
            Self::Failed { failure, .. } => (**failure).clone(),
            _ => Failure::System {
                what: self.to_string(),
            },
        }
    }

    /// The events the failed run recorded.
    pub fn events(&self) -> &[Event] {
        match self {
            Self::Failed { events, .. } => events,
            _ => &[],
        }
    }
}

impl RunError {
    /// The failure as `run --json` prints it.
    pub fn document(&self) -> control_plane::report::RunFailure {
        control_plane::report::RunFailure {
            ok: false,
            error: self.to_string(),
            cause: self.cause(),
            events: self.events().to_vec(),
        }
    }
}

impl std::fmt::Display for RunError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            RunError::Input(m) => f.write_str(m),
            RunError::Failed { failure, .. } => write!(f, "{failure}"),
            RunError::Interrupted => f.write_str("interrupted; every process was stopped"),
        }
    }
}

impl std::error::Error for RunError {}

impl From<recorder::RecordError> for RunError {
    fn from(e: recorder::RecordError) -> Self {
        if e.is_input() {
            Self::Input(e.to_string())
        } else {
            Self::system(e.to_string())
        }
    }
}
