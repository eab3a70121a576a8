//! Environment names → constructors, with typed options read from TOML.
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

use super::{
    Ant, AntOptions, Env, EnvError, HalfCheetah, HalfCheetahOptions, Humanoid, HumanoidOptions, InvertedPendulum,
    InvertedPendulumOptions, Minitaur, MinitaurOptions,
};

const NAMES: [&str; 5] = ["half-cheetah", "ant", "humanoid", "inverted-pendulum", "minitaur"];

pub fn env_names() -> &'static [&'static str] {
    &NAMES
}

/// An environment name plus its options as a TOML table (keys not given take their defaults).
/// This is what run directories store, so a run can rebuild exactly the environment it used.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EnvConfig {
    pub name: String,
    #[serde(default)]
    pub options: toml::Table,
}

impl EnvConfig {
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

    /// Every option with its effective value (defaults filled in), validated.
    pub fn resolved_options(&self) -> Result<toml::Table, EnvError> {
        fn resolve<T: DeserializeOwned + Serialize>(c: &EnvConfig) -> Result<toml::Table, EnvError> {
            let typed: T = typed_options(c)?;
            Ok(toml::Table::try_from(&typed).expect("options serialise to a table"))
        }
        check_name(&self.name)?;
        make(self)?; // validates
        match self.name.as_str() {
            "half-cheetah" => resolve::<HalfCheetahOptions>(self),
            "ant" => resolve::<AntOptions>(self),
            "humanoid" => resolve::<HumanoidOptions>(self),
            "inverted-pendulum" => resolve::<InvertedPendulumOptions>(self),
            _ => resolve::<MinitaurOptions>(self),
        }
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
    check_name(env)?;
    let key = match (env, term) {
        ("minitaur", "distance") => "distance_weight",
        ("minitaur", "energy") => "energy_weight",
        ("minitaur", "drift") => "drift_weight",
        ("minitaur", "shake") => "shake_weight",
        ("minitaur", _) => "",
        ("inverted-pendulum", _) => "",
        (_, "forward") => "forward_reward_weight",
        (_, "ctrl" | "ctrl_cost") => "ctrl_cost_weight",
        ("ant" | "humanoid", "contact" | "contact_cost") => "contact_cost_weight",
        ("ant" | "humanoid", "healthy") => "healthy_reward",
        _ => "",
    };
    if key.is_empty() {
        return Err(EnvError::InvalidOption {
            env: env.to_string(),
            message: format!("'{term}' is not a weighted reward term of {env}"),
        });
    }
    Ok(key)
}

fn check_name(name: &str) -> Result<(), EnvError> {
    if NAMES.contains(&name) {
        Ok(())
    } else {
        Err(EnvError::UnknownEnv { name: name.to_string(), known: NAMES.join(", ") })
    }
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
    check_name(&config.name)?;
    Ok(match config.name.as_str() {
        "half-cheetah" => Box::new(HalfCheetah::new(typed_options(config)?)?),
        "ant" => Box::new(Ant::new(typed_options(config)?)?),
        "humanoid" => Box::new(Humanoid::new(typed_options(config)?)?),
        "inverted-pendulum" => Box::new(InvertedPendulum::new(typed_options(config)?)?),
        _ => Box::new(Minitaur::new(typed_options(config)?)?),
    })
}
