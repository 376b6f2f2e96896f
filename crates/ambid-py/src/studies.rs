//! The excitation studies of recorded data from Python: the robust best linear approximation
//! (BLA) of one level and the BLA amplitude study over levels (`ambid bla --records`), and the
//! seed-style amplitude study (`ambid study amplitude --files`). Each calls the library
//! function the CLI calls; the per-level figures come back as dicts with the keys of the
//! library's serialised rows (`summary.json`).

use super::{band_of, err, finite_positive, put_frds, to_py, vec1, Kind};
use ambid::analysis::FrfSettings;
use ambid::bla::{
    amplitude_study_from_records, bla_of_level, figures_of, Realisation, RecordedLevel,
    RecordedPlan,
};
use ambid::study::{amplitude_from_records, LevelRecord, Recommendation};
use ambid_core::frf::bla::BlaEstimate;
use numpy::IntoPyArray;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

/// A JSON value as the Python object `json.loads` would give.
fn json_to_py<'py>(py: Python<'py>, v: &serde_json::Value) -> PyResult<Bound<'py, PyAny>> {
    use serde_json::Value;
    Ok(match v {
        Value::Null => py.None().into_bound(py),
        Value::Bool(b) => b.into_pyobject(py)?.to_owned().into_any(),
        Value::Number(n) => match n.as_i64() {
            Some(i) if !n.is_f64() => i.into_pyobject(py)?.into_any(),
            _ => n.as_f64().unwrap_or(f64::NAN).into_pyobject(py)?.into_any(),
        },
        Value::String(s) => s.into_pyobject(py)?.into_any(),
        Value::Array(a) => {
            let l = PyList::empty(py);
            for x in a {
                l.append(json_to_py(py, x)?)?;
            }
            l.into_any()
        }
        Value::Object(o) => {
            let d = PyDict::new(py);
            for (k, x) in o {
                d.set_item(k, json_to_py(py, x)?)?;
            }
            d.into_any()
        }
    })
}

/// A serialisable row as a dict.
fn row_dict<'py, T: serde::Serialize>(py: Python<'py>, row: &T) -> PyResult<Bound<'py, PyAny>> {
    let v = serde_json::to_value(row).map_err(|e| err(Kind::Computation, e.to_string()))?;
    json_to_py(py, &v)
}

/// Serialisable rows as a list of dicts.
fn rows_list<'py, T: serde::Serialize>(
    py: Python<'py>,
    rows: &[T],
) -> PyResult<Bound<'py, PyList>> {
    let l = PyList::empty(py);
    for r in rows {
        l.append(row_dict(py, r)?)?;
    }
    Ok(l)
}

/// A 1-D array of a dict entry, copied (`what` names it in errors).
fn entry(d: &Bound<'_, PyDict>, key: &str, what: &str) -> PyResult<Option<Vec<f64>>> {
    match d.get_item(key)? {
        None => Ok(None),
        Some(o) if o.is_none() => Ok(None),
        Some(o) => Ok(Some(vec1(&format!("{what}[\"{key}\"]"), &o)?)),
    }
}

fn required(d: &Bound<'_, PyDict>, key: &str, what: &str) -> PyResult<Vec<f64>> {
    entry(d, key, what)?.ok_or_else(|| {
        err(
            Kind::Input,
            format!("`{what}` has no \"{key}\": give the arrays r (closed loop), u and y"),
        )
    })
}

/// One BLA realisation from a dict `{"r" (optional: open loop without it), "u", "y"}`.
fn realisation(obj: &Bound<'_, PyAny>, what: &str) -> PyResult<Realisation> {
    let d = obj.cast::<PyDict>().map_err(|_| {
        err(
            Kind::Input,
            format!("`{what}` must be a dict with the arrays r, u, y"),
        )
    })?;
    Ok(Realisation {
        r: entry(d, "r", what)?,
        u: required(d, "u", what)?,
        y: required(d, "y", what)?,
        saturated_fraction: None,
        source: what.to_string(),
    })
}

fn plan(
    fs: f64,
    period_samples: usize,
    skip_periods: usize,
    band: Option<(f64, f64)>,
) -> PyResult<RecordedPlan> {
    if period_samples < 2 {
        return Err(err(
            Kind::Usage,
            format!("`period_samples` must be at least 2, got {period_samples}"),
        ));
    }
    Ok(RecordedPlan {
        fs: finite_positive("fs", fs)?,
        period_samples,
        skip_periods,
        summary_band_hz: band_of("band", band)?.unwrap_or((10.0, 1000.0)),
    })
}

