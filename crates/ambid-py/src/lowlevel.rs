//! Lower-level stages of the library exposed one to one: Welch spectra of several channels,
//! subspace identification with its diagnostics (optionally refined by state-space PEM), and a
//! `Model` built from given matrices. They are what a script composes when the whole-workflow
//! functions do too much, and what the peer comparison (`bench/compare`) times from Python.

use super::{
    err, finite_positive, put_frds, readonly_contiguous, ro1, samples, ss_model, to_py, Kind,
    PyModel,
};
use ambid::analysis::FrfSettings;
use ambid_core::estimate::pem::Focus;
use ambid_core::estimate::ss_pem::{refine_ss, SsPemOptions};
use ambid_core::estimate::subspace::{n4sid_detailed, SubspaceOptions};
use ambid_core::frf::closed_loop::{from_periodic, Channels};
use ambid_core::frf::periodic::{PeriodicAnalyzer, PeriodicOptions};
use ambid_core::frf::welch::{welch_spectra, Scaling, SegmentDetrend, WelchOptions};
use ambid_core::frf::window::Window;
use ambid_core::lti::StateSpace;
use faer::{Mat, MatRef};
use num_complex::Complex64;
use numpy::ndarray::Array3;
use numpy::{IntoPyArray, PyArrayMethods, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

/// A float64 array of one channel (1-D, `N`) or of several (2-D C-contiguous, `N × m`, one
/// column per channel), borrowed without a copy.
pub(crate) struct Columns<'py> {
    ro: numpy::PyReadonlyArrayDyn<'py, f64>,
    rows: usize,
    cols: usize,
}

impl<'py> Columns<'py> {
    pub(crate) fn of(name: &str, obj: &Bound<'py, PyAny>) -> PyResult<Self> {
        if let Ok(a) = obj.cast::<numpy::PyArrayDyn<f64>>() {
            if a.ndim() == 2 {
                let (rows, cols) = (a.shape()[0], a.shape()[1]);
                let ro = readonly_contiguous(name, a)?;
                return Ok(Self { ro, rows, cols });
            }
        }
        // everything else goes through the 1-D rules (and their messages)
        let ro = ro1(name, obj)?;
        let rows = ro.len();
        Ok(Self { ro, rows, cols: 1 })
    }

    /// The data as an `N × m` matrix view (row-major storage, no copy).
    pub(crate) fn mat(&self, name: &str) -> PyResult<MatRef<'_, f64>> {
        let s = samples(name, &self.ro)?;
        Ok(MatRef::from_row_major_slice(s, self.rows, self.cols))
    }
}

/// Welch auto and cross spectral densities of several channels (`welch_spectra`, as
/// `ambid frf --method welch` uses them), with scipy's conventions: periodic window, one-sided,
/// mean of the segments. Without `nperseg` the segment comes from the record length by the rule
/// of `ambid frf` (the largest power of two ≤ N/8, clamped to 64 … 8192 samples).
///
/// # Example
///
/// ```python
/// >>> import numpy as np, ambid
/// >>> x = np.random.default_rng(0).standard_normal(8192)
/// >>> s = ambid.spectra([x, 2.0 * x], 1000.0, nperseg=1024)
/// >>> s["csd"].shape, round(float(s["coherence"][0, 1].min()), 9)
/// ((2, 2, 513), 1.0)
///
/// ```
#[pyfunction]
#[pyo3(signature = (channels, fs, *, nperseg=None, noverlap=None, window="hann", detrend="constant", scaling="density"))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn spectra<'py>(
    py: Python<'py>,
    channels: &Bound<'py, PyList>,
    fs: f64,
    nperseg: Option<usize>,
    noverlap: Option<usize>,
    window: &str,
    detrend: &str,
    scaling: &str,
) -> PyResult<Bound<'py, PyDict>> {
    let fs = finite_positive("fs", fs)?;
    let usage = |m: String| err(Kind::Usage, m);
    let arrays = channels
        .iter()
        .enumerate()
        .map(|(k, c)| ro1(&format!("channels[{k}]"), &c))
        .collect::<PyResult<Vec<_>>>()?;
    let slices = arrays
        .iter()
        .enumerate()
        .map(|(k, a)| samples(&format!("channels[{k}]"), a))
        .collect::<PyResult<Vec<_>>>()?;
    // the segment from the record when not given: the one rule of `ambid frf` (n/8 rounded
    // down to a power of two, 64 … 8192 samples)
    let Some(n) = slices.first().map(|c| c.len()) else {
        return Err(err(
            Kind::Input,
            "`channels` is empty: give at least one channel (a 1-D float64 array)",
        ));
    };
    let nperseg = nperseg.unwrap_or_else(|| FrfSettings::default_nperseg(n));
    let mut opts = WelchOptions::new(fs, nperseg);
    if let Some(o) = noverlap {
        opts.noverlap = o;
    }
    opts.window = window
        .parse::<Window>()
        .map_err(|e| usage(format!("`window`: {e}")))?;
    opts.detrend = match detrend {
        "none" => SegmentDetrend::None,
        "constant" => SegmentDetrend::Constant,
        "linear" => SegmentDetrend::Linear,
        d => {
            return Err(usage(format!(
                "`detrend` must be none, constant or linear, got `{d}`"
            )))
        }
    };
    opts.scaling = match scaling {
        "density" => Scaling::Density,
        "spectrum" => Scaling::Spectrum,
        s => {
            return Err(usage(format!(
                "`scaling` must be density or spectrum, got `{s}`"
            )))
        }
    };
    let nc = slices.len();
    let (s, coh) = py
        .detach(|| -> ambid_core::Result<_> {
            let s = welch_spectra(&slices, &opts)?;
            // each pair i < j once, in the order the fill below reads them
            let coh = (0..nc)
                .flat_map(|i| (i + 1..nc).map(move |j| (i, j)))
                .map(|(i, j)| s.coherence(i, j))
                .collect::<ambid_core::Result<Vec<_>>>()?;
            Ok((s, coh))
        })
        .map_err(to_py)?;
    let l = s.f_hz().len();
    let mut csd = Array3::<Complex64>::zeros((nc, nc, l));
    let mut cohm = Array3::<f64>::ones((nc, nc, l));
    let mut pairs = coh.iter();
    for i in 0..nc {
        for j in i..nc {
            let v = s.get(i, j).map_err(to_py)?;
            for (k, z) in v.iter().enumerate() {
                csd[[i, j, k]] = *z;
                csd[[j, i, k]] = z.conj();
            }
            if i == j {
                continue;
            }
            if let Some(c) = pairs.next() {
                for (k, v) in c.iter().enumerate() {
                    cohm[[i, j, k]] = *v;
                    cohm[[j, i, k]] = *v;
                }
            }
        }
    }
    let d = PyDict::new(py);
    d.set_item("f_hz", s.f_hz().to_vec().into_pyarray(py))?;
    d.set_item("csd", csd.into_pyarray(py))?;
    d.set_item("coherence", cohm.into_pyarray(py))?;
    d.set_item("segments", s.n_segments())?;
    Ok(d)
}

