//! The comparison (`check`) on the CPU, per algorithm.
use candle_core::Device;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use super::check::{compare, config, tolerance, ACT, OBS, UPDATES};
use locobench::agents::common::device::{make_generic_agent, make_generic_on_policy};
use locobench::agents::{make_agent, make_learner, Algo, TrainConfig};

fn check(algo: Algo) {
    let gap = compare(algo, &Device::Cpu, UPDATES);
    let tol = tolerance(algo);
    eprintln!("{algo:?}: largest loss gap {:.2e}, weight gap {:.2e} ({})", gap.loss, gap.weight, gap.weight_name);
    assert!(gap.loss <= tol.loss, "{algo:?}: losses differ by {:.3e} (relative), over {:.0e}", gap.loss, tol.loss);
    assert!(
        gap.weight <= tol.weight,
        "{algo:?}: weight {} differs by {:.3e}, over {:.0e}",
        gap.weight_name,
        gap.weight,
        tol.weight
    );
}

#[test]
fn td3_generic_path_follows_the_fused_one() {
    check(Algo::Td3);
}

#[test]
fn ddpg_generic_path_follows_the_fused_one() {
    check(Algo::Ddpg);
}

#[test]
fn sac_generic_path_follows_the_fused_one() {
    check(Algo::Sac);
}

#[test]
fn crossq_generic_path_follows_the_fused_one() {
    check(Algo::Crossq);
}

#[test]
fn crossq_td3_mode_generic_path_follows_the_fused_one() {
    let mut cfg = config(Algo::Crossq);
    cfg.crossq.as_mut().unwrap().td3_mode = true;
    let gap = super::check::compare_config(&cfg, &Device::Cpu, UPDATES);
    let tol = tolerance(Algo::Crossq);
    assert!(gap.loss <= tol.loss && gap.weight <= tol.weight, "{gap:?}");
}

#[test]
fn dqn_generic_path_follows_the_fused_one() {
    check(Algo::Dqn);
}

#[test]
fn ppo_generic_path_follows_the_fused_one() {
    check(Algo::Ppo);
}

#[test]
fn ppo_with_relu_and_a_log_std_init_follows_the_fused_one_too() {
    let mut cfg = super::check::config(Algo::Ppo);
    cfg.weight_init = locobench::agents::config::WeightInit::Uniform;
    let ppo = cfg.ppo.as_mut().unwrap();
    (ppo.activation, ppo.log_std_init) = (locobench::agents::ppo::Activation::Relu, -2.0);
    // With a std of e^-2 a step of 1e-2 moves the mean by several stds, the ratios leave any
    // range and the paths' last-bit differences decide which samples clip: 1e-3 still clips.
    (cfg.actor_lr, cfg.critic_lr) = (1e-3, 1e-3);
    let gap = super::check::compare_ppo(&cfg, &Device::Cpu, UPDATES);
    let tol = tolerance(Algo::Ppo);
    assert!(gap.loss <= tol.loss && gap.weight <= tol.weight, "{gap:?}");
}

#[test]
fn each_builder_refuses_the_other_kind_of_learner() {
    let rng = &mut ChaCha8Rng::seed_from_u64(1);
    let err = make_generic_agent(&TrainConfig::defaults(Algo::Ppo), OBS, ACT, rng, &Device::Cpu).err().unwrap();
    assert!(err.to_string().contains("ppo learns from its own rollouts"), "{err}");
    let err = make_generic_on_policy(&TrainConfig::defaults(Algo::Sac), OBS, ACT, rng, &Device::Cpu).err().unwrap();
    assert!(err.to_string().contains("sac learns from replay minibatches"), "{err}");
}

#[test]
fn acting_agrees_with_the_fused_path() {
    for algo in [Algo::Td3, Algo::Sac, Algo::Crossq, Algo::Dqn] {
        let cfg = config(algo);
        let fused = make_agent(&cfg, OBS, ACT, &mut ChaCha8Rng::seed_from_u64(2)).unwrap();
        let mut generic = make_generic_agent(&cfg, OBS, ACT, &mut ChaCha8Rng::seed_from_u64(2), &Device::Cpu).unwrap();
        let obs: Vec<f32> = (0..OBS).map(|i| i as f32 * 0.3 - 1.0).collect();
        let (a, b) = (fused.act(&obs).unwrap(), generic.act(&obs).unwrap());
        assert_eq!(a.len(), ACT);
        for (x, y) in a.iter().zip(&b) {
            assert!((x - y).abs() < 1e-5, "{algo:?}: {a:?} vs {b:?}");
        }
        let e = generic.explore(&obs, &mut ChaCha8Rng::seed_from_u64(4)).unwrap();
        assert!(e.iter().all(|v| v.abs() <= 1.0) && e.len() == ACT);
    }
}

#[test]
fn a_fused_checkpoints_state_continues_on_the_generic_path() {
    // What a checkpoint holds (parameters by name, optimiser moments by name, counters) moves
    // from the fused agent into the generic one, which then updates as the fused one does.
    for algo in [Algo::Td3, Algo::Sac, Algo::Crossq, Algo::Dqn] {
        let cfg = config(algo);
        let mut fused = make_learner(&cfg, OBS, ACT, &mut ChaCha8Rng::seed_from_u64(21)).unwrap();
        // another seed: every weight must come from the fused agent's state
        let mut generic = make_generic_agent(&cfg, OBS, ACT, &mut ChaCha8Rng::seed_from_u64(99), &Device::Cpu).unwrap();
        let mut data = ChaCha8Rng::seed_from_u64(3);
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        for _ in 0..7 {
            fused.update(&super::check::batch(&mut data, cfg.batch_size, OBS, ACT), &mut rng).unwrap();
        }
        for ((name, theirs), (other, ours)) in fused.parameters().iter().zip(generic.parameters()) {
            assert_eq!(name, &other);
            ours.set(theirs.as_tensor()).unwrap();
        }
        let states: Vec<_> = fused.optimizers().iter().map(|(n, o)| (n.to_string(), o.state(n).unwrap())).collect();
        for ((name, opt), (saved_name, (tensors, steps))) in generic.optimizers().into_iter().zip(&states) {
            assert_eq!(name, saved_name);
            opt.load_state(name, &tensors.iter().cloned().collect(), *steps).unwrap();
        }
        for (name, value) in fused.counters() {
            generic.set_counter(name, value);
        }
        let b = super::check::batch(&mut data, cfg.batch_size, OBS, ACT);
        let (mut rf, mut rg) = (ChaCha8Rng::seed_from_u64(8), ChaCha8Rng::seed_from_u64(8));
        let (lf, lg) = (fused.update(&b, &mut rf).unwrap(), generic.update(&b, &mut rg).unwrap());
        assert!((lf.critic - lg.critic).abs() <= 1e-5 * (1.0 + lf.critic.abs()), "{algo:?}: {lf:?} vs {lg:?}");
        assert_eq!(lf.actor.is_some(), lg.actor.is_some(), "{algo:?}: the counters did not carry over");
    }
}
