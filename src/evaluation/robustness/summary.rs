//! What the suite's cells say per axis: the largest level each contender survives at 90%, and
//! how often a policy survives an episode the controller fell in.
use super::axes::Axis;
use super::suite::{Cell, Outcome, NOMINAL};
use crate::evaluation::stats::{wilson, Interval};

/// The survival rate a level must reach to count as survived.
pub const SURVIVAL_BAR: f64 = 0.9;

/// One contender's cells along one axis, nominal first, in order of severity.
pub fn along<'a>(cells: &'a [Cell], policy: &str, axis: &Axis) -> Vec<&'a Cell> {
    let mut out: Vec<&Cell> = cells.iter().filter(|c| c.policy == policy && c.axis == NOMINAL).take(1).collect();
    for level in axis.levels {
        out.extend(cells.iter().find(|c| c.policy == policy && c.axis == axis.name && c.level == *level));
    }
    out
}

/// The most severe level reached with survival >= 90% at it and at every milder level, with the
/// survival interval there. Levels are the axis's own (nominal's is the axis's nominal). None
/// when even the nominal cell is below the bar.
#[derive(Debug, Clone, PartialEq)]
pub struct Threshold {
    /// The level (None: not even nominal).
    pub level: Option<f64>,
    /// Survival at that level.
    pub survival: Option<Interval>,
    /// Whether the last level of the axis was survived too (the axis did not find its limit).
    pub beyond_last: bool,
    /// The first level below the bar, with its survival: where the contender drops below 90%.
    pub first_below: Option<(f64, Interval)>,
}

/// The share of its nominal speed a contender must keep at a level to count as walking there.
pub const WALK_SHARE: f64 = 0.5;

/// What a level must show to count as reached along an axis.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Bar {
    /// Survival of at least [`SURVIVAL_BAR`].
    Survival,
    /// That, and a mean forward speed of at least [`WALK_SHARE`] of the nominal speed.
    SurvivalAndSpeed,
    /// The speed alone, whatever the survival.
    Speed,
}

/// The 90% threshold of `policy` along `axis`.
pub fn threshold(cells: &[Cell], policy: &str, axis: &Axis) -> Threshold {
    threshold_by(cells, policy, axis, Bar::Survival)
}

/// As [`threshold`], where a level counts only if the contender also walks there: its mean
/// forward speed is at least [`WALK_SHARE`] of its nominal speed. Survival alone rewards a policy
/// that stands still on ice; this does not.
pub fn walking_threshold(cells: &[Cell], policy: &str, axis: &Axis) -> Threshold {
    threshold_by(cells, policy, axis, Bar::SurvivalAndSpeed)
}

/// The most severe level up to which `policy` keeps at least [`WALK_SHARE`] of its nominal mean
/// speed, whatever its survival: what is left to compare for a contender that falls too often
/// even nominally to have a 90% level (Gymnasium's Ant, whose fall rule is its torso height,
/// seldom counts a stalled robot as fallen, so there speed is the telling measure).
pub fn speed_threshold(cells: &[Cell], policy: &str, axis: &Axis) -> Threshold {
    threshold_by(cells, policy, axis, Bar::Speed)
}

/// Where surviving and walking part: "walking (at least 50% of its nominal speed) up to X", the
/// level up to which `policy` also keeps half its nominal speed, written by `level`. None where
/// that is its 90% survival level. Where even nominal is below the survival bar: "keeps at least
/// 50% of its nominal speed up to X", from [`speed_threshold`].
pub fn walking_note(cells: &[Cell], policy: &str, axis: &Axis, level: impl Fn(f64) -> String) -> Option<String> {
    let up_to = |reached: Option<f64>| match reached {
        Some(l) if l == axis.nominal => "nominal only".to_string(),
        Some(l) => level(l),
        None => "not even nominal".to_string(),
    };
    let share = WALK_SHARE * 100.0;
    let survives = threshold(cells, policy, axis).level;
    if survives.is_none() {
        let keeps = speed_threshold(cells, policy, axis);
        let every = if keeps.beyond_last { ", every level" } else { "" };
        return Some(format!("keeps at least {share:.0}% of its nominal speed up to {}{every}", up_to(keeps.level)));
    }
    let walks = walking_threshold(cells, policy, axis).level;
    (walks != survives).then(|| format!("walking (at least {share:.0}% of its nominal speed) up to {}", up_to(walks)))
}

