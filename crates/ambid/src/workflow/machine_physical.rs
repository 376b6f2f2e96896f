//! `[machine] physical = true`: the whole-machine gray box per speed — $k_i$, $k_x$ of every
//! axis' magnet, the bending mode and its shape with intervals, from the measured 4×4 plant FRF
//! (`ambid_core::estimate::graybox::fit_machine_physical`, docs/physical.md "The whole
//! machine"), with the twin's values beside them when on the twin; with the machine's amplitude
//! study (`[machine] amplitude_levels_pct`, on by default with `physical` on the twin) the same
//! fitted at every level and extrapolated to zero amplitude
//! (`ambid_core::estimate::graybox::extrapolate_machine_to_zero_amplitude`): the small-signal
//! values of a nonlinear magnet.

use super::machine::{note, section, MachineData};
use crate::config::MachineSection;
use crate::error::Error;
use crate::physical::{
    fit_machine_physical, machine_drawing, machine_truth, Drawing, PhysicalOptions, Rotation,
    MACHINE_AXES, MACHINE_PARAMETER_NAMES,
};
use crate::report::{format_number as fmt, Block, NoteKind, Section, Table};
use ambid_core::estimate::graybox::{
    extrapolate_machine_to_zero_amplitude, MachineAtLevel, MachinePhysicalFit,
};
use ambid_twin::{Machine, MachineConfig};
use serde::Serialize;
use std::path::Path;

/// The band of the fit: the plant FRF's lines in 3 Hz … min(3 kHz, 0.3 f_s) (the band the
/// coverage of docs/physical.md was measured on; the lines are weighted by their variances).
pub const MACHINE_PHYSICAL_BAND_HZ: (f64, f64) = (3.0, 3000.0);

/// The units of [`MACHINE_PARAMETER_NAMES`].
pub const MACHINE_PARAMETER_UNITS: [&str; 12] = [
    "N/A", "N/A", "N/A", "N/A", "N/m", "N/m", "N/m", "N/m", "Hz", "-", "kg^-1/2", "kg^-1/2",
];

/// One parameter's estimate.
#[derive(Debug, Clone, Serialize)]
pub struct PhysicalParameterRow {
    /// Its name ([`MACHINE_PARAMETER_NAMES`]).
    pub name: String,
    /// Its unit.
    pub unit: String,
    /// The estimate.
    pub estimate: f64,
    /// Its standard deviation.
    pub std: f64,
    /// The 95 % interval.
    pub interval: [f64; 2],
    /// The twin's value (on the twin).
    pub twin: Option<f64>,
}

/// The parameters extrapolated to zero excitation amplitude at one speed, from the gray box
/// fitted at the identification level and at each level of the amplitude study
/// (`[machine] amplitude_levels_pct`): the small-signal $k_i$, $k_x$ of a nonlinear magnet,
/// whose estimate at a finite level is the best linear approximation's (docs/physical.md, "The
/// whole machine").
#[derive(Debug, Clone, Serialize)]
pub struct MachineZeroAmplitudeRow {
    /// The levels whose estimates entered the line \[% of i_sat\], increasing.
    pub levels_pct: Vec<f64>,
    /// The twelve parameters at zero amplitude.
    pub parameters: Vec<PhysicalParameterRow>,
    /// Per parameter: the relative change from zero amplitude to the highest level.
    pub change_at_top_level: Vec<f64>,
    /// The line's degrees of freedom (levels − 2).
    pub dof: usize,
}

