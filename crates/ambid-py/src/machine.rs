//! The whole rotor from Python: the 4-axis twin's multi-axis experiments with their MIMO
//! closed-loop FRF per speed (`ambid::workflow::machine::acquire_twin`, the data stage of
//! `ambid run` with a `[machine]` section), and the MIMO FRF of experiments given as arrays
//! (`ambid::workflow::machine::measure_records`, the same function that stage calls).
//!
//! Arrays of several axes are `N × 4` (one column per axis, in the order `xa, xb, ya, yb`);
//! matrix FRFs are `(L, ny, nu)` complex arrays, entry `[l, i, j]` from input `j` to output `i`.

use super::{err, finite_positive, ss_model, to_py, Kind};
use ambid::config::MachineSection;
use ambid::workflow::machine::{acquire_twin, measure_records, MeasuredFrf};
use ambid_core::data::{IoData, AXES};
use ambid_core::lti::Frd;
use numpy::ndarray::{Array2, Array3};
use numpy::{IntoPyArray, PyArrayMethods, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use std::path::Path;

/// Puts each matrix FRF as `key` (`(L, ny, nu)` complex) and, with variances, `key_std`.
fn put_matrix(d: &Bound<'_, PyDict>, frds: &[(&str, &Frd)]) -> PyResult<()> {
    let py = d.py();
    for (key, g) in frds {
        let (l, ny, nu) = (g.len(), g.ny(), g.nu());
        // the Frd stores line k column-major: index k·ny·nu + j·ny + i
        let at = |k: usize, i: usize, j: usize| k * ny * nu + j * ny + i;
        let v = g.values();
        d.set_item(
            *key,
            Array3::from_shape_fn((l, ny, nu), |(k, i, j)| v[at(k, i, j)]).into_pyarray(py),
        )?;
        if let Some(var) = g.variance() {
            d.set_item(
                format!("{key}_std"),
                Array3::from_shape_fn((l, ny, nu), |(k, i, j)| var[at(k, i, j)].sqrt())
                    .into_pyarray(py),
            )?;
        }
    }
    Ok(())
}

/// One speed's measured FRFs: `f_hz`, `plant` and, when present, `t_ry` and `s`, each with
/// `*_std`.
fn put_measured(d: &Bound<'_, PyDict>, m: &MeasuredFrf) -> PyResult<()> {
    d.set_item("f_hz", m.plant.f_hz().to_vec().into_pyarray(d.py()))?;
    let mut frds = vec![("plant", &m.plant)];
    if let Some(t) = &m.t_ry {
        frds.push(("t_ry", t));
    }
    if let Some(t) = &m.s {
        frds.push(("s", t));
    }
    put_matrix(d, &frds)
}

/// One experiment's channels as `N × 4` arrays per quantity (`r`, `u`, `y`, and `i` when
/// recorded).
fn experiment_dict<'py>(py: Python<'py>, rec: &IoData) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    for q in ["r", "u", "y", "i"] {
        let cols: Vec<&[f64]> = AXES
            .iter()
            .filter_map(|ax| rec.channel(&format!("{q}_{ax}")).ok())
            .collect();
        if cols.len() != AXES.len() {
            continue;
        }
        let n = cols[0].len();
        d.set_item(
            q,
            Array2::from_shape_fn((n, AXES.len()), |(t, k)| cols[k][t]).into_pyarray(py),
        )?;
    }
    Ok(d)
}

/// The `[machine]` section from its TOML text (the keys of the workflow file's section,
/// docs/workflow.md "Whole machine"), checked as `ambid run` checks it.
fn section(text: &str) -> PyResult<MachineSection> {
    let m: MachineSection = toml::from_str(text).map_err(|e| {
        err(
            Kind::Usage,
            format!("the machine settings: {e} (the keys of a workflow file's [machine] section, docs/workflow.md)"),
        )
    })?;
    m.check(Path::new("machine settings"), false)
        .map_err(|e| to_py(ambid::error::Error::from(e)))?;
    if m.from_files() {
        return Err(err(
            Kind::Usage,
            "machine_experiments runs the twin; for recorded experiments read the files and call \
             ambid.frf_mimo (or ambid.run with [[machine.files]])",
        ));
    }
    Ok(m)
}

/// The 4-axis twin's experiments at every speed of the `[machine]` settings `machine` (TOML
/// text; empty: the defaults, 0, 15 000 and 30 000 rpm, orthogonal PRBS design), with the MIMO
/// FRF of each speed, exactly as `ambid run` acquires them. Returns one dict per speed.
///
/// # Example
///
/// ```python
/// >>> import numpy as np, ambid
/// >>> (s,) = ambid.machine_experiments('speeds_rpm = [0.0]\nmode = "linear"\nnoise = false\nperiods = 4')
/// >>> s["plant"].shape[1:], len(s["experiments"])
/// ((4, 4), 4)
/// >>> p = s["plant_true"].freq_response(s["f_hz"])
/// >>> bool(np.max(np.abs(s["plant"] - p)) < 1e-6 * np.max(np.abs(p)))
/// True
///
/// ```
#[pyfunction]
#[pyo3(signature = (machine="", *, seed=1))]
pub(crate) fn machine_experiments<'py>(
    py: Python<'py>,
    machine: &str,
    seed: u64,
) -> PyResult<Bound<'py, PyList>> {
    let m = section(machine)?;
    let seed = m.seed.unwrap_or(seed);
    let data = py
        .detach(|| acquire_twin(&m, Path::new("."), seed))
        .map_err(to_py)?;
    let out = PyList::empty(py);
    for (k, s) in data.speeds.iter().enumerate() {
        let d = PyDict::new(py);
        d.set_item("speed_rpm", s.speed_rpm)?;
        d.set_item("fs", 1.0 / data.ts)?;
        d.set_item("period_samples", s.period_samples)?;
        d.set_item("sync_removed_hz", s.sync_removed_hz)?;
        d.set_item("axes", AXES.to_vec())?;
        put_measured(&d, &s.frf)?;
        let exps = PyList::empty(py);
        for rec in &s.records {
            exps.append(experiment_dict(py, rec)?)?;
        }
        d.set_item("experiments", exps)?;
        if let Some(t) = data.truth.as_ref().and_then(|t| t.get(k)) {
            d.set_item("plant_true", Py::new(py, ss_model(t.plant.clone(), "ss"))?)?;
            d.set_item(
                "controller",
                Py::new(py, ss_model(t.controller.clone(), "ss"))?,
            )?;
        }
        out.append(d)?;
    }
    Ok(out)
}

