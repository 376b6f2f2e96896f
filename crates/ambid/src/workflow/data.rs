//! The workflow's data: the twin, or recorded files read through [`crate::io::table`].

use super::config::{ColumnSpec, SourceKind, WorkflowConfig};
use super::{computation, input, Ctx, Error};
use crate::error::Context;
use crate::io::table::{ReadOptions, Table};
use crate::io::ControllerModel;
use crate::report::{Block, NoteKind, Section, Table as RTable};
use ambid_core::data::{detrend, Detrend};
use ambid_twin::{Mode, Twin, TwinConfig};
use std::path::Path;

pub use crate::stage::{excitation_kind, Recording, Signals, TwinSource};

pub struct Prepared {
    pub twin: Option<TwinSource>,
    pub ident: Option<Recording>,
    pub valid: Option<Recording>,
    pub controller: Option<ControllerModel>,
}

/// Reads the data (files) or builds the twin.
pub fn prepare(cfg: &WorkflowConfig, base: &Path) -> Result<Prepared, Error> {
    match cfg.source {
        SourceKind::Twin => {
            let mut tc = match &cfg.twin.config {
                Some(p) => {
                    let path = base.join(p);
                    let text = std::fs::read_to_string(&path).map_err(|e| {
                        Error::input(format!(
                            "{}: cannot read the twin configuration: {e}",
                            path.display()
                        ))
                    })?;
                    TwinConfig::from_toml_str(&text)
                        .with_context(|| {
                            format!("{}: not a valid twin configuration", path.display())
                        })
                        .map_err(input)?
                }
                None => TwinConfig::default(),
            };
            if let Some(n) = cfg.twin.noise_rms_um {
                tc.sensor.noise_rms_m = n * 1e-6;
            }
            let mode = if cfg.twin.mode == "linear" {
                Mode::Linear
            } else {
                Mode::Nonlinear
            };
            let twin = Twin::new(tc.clone())
                .context("building the twin")
                .map_err(input)?;
            let controller =
                ControllerModel::new(twin.controller().clone(), "the twin's discrete PID (exact)")
                    .map_err(computation)?;
            Ok(Prepared {
                twin: Some(TwinSource {
                    noise: tc.sensor.noise_rms_m > 0.0,
                    cfg: tc,
                    mode,
                    twin,
                }),
                ident: None,
                valid: None,
                controller: Some(controller),
            })
        }
        SourceKind::Files => {
            let d = &cfg.data;
            let ident_path = d
                .identification
                .as_ref()
                .ok_or_else(|| Error::input("[data] identification is missing"))?;
            let mut ident = load_file(cfg, base, ident_path, "identification")?;
            let mut valid = match &d.validation {
                Some(p) => Some(load_file(cfg, base, p, "validation")?),
                None => None,
            };
            let kind = match d.detrend.as_str() {
                "linear" => Detrend::Linear,
                "none" => Detrend::None,
                _ => Detrend::Mean,
            };
            if d.detrend_scope == "record" {
                // the whole identification record (before any split), like MATLAB's detrend(data)
                detrend_pair(&mut ident, None, kind)?;
            }
            if valid.is_none() {
                let n = ident.len();
                let k = ((n as f64) * d.split).floor() as usize;
                if k < 50 || n - k < 50 {
                    return Err(Error::input(format!(
                        "{}: {n} samples are too few to split into estimation and validation (split = {}); give a [data] validation file",
                        ident.source, d.split
                    )));
                }
                let (a, b) = split(&ident, k)?;
                ident = a;
                valid = Some(b);
            }
            match d.detrend_scope.as_str() {
                // the estimation part's mean (or line) is removed from both records
                "estimation" => detrend_pair(&mut ident, valid.as_mut(), kind)?,
                // each record by its own
                "each" => {
                    detrend_pair(&mut ident, None, kind)?;
                    if let Some(v) = valid.as_mut() {
                        detrend_pair(v, None, kind)?;
                    }
                }
                _ => {
                    if let Some(v) = valid.as_mut().filter(|_| d.validation.is_some()) {
                        detrend_pair(v, None, kind)?;
                    }
                }
            }
            let controller = match &d.controller {
                Some(p) => {
                    let path = base.join(p);
                    let c = crate::io::read_controller(&path).map_err(input)?;
                    c.check_ts(ident.ts())
                        .with_context(|| format!("{}", path.display()))
                        .map_err(input)?;
                    Some(c)
                }
                None => None,
            };
            let closed = d
                .closed_loop
                .unwrap_or(ident.r().is_some() || controller.is_some());
            ident.closed_loop = closed;
            if let Some(v) = valid.as_mut() {
                v.closed_loop = closed;
            }
            Ok(Prepared {
                twin: None,
                ident: Some(ident),
                valid,
                controller,
            })
        }
    }
}

