//! Model validation: closed-loop simulation of identified plants, model comparison, pole-zero
//! analysis, residual tests, k-step prediction, the ISO 14839-3 sensitivity zone.

pub mod closed_loop;
pub mod compare;
pub mod fit;
pub mod iso;
pub mod machine;
pub mod margins;
pub mod nyquist;
pub mod predict;
pub mod pz;
pub mod residuals;
pub mod robust;
pub mod uncertainty;
pub mod weight;
