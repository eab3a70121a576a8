use crate::mujoco::MjError;

/// Why an environment refused a call.
#[derive(Debug, thiserror::Error)]
pub enum EnvError {
    /// The action's length is not the action space's.
    #[error("action has {got} entries, this environment expects {expected}")]
    ActionLength {
        /// The action space's dimension.
        expected: usize,
        /// The action's length.
        got: usize,
    },
    /// An action entry is NaN or infinite.
    #[error("action entry {index} is {value}: actions must be finite numbers")]
    NonFiniteAction {
        /// The first such entry.
        index: usize,
        /// Its value.
        value: f64,
    },
    /// No environment is registered under this name.
    #[error("unknown environment '{name}'; known environments: {known}")]
    UnknownEnv {
        /// The name asked for.
        name: String,
        /// The registered names, comma-separated.
        known: String,
    },
    /// An option is unknown, of the wrong type or out of range.
    #[error("invalid option for {env}: {message}")]
    InvalidOption {
        /// The environment's name.
        env: String,
        /// What is wrong, naming the option.
        message: String,
    },
    /// A vector environment got a different number of actions than it has copies.
    #[error("got {got} actions for {expected} environment copies")]
    ActionCount {
        /// The number of copies.
        expected: usize,
        /// The number of actions.
        got: usize,
    },
    /// One copy of a vector environment failed.
    #[error("environment copy {copy}: {source}")]
    InCopy {
        /// The copy's index.
        copy: usize,
        /// What went wrong in it.
        source: Box<EnvError>,
    },
    /// `step` before the first `reset`.
    #[error("step called before reset")]
    NotReset,
    /// `step` after the episode terminated or was truncated.
    #[error("the episode is over (terminated or truncated); call reset")]
    EpisodeOver,
    /// The model failed to load or the engine reported an error.
    #[error(transparent)]
    Mujoco(#[from] MjError),
}
