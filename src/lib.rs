//! locobench: legged-locomotion reinforcement learning and classical control on MuJoCo.
pub mod envs;
pub mod mujoco;
