//! `locobench sweep status DIR`: where each job of a sweep stands, from the run directories,
//! the jobs' exit files and locks, and (for Slurm sweeps) the scheduler.
use std::path::Path;

use anyhow::Result;

use super::slurm::{is_active, is_failure, is_running, task_states, TaskState};
use super::{exit_path, log_path, read_plan, Job};
use crate::train::run_lock::read_lock;
use crate::train::{run_progress, RunProgress};

/// Where a sweep job stands.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum JobState {
    /// Reached its budget.
    Finished,
    /// Running now (its run lock is held).
    Running,
    /// Queued, or not started yet.
    Pending,
    /// Stopped before its budget (a signal, a time limit) with a checkpoint: running the job
    /// again continues it.
    Stopped,
    /// Exited with an error, or Slurm reports a failed task.
    Failed,
}

impl JobState {
    /// The state's name in the status table.
    pub fn label(self) -> &'static str {
        match self {
            JobState::Finished => "finished",
            JobState::Running => "running",
            JobState::Pending => "pending",
            JobState::Stopped => "stopped",
            JobState::Failed => "failed",
        }
    }
}

/// One job's state, progress and where it runs.
#[derive(Debug, Clone)]
pub struct JobStatus {
    /// The job's name.
    pub name: String,
    /// Where it stands.
    pub state: JobState,
    /// Steps done and budget, from its run directory.
    pub progress: Option<RunProgress>,
    /// The exit code recorded, if it ended.
    pub exit_code: Option<i32>,
    /// Slurm's view of its array task, for Slurm sweeps.
    pub slurm: Option<TaskState>,
    /// Where the job runs or ran, when another host holds its lock.
    pub host: Option<String>,
    /// The end of the job's log, for failed jobs.
    pub log_tail: Vec<String>,
}

/// Decides one job's state. The order matters: a finished run is finished whatever the
/// scheduler says; the scheduler knows best what still runs or waits; then the local evidence.
pub(crate) fn job_state(
    progress: Option<&RunProgress>,
    exit_code: Option<i32>,
    slurm: Option<&str>,
    lock_alive: Option<Option<bool>>,
) -> JobState {
    if progress.is_some_and(|p| p.finished()) {
        return JobState::Finished;
    }
    match slurm {
        Some(s) if is_running(s) => return JobState::Running,
        Some(s) if is_active(s) => return JobState::Pending,
        _ => {}
    }
    match lock_alive {
        // this host's process is alive, or another host's lock (Slurm may not be asked)
        Some(Some(true)) | Some(None) => return JobState::Running,
        // a lock whose process is gone: it died without cleaning up (killed, out of memory)
        Some(Some(false)) => return JobState::Failed,
        None => {}
    }
    if exit_code.is_some_and(|c| c != 0) || slurm.is_some_and(is_failure) {
        return JobState::Failed;
    }
    if progress.is_some() {
        JobState::Stopped
    } else {
        JobState::Pending
    }
}

fn tail(path: &Path, lines: usize) -> Vec<String> {
    let text = std::fs::read_to_string(path).unwrap_or_default();
    let all: Vec<&str> = text.lines().filter(|l| !l.trim().is_empty()).collect();
    all[all.len().saturating_sub(lines)..].iter().map(|s| s.to_string()).collect()
}

/// The status of every job of the sweep in `sweep_dir`, in jobs.txt order.
pub fn sweep_status(sweep_dir: &Path) -> Result<Vec<JobStatus>> {
    let (_, jobs) = read_plan(sweep_dir)?;
    let slurm = task_states(sweep_dir)?;
    Ok(jobs.iter().enumerate().map(|(i, job)| job_status(sweep_dir, i, job, &slurm)).collect())
}

