//! Model validation: pole-zero analysis.

pub mod pz;