/// Subspace identification (`n4sid_detailed`: CVA weighting, horizon ladder unless
/// `block_rows` is given, order from the singular values unless given) of `u → y`, one column
/// per channel (1-D for one channel, `N × m` for several), optionally refined by state-space
/// PEM (`refine` = `"simulation"` or `"prediction"`). Returns `{"model", "block_rows",
/// "order", "singular_values"}`.
///
/// # Example
///
/// ```python
/// >>> import numpy as np, ambid
/// >>> rng = np.random.default_rng(1)
/// >>> u = rng.standard_normal(2000)
/// >>> y = np.zeros(2000)
/// >>> for k in range(1, 2000):
/// ...     y[k] = 0.9 * y[k - 1] + u[k - 1]
/// >>> out = ambid.n4sid(u, y, 1.0, order=1)
/// >>> out["order"], round(float(out["model"].poles()[0].real), 6)
/// (1, 0.9)
///
/// ```
#[pyfunction]
#[pyo3(signature = (u, y, ts, *, order=None, max_order=10, block_rows=None, feedthrough=false, refine=None))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn n4sid<'py>(
    py: Python<'py>,
    u: &Bound<'py, PyAny>,
    y: &Bound<'py, PyAny>,
    ts: f64,
    order: Option<usize>,
    max_order: usize,
    block_rows: Option<usize>,
    feedthrough: bool,
    refine: Option<&str>,
) -> PyResult<Bound<'py, PyDict>> {
    let (u, y) = (Columns::of("u", u)?, Columns::of("y", y)?);
    let (um, ym) = (u.mat("u")?, y.mat("y")?);
    let mut so = SubspaceOptions::new(finite_positive("ts", ts)?);
    so.order = order;
    so.max_order = max_order;
    so.block_rows = block_rows;
    so.feedthrough = feedthrough;
    let focus = match refine {
        None => None,
        Some("simulation") => Some(Focus::Simulation),
        Some("prediction") => Some(Focus::Prediction),
        Some(r) => {
            return Err(err(
                Kind::Usage,
                format!("`refine` must be None, \"simulation\" or \"prediction\", got `{r}`"),
            ))
        }
    };
    let (sub, model, n_samples) = py
        .detach(|| -> ambid_core::Result<_> {
            let sub = n4sid_detailed(ym, um, &so)?;
            let fitted = match focus {
                None => sub.fitted.clone(),
                Some(focus) => {
                    let p = SsPemOptions {
                        focus,
                        ..SsPemOptions::default()
                    };
                    let k = sub.kalman_gain.as_ref().map(|k| k.as_ref());
                    refine_ss(ym, um, &sub.fitted.model, k, &p)?.fitted
                }
            };
            Ok((sub, fitted.model, fitted.n_samples))
        })
        .map_err(to_py)?;
    let d = PyDict::new(py);
    let m = PyModel {
        n_samples,
        ..ss_model(model, "ss")
    };
    d.set_item("model", Py::new(py, m)?)?;
    d.set_item("block_rows", sub.block_rows)?;
    d.set_item("order", sub.order)?;
    d.set_item(
        "singular_values",
        sub.singular_values.clone().into_pyarray(py),
    )?;
    Ok(d)
}