/// The gray box at one speed.
#[derive(Debug, Clone, Serialize)]
pub struct MachinePhysicalRow {
    /// The speed \[rpm\].
    pub speed_rpm: f64,
    /// The band of the lines used \[Hz\].
    pub band_hz: [f64; 2],
    /// The lines used.
    pub lines: usize,
    /// $\chi^2$ per degree of freedom of the fit.
    pub chi2_per_dof: f64,
    /// The twelve parameters (empty when the fit failed).
    pub parameters: Vec<PhysicalParameterRow>,
    /// $k_i/k_x$ per axis with its interval \[m/A\] (identifiable without the drawing).
    pub ratios: Vec<(String, f64, [f64; 2])>,
    /// Why the fit failed at this speed, if it did.
    pub error: Option<String>,
    /// The parameters at zero amplitude (with an amplitude study whose estimates at two or
    /// more levels, the identification level's included, did not saturate).
    pub zero_amplitude: Option<MachineZeroAmplitudeRow>,
    /// With an amplitude study: the levels left out of the line and why, or why there is no
    /// line.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub zero_amplitude_note: Option<String>,
}

/// The drawing of the run: the twin's configuration, or `[machine] drawing` (files).
fn drawing_of(m: &MachineSection, base: &Path, data: &MachineData) -> Result<Drawing, Error> {
    if let Some(cfg) = &data.twin {
        return Ok(machine_drawing(cfg).0);
    }
    let p = m.drawing.as_ref().map(|p| base.join(p)).ok_or_else(|| {
        Error::usage("machine.physical = true with files needs machine.drawing (docs/physical.md)")
    })?;
    crate::physical::read_drawing(&p)
}

/// The table rows of an estimate, its standard deviations and intervals, beside the truth.
fn parameter_rows(
    est: &[f64; 12],
    std: &[f64; 12],
    intervals: &[(f64, f64); 12],
    truth: Option<[f64; 12]>,
) -> Vec<PhysicalParameterRow> {
    (0..12)
        .map(|k| PhysicalParameterRow {
            name: MACHINE_PARAMETER_NAMES[k].into(),
            unit: MACHINE_PARAMETER_UNITS[k].into(),
            estimate: est[k],
            std: std[k],
            interval: [intervals[k].0, intervals[k].1],
            twin: truth.map(|t| t[k]),
        })
        .collect()
}

/// One gray-box fit of the run: the speed's index and the study level's (`None`: the
/// identification FRF).
type Job = (usize, Option<usize>);

/// The line through the estimates at the levels of one speed (`fits`: level \[%\], its
/// saturated fraction if known, the fit or why it failed), or why there is none. The levels'
/// unit is %, so the change at the top level is in the same unit.
fn zero_amplitude(
    fits: &[(f64, Option<f64>, Result<&MachinePhysicalFit, &str>)],
    truth: Option<[f64; 12]>,
) -> (Option<MachineZeroAmplitudeRow>, Option<String>) {
    let mut points = Vec::new();
    let mut left_out = Vec::new();
    for (pct, sat, fit) in fits {
        match (sat, fit) {
            // a saturated record is outside the small-amplitude law
            (Some(f), _) if *f > 0.0 => left_out.push(format!(
                "{} % ({:.2e} % of its samples saturated)",
                fmt(*pct),
                100.0 * f
            )),
            (_, Err(e)) => left_out.push(format!("{} % (the fit failed: {e})", fmt(*pct))),
            (_, Ok(f)) => points.push(MachineAtLevel {
                level: *pct,
                params: f.params,
                std: f.std,
            }),
        }
    }
    let left = if left_out.is_empty() {
        String::new()
    } else {
        format!("levels left out: {}", left_out.join("; "))
    };
    points.sort_by(|a, b| a.level.total_cmp(&b.level));
    let confidence = fits
        .iter()
        .find_map(|(_, _, f)| f.ok().map(|f| f.confidence))
        .unwrap_or(0.95);
    match extrapolate_machine_to_zero_amplitude(&points, confidence) {
        Ok(z) => {
            let top = points.last().map_or(0.0, |p| p.level);
            let row = MachineZeroAmplitudeRow {
                levels_pct: points.iter().map(|p| p.level).collect(),
                parameters: parameter_rows(&z.params.to_array(), &z.std, &z.intervals, truth),
                change_at_top_level: z.change_at(top).to_vec(),
                dof: z.dof,
            };
            (Some(row), (!left.is_empty()).then(|| format!("{left}.")))
        }
        Err(e) => (
            None,
            Some(format!(
                "no extrapolation to zero amplitude ({e}){}{left}.",
                if left.is_empty() { "" } else { "; " }
            )),
        ),
    }
}

