//! Episodes played outside locobench's own agents (`locobench.evaluate(..., out=DIR)` in
//! Python: an SB3 model, a CleanRL actor, any callable), kept with their provenance so that
//! `locobench report --external DIR` puts them beside ours under the same statistics.
//!
//! A directory holds `external.toml` (who and what: a label, the env with its options, the
//! protocol, the library and its version, the policy's file and SHA-256, the machine, who wrote
//! it, and optionally the training seed and steps) and `episodes.csv` (one line per held-out
//! episode, every measure the report's statistics use, floats written so they read back to the
//! same bits). Both are written atomically.
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{bail, ensure, Context, Result};
use serde::{Deserialize, Serialize};

use super::Protocol;
use crate::controller::measure::GaitEpisode;
use crate::envs::EnvConfig;
use crate::io::write_bytes_atomic;

/// The provenance file's name.
pub const META_FILE: &str = "external.toml";
/// The episodes file's name.
pub const EPISODES_FILE: &str = "episodes.csv";

const COLUMNS: [&str; 14] = [
    "episode",
    "episode_return",
    "length",
    "fell",
    "mean_speed",
    "speed_error",
    "yaw_rate",
    "sideways",
    "energy",
    "cost_of_transport",
    "weight_times_distance",
    "drift",
    "shake",
    "qp_failures",
];

/// What `external.toml` says.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExternalMeta {
    /// The row's name in the report (runs with one label are one row, their seeds pooled).
    pub label: String,
    /// The env's name.
    pub env: String,
    /// The env's options and reward weights, as `EnvConfig` resolves them.
    pub options: toml::Table,
    /// Held-out episodes.
    pub episodes: usize,
    /// The protocol seed that picked their reset seeds.
    pub protocol_seed: u64,
    /// The library that trained and ran the policy.
    pub library: String,
    /// Its version.
    pub library_version: String,
    /// The policy's file, when given.
    #[serde(default)]
    pub policy_file: String,
    /// Its SHA-256, when given.
    #[serde(default)]
    pub policy_sha256: String,
    /// The machine the episodes ran on.
    pub machine: String,
    /// Who wrote them.
    pub author: String,
    /// locobench's version.
    pub locobench_version: String,
    /// The training seed, when known.
    #[serde(default)]
    pub seed: Option<u64>,
    /// The training's environment steps, when known.
    #[serde(default)]
    pub steps: Option<u64>,
}

/// One directory's episodes and what they are.
#[derive(Debug, Clone)]
pub struct External {
    /// Where they were read from.
    pub dir: PathBuf,
    /// The provenance.
    pub meta: ExternalMeta,
    /// The env they were played in.
    pub env: EnvConfig,
    /// The held-out episodes, in the protocol's order.
    pub episodes: Vec<GaitEpisode>,
}

impl External {
    /// The protocol the episodes follow.
    pub fn protocol(&self) -> Protocol {
        Protocol { episodes: self.meta.episodes, seed: self.meta.protocol_seed }
    }

    /// The provenance as one line: library, policy, machine, author.
    pub fn provenance(&self) -> String {
        let m = &self.meta;
        let mut s = format!("evaluated outside locobench: {} {}", m.library, m.library_version);
        if !m.policy_file.is_empty() {
            let _ = write!(s, ", {}", m.policy_file);
            if m.policy_sha256.len() >= 12 {
                let _ = write!(s, " (sha256 {})", &m.policy_sha256[..12]);
            }
        }
        let _ = write!(s, ", on {} by {} (locobench {})", m.machine, m.author, m.locobench_version);
        s
    }
}

/// The machine, as the report's provenance names machines (CPU model and SIMD level).
pub fn this_machine() -> String {
    format!("{} ({})", crate::train::provenance::cpu_model(), crate::train::provenance::simd_level())
}

