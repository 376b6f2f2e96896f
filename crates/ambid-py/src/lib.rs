//! # ambid-py
//!
//! The native part of the Python package `ambid` (module `ambid._native`, built by maturin as
//! one abi3 wheel). It is a thin layer: every function converts numpy arrays to slices, calls
//! the same library function the command line calls (so the numbers are the CLI's, bit for
//! bit), releases the GIL while it computes, and converts the result back to numpy arrays.
//! The Python-facing API, its docstrings and stubs live in `python/ambid/` (docs/python.md).
//!
//! Input rules (every array argument): a 1-D, C-contiguous `float64` numpy array; anything else
//! (another dtype, 2-D, a strided view, a list) raises `ambid.InputError` naming the argument
//! and the fix (`np.ascontiguousarray(x, dtype=float)`). NaN and length mismatches are the
//! library's typed errors, raised as the exception of their class:
//!
//! | library error class | Python exception |
//! |---|---|
//! | configuration / usage (exit 2) | `ambid.UsageError` (also a `ValueError`) |
//! | input data (exit 3) | `ambid.InputError` (also a `ValueError`) |
//! | computation (exit 4) | `ambid.ComputationError` (also a `RuntimeError`) |
//! | output (exit 5) | `ambid.OutputError` (also an `OSError`) |
//! | anything else | `ambid.AmbidError` |

use ambid::analysis::{analyze, FrfSettings, Record};
use ambid::error::{Error as AppError, FailureClass};
use ambid_core::estimate::pem::{pem, Orders, PemOptions};
use ambid_core::lti::{Frd, PolyModel, StateSpace, Structure};
use num_complex::Complex64;
use numpy::ndarray::{Array2, Array3};
use numpy::{IntoPyArray, PyArray1, PyArray2, PyArray3, PyArrayMethods, PyUntypedArrayMethods};
use pyo3::create_exception;
use pyo3::exceptions::PyException;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::PathBuf;

/// The extension's allocator for everything Rust allocates (arrays handed to numpy are freed
/// by it too): glibc's malloc in a Python process gives the analyses' large buffers back to the
/// system after every call and page-faults them in again on the next, which cost 1.4–1.6× on a
/// 4 ms FRF; mimalloc keeps them (docs/benchmarks.md, "The Python package").
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

mod lowlevel;
mod machine;
mod studies;

create_exception!(
    _native,
    AmbidError,
    PyException,
    "Base of every ambid error."
);

/// The four error classes below `AmbidError`; each is also the built-in exception a Python user
/// would catch for it (`ValueError`, `ValueError`, `RuntimeError`, `OSError`).
#[derive(Clone, Copy)]
enum Kind {
    Usage,
    Input,
    Computation,
    Output,
}

const KINDS: [(&str, &str, &str); 4] = [
    (
        "UsageError",
        "ValueError",
        "A setting or option is wrong (the CLI's exit code 2).",
    ),
    (
        "InputError",
        "ValueError",
        "The input data are wrong: type, shape, NaN, length, file (the CLI's exit code 3).",
    ),
    (
        "ComputationError",
        "RuntimeError",
        "A computation failed on valid input, e.g. an unstable or rank-deficient fit (exit code 4).",
    ),
    (
        "OutputError",
        "OSError",
        "An output could not be written (the CLI's exit code 5).",
    ),
];

/// The classes of [`KINDS`], made once at import: `type(name, (AmbidError, builtin), {...})`.
static TYPES: pyo3::sync::PyOnceLock<Vec<Py<pyo3::types::PyType>>> = pyo3::sync::PyOnceLock::new();

fn make_types(py: Python<'_>) -> PyResult<Vec<Py<pyo3::types::PyType>>> {
    let builtins = py.import("builtins")?;
    let ty = builtins.getattr("type")?;
    KINDS
        .iter()
        .map(|(name, base, doc)| {
            let d = PyDict::new(py);
            d.set_item("__doc__", *doc)?;
            d.set_item("__module__", "ambid")?;
            let bases = (py.get_type::<AmbidError>(), builtins.getattr(*base)?);
            Ok(ty
                .call1((*name, bases, d))?
                .cast_into::<pyo3::types::PyType>()?
                .unbind())
        })
        .collect()
}

/// The exception of `kind` with `msg`.
fn err(kind: Kind, msg: impl Into<String>) -> PyErr {
    let msg = msg.into();
    Python::attach(|py| match TYPES.get(py) {
        Some(t) => PyErr::from_type(t[kind as usize].bind(py).clone(), msg),
        None => AmbidError::new_err(msg),
    })
}

/// The Python exception of a library error: its class decides the type, the message is the
/// library's (the CLI prints the same text).
fn to_py(e: impl Into<AppError>) -> PyErr {
    let e: AppError = e.into();
    let msg = ambid::workflow::chain_message(&e);
    match e.class() {
        Some(FailureClass::Config) => err(Kind::Usage, msg),
        Some(FailureClass::Input) => err(Kind::Input, msg),
        Some(FailureClass::Computation) => err(Kind::Computation, msg),
        Some(FailureClass::Output) => err(Kind::Output, msg),
        None => AmbidError::new_err(msg),
    }
}

/// A 1-D, C-contiguous float64 array borrowed read-only (no copy), or `InputError` naming
/// `name`. The data are read while the GIL is released: another Python thread must not write
/// to the array during the call (as with any numpy function that releases the GIL).
fn ro1<'py>(name: &str, obj: &Bound<'py, PyAny>) -> PyResult<numpy::PyReadonlyArrayDyn<'py, f64>> {
    let Ok(arr) = obj.cast::<numpy::PyArrayDyn<f64>>() else {
        let what = match obj.cast::<numpy::PyUntypedArray>() {
            Ok(a) => format!("a numpy array of dtype {}", a.dtype()),
            Err(_) => format!("a {}", obj.get_type().name()?),
        };
        return Err(err(Kind::Input, format!(
            "`{name}` must be a 1-D float64 numpy array, got {what}; convert it with np.ascontiguousarray({name}, dtype=float)"
        )));
    };
    if arr.ndim() != 1 {
        return Err(err(Kind::Input, format!(
            "`{name}` must be 1-D, got an array of shape {:?}; pass one channel (e.g. {name}[:, k]) as np.ascontiguousarray",
            arr.shape()
        )));
    }
    readonly_contiguous(name, arr)
}

/// `arr` borrowed read-only, or `InputError` when it is borrowed mutably elsewhere or not
/// C-contiguous (the rule of every array argument, 1-D or 2-D).
fn readonly_contiguous<'py>(
    name: &str,
    arr: &Bound<'py, numpy::PyArrayDyn<f64>>,
) -> PyResult<numpy::PyReadonlyArrayDyn<'py, f64>> {
    let ro = arr.try_readonly().map_err(|e| {
        err(
            Kind::Input,
            format!("`{name}` cannot be borrowed for reading ({e})"),
        )
    })?;
    if !ro.is_c_contiguous() {
        return Err(err(
            Kind::Input,
            format!(
                "`{name}` is not C-contiguous (a strided view); pass np.ascontiguousarray({name})"
            ),
        ));
    }
    Ok(ro)
}

