//! `locobench device`: the GPU checks. `check` runs the device-generic path against the fused CPU
//! path on a device (the same comparison the CPU tests in `tests` make); `speed` times updates.
mod check;
mod speed;
#[cfg(test)]
mod tests;

use anyhow::{bail, Result};
use clap::{Args, Subcommand};

use locobench::agents::Algo;
use locobench::device::ComputeDevice;

#[derive(Args, Debug)]
pub struct DeviceArgs {
    #[command(subcommand)]
    command: DeviceCommand,
}

#[derive(Subcommand, Debug)]
enum DeviceCommand {
    /// From the same weights and 100 batches, compare the device-generic path on --device with
    /// the fused CPU path: the largest loss and weight gaps per algorithm, against the tolerance.
    Check {
        #[arg(long, default_value = "cpu", value_name = "cpu|cuda[:N]")]
        device: ComputeDevice,
    },
    /// Updates per second of one algorithm at given widths (HalfCheetah-sized inputs), as CSV.
    Speed {
        /// td3, ddpg, sac, crossq, dqn or ppo (timed in epochs: passes over a 2048-step rollout in
        /// minibatches of --batch).
        #[arg(long)]
        algo: String,
        #[arg(long, default_value = "cpu", value_name = "cpu|cuda[:N]")]
        device: ComputeDevice,
        /// fused (the CPU's exact path) or generic.
        #[arg(long, default_value = "generic")]
        path: String,
        /// Hidden layers of the actor (and of TD3's, DDPG's and SAC's critics), e.g. 400,300.
        #[arg(long, value_delimiter = ',', default_value = "256,256")]
        hidden: Vec<usize>,
        /// CrossQ's critic layers, e.g. 2048,2048.
        #[arg(long, value_delimiter = ',')]
        critic_hidden: Option<Vec<usize>>,
        #[arg(long, default_value_t = 256)]
        batch: usize,
        #[arg(long, default_value_t = 17)]
        obs: usize,
        #[arg(long, default_value_t = 6)]
        act: usize,
        /// Seconds to time (after 20 untimed updates).
        #[arg(long, default_value_t = 5.0)]
        seconds: f64,
        /// Print the CSV header first.
        #[arg(long)]
        header: bool,
    },
}

pub fn run(args: DeviceArgs) -> Result<()> {
    match args.command {
        DeviceCommand::Check { device } => run_check(device),
        DeviceCommand::Speed { algo, device, path, hidden, critic_hidden, batch, obs, act, seconds, header } => {
            let algo = Algo::parse(&algo)?;
            let path = match path.as_str() {
                "fused" if device == ComputeDevice::Cpu => speed::Path::Fused,
                "fused" => bail!("the fused path runs on the CPU only; use --path generic with --device {device}"),
                "generic" => speed::Path::Generic,
                other => bail!("unknown path '{other}': expected fused or generic"),
            };
            let cfg = speed::sized_config(algo, &hidden, critic_hidden.as_deref(), batch);
            let dev = device.open()?;
            let unit = if algo == Algo::Ppo { "epochs" } else { "updates" };
            let s = speed::measure(&cfg, obs, act, path, &dev, 20, seconds)?;
            let readback = speed::readback_us(&dev)?;
            if header {
                println!(
                    "algo,device,path,hidden,critic_hidden,batch,updates,updates_per_s,upload_us,readback_us,unit"
                );
            }
            let join = |w: &[usize]| w.iter().map(|v| v.to_string()).collect::<Vec<_>>().join("-");
            println!(
                "{},{device},{},{},{},{batch},{},{:.1},{:.1},{:.1},{unit}",
                algo.name(),
                if path == speed::Path::Fused { "fused" } else { "generic" },
                join(&hidden),
                critic_hidden.as_deref().map(join).unwrap_or_default(),
                s.updates,
                s.updates_per_s,
                s.upload_us,
                readback
            );
            Ok(())
        }
    }
}

fn run_check(device: ComputeDevice) -> Result<()> {
    let dev = device.open()?;
    println!("algo,device,updates,loss_gap,loss_tolerance,weight_gap,weight_tolerance,largest_weight_gap_at,ok");
    let mut failed = Vec::new();
    for algo in check::ALGOS {
        let gap = check::compare(algo, &dev, check::UPDATES);
        let tol = check::tolerance(algo);
        let ok = gap.loss <= tol.loss && gap.weight <= tol.weight;
        println!(
            "{},{device},{},{:.3e},{:.0e},{:.3e},{:.0e},{},{ok}",
            algo.name(),
            check::UPDATES,
            gap.loss,
            tol.loss,
            gap.weight,
            tol.weight,
            gap.weight_name
        );
        if !ok {
            failed.push(algo.name());
        }
    }
    if !failed.is_empty() {
        bail!("the generic path on {device} left the tolerance for {}", failed.join(", "));
    }
    Ok(())
}
