//! rerun recordings (`.rrd`) of rollouts and of training runs.
//!
//! Entity layout:
//! - `world/<body>`: each body's pose per step (MuJoCo's `xpos`/`xquat`), with its geoms
//!   logged once, statically, as children `world/<body>/<geom>`; geoms of the world body (the
//!   floor) sit directly under `world/`.
//! - `world/contacts/points` and `world/contacts/forces`: contact points and force arrows.
//! - `world/foot_targets`: controller foot targets, when the policy reports them.
//! - `plots/...`: time series (reward and its terms, forward speed, base height, actions,
//!   actuator torques, controller signals) on the `step` and `sim_time` timelines.
//! - `training/...`: learning curves on the `train_step` timeline.
//!
//! Files are written to a temporary name beside the target and renamed when complete.
mod rollout;
mod scene;

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};

pub use rollout::RolloutRecorder;
pub use scene::{body_entity, log_scene};

/// Where the application id shows in the viewer.
pub(crate) const APPLICATION_ID: &str = "locobench";

/// A recording being written to a file.
pub struct Recording {
    stream: rerun::RecordingStream,
    partial: PathBuf,
    target: PathBuf,
    finished: bool,
}

impl Recording {
    /// Starts a recording that becomes `path` when finished (written atomically).
    pub fn create(path: &Path) -> Result<Recording> {
        let dir = match path.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        };
        std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
        let name = path.file_name().with_context(|| format!("{} is not a file path", path.display()))?;
        let partial = dir.join(format!(".{}.partial-{}", name.to_string_lossy(), std::process::id()));
        let stream = rerun::RecordingStreamBuilder::new(APPLICATION_ID)
            .save(&partial)
            .with_context(|| format!("opening {} for writing", partial.display()))?;
        Ok(Recording { stream, partial, target: path.to_path_buf(), finished: false })
    }

    /// The rerun stream to log to.
    pub fn stream(&self) -> &rerun::RecordingStream {
        &self.stream
    }

    /// Flushes everything to disk and moves the file to its final name.
    pub fn finish(mut self) -> Result<PathBuf> {
        self.stream.flush_blocking().map_err(|e| anyhow::anyhow!("flushing {}: {e}", self.partial.display()))?;
        std::fs::rename(&self.partial, &self.target)
            .with_context(|| format!("moving {} to {}", self.partial.display(), self.target.display()))?;
        self.finished = true;
        Ok(self.target.clone())
    }
}

impl Drop for Recording {
    fn drop(&mut self) {
        if !self.finished {
            let _ = self.stream.flush_blocking();
            let _ = std::fs::remove_file(&self.partial);
        }
    }
}

/// Opens `file` in the rerun viewer when a `rerun` binary is on the PATH.
pub fn spawn_viewer(file: &Path) -> Result<()> {
    let found = std::env::var_os("PATH")
        .map(|paths| std::env::split_paths(&paths).any(|dir| dir.join("rerun").is_file()))
        .unwrap_or(false);
    if !found {
        anyhow::bail!(
            "no `rerun` binary on the PATH; install the viewer with `pip install rerun-sdk=={}` \
             (its version must match the recording's), then run `rerun {}`",
            RERUN_VERSION,
            file.display()
        );
    }
    std::process::Command::new("rerun")
        .arg(file)
        .spawn()
        .with_context(|| format!("starting `rerun {}`", file.display()))?;
    Ok(())
}

/// The rerun crate version this build writes (the viewer must match it).
pub(crate) const RERUN_VERSION: &str = "0.36.3";