/// The samples of an array [`ro1`] accepted.
fn samples<'a>(name: &str, a: &'a numpy::PyReadonlyArrayDyn<'_, f64>) -> PyResult<&'a [f64]> {
    a.as_slice().map_err(|_| {
        err(
            Kind::Input,
            format!(
                "`{name}` is not C-contiguous (a strided view); pass np.ascontiguousarray({name})"
            ),
        )
    })
}

/// A 1-D, C-contiguous float64 array as an owned vector (small arguments: frequencies).
fn vec1(name: &str, obj: &Bound<'_, PyAny>) -> PyResult<Vec<f64>> {
    let ro = ro1(name, obj)?;
    Ok(samples(name, &ro)?.to_vec())
}

fn finite_positive(name: &str, v: f64) -> PyResult<f64> {
    if v.is_finite() && v > 0.0 {
        Ok(v)
    } else {
        Err(err(
            Kind::Usage,
            format!("`{name}` must be a finite positive number, got {v}"),
        ))
    }
}

fn band_of(name: &str, b: Option<(f64, f64)>) -> PyResult<Option<(f64, f64)>> {
    match b {
        Some((lo, hi)) if !(lo.is_finite() && hi.is_finite() && 0.0 <= lo && lo < hi) => Err(err(
            Kind::Usage,
            format!(
                "`{name}` must be (f_min, f_max) in Hz with 0 <= f_min < f_max, got ({lo}, {hi})"
            ),
        )),
        b => Ok(b),
    }
}

fn complex_array<'py>(py: Python<'py>, v: &[Complex64]) -> Bound<'py, PyArray1<Complex64>> {
    v.to_vec().into_pyarray(py)
}

/// Each FRF's values as `key` (complex) and, when it has variances, its standard deviations as
/// `key_std`.
fn put_frds(d: &Bound<'_, PyDict>, frds: &[(&str, &Frd)]) -> PyResult<()> {
    let py = d.py();
    for (key, frd) in frds {
        d.set_item(*key, complex_array(py, frd.values()))?;
        if let Some(v) = frd.variance() {
            let s: Vec<f64> = v.iter().map(|x| x.sqrt()).collect();
            d.set_item(format!("{key}_std"), s.into_pyarray(py))?;
        }
    }
    Ok(())
}

/// Nonparametric closed-loop FRFs of one axis (the computation of `ambid frf`).
///
/// # Example
///
/// ```python
/// >>> import numpy as np, ambid
/// >>> rec = ambid.simulate(seed=1, mode="linear")
/// >>> f = ambid.frf(rec["r"], rec["u"], rec["y"], rec["fs"], period_samples=rec["period_samples"])
/// >>> p = ambid.truth(f["f_hz"])["plant"]
/// >>> band = (f["f_hz"] > 10) & (f["f_hz"] < 1000)
/// >>> bool(np.median(np.abs(f["plant"] - p)[band] / np.abs(p[band])) < 0.05)
/// True
///
/// ```
#[pyfunction]
#[pyo3(signature = (r, u, y, fs, *, period_samples=None, skip_periods=1, nperseg=None, band=None, quality_band=None, i_sat=None, screen=true, noise=None, current=None))]
#[allow(clippy::too_many_arguments)]
fn frf<'py>(
    py: Python<'py>,
    r: &Bound<'py, PyAny>,
    u: &Bound<'py, PyAny>,
    y: &Bound<'py, PyAny>,
    fs: f64,
    period_samples: Option<usize>,
    skip_periods: usize,
    nperseg: Option<usize>,
    band: Option<(f64, f64)>,
    quality_band: Option<(f64, f64)>,
    i_sat: Option<f64>,
    screen: bool,
    noise: Option<&Bound<'py, PyAny>>,
    current: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyDict>> {
    let (r, u, y) = (ro1("r", r)?, ro1("u", u)?, ro1("y", y)?);
    let noise = noise.map(|n| ro1("noise", n)).transpose()?;
    let current = current.map(|c| ro1("current", c)).transpose()?;
    let (r, u, y) = (samples("r", &r)?, samples("u", &u)?, samples("y", &y)?);
    let noise = noise.as_ref().map(|n| samples("noise", n)).transpose()?;
    let current = current
        .as_ref()
        .map(|c| samples("current", c))
        .transpose()?;
    let fs = finite_positive("fs", fs)?;
    let mut settings = match (period_samples, nperseg) {
        (Some(_), Some(_)) => {
            return Err(err(
                Kind::Usage,
                "give period_samples (period averaging) or nperseg (Welch), not both",
            ))
        }
        (Some(p), None) => FrfSettings::periodic(p, skip_periods),
        (None, Some(n)) => FrfSettings::welch(n),
        // the period of `r` when it repeats (as `ambid frf` finds it), else Welch
        (None, None) => {
            FrfSettings::found_period(r.len(), ambid_core::signal::PeriodScan::of(r), skip_periods)
                .unwrap_or_else(|| FrfSettings::welch(FrfSettings::default_nperseg(r.len())))
        }
    };
    settings.band = band_of("band", band)?;
    settings.quality_band = band_of("quality_band", quality_band)?;
    settings.i_sat = i_sat.map(|v| finite_positive("i_sat", v)).transpose()?;
    settings.screen = screen;
    let used_period = match settings.method {
        ambid::analysis::FrfMethod::Periodic { period_samples, .. } => Some(period_samples),
        ambid::analysis::FrfMethod::Welch { .. } => None,
    };
    let out = py
        .detach(|| {
            let rec = Record {
                r,
                u,
                y,
                i: current,
                fs,
            };
            analyze(&rec, &settings, noise)
        })
        .map_err(to_py)?;
    let d = PyDict::new(py);
    let fr = &out.frf;
    d.set_item("f_hz", fr.f_hz().to_vec().into_pyarray(py))?;
    put_frds(
        &d,
        &[
            ("plant", &fr.plant),
            ("t_ry", &fr.t_ry),
            ("s", &fr.t_ru),
            ("controller", &fr.controller),
        ],
    )?;
    if let Some(p) = &fr.plant_indirect {
        d.set_item("plant_indirect", complex_array(py, p.values()))?;
    }
    d.set_item("coh_ry", fr.coh_ry.clone().into_pyarray(py))?;
    d.set_item("coh_ru", fr.coh_ru.clone().into_pyarray(py))?;
    d.set_item("dof", fr.dof)?;
    let q = PyDict::new(py);
    let qu = &out.quality;
    q.set_item("band_hz", qu.band)?;
    q.set_item("lines", qu.lines)?;
    q.set_item("mean_coherence_ry", qu.mean_coherence_ry)?;
    q.set_item("mean_coherence_ru", qu.mean_coherence_ru)?;
    q.set_item("mean_plant_variance", qu.mean_plant_variance)?;
    q.set_item("mean_plant_rel_variance", qu.mean_plant_rel_variance)?;
    q.set_item("output_snr_db", qu.output_snr_db)?;
    d.set_item("quality", q)?;
    d.set_item("band_hz", out.bands.band)?;
    d.set_item("quality_band_hz", out.bands.quality_band)?;
    d.set_item("period_samples", used_period)?;
    d.set_item("warnings", out.warnings.clone())?;
    Ok(d)
}

