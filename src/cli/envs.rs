use anyhow::Result;
use locobench::envs::{env_names, make, EnvConfig};

pub fn run() -> Result<()> {
    println!("{:<18} {:>5} {:>7} {:>8} {:>9}  reward terms", "name", "obs", "action", "dt (s)", "max steps");
    for name in env_names() {
        let env = make(&EnvConfig::new(name))?;
        let s = env.spec();
        let bound = format!("[{}, {}]", s.action_space.low[0], s.action_space.high[0]);
        println!(
            "{:<18} {:>5} {:>7} {:>8} {:>9}  {}   actions in {bound}",
            s.name,
            s.observation_space.dim(),
            s.action_space.dim(),
            s.dt,
            s.max_episode_steps,
            s.reward_terms.join(", "),
        );
    }
    Ok(())
}