/// A float64 matrix argument (any layout; copied, they are small).
fn mat_arg(name: &str, obj: &Bound<'_, PyAny>) -> PyResult<Mat<f64>> {
    let a = obj.cast::<numpy::PyArray2<f64>>().map_err(|_| {
        err(
            Kind::Input,
            format!("`{name}` must be a 2-D float64 numpy array; convert it with np.atleast_2d(np.asarray({name}, dtype=float))"),
        )
    })?;
    let ro = a.readonly();
    let v = ro.as_array();
    Ok(Mat::from_fn(v.nrows(), v.ncols(), |i, j| v[[i, j]]))
}

/// A discrete state-space `Model` x⁺ = A x + B u, y = C x + D u with sample time `ts` (shapes
/// n×n, n×m, p×n, p×m); stable or not, as given.
///
/// # Example
///
/// ```python
/// >>> import numpy as np, ambid
/// >>> m = ambid.ss(np.array([[1.1]]), np.array([[1.0]]), np.array([[1.0]]), np.array([[0.0]]), 1e-3)
/// >>> m.order, bool(abs(m.poles()[0]) > 1.0)
/// (1, True)
///
/// ```
#[pyfunction]
pub(crate) fn ss(
    a: &Bound<'_, PyAny>,
    b: &Bound<'_, PyAny>,
    c: &Bound<'_, PyAny>,
    d: &Bound<'_, PyAny>,
    ts: f64,
) -> PyResult<PyModel> {
    let ts = finite_positive("ts", ts)?;
    let m = StateSpace::discrete(
        mat_arg("a", a)?,
        mat_arg("b", b)?,
        mat_arg("c", c)?,
        mat_arg("d", d)?,
        ts,
    )
    // the matrices are the caller's: a shape or finiteness problem is an input error
    .map_err(|e| err(Kind::Input, e.to_string()))?;
    Ok(ss_model(m, "ss"))
}

/// The period-averaged closed-loop FRFs alone (`PeriodicAnalyzer` + `from_periodic`, the core
/// of `ambid.frf` without its band detection, quality figures and screening): T_ry, S, the
/// plant T_ry/S and the controller (r − u)/y with standard deviations from the spread over
/// periods, and the coherences, on the lines where r has power (amplitude above `threshold`
/// times the largest non-DC line).
///
/// # Example
///
/// ```python
/// >>> import numpy as np, ambid
/// >>> rec = ambid.simulate(seed=1, mode="linear")
/// >>> out = ambid.periodic_frf(rec["r"], rec["u"], rec["y"], rec["fs"], period_samples=5115)
/// >>> p = ambid.truth(out["f_hz"])["plant"]
/// >>> bool(np.median(np.abs(out["plant"] - p) / out["plant_std"]) < 2.0)
/// True
///
/// ```
#[pyfunction]
#[pyo3(signature = (r, u, y, fs, *, period_samples, skip_periods=1, threshold=1e-6))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn periodic_frf<'py>(
    py: Python<'py>,
    r: &Bound<'py, PyAny>,
    u: &Bound<'py, PyAny>,
    y: &Bound<'py, PyAny>,
    fs: f64,
    period_samples: usize,
    skip_periods: usize,
    threshold: f64,
) -> PyResult<Bound<'py, PyDict>> {
    let (r, u, y) = (ro1("r", r)?, ro1("u", u)?, ro1("y", y)?);
    let (r, u, y) = (samples("r", &r)?, samples("u", &u)?, samples("y", &y)?);
    let fs = finite_positive("fs", fs)?;
    let frf = py
        .detach(|| -> ambid_core::Result<_> {
            let mut an = PeriodicAnalyzer::new(period_samples)?;
            let opts = PeriodicOptions::new(period_samples).skip(skip_periods);
            let s = an.analyze(&[r, u, y], fs, &opts)?;
            let lines = s.excited_lines(0, threshold)?;
            from_periodic(&s, Channels { r: 0, u: 1, y: 2 }, &lines, None)
        })
        .map_err(to_py)?;
    let d = PyDict::new(py);
    d.set_item("f_hz", frf.f_hz().to_vec().into_pyarray(py))?;
    put_frds(
        &d,
        &[
            ("t_ry", &frf.t_ry),
            ("s", &frf.t_ru),
            ("plant", &frf.plant),
            ("controller", &frf.controller),
        ],
    )?;
    d.set_item("coh_ry", frf.coh_ry.clone().into_pyarray(py))?;
    d.set_item("coh_ru", frf.coh_ru.clone().into_pyarray(py))?;
    d.set_item("dof", frf.dof)?;
    Ok(d)
}
