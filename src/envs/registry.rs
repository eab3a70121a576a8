//! The environment registry: every environment is declared once, in [`ENVS`] (name, model,
//! options type and constructor, reward weights), and every lookup by name goes through that
//! table; an unknown name is an error everywhere.
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

use super::ant::AntTask;
use super::command::{CommandBase, CommandEnv, CommandOptions};
use super::half_cheetah::HalfCheetahTask;
use super::hopper::HopperTask;
use super::humanoid::HumanoidTask;
use super::inverted_pendulum::InvertedPendulumTask;
use super::walker2d::Walker2dTask;
use super::{minitaur, Ant, Env, EnvError, Minitaur, MinitaurOptions, MujocoEnv, Task};

/// An environment type the registry can build from its options.
pub trait Registered: Env + Sized + 'static {
    /// Its options, every field defaulted (`#[serde(default, deny_unknown_fields)]`).
    type Options: DeserializeOwned + Serialize;
    /// The environment `options` describe, checked.
    fn build(options: Self::Options) -> Result<Self, EnvError>;
}

impl<T: Task> Registered for MujocoEnv<T> {
    type Options = T::Options;
    fn build(options: T::Options) -> Result<Self, EnvError> {
        MujocoEnv::new(options)
    }
}

impl Registered for Minitaur {
    type Options = MinitaurOptions;
    fn build(options: MinitaurOptions) -> Result<Self, EnvError> {
        Minitaur::new(options)
    }
}

impl<B: CommandBase> Registered for CommandEnv<B> {
    type Options = CommandOptions<B>;
    fn build(options: Self::Options) -> Result<Self, EnvError> {
        CommandEnv::new(options)
    }
}

/// One environment's declaration.
pub struct EnvEntry {
    /// The registered name (`--env`).
    pub name: &'static str,
    /// The MJCF model it loads.
    pub model_xml: &'static str,
    /// Reward term names (as `--reward` takes them) and the option that weighs each.
    pub reward_weights: &'static [(&'static str, &'static str)],
    /// For a command task, the registered env whose body it commands (`ant` under `ant-command`).
    pub command_base: Option<&'static str>,
    build: fn(&EnvConfig) -> Result<Box<dyn Env>, EnvError>,
    resolve: fn(&EnvConfig) -> Result<toml::Table, EnvError>,
}

const fn entry<E: Registered>(
    name: &'static str,
    model_xml: &'static str,
    reward_weights: &'static [(&'static str, &'static str)],
) -> EnvEntry {
    EnvEntry { name, model_xml, reward_weights, command_base: None, build: build::<E>, resolve: resolve::<E> }
}

/// The declaration of the command task over `base` (its registered name), named by the base's
/// [`CommandBase::COMMAND_NAME`].
const fn command<B: CommandBase>(base: &'static str, model_xml: &'static str) -> EnvEntry {
    EnvEntry { command_base: Some(base), ..entry::<CommandEnv<B>>(B::COMMAND_NAME, model_xml, COMMAND_REWARD) }
}

/// The declaration of a [`Task`]: its name and model come from the task itself.
const fn task<T: Task>(reward_weights: &'static [(&'static str, &'static str)]) -> EnvEntry {
    entry::<MujocoEnv<T>>(T::NAME, T::MODEL_XML, reward_weights)
}

fn build<E: Registered>(c: &EnvConfig) -> Result<Box<dyn Env>, EnvError> {
    Ok(Box::new(E::build(typed_options(c)?)?))
}

/// Every option with its effective value, after building the env once to validate them.
fn resolve<E: Registered>(c: &EnvConfig) -> Result<toml::Table, EnvError> {
    E::build(typed_options(c)?)?;
    let typed: E::Options = typed_options(c)?;
    Ok(toml::Table::try_from(&typed).expect("options serialise to a table"))
}

const MUJOCO_REWARD: &[(&str, &str)] =
    &[("forward", "forward_reward_weight"), ("ctrl", "ctrl_cost_weight"), ("ctrl_cost", "ctrl_cost_weight")];
const LEGGED_REWARD: &[(&str, &str)] = &[
    ("forward", "forward_reward_weight"),
    ("ctrl", "ctrl_cost_weight"),
    ("ctrl_cost", "ctrl_cost_weight"),
    ("contact", "contact_cost_weight"),
    ("contact_cost", "contact_cost_weight"),
    ("healthy", "healthy_reward"),
];
const PLANAR_WALKER_REWARD: &[(&str, &str)] = &[
    ("forward", "forward_reward_weight"),
    ("ctrl", "ctrl_cost_weight"),
    ("ctrl_cost", "ctrl_cost_weight"),
    ("healthy", "healthy_reward"),
];

