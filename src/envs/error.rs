use crate::mujoco::MjError;

#[derive(Debug, thiserror::Error)]
pub enum EnvError {
    #[error("action has {got} entries, this environment expects {expected}")]
    ActionLength { expected: usize, got: usize },
    #[error("action entry {index} is {value}: actions must be finite numbers")]
    NonFiniteAction { index: usize, value: f64 },
    #[error("unknown environment '{name}'; known environments: {known}")]
    UnknownEnv { name: String, known: String },
    #[error("invalid option for {env}: {message}")]
    InvalidOption { env: String, message: String },
    #[error("step called before reset")]
    NotReset,
    #[error("the episode is over (terminated or truncated); call reset")]
    EpisodeOver,
    #[error(transparent)]
    Mujoco(#[from] MjError),
}