/// The gray box at every speed of `data` (module docs) and, where the speed has an amplitude
/// study, the parameters extrapolated to zero amplitude; the identification level's fits run
/// in parallel over the speeds, then the study levels' in parallel, each started from its
/// speed's bending mode at the identification level. A fit that fails at one speed is reported in its row; a drawing that cannot be
/// read is an error.
///
/// # Errors
/// The drawing's read or parse error; the twin's configuration at a speed that is refused.
pub fn machine_physical(
    m: &MachineSection,
    base: &Path,
    data: &MachineData,
) -> Result<Vec<MachinePhysicalRow>, Error> {
    use rayon::prelude::*;
    let drawing = drawing_of(m, base, data)?;
    let band = (
        MACHINE_PHYSICAL_BAND_HZ.0,
        MACHINE_PHYSICAL_BAND_HZ.1.min(0.3 / data.ts),
    );
    let mut setup = Vec::with_capacity(data.speeds.len());
    for s in &data.speeds {
        setup.push(match &data.twin {
            Some(cfg) => {
                let at = MachineConfig {
                    speed_rpm: s.speed_rpm,
                    ..cfg.clone()
                };
                let truth = machine_truth(&Machine::new(at.clone())?).to_array();
                (machine_drawing(&at).1, Some(truth))
            }
            None => (
                Rotation {
                    speed_rpm: s.speed_rpm,
                    polar_inertia_kgm2: m.polar_inertia_kgm2.unwrap_or(0.0),
                },
                None,
            ),
        });
    }
    let fit_one = |(i, l): Job, bending: &[(f64, f64)]| {
        let s = &data.speeds[i];
        let plant = l.map_or(&s.frf.plant, |l| &s.amplitude[l].plant);
        let mut lines = 0;
        let fit = plant
            .band(band.0, band.1)
            .and_then(|frd| {
                lines = frd.len();
                fit_machine_physical(
                    &frd,
                    &drawing,
                    &setup[i].0,
                    bending,
                    &PhysicalOptions::default(),
                )
            })
            .map_err(|e| e.to_string());
        ((i, l), lines, fit)
    };
    // the identification level's fits (speeds in parallel), then the study's levels (all in
    // parallel), each started from its speed's bending mode at the identification level (the
    // level moves it by hundredths of a per cent), else from the search
    let mut fits: Vec<(Job, usize, Result<MachinePhysicalFit, String>)> = (0..data.speeds.len())
        .into_par_iter()
        .map(|i| fit_one((i, None), &[]))
        .collect();
    let level_jobs: Vec<(Job, Vec<(f64, f64)>)> = fits
        .iter()
        .flat_map(|((i, _), _, fit)| {
            let hint: Vec<(f64, f64)> = fit
                .as_ref()
                .map(|f| vec![(f.params.bending_hz, f.params.bending_damping)])
                .unwrap_or_default();
            (0..data.speeds[*i].amplitude.len()).map(move |l| ((*i, Some(l)), hint.clone()))
        })
        .collect();
    fits.extend(
        level_jobs
            .into_par_iter()
            .map(|(job, hint)| fit_one(job, &hint))
            .collect::<Vec<_>>(),
    );
    let mut rows = Vec::with_capacity(data.speeds.len());
    for (i, s) in data.speeds.iter().enumerate() {
        let truth = setup[i].1;
        let mut row = MachinePhysicalRow {
            speed_rpm: s.speed_rpm,
            band_hz: [band.0, band.1],
            lines: 0,
            chi2_per_dof: f64::NAN,
            parameters: Vec::new(),
            ratios: Vec::new(),
            error: None,
            zero_amplitude: None,
            zero_amplitude_note: None,
        };
        let mine: Vec<&(Job, usize, Result<MachinePhysicalFit, String>)> =
            fits.iter().filter(|((k, _), _, _)| *k == i).collect();
        if let Some((_, lines, fit)) = mine.iter().find(|((_, l), _, _)| l.is_none()) {
            row.lines = *lines;
            match fit {
                Ok(fit) => {
                    row.chi2_per_dof = fit.chi2 / fit.dof as f64;
                    row.parameters =
                        parameter_rows(&fit.params.to_array(), &fit.std, &fit.intervals, truth);
                    row.ratios = fit
                        .ratios()
                        .iter()
                        .zip(MACHINE_AXES)
                        .map(|((r, (lo, hi)), ax)| (ax.to_string(), *r, [*lo, *hi]))
                        .collect();
                }
                Err(e) => row.error = Some(e.clone()),
            }
        }
        if !s.amplitude.is_empty() {
            let at: Vec<(f64, Option<f64>, Result<&MachinePhysicalFit, &str>)> = mine
                .iter()
                .filter_map(|((_, l), _, fit)| {
                    let (pct, sat) = match l {
                        None => (s.level_pct?, s.saturated_fraction),
                        Some(l) => (
                            s.amplitude[*l].level_pct,
                            Some(s.amplitude[*l].saturated_fraction),
                        ),
                    };
                    Some((pct, sat, fit.as_ref().map_err(String::as_str)))
                })
                .collect();
            (row.zero_amplitude, row.zero_amplitude_note) = zero_amplitude(&at, truth);
        }
        rows.push(row);
    }
    Ok(rows)
}

