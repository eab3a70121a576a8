//! Building a run's configuration: algorithm defaults, then the shipped presets for the
//! environment, then command-line overrides.
use anyhow::Result;

use crate::agents::{Algo, OtherAlgorithmKeys, TrainConfig};

const PRESETS: &str = include_str!("presets.toml");

/// The preset table for an env (and algorithm), merged over the algorithm's defaults, then
/// `overrides` (`key=value`, values parsed as TOML) on top. Keys are flat: an algorithm's own
/// settings are named without their section (`policy_noise`, not `td3.policy_noise`).
pub fn build_config(env: &str, algo: Algo, overrides: &[(String, String)]) -> Result<TrainConfig> {
    let mut table = TrainConfig::defaults(algo).to_flat_table();
    let presets: toml::Table = PRESETS.parse().expect("shipped presets parse");
    if let Some(toml::Value::Table(env_table)) = presets.get(env) {
        for (k, v) in env_table {
            // Algorithm tables are read below; every other key applies to all algorithms.
            if Algo::parse(k).is_err() {
                table.insert(k.clone(), v.clone());
            }
        }
        if let Some(toml::Value::Table(algo_table)) = env_table.get(algo.name()) {
            table.extend(algo_table.clone());
        }
    }
    apply_overrides(&mut table, overrides)?;
    let cfg = TrainConfig::from_table(&table, OtherAlgorithmKeys::Refuse)?;
    cfg.validate()?;
    Ok(cfg)
}

/// Sets `key=value` pairs in a flat table; which keys exist is checked when the table is read.
pub(crate) fn apply_overrides(table: &mut toml::Table, overrides: &[(String, String)]) -> Result<()> {
    for (key, value) in overrides {
        anyhow::ensure!(key != "algo", "choose the algorithm with --algo, not --set algo=");
        let parsed: toml::Value = format!("v = {value}")
            .parse::<toml::Table>()
            .ok()
            .and_then(|mut t| t.remove("v"))
            .unwrap_or_else(|| toml::Value::String(value.clone()));
        table.insert(key.clone(), parsed);
    }
    Ok(())
}

/// Splits `a=1,b=[2,3]` into pairs, as environment options are split.
pub fn split_pairs(text: &str) -> Result<Vec<(String, String)>> {
    Ok(crate::envs::parse_overrides(text)?)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn presets_then_overrides() {
        let c = build_config("inverted-pendulum", Algo::Td3, &[]).unwrap();
        assert_eq!(c.hidden, vec![64, 64]);
        assert_eq!(c.batch_size, 256);
        assert_eq!(c.dpg().policy_delay, 2);
        let c = build_config("half-cheetah", Algo::Ddpg, &split_pairs("hidden=[32,32],tau=0.01").unwrap()).unwrap();
        assert_eq!(c.hidden, vec![32, 32]);
        assert_eq!(c.tau, 0.01);
        assert!(!c.dpg().twin_critics);
        assert!(build_config("ant", Algo::Sac, &split_pairs("nonsense=1").unwrap()).is_err());
        let err = build_config("ant", Algo::Td3, &split_pairs("alpha_lr=0.1").unwrap()).unwrap_err().to_string();
        assert!(err.contains("'alpha_lr' is a setting of sac and crossq, not of td3"), "{err}");
        let c = build_config("ant", Algo::Sac, &split_pairs("target_entropy=-4,alpha_lr=0.001").unwrap()).unwrap();
        assert_eq!((c.sac().target_entropy, c.sac().alpha_lr), (Some(-4.0), 0.001));
        assert!(build_config("ant", Algo::Sac, &split_pairs("tau=2").unwrap()).is_err());
        assert!(build_config("ant", Algo::Sac, &split_pairs("batch_size=\"big\"").unwrap()).is_err());
    }
}
