//! # ambid
//!
//! The ambid application as a library: file formats ([`io`]), the twin experiment
//! ([`experiment`]), the excitation comparison ([`comparison`]), the identification pipeline as
//! typed stages ([`stage`]) with their settings ([`config`], the workflow file) and the workflow that sequences them into one typed outcome
//! ([`workflow`]). The `ambid` binary is a thin command-line layer over these.

pub mod analysis;
pub mod bla;
pub mod comparison;
pub mod config;
mod config_machine;
pub mod error;
pub mod experiment;
pub mod fitting;
pub mod frf_stream;
pub mod io;
pub mod physical;
pub mod report;
pub mod stage;
pub mod stepped_sine;
pub mod study;
pub mod uncertainty;
pub mod validation;
pub mod workflow;