fn threshold_by(cells: &[Cell], policy: &str, axis: &Axis, bar: Bar) -> Threshold {
    let line = along(cells, policy, axis);
    let levels: Vec<f64> = axis.all_levels();
    let nominal_speed = line.first().map_or(f64::NAN, |c| c.speed);
    let mut reached = None;
    let mut first_below = None;
    for (cell, level) in line.iter().zip(&levels) {
        let s = cell.survival();
        let survives = bar == Bar::Speed || s.estimate >= SURVIVAL_BAR;
        let walks = bar == Bar::Survival || cell.speed >= WALK_SHARE * nominal_speed;
        if survives && walks {
            reached = Some((*level, s));
        } else {
            first_below = Some((*level, s));
            break;
        }
    }
    let beyond_last = line.len() == levels.len() && reached.is_some_and(|(l, _)| l == *levels.last().unwrap());
    Threshold { level: reached.map(|r| r.0), survival: reached.map(|r| r.1), beyond_last, first_below }
}

/// P(policy survives | the controller fell), over the paired episodes (same level, same reset
/// seed) of every level of `axis` where the controller fell; the count of such episodes and the
/// Wilson interval. A row of several seeds plays each episode once per seed: every seed's
/// episode pairs with the controller's. None when the controller never fell on the axis.
pub fn survives_where_controller_falls(
    cells: &[Cell],
    policy: &str,
    controller: &str,
    axis: &Axis,
) -> Option<(usize, Interval)> {
    let (p, c) = (along(cells, policy, axis), along(cells, controller, axis));
    let (mut n, mut k) = (0, 0);
    for (pc, cc) in p.iter().zip(&c) {
        let n_ctrl = cc.outcomes.len().max(1);
        for (i, po) in pc.outcomes.iter().enumerate() {
            let co = cc.outcomes.get(i % n_ctrl).copied().unwrap_or(Outcome::Unstable);
            if co == Outcome::Fell && *po != Outcome::Unstable {
                n += 1;
                k += usize::from(*po == Outcome::Survived);
            }
        }
    }
    (n > 0).then(|| (n, wilson(k, n)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::evaluation::robustness::axes::MINITAUR_AXES;

    fn cell(policy: &str, axis: &str, level: f64, outcomes: &str) -> Cell {
        crate::evaluation::robustness::suite::test_cell(policy, "policy", axis, level, outcomes)
    }

    #[test]
    fn thresholds_stop_at_the_first_level_below_the_bar() {
        let payload = MINITAUR_AXES.iter().find(|a| a.name == "payload").unwrap();
        let ten = |s: usize| "S".repeat(s) + &"F".repeat(10 - s);
        let cells = vec![
            cell("a", NOMINAL, 0.0, &ten(10)),
            cell("a", "payload", 1.0, &ten(9)),
            cell("a", "payload", 2.0, &ten(5)),
            cell("a", "payload", 4.0, &ten(10)),
            cell("a", "payload", 6.0, &ten(0)),
            cell("c", NOMINAL, 0.0, &ten(10)),
            cell("c", "payload", 1.0, &ten(4)),
            cell("c", "payload", 2.0, &ten(0)),
            cell("c", "payload", 4.0, &ten(0)),
            cell("c", "payload", 6.0, &ten(0)),
        ];
        let t = threshold(&cells, "a", payload);
        assert_eq!(t.level, Some(1.0));
        assert_eq!(t.survival, Some(wilson(9, 10)));
        assert!(!t.beyond_last);
        assert_eq!(t.first_below, Some((2.0, wilson(5, 10))), "drops below the bar at 2 kg");
        assert_eq!(threshold(&cells, "c", payload).level, Some(0.0));
        // The controller fell in its last 6 episodes at 1 kg ("a" survived 5 of those) and in
        // all 10 at 2, 4 and 6 kg ("a" survived 5, 10 and 0).
        let (n, p) = survives_where_controller_falls(&cells, "a", "c", payload).unwrap();
        assert_eq!(n, 36);
        assert_eq!(p, wilson(5 + 5 + 10, 36));
        assert!(survives_where_controller_falls(&cells, "c", "a", payload).is_some());
    }

    #[test]
    fn walking_levels_also_keep_half_the_nominal_speed() {
        let friction = MINITAUR_AXES.iter().find(|a| a.name == "friction_low").unwrap();
        let at = |level: f64, speed: f64| {
            let axis = if level == 1.0 { NOMINAL } else { "friction_low" };
            let mut c = cell("a", axis, level, &"S".repeat(10));
            c.speed = speed;
            c
        };
        // Survives every level, but at 0.1 x it crawls at 0.7 of half its nominal 1.2 m/s.
        let cells = vec![at(1.0, 1.2), at(0.3, 1.0), at(0.1, 0.6), at(0.03, 0.42), at(0.01, 0.1)];
        assert_eq!(threshold(&cells, "a", friction).level, Some(0.01));
        let w = walking_threshold(&cells, "a", friction);
        assert_eq!(w.level, Some(0.1), "0.6 m/s is exactly half of 1.2");
        assert_eq!(w.first_below.map(|b| b.0), Some(0.03));
        let note = walking_note(&cells, "a", friction, |l| format!("{l} x")).unwrap();
        assert_eq!(note, "walking (at least 50% of its nominal speed) up to 0.1 x");
        // Where walking and surviving end at the same level there is nothing to add.
        let steady = vec![at(1.0, 1.2), at(0.3, 1.0), at(0.1, 0.9), at(0.03, 0.8), at(0.01, 0.7)];
        assert_eq!(walking_note(&steady, "a", friction, |l| format!("{l} x")), None);
        // Surviving ice at a crawl from the first level on: it walks only at nominal.
        let crawl = vec![at(1.0, 1.2), at(0.3, 0.5), at(0.1, 0.5), at(0.03, 0.5), at(0.01, 0.5)];
        let note = walking_note(&crawl, "a", friction, |l| format!("{l} x")).unwrap();
        assert!(note.ends_with("up to nominal only"), "{note}");
    }

    #[test]
    fn below_the_survival_bar_the_note_gives_the_speed_kept() {
        let friction = MINITAUR_AXES.iter().find(|a| a.name == "friction_low").unwrap();
        let at = |level: f64, speed: f64| {
            let axis = if level == 1.0 { NOMINAL } else { "friction_low" };
            // 8 of 10 survive: below the 90% bar at every level, nominal included.
            let mut c = cell("a", axis, level, "SSSSSSSSFF");
            c.speed = speed;
            c
        };
        let cells = vec![at(1.0, 3.0), at(0.3, 2.9), at(0.1, 2.0), at(0.03, 1.5), at(0.01, 1.4)];
        assert_eq!(threshold(&cells, "a", friction).level, None);
        assert_eq!(walking_threshold(&cells, "a", friction).level, None);
        let kept = speed_threshold(&cells, "a", friction);
        assert_eq!(kept.level, Some(0.03), "1.5 m/s is exactly half of 3");
        assert_eq!(kept.first_below.map(|b| b.0), Some(0.01));
        let note = walking_note(&cells, "a", friction, |l| format!("{l} x")).unwrap();
        assert_eq!(note, "keeps at least 50% of its nominal speed up to 0.03 x");
        let mut fast = vec![at(1.0, 3.0)];
        fast.extend(friction.levels.iter().map(|l| at(*l, 1.5)));
        let last = friction.levels.last().unwrap();
        let note = walking_note(&fast, "a", friction, |l| format!("{l} x")).unwrap();
        assert_eq!(note, format!("keeps at least 50% of its nominal speed up to {last} x, every level"));
        let stalled = vec![at(1.0, 3.0), at(0.3, 1.0)];
        let note = walking_note(&stalled, "a", friction, |l| format!("{l} x")).unwrap();
        assert!(note.ends_with("up to nominal only"), "{note}");
    }
}
