//! Running the suite: every contender (the controller commanded to a speed, or a trained policy)
//! plays the protocol's held-out episodes at every level of every axis, with the same reset
//! seeds, the same pushes and the same env for all. One cell is one (contender, axis, level).
use std::path::PathBuf;

use anyhow::{bail, Context, Result};

use super::axes::Axis;
use crate::controller::baseline::{baseline_controller, baseline_env_like, RAMP_TIME};
use crate::controller::command::SpeedProfile;
use crate::controller::measure::{mean_cost_of_transport, GaitEpisode};
use crate::envs::{make, EnvConfig};
use crate::evaluation::cache::Key;
use crate::evaluation::stats::{self, wilson, Interval};
use crate::evaluation::stats::{estimate, BOOTSTRAP_SEED};
use crate::evaluation::Protocol;
use crate::policy::AgentPolicy;
use crate::train::resolve_policy;

/// Who plays the suite.
#[derive(Debug, Clone, PartialEq)]
pub enum Contender {
    /// The Raibert-style controller commanded to `speed` m/s.
    Controller {
        /// Its label.
        label: String,
        /// Commanded speed (m/s).
        speed: f64,
    },
    /// A trained policy, or a row of them (one per training seed, each playing every episode:
    /// the report's rows are such groups).
    Agent {
        /// Its label.
        label: String,
        /// The policies.
        seeds: Vec<PolicySource>,
    },
}

/// Where one trained policy lives.
#[derive(Debug, Clone, PartialEq)]
pub struct PolicySource {
    /// Any policy reference (`eval --policy` takes the same).
    pub reference: PathBuf,
    /// The budget, for a committed result run.
    pub budget: Option<u64>,
}

impl Contender {
    /// Trained policies from `LABEL=REFERENCE` or `LABEL=REFERENCE@BUDGET` each; entries with the
    /// same label form one row (one policy per seed), in the order given.
    pub fn parse_agents(items: &[String]) -> Result<Vec<Contender>> {
        let mut out: Vec<Contender> = Vec::new();
        for text in items {
            let Some((label, rest)) = text.split_once('=') else {
                bail!("policy '{text}' is not LABEL=REFERENCE[@BUDGET]");
            };
            if label.is_empty() || label.contains(',') {
                bail!("policy '{text}': the label must be non-empty and without commas");
            }
            let (reference, budget) = match rest.rsplit_once('@') {
                Some((r, b)) => match b.parse::<u64>() {
                    Ok(b) => (r, Some(b)),
                    Err(_) => bail!("policy '{text}': '{b}' after @ is not a step budget"),
                },
                None => (rest, None),
            };
            let source = PolicySource { reference: PathBuf::from(reference), budget };
            match out.iter_mut().find(|c| c.label() == label) {
                Some(Contender::Agent { seeds, .. }) => seeds.push(source),
                _ => out.push(Contender::Agent { label: label.to_string(), seeds: vec![source] }),
            }
        }
        Ok(out)
    }

    /// Its label in tables and charts.
    pub fn label(&self) -> &str {
        match self {
            Contender::Controller { label, .. } | Contender::Agent { label, .. } => label,
        }
    }
    /// `controller` or `policy`.
    pub fn kind(&self) -> &'static str {
        match self {
            Contender::Controller { .. } => "controller",
            Contender::Agent { .. } => "policy",
        }
    }
    /// The controller's commanded speed (m/s); NaN for a policy.
    pub fn commanded(&self) -> f64 {
        match self {
            Contender::Controller { speed, .. } => *speed,
            Contender::Agent { .. } => f64::NAN,
        }
    }
}

/// How one episode ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Outcome {
    /// Walked to the time limit.
    Survived,
    /// Fell.
    Fell,
    /// The physics blew up: neither a fall nor a survival.
    Unstable,
}

impl Outcome {
    fn of(e: &GaitEpisode) -> Outcome {
        if e.unstable {
            Outcome::Unstable
        } else if e.fell {
            Outcome::Fell
        } else {
            Outcome::Survived
        }
    }
    /// One letter per episode in the CSV: S, F, U.
    pub fn letter(self) -> char {
        match self {
            Outcome::Survived => 'S',
            Outcome::Fell => 'F',
            Outcome::Unstable => 'U',
        }
    }
    /// The outcome a letter stands for.
    pub fn from_letter(c: char) -> Result<Outcome> {
        Ok(match c {
            'S' => Outcome::Survived,
            'F' => Outcome::Fell,
            'U' => Outcome::Unstable,
            other => bail!("'{other}' is not an episode outcome (S, F or U)"),
        })
    }
}

