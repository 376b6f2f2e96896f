//! `[machine] physical = true`: the whole-machine gray box per speed — $k_i$, $k_x$ of every
//! axis' magnet, the bending mode and its shape with intervals, from the measured 4×4 plant FRF
//! (`ambid_core::estimate::graybox::fit_machine_physical`, docs/physical.md "The whole
//! machine"), with the twin's values beside them when on the twin.

use super::machine::{note, section, MachineData};
use crate::config::MachineSection;
use crate::error::Error;
use crate::physical::{
    fit_machine_physical, machine_drawing, machine_truth, Drawing, PhysicalOptions, Rotation,
    MACHINE_AXES, MACHINE_PARAMETER_NAMES,
};
use crate::report::{format_number as fmt, Block, NoteKind, Section, Table};
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

/// The gray box at every speed of `data` (module docs). A fit that fails at one speed is
/// reported in its row; a drawing that cannot be read is an error.
///
/// # Errors
/// The drawing's read or parse error; the twin's configuration at a speed that is refused.
pub fn machine_physical(
    m: &MachineSection,
    base: &Path,
    data: &MachineData,
) -> Result<Vec<MachinePhysicalRow>, Error> {
    let drawing = drawing_of(m, base, data)?;
    let hi = MACHINE_PHYSICAL_BAND_HZ.1.min(0.3 / data.ts);
    let mut rows = Vec::with_capacity(data.speeds.len());
    for s in &data.speeds {
        let (rotation, truth) = match &data.twin {
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
        };
        let mut row = MachinePhysicalRow {
            speed_rpm: s.speed_rpm,
            band_hz: [MACHINE_PHYSICAL_BAND_HZ.0, hi],
            lines: 0,
            chi2_per_dof: f64::NAN,
            parameters: Vec::new(),
            ratios: Vec::new(),
            error: None,
        };
        let fit = s
            .frf
            .plant
            .band(MACHINE_PHYSICAL_BAND_HZ.0, hi)
            .and_then(|frd| {
                row.lines = frd.len();
                fit_machine_physical(&frd, &drawing, &rotation, &[], &PhysicalOptions::default())
            });
        match fit {
            Ok(fit) => {
                let est = fit.params.to_array();
                row.chi2_per_dof = fit.chi2 / fit.dof as f64;
                row.parameters = (0..12)
                    .map(|k| PhysicalParameterRow {
                        name: MACHINE_PARAMETER_NAMES[k].into(),
                        unit: MACHINE_PARAMETER_UNITS[k].into(),
                        estimate: est[k],
                        std: fit.std[k],
                        interval: [fit.intervals[k].0, fit.intervals[k].1],
                        twin: truth.map(|t| t[k]),
                    })
                    .collect();
                row.ratios = fit
                    .ratios()
                    .iter()
                    .zip(MACHINE_AXES)
                    .map(|((r, (lo, hi)), ax)| (ax.to_string(), *r, [*lo, *hi]))
                    .collect();
            }
            Err(e) => row.error = Some(e.to_string()),
        }
        rows.push(row);
    }
    Ok(rows)
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
            .map(|p| {
                let mut row = vec![
                    p.name.clone(),
                    p.unit.clone(),
                    fmt(p.estimate),
                    format!("{} … {}", fmt(p.interval[0]), fmt(p.interval[1])),
                ];
                if let Some(t) = p.twin {
                    row.push(fmt(t));
                    row.push(fmt(100.0 * (p.estimate / t - 1.0)));
                } else if twin {
                    row.extend(["—".into(), "—".into()]);
                }
                row
            })
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
                 parameter (docs/physical.md, \"The whole machine\"); on the nonlinear twin k_x \
                 is the best linear approximation's, above the small-signal value.",
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
    }
    section(
        "machine-physical",
        "Physical parameters (whole-machine gray box)",
        blocks,
    )
}
