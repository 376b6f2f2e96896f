//! Measured input-output data and its preprocessing.