/// One (contender, axis, level) over the protocol's episodes.
#[derive(Debug, Clone, PartialEq)]
pub struct Cell {
    /// The env.
    pub env: String,
    /// The contender's label.
    pub policy: String,
    /// `controller` or `policy`.
    pub kind: String,
    /// The controller's commanded speed; NaN for a policy.
    pub commanded: f64,
    /// The axis (`nominal` for the unperturbed cell every axis shares).
    pub axis: String,
    /// The axis's level.
    pub level: f64,
    /// Each episode's outcome, in the protocol's order.
    pub outcomes: Vec<Outcome>,
    /// Mean return with its 95% bootstrap interval over episodes.
    pub ret: Interval,
    /// Mean forward speed (m/s).
    pub speed: f64,
    /// Cost of transport of the episodes together.
    pub cost_of_transport: f64,
    /// The commit of the binary that played the cell (`-dirty` when its source had uncommitted
    /// edits). `<=HASH` for a cell carried over from a suite written before the CSV had this
    /// column: it was played at that suite's commit or an earlier one.
    pub commit: String,
}

impl Cell {
    /// Episodes that walked to the end.
    pub fn survived(&self) -> usize {
        self.outcomes.iter().filter(|o| **o == Outcome::Survived).count()
    }
    /// Episodes that fell.
    pub fn fell(&self) -> usize {
        self.outcomes.iter().filter(|o| **o == Outcome::Fell).count()
    }
    /// Episodes where the physics blew up.
    pub fn unstable(&self) -> usize {
        self.outcomes.iter().filter(|o| **o == Outcome::Unstable).count()
    }
    /// Survival over the episodes that either survived or fell, with its 95% Wilson interval;
    /// blow-ups are counted apart.
    pub fn survival(&self) -> Interval {
        wilson(self.survived(), self.survived() + self.fell())
    }

    fn of(env: &str, contender: &Contender, axis: &str, level: f64, episodes: &[GaitEpisode]) -> Cell {
        let returns: Vec<f64> = episodes.iter().map(|e| e.episode_return).collect();
        Cell {
            env: env.to_string(),
            policy: contender.label().to_string(),
            kind: contender.kind().to_string(),
            commanded: contender.commanded(),
            axis: axis.to_string(),
            level,
            outcomes: episodes.iter().map(Outcome::of).collect(),
            ret: estimate(std::slice::from_ref(&returns), stats::mean, BOOTSTRAP_SEED).interval,
            speed: stats::mean(&episodes.iter().map(|e| e.mean_speed).collect::<Vec<_>>()),
            cost_of_transport: mean_cost_of_transport(episodes),
            commit: crate::train::git_commit().unwrap_or_else(|| UNKNOWN_COMMIT.into()),
        }
    }
}

/// A cell with only its outcomes (one letter per episode: S, F, U), for tests of what is
/// computed from them.
#[cfg(test)]
pub(crate) fn test_cell(policy: &str, kind: &str, axis: &str, level: f64, outcomes: &str) -> Cell {
    Cell {
        env: "minitaur".into(),
        policy: policy.into(),
        kind: kind.into(),
        commanded: f64::NAN,
        axis: axis.into(),
        level,
        outcomes: outcomes.chars().map(|c| Outcome::from_letter(c).unwrap()).collect(),
        ret: Interval::point(0.0),
        speed: 0.0,
        cost_of_transport: 0.0,
        commit: "abc".into(),
    }
}

/// The axis name of the unperturbed cell.
pub const NOMINAL: &str = "nominal";

/// What to run.
#[derive(Debug, Clone)]
pub struct Suite {
    /// The env every contender runs in (its defaults, unless options are given): the training
    /// options of a policy's own run are not used, so every policy meets the same world. Only
    /// its control rate comes with a policy ([`at_control_rate_of`]).
    pub env: EnvConfig,
    /// The axes.
    pub axes: Vec<Axis>,
    /// The held-out episodes.
    pub protocol: Protocol,
    /// Cells evaluated at once.
    pub threads: usize,
    /// Where each contender's episodes on each cell are kept between runs (`evaluation::cache`;
    /// off unless set).
    pub cache: crate::evaluation::EvalCache,
}

