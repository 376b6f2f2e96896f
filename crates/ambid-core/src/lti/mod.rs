//! Linear time-invariant models: state space, polynomial (transfer-function) models, frequency
//! response data, conversions, discretisation, simulation, interconnection.
//!
//! * [`StateSpace`]: continuous or discrete, MIMO; frequency response, poles, transmission zeros,
//!   simulation, impulse response, c2d (ZOH, Tustin with prewarping), d2c (inverse Tustin, inverse
//!   ZOH by the matrix logarithm), series / parallel / feedback.
//! * [`TransferFunction`]: SISO discrete, ascending powers of $q^{-1}$ (controllers as
//!   `{ts, num, den}`); conversions to and from state space.
//! * [`PolyModel`]: $A y = (B/F) u + (C/D) e$ with a [`Structure`] tag.
//! * [`Frd`]: frequency-response data in Hz with optional variance, and its algebra.
//! * [`PidSpec`]: a continuous filtered PID and its discrete equivalent (Tustin, prewarped
//!   Tustin or ZOH, optional computation delay).

mod condition;
mod frd;
mod interconnect;
pub mod pid;
mod poly;
mod ss;
pub(crate) mod tf;

pub use frd::Frd;
pub use interconnect::FeedbackSign;
pub use pid::{Discretisation, PidSpec};
pub use poly::{PolyModel, Structure};
pub use ss::{StateSpace, ZEROS_MAX_ORDER};
pub use tf::TransferFunction;