/// Closed-loop FRFs of one record by a local method (the computation of `ambid frf --method
/// lpm|lrm`): the Local Polynomial Method (window chosen from the record by leave-one-out
/// cross-validation unless `degree` or `half_width` is given; periodic records detected from
/// the line pattern) or the Local Rational Method (`lrm_degrees` = (Rn, Rd, Rm)).
///
/// # Example
///
/// ```python
/// >>> import numpy as np, ambid
/// >>> rec = ambid.simulate(seed=2, mode="linear", periods=4)
/// >>> out = ambid.frf_local(rec["r"], rec["u"], rec["y"], rec["fs"], method="lpm", band=(20.0, 500.0))
/// >>> p = ambid.truth(out["f_hz"])["plant"]
/// >>> bool(np.median(np.abs(out["plant"] - p) / out["plant_std"]) < 3.0)
/// True
///
/// ```
#[pyfunction]
#[pyo3(signature = (r, u, y, fs, *, method="lpm", band=None, degree=None, half_width=None, lrm_degrees=(2, 2, 2)))]
#[allow(clippy::too_many_arguments)]
fn frf_local<'py>(
    py: Python<'py>,
    r: &Bound<'py, PyAny>,
    u: &Bound<'py, PyAny>,
    y: &Bound<'py, PyAny>,
    fs: f64,
    method: &str,
    band: Option<(f64, f64)>,
    degree: Option<usize>,
    half_width: Option<usize>,
    lrm_degrees: (usize, usize, usize),
) -> PyResult<Bound<'py, PyDict>> {
    use ambid_core::frf::lpm::{lpm_closed_loop, LpmOptions};
    use ambid_core::frf::lrm::{lrm_closed_loop, LrmOptions};
    let (r, u, y) = (ro1("r", r)?, ro1("u", u)?, ro1("y", y)?);
    let (r, u, y) = (samples("r", &r)?, samples("u", &u)?, samples("y", &y)?);
    let fs = finite_positive("fs", fs)?;
    let band = band_of("band", band)?.unwrap_or((1.0, 0.5 * fs));
    let (t_ry, t_ru, plant, dof) = match method {
        "lpm" => {
            let opts = match (degree, half_width) {
                (None, None) => LpmOptions::auto(),
                (deg, half) => {
                    let o = LpmOptions::default()
                        .with_degree(deg.unwrap_or(2))
                        .map_err(to_py)?;
                    match half {
                        Some(n) => o.with_half_width(n).map_err(to_py)?,
                        None => o,
                    }
                }
            };
            let c = py
                .detach(|| lpm_closed_loop(r, u, y, fs, band, &opts))
                .map_err(to_py)?;
            let dof = c.dof();
            (c.t_ry, c.t_ru, c.plant, dof)
        }
        "lrm" => {
            let (rn, rd, rm) = lrm_degrees;
            let mut opts = LrmOptions::default()
                .with_degrees(rn, rd, rm)
                .map_err(to_py)?;
            if let Some(n) = half_width {
                opts = opts.with_half_width(n).map_err(to_py)?;
            }
            let c = py
                .detach(|| lrm_closed_loop(r, u, y, fs, band, &opts))
                .map_err(to_py)?;
            let dof = c.dof();
            (c.t_ry, c.t_ru, c.plant, dof)
        }
        other => {
            return Err(err(
                Kind::Usage,
                format!("unknown method `{other}`: use \"lpm\" or \"lrm\" (frf() for period averaging and Welch)"),
            ))
        }
    };
    let d = PyDict::new(py);
    d.set_item("f_hz", plant.f_hz().to_vec().into_pyarray(py))?;
    put_frds(&d, &[("plant", &plant), ("t_ry", &t_ry), ("s", &t_ru)])?;
    d.set_item("dof", dof)?;
    Ok(d)
}

/// The ARX order scan of `u → y` (the computation of `ambid order`): every ARX(na, nb, nk) with
/// 1 ≤ na ≤ `na_max`, 1 ≤ nb ≤ `nb_max`, nk in `nk`, from one least-squares factorisation; loss,
/// AIC, BIC, FPE and (with `validation = (u_val, y_val)`) the validation loss and 1-step fit per
/// model, and the indices of the best models by each criterion. The data are used as given
/// (`ambid order` removes the estimation data's means first).
///
/// # Example
///
/// ```python
/// >>> import numpy as np, ambid
/// >>> rng = np.random.default_rng(0)
/// >>> u = rng.standard_normal(3000)
/// >>> y = np.zeros(3000)
/// >>> for k in range(2, 3000):
/// ...     y[k] = 1.2 * y[k - 1] - 0.5 * y[k - 2] + u[k - 1] + 0.01 * rng.standard_normal()
/// >>> s = ambid.order_scan(u, y, na_max=4, nb_max=3)
/// >>> int(s["na"][s["best_bic"]]), int(s["nb"][s["best_bic"]])
/// (2, 1)
///
/// ```
#[pyfunction]
#[pyo3(signature = (u, y, *, na_max=10, nb_max=10, nk=vec![1], validation=None))]
fn order_scan<'py>(
    py: Python<'py>,
    u: &Bound<'py, PyAny>,
    y: &Bound<'py, PyAny>,
    na_max: usize,
    nb_max: usize,
    nk: Vec<usize>,
    validation: Option<(Bound<'py, PyAny>, Bound<'py, PyAny>)>,
) -> PyResult<Bound<'py, PyDict>> {
    use ambid_core::estimate::order::{arx_order_scan, ArxScanSpec};
    let (u, y) = (ro1("u", u)?, ro1("y", y)?);
    let (u, y) = (samples("u", &u)?, samples("y", &y)?);
    let val = match &validation {
        Some((uv, yv)) => Some((ro1("validation[0] (u)", uv)?, ro1("validation[1] (y)", yv)?)),
        None => None,
    };
    let val = match &val {
        Some((uv, yv)) => Some((samples("validation u", uv)?, samples("validation y", yv)?)),
        None => None,
    };
    if na_max == 0 || nb_max == 0 || nk.is_empty() {
        return Err(err(
            Kind::Usage,
            "na_max and nb_max must be at least 1 and nk must name at least one delay",
        ));
    }
    let spec = ArxScanSpec::new(1..=na_max, 1..=nb_max, nk);
    let scan = py
        .detach(|| arx_order_scan(y, u, &spec, val.map(|(uv, yv)| (yv, uv))))
        .map_err(to_py)?;
    let d = PyDict::new(py);
    let col = |f: &dyn Fn(&ambid_core::estimate::order::OrderRow) -> f64| -> Vec<f64> {
        scan.rows.iter().map(f).collect()
    };
    let icol = |f: &dyn Fn(&ambid_core::estimate::order::OrderRow) -> usize| -> Vec<usize> {
        scan.rows.iter().map(f).collect()
    };
    d.set_item("na", icol(&|r| r.na).into_pyarray(py))?;
    d.set_item("nb", icol(&|r| r.nb).into_pyarray(py))?;
    d.set_item("nk", icol(&|r| r.nk).into_pyarray(py))?;
    d.set_item("n_params", icol(&|r| r.n_params).into_pyarray(py))?;
    d.set_item("loss", col(&|r| r.loss).into_pyarray(py))?;
    d.set_item("aic", col(&|r| r.aic).into_pyarray(py))?;
    d.set_item("bic", col(&|r| r.bic).into_pyarray(py))?;
    d.set_item("fpe", col(&|r| r.fpe).into_pyarray(py))?;
    d.set_item(
        "val_loss",
        col(&|r| r.val_loss.unwrap_or(f64::NAN)).into_pyarray(py),
    )?;
    d.set_item(
        "val_fit",
        col(&|r| r.val_fit.unwrap_or(f64::NAN)).into_pyarray(py),
    )?;
    let params: Vec<_> = scan
        .rows
        .iter()
        .map(|r| r.params.clone().into_pyarray(py))
        .collect();
    d.set_item("params", params)?;
    d.set_item("best_aic", scan.best_aic)?;
    d.set_item("best_bic", scan.best_bic)?;
    d.set_item("best_val", scan.best_val)?;
    d.set_item("parsimonious", scan.parsimonious)?;
    d.set_item("knee", scan.knee)?;
    d.set_item("n_samples", scan.n_samples)?;
    d.set_item("k0", scan.k0)?;
    Ok(d)
}

