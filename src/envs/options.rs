//! Validation helpers shared by the environments' option structs.
use super::EnvError;

pub(crate) struct Check<'a> {
    pub env: &'a str,
}

impl Check<'_> {
    fn fail(&self, message: String) -> EnvError {
        EnvError::InvalidOption { env: self.env.to_string(), message }
    }
    pub(crate) fn non_negative(&self, name: &str, v: f64) -> Result<(), EnvError> {
        if v.is_finite() && v >= 0.0 {
            Ok(())
        } else {
            Err(self.fail(format!("{name} must be a finite number >= 0, got {v}")))
        }
    }
    pub fn range(&self, name: &str, r: [f64; 2]) -> Result<(), EnvError> {
        if r[0].is_nan() || r[1].is_nan() || r[0] >= r[1] {
            Err(self.fail(format!("{name} must be [low, high] with low < high, got {r:?}")))
        } else {
            Ok(())
        }
    }
    pub(crate) fn positive_count(&self, name: &str, v: usize) -> Result<(), EnvError> {
        if v > 0 {
            Ok(())
        } else {
            Err(self.fail(format!("{name} must be at least 1")))
        }
    }
    pub fn within(&self, name: &str, v: f64, low: f64, high: f64) -> Result<(), EnvError> {
        if v.is_finite() && v >= low && v <= high {
            Ok(())
        } else {
            Err(self.fail(format!("{name} must lie in [{low}, {high}], got {v}")))
        }
    }
}

/// The checks every MuJoCo task's options get by their names, so that no env restates them:
/// weights, rewards, scales and maxima (`*_weight`, `*_reward`, `*_scale`, `*_max`) are finite
/// and >= 0, ranges (`*_range`) have low < high, step counts (`*_steps`, `frame_skip`) are >= 1.
/// A task checks only what is its own on top (InvertedPendulum's angle limit, say).
/// `MujocoEnv::new` runs it on every task's options before the task is built.
pub(crate) fn check_by_name<T: serde::Serialize>(env: &str, options: &T) -> Result<(), EnvError> {
    let c = Check { env };
    let number = |v: &toml::Value| v.as_float().or_else(|| v.as_integer().map(|i| i as f64));
    let table = toml::Table::try_from(options).expect("options serialise to a table");
    for (key, value) in &table {
        let name = key.as_str();
        if ["_weight", "_reward", "_scale", "_max"].iter().any(|s| name.ends_with(s)) {
            if let Some(v) = number(value) {
                c.non_negative(name, v)?;
            }
        } else if name.ends_with("_range") {
            let bounds = value.as_array().map(|a| [a.first().and_then(number), a.get(1).and_then(number)]);
            if let Some([Some(lo), Some(hi)]) = bounds {
                c.range(name, [lo, hi])?;
            }
        } else if name.ends_with("_steps") || name == "frame_skip" {
            if let Some(n) = value.as_integer() {
                c.positive_count(name, n.max(0) as usize)?;
            }
        }
    }
    Ok(())
}

/// The fields named in `T` read from a task's options (the timing every task has, the reward
/// weights a family of tasks shares), so that no task copies them over by hand. Done once, when
/// the environment is built.
pub(crate) fn read_by_name<T: serde::de::DeserializeOwned, O: serde::Serialize>(options: &O) -> T {
    let value = toml::Value::try_from(options).expect("options serialise");
    value.try_into().unwrap_or_else(|e| panic!("the options lack a field {}: {e}", std::any::type_name::<T>()))
}

/// A wrapper env's options in one flat table: the keys `own_defaults` has go to the wrapper's own
/// settings (missing ones keep those defaults), every other key to the base env's options, which
/// refuse a key they do not know. serde's `flatten` would accept any key, so the split is by name.
pub(crate) fn split_wrapped<B: serde::de::DeserializeOwned, S: serde::Serialize + serde::de::DeserializeOwned>(
    table: toml::Table,
    own_defaults: &S,
) -> Result<(B, S), String> {
    let mut own = toml::Table::try_from(own_defaults).map_err(|e| e.to_string())?;
    let mut base = toml::Table::new();
    for (key, value) in table {
        if own.contains_key(&key) {
            own.insert(key, value);
        } else {
            base.insert(key, value);
        }
    }
    Ok((
        toml::Value::Table(base).try_into().map_err(|e: toml::de::Error| e.message().to_string())?,
        toml::Value::Table(own).try_into().map_err(|e: toml::de::Error| e.message().to_string())?,
    ))
}

/// The flat table of a wrapper env's options: the base's keys, then its own.
pub(crate) fn join_wrapped<B: serde::Serialize, S: serde::Serialize>(base: &B, own: &S) -> Result<toml::Table, String> {
    let mut table = toml::Table::try_from(base).map_err(|e| e.to_string())?;
    table.extend(toml::Table::try_from(own).map_err(|e| e.to_string())?);
    Ok(table)
}
