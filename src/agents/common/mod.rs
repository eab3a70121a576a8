//! What several algorithms share: networks ([`nets`], [`critics`]), the objectives SAC and CrossQ
//! both minimise ([`objectives`], [`squashed`]), the replay buffer, observation normalisation,
//! exploration noise, and the building blocks of the device versions ([`device`]).
pub mod buffer;
pub(crate) mod critics;
pub mod device;
pub(crate) mod nets;
pub mod noise;
pub mod normalize;
pub mod objectives;
pub mod squashed;
