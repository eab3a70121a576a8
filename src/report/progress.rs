//! `locobench report --progress RUN`: a run's training clips (`train --video-every`) in training
//! order, each beside the evaluation it filmed, so a reader sees the gait emerge. The clips are
//! copied beside the page (`videos/`), so the page stands alone; HTML plays the MP4s, Markdown
//! shows the GIFs.
use std::path::{Path, PathBuf};

use anyhow::{ensure, Context, Result};

use super::document::{Block, Document};
use super::format::{budget, fmt_return};
use crate::io::write_bytes_atomic;
use crate::train::metrics;

/// The clips a run holds: (step, MP4, GIF), by step.
fn clips(run: &Path) -> Result<Vec<(u64, PathBuf, PathBuf)>> {
    let dir = run.join("videos");
    let entries = std::fs::read_dir(&dir).with_context(|| {
        format!("{}: no training clips (train with --video-every N to film its evaluations)", dir.display())
    })?;
    let mut out = Vec::new();
    for e in entries {
        let path = e?.path();
        let name = path.file_name().and_then(|n| n.to_str()).unwrap_or_default();
        if let Some(step) = name.strip_prefix("eval-step-").and_then(|r| r.strip_suffix(".mp4")) {
            let Ok(step) = step.parse::<u64>() else { continue };
            out.push((step, path.clone(), path.with_extension("gif")));
        }
    }
    out.sort_by_key(|c| c.0);
    ensure!(!out.is_empty(), "{}: no training clips (eval-step-N.mp4)", dir.display());
    Ok(out)
}

/// Writes the progress page of `run` into `out` (index.html and README.md, clips in videos/).
pub fn write_progress(run: &Path, out: &Path) -> Result<(PathBuf, usize)> {
    let config = crate::train::run_config::read_run_config(run)
        .with_context(|| format!("{} is not a run directory", run.display()))?;
    let rows = metrics::read(&run.join(metrics::FILE))?;
    let clips = clips(run)?;
    let videos = out.join(super::videos::VIDEO_DIR);
    std::fs::create_dir_all(&videos).with_context(|| format!("creating {}", videos.display()))?;
    let mut doc = Document::new(&format!("Training progress: {}", run.display()));
    doc.paragraph(format!(
        "{} on {}, seed {}: the deterministic evaluation episode (the run's first evaluation seed) filmed during \
         training, in training order. Each caption gives the evaluation's mean return over its {} episodes.",
        config.train.algo.name(),
        config.env.name,
        config.seed,
        config.train.eval_episodes
    ));
    for (step, mp4, gif) in &clips {
        let name = |p: &Path| p.file_name().expect("a clip file").to_string_lossy().into_owned();
        let copy = |from: &Path| -> Result<String> {
            let bytes = std::fs::read(from).with_context(|| format!("reading {}", from.display()))?;
            write_bytes_atomic(&videos.join(name(from)), &bytes)?;
            Ok(format!("{}/{}", super::videos::VIDEO_DIR, name(from)))
        };
        let eval = rows.iter().find(|r| r.kind == "eval" && r.step == *step);
        let caption = match eval.and_then(|r| r.eval_mean.zip(r.eval_std)) {
            Some((mean, std)) => format!(
                "step {} ({}): evaluation return {} ± {} (sample std)",
                step,
                budget(*step),
                fmt_return(mean),
                fmt_return(std)
            ),
            None => format!("step {step} ({})", budget(*step)),
        };
        doc.heading(1, format!("Step {}", budget(*step)));
        let gif = if gif.is_file() { Some(copy(gif)?) } else { None };
        doc.blocks.push(Block::Video { video: copy(mp4)?, gif, poster: None, caption, timing: None });
    }
    write_bytes_atomic(&out.join("index.html"), doc.to_html().as_bytes())?;
    write_bytes_atomic(&out.join("README.md"), doc.to_markdown().as_bytes())?;
    Ok((out.join("index.html"), clips.len()))
}
