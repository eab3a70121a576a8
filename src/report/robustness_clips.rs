//! One side-by-side clip per axis of a committed robustness suite (`report --robustness DIR
//! --videos`): every policy row (by its first seed) and the controller at its best speed, left to
//! right, replaying one episode the suite played, at the mildest level of the axis where the
//! outcomes of those that walk nominally differ. The replay is checked against the suite's
//! recorded outcomes.
use anyhow::{Context, Result};

use super::robustness::SuiteData;
use super::videos::{film, Clip, ClipPlan};
use crate::evaluation::robustness::suite::NOMINAL;
use crate::evaluation::robustness::summary::SURVIVAL_BAR;
use crate::evaluation::robustness::{Axis, Contender, Outcome};
use crate::evaluation::Protocol;

/// The episode a clip replays.
#[derive(Debug, Clone, PartialEq)]
pub struct Pick {
    /// The axis's level.
    pub level: f64,
    /// The episode's index in the protocol's order.
    pub episode: usize,
    /// Each panel's outcome in the suite, left to right.
    pub outcomes: Vec<Outcome>,
}

/// The clip's contenders: every policy row, then the controller at its best speed.
fn panels(s: &SuiteData) -> Result<Vec<Contender>> {
    let all = s.meta.parsed_contenders()?;
    let best = s.best_controller();
    Ok(all.into_iter().filter(|c| matches!(c, Contender::Agent { .. }) || Some(c.label()) == best).collect())
}

/// The mildest level of `axis`, and the first episode there, at which one of the contenders that
/// survive at least 90% of the nominal episodes survives and another of them falls (all of
/// `labels` when fewer than two do; a row of several seeds by its first seed); without one, the
/// last level's first episode. The outcomes are those of every one of `labels`. `None` when a
/// contender has no cell on the axis.
pub fn pick(s: &SuiteData, axis: &Axis, labels: &[&str]) -> Option<Pick> {
    let strong =
        |l: &str| s.cells.iter().any(|c| c.policy == l && c.axis == NOMINAL && c.survival().estimate >= SURVIVAL_BAR);
    let mut deciders: Vec<bool> = labels.iter().map(|l| strong(l)).collect();
    if deciders.iter().filter(|d| **d).count() < 2 {
        deciders = vec![true; labels.len()];
    }
    let episodes = s.meta.episodes;
    let outcomes_at = |level: f64| -> Option<Vec<&[Outcome]>> {
        labels
            .iter()
            .map(|l| {
                let cell = s.cells.iter().find(|c| c.policy == *l && c.axis == axis.name && c.level == level)?;
                cell.outcomes.get(..episodes)
            })
            .collect()
    };
    for &level in axis.levels {
        let cells = outcomes_at(level)?;
        for k in 0..episodes {
            let here: Vec<Outcome> = cells.iter().map(|o| o[k]).collect();
            let decided = || here.iter().zip(&deciders).filter(|(_, d)| **d).map(|(o, _)| *o);
            if decided().any(|o| o == Outcome::Survived) && decided().any(|o| o == Outcome::Fell) {
                return Some(Pick { level, episode: k, outcomes: here });
            }
        }
    }
    let level = *axis.levels.last()?;
    let cells = outcomes_at(level)?;
    Some(Pick { level, episode: 0, outcomes: cells.iter().map(|o| o[0]).collect() })
}

fn word(o: Outcome) -> &'static str {
    match o {
        Outcome::Survived => "survived",
        Outcome::Fell => "fell",
        Outcome::Unstable => "blew up",
    }
}