/// Writes `episodes` and `meta` into `dir` (created if needed).
pub fn write(dir: &Path, meta: &ExternalMeta, episodes: &[GaitEpisode]) -> Result<()> {
    ensure!(!meta.label.trim().is_empty(), "an external row needs a label");
    ensure!(episodes.len() == meta.episodes, "{} episodes, the protocol says {}", episodes.len(), meta.episodes);
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let terms: Vec<&str> = episodes.first().map_or_else(Vec::new, |e| e.reward_terms.iter().map(|(t, _)| *t).collect());
    let mut csv = COLUMNS.join(",");
    for t in &terms {
        let _ = write!(csv, ",term:{t}");
    }
    csv.push('\n');
    for (i, e) in episodes.iter().enumerate() {
        let _ = write!(
            csv,
            "{i},{:?},{},{},{:?},{:?},{:?},{:?},{:?},{:?},{:?},{:?},{:?},{:?}",
            e.episode_return,
            e.length,
            e.fell,
            e.mean_speed,
            e.speed_error,
            e.yaw_rate,
            e.sideways,
            e.energy,
            e.cost_of_transport,
            e.weight_times_distance,
            e.drift,
            e.shake,
            e.qp_failures
        );
        for (_, v) in &e.reward_terms {
            let _ = write!(csv, ",{v:?}");
        }
        csv.push('\n');
    }
    write_bytes_atomic(&dir.join(EPISODES_FILE), csv.as_bytes())?;
    write_bytes_atomic(&dir.join(META_FILE), toml::to_string(meta)?.as_bytes())?;
    Ok(())
}

/// Reads a directory `write` wrote; an error names the file and, for a bad line, the line.
pub fn read(dir: &Path) -> Result<External> {
    let meta_path = dir.join(META_FILE);
    let text = std::fs::read_to_string(&meta_path)
        .with_context(|| format!("{}: not an external evaluation (no {META_FILE})", dir.display()))?;
    let meta: ExternalMeta = toml::from_str(&text).with_context(|| format!("reading {}", meta_path.display()))?;
    let env = EnvConfig { name: meta.env.clone(), options: meta.options.clone() };
    let spec = crate::envs::make(&env).with_context(|| format!("{}: its env", meta_path.display()))?.spec().clone();
    let path = dir.join(EPISODES_FILE);
    let text = std::fs::read_to_string(&path).with_context(|| format!("reading {}", path.display()))?;
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().with_context(|| format!("{}: empty", path.display()))?.split(',').collect();
    ensure!(
        header.len() >= COLUMNS.len() && header[..COLUMNS.len()] == COLUMNS,
        "{}: the header is not {}",
        path.display(),
        COLUMNS.join(",")
    );
    let mut terms: Vec<&'static str> = Vec::new();
    for h in &header[COLUMNS.len()..] {
        let name =
            h.strip_prefix("term:").with_context(|| format!("{}: column {h} is not term:NAME", path.display()))?;
        let known = spec.reward_terms.iter().find(|t| **t == name).with_context(|| {
            format!(
                "{}: reward term {name} is not one of {}'s ({})",
                path.display(),
                meta.env,
                spec.reward_terms.join(", ")
            )
        })?;
        terms.push(known);
    }
    let mut episodes = Vec::new();
    for (n, line) in lines.enumerate() {
        let at = || format!("{}, line {}", path.display(), n + 2);
        let cells: Vec<&str> = line.split(',').collect();
        ensure!(cells.len() == header.len(), "{}: {} fields, the header has {}", at(), cells.len(), header.len());
        let num = |i: usize| -> Result<f64> {
            cells[i].parse::<f64>().with_context(|| format!("{}: {} = '{}' is not a number", at(), header[i], cells[i]))
        };
        ensure!(cells[0].parse::<usize>().ok() == Some(n), "{}: episode {} out of order", at(), cells[0]);
        let fell = match cells[3] {
            "true" => true,
            "false" => false,
            other => bail!("{}: fell = '{other}' is not true or false", at()),
        };
        episodes.push(GaitEpisode {
            episode_return: num(1)?,
            length: cells[2].parse().with_context(|| format!("{}: length '{}'", at(), cells[2]))?,
            fell,
            unstable: false,
            mean_speed: num(4)?,
            speed_error: num(5)?,
            yaw_rate: num(6)?,
            sideways: num(7)?,
            energy: num(8)?,
            cost_of_transport: num(9)?,
            weight_times_distance: num(10)?,
            drift: num(11)?,
            shake: num(12)?,
            qp_failures: num(13)?,
            diagnostics: Vec::new(),
            reward_terms: terms
                .iter()
                .enumerate()
                .map(|(k, t)| Ok((*t, num(COLUMNS.len() + k)?)))
                .collect::<Result<_>>()?,
        });
    }
    ensure!(
        episodes.len() == meta.episodes,
        "{}: {} episodes, {META_FILE} says {}",
        path.display(),
        episodes.len(),
        meta.episodes
    );
    Ok(External { dir: dir.to_path_buf(), meta, env, episodes })
}