/// A state-space model as a [`PyModel`] (no parameters of its own: the twin's exact plant or a
/// controller).
fn ss_model(ss: StateSpace, structure: &str) -> PyModel {
    PyModel {
        ss,
        poly: None,
        structure: structure.into(),
        params: Vec::new(),
        std: None,
        loss: f64::NAN,
        noise_variance: f64::NAN,
        n_samples: 0,
    }
}

/// The nominal rig's configuration, or random test rig `rig_seed`'s.
fn rig_of(rig_seed: Option<u64>) -> PyResult<ambid_twin::TwinConfig> {
    match rig_seed {
        Some(s) => ambid_twin::random_rig(s).map_err(to_py),
        None => Ok(ambid_twin::TwinConfig::default()),
    }
}

fn twin_of(rig_seed: Option<u64>) -> PyResult<ambid_twin::Twin> {
    ambid_twin::Twin::new(rig_of(rig_seed)?).map_err(to_py)
}

/// The twin's exact linearised plant u → y (discrete, at the twin's sample rate; unstable) as a
/// `Model`, nominal rig or random test rig `rig_seed`.
///
/// # Example
///
/// ```python
/// >>> import numpy as np, ambid
/// >>> p = ambid.twin_plant()
/// >>> int(np.sum(np.abs(p.poles()) > 1.0))  # the magnet's negative stiffness: one unstable pole
/// 1
///
/// ```
#[pyfunction]
#[pyo3(signature = (*, rig_seed=None))]
fn twin_plant(rig_seed: Option<u64>) -> PyResult<PyModel> {
    Ok(ss_model(twin_of(rig_seed)?.plant().clone(), "ss"))
}

/// A controller as a `Model` (its state space, u = −C y + r): from a controller file (TOML PID,
/// transfer function or state space, docs/formats.md) or, without a path, the twin's
/// (`rig_seed` for a random test rig).
///
/// # Example
///
/// ```python
/// >>> import ambid
/// >>> c = ambid.controller()
/// >>> c.b.shape[1], c.c.shape[0]
/// (1, 1)
///
/// ```
#[pyfunction]
#[pyo3(signature = (path=None, *, rig_seed=None))]
fn controller(path: Option<PathBuf>, rig_seed: Option<u64>) -> PyResult<PyModel> {
    match path {
        Some(p) => {
            let c = ambid::io::read_controller(&p).map_err(to_py)?;
            Ok(ss_model(c.state_space().clone(), "controller"))
        }
        None => Ok(ss_model(
            twin_of(rig_seed)?.controller().clone(),
            "controller",
        )),
    }
}

/// Closed-loop validation of a plant model with its controller on a record (the computation of
/// `ambid validate`): the loop simulated from r (and w) from the initial state that best
/// explains the record; fits of y and u, the output-error residual test (independence from the
/// excitation), the closed-loop poles' stability, margins and the model's ISO 14839-3 zone.
///
/// # Example
///
/// ```python
/// >>> import ambid
/// >>> rec = ambid.simulate(seed=1, mode="linear", noise=False, periods=4)
/// >>> v = ambid.validate(ambid.twin_plant(), ambid.controller(), rec["r"], rec["u"], rec["y"], rec["fs"])
/// >>> v["fit_y_pct"] > 99.9
/// True
///
/// ```
#[pyfunction]
#[pyo3(signature = (model, controller, r, u, y, fs, *, w=None, skip=0, lags=25, windows=20))]
#[allow(clippy::too_many_arguments)]
fn validate<'py>(
    py: Python<'py>,
    model: &PyModel,
    controller: &PyModel,
    r: &Bound<'py, PyAny>,
    u: &Bound<'py, PyAny>,
    y: &Bound<'py, PyAny>,
    fs: f64,
    w: Option<&Bound<'py, PyAny>>,
    skip: usize,
    lags: usize,
    windows: usize,
) -> PyResult<Bound<'py, PyDict>> {
    use ambid::validation::{validate_closed_loop, MeasuredLoop, ValidationSettings};
    let (r, u, y) = (ro1("r", r)?, ro1("u", u)?, ro1("y", y)?);
    let (r, u, y) = (samples("r", &r)?, samples("u", &u)?, samples("y", &y)?);
    let fs = finite_positive("fs", fs)?;
    let n = y.len();
    for (name, x) in [("r", r), ("u", u)] {
        if x.len() != n {
            return Err(err(
                Kind::Input,
                format!("`{name}` has {} samples but `y` has {n}; all channels must be recorded together", x.len()),
            ));
        }
    }
    let w_arr = w.map(|w| ro1("w", w)).transpose()?;
    let zeros = vec![0.0; n];
    let w = match &w_arr {
        Some(a) => samples("w", a)?,
        None => &zeros,
    };
    if w.len() != n {
        return Err(err(
            Kind::Input,
            format!("`w` has {} samples but `y` has {n}", w.len()),
        ));
    }
    let settings = ValidationSettings {
        skip,
        lags,
        windows,
        ..Default::default()
    };
    let rec = MeasuredLoop {
        w,
        r: Some(r),
        y,
        u,
        ts: 1.0 / fs,
    };
    let out = py
        .detach(|| validate_closed_loop(&model.ss, &controller.ss, &rec, &settings))
        .map_err(to_py)?;
    let d = PyDict::new(py);
    d.set_item("fit_y_pct", out.fit_y)?;
    d.set_item("fit_u_pct", out.fit_u)?;
    d.set_item("rmse_y", out.rmse_y)?;
    d.set_item("max_error_y", out.max_error_y)?;
    d.set_item("samples", out.samples)?;
    d.set_item(
        "y_simulated",
        out.reconstruction.simulated.y.clone().into_pyarray(py),
    )?;
    if let Some(t) = &out.residuals.independence {
        d.set_item("independence_pass", t.pass)?;
        d.set_item("independence_statistic", t.statistic)?;
        d.set_item("independence_threshold", t.threshold)?;
    }
    let poles: Vec<Complex64> = out.closed_loop.poles.iter().map(|p| p.z).collect();
    d.set_item("closed_loop_poles", poles.into_pyarray(py))?;
    d.set_item("peak_sensitivity", out.margins.peak_sensitivity.0)?;
    d.set_item("peak_sensitivity_hz", out.margins.peak_sensitivity.1)?;
    d.set_item("iso_zone", format!("{:?}", out.iso_model.zone))?;
    Ok(d)
}

