//! File formats of ambid (see `docs/formats.md`; they are a public interface).
//!
//! * time data: CSV with a header row, one column per signal, SI units, optional `t` column;
//!   also text without a header, NumPy, MATLAB and Parquet files through [`table`]; every command
//!   reads a record through [`time::read_time`];
//! * frequency-response data: CSV `f_hz, <q>_re, <q>_im, <q>_std, …`;
//! * controllers: TOML or JSON, a PID description, a transfer function or a state space;
//! * models: JSON ([`model`]) and MATLAB/NumPy exports ([`export`]).

pub mod controller;
pub mod csv;
pub mod export;
pub mod model;
pub mod output;
pub mod stream;
pub mod table;
pub mod time;

pub use self::controller::{read_controller, ControllerModel};
pub use self::csv::{
    frf_csv_bytes, time_csv_bytes, time_csv_to, write_frf_csv, write_frf_csv_with, write_time_csv,
    FrfColumn,
};
pub use self::output::{OutputError, OutputSet};
pub use self::time::{read_time, TimeData, TimeOptions};