/// One BLA estimate's per-line arrays under `key`: the values, the total and noise standard
/// deviations of the estimate and the standard deviation of the nonlinear distortion of one
/// realisation (its variance clipped at 0).
fn put_bla(d: &Bound<'_, PyDict>, key: &str, b: &BlaEstimate) -> PyResult<()> {
    let py = d.py();
    let sq = |v: &[f64]| -> Vec<f64> { v.iter().map(|x| x.max(0.0).sqrt()).collect() };
    d.set_item(key, b.values.clone().into_pyarray(py))?;
    d.set_item(format!("{key}_std"), sq(&b.var_total).into_pyarray(py))?;
    d.set_item(
        format!("{key}_std_noise"),
        sq(&b.var_noise).into_pyarray(py),
    )?;
    d.set_item(format!("{key}_std_nl"), sq(&b.var_nl).into_pyarray(py))?;
    Ok(())
}

/// The robust BLA of one level from M ≥ 2 random-phase multisine realisations, each a dict of
/// `r`, `u`, `y` (closed loop: the plant as T_ry/T_ru per realisation) or `u`, `y` (open loop),
/// as `ambid bla --records` with one level. Returns the per-line BLA (`f_hz`, `g` with `g_std`,
/// `g_std_noise`, `g_std_nl`; closed loop also `t_ry…`, `s…`), the detection-line levels and
/// the band figures of the level (`figures`).
///
/// # Example
///
/// ```python
/// >>> import numpy as np, ambid
/// >>> rng = np.random.default_rng(0)
/// >>> n = 128
/// >>> def realisation():
/// ...     x = np.zeros(n // 2 + 1, complex)
/// ...     x[1:40:2] = np.exp(2j * np.pi * rng.random(20))
/// ...     u = np.tile(np.fft.irfft(x, n), 4)
/// ...     return {"u": u, "y": 2.0 * u + 1e-6 * rng.standard_normal(4 * n)}
/// >>> b = ambid.bla([realisation() for _ in range(4)], 1000.0, period_samples=n, band=(1.0, 300.0))
/// >>> bool(np.allclose(b["g"], 2.0, rtol=1e-3))
/// True
///
/// ```
#[pyfunction]
#[pyo3(signature = (realisations, fs, *, period_samples, skip_periods=1, band=None, level_pct=None))]
pub(crate) fn bla<'py>(
    py: Python<'py>,
    realisations: &Bound<'py, PyList>,
    fs: f64,
    period_samples: usize,
    skip_periods: usize,
    band: Option<(f64, f64)>,
    level_pct: Option<f64>,
) -> PyResult<Bound<'py, PyDict>> {
    let plan = plan(fs, period_samples, skip_periods, band)?;
    let level = RecordedLevel {
        level_pct: level_pct.unwrap_or(f64::NAN),
        realisations: realisations
            .iter()
            .enumerate()
            .map(|(m, x)| realisation(&x, &format!("realisations[{m}]")))
            .collect::<PyResult<_>>()?,
    };
    let (bla, figures) = py
        .detach(|| -> ambid::error::Result<_> {
            let bla = bla_of_level(&level, &plan)?;
            let f = figures_of(&bla, level.level_pct, plan.summary_band_hz, 0.0, None)?;
            Ok((bla, f))
        })
        .map_err(to_py)?;
    let d = PyDict::new(py);
    d.set_item("f_hz", bla.g.f_hz.clone().into_pyarray(py))?;
    put_bla(&d, "g", &bla.g)?;
    if let Some(t) = &bla.t_ry {
        put_bla(&d, "t_ry", t)?;
    }
    if let Some(t) = &bla.t_ru {
        put_bla(&d, "s", t)?;
    }
    d.set_item("realisations", bla.g.realisations)?;
    d.set_item("periods", bla.g.periods)?;
    d.set_item("even_db", bla.detection.even.ratio_db)?;
    d.set_item("odd_db", bla.detection.odd.ratio_db)?;
    d.set_item("figures", row_dict(py, &figures)?)?;
    Ok(d)
}