/// The registry. Adding an environment is one line here (plus its module and model file).
pub const ENVS: &[EnvEntry] = &[
    task::<HalfCheetahTask>(MUJOCO_REWARD),
    task::<AntTask>(LEGGED_REWARD),
    task::<HumanoidTask>(LEGGED_REWARD),
    task::<InvertedPendulumTask>(&[]),
    task::<Walker2dTask>(PLANAR_WALKER_REWARD),
    task::<HopperTask>(PLANAR_WALKER_REWARD),
    entry::<Minitaur>(
        "minitaur",
        minitaur::MODEL_XML,
        &[
            ("distance", "distance_weight"),
            ("energy", "energy_weight"),
            ("drift", "drift_weight"),
            ("shake", "shake_weight"),
        ],
    ),
    command::<Minitaur>("minitaur", minitaur::MODEL_XML),
    command::<Ant>(AntTask::NAME, super::ant::MODEL_XML),
    entry::<super::notch::NotchWalker>(super::notch::NAME, super::walker2d::MODEL_XML, PLANAR_WALKER_REWARD),
];

const COMMAND_REWARD: &[(&str, &str)] = &[
    ("tracking_speed", "tracking_speed_weight"),
    ("tracking_yaw_rate", "tracking_yaw_rate_weight"),
    ("orientation", "orientation_weight"),
    ("body_rates", "body_rates_weight"),
    ("vertical_velocity", "vertical_velocity_weight"),
    ("action_rate", "action_rate_weight"),
    ("energy", "energy_weight"),
];

/// The declaration of `name`, or an error listing the known names.
pub fn lookup(name: &str) -> Result<&'static EnvEntry, EnvError> {
    ENVS.iter()
        .find(|e| e.name == name)
        .ok_or_else(|| EnvError::UnknownEnv { name: name.to_string(), known: env_names().join(", ") })
}

/// The env whose body the command task `name` commands; None when `name` is not a command task.
pub fn command_base(name: &str) -> Option<&'static str> {
    lookup(name).ok().and_then(|e| e.command_base)
}

/// Every registered environment name, in registration order.
pub fn env_names() -> Vec<&'static str> {
    ENVS.iter().map(|e| e.name).collect()
}

/// An environment name plus its options as a TOML table (keys not given take their defaults).
/// This is what run directories store, so a run can rebuild exactly the environment it used.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EnvConfig {
    /// The registered environment name.
    pub name: String,
    /// Options that differ from the defaults.
    #[serde(default)]
    pub options: toml::Table,
}

impl EnvConfig {
    /// The named environment with default options.
    pub fn new(name: &str) -> EnvConfig {
        EnvConfig { name: name.to_string(), options: toml::Table::new() }
    }

    /// Reads `name = "..."` and an `[options]` table from TOML text.
    pub fn from_toml(text: &str) -> Result<EnvConfig, EnvError> {
        toml::from_str(text)
            .map_err(|e| EnvError::InvalidOption { env: "<config>".into(), message: e.message().to_string() })
    }

    /// Sets options from `key=value` pairs (values parsed as TOML: numbers, booleans, arrays,
    /// bare words as strings). The result is validated when the environment is built.
    pub fn with_overrides(mut self, pairs: &[(String, String)]) -> Result<EnvConfig, EnvError> {
        for (key, value) in pairs {
            let parsed = parse_value(value);
            self.options.insert(key.clone(), parsed);
        }
        Ok(self)
    }

    /// The env the held-out protocol evaluates a policy of this env in: the same env, reward and
    /// options, except perturbations (friction, payload, latency, noise, terrain, slopes, random
    /// shoves), which return to nominal. A policy trained under perturbations then meets the
    /// world every other policy meets; `--option` puts a perturbation back.
    pub fn for_evaluation(&self) -> EnvConfig {
        let mut out = self.clone();
        // A command task takes its base env's perturbations.
        let perturbations: &[&str] = match command_base(&self.name).unwrap_or(&self.name) {
            "minitaur" => &super::minitaur::perturb::OPTIONS,
            "ant" => &super::world::OPTIONS,
            _ => &[],
        };
        for key in perturbations {
            out.options.remove(*key);
        }
        out
    }

    /// Every option with its effective value (defaults filled in), validated.
    pub fn resolved_options(&self) -> Result<toml::Table, EnvError> {
        (lookup(&self.name)?.resolve)(self)
    }
}

fn parse_value(text: &str) -> toml::Value {
    let wrapped = format!("v = {text}");
    match wrapped.parse::<toml::Table>() {
        Ok(mut t) => t.remove("v").unwrap_or_else(|| toml::Value::String(text.to_string())),
        Err(_) => toml::Value::String(text.to_string()),
    }
}

