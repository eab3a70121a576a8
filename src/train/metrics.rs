//! `metrics.csv`: one row per training episode and per evaluation, rewritten atomically.
use std::path::Path;

use anyhow::{bail, Context, Result};

use crate::agents::Losses;
use crate::io::write_atomic;

/// The file's name, in a run directory and in each checkpoint.
pub const FILE: &str = "metrics.csv";

/// One row of `metrics.csv`: a training episode's end or an evaluation.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct MetricsRow {
    /// `episode` or `eval`.
    pub kind: &'static str,
    /// Environment steps so far.
    pub step: u64,
    /// The episode's return (`episode` rows).
    pub episode_return: Option<f64>,
    /// The episode's length (`episode` rows).
    pub episode_length: Option<u64>,
    /// Mean evaluation return (`eval` rows).
    pub eval_mean: Option<f64>,
    /// Std of the evaluation returns (`eval` rows).
    pub eval_std: Option<f64>,
    /// Latest critic loss.
    pub critic_loss: Option<f64>,
    /// Latest actor loss.
    pub actor_loss: Option<f64>,
    /// SAC's temperature.
    pub alpha: Option<f64>,
    /// Environment steps per second since the previous row.
    pub steps_per_s: f64,
    /// Seconds since the run started, summed over resumed stretches.
    pub wall_time: f64,
    /// Evaluation rows: share of action components at the bounds (|a| >= 0.99) over every
    /// evaluation step, the sign of a deterministic actor pushed into saturation. Absent in
    /// files written before the column existed.
    pub eval_saturation: Option<f64>,
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

    /// Every value the row carries besides its kind and step, by its `metrics.csv` column
    /// (None where the column is empty), for the logs that mirror the file.
    pub(crate) fn values(&self) -> [(&'static str, Option<f64>); 10] {
        [
            ("episode_return", self.episode_return),
            ("episode_length", self.episode_length.map(|l| l as f64)),
            ("eval_mean", self.eval_mean),
            ("eval_std", self.eval_std),
            ("critic_loss", self.critic_loss),
            ("actor_loss", self.actor_loss),
            ("alpha", self.alpha),
            ("steps_per_s", Some(self.steps_per_s)),
            ("wall_time", Some(self.wall_time)),
            ("eval_saturation", self.eval_saturation),
        ]
    }

    /// This row with an evaluation's mean, std and saturation.
    pub(crate) fn with_evaluation(self, e: &super::evaluate::Evaluation) -> MetricsRow {
        MetricsRow { eval_mean: Some(e.mean()), eval_std: Some(e.std()), eval_saturation: Some(e.saturation), ..self }
    }
}

pub(crate) const HEADER: [&str; 12] = [
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
    "eval_saturation",
];

fn opt<T: ToString>(v: Option<T>) -> String {
    v.map(|x| x.to_string()).unwrap_or_default()
}

/// Writes the rows to `path` atomically.
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
                opt(r.eval_saturation),
            ])?;
        }
        csv.flush()?;
        Ok(())
    })
}

/// Reads the rows of a `metrics.csv`. A row that does not parse is an error naming the file and
/// its line.
pub fn read(path: &Path) -> Result<Vec<MetricsRow>> {
    let text = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    parse(&text, path)
}

/// The rows of `text`, the contents of the `metrics.csv` at `path` (named in errors).
fn parse(text: &str, path: &Path) -> Result<Vec<MetricsRow>> {
    let mut rows = Vec::new();
    // Flexible: files from before the eval_saturation column have one field fewer.
    let mut reader = csv::ReaderBuilder::new().flexible(true).from_reader(text.as_bytes());
    let header = reader.headers().with_context(|| format!("reading {}", path.display()))?.clone();
    if header.iter().ne(HEADER.iter().copied().take(header.len())) || header.len() < HEADER.len() - 1 {
        bail!("{} does not start with the metrics header ({})", path.display(), HEADER.join(","));
    }
    for (i, rec) in reader.records().enumerate() {
        let line = i + 2;
        let row = rec.map_err(anyhow::Error::from).and_then(|rec| parse_row(&rec, header.len()));
        rows.push(row.with_context(|| format!("{} line {line} is not a metrics row", path.display()))?);
    }
    Ok(rows)
}

