//! locobench: legged-locomotion reinforcement learning and classical control on MuJoCo.
#![warn(missing_docs)]
#![warn(clippy::undocumented_unsafe_blocks)]
pub mod agents;
pub mod args;
pub mod controller;
pub mod device;
pub mod envs;
pub mod evaluation;
pub mod io;
pub mod mujoco;
pub mod numeric;
pub mod policy;
pub mod record;
pub mod render;
pub mod report;
pub mod rollout;
pub mod runtime;
pub mod sweep;
pub mod train;