fn split(rec: &Recording, k: usize) -> Result<(Recording, Recording), Error> {
    let part = |range: (usize, usize), what: &str| -> Result<Recording, Error> {
        Ok(Recording {
            data: rec.data.slice(range.0, range.1).map_err(input)?,
            closed_loop: rec.closed_loop,
            source: format!("{} ({what})", rec.source),
            saturated_fraction: None,
            notes: rec.notes.clone(),
        })
    };
    Ok((
        part((0, k), &format!("samples 1–{k}, estimation"))?,
        part(
            (k, rec.len()),
            &format!("samples {}–{}, validation", k + 1, rec.len()),
        )?,
    ))
}

fn detrend_pair(a: &mut Recording, b: Option<&mut Recording>, kind: Detrend) -> Result<(), Error> {
    if kind == Detrend::None {
        return Ok(());
    }
    let mut offsets = Vec::new();
    let mut sa = a.signals();
    for (name, x) in [("u", &mut sa.u), ("y", &mut sa.y)]
        .into_iter()
        .chain(sa.i.as_mut().map(|i| ("i", i)))
    {
        let (d, rep) = detrend(x, kind)
            .with_context(|| format!("{}: detrending `{name}`", a.source))
            .map_err(input)?;
        *x = d;
        offsets.push((name, rep));
    }
    *a = a.with_signals(sa)?;
    if let Some(b) = b {
        let mut sb = b.signals();
        for (name, rep) in offsets {
            let x = match name {
                "u" => &mut sb.u,
                "y" => &mut sb.y,
                _ => match sb.i.as_mut() {
                    Some(i) => i,
                    None => continue,
                },
            };
            if kind == Detrend::Mean {
                x.iter_mut().for_each(|v| *v -= rep.offset);
            } else {
                let (d, _) = detrend(x, kind)
                    .with_context(|| format!("{}: detrending `{name}`", b.source))
                    .map_err(input)?;
                *x = d;
            }
        }
        *b = b.with_signals(sb)?;
    }
    Ok(())
}

/// How a column spec is written in the workflow file (`y`, `#3`).
fn spec_name(spec: &ColumnSpec) -> String {
    spec.to_ref().to_string()
}

