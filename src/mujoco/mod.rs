//! Safe access to MuJoCo 2.2.2: load models, simulate, read state. No input can make MuJoCo
//! abort the process: its fatal errors come back as [`MjError`].
mod data;
mod error;
mod model;
pub mod sys;

pub use data::{Contact, Data, InstabilityCounts};
pub(crate) use error::last_engine_error;
pub use error::{take_warnings, MjError, MjResult};
pub use model::{version, Model, ObjKind};
