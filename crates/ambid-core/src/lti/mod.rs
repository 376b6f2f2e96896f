//! Linear time-invariant models: state space, polynomial (transfer-function) models, frequency
//! response data, conversions, discretisation, simulation, interconnection.

mod ss;

pub use ss::StateSpace;