pub fn load_file(
    cfg: &WorkflowConfig,
    base: &Path,
    rel: &Path,
    what: &str,
) -> Result<Recording, Error> {
    let d = &cfg.data;
    let path = base.join(rel);
    let opts = ReadOptions {
        variable: d.variable.clone(),
        ..ReadOptions::default()
    };
    // the window ([data] from/to) and, for TDMS and MAT v7.3 files, only the columns named in
    // [data] and those taken by name below (nothing else of the file is read)
    let bound = |b: &Option<crate::config::BoundSpec>, key: &str| -> Result<_, Error> {
        b.as_ref()
            .map(|b| {
                b.to_bound()
                    .map_err(|e| Error::input(format!("[data] {key}: {e}")))
            })
            .transpose()
    };
    let (from, to) = (bound(&d.from, "from")?, bound(&d.to, "to")?);
    let specs: Vec<&ColumnSpec> = [&d.time, &d.r, &d.i, &d.w]
        .into_iter()
        .flatten()
        .chain([&d.u, &d.y])
        .collect();
    let mut wanted: Vec<String> = specs.iter().map(|s| spec_name(s)).collect();
    wanted.extend(["t", "r", "i", "w"].map(String::from));
    let part = crate::io::time::read_part(
        &path,
        &crate::io::TimeOptions {
            fs_hz: d.fs_hz,
            time: d.time.as_ref().map(ColumnSpec::to_ref),
            read: opts,
            window: (from.is_some() || to.is_some())
                .then_some(crate::io::time::Window { from, to }),
            columns: Some(wanted),
        },
    )
    .map_err(input)?;
    let table = part.table;
    // rows are counted in the file: the window's first row is added to positions in messages
    let row0 = part.first_row;
    // a file read in part has only some columns: `#k` specs become the names they selected
    let aliases = part.aliases.unwrap_or_default();
    let fix = |s: &ColumnSpec| -> ColumnSpec {
        match aliases.iter().find(|(w, _)| *w == spec_name(s)) {
            Some((_, k)) => ColumnSpec::Name(table.names[*k].clone()),
            None => s.clone(),
        }
    };
    let fixed = |s: &Option<ColumnSpec>| s.as_ref().map(fix);
    let (d_time, d_r, d_i, d_w, d_u, d_y) = (
        fixed(&d.time),
        fixed(&d.r),
        fixed(&d.i),
        fixed(&d.w),
        fix(&d.u),
        fix(&d.y),
    );
    // a channel not named in [data] is taken from a column with exactly its name, when there is one
    let mut notes = Vec::new();
    let has = |name: &str| {
        table
            .index_of(&ColumnSpec::Name(name.into()).to_ref())
            .is_ok()
    };
    let mut auto = |name: &str, spec: &Option<ColumnSpec>| -> Option<ColumnSpec> {
        match spec {
            Some(s) => Some(s.clone()),
            None if has(name) => {
                notes.push(name.to_string());
                Some(ColumnSpec::Name(name.into()))
            }
            None => None,
        }
    };
    let time = if d.fs_hz.is_none() {
        auto("t", &d_time)
    } else {
        d_time.clone()
    };
    let (r_spec, i_spec, w_spec) = (auto("r", &d_r), auto("i", &d_i), auto("w", &d_w));
    let notes = if notes.is_empty() {
        Vec::new()
    } else {
        vec![format!(
            "{}: column(s) {} taken by name (not named in [data]); name them (or set [data] closed_loop) to change this",
            path.display(),
            notes
                .iter()
                .map(|n| format!("`{n}`"))
                .collect::<Vec<_>>()
                .join(", ")
        )]
    };
    // the sample rate: the time column, `fs`, else the file's own metadata (TDMS wf_increment)
    let fs = d.fs_hz.or(if time.is_none() {
        table.ts_metadata.map(|ts| 1.0 / ts)
    } else {
        None
    });
    let ts = table
        .sample_time(time.as_ref().map(ColumnSpec::to_ref).as_ref(), fs)
        .map_err(input)?;
    let col = |name: &str, spec: &ColumnSpec| -> Result<Vec<f64>, Error> {
        let x = table.column(&spec.to_ref()).map_err(input)?;
        let scale = d.scale.get(name).copied().unwrap_or(1.0);
        let skip = d.skip_samples;
        if skip + 2 >= x.len() {
            return Err(Error::input(format!(
                "{}: skip_samples = {skip} leaves no data ({} samples)",
                path.display(),
                x.len()
            )));
        }
        let v: Vec<f64> = x[skip..].iter().map(|v| v * scale).collect();
        if let Some(k) = v.iter().position(|v| !v.is_finite()) {
            return Err(Error::input(format!(
                "{}: column `{}` (`{name}`), data row {} (counted after the header, without comment lines): the value is {}; repair the sample, or cut the record with [data] skip_samples",
                path.display(),
                spec_name(spec),
                k + skip + row0 + 1,
                if x[k + skip].is_nan() { "missing or NaN".to_string() } else { format!("{}", x[k + skip]) }
            )));
        }
        let max = crate::io::csv::MAX_SAMPLE_MAGNITUDE;
        if let Some(k) = v.iter().position(|v| v.abs() > max) {
            return Err(Error::input(format!(
                "{}: column `{}` (`{name}`), data row {}: {:.6e} is beyond ±{max:e}, where sums of squares overflow; check the column's units or [data] scale",
                path.display(),
                spec_name(spec),
                k + skip + row0 + 1,
                v[k]
            )));
        }
        Ok(v)
    };
    let opt = |name: &str, spec: &Option<ColumnSpec>| -> Result<Option<Vec<f64>>, Error> {
        spec.as_ref().map(|s| col(name, s)).transpose()
    };
    let r = opt("r", &r_spec)?;
    // the period: [data] period_samples, else the smallest lag at which `r` repeats exactly
    // (ambid_core::signal::PeriodScan, as `ambid frf` finds it), unless the FRF is Welch's
    let mut notes = notes;
    let period = match (d.period_samples, &r) {
        (Some(p), _) => Some(p),
        (None, Some(r)) if cfg.frf.method != "welch" => {
            let found = ambid_core::signal::PeriodScan::of(r);
            if let Some(p) = found {
                notes.push(format!(
                    "{}: the excitation `r` repeats every {p} samples ({} periods): the FRF averages \
                     periods; set [data] period_samples to override, or [frf] method = \"welch\"",
                    path.display(),
                    r.len() / p
                ));
            }
            found
        }
        _ => None,
    };
    let rec = Recording {
        notes,
        ..Recording::from_signals(
            ts,
            period,
            Signals {
                r,
                u: col("u", &d_u)?,
                y: col("y", &d_y)?,
                i: opt("i", &i_spec)?,
                w: opt("w", &w_spec)?,
            },
            false,
            format!("{} ({what})", path.display()),
        )?
    };
    let _: &Table = &table;
    Ok(rec)
}

