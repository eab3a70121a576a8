//! Why a run stops before its budget, and how.
//!
//! - SIGINT (Ctrl-C) stops at once with a checkpoint. Taken mid-episode, that checkpoint
//!   resumes by starting a new episode, so the continued run is not bit-identical.
//! - SIGUSR1 and SIGTERM stop at the next episode boundary. A scheduler sends these before a
//!   time limit or a preemption (Slurm: `--signal=B:USR1@120`, then SIGTERM at the limit); an
//!   episode is at most a few seconds of training, and the checkpoint taken at its end resumes
//!   bit for bit, so a requeued job loses nothing.
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, OnceLock};

pub(crate) struct StopSignals {
    now: Arc<AtomicBool>,
    at_episode_end: Arc<AtomicBool>,
}

impl StopSignals {
    /// Stop at once (Ctrl-C).
    pub fn now(&self) -> bool {
        self.now.load(Ordering::SeqCst)
    }

    /// Stop at the next episode boundary (SIGUSR1, SIGTERM).
    pub(crate) fn at_episode_end(&self) -> bool {
        self.at_episode_end.load(Ordering::SeqCst)
    }
}

/// The process-wide flags; the handlers are installed on first use.
pub(crate) fn stop_signals() -> &'static StopSignals {
    static SIGNALS: OnceLock<StopSignals> = OnceLock::new();
    SIGNALS.get_or_init(|| {
        let s = StopSignals { now: Arc::new(AtomicBool::new(false)), at_episode_end: Arc::new(AtomicBool::new(false)) };
        use signal_hook::consts::{SIGINT, SIGTERM, SIGUSR1};
        // Registering only fails for signals that cannot be caught; these three can.
        let _ = signal_hook::flag::register(SIGINT, Arc::clone(&s.now));
        for sig in [SIGUSR1, SIGTERM] {
            let _ = signal_hook::flag::register(sig, Arc::clone(&s.at_episode_end));
        }
        s
    })
}
