//! Where a command task's command comes from: random draws redrawn at random moments, a fixed
//! schedule, or a command a caller holds (a joystick).
use rand::Rng;
use rand_chacha::ChaCha8Rng;

use super::CommandSettings;

/// A fixed command stream: (time s, forward speed m/s, yaw rate rad/s) knots, each held until
/// the next one.
#[derive(Debug, Clone, PartialEq)]
pub struct Schedule {
    knots: Vec<(f64, f64, f64)>,
}

impl Schedule {
    /// `time:speed:yaw_rate` knots separated by commas, semicolons or spaces, the first at time 0
    /// and times increasing; an empty text is no schedule.
    pub fn parse(text: &str) -> Result<Option<Schedule>, String> {
        let mut knots: Vec<(f64, f64, f64)> = Vec::new();
        for item in text.split([',', ';', ' ']).map(str::trim).filter(|s| !s.is_empty()) {
            let parts: Vec<&str> = item.split(':').map(str::trim).collect();
            let [t, v, w] = parts[..] else {
                return Err(format!("'{item}' is not time:speed:yaw_rate"));
            };
            let number = |s: &str, what: &str| -> Result<f64, String> {
                let x: f64 = s.parse().map_err(|_| format!("bad {what} '{s}' in '{item}'"))?;
                if x.is_finite() {
                    Ok(x)
                } else {
                    Err(format!("{what} in '{item}' must be finite"))
                }
            };
            let (t, v, w) = (number(t, "time")?, number(v, "speed")?, number(w, "yaw rate")?);
            match knots.last() {
                None if t != 0.0 => return Err(format!("the first knot must be at time 0, got {t}")),
                Some(&(last, _, _)) if t <= last => {
                    return Err(format!("times must increase: {t} comes after {last}"));
                }
                _ => {}
            }
            knots.push((t, v, w));
        }
        Ok((!knots.is_empty()).then_some(Schedule { knots }))
    }

    /// The command at time `t` (s).
    pub fn at(&self, t: f64) -> [f64; 2] {
        let k = self.knots.iter().rev().find(|k| k.0 <= t + 1e-9).unwrap_or(&self.knots[0]);
        [k.1, k.2]
    }

    /// The commands the schedule holds, in order.
    pub fn commands(&self) -> Vec<[f64; 2]> {
        self.knots.iter().map(|k| [k.1, k.2]).collect()
    }

    /// The knots' times.
    pub fn times(&self) -> Vec<f64> {
        self.knots.iter().map(|k| k.0).collect()
    }
}

/// The command over an episode.
#[derive(Debug, Clone)]
pub struct CommandProcess {
    speed_range: [f64; 2],
    yaw_rate_range: [f64; 2],
    standing_probability: f64,
    resample_time_range: [f64; 2],
    schedule: Option<Schedule>,
    time: f64,
    next_draw: f64,
    current: [f64; 2],
    held: bool,
}

impl CommandProcess {
    /// The process `settings` describe, following `schedule` when there is one.
    pub fn new(settings: &CommandSettings, schedule: Option<Schedule>) -> CommandProcess {
        CommandProcess {
            speed_range: settings.speed_range,
            yaw_rate_range: settings.yaw_rate_range,
            standing_probability: settings.standing_probability,
            resample_time_range: settings.resample_time_range,
            schedule,
            time: 0.0,
            next_draw: f64::INFINITY,
            current: [0.0, 0.0],
            held: false,
        }
    }

    /// The command in force.
    pub fn current(&self) -> [f64; 2] {
        self.current
    }

    /// Starts an episode: the schedule's first command, or a draw from `rng`.
    pub fn reset(&mut self, rng: &mut ChaCha8Rng) {
        self.time = 0.0;
        self.held = false;
        match &self.schedule {
            Some(s) => self.current = s.at(0.0),
            None => {
                self.current = self.draw(rng);
                self.next_draw = self.interval(rng);
            }
        }
    }