/// The report's data section.
pub fn describe(ctx: &mut Ctx<'_>) -> Section {
    let mut blocks = Vec::new();
    match ctx.cfg.source {
        SourceKind::Twin => {
            let t = ctx.twin.as_ref();
            let (fs, isat, noise, mode) = t.map_or((f64::NAN, f64::NAN, f64::NAN, "?"), |t| {
                (
                    t.twin.fs(),
                    t.twin.i_sat(),
                    t.cfg.sensor.noise_rms_m,
                    if t.mode == Mode::Linear {
                        "linear"
                    } else {
                        "nonlinear"
                    },
                )
            });
            ctx.typed.data = Some(super::DataSummary {
                source: Some("twin".into()),
                fs_hz: Some(fs),
                i_sat_a: Some(isat),
                noise_rms_m: Some(noise),
                ..Default::default()
            });
            blocks.push(Block::Text(format!(
                "Data come from ambid's embedded AMB digital twin ({mode} physics): rigid rotor on two \
                 radial bearings with a bending mode near 780 Hz, magnet force law, amplifier lag and \
                 saturation, sensor noise {} µm RMS, one-sample computation delay and the discrete PID \
                 at {} Hz. The twin also knows its exact linearised plant, which the report shows as \
                 \"truth\" wherever an estimate can be checked against it. Amplifier saturation \
                 current i_sat = {} A.",
                crate::report::format_number(noise * 1e6),
                crate::report::format_number(fs),
                crate::report::format_number(isat),
            )));
        }
        SourceKind::Files => {
            let mut rows = Vec::new();
            for r in [ctx.ident.as_ref(), ctx.valid.as_ref()]
                .into_iter()
                .flatten()
            {
                rows.push(vec![
                    r.source.clone(),
                    r.len().to_string(),
                    crate::report::format_number(r.fs()),
                    [
                        r.r().as_ref().map(|_| "r"),
                        Some("u"),
                        Some("y"),
                        r.i().as_ref().map(|_| "i"),
                        r.w().as_ref().map(|_| "w"),
                    ]
                    .into_iter()
                    .flatten()
                    .collect::<Vec<_>>()
                    .join(", "),
                ]);
            }
            if let Some(r) = ctx.ident.as_ref() {
                let closed = r.closed_loop;
                let (n, fs) = (r.len(), r.fs());
                let d = ctx.typed.data.get_or_insert_with(Default::default);
                d.source = Some("files".into());
                d.fs_hz = Some(fs);
                d.identification_samples = Some(n as f64);
                d.closed_loop = Some(closed);
            }
            if let Some(v) = ctx.valid.as_ref() {
                let n = v.len();
                ctx.typed
                    .data
                    .get_or_insert_with(Default::default)
                    .validation_samples = Some(n as f64);
            }
            blocks.push(Block::Table(RTable {
                id: "data".into(),
                caption: format!(
                    "Records read (after dropping {} leading samples, scaling to SI and removing the \
                     estimation part's {}).",
                    ctx.cfg.data.skip_samples, ctx.cfg.data.detrend
                ),
                header: vec![
                    "record".into(),
                    "samples".into(),
                    "fs [Hz]".into(),
                    "channels".into(),
                ],
                rows,
                highlight: None,
            }));
            let notes: Vec<String> = [ctx.ident.as_ref(), ctx.valid.as_ref()]
                .into_iter()
                .flatten()
                .flat_map(|r| r.notes.iter().cloned())
                .collect();
            for n in notes {
                blocks.push(Ctx::note(NoteKind::Info, n));
            }
            let (yu, uu) = units(ctx);
            blocks.push(Ctx::note(
                NoteKind::Info,
                format!(
                    "Units: y in {yu}, u in {uu} ([data] y_unit / u_unit); plant magnitudes in {}.",
                    plant_unit(ctx)
                ),
            ));
            let cl = ctx.is_closed_loop();
            let has_r = ctx.ident.as_ref().is_some_and(|r| r.r().is_some());
            blocks.push(note_of(match (cl, has_r, ctx.controller.is_some()) {
                (false, _, _) => (NoteKind::Info, "Open-loop data: the FRF is the H1 estimate u → y; the closed-loop steps (closed-loop validation, reconstruction, ISO zone) are skipped.".to_string()),
                (true, false, _) => (NoteKind::Warning, "Closed-loop data without a recorded excitation r: the plant can only be estimated by the direct method (u → y), which is biased by the feedback of the noise; treat the FRF and the models with care.".to_string()),
                (true, true, false) => (NoteKind::Info, "Closed-loop data with the excitation r: joint input-output FRF; no controller file, so the closed-loop validation steps are skipped.".to_string()),
                (true, true, true) => (NoteKind::Info, "Closed-loop data with the excitation r and the controller: every step can run.".to_string()),
            }));
        }
    }
    Section {
        id: "data".into(),
        title: "Data".into(),
        blocks,
    }
}

