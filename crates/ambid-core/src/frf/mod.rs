//! Nonparametric frequency-response estimation from (closed-loop) data.

pub mod band;
pub mod bla;
pub mod closed_loop;
pub mod lpm;
pub mod lrm;
pub mod mimo;
pub mod mimo_lpm;
pub mod periodic;
pub mod quality;
pub mod resonance;
pub mod stepped_sine;
pub mod synchronous;
pub mod welch;
pub mod window;

pub use mimo::{MimoClosedLoopFrf, MimoDesign, MimoOptions};
pub use synchronous::{synchronous, SynchronousLine, SynchronousOptions};