/// A fitted linear model: state space (always), and the polynomials when it is one.
#[pyclass(frozen, module = "ambid._native", name = "Model")]
struct PyModel {
    ss: StateSpace,
    poly: Option<PolyModel>,
    structure: String,
    params: Vec<f64>,
    std: Option<Vec<f64>>,
    loss: f64,
    noise_variance: f64,
    n_samples: usize,
}

fn mat2<'py>(py: Python<'py>, m: faer::MatRef<'_, f64>) -> Bound<'py, PyArray2<f64>> {
    Array2::from_shape_fn((m.nrows(), m.ncols()), |(i, j)| m[(i, j)]).into_pyarray(py)
}

#[pymethods]
impl PyModel {
    /// The structure: `arx`, `fir`, `armax`, `oe`, `bj` or `ss`.
    #[getter]
    fn structure(&self) -> &str {
        &self.structure
    }
    /// Sample time in seconds.
    #[getter]
    fn ts(&self) -> f64 {
        self.ss.ts().unwrap_or(0.0)
    }
    /// Number of states of the state-space form.
    #[getter]
    fn order(&self) -> usize {
        self.ss.order()
    }
    #[getter]
    fn a<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        mat2(py, self.ss.a())
    }
    #[getter]
    fn b<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        mat2(py, self.ss.b())
    }
    #[getter]
    fn c<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        mat2(py, self.ss.c())
    }
    #[getter]
    fn d<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        mat2(py, self.ss.d())
    }
    /// The estimated parameter vector θ (ordering as the Rust estimator documents).
    #[getter]
    fn params<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        self.params.clone().into_pyarray(py)
    }
    /// Standard deviations of θ, or `None` when no covariance was computed.
    #[getter]
    fn params_std<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyArray1<f64>>> {
        self.std.clone().map(|s| s.into_pyarray(py))
    }
    /// Loss V_N (mean squared prediction error on the estimation data).
    #[getter]
    fn loss(&self) -> f64 {
        self.loss
    }
    /// Estimated innovation variance.
    #[getter]
    fn noise_variance(&self) -> f64 {
        self.noise_variance
    }
    /// Samples used in the criterion.
    #[getter]
    fn n_samples(&self) -> usize {
        self.n_samples
    }
    /// The polynomials `{"a", "b", "c", "d", "f"}` (ascending powers of q⁻¹) of a polynomial
    /// model, `None` for a state-space one.
    #[getter]
    fn polynomials<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        let Some(p) = &self.poly else { return Ok(None) };
        let d = PyDict::new(py);
        d.set_item("a", p.a().to_vec().into_pyarray(py))?;
        d.set_item("b", p.b().to_vec().into_pyarray(py))?;
        d.set_item("c", p.c().to_vec().into_pyarray(py))?;
        d.set_item("d", p.d().to_vec().into_pyarray(py))?;
        d.set_item("f", p.f().to_vec().into_pyarray(py))?;
        Ok(Some(d))
    }
    /// Poles (eigenvalues of A, discrete time).
    fn poles<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray1<Complex64>>> {
        let p = self.ss.poles().map_err(to_py)?;
        Ok(p.into_pyarray(py))
    }
    /// Frequency response at `f_hz` as an `(L, ny, nu)` complex array.
    fn freq_response<'py>(
        &self,
        py: Python<'py>,
        f_hz: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyArray3<Complex64>>> {
        let f = vec1("f_hz", f_hz)?;
        let resp = py.detach(|| self.ss.freq_response(&f)).map_err(to_py)?;
        let (ny, nu) = (self.ss.noutputs(), self.ss.ninputs());
        Ok(Array3::from_shape_fn((f.len(), ny, nu), |(k, i, j)| resp[k][(i, j)]).into_pyarray(py))
    }
    /// The model as a python-control `StateSpace` (discrete, sample time `ts`); needs the
    /// package `control` (`pip install control`).
    fn to_control<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let control = py.import("control").map_err(|e| {
            pyo3::exceptions::PyImportError::new_err(format!(
                "to_control() needs python-control: pip install control ({e})"
            ))
        })?;
        control.call_method1(
            "ss",
            (self.a(py), self.b(py), self.c(py), self.d(py), self.ts()),
        )
    }
    /// The model as the JSON text `ambid fit` writes (`kind` = `state_space` or `polynomial`).
    fn to_json(&self) -> PyResult<String> {
        let meta = serde_json::json!({ "structure": self.structure });
        let v = match &self.poly {
            Some(p) => ambid::io::model::polynomial_json(p, "u", "y", meta),
            None => ambid::io::model::state_space_json(&self.ss, "u", "y", meta),
        };
        serde_json::to_string_pretty(&v).map_err(|e| AmbidError::new_err(e.to_string()))
    }
    /// Writes the model as `ambid fit` and `ambid export` do: `path` (`.json`, the model file)
    /// and beside it `.m` (a MATLAB script building `idpoly`/`idss`), `.mat` (MATLAB v5) and
    /// `.npz` (numpy), all or nothing (an existing file is replaced only with `force`).
    /// Returns the paths written.
    #[pyo3(signature = (path, *, force=false))]
    fn save(&self, py: Python<'_>, path: PathBuf, force: bool) -> PyResult<Vec<PathBuf>> {
        if path.extension().and_then(|e| e.to_str()) != Some("json") {
            return Err(err(
                Kind::Usage,
                format!(
                    "`{}`: the model file's name must end in .json (the .m, .mat and .npz \
                     exports are written beside it)",
                    path.display()
                ),
            ));
        }
        let text = self.to_json()?;
        py.detach(|| -> Result<Vec<PathBuf>, AppError> {
            for ext in ["json", "m", "mat", "npz"] {
                ambid::io::OutputSet::check(&path.with_extension(ext), force)?;
            }
            let mut set = ambid::io::OutputSet::new(force);
            set.write(&path, text.as_bytes())?;
            set.commit()?;
            let mut out = vec![path.clone()];
            out.extend(ambid::io::model::write_model_exports(&path)?);
            Ok(out)
        })
        .map_err(to_py)
    }
    fn __repr__(&self) -> String {
        format!(
            "Model(structure='{}', order={}, ts={}, inputs={}, outputs={})",
            self.structure,
            self.ss.order(),
            self.ss.ts().unwrap_or(0.0),
            self.ss.ninputs(),
            self.ss.noutputs()
        )
    }
}

fn poly_model(
    fitted: ambid_core::estimate::Fitted<PolyModel>,
    structure: &str,
) -> PyResult<PyModel> {
    let ss = fitted
        .model
        .g()
        .and_then(|g| g.to_state_space())
        .map_err(to_py)?;
    let std = fitted.std();
    Ok(PyModel {
        ss,
        structure: structure.to_string(),
        std,
        params: fitted.params,
        loss: fitted.loss,
        noise_variance: fitted.noise_variance,
        n_samples: fitted.n_samples,
        poly: Some(fitted.model),
    })
}

