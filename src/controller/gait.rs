//! Gait scheduling: each leg has a phase in [0, 1) over one gait cycle; it is in stance for the
//! first `duty_factor` of its cycle and in swing for the rest.

use crate::policy::Telemetry;

/// Legs in the Minitaur order: front-left, back-left, front-right, back-right.
pub(crate) const LEGS: usize = 4;
/// Leg names in the scheduler's order.
pub(crate) const LEG_NAMES: [&str; LEGS] = ["fl", "bl", "fr", "br"];

/// Which legs swing together.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GaitKind {
    /// Diagonal pairs together (FL+BR, FR+BL).
    Trot,
    /// Front pair, then back pair.
    Bound,
    /// Left pair, then right pair.
    Pace,
    /// Ant only (`controller::ant_row`): the two legs across the direction of travel push
    /// together while the two along it slide as skids; scheduled as a trot, whose pairs they are.
    Row,
}

impl GaitKind {
    /// Phase offset of each leg (FL, BL, FR, BR) as a fraction of the cycle.
    pub(crate) fn offsets(self) -> [f64; LEGS] {
        match self {
            GaitKind::Trot | GaitKind::Row => [0.0, 0.5, 0.5, 0.0],
            GaitKind::Bound => [0.0, 0.5, 0.0, 0.5],
            GaitKind::Pace => [0.0, 0.0, 0.5, 0.5],
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct LegPhase {
    pub(crate) in_stance: bool,
    /// Progress through the current stance or swing, in [0, 1).
    pub progress: f64,
}

#[derive(Debug, Clone)]
pub(crate) struct GaitScheduler {
    pub kind: GaitKind,
    /// Seconds of stance per cycle.
    pub(crate) stance_duration: f64,
    /// Fraction of the cycle in stance, in (0, 1).
    pub(crate) duty_factor: f64,
    time: f64,
}

impl GaitScheduler {
    pub fn new(kind: GaitKind, stance_duration: f64, duty_factor: f64) -> anyhow::Result<GaitScheduler> {
        anyhow::ensure!(stance_duration > 0.0 && stance_duration.is_finite(), "stance duration must be > 0");
        anyhow::ensure!(duty_factor > 0.0 && duty_factor < 1.0, "duty factor must lie in (0, 1)");
        Ok(GaitScheduler { kind, stance_duration, duty_factor, time: 0.0 })
    }

    pub fn period(&self) -> f64 {
        self.stance_duration / self.duty_factor
    }

    pub(crate) fn swing_duration(&self) -> f64 {
        self.period() - self.stance_duration
    }

    pub(crate) fn advance(&mut self, dt: f64) {
        self.time += dt;
    }

    /// A new stance duration and duty factor, each leg kept at the same point of its cycle.
    pub(crate) fn retime(&mut self, stance_duration: f64, duty_factor: f64) {
        let phase = self.time / self.period();
        self.stance_duration = stance_duration;
        self.duty_factor = duty_factor;
        self.time = phase * self.period();
    }

    pub fn reset(&mut self) {
        self.time = 0.0;
    }

    pub fn legs(&self) -> [LegPhase; LEGS] {
        let offsets = self.kind.offsets();
        std::array::from_fn(|leg| {
            let phase = (self.time / self.period() + offsets[leg]).rem_euclid(1.0);
            if phase < self.duty_factor {
                LegPhase { in_stance: true, progress: phase / self.duty_factor }
            } else {
                LegPhase { in_stance: false, progress: (phase - self.duty_factor) / (1.0 - self.duty_factor) }
            }
        })
    }
}

/// Stance (1) or swing (0) and phase progress per leg; the foot target of each swing leg.
pub(crate) fn gait_telemetry(phases: &[(bool, f64); LEGS], target: impl Fn(usize) -> [f64; 3]) -> Telemetry {
    let mut t = Telemetry::default();
    for (leg, &(stance, progress)) in phases.iter().enumerate() {
        let name = LEG_NAMES[leg];
        t.scalars.push((format!("stance/{name}"), stance as u8 as f64));
        t.scalars.push((format!("phase/{name}"), progress));
        if !stance {
            t.points.push((format!("foot_target/{name}"), target(leg)));
        }
    }
    t
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn trot_alternates_diagonal_pairs() {
        let mut g = GaitScheduler::new(GaitKind::Trot, 0.25, 0.5).unwrap();
        assert!((g.period() - 0.5).abs() < 1e-12);
        let stance = |g: &GaitScheduler| g.legs().map(|l| l.in_stance);
        assert_eq!(stance(&g), [true, false, false, true]);
        g.advance(0.3);
        assert_eq!(stance(&g), [false, true, true, false]);
        let p = g.legs()[0].progress;
        assert!((p - 0.2).abs() < 1e-9, "{p}");
        g.advance(0.2);
        assert_eq!(stance(&g), [true, false, false, true]);
    }

    #[test]
    fn bound_pace_and_duty_factor() {
        let g = GaitScheduler::new(GaitKind::Bound, 0.2, 0.5).unwrap();
        assert_eq!(g.legs().map(|l| l.in_stance), [true, false, true, false]);
        let g = GaitScheduler::new(GaitKind::Pace, 0.2, 0.5).unwrap();
        assert_eq!(g.legs().map(|l| l.in_stance), [true, true, false, false]);
        // Duty factor 0.75: a leg spends three quarters of the cycle in stance.
        let mut g = GaitScheduler::new(GaitKind::Trot, 0.3, 0.75).unwrap();
        let mut stance_time: f64 = 0.0;
        for _ in 0..4000 {
            if g.legs()[0].in_stance {
                stance_time += 1e-4;
            }
            g.advance(1e-4);
        }
        assert!((stance_time / 0.4 - 0.75).abs() < 1e-2, "{stance_time}");
        assert!(GaitScheduler::new(GaitKind::Trot, 0.3, 1.0).is_err());
    }
}
