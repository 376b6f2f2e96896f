//! File formats of ambid (see `docs/formats.md`; they are a public interface).
//!
//! * time data: CSV with a header row, one column per signal, SI units, optional `t` column;
//! * frequency-response data: CSV `f_hz, <q>_re, <q>_im, <q>_std, …`;
//! * controllers: TOML or JSON, a PID description, a transfer function or a state space.

pub mod controller;
pub mod csv;
pub mod model;

pub use self::controller::{read_controller, ControllerModel};
pub use self::csv::{
    read_time_csv, write_frf_csv, write_frf_csv_with, write_time_csv, FrfColumn, TimeData,
};
