//! Exporting identified models for MATLAB and Python users: a MATLAB `.m` script that rebuilds
//! the model, a MATLAB `.mat` (v5) file and a NumPy `.npz` archive (the JSON form is in
//! [`super::model`]).
//!
//! SKELETON: the interface is fixed; the writers are being written.

use ambid_core::lti::{PolyModel, StateSpace};

/// A model to export, with its signal names.
#[derive(Debug, Clone, Copy)]
pub enum ExportModel<'a> {
    /// A polynomial model (`A y = B/F u + C/D e`).
    Poly(&'a PolyModel),
    /// A discrete state-space model (optionally with a Kalman gain for the innovations form).
    StateSpace(&'a StateSpace, Option<&'a [f64]>),
}

/// Names carried into the exported files.
#[derive(Debug, Clone)]
pub struct ExportNames {
    /// Variable / model name (a valid MATLAB and Python identifier).
    pub name: String,
    /// Input signal name.
    pub input: String,
    /// Output signal name.
    pub output: String,
}

/// A MATLAB script (`.m`) that rebuilds the model.
pub fn matlab_script(model: ExportModel<'_>, names: &ExportNames) -> String {
    let _ = (model, names);
    String::new()
}

/// The model as a MATLAB v5 `.mat` file (bytes).
pub fn mat_bytes(model: ExportModel<'_>, names: &ExportNames) -> anyhow::Result<Vec<u8>> {
    let _ = (model, names);
    anyhow::bail!("not implemented yet")
}

/// The model as a NumPy `.npz` archive (bytes).
pub fn npz_bytes(model: ExportModel<'_>, names: &ExportNames) -> anyhow::Result<Vec<u8>> {
    let _ = (model, names);
    anyhow::bail!("not implemented yet")
}