    /// Moves `dt` seconds on: the schedule's command then, or a redraw when one is due.
    pub fn advance(&mut self, dt: f64, rng: &mut ChaCha8Rng) {
        self.time += dt;
        if self.held {
            return;
        }
        match &self.schedule {
            Some(s) => self.current = s.at(self.time),
            None => {
                if self.time >= self.next_draw - 1e-9 {
                    self.current = self.draw(rng);
                    self.next_draw += self.interval(rng);
                }
            }
        }
    }

    /// Holds `command` until the next reset.
    pub fn hold(&mut self, command: [f64; 2]) {
        self.current = command;
        self.held = true;
    }

    /// Three draws, always: standing or not, a speed and a yaw rate.
    fn draw(&self, rng: &mut ChaCha8Rng) -> [f64; 2] {
        let standing = rng.random::<f64>() < self.standing_probability;
        let speed = rng.random_range(self.speed_range[0]..=self.speed_range[1]);
        let yaw_rate = rng.random_range(self.yaw_rate_range[0]..=self.yaw_rate_range[1]);
        if standing {
            [0.0, 0.0]
        } else {
            [speed, yaw_rate]
        }
    }

    fn interval(&self, rng: &mut ChaCha8Rng) -> f64 {
        rng.random_range(self.resample_time_range[0]..=self.resample_time_range[1])
    }
}

#[cfg(test)]
mod tests {
    use rand::SeedableRng;

    use super::*;

    #[test]
    fn a_schedule_holds_each_knot_until_the_next() {
        let s = Schedule::parse("0:0.5:0, 3:1.0:0, 6:1.0:0.3").unwrap().unwrap();
        assert_eq!(Schedule::parse("0:0.5:0 3:1.0:0;6:1.0:0.3").unwrap().unwrap(), s);
        assert_eq!(s.at(0.0), [0.5, 0.0]);
        assert_eq!(s.at(2.99), [0.5, 0.0]);
        assert_eq!(s.at(3.0), [1.0, 0.0]);
        assert_eq!(s.at(100.0), [1.0, 0.3]);
        assert_eq!(Schedule::parse("").unwrap(), None);
    }

    #[test]
    fn bad_schedules_are_errors_that_say_why() {
        assert!(Schedule::parse("0:1:0,2:1:0,1:0:0").unwrap_err().contains("times must increase"));
        assert!(Schedule::parse("1:1:0").unwrap_err().contains("first knot must be at time 0"));
        assert!(Schedule::parse("0:1").unwrap_err().contains("time:speed:yaw_rate"));
        assert!(Schedule::parse("0:fast:0").unwrap_err().contains("bad speed"));
    }

    #[test]
    fn random_commands_are_redrawn_within_the_ranges_at_the_drawn_moments() {
        let settings = CommandSettings {
            speed_range: [0.5, 1.0],
            yaw_rate_range: [-0.2, 0.2],
            standing_probability: 0.0,
            resample_time_range: [1.0, 2.0],
            ..CommandSettings::default()
        };
        let mut p = CommandProcess::new(&settings, None);
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        p.reset(&mut rng);
        let mut changes = 0;
        let mut last = p.current();
        for _ in 0..1000 {
            p.advance(0.01, &mut rng);
            let c = p.current();
            assert!((0.5..=1.0).contains(&c[0]) && (-0.2..=0.2).contains(&c[1]), "{c:?}");
            if c != last {
                changes += 1;
                last = c;
            }
        }
        // 10 s with a redraw every 1-2 s
        assert!((5..=10).contains(&changes), "{changes} changes");
    }

    #[test]
    fn a_held_command_stays_until_the_next_reset() {
        let mut p = CommandProcess::new(&CommandSettings::default(), None);
        let mut rng = ChaCha8Rng::seed_from_u64(0);
        p.reset(&mut rng);
        p.hold([0.7, -0.1]);
        for _ in 0..2000 {
            p.advance(0.01, &mut rng);
        }
        assert_eq!(p.current(), [0.7, -0.1]);
    }
}