/// A parameter's table cells: name, unit, estimate, interval, `extra` when given, and with
/// `twin` the twin's value and the error in % (dashes where the parameter has none).
fn parameter_cells(p: &PhysicalParameterRow, extra: Option<String>, twin: bool) -> Vec<String> {
    let mut row = vec![
        p.name.clone(),
        p.unit.clone(),
        fmt(p.estimate),
        format!("{} … {}", fmt(p.interval[0]), fmt(p.interval[1])),
    ];
    row.extend(extra);
    if let Some(t) = p.twin {
        row.push(fmt(t));
        row.push(fmt(100.0 * (p.estimate / t - 1.0)));
    } else if twin {
        row.extend(["—".into(), "—".into()]);
    }
    row
}

/// The report section of the rows.
pub fn physical_section(rows: &[MachinePhysicalRow]) -> Section {
    let mut blocks = Vec::new();
    for r in rows {
        if let Some(e) = &r.error {
            blocks.push(note(
                NoteKind::Warning,
                format!(
                    "Physical parameters at {} rpm: the gray-box fit failed ({e}).",
                    fmt(r.speed_rpm)
                ),
            ));
            continue;
        }
        let twin = r.parameters.iter().any(|p| p.twin.is_some());
        let mut header: Vec<String> = ["parameter", "unit", "estimate", "95 % interval"]
            .map(String::from)
            .to_vec();
        if twin {
            header.push("twin".into());
            header.push("error [%]".into());
        }
        let mut table_rows: Vec<Vec<String>> = r
            .parameters
            .iter()
            .map(|p| parameter_cells(p, None, twin))
            .collect();
        for (ax, v, iv) in &r.ratios {
            let mut row = vec![
                format!("k_i/k_x {ax}"),
                "m/A".into(),
                fmt(*v),
                format!("{} … {}", fmt(iv[0]), fmt(iv[1])),
            ];
            if twin {
                let t = r
                    .parameters
                    .iter()
                    .find(|p| p.name == format!("k_i_{ax}"))
                    .zip(r.parameters.iter().find(|p| p.name == format!("k_x_{ax}")))
                    .and_then(|(i, x)| Some(i.twin? / x.twin?));
                row.push(t.map_or("—".into(), fmt));
                row.push(t.map_or("—".into(), |t| fmt(100.0 * (v / t - 1.0))));
            }
            table_rows.push(row);
        }
        blocks.push(Block::Table(Table {
            id: format!("machine-physical-{:.0}rpm", r.speed_rpm),
            caption: format!(
                "Physical parameters at {} rpm by the whole-machine gray box (rigid rotor with \
                 gyroscopics, free–free bending mode, one magnet per axis, amplifiers, sensors, \
                 ZOH and delay; all loops open) fitted to the 4×4 plant FRF on {} lines in {}–{} \
                 Hz, χ²/dof {}. k_i/k_x per axis is identifiable without the drawing; the values \
                 themselves need its mass, inertia and bearing positions. Coverage of the 95 % \
                 intervals on 200 random asymmetric linear-twin machines: 0.91–0.99 per \
                 parameter (docs/physical.md, \"The whole machine\"). At a finite excitation \
                 level a nonlinear magnet's k_x is the best linear approximation's, above the \
                 small-signal value: the table at zero amplitude (with an amplitude study) \
                 removes that bias.",
                fmt(r.speed_rpm),
                r.lines,
                fmt(r.band_hz[0]),
                fmt(r.band_hz[1]),
                fmt(r.chi2_per_dof)
            ),
            header,
            rows: table_rows,
            highlight: None,
        }));
        blocks.extend(zero_amplitude_blocks(r));
    }
    section(
        "machine-physical",
        "Physical parameters (whole-machine gray box)",
        blocks,
    )
}

