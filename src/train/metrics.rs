//! `metrics.csv`: one row per training episode and per evaluation, rewritten atomically.
use std::path::Path;

use anyhow::Result;

use crate::agents::Losses;
use crate::io::write_atomic;

#[derive(Debug, Clone, Default, PartialEq)]
pub struct MetricsRow {
    /// `episode` or `eval`.
    pub kind: &'static str,
    pub step: u64,
    pub episode_return: Option<f64>,
    pub episode_length: Option<u64>,
    pub eval_mean: Option<f64>,
    pub eval_std: Option<f64>,
    pub critic_loss: Option<f64>,
    pub actor_loss: Option<f64>,
    pub alpha: Option<f64>,
    pub steps_per_s: f64,
    pub wall_time: f64,
}

impl MetricsRow {
    /// A row with the fields every row carries: losses (once learning started), speed, time.
    pub fn progress(
        kind: &'static str,
        step: u64,
        losses: Option<Losses>,
        steps_per_s: f64,
        wall_time: f64,
    ) -> MetricsRow {
        MetricsRow {
            kind,
            step,
            critic_loss: losses.map(|l| l.critic),
            actor_loss: losses.and_then(|l| l.actor),
            alpha: losses.and_then(|l| l.alpha),
            steps_per_s,
            wall_time,
            ..Default::default()
        }
    }
}

pub const HEADER: [&str; 11] = [
    "kind",
    "step",
    "episode_return",
    "episode_length",
    "eval_mean",
    "eval_std",
    "critic_loss",
    "actor_loss",
    "alpha",
    "steps_per_s",
    "wall_time",
];

fn opt<T: ToString>(v: Option<T>) -> String {
    v.map(|x| x.to_string()).unwrap_or_default()
}

pub fn write(path: &Path, rows: &[MetricsRow]) -> Result<()> {
    write_atomic(path, |w| {
        let mut csv = csv::Writer::from_writer(w);
        csv.write_record(HEADER)?;
        for r in rows {
            csv.write_record([
                r.kind.to_string(),
                r.step.to_string(),
                opt(r.episode_return),
                opt(r.episode_length),
                opt(r.eval_mean),
                opt(r.eval_std),
                opt(r.critic_loss),
                opt(r.actor_loss),
                opt(r.alpha),
                format!("{:.1}", r.steps_per_s),
                format!("{:.3}", r.wall_time),
            ])?;
        }
        csv.flush()?;
        Ok(())
    })
}

pub fn read(path: &Path) -> Result<Vec<MetricsRow>> {
    let mut rows = Vec::new();
    let mut reader = csv::Reader::from_path(path)?;
    for rec in reader.records() {
        let rec = rec?;
        let f = |i: usize| rec.get(i).filter(|s| !s.is_empty()).map(|s| s.parse::<f64>()).transpose();
        rows.push(MetricsRow {
            kind: if rec.get(0) == Some("eval") { "eval" } else { "episode" },
            step: rec.get(1).unwrap_or("0").parse()?,
            episode_return: f(2)?,
            episode_length: f(3)?.map(|v| v as u64),
            eval_mean: f(4)?,
            eval_std: f(5)?,
            critic_loss: f(6)?,
            actor_loss: f(7)?,
            alpha: f(8)?,
            steps_per_s: f(9)?.unwrap_or(0.0),
            wall_time: f(10)?.unwrap_or(0.0),
        });
    }
    Ok(rows)
}
