//! The command line: one module per command, the argument groups and helpers they share
//! ([`args`], [`common`]) and the exit-code rule ([`exit`]). This is the binary's code (not the
//! library's): it may use `anyhow`, the library returns `ambid::error::Error` and the typed
//! errors it wraps.

pub mod args;
pub mod common;
pub mod exit;

pub mod bla;
pub mod campbell;
pub mod compare;
pub mod compare_models;
pub mod config;
pub mod excite;
pub mod fit;
pub mod frf;
pub mod frf4;
pub mod info;
pub mod init;
pub mod order;
pub mod physical;
pub mod physical_machine;
pub mod physical_operating;
pub mod run;
pub mod simulate;
pub mod simulate4;
pub mod study;
pub mod uncertainty;
pub mod uncertainty_machine;
pub mod validate;