/// Least-squares ARX(na, nb, nk) model of `u → y` (the computation of `ambid fit --structure
/// arx`).
#[pyfunction]
#[pyo3(signature = (u, y, ts, *, na, nb, nk=1))]
fn fit_arx<'py>(
    py: Python<'py>,
    u: &Bound<'py, PyAny>,
    y: &Bound<'py, PyAny>,
    ts: f64,
    na: usize,
    nb: usize,
    nk: usize,
) -> PyResult<PyModel> {
    let (u, y) = (ro1("u", u)?, ro1("y", y)?);
    let (u, y) = (samples("u", &u)?, samples("y", &y)?);
    let ts = finite_positive("ts", ts)?;
    let f = py
        .detach(|| ambid::fitting::arx_fitted(y, u, na, nb, nk, ts))
        .map_err(to_py)?;
    poly_model(f, if na == 0 { "fir" } else { "arx" })
}

/// Prediction-error model (ARMAX, OE, BJ) of `u → y` with the library's default options.
#[pyfunction]
#[pyo3(signature = (u, y, ts, structure, *, na=0, nb=1, nc=0, nd=0, nf=0, nk=1, max_iterations=100))]
#[allow(clippy::too_many_arguments)]
fn fit_pem<'py>(
    py: Python<'py>,
    u: &Bound<'py, PyAny>,
    y: &Bound<'py, PyAny>,
    ts: f64,
    structure: &str,
    na: usize,
    nb: usize,
    nc: usize,
    nd: usize,
    nf: usize,
    nk: usize,
    max_iterations: usize,
) -> PyResult<PyModel> {
    let (u, y) = (ro1("u", u)?, ro1("y", y)?);
    let (u, y) = (samples("u", &u)?, samples("y", &y)?);
    let ts = finite_positive("ts", ts)?;
    let (s, orders) = match structure {
        "armax" => (Structure::Armax, Orders::armax(na, nb, nc, nk)),
        "oe" => (Structure::Oe, Orders::oe(nb, nf, nk)),
        "bj" => (Structure::Bj, Orders::bj(nb, nc, nd, nf, nk)),
        other => {
            return Err(err(Kind::Usage, format!(
                "unknown structure `{other}`: fit_pem takes \"armax\", \"oe\" or \"bj\" (fit_arx for ARX/FIR, fit_ss for state space)"
            )))
        }
    };
    let opts = PemOptions::default()
        .with_max_iterations(max_iterations)
        .map_err(to_py)?;
    let (f, _) = py
        .detach(|| pem(y, u, s, &orders, ts, &opts))
        .map_err(to_py)?;
    poly_model(f, structure)
}

/// The twin's seed experiment (or one of its random test rigs): the recorded signals and the
/// exact linearised truth on the record's DFT grid.
///
/// # Example
///
/// ```python
/// >>> import ambid
/// >>> rec = ambid.simulate(seed=1, mode="linear", periods=4)
/// >>> rec["fs"], rec["period_samples"], rec["y"].shape
/// (20000.0, 5115, (20460,))
///
/// ```
#[pyfunction]
#[pyo3(signature = (*, seed=1, rig_seed=None, mode="nonlinear", noise=true, prbs_order=10, samples_per_bit=5, periods=20, level=0.1))]
#[allow(clippy::too_many_arguments)]
fn simulate<'py>(
    py: Python<'py>,
    seed: u64,
    rig_seed: Option<u64>,
    mode: &str,
    noise: bool,
    prbs_order: u32,
    samples_per_bit: usize,
    periods: usize,
    level: f64,
) -> PyResult<Bound<'py, PyDict>> {
    let mode = match mode {
        "linear" => ambid_twin::Mode::Linear,
        "nonlinear" => ambid_twin::Mode::Nonlinear,
        other => {
            return Err(err(
                Kind::Usage,
                format!("unknown mode `{other}`: use \"linear\" or \"nonlinear\""),
            ))
        }
    };
    let twin = rig_of(rig_seed)?;
    let exp = ambid::experiment::Experiment {
        twin,
        excitation: ambid::experiment::ExcitationPlan {
            prbs_order,
            samples_per_bit,
            periods,
            amplitude_frac: level,
            ..Default::default()
        },
        mode,
        seed,
        noise,
        record_b: false,
    };
    let out = py.detach(|| ambid::experiment::run(&exp)).map_err(to_py)?;
    let rec = &out.record;
    let d = PyDict::new(py);
    d.set_item("fs", 1.0 / rec.ts)?;
    d.set_item("period_samples", out.excitation.period_samples)?;
    for (k, v) in [
        ("t", &rec.t),
        ("r", &rec.r),
        ("u", &rec.u),
        ("i", &rec.i),
        ("y", &rec.y),
        ("w", &rec.w),
    ] {
        d.set_item(k, v.clone().into_pyarray(py))?;
    }
    Ok(d)
}

/// The twin's exact linearised plant, T_ry, S and controller at `f_hz` (nominal rig or random
/// rig `rig_seed`).
///
/// # Example
///
/// ```python
/// >>> import numpy as np, ambid
/// >>> t = ambid.truth(np.array([50.0, 500.0]))
/// >>> t["plant"].shape, t["plant"].dtype
/// ((2,), dtype('complex128'))
///
/// ```
#[pyfunction]
#[pyo3(signature = (f_hz, *, rig_seed=None))]
fn truth<'py>(
    py: Python<'py>,
    f_hz: &Bound<'py, PyAny>,
    rig_seed: Option<u64>,
) -> PyResult<Bound<'py, PyDict>> {
    let f = vec1("f_hz", f_hz)?;
    let cfg = rig_of(rig_seed)?;
    let tr = py
        .detach(|| {
            let twin = ambid_twin::Twin::new(cfg).map_err(AppError::from)?;
            ambid::experiment::truth(&twin, &f)
        })
        .map_err(to_py)?;
    let d = PyDict::new(py);
    d.set_item("f_hz", tr.f_hz.into_pyarray(py))?;
    d.set_item("plant", tr.plant.into_pyarray(py))?;
    d.set_item("t_ry", tr.t_ry.into_pyarray(py))?;
    d.set_item("s", tr.t_ru.into_pyarray(py))?;
    d.set_item("controller", tr.controller.into_pyarray(py))?;
    Ok(d)
}

/// The outcome of the whole workflow.
#[pyclass(frozen, module = "ambid._native", name = "Outcome")]
struct PyOutcome {
    inner: ambid::workflow::Outcome,
}

#[pymethods]
impl PyOutcome {
    /// The run's summary as JSON text (what `ambid run` writes as `summary.json`).
    fn summary_json(&self) -> PyResult<String> {
        serde_json::to_string(&self.inner.summary).map_err(|e| AmbidError::new_err(e.to_string()))
    }
    /// The offline HTML report.
    fn html(&self, py: Python<'_>) -> String {
        py.detach(|| self.inner.report.to_html())
    }
    /// Writes the report, summary, figures, tables and models into `out` (atomically; an
    /// existing directory only with `force`). Returns the written paths.
    #[pyo3(signature = (out, *, force=false))]
    fn write(&self, py: Python<'_>, out: PathBuf, force: bool) -> PyResult<Vec<PathBuf>> {
        py.detach(|| self.inner.write(&out, force)).map_err(to_py)
    }
    /// The exported models as `(name, json text)` pairs: the text of `models/<name>.json`.
    fn models(&self) -> PyResult<Vec<(String, String)>> {
        self.inner
            .model_jsons()
            .map_err(to_py)?
            .into_iter()
            .map(|(name, v)| {
                serde_json::to_string(&v)
                    .map(|t| (name, t))
                    .map_err(|e| AmbidError::new_err(e.to_string()))
            })
            .collect()
    }
}

