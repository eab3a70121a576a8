//! The robustness suite: the same perturbations for the controller and for every trained policy
//! (pushes both ways, ground friction, payload and centre of mass, motor strength and battery,
//! control latency, sensor noise, rough terrain, slopes), each from nominal to where policies
//! fail, on the protocol's held-out episodes. `locobench robustness` and
//! `cargo bench --bench robustness` run it; the report charts its committed CSV.
pub mod axes;
pub mod output;
pub mod plan;
pub mod suite;
pub mod summary;

pub use axes::{axes_of, select, Axis};
pub use plan::{plan, ControllerChoice, Plan};
pub use suite::{Cell, Contender, Outcome, Suite};