impl Suite {
    /// Every (axis, level) cell of the suite: the shared nominal cell, then each axis's levels.
    pub fn cells(&self) -> Vec<(Option<Axis>, f64)> {
        let mut out = vec![(None, 0.0)];
        for axis in &self.axes {
            out.extend(axis.levels.iter().map(|&l| (Some(*axis), l)));
        }
        out
    }

    /// Plays the suite for each contender; cells in the order contenders x cells. A cell in
    /// `known` (same contender, axis and level) is taken as played.
    pub fn run(&self, contenders: &[Contender], known: &[Cell]) -> Result<Vec<Cell>> {
        let jobs: Vec<(&Contender, Option<Axis>, f64)> =
            contenders.iter().flat_map(|c| self.cells().into_iter().map(move |(a, l)| (c, a, l))).collect();
        super::super::parallel::map_in_order(&jobs, self.threads, |&(c, axis, level)| {
            let name = axis.map_or(NOMINAL, |a| a.name);
            match known.iter().find(|k| k.policy == c.label() && k.axis == name && k.level == level) {
                Some(k) => Ok(k.clone()),
                None => self.cell(c, axis, level),
            }
        })
    }

    /// One contender's episodes on one cell.
    pub fn cell(&self, contender: &Contender, axis: Option<Axis>, level: f64) -> Result<Cell> {
        let (cfg, push) = match &axis {
            Some(a) => a.at(&self.env, level)?,
            None => (self.env.clone(), None),
        };
        let name = axis.map_or(NOMINAL, |a| a.name);
        let episodes = match contender {
            Contender::Controller { speed, .. } => {
                let cfg = baseline_env_like(&cfg)?;
                let profile = SpeedProfile::ramp(*speed, RAMP_TIME);
                let key = Key::episodes(&cfg, &self.protocol, &format!("controller {speed:?}"), Some(&profile), push)?;
                self.cache.episodes(&key, || {
                    let mut env = make(&cfg)?;
                    let mut controller = baseline_controller(&cfg.name, *speed, None)?;
                    self.protocol.run(env.as_mut(), controller.as_mut(), Some(&profile), push)
                })?
            }
            Contender::Agent { label, seeds } => {
                let mut all = Vec::new();
                for source in seeds {
                    let policy_ref = resolve_policy(&source.reference, source.budget)?;
                    let (run, agent) = policy_ref
                        .load()
                        .with_context(|| format!("loading {label} from {}", source.reference.display()))?;
                    if run.env.name != cfg.name {
                        bail!("{label} was trained on {}, not on the suite's env {}", run.env.name, cfg.name);
                    }
                    let cfg = at_control_rate_of(&cfg, &run.env)
                        .with_context(|| format!("{label} from {}", source.reference.display()))?;
                    let key =
                        Key::episodes(&cfg, &self.protocol, &format!("agent {}", policy_ref.digest()?), None, push)?;
                    all.extend(self.cache.episodes(&key, || {
                        let mut env = make(&cfg)?;
                        let mut policy = AgentPolicy { agent: agent.as_ref(), label: label.clone() };
                        self.protocol.run(env.as_mut(), &mut policy, None, push)
                    })?);
                }
                all
            }
        };
        Ok(Cell::of(&self.env.name, contender, name, level, &episodes))
    }
}

/// The suite's world `cfg` at the control rate the policy's run `run` was trained at: the run's
/// `action_repeat`, with `max_episode_steps` scaled so that an episode lasts as long as the
/// suite's. A policy trained at 50 Hz acts every 20 ms here too; the physics, the perturbations
/// and the pushes (timed in seconds) are the suite's. An env without an action repeat, or a run
/// at the suite's rate, gets `cfg` as it is.
pub fn at_control_rate_of(cfg: &EnvConfig, run: &EnvConfig) -> Result<EnvConfig> {
    let (suite, own) = (cfg.resolved_options()?, run.resolved_options()?);
    let int = |t: &toml::Table, key: &str| t.get(key).and_then(toml::Value::as_integer);
    let (Some(suite_repeat), Some(own_repeat)) = (int(&suite, "action_repeat"), int(&own, "action_repeat")) else {
        return Ok(cfg.clone());
    };
    if suite_repeat == own_repeat {
        return Ok(cfg.clone());
    }
    let steps = int(&suite, "max_episode_steps").context("an env with action_repeat has max_episode_steps")?;
    let ticks = steps * suite_repeat;
    anyhow::ensure!(
        ticks % own_repeat == 0,
        "the policy acts every {own_repeat} physics steps (action_repeat), which does not divide the suite's \
         episode of {steps} x {suite_repeat} physics steps"
    );
    let mut out = cfg.clone();
    out.options.insert("action_repeat".into(), toml::Value::Integer(own_repeat));
    out.options.insert("max_episode_steps".into(), toml::Value::Integer(ticks / own_repeat));
    Ok(out)
}