/// Runs the workflow of a workflow file's text (`ambid run`): `config` is the TOML text,
/// `base` the directory its relative paths are read from.
///
/// # Example
///
/// ```python
/// >>> import ambid
/// >>> out = ambid.run('steps = ["frf", "order", "models"]')
/// >>> "chosen" in out.summary["models"]
/// True
///
/// ```
#[pyfunction]
#[pyo3(signature = (config="", *, base=None))]
fn run(py: Python<'_>, config: &str, base: Option<PathBuf>) -> PyResult<PyOutcome> {
    let base = base.unwrap_or_else(|| PathBuf::from("."));
    let cfg = ambid::workflow::WorkflowConfig::from_toml_str(config, &base.join("workflow.toml"))
        .map_err(to_py)?;
    let out = py
        .detach(|| {
            let mut progress = ambid::workflow::Progress::new(ambid::workflow::Verbosity::Quiet);
            ambid::workflow::run(&cfg, &base, &mut progress)
        })
        .map_err(to_py)?;
    Ok(PyOutcome { inner: out })
}

/// A complex128 array of shape `(L,)` (one entry) or `(L, ny, nu)` as `(values in the Frd's
/// column-major layout per line, ny, nu)`, or `InputError` naming `name`.
fn frd_values(
    name: &str,
    obj: &Bound<'_, PyAny>,
) -> PyResult<(Vec<Complex64>, usize, usize, usize)> {
    let Ok(arr) = obj.cast::<numpy::PyArrayDyn<Complex64>>() else {
        return Err(err(Kind::Input, format!(
            "`{name}` must be a complex128 numpy array of shape (L,) or (L, ny, nu); convert it with np.ascontiguousarray({name}, dtype=complex)"
        )));
    };
    let shape = arr.shape().to_vec();
    let ro = arr.readonly();
    let flat = ro.as_slice().map_err(|_| {
        err(
            Kind::Input,
            format!("`{name}` is not C-contiguous; pass np.ascontiguousarray({name})"),
        )
    })?;
    match shape.as_slice() {
        [l] => Ok((flat.to_vec(), *l, 1, 1)),
        [l, ny, nu] => {
            let (l, ny, nu) = (*l, *ny, *nu);
            // numpy is row-major (k, i, j); the Frd stores line k column-major (k e + j ny + i)
            let mut v = vec![Complex64::new(0.0, 0.0); l * ny * nu];
            for k in 0..l {
                for i in 0..ny {
                    for j in 0..nu {
                        v[k * ny * nu + j * ny + i] = flat[(k * ny + i) * nu + j];
                    }
                }
            }
            Ok((v, l, ny, nu))
        }
        other => Err(err(
            Kind::Input,
            format!("`{name}` must have shape (L,) or (L, ny, nu), got {other:?}"),
        )),
    }
}

/// A state-space model of order `order` fitted to frequency-response data (the weighted
/// complex-error fit of `ambid_core::estimate::freqfit_mimo`, any number of inputs and outputs;
/// one entry is the 1×1 case).
///
/// # Example
///
/// ```python
/// >>> import numpy as np, ambid
/// >>> true = ambid.ss(np.array([[1.05, 0.0], [0.3, 0.6]]), np.array([[1.0], [0.0]]),
/// ...                 np.array([[0.0, 1.0]]), np.array([[0.0]]), 1e-3)
/// >>> f = np.linspace(1.0, 450.0, 200)
/// >>> m = ambid.fit_frf(f, true.freq_response(f)[:, 0, 0].copy(), 1e-3, 2)
/// >>> sorted(round(float(abs(p)), 6) for p in m.poles())  # the unstable pole is kept
/// [0.6, 1.05]
///
/// ```
#[pyfunction]
#[pyo3(signature = (f_hz, g, ts, order, *, std=None, band=None, max_unstable_poles=None, feedthrough=false, max_iterations=100))]
#[allow(clippy::too_many_arguments)]
fn fit_frf(
    py: Python<'_>,
    f_hz: &Bound<'_, PyAny>,
    g: &Bound<'_, PyAny>,
    ts: f64,
    order: usize,
    std: Option<&Bound<'_, PyAny>>,
    band: Option<(f64, f64)>,
    max_unstable_poles: Option<usize>,
    feedthrough: bool,
    max_iterations: usize,
) -> PyResult<PyModel> {
    use ambid_core::estimate::freqfit_mimo::{ss_frd_mimo, MimoFreqOptions};
    let f = vec1("f_hz", f_hz)?;
    let (values, l, ny, nu) = frd_values("g", g)?;
    if l != f.len() {
        return Err(err(
            Kind::Input,
            format!(
                "`g` has {l} lines but `f_hz` has {}; give one response per frequency",
                f.len()
            ),
        ));
    }
    let variance = match std {
        Some(s) => {
            let s = vec1("std", s)?;
            if s.len() != values.len() {
                return Err(err(Kind::Input, format!(
                    "`std` must be flat with one value per entry and line ({}), got {}; pass std.ravel() of an (L,) or (L, ny, nu) array",
                    values.len(),
                    s.len()
                )));
            }
            // the same (k, i, j) → Frd layout as the values
            let mut v = vec![0.0; s.len()];
            for k in 0..l {
                for i in 0..ny {
                    for j in 0..nu {
                        let x = s[(k * ny + i) * nu + j];
                        v[k * ny * nu + j * ny + i] = x * x;
                    }
                }
            }
            Some(v)
        }
        None => None,
    };
    let ts = finite_positive("ts", ts)?;
    let opts = MimoFreqOptions {
        band_hz: band_of("band", band)?,
        max_unstable_poles,
        feedthrough,
        max_iterations,
        ..Default::default()
    };
    let fit = py
        .detach(|| {
            let frd = Frd::new_matrix(f, ny, nu, values, variance, Some(ts))?;
            ss_frd_mimo(&frd, order, &opts)
        })
        .map_err(to_py)?;
    Ok(PyModel {
        loss: fit.cost,
        n_samples: fit.n_equations,
        ..ss_model(fit.model, "ss")
    })
}