/// Splits `a=1,b=[2,3]` into pairs (commas inside `[...]` belong to the value); an entry
/// without `=` is an error.
pub fn parse_overrides(text: &str) -> Result<Vec<(String, String)>, EnvError> {
    let mut items = Vec::new();
    let (mut depth, mut start) = (0i32, 0usize);
    for (i, c) in text.char_indices() {
        match c {
            '[' => depth += 1,
            ']' => depth -= 1,
            ',' if depth == 0 => {
                items.push(&text[start..i]);
                start = i + 1;
            }
            _ => {}
        }
    }
    items.push(&text[start..]);
    items
        .into_iter()
        .filter(|s| !s.trim().is_empty())
        .map(|item| {
            let (k, v) = item.split_once('=').ok_or_else(|| EnvError::InvalidOption {
                env: "<overrides>".into(),
                message: format!("'{item}' is not key=value"),
            })?;
            Ok((k.trim().to_string(), v.trim().to_string()))
        })
        .collect()
}

/// The option that weighs a reward term: `drift` -> `drift_weight` on Minitaur, `forward` ->
/// `forward_reward_weight`, `ctrl` -> `ctrl_cost_weight`, ... on the others.
pub fn reward_weight_option(env: &str, term: &str) -> Result<&'static str, EnvError> {
    let entry = lookup(env)?;
    entry.reward_weights.iter().find(|(t, _)| *t == term).map(|(_, key)| *key).ok_or_else(|| EnvError::InvalidOption {
        env: env.to_string(),
        message: format!(
            "'{term}' is not a weighted reward term of {env} (its terms: {})",
            if entry.reward_weights.is_empty() {
                "none".to_string()
            } else {
                entry.reward_weights.iter().map(|(t, _)| *t).collect::<Vec<_>>().join(", ")
            }
        ),
    })
}

fn typed_options<T: DeserializeOwned>(c: &EnvConfig) -> Result<T, EnvError> {
    let parse = |table: toml::Table| toml::Value::Table(table).try_into::<T>();
    parse(c.options.clone()).map_err(|e| {
        // serde's message may not say which key was wrong: find it by parsing keys one by one.
        let culprit = c.options.iter().find(|(k, v)| {
            let mut single = toml::Table::new();
            single.insert((*k).clone(), (*v).clone());
            parse(single).is_err()
        });
        let message = match culprit {
            Some((key, _)) if !e.message().contains(key.as_str()) => {
                format!("option '{key}': {}", e.message())
            }
            _ => e.message().to_string(),
        };
        EnvError::InvalidOption { env: c.name.clone(), message }
    })
}

/// Builds the environment a config names.
pub fn make(config: &EnvConfig) -> Result<Box<dyn Env>, EnvError> {
    (lookup(&config.name)?.build)(config)
}

/// The MJCF model an environment loads.
pub fn model_xml(env_name: &str) -> Result<&'static str, EnvError> {
    Ok(lookup(env_name)?.model_xml)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every declaration is whole: the name is unique, the env builds with its defaults, each
    /// reward weight names an option the env really has, and the model is the env's own.
    #[test]
    fn every_entry_is_consistent() {
        let names = env_names();
        for (i, e) in ENVS.iter().enumerate() {
            assert!(!names[..i].contains(&e.name), "{} declared twice", e.name);
            let config = EnvConfig::new(e.name);
            let env = make(&config).unwrap();
            assert_eq!(env.spec().name, e.name);
            let options = config.resolved_options().unwrap();
            for (term, key) in e.reward_weights {
                assert!(options.contains_key(*key), "{}: reward term {term} names missing option {key}", e.name);
                assert_eq!(reward_weight_option(e.name, term).unwrap(), *key);
            }
            assert_eq!(model_xml(e.name).unwrap(), e.model_xml);
            if let Some(base) = e.command_base {
                // A command task observes its base env's observations first, then the command's.
                let base_dim = make(&EnvConfig::new(base)).unwrap().spec().observation_space.dim();
                let extra = crate::envs::command::EXTRA_OBSERVATIONS;
                assert_eq!(env.spec().observation_space.dim(), base_dim + extra, "{} over {base}", e.name);
                assert_eq!(lookup(base).unwrap().model_xml, e.model_xml);
            }
        }
        assert_eq!(command_base("minitaur-command"), Some("minitaur"));
        assert_eq!(command_base("ant-command"), Some("ant"));
        for not_a_command_task in ["ant", "walker2d-notch", "hopper-command", ""] {
            assert_eq!(command_base(not_a_command_task), None);
        }
        for bad in [make(&EnvConfig::new("hoper")).err(), model_xml("hoper").err(), lookup("").err()] {
            assert!(matches!(bad, Some(EnvError::UnknownEnv { .. })));
        }
        assert!(EnvConfig::new("walker").resolved_options().is_err());
        assert!(EnvConfig::new("walker-2d").resolved_options().is_err());
        assert!(reward_weight_option("inverted-pendulum", "forward").is_err());
        assert!(reward_weight_option("minitaur", "forward").is_err());
    }
}
