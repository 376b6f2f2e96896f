//! Model validation: closed-loop simulation of identified plants, model comparison, pole-zero
//! analysis.

pub mod closed_loop;
pub mod compare;
pub mod pz;
