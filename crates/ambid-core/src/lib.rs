//! # ambid-core
//!
//! A closed-loop system-identification library: linear models and matrix-valued frequency-response
//! data ([`lti`]), dense linear algebra glue ([`linalg`]), excitation signals ([`signal`]), measured
//! data with channel roles and experiments ([`data`]), nonparametric FRF estimation ([`frf`]),
//! parametric estimation ([`estimate`]) and validation and metrics ([`validate`]). Pure
//! computation: no file I/O, no plotting.
//!
//! Conventions (see `docs/conventions.md`): SI units, frequencies in Hz at every public boundary,
//! polynomials in ascending powers of $q^{-1}$, every discrete model carries its sample time.
#![warn(missing_docs)]

pub mod data;
pub mod error;
pub mod estimate;
pub mod frf;
pub mod linalg;
pub mod lti;
pub mod signal;
pub mod validate;

pub use error::{Error, Result};
pub use faer::c64;