fn parse_row(rec: &csv::StringRecord, width: usize) -> Result<MetricsRow> {
    if rec.len() != width {
        bail!("{} fields where the header has {width}", rec.len());
    }
    let f = |i: usize| rec.get(i).filter(|s| !s.is_empty()).map(|s| s.parse::<f64>()).transpose();
    let kind = match rec.get(0) {
        Some("eval") => "eval",
        Some("episode") => "episode",
        other => bail!("unknown kind {:?}", other.unwrap_or("")),
    };
    Ok(MetricsRow {
        kind,
        step: rec.get(1).unwrap_or("").parse().context("the step is not a whole number")?,
        episode_return: f(2)?,
        episode_length: f(3)?.map(|v| v as u64),
        eval_mean: f(4)?,
        eval_std: f(5)?,
        critic_loss: f(6)?,
        actor_loss: f(7)?,
        alpha: f(8)?,
        steps_per_s: f(9)?.unwrap_or(0.0),
        wall_time: f(10)?.unwrap_or(0.0),
        eval_saturation: f(11)?,
    })
}

/// The rows a run resumed from `checkpoint` (at `step`) starts with. The checkpoint's own copy is
/// authoritative; the run's `metrics.csv` must begin with exactly those rows (it is written before
/// every checkpoint, so it is never behind one). A run's file that is missing, cut short or
/// changed is an error that names it and loses nothing: it is never silently rewritten.
/// Checkpoints from before the copy existed take the run's rows up to `step`.
pub(crate) fn restore(run_dir: &Path, checkpoint: &Path, step: u64) -> Result<Vec<MetricsRow>> {
    let run_file = run_dir.join(FILE);
    let kept = checkpoint.join(FILE);
    if !kept.exists() {
        return Ok(if run_file.exists() {
            read(&run_file)?.into_iter().filter(|r| r.step <= step).collect()
        } else {
            Vec::new()
        });
    }
    let kept_text = std::fs::read_to_string(&kept).with_context(|| format!("reading {}", kept.display()))?;
    let rows = parse(&kept_text, &kept)?;
    let fix = format!(
        "the checkpoint keeps the rows up to step {step} in {}: move the damaged file aside and copy that one in its \
         place to resume (nothing was changed)",
        kept.display()
    );
    let text = match std::fs::read_to_string(&run_file) {
        Ok(text) => text,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound && rows.is_empty() => return Ok(rows),
        Err(e) => return Err(e).with_context(|| format!("{} cannot be read; {fix}", run_file.display())),
    };
    let ours = parse(&text, &run_file).with_context(|| format!("{} is damaged; {fix}", run_file.display()))?;
    let (expected, found): (Vec<&str>, Vec<&str>) = (kept_text.lines().collect(), text.lines().collect());
    if let Some(line) = (0..expected.len()).find(|&i| found.get(i) != expected.get(i)) {
        let what = if line >= found.len() {
            format!(
                "ends after line {} where the checkpoint at step {step} recorded {} lines",
                found.len(),
                expected.len()
            )
        } else {
            format!("line {} differs from the checkpoint's copy", line + 1)
        };
        bail!("{} is damaged or cut short: it {what}; {fix}", run_file.display());
    }
    if let Some(bad) = ours[rows.len()..].iter().position(|r| r.step <= step) {
        bail!(
            "{} is damaged: line {} is at step {} but follows the checkpoint's rows (step {step}); {fix}",
            run_file.display(),
            rows.len() + bad + 2,
            ours[rows.len() + bad].step
        );
    }
    Ok(rows)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn saturation_round_trips_and_older_files_still_read() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("metrics.csv");
        let rows = vec![
            MetricsRow {
                kind: "episode",
                step: 7,
                episode_return: Some(1.5),
                episode_length: Some(7),
                ..Default::default()
            },
            MetricsRow {
                kind: "eval",
                step: 10,
                eval_mean: Some(2.0),
                eval_std: Some(0.5),
                eval_saturation: Some(0.25),
                ..Default::default()
            },
        ];
        write(&path, &rows).unwrap();
        assert_eq!(read(&path).unwrap(), rows);
        // A file from before the column: one field fewer per row.
        std::fs::write(
            &path,
            "kind,step,episode_return,episode_length,eval_mean,eval_std,critic_loss,actor_loss,alpha,steps_per_s,wall_time\n\
             eval,10,,,2,0.5,,,,0.0,0.000\n",
        )
        .unwrap();
        let old = read(&path).unwrap();
        assert_eq!((old[0].eval_mean, old[0].eval_saturation), (Some(2.0), None));
    }
}
