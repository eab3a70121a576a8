//! How results are measured: one protocol for every policy (held-out reset seeds, the same env
//! and reward, deterministic actions), the controller evaluated as a family over commanded
//! speeds, pushes as a robustness axis, and the statistics every table reports. `report` and
//! the returns bench build their tables on this module alone.
pub mod cache;
pub mod external;
pub mod parallel;
pub mod protocol;
pub mod push;
pub mod robustness;
pub mod speed_grid;
pub mod stats;
pub mod summary;
pub mod tracking;
pub mod walking;

pub use cache::EvalCache;
pub use protocol::{Protocol, DEFAULT_EPISODES};
pub use push::{Push, PushDirection};
pub use speed_grid::{ControllerFamily, SpeedPoint};
pub use walking::{HeldOutCheck, WalkingCheck};