fn job_status(sweep_dir: &Path, index: usize, job: &Job, slurm: &[(usize, TaskState)]) -> JobStatus {
    let progress = run_progress(&job.run_dir).ok();
    let exit_code = std::fs::read_to_string(exit_path(sweep_dir, job)).ok().and_then(|t| t.trim().parse().ok());
    let slurm = slurm.iter().find(|(t, _)| *t == index).map(|(_, s)| s.clone());
    let lock = read_lock(&job.run_dir);
    let state = job_state(
        progress.as_ref(),
        exit_code,
        slurm.as_ref().map(|s| s.state.as_str()),
        lock.as_ref().map(|l| l.alive()),
    );
    let host = lock.filter(|l| l.alive().is_none()).map(|l| l.host);
    let log_tail = if state == JobState::Failed { tail(&log_path(sweep_dir, job), 5) } else { Vec::new() };
    JobStatus { name: job.name.clone(), state, progress, exit_code, slurm, host, log_tail }
}

/// The status table as text: one line per job, failed jobs' last log lines under them, and a
/// count per state.
pub fn render(statuses: &[JobStatus]) -> String {
    let width = statuses.iter().map(|s| s.name.len()).max().unwrap_or(3).max(3);
    let mut out = format!("{:width$}  {:8}  {:>17}  {:>10}  slurm\n", "job", "state", "steps", "last eval");
    for s in statuses {
        let steps = s.progress.as_ref().map_or("-".to_string(), |p| format!("{}/{}", p.step(), p.total_steps));
        let eval = s.progress.as_ref().and_then(|p| p.last_eval).map_or("-".to_string(), |e| format!("{e:.2}"));
        let mut slurm = s.slurm.as_ref().map_or("-".to_string(), |t| format!("{} {}", t.job_id, t.state));
        if let Some(h) = &s.host {
            slurm.push_str(&format!(" (lock on {h})"));
        }
        if let Some(c) = s.exit_code.filter(|c| *c != 0) {
            slurm.push_str(&format!(" exit {c}"));
        }
        out.push_str(&format!("{:width$}  {:8}  {steps:>17}  {eval:>10}  {slurm}\n", s.name, s.state.label()));
        for line in &s.log_tail {
            out.push_str(&format!("    | {line}\n"));
        }
    }
    let count = |st: JobState| statuses.iter().filter(|s| s.state == st).count();
    out.push_str(&format!(
        "{} jobs: {} finished, {} running, {} pending, {} stopped, {} failed\n",
        statuses.len(),
        count(JobState::Finished),
        count(JobState::Running),
        count(JobState::Pending),
        count(JobState::Stopped),
        count(JobState::Failed)
    ));
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn progress(step: u64, total: u64) -> RunProgress {
        RunProgress { total_steps: total, checkpoint_step: Some(step), metrics_step: Some(step), last_eval: None }
    }

    #[test]
    fn states_follow_the_evidence_in_order() {
        let done = progress(100, 100);
        let half = progress(50, 100);
        // finished wins over everything
        assert_eq!(job_state(Some(&done), Some(1), Some("FAILED"), None), JobState::Finished);
        // the scheduler knows what runs and waits
        assert_eq!(job_state(Some(&half), None, Some("RUNNING"), None), JobState::Running);
        assert_eq!(job_state(Some(&half), Some(0), Some("REQUEUED"), None), JobState::Pending);
        assert_eq!(job_state(None, None, Some("PENDING"), None), JobState::Pending);
        // local evidence
        assert_eq!(job_state(Some(&half), None, None, Some(Some(true))), JobState::Running);
        assert_eq!(job_state(Some(&half), None, None, Some(Some(false))), JobState::Failed);
        assert_eq!(job_state(Some(&half), Some(1), None, None), JobState::Failed);
        assert_eq!(job_state(Some(&half), None, Some("TIMEOUT"), None), JobState::Failed);
        assert_eq!(job_state(Some(&half), Some(0), Some("COMPLETED"), None), JobState::Stopped);
        assert_eq!(job_state(None, None, None, None), JobState::Pending);
    }
}