/// The report blocks of a row's extrapolation to zero amplitude: a note when the study gave
/// none or left levels out, the table when there is one.
fn zero_amplitude_blocks(r: &MachinePhysicalRow) -> Vec<Block> {
    let mut blocks = Vec::new();
    if let Some(n) = &r.zero_amplitude_note {
        let kind = if r.zero_amplitude.is_some() {
            NoteKind::Info
        } else {
            NoteKind::Warning
        };
        blocks.push(note(
            kind,
            format!("Physical parameters at {} rpm: {n}", fmt(r.speed_rpm)),
        ));
    }
    let Some(z) = &r.zero_amplitude else {
        return blocks;
    };
    let twin = z.parameters.iter().any(|p| p.twin.is_some());
    let top = z.levels_pct.last().copied().unwrap_or(f64::NAN);
    let mut header: Vec<String> = vec![
        "parameter".into(),
        "unit".into(),
        "at zero amplitude".into(),
        "95 % interval".into(),
        format!("change at {} % [%]", fmt(top)),
    ];
    if twin {
        header.push("twin".into());
        header.push("error [%]".into());
    }
    let rows = z
        .parameters
        .iter()
        .zip(&z.change_at_top_level)
        .map(|(p, c)| parameter_cells(p, Some(format!("{:+.3}", 100.0 * c)), twin))
        .collect();
    blocks.push(Block::Table(Table {
        id: format!("machine-physical-zero-{:.0}rpm", r.speed_rpm),
        caption: format!(
            "Physical parameters at {} rpm extrapolated to zero excitation amplitude: the gray box \
             fitted to the plant FRF at each of {} levels ({} % of i_sat, the identification \
             level's and the amplitude study's, on the same lines) and each parameter's weighted \
             straight line in level² (in ln p for the positive ones) taken to zero, with 95 % \
             intervals. These are the small-signal values a controller is designed on; the change \
             column is how far the top level moved each one (docs/physical.md, \"The whole \
             machine\").",
            fmt(r.speed_rpm),
            z.levels_pct.len(),
            z.levels_pct
                .iter()
                .map(|l| fmt(*l))
                .collect::<Vec<_>>()
                .join(", ")
        ),
        header,
        rows,
        highlight: None,
    }));
    blocks
}
