//! # ambid-twin
//! (docs below)
#![warn(missing_docs)]

pub mod config;
pub mod error;
pub mod model;
pub mod sim;
mod twin;

pub use config::{
    AmplifierConfig, ControllerConfig, MagnetConfig, Mode, OperatingPoint, RotorConfig,
    SensorConfig, SimulationConfig, TwinConfig,
};
pub use error::{Result, TwinError};
pub use faer::c64;
pub use model::{LinearParams, UnstablePolePrediction};
pub use sim::{Channels, SimMeta, SimOptions, SimRecord};
pub use twin::{ClosedLoopMode, Twin, LIGHTLY_DAMPED};