/// Films one clip per axis into `out/videos/` (`threads` panels at a time). A clip whose replay
/// ends differently from the suite's record says so in its caption.
pub fn film_axes(
    s: &SuiteData,
    out: &std::path::Path,
    threads: usize,
    cache: &crate::evaluation::EvalCache,
) -> Result<Vec<(Axis, Clip)>> {
    let contenders = panels(s)?;
    let labels: Vec<&str> = contenders.iter().map(Contender::label).collect();
    let protocol = Protocol { episodes: s.meta.episodes, seed: s.meta.protocol_seed };
    let seeds = protocol.reset_seeds();
    let env = &s.meta.env.name;
    let mut plans = Vec::new();
    let mut picks = Vec::new();
    for axis in &s.axes {
        let Some(p) = pick(s, axis, &labels) else { continue };
        let (cfg, push) = axis.at(&s.meta.env, p.level)?;
        let seed = *seeds.get(p.episode).context("an episode beyond the protocol's")?;
        let who =
            labels.iter().zip(&p.outcomes).map(|(l, o)| format!("{l} ({})", word(*o))).collect::<Vec<_>>().join(", ");
        let caption = format!(
            "{} at {} {}: held-out episode {} of {} (reset seed {seed}); left to right {who}, as the suite recorded them",
            axis.label,
            p.level,
            axis.unit,
            p.episode + 1,
            s.meta.episodes
        );
        let stem = format!("{env}_robustness_{}", axis.name);
        plans.push(ClipPlan::of_contenders(stem, caption, &contenders, cfg, push, seed)?);
        picks.push((*axis, p));
    }
    let clips = film(&plans, &[], out, &protocol, threads, cache)?;
    Ok(picks
        .into_iter()
        .zip(clips)
        .map(|((axis, p), mut clip)| {
            let recorded: Vec<bool> = p.outcomes.iter().map(|o| *o != Outcome::Survived).collect();
            if recorded != clip.fell {
                clip.caption.push_str(&format!(
                    ". The replay ended otherwise: {}",
                    clip.fell.iter().map(|f| if *f { "fell" } else { "survived" }).collect::<Vec<_>>().join(", ")
                ));
            }
            (axis, clip)
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::evaluation::robustness::output::SuiteMeta;
    use crate::evaluation::robustness::{axes_of, Cell};

    fn cell(policy: &str, axis: &str, level: f64, outcomes: &str) -> Cell {
        let kind = if policy == "ctrl (best)" { "controller" } else { "policy" };
        crate::evaluation::robustness::suite::test_cell(policy, kind, axis, level, outcomes)
    }

    fn suite(cells: Vec<Cell>) -> SuiteData {
        let meta: SuiteMeta = toml::from_str(
            "command = \"x\"\nmachine = \"m\"\ngit_commit = \"c\"\nepisodes = 3\nprotocol_seed = 100\nthreads = 1\n\
             wall_seconds = 1.0\ncontenders = []\nnotes = []\n[env]\nname = \"minitaur\"\n[env.options]\n",
        )
        .unwrap();
        let axes = axes_of("minitaur").unwrap().iter().filter(|a| a.name == "payload").copied().collect();
        SuiteData { cells, meta, axes }
    }

    #[test]
    fn the_clip_replays_the_mildest_level_where_outcomes_differ() {
        // "weak" falls in a nominal episode (below 90%), so its outcomes do not pick the episode.
        let mut cells = vec![
            cell("ppo", NOMINAL, 0.0, "SSS"),
            cell("ctrl (best)", NOMINAL, 0.0, "SSS"),
            cell("weak", NOMINAL, 0.0, "FSS"),
        ];
        // Both survive 1 kg (where "weak" falls once); at 2 kg the controller falls in the second
        // episode, the policy in none; at 4 kg both fall in every episode. A row of two seeds
        // counts its first seed.
        for (level, policy, ctrl, weak) in [
            (1.0, "SSSSSS", "SSS", "FSS"),
            (2.0, "SSSFFF", "SFS", "FFF"),
            (4.0, "FFFFFF", "FFF", "FFF"),
            (6.0, "FFFFFF", "FFF", "FFF"),
        ] {
            cells.push(cell("ppo", "payload", level, policy));
            cells.push(cell("ctrl (best)", "payload", level, ctrl));
            cells.push(cell("weak", "payload", level, weak));
        }
        let s = suite(cells.clone());
        let axis = s.axes[0];
        let p = pick(&s, &axis, &["ppo", "weak", "ctrl (best)"]).unwrap();
        assert_eq!(p, Pick { level: 2.0, episode: 1, outcomes: vec![Outcome::Survived, Outcome::Fell, Outcome::Fell] });
        // With only one contender above the bar, every contender decides.
        let p = pick(&s, &axis, &["ppo", "weak"]).unwrap();
        assert_eq!((p.level, p.episode), (1.0, 0));
        // Where no episode tells them apart, the last level's first episode.
        let same: Vec<Cell> =
            cells.iter().map(|c| Cell { outcomes: vec![Outcome::Fell; c.outcomes.len()], ..c.clone() }).collect();
        let p = pick(&suite(same), &axis, &["ppo", "ctrl (best)"]).unwrap();
        assert_eq!((p.level, p.episode), (6.0, 0));
        // A contender without cells on the axis: no clip.
        assert!(pick(&s, &axis, &["ppo", "td3"]).is_none());
    }
}
