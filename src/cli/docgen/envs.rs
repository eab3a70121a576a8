//! The environments table, from the registry itself.
use std::fmt::Write as _;

use anyhow::Result;

use locobench::envs::{env_names, make, EnvConfig};

pub fn table() -> Result<String> {
    let mut out = String::from(
        "| name | observation | action | action bounds | control period (s) | steps per episode | reward terms |\n\
         |---|---|---|---|---|---|---|\n",
    );
    for name in env_names() {
        let env = make(&EnvConfig::new(name))?;
        let s = env.spec();
        let _ = writeln!(
            out,
            "| `{}` | {} | {} | [{}, {}] | {} | {} | {} |",
            s.name,
            s.observation_space.dim(),
            s.action_space.dim(),
            s.action_space.low[0],
            s.action_space.high[0],
            s.dt,
            s.max_episode_steps,
            s.reward_terms.join(", "),
        );
    }
    Ok(out)
}