/// An `N × 4` float64 array of experiment `e`'s quantity `q`, as 4 columns.
fn columns(e: usize, q: &str, obj: &Bound<'_, PyAny>) -> PyResult<Vec<Vec<f64>>> {
    let name = format!("experiments[{e}][\"{q}\"]");
    let a = obj.cast::<numpy::PyArray2<f64>>().map_err(|_| {
        err(
            Kind::Input,
            format!("`{name}` must be a 2-D float64 numpy array (samples × axes)"),
        )
    })?;
    let ro = a.readonly();
    let v = ro.as_array();
    if v.ncols() != AXES.len() {
        return Err(err(
            Kind::Input,
            format!(
                "`{name}` has shape {:?}: give one column per axis, {} columns (xa, xb, ya, yb; \
                 a zero column for an axis that is not excited)",
                a.shape(),
                AXES.len()
            ),
        ));
    }
    Ok((0..v.ncols()).map(|j| v.column(j).to_vec()).collect())
}

/// The MIMO closed-loop FRF of periodic multi-axis experiments given as arrays: each
/// experiment a dict with `r`, `u`, `y` as `N × 4` arrays (columns `xa, xb, ya, yb`; r added
/// to the controller outputs). Several experiments (4 or more: sequential or
/// orthogonal designs) are solved per line; one experiment exciting every axis on its own
/// lines (zippered) column by column. With `speed_rpm` > 0 the 1× line is estimated and
/// removed first. The same function as the data stage of `ambid run` with `[machine]`.
///
/// # Example
///
/// ```python
/// >>> import numpy as np, ambid
/// >>> (s,) = ambid.machine_experiments('speeds_rpm = [0.0]\nmode = "linear"\nperiods = 4')
/// >>> exps = [{k: e[k] for k in ("r", "u", "y")} for e in s["experiments"]]
/// >>> out = ambid.frf_mimo(exps, s["fs"], period_samples=s["period_samples"])
/// >>> bool(np.array_equal(out["plant"], s["plant"]))
/// True
///
/// ```
#[pyfunction]
#[pyo3(signature = (experiments, fs, *, period_samples, skip_periods=1, band=None, speed_rpm=0.0))]
pub(crate) fn frf_mimo<'py>(
    py: Python<'py>,
    experiments: &Bound<'py, PyList>,
    fs: f64,
    period_samples: usize,
    skip_periods: usize,
    band: Option<(f64, f64)>,
    speed_rpm: f64,
) -> PyResult<Bound<'py, PyDict>> {
    let fs = finite_positive("fs", fs)?;
    if !(speed_rpm.is_finite() && speed_rpm >= 0.0) {
        return Err(err(
            Kind::Usage,
            format!("`speed_rpm` must be a finite speed ≥ 0, got {speed_rpm}"),
        ));
    }
    let band = super::band_of("band", band)?;
    if experiments.is_empty() {
        return Err(err(
            Kind::Input,
            "`experiments` is empty: give at least one experiment",
        ));
    }
    let mut records = Vec::with_capacity(experiments.len());
    for (e, ex) in experiments.iter().enumerate() {
        let ex = ex.cast::<PyDict>().map_err(|_| {
            err(
                Kind::Input,
                format!("`experiments[{e}]` must be a dict with the arrays r, u, y"),
            )
        })?;
        let mut ch = Vec::new();
        for q in ["r", "u", "y"] {
            let obj = ex.get_item(q)?.ok_or_else(|| {
                err(
                    Kind::Input,
                    format!("`experiments[{e}]` has no \"{q}\": give r, u and y (samples × axes)"),
                )
            })?;
            for (j, c) in columns(e, q, &obj)?.into_iter().enumerate() {
                ch.push((format!("{q}_{}", AXES[j]), c));
            }
        }
        records.push(
            IoData::new(ch, 1.0 / fs, Some(period_samples))
                .map_err(|e2| err(Kind::Input, format!("experiments[{e}]: {e2}")))?,
        );
    }
    let (measured, _, sync) = py
        .detach(|| {
            measure_records(
                records,
                period_samples,
                skip_periods,
                band,
                speed_rpm,
                "the experiments",
            )
        })
        .map_err(to_py)?;
    let d = PyDict::new(py);
    put_measured(&d, &measured)?;
    d.set_item("sync_removed_hz", sync)?;
    Ok(d)
}