/// A state-space model of `u → y` from time data: subspace identification (order from the
/// singular values unless given) refined by the prediction-error method
/// (`ambid::fitting::identify_state_space`, as `ambid fit --structure ss`).
///
/// # Example
///
/// ```python
/// >>> import numpy as np, ambid
/// >>> rng = np.random.default_rng(1)
/// >>> u = rng.standard_normal(3000)
/// >>> y = np.zeros(3000)
/// >>> for k in range(1, 3000):
/// ...     y[k] = 0.9 * y[k - 1] + u[k - 1]
/// >>> m = ambid.fit_ss(u, y, 1.0, order=1)
/// >>> round(float(m.poles()[0].real), 6)
/// 0.9
///
/// ```
#[pyfunction]
#[pyo3(signature = (u, y, ts, *, order=None, feedthrough=false, max_iterations=100))]
fn fit_ss(
    py: Python<'_>,
    u: &Bound<'_, PyAny>,
    y: &Bound<'_, PyAny>,
    ts: f64,
    order: Option<usize>,
    feedthrough: bool,
    max_iterations: usize,
) -> PyResult<PyModel> {
    let (u, y) = (ro1("u", u)?, ro1("y", y)?);
    let (u, y) = (samples("u", &u)?, samples("y", &y)?);
    let ts = finite_positive("ts", ts)?;
    let opts = ambid::fitting::SsFitOptions {
        order,
        feedthrough,
        max_iterations,
        ..Default::default()
    };
    let id = py
        .detach(|| ambid::fitting::identify_state_space(u, y, ts, &opts))
        .map_err(to_py)?;
    Ok(PyModel {
        n_samples: u.len(),
        ..ss_model(id.model, "ss")
    })
}

/// An excitation signal (`ambid_core::signal`, the computation of `ambid excite`): `kind` is
/// `prbs`, `chirp`, `noise` or `multisine`, `params` a JSON object of the spec's fields (PRBS
/// fields default to the seed paper's; the others must be given). Returns the samples, the
/// period and the band report.
#[pyfunction]
fn excite<'py>(py: Python<'py>, kind: &str, fs: f64, params: &str) -> PyResult<Bound<'py, PyDict>> {
    use ambid_core::signal::{ExcitationSpec, PrbsSpec};
    let fs = finite_positive("fs", fs)?;
    let given: serde_json::Map<String, serde_json::Value> =
        serde_json::from_str(params).map_err(|e| {
            err(
                Kind::Usage,
                format!("the excitation parameters are not a JSON object: {e}"),
            )
        })?;
    let mut obj = match kind {
        "prbs" => match serde_json::to_value(PrbsSpec::default()) {
            Ok(serde_json::Value::Object(m)) => m,
            _ => serde_json::Map::new(),
        },
        "chirp" | "noise" | "multisine" => serde_json::Map::new(),
        other => {
            return Err(err(
                Kind::Usage,
                format!(
                "unknown excitation `{other}`: use \"prbs\", \"chirp\", \"noise\" or \"multisine\""
            ),
            ))
        }
    };
    for (k, v) in &given {
        obj.insert(k.clone(), v.clone());
    }
    obj.insert("kind".into(), serde_json::Value::String(kind.into()));
    let spec: ExcitationSpec = serde_json::from_value(serde_json::Value::Object(obj))
        .map_err(|e| err(Kind::Usage, format!("{kind}: {e}")))?;
    // serde ignores unknown fields: a misspelt option would pass silently, so compare
    let known = match serde_json::to_value(&spec) {
        Ok(serde_json::Value::Object(m)) => m,
        _ => serde_json::Map::new(),
    };
    if let Some(bad) = given.keys().find(|k| !known.contains_key(*k)) {
        let mut names: Vec<&String> = known.keys().filter(|k| *k != "kind").collect();
        names.sort();
        return Err(err(
            Kind::Usage,
            format!("unknown option `{bad}` for a {kind}; its options are {names:?}"),
        ));
    }
    let ts = 1.0 / fs;
    let (exc, rep) = py
        .detach(|| Ok::<_, ambid_core::Error>((spec.generate(ts)?, spec.report(ts)?)))
        .map_err(to_py)?;
    let d = PyDict::new(py);
    d.set_item("values", exc.values.into_pyarray(py))?;
    d.set_item("ts", exc.ts)?;
    d.set_item("period_samples", exc.period_samples)?;
    d.set_item("periods", exc.periods)?;
    let r = PyDict::new(py);
    r.set_item("f_min_hz", rep.f_min_hz)?;
    r.set_item("f_max_hz", rep.f_max_hz)?;
    r.set_item("resolution_hz", rep.resolution_hz)?;
    r.set_item("duration_s", rep.duration_s)?;
    r.set_item("n_samples", rep.n_samples)?;
    r.set_item("rms", rep.rms)?;
    r.set_item("peak", rep.peak)?;
    r.set_item("crest_factor", rep.crest_factor)?;
    d.set_item("report", r)?;
    Ok(d)
}

/// Random test rig `seed`'s twin configuration as TOML (what `ambid config --rig-seed N`
/// prints): a workflow's `[twin] config` file.
///
/// # Example
///
/// ```python
/// >>> import ambid
/// >>> "[rotor]" in ambid.rig_config(3) or "mass" in ambid.rig_config(3)
/// True
///
/// ```
#[pyfunction]
fn rig_config(seed: u64) -> PyResult<String> {
    ambid_twin::random_rig(seed)
        .and_then(|c| c.to_toml_string())
        .map_err(to_py)
}

/// The ambid version.
#[pyfunction]
fn version() -> &'static str {
    env!("CARGO_PKG_VERSION")
}

#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("AmbidError", py.get_type::<AmbidError>())?;
    let types = TYPES.get_or_try_init(py, || make_types(py))?;
    for ((name, _, _), t) in KINDS.iter().zip(types) {
        m.add(*name, t.bind(py))?;
    }
    m.add_class::<PyModel>()?;
    m.add_class::<PyOutcome>()?;
    m.add_function(wrap_pyfunction!(version, m)?)?;
    m.add_function(wrap_pyfunction!(frf, m)?)?;
    m.add_function(wrap_pyfunction!(fit_arx, m)?)?;
    m.add_function(wrap_pyfunction!(fit_pem, m)?)?;
    m.add_function(wrap_pyfunction!(simulate, m)?)?;
    m.add_function(wrap_pyfunction!(truth, m)?)?;
    m.add_function(wrap_pyfunction!(run, m)?)?;
    m.add_function(wrap_pyfunction!(rig_config, m)?)?;
    m.add_function(wrap_pyfunction!(excite, m)?)?;
    m.add_function(wrap_pyfunction!(fit_frf, m)?)?;
    m.add_function(wrap_pyfunction!(fit_ss, m)?)?;
    m.add_function(wrap_pyfunction!(frf_local, m)?)?;
    m.add_function(wrap_pyfunction!(order_scan, m)?)?;
    m.add_function(wrap_pyfunction!(twin_plant, m)?)?;
    m.add_function(wrap_pyfunction!(controller, m)?)?;
    m.add_function(wrap_pyfunction!(validate, m)?)?;
    m.add_function(wrap_pyfunction!(lowlevel::spectra, m)?)?;
    m.add_function(wrap_pyfunction!(lowlevel::n4sid, m)?)?;
    m.add_function(wrap_pyfunction!(lowlevel::ss, m)?)?;
    m.add_function(wrap_pyfunction!(lowlevel::periodic_frf, m)?)?;
    m.add_function(wrap_pyfunction!(machine::machine_experiments, m)?)?;
    m.add_function(wrap_pyfunction!(machine::frf_mimo, m)?)?;
    m.add_function(wrap_pyfunction!(studies::bla, m)?)?;
    m.add_function(wrap_pyfunction!(studies::bla_study, m)?)?;
    m.add_function(wrap_pyfunction!(studies::amplitude_study, m)?)?;
    Ok(())
}