/// The CSV's header.
pub const CSV_HEADER: &str = "env,policy,kind,commanded,axis,level,episodes,survived,fell,unstable,survival,\
survival_low,survival_high,return_mean,return_low,return_high,speed,cost_of_transport,outcomes,commit";

/// A cell's commit where the binary was built outside a git checkout.
pub const UNKNOWN_COMMIT: &str = "unknown";

/// The cells as CSV text (one row each).
pub fn to_csv(cells: &[Cell]) -> String {
    let mut out = String::from(CSV_HEADER);
    out.push('\n');
    for c in cells {
        let s = c.survival();
        let outcomes: String = c.outcomes.iter().map(|o| o.letter()).collect();
        out.push_str(&format!(
            "{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}\n",
            c.env,
            c.policy,
            c.kind,
            c.commanded,
            c.axis,
            c.level,
            c.outcomes.len(),
            c.survived(),
            c.fell(),
            c.unstable(),
            s.estimate,
            s.low,
            s.high,
            c.ret.estimate,
            c.ret.low,
            c.ret.high,
            c.speed,
            c.cost_of_transport,
            outcomes,
            c.commit
        ));
    }
    out
}

/// Reads cells back from `to_csv`'s text; `source` names the file in errors. A suite written
/// before the commit column gets an empty commit, which [`super::output::read_dir`] fills in.
pub fn from_csv(text: &str, source: &str) -> Result<Vec<Cell>> {
    let mut lines = text.lines();
    // A suite written before cells carried their commit has the header without its last column.
    let header = lines.next().map(str::trim);
    let fields = if header == Some(CSV_HEADER) {
        20
    } else if header.is_some() && header == CSV_HEADER.strip_suffix(",commit") {
        19
    } else {
        bail!("{source}: not a robustness CSV (its header differs from `{CSV_HEADER}`)");
    };
    lines
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty())
        .map(|(i, line)| {
            let at = || format!("{source} line {}", i + 2);
            let f: Vec<&str> = line.split(',').collect();
            if f.len() != fields {
                bail!("{}: {} fields, expected {fields}", at(), f.len());
            }
            let num = |k: usize| f[k].parse::<f64>().with_context(|| format!("{}: '{}' is not a number", at(), f[k]));
            let outcomes = f[18].chars().map(Outcome::from_letter).collect::<Result<Vec<_>>>().with_context(at)?;
            Ok(Cell {
                env: f[0].into(),
                policy: f[1].into(),
                kind: f[2].into(),
                commanded: num(3)?,
                axis: f[4].into(),
                level: num(5)?,
                outcomes,
                ret: Interval { estimate: num(13)?, low: num(14)?, high: num(15)? },
                speed: num(16)?,
                cost_of_transport: num(17)?,
                commit: f.get(19).map_or(String::new(), |c| c.to_string()),
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cells_round_trip_through_csv_and_blow_ups_are_not_falls() {
        let eps = vec![
            GaitEpisode { episode_return: 1.0, ..Default::default() },
            GaitEpisode { episode_return: 0.5, fell: true, ..Default::default() },
            GaitEpisode { episode_return: 0.2, fell: true, unstable: true, ..Default::default() },
        ];
        let c = Contender::Controller { label: "controller 1.5".into(), speed: 1.5 };
        let cell = Cell::of("minitaur", &c, "payload", 2.0, &eps);
        assert_eq!((cell.survived(), cell.fell(), cell.unstable()), (1, 1, 1));
        assert_eq!(cell.survival(), wilson(1, 2));
        let text = to_csv(std::slice::from_ref(&cell));
        let commit = crate::train::git_commit().unwrap_or_else(|| UNKNOWN_COMMIT.into());
        assert!(text.lines().nth(1).unwrap().ends_with(&format!(",SFU,{commit}")));
        let back = from_csv(&text, "x.csv").unwrap();
        assert_eq!(back[0].outcomes, cell.outcomes);
        assert_eq!(back[0].ret, cell.ret);
        assert_eq!(back[0].commit, commit);
        // The header and rows without the commit column still read, with an empty commit.
        let legacy = text.replace(",outcomes,commit", ",outcomes").replace(&format!(",SFU,{commit}"), ",SFU");
        assert_eq!(from_csv(&legacy, "old.csv").unwrap()[0].commit, "");
        let short = text.replace(&format!(",SFU,{commit}"), ",SFU");
        assert!(from_csv(&short, "w.csv").unwrap_err().to_string().contains("19 fields, expected 20"));
        assert!(from_csv("a,b\n", "y.csv").unwrap_err().to_string().contains("y.csv"));
        let bad = text.replace(",SFU,", ",SXU,");
        assert!(format!("{:#}", from_csv(&bad, "z.csv").unwrap_err()).contains("z.csv line 2"));
    }

    #[test]
    fn policies_parse_with_and_without_a_budget_and_group_by_label() {
        let items: Vec<String> =
            ["ppo=runs/a@1000000", "x=models/p", "ppo=runs/b@1000000"].iter().map(|s| s.to_string()).collect();
        let c = Contender::parse_agents(&items).unwrap();
        assert_eq!(c.len(), 2);
        let a = |r: &str, b| PolicySource { reference: PathBuf::from(r), budget: b };
        assert_eq!(
            c[0],
            Contender::Agent {
                label: "ppo".into(),
                seeds: vec![a("runs/a", Some(1_000_000)), a("runs/b", Some(1_000_000))]
            }
        );
        assert_eq!(c[1], Contender::Agent { label: "x".into(), seeds: vec![a("models/p", None)] });
        for bad in ["models/p", "=models/p", "a,b=models/p", "x=runs/a@ten"] {
            assert!(Contender::parse_agents(&[bad.to_string()]).is_err(), "{bad}");
        }
    }

    #[test]
    fn a_policy_plays_at_its_own_control_rate_for_the_suites_episode_length() {
        let suite = EnvConfig::new("minitaur").with_overrides(&[("friction_scale".into(), "0.5".into())]).unwrap();
        let run =
            |o: &str| EnvConfig::new("minitaur").with_overrides(&crate::envs::parse_overrides(o).unwrap()).unwrap();
        // Trained at the suite's rate (whatever else it trained with): the suite's env as it is.
        assert_eq!(at_control_rate_of(&suite, &run("random_push_max=1.0")).unwrap(), suite);
        // Trained at 50 Hz for 500 steps: 50 Hz here, for the suite's 10 s, in the suite's world.
        let fifty = at_control_rate_of(&suite, &run("action_repeat=10,max_episode_steps=500")).unwrap();
        let o = fifty.resolved_options().unwrap();
        assert_eq!((o["action_repeat"].as_integer(), o["max_episode_steps"].as_integer()), (Some(10), Some(500)));
        assert_eq!(o["friction_scale"].as_float(), Some(0.5));
        // A 20 s suite gives a 50 Hz policy 1000 steps, not the 500 it trained for.
        let mut long = suite.clone();
        long.options.insert("max_episode_steps".into(), toml::Value::Integer(2000));
        let o = at_control_rate_of(&long, &run("action_repeat=10,max_episode_steps=500")).unwrap();
        assert_eq!(o.resolved_options().unwrap()["max_episode_steps"].as_integer(), Some(1000));
        // A rate that does not divide the suite's episode is refused, naming it.
        let e = at_control_rate_of(&long, &run("action_repeat=3")).unwrap_err().to_string();
        assert!(e.contains("action_repeat") && e.contains("3"), "{e}");
        // An env without an action repeat.
        let ant = EnvConfig::new("ant");
        assert_eq!(at_control_rate_of(&ant, &ant).unwrap(), ant);
    }

    #[test]
    fn a_policy_from_another_env_is_refused() {
        let suite = Suite {
            env: EnvConfig::new("ant"),
            axes: vec![],
            protocol: Protocol { episodes: 1, seed: 0 },
            threads: 1,
            cache: Default::default(),
        };
        let policy = Contender::Agent {
            label: "ppo".into(),
            seeds: vec![PolicySource {
                reference: PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/models/policies/minitaur-ppo")),
                budget: None,
            }],
        };
        let e = suite.cell(&policy, None, 0.0).unwrap_err().to_string();
        assert!(e.contains("minitaur") && e.contains("ant"), "{e}");
    }
}
