//! Model validation: closed-loop simulation of identified plants, model comparison, pole-zero
//! analysis, residual tests.

pub mod closed_loop;
pub mod compare;
pub mod pz;
pub mod residuals;
