//! Model validation: closed-loop simulation of identified plants, pole-zero analysis.

pub mod closed_loop;
pub mod pz;
