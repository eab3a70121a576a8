//! Learning curves on the `train_step` timeline.
use anyhow::Result;
use rerun::RecordingStream;

use crate::train::metrics::MetricsRow;

/// Logs every value a metrics row carries under `training/`.
pub fn log_training_row(rec: &RecordingStream, row: &MetricsRow) -> Result<()> {
    rec.reset_time();
    rec.set_time_sequence("train_step", row.step as i64);
    let values = [
        ("training/episode_return", row.episode_return),
        ("training/episode_length", row.episode_length.map(|l| l as f64)),
        ("training/eval_mean", row.eval_mean),
        ("training/eval_std", row.eval_std),
        ("training/critic_loss", row.critic_loss),
        ("training/actor_loss", row.actor_loss),
        ("training/alpha", row.alpha),
        ("training/steps_per_s", Some(row.steps_per_s)),
    ];
    for (path, value) in values {
        if let Some(v) = value {
            rec.log(path, &rerun::Scalars::single(v))?;
        }
    }
    Ok(())
}
