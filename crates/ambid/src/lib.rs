//! # ambid
//!
//! The ambid application as a library: file formats ([`io`]) and the twin experiment
//! ([`experiment`]). The `ambid` binary is a thin command-line layer over these.

pub mod experiment;
pub mod io;