/// The BLA amplitude study of recorded levels (`ambid bla --records` with several levels):
/// `levels` maps a level in % of i_sat to its realisations (as for [`bla`]). Returns the rows
/// (one dict per level: noise and nonlinear variance relative to |G|², their sum, the
/// detection-line levels), the recommended level and the reasoning.
///
/// # Example
///
/// ```python
/// >>> import numpy as np, ambid
/// >>> rng = np.random.default_rng(0)
/// >>> n = 128
/// >>> def realisation(level):
/// ...     x = np.zeros(n // 2 + 1, complex)
/// ...     x[1:40:2] = np.exp(2j * np.pi * rng.random(20))
/// ...     u = np.tile(np.fft.irfft(x, n), 4) * level
/// ...     return {"u": u, "y": 2.0 * u + 1e-4 * rng.standard_normal(4 * n)}
/// >>> st = ambid.bla_study({1.0: [realisation(0.01) for _ in range(4)],
/// ...                       10.0: [realisation(0.1) for _ in range(4)]}, 1000.0, period_samples=n)
/// >>> st["recommended_pct"]
/// 10.0
///
/// ```
#[pyfunction]
#[pyo3(signature = (levels, fs, *, period_samples, skip_periods=1, band=None))]
pub(crate) fn bla_study<'py>(
    py: Python<'py>,
    levels: &Bound<'py, PyDict>,
    fs: f64,
    period_samples: usize,
    skip_periods: usize,
    band: Option<(f64, f64)>,
) -> PyResult<Bound<'py, PyDict>> {
    let plan = plan(fs, period_samples, skip_periods, band)?;
    let mut tagged = Vec::new();
    for (k, v) in levels.iter() {
        let pct: f64 = k.extract().map_err(|_| {
            err(
                Kind::Input,
                "`levels` maps a level in % of i_sat (a number) to a list of realisations",
            )
        })?;
        let list = v.cast::<PyList>().map_err(|_| {
            err(
                Kind::Input,
                format!("`levels[{pct}]` must be a list of realisations (dicts of r, u, y)"),
            )
        })?;
        for (m, x) in list.iter().enumerate() {
            tagged.push((pct, realisation(&x, &format!("levels[{pct}][{m}]"))?));
        }
    }
    let grouped = RecordedLevel::group(tagged);
    let study = py
        .detach(|| amplitude_study_from_records(&grouped, &plan))
        .map_err(to_py)?;
    let d = PyDict::new(py);
    d.set_item("rows", rows_list(py, &study.rows)?)?;
    d.set_item("recommended_pct", study.recommended_pct)?;
    d.set_item("reasoning", study.reasoning)?;
    Ok(d)
}

/// The amplitude study of recorded periodic experiments, one per level (`ambid study amplitude
/// --files`): each record a dict of `level_pct`, `r`, `u`, `y` and optionally `i`; `noise` an
/// output record without excitation (for the SNR). Per level the band averages of the
/// coherences and of the plant's single-period variance, the SNR and the saturation; the
/// recommended range of levels and why; the plant FRF of each level.
///
/// # Example
///
/// ```python
/// >>> import ambid
/// >>> recs = []
/// >>> for k, lvl in enumerate((0.02, 0.08)):
/// ...     r = ambid.simulate(seed=10 + k, mode="linear", level=lvl, periods=6)
/// ...     recs.append({"level_pct": 100 * lvl, "r": r["r"], "u": r["u"], "y": r["y"]})
/// >>> out = ambid.amplitude_study(recs, 20000.0, period_samples=5115, band=(10.0, 1000.0))
/// >>> [r["level_pct"] for r in out["rows"]]
/// [2.0, 8.0]
///
/// ```
#[pyfunction]
#[pyo3(signature = (records, fs, *, period_samples, skip_periods=1, band=None, noise=None))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn amplitude_study<'py>(
    py: Python<'py>,
    records: &Bound<'py, PyList>,
    fs: f64,
    period_samples: usize,
    skip_periods: usize,
    band: Option<(f64, f64)>,
    noise: Option<Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyDict>> {
    let fs = finite_positive("fs", fs)?;
    let band = band_of("band", band)?;
    let mut recs = Vec::with_capacity(records.len());
    for (k, x) in records.iter().enumerate() {
        let what = format!("records[{k}]");
        let d = x.cast::<PyDict>().map_err(|_| {
            err(
                Kind::Input,
                format!("`{what}` must be a dict of level_pct, r, u, y (and optionally i)"),
            )
        })?;
        let level: f64 = d
            .get_item("level_pct")?
            .ok_or_else(|| {
                err(
                    Kind::Input,
                    format!("`{what}` has no \"level_pct\" (the level in % of i_sat)"),
                )
            })?
            .extract()?;
        recs.push(LevelRecord {
            level: level / 100.0,
            r: required(d, "r", &what)?,
            u: required(d, "u", &what)?,
            y: required(d, "y", &what)?,
            i: entry(d, "i", &what)?,
            saturated_fraction: None,
        });
    }
    let noise = match &noise {
        Some(n) if !n.is_none() => Some(vec1("noise", n)?),
        _ => None,
    };
    let mut settings = FrfSettings::periodic(period_samples, skip_periods);
    settings.band = band;
    settings.quality_band = band;
    let out = py
        .detach(|| {
            amplitude_from_records(
                &recs,
                fs,
                noise.as_deref(),
                &settings,
                None,
                Recommendation::default(),
            )
        })
        .map_err(to_py)?;
    let d = PyDict::new(py);
    d.set_item("rows", rows_list(py, &out.rows)?)?;
    let plants = PyList::empty(py);
    for p in &out.plants {
        let pd = PyDict::new(py);
        pd.set_item("f_hz", p.f_hz().to_vec().into_pyarray(py))?;
        put_frds(&pd, &[("plant", p)])?;
        plants.append(pd)?;
    }
    d.set_item("plants", plants)?;
    d.set_item("recommended_pct", out.recommended_pct)?;
    d.set_item("reasoning", out.reasoning)?;
    Ok(d)
}
