//! A controller built for one command, made to follow a command task's stream: whenever the
//! command at the end of the observation changes, the controller for the new command is built
//! and takes over, ramping from where the robot is (its own ramp, from standing, when the
//! episode starts). What the Ant controllers do on `ant-command`, whose rowing cycle and posture
//! are chosen for one speed; the Minitaur controller follows the stream itself.
use anyhow::Result;

use super::command::Command;
use super::gait::GaitKind;
use crate::envs::Env;
use crate::policy::{Policy, Telemetry};

/// Builds the controller for a command.
type Build = fn(Command, Option<GaitKind>) -> Result<Box<dyn Policy>>;

/// Follows the command a command task puts at the end of its observation.
pub(crate) struct CommandFollower {
    build: Build,
    gait: Option<GaitKind>,
    name: String,
    episode: usize,
    command: Option<[f64; 2]>,
    inner: Option<Box<dyn Policy>>,
}

impl CommandFollower {
    pub(crate) fn new(name: String, build: Build, gait: Option<GaitKind>) -> CommandFollower {
        CommandFollower { build, gait, name, episode: 0, command: None, inner: None }
    }
}

impl Policy for CommandFollower {
    fn name(&self) -> String {
        self.name.clone()
    }

    fn begin_episode(&mut self, episode: usize) {
        self.episode = episode;
        self.command = None;
        self.inner = None;
    }

    fn act(&mut self, env: &dyn Env, observation: &[f64]) -> Result<Vec<f64>> {
        let n = observation.len();
        let command = [observation[n - 2], observation[n - 1]];
        if self.command != Some(command) || self.inner.is_none() {
            let ramp = if self.command.is_none() { super::baseline::RAMP_TIME } else { 0.0 };
            let mut c = (self.build)(
                Command { speed: super::command::SpeedProfile::ramp(command[0], ramp), yaw_rate: command[1] },
                self.gait,
            )?;
            c.begin_episode(self.episode);
            self.inner = Some(c);
            self.command = Some(command);
        }
        self.inner.as_mut().expect("built above").act(env, observation)
    }

    fn diagnostics(&self) -> Vec<(&'static str, f64)> {
        self.inner.as_ref().map(|c| c.diagnostics()).unwrap_or_default()
    }

    fn telemetry(&self) -> Telemetry {
        self.inner.as_ref().map(|c| c.telemetry()).unwrap_or_default()
    }
}
