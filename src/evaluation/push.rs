//! Pushes as an evaluation axis: the push itself is an env perturbation (`envs::push`), below
//! both the evaluation and the renderer that films it.
pub use crate::envs::push::{Push, PushDirection, Pushed, PUSH_DURATION};