/// The units of y and u: the twin's m and A, or the declared `[data] y_unit` / `u_unit`, or
/// "unit not given".
pub fn units(ctx: &Ctx<'_>) -> (String, String) {
    if ctx.twin.is_some() {
        return ("m".into(), "A".into());
    }
    let d = &ctx.cfg.data;
    let given = |u: &Option<String>| u.clone().unwrap_or_else(|| "unit not given".into());
    (given(&d.y_unit), given(&d.u_unit))
}

/// The unit of a plant magnitude |y/u|: `m/A`, or "unit not given" when either is unknown.
pub fn plant_unit(ctx: &Ctx<'_>) -> String {
    let d = &ctx.cfg.data;
    match (&ctx.twin, &d.y_unit, &d.u_unit) {
        (Some(_), _, _) => "m/A".into(),
        (None, Some(y), Some(u)) => format!("{y}/{u}"),
        _ => "unit not given".into(),
    }
}

/// The units the report labels its axes and tables with (what a section renderer needs besides
/// its stage's typed result).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Units {
    /// Unit of y ([`units`]).
    pub y: String,
    /// Unit of u ([`units`]).
    pub u: String,
    /// Unit of a plant magnitude |y/u| ([`plant_unit`]).
    pub plant: String,
}

impl Units {
    /// The units of the run's data.
    pub fn of(ctx: &Ctx<'_>) -> Self {
        let (y, u) = units(ctx);
        Self {
            y,
            u,
            plant: plant_unit(ctx),
        }
    }
}

fn note_of((kind, text): (NoteKind, String)) -> Block {
    Ctx::note(kind, text)
}
