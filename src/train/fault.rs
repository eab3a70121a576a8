//! Crash points for the crash tests (`tests/crash.rs`): with `LOCOBENCH_FAULT=<point>:<n>` set,
//! the process kills itself with SIGKILL the n-th time it reaches `<point>`, the way a
//! preempting scheduler or the OOM killer would: no destructor, no flush, no signal handler runs.
//! Unset (always, outside those tests), reaching a point is one load of a cached value.
//!
//! The points are the moments where a kill could tear a run's files apart: half-way through a
//! checkpoint's files, right after a checkpoint, between two environment steps (mid-episode),
//! half-way through an evaluation, and half-way through writing a budget policy.
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::OnceLock;

/// Where a run can be killed on purpose.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Point {
    /// A checkpoint's networks are written under the temporary name, the rest is not.
    CheckpointWrite,
    /// A checkpoint was just made the newest one.
    AfterCheckpoint,
    /// An environment step (one call of the vector env's step counts once).
    Step,
    /// An evaluation has played its first episode.
    Evaluation,
    /// A budget policy's temporary file is written, not yet renamed into place.
    BudgetPolicyWrite,
}

impl Point {
    const ALL: [Point; 5] =
        [Point::CheckpointWrite, Point::AfterCheckpoint, Point::Step, Point::Evaluation, Point::BudgetPolicyWrite];

    fn name(self) -> &'static str {
        match self {
            Point::CheckpointWrite => "checkpoint-write",
            Point::AfterCheckpoint => "after-checkpoint",
            Point::Step => "step",
            Point::Evaluation => "evaluation",
            Point::BudgetPolicyWrite => "budget-policy-write",
        }
    }
}

/// The variable that arms a crash point.
pub const VARIABLE: &str = "LOCOBENCH_FAULT";

fn armed() -> Option<(Point, u64)> {
    static ARMED: OnceLock<Option<(Point, u64)>> = OnceLock::new();
    *ARMED.get_or_init(|| {
        let value = std::env::var(VARIABLE).ok()?;
        let parsed = value.split_once(':').and_then(|(name, n)| {
            let point = Point::ALL.into_iter().find(|p| p.name() == name)?;
            Some((point, n.parse::<u64>().ok().filter(|&n| n > 0)?))
        });
        if parsed.is_none() {
            let names: Vec<&str> = Point::ALL.iter().map(|p| p.name()).collect();
            eprintln!(
                "warning: {VARIABLE}={value:?} ignored: expected <point>:<n> with n >= 1, point one of {names:?}"
            );
        }
        parsed
    })
}

/// Kills this process if `point` is armed and this is its n-th visit.
pub(crate) fn reach(point: Point) {
    static VISITS: AtomicU64 = AtomicU64::new(0);
    if let Some((armed_point, n)) = armed() {
        if armed_point == point && VISITS.fetch_add(1, Ordering::SeqCst) + 1 == n {
            // SAFETY: kill(2) on our own pid; it does not return for SIGKILL.
            unsafe { libc::kill(libc::getpid(), libc::SIGKILL) };
        }
    }
}
