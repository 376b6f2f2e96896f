//! The report's whole-machine sections, rendered from the typed data of
//! [`super::machine`]: the 4×4 Bode matrix, the cross-coupling against speed, the Campbell
//! diagram, the MIMO comparison table, the per-axis validation and the ISO 14839-3 table.
//! Nothing is estimated here; every renderer is a pure function of plain structs (tested with
//! constructed inputs).

use super::machine::{
    coupling, iso_rows, note, section, whirl_str, AxisValidationRow, ComparisonRow, Coupling,
    IsoRow, MachineData, MachineModelOutput, MachineSummary, ModePoint,
};
use crate::config::MachineSection;
use crate::error::Error;
use crate::report::{
    format_number as fmt, Axis, Block, Figure, Marker, NoteKind, Panel, PanelContent, Scale,
    Section, Series, Style, Table,
};
use ambid_core::data::AXES;
use ambid_core::lti::Frd;
use ambid_core::validate::iso::{IsoZones, Zone};
use ambid_twin::Whirl;

/// One curve of a Bode-matrix panel set: a 4×4 response and how to draw it.
#[derive(Debug, Clone, Copy)]
pub struct BodeLayer<'a> {
    /// Legend name.
    pub name: &'a str,
    /// The 4×4 response.
    pub frd: &'a Frd,
    /// Dashed (truth, model) or solid (measurement).
    pub dashed: bool,
    /// Draw its ±2σ band (from the per-entry variance) when it has one.
    pub band: bool,
    /// Palette index.
    pub color: usize,
}

fn log_axis(label: &str) -> Axis {
    Axis {
        label: label.into(),
        scale: Scale::Log,
        range: None,
    }
}

fn lin_axis(label: &str) -> Axis {
    Axis {
        label: label.into(),
        scale: Scale::Linear,
        range: None,
    }
}

/// The 4×4 Bode matrix (magnitude) of one speed: 16 panels, row = output, column = input (axis
/// order `xa, xb, ya, yb`), each with every layer's $|G_{ij}|$ and, for a layer with
/// variances, the band $|G_{ij}| \pm 2\sigma_{ij}$ (lower edge clipped at 1 % of $|G_{ij}|$ on
/// the log axis).
///
/// # Errors
/// When a layer is not 4×4.
pub fn bode_matrix(
    id: &str,
    title: &str,
    caption: &str,
    layers: &[BodeLayer<'_>],
) -> Result<Figure, Error> {
    let mut panels = Vec::with_capacity(16);
    for l in layers {
        if l.frd.ny() != 4 || l.frd.nu() != 4 {
            return Err(Error::computation(format!(
                "the Bode matrix needs 4×4 responses; `{}` is {}×{}",
                l.name,
                l.frd.ny(),
                l.frd.nu()
            )));
        }
    }
    for (i, out_ax) in AXES.iter().enumerate() {
        for (j, in_ax) in AXES.iter().enumerate() {
            let mut series = Vec::new();
            for l in layers {
                let g = l.frd.entry(i, j)?;
                let f = g.f_hz().to_vec();
                let mag = g.magnitude();
                if l.band {
                    if let Some(sd) = g.std() {
                        let upper: Vec<f64> =
                            mag.iter().zip(&sd).map(|(m, s)| m + 2.0 * s).collect();
                        let lower: Vec<f64> = mag
                            .iter()
                            .zip(&sd)
                            .map(|(m, s)| (m - 2.0 * s).max(0.01 * m))
                            .collect();
                        series.push(Series {
                            name: format!("{} ±2σ", l.name),
                            x: f.clone(),
                            y: upper,
                            style: Style::Band { lower },
                            color: Some(l.color),
                        });
                    }
                }
                series.push(Series {
                    name: l.name.to_string(),
                    x: f,
                    y: mag,
                    style: if l.dashed { Style::Dashed } else { Style::Line },
                    color: Some(l.color),
                });
            }
            panels.push(Panel {
                title: format!("{out_ax} ← {in_ax}"),
                x: log_axis("frequency [Hz]"),
                y: log_axis(&format!("|P {out_ax}←{in_ax}| [m/A]")),
                content: PanelContent::Xy(series),
                spans: vec![],
                equal_aspect: false,
            });
        }
    }
    Ok(Figure {
        id: id.into(),
        title: title.into(),
        caption: caption.into(),
        panels,
        columns: 4,
    })
}

/// The cross-coupling against speed ([`super::machine::coupling`]): x–y and A–B, median and
/// largest over the band, measured (solid) and the twin's exact plant (dashed) when given.
pub fn coupling_figure(measured: &[Coupling], truth: &[Coupling], band: [f64; 2]) -> Figure {
    let mut series = Vec::new();
    let sp = |c: &[Coupling]| c.iter().map(|c| c.speed_rpm).collect::<Vec<_>>();
    for (name, pick, color) in [
        (
            "x–y median",
            (|c: &Coupling| c.xy_median) as fn(&Coupling) -> f64,
            0usize,
        ),
        ("x–y max", |c: &Coupling| c.xy_max, 1),
        ("A–B median", |c: &Coupling| c.ab_median, 2),
        ("A–B max", |c: &Coupling| c.ab_max, 3),
    ] {
        series.push(Series {
            name: format!("{name} (measured)"),
            x: sp(measured),
            y: measured.iter().map(pick).collect(),
            style: Style::LineMarkers(Marker::Dot),
            color: Some(color),
        });
        if !truth.is_empty() {
            series.push(Series {
                name: format!("{name} (exact plant)"),
                x: sp(truth),
                y: truth.iter().map(pick).collect(),
                style: Style::Dashed,
                color: Some(color),
            });
        }
    }
    Figure {
        id: "machine-coupling".into(),
        title: "Cross-coupling strength against speed".into(),
        caption: format!(
            "κ = max over pairs (i, j) of max(|P_ij|, |P_ji|)/√(|P_ii| |P_jj|) per line, then its \
             median and largest value over the lines in {}–{} Hz; x–y pairs: every x axis with \
             every y axis (the gyroscopic coupling, 0 at standstill on a symmetric rotor); A–B \
             pairs: the two bearings in one plane (the coupling through the rigid rotor).",
            fmt(band[0]),
            fmt(band[1])
        ),
        panels: vec![Panel {
            title: String::new(),
            x: lin_axis("speed [rpm]"),
            y: log_axis("coupling κ [-]"),
            content: PanelContent::Xy(series),
            spans: vec![],
            equal_aspect: false,
        }],
        columns: 1,
    }
}

/// The coupling table: one row per speed.
pub fn coupling_table(measured: &[Coupling], truth: &[Coupling]) -> Table {
    let rows = measured
        .iter()
        .enumerate()
        .map(|(k, c)| {
            let t = truth.get(k);
            vec![
                fmt(c.speed_rpm),
                fmt(c.xy_median),
                fmt(c.xy_max),
                t.map_or("—".into(), |t| fmt(t.xy_median)),
                fmt(c.ab_median),
                fmt(c.ab_max),
                t.map_or("—".into(), |t| fmt(t.ab_median)),
                c.lines.to_string(),
            ]
        })
        .collect();
    Table {
        id: "machine-coupling".into(),
        caption: "Cross-coupling strength κ per speed (definition under the figure); the exact \
                  plant's on the same lines (twin)."
            .into(),
        header: [
            "speed [rpm]",
            "x–y median",
            "x–y max",
            "x–y median, exact",
            "A–B median",
            "A–B max",
            "A–B median, exact",
            "lines",
        ]
        .map(String::from)
        .to_vec(),
        rows,
        highlight: None,
    }
}

fn whirl_color(w: Whirl) -> usize {
    match w {
        Whirl::Forward => 0,
        Whirl::Backward => 1,
        Whirl::None => 2,
    }
}

/// Splits mode points by whirl into marker series named `<prefix>, <whirl>`.
fn by_whirl(points: &[ModePoint], prefix: &str, marker: Marker) -> Vec<Series> {
    [Whirl::Forward, Whirl::Backward, Whirl::None]
        .into_iter()
        .filter_map(|w| {
            let p: Vec<&ModePoint> = points.iter().filter(|p| p.whirl == w).collect();
            (!p.is_empty()).then(|| Series {
                name: format!("{prefix}, {} whirl", whirl_str(w)),
                x: p.iter().map(|p| p.speed_rpm).collect(),
                y: p.iter().map(|p| p.freq_hz).collect(),
                style: Style::Markers(marker),
                color: Some(whirl_color(w)),
            })
        })
        .collect()
}

/// The Campbell diagram: the model's curves (`curves`: the speed-scheduled model, or the
/// twin's exact model on a dense speed grid) as small dots, the identified models' modes
/// (`points`) as squares, coloured by whirl (forward, backward, planar), and the 1× line
/// $f = \Omega/60$ up to `max_rpm`.
pub fn campbell_figure(
    curves: &[ModePoint],
    curves_name: &str,
    points: &[ModePoint],
    max_rpm: f64,
    f_max_hz: f64,
) -> Figure {
    let mut series = by_whirl(curves, curves_name, Marker::Dot);
    series.extend(by_whirl(points, "identified models", Marker::Square));
    let top = max_rpm.min(60.0 * f_max_hz);
    series.push(Series {
        name: "1× (synchronous)".into(),
        x: vec![0.0, top],
        y: vec![0.0, top / 60.0],
        style: Style::Dashed,
        color: Some(4),
    });
    Figure {
        id: "machine-campbell".into(),
        title: "Campbell diagram".into(),
        caption: format!(
            "Closed-loop natural frequencies against speed up to {} Hz. Dots: {curves_name}; \
             squares: the modes of the identified model at each measured speed (when a model was \
             identified). Whirl as the twin labels it: forward when the orbit's forward circular \
             part dominates (|v_x + j v_y|² share > ½). Dashed: the 1× line f = Ω/60.",
            fmt(f_max_hz)
        ),
        panels: vec![Panel {
            title: String::new(),
            x: lin_axis("speed [rpm]"),
            y: lin_axis("frequency [Hz]"),
            content: PanelContent::Xy(series),
            spans: vec![],
            equal_aspect: false,
        }],
        columns: 1,
    }
}

fn opt(v: Option<f64>) -> String {
    v.filter(|x| x.is_finite()).map_or("—".into(), fmt)
}

/// The MIMO comparison table (the chosen row of each speed marked).
pub fn comparison_table(rows: &[ComparisonRow]) -> Table {
    Table {
        id: "machine-comparison".into(),
        caption: "MIMO model comparison per speed: frequency error per entry (largest over the \
                  16 entries of the median relative error) and norm-wise (median over the band \
                  of ‖Ĝ − P̂‖₂/‖P̂‖₂), BIC, unstable poles and the closed-loop validation fit \
                  per axis; ✓ marks the chosen model."
            .into(),
        header: [
            "speed [rpm]",
            "model",
            "order",
            "unstable poles",
            "‖Ĝ−P̂‖/‖P̂‖ median [%]",
            "max entry error [%]",
            "BIC",
            "fit y xa / xb / ya / yb [%]",
            "chosen",
        ]
        .map(String::from)
        .to_vec(),
        rows: rows
            .iter()
            .map(|r| {
                vec![
                    fmt(r.speed_rpm),
                    r.model.clone(),
                    r.order.to_string(),
                    r.unstable_poles.to_string(),
                    fmt(r.median_norm_error_pct),
                    fmt(r.max_entry_error_pct),
                    opt(r.bic),
                    r.fit_y_pct.map_or("—".into(), |f| {
                        f.iter().map(|v| fmt(*v)).collect::<Vec<_>>().join(" / ")
                    }),
                    if r.chosen {
                        "✓".into()
                    } else {
                        String::new()
                    },
                ]
            })
            .collect(),
        highlight: None,
    }
}

/// A gain interval `lo … hi`, or a dash.
fn pair(p: Option<[f64; 2]>) -> String {
    p.map_or("—".into(), |[a, b]| format!("{} … {}", fmt(a), fmt(b)))
}

/// The chosen models' uncertainty per speed (`[machine] uncertainty`).
pub fn uncertainty_table(rows: &[super::machine::UncertaintyRow]) -> Table {
    Table {
        id: "machine-uncertainty".into(),
        caption: "The chosen model's uncertainty per speed, entry by entry: |P_ij − P̂_ij| ≤ L_ij \
                  with (a) the FRF's confidence region carried through the fit of all 16 entries \
                  together and (b) the significant smoothed misfit, raised so that it covers the \
                  model's drawn error on 98 % of the (line, entry) pairs in 95 % of 2 000 draws; \
                  ‖L‖₂ bounds σ̄(P − P̂). The four controllers' robust stability against it on the \
                  fit's lines (max ρ(L|M|), M = (I + C P̂)⁻¹C; an upper bound of μ) and the robust \
                  gain margins of all four gains together, beside the exact loop's on the twin \
                  With the amplitude study (`[machine] amplitude_levels_pct`, on by default on \
                  the twin) every entry has (e), the shift of the best linear approximation at \
                  the identification level from its extrapolation to zero amplitude, so the \
                  bound holds the small-signal plant (docs/uncertainty.md, \"MIMO entries\" and \
                  \"Term (e) for the machine\": on random 4-axis rigs, coverage and margins as \
                  measured there)."
            .into(),
        header: [
            "speed [rpm]",
            "fit band; bound to [Hz] (lines)",
            "raise",
            "‖L‖/σ̄(P̂) median / max [%]",
            "robustly stable",
            "max ρ(L|M|) at [Hz]",
            "robust gain margins",
            "exact gain margins",
            "‖L‖ ≥ σ̄(P−P̂) on [%]",
            "(e) levels [%]: median σ̄(E)/σ̄(P̂) [%]",
        ]
        .map(String::from)
        .to_vec(),
        rows: rows
            .iter()
            .map(|r| {
                vec![
                    fmt(r.speed_rpm),
                    format!(
                        "{}–{}; {} ({})",
                        fmt(r.band_hz[0]),
                        fmt(r.band_hz[1]),
                        fmt(r.bound_band_hz[1]),
                        r.lines
                    ),
                    fmt(r.raise),
                    format!("{} / {}", fmt(r.median_rel_pct), fmt(r.max_rel_pct)),
                    if r.robustly_stable { "yes" } else { "no" }.into(),
                    format!("{} at {}", fmt(r.mu_peak), fmt(r.mu_peak_hz)),
                    pair(r.gain_margins),
                    pair(r.exact_gain_margins),
                    opt(r.truth_coverage.map(|c| 100.0 * c)),
                    match (&r.amplitude_levels_pct, r.amplitude_median_rel_pct) {
                        (Some(l), Some(m)) => format!(
                            "{}: {}",
                            l.iter().map(|v| fmt(*v)).collect::<Vec<_>>().join(", "),
                            fmt(m)
                        ),
                        _ => "—".into(),
                    },
                ]
            })
            .collect(),
        highlight: None,
    }
}

/// The machine's uncertainty section: a note per speed whose bound has no term (e) (the
/// reason, or that no amplitude study ran), then [`uncertainty_table`] and
/// [`uncertainty_weight_table`].
pub fn uncertainty_blocks(rows: &[super::machine::UncertaintyRow]) -> Vec<Block> {
    let mut out = Vec::new();
    let bare: Vec<String> = rows
        .iter()
        .filter(|r| r.amplitude_levels_pct.is_none() && r.amplitude_note.is_none())
        .map(|r| fmt(r.speed_rpm))
        .collect();
    if !bare.is_empty() {
        out.push(note(
            NoteKind::Warning,
            format!(
                "No amplitude study at {} rpm, so the bound there has no term (e): it holds the best linear approximation at the identification level, not the small-signal plant a controller is designed on. On the twin set `[machine] amplitude_levels_pct` (default [5, 16] with uncertainty = true).",
                bare.join(", ")
            ),
        ));
    }
    for r in rows {
        if let Some(n) = &r.amplitude_note {
            out.push(note(
                NoteKind::Warning,
                format!("{} rpm: {n}.", fmt(r.speed_rpm)),
            ));
        }
    }
    out.push(Block::Table(uncertainty_table(rows)));
    out.push(Block::Table(uncertainty_coherent_table(rows)));
    out.push(Block::Table(uncertainty_weight_table(rows)));
    out
}

/// The robust gain margins against coherent draws of the model's error, per speed, beside the
/// element-wise ones on the same lines and the exact loop's.
pub fn uncertainty_coherent_table(rows: &[super::machine::UncertaintyRow]) -> Table {
    Table {
        id: "machine-uncertainty-coherent".into(),
        caption: "Robust gain margins at a confidence, per speed: the model's error drawn as \
                  whole 4×4 matrices (the fit's parameter uncertainty and the amplitude shift \
                  projected through the model move all 16 entries together, the nonlinear \
                  distortion per line), the rest of the bound, whose phase is not known (the \
                  misfit, the per-line amplitude term), taken element-wise at its worst around \
                  each draw. The margins are those the stated fraction of the draws reach: a \
                  statement under the error model, not a worst case over a set. The \
                  element-wise check on the lines (previous table) lets the 16 entries' errors \
                  take the phases that line up worst against the loop, which the true error, one \
                  coherent matrix, does not; at a lightly damped mode that costs up to half the \
                  margin. Outside the fit's lines the draws know nothing: there the entry \
                  weights of the next table bound the error element-wise (their \
                  extrapolation, tested up to an octave beyond the lines), and the gain \
                  interval in which the loop passes that test (column \"outside the lines\", \
                  with the frequency that ends it above) caps every draw's; farther out a \
                  weight fitted on the lines bounds nothing, and only the model caps the \
                  margins. Without that cap the \
                  upper margin exceeded the exact loop's on a test rig whose loop goes \
                  unstable above the lines (docs/uncertainty.md, \"Coherent draws for the \
                  machine\", with the rigs these margins were measured on)."
            .into(),
        header: [
            "speed [rpm]",
            "draws",
            "confidence",
            "draws stable at gain 1 [%]",
            "robust gain margins, coherent",
            "outside the lines (entry weights)",
            "robust gain margins, element-wise on the lines",
            "exact gain margins",
        ]
        .map(String::from)
        .to_vec(),
        rows: rows
            .iter()
            .map(|r| {
                vec![
                    fmt(r.speed_rpm),
                    r.coherent_draws.to_string(),
                    fmt(r.coherent_confidence),
                    fmt(100.0 * r.coherent_stable_fraction),
                    pair(r.coherent_gain_margins),
                    match (
                        r.coherent_outside_gain_interval,
                        r.coherent_outside_critical_hz[1],
                    ) {
                        (Some(p), Some(f)) => format!("{} (above: {} Hz)", pair(Some(p)), fmt(f)),
                        (p, _) => pair(p),
                    },
                    pair(r.gain_margins),
                    pair(r.exact_gain_margins),
                ]
            })
            .collect(),
        highlight: None,
    }
}

/// The structured weight's table: per speed, one relative weight per entry over the raised
/// bound, and the four controllers' robust stability against it.
pub fn uncertainty_weight_table(rows: &[super::machine::UncertaintyRow]) -> Table {
    Table {
        id: "machine-uncertainty-weights".into(),
        caption: "The uncertain model for robust-control design, per speed: one stable \
                  minimum-phase relative weight per entry, P_ij = P̂_ij(1 + W_ij δ_ij) with \
                  independent |δ_ij| ≤ 1, each of order ≤ 4 over the entry's bound L_ij/|P̂_ij| \
                  on 98 % of its lines, that bound raised (column \"raise\") so that it covers \
                  the model's drawn error on 95 % of the (line, entry) pairs, the coverage bar's \
                  fraction, in 95 % of the same draws (exported as \
                  models/<model>_uncertain.{m,mat,npz,json}, the MATLAB script building one \
                  ultidyn per entry). The robust test against the weights, max \
                  ρ((|P̂|∘|W|)|M|) on a dense grid, and the robust gain margins of all four gains \
                  together. A weight of order ≤ 4 cannot follow the bound's narrow peaks at the \
                  lightly damped modes, so these margins are narrower than those on the lines; \
                  on random 4-axis rigs 1–100 of the nonlinear twin with term (e) the weights \
                  covered the exact plant on 100, the exact loop was stable at 90 % of these \
                  margins on 99 and they were at least half the exact ones on 65; on rigs 1–72 of \
                  the linear twin 72, 72 and 60 (docs/uncertainty.md, \"Two raises for the \
                  machine\")."
            .into(),
        header: [
            "speed [rpm]",
            "raise",
            "highest weight order",
            "weight looseness (median over entries)",
            "robustly stable",
            "max ρ((|P̂|∘|W|)|M|) at [Hz]",
            "robust gain margins",
            "exact gain margins",
            "‖ |P̂|∘|W| ‖ ≥ σ̄(P−P̂) on [%]",
        ]
        .map(String::from)
        .to_vec(),
        rows: rows
            .iter()
            .map(|r| {
                vec![
                    fmt(r.speed_rpm),
                    fmt(r.weight_raise),
                    r.weight_max_order.to_string(),
                    fmt(r.weight_looseness),
                    if r.weight_robustly_stable {
                        "yes"
                    } else {
                        "no"
                    }
                    .into(),
                    format!("{} at {}", fmt(r.weight_mu_peak), fmt(r.weight_mu_peak_hz)),
                    pair(r.weight_gain_margins),
                    pair(r.exact_gain_margins),
                    opt(r.weight_truth_coverage.map(|c| 100.0 * c)),
                ]
            })
            .collect(),
        highlight: None,
    }
}

/// The per-axis validation table.
pub fn validation_table(rows: &[AxisValidationRow]) -> Table {
    let yes = |b: Option<bool>| match b {
        Some(true) => "pass".to_string(),
        Some(false) => "fail".to_string(),
        None => "—".to_string(),
    };
    Table {
        id: "machine-validation".into(),
        caption: "Closed-loop validation per axis: the identified 4×4 plant with the four \
                  decentralised controllers simulated against an independent record; fit of \
                  the displacement and the current, the exact plant's fit on the same record \
                  (twin) and the residual tests."
            .into(),
        header: [
            "speed [rpm]",
            "axis",
            "fit y [%]",
            "fit i [%]",
            "exact plant's fit y [%]",
            "whiteness",
            "independence",
        ]
        .map(String::from)
        .to_vec(),
        rows: rows
            .iter()
            .map(|r| {
                vec![
                    fmt(r.speed_rpm),
                    r.axis.clone(),
                    fmt(r.fit_y_pct),
                    opt(r.fit_i_pct),
                    opt(r.truth_fit_y_pct),
                    yes(r.whiteness_ok),
                    yes(r.independence_ok),
                ]
            })
            .collect(),
        highlight: None,
    }
}

fn zone_name(z: Zone) -> &'static str {
    match z {
        Zone::A => "A",
        Zone::B => "B",
        Zone::C => "C",
        Zone::D => "D",
    }
}

/// The ISO 14839-3 table: peak $|S_{ii}|$ per axis and speed, with its frequency and zone.
pub fn iso_table(rows: &[IsoRow], zones: &IsoZones) -> Table {
    Table {
        id: "machine-iso".into(),
        caption: format!(
            "ISO 14839-3 per axis: the peak of the diagonal sensitivity |S_ii| (S = (I + C P)⁻¹, \
             r at the controller outputs) and its zone (A < {}, B < {}, C < {}, else D); \
             `measured`: the 4×4 FRF's Ŝ, `truth`: the twin's exact loop, `model`: the identified \
             plant's loop.",
            fmt(zones.a),
            fmt(zones.b),
            fmt(zones.c)
        ),
        header: [
            "speed [rpm]",
            "axis",
            "from",
            "peak |S_ii|",
            "peak [dB]",
            "at [Hz]",
            "zone",
        ]
        .map(String::from)
        .to_vec(),
        rows: rows
            .iter()
            .map(|r| {
                vec![
                    fmt(r.speed_rpm),
                    r.axis.clone(),
                    r.from.clone(),
                    fmt(r.peak),
                    fmt(20.0 * r.peak.log10()),
                    fmt(r.f_hz),
                    zone_name(r.zone).into(),
                ]
            })
            .collect(),
        highlight: None,
    }
}

/// $\lVert M\rVert_2$ of a complex 4×4 matrix stored column by column, as the largest singular
/// value of its real 8×8 form $\begin{bmatrix}\Re & -\Im\\ \Im & \Re\end{bmatrix}$.
pub fn norm2(m: &[ambid_core::c64], n: usize) -> Result<f64, Error> {
    let r = faer::Mat::<f64>::from_fn(2 * n, 2 * n, |i, j| {
        let (ii, jj) = (i % n, j % n);
        let v = m[ii + n * jj];
        match (i < n, j < n) {
            (true, true) | (false, false) => v.re,
            (true, false) => -v.im,
            (false, true) => v.im,
        }
    });
    let sv = ambid_core::linalg::singular_values(r.as_ref())?;
    Ok(sv.into_iter().fold(0.0, f64::max))
}

/// Median over the lines in `band` of $\lVert\hat P - P\rVert_2/\lVert P\rVert_2$ \[%\].
///
/// # Errors
/// When the grids differ or no line is in the band.
pub fn median_norm_error_pct(est: &Frd, truth: &Frd, band: [f64; 2]) -> Result<f64, Error> {
    if est.len() != truth.len() || est.ny() != truth.ny() || est.nu() != truth.nu() {
        return Err(Error::computation("the two responses are not on one grid"));
    }
    let per = est.ny() * est.nu();
    let mut e = Vec::new();
    for (k, f) in est.f_hz().iter().enumerate() {
        if *f < band[0] || *f > band[1] {
            continue;
        }
        let a = &est.values()[k * per..(k + 1) * per];
        let b = &truth.values()[k * per..(k + 1) * per];
        let d: Vec<ambid_core::c64> = a.iter().zip(b).map(|(x, y)| x - y).collect();
        e.push(100.0 * norm2(&d, est.ny())? / norm2(b, est.ny())?);
    }
    if e.is_empty() {
        return Err(Error::computation("no line in the band"));
    }
    e.sort_by(f64::total_cmp);
    let n = e.len();
    Ok(if n % 2 == 1 {
        e[n / 2]
    } else {
        0.5 * (e[n / 2 - 1] + e[n / 2])
    })
}

/// The Campbell curves of the twin's exact model on `n` speeds from 0 to `max_rpm`.
fn truth_campbell(
    cfg: &ambid_twin::MachineConfig,
    max_rpm: f64,
    f_max_hz: f64,
) -> Result<Vec<ModePoint>, Error> {
    let n = 25;
    let grid: Vec<f64> = (0..n)
        .map(|k| max_rpm * k as f64 / (n - 1) as f64)
        .collect();
    let pts = ambid_twin::campbell(cfg, &grid, f_max_hz)?;
    Ok(pts
        .iter()
        .flat_map(|p| {
            p.modes.iter().map(move |m| ModePoint {
                speed_rpm: p.speed_rpm,
                freq_hz: m.freq_hz,
                damping: m.damping,
                whirl: m.whirl,
            })
        })
        .collect())
}

/// Every machine section and the typed summary.
///
/// # Errors
/// A computation that failed (a response that is not 4×4).
pub fn sections(
    m: &MachineSection,
    data: &MachineData,
    models: &MachineModelOutput,
    zones: &IsoZones,
) -> Result<(Vec<Section>, MachineSummary), Error> {
    let band = m.quality_band_hz;
    let twin = data.truth.is_some();
    let mut summary = MachineSummary {
        source: if twin { "twin" } else { "files" }.into(),
        speeds_rpm: data.speeds.iter().map(|s| s.speed_rpm).collect(),
        design: (twin).then(|| m.design.clone()),
        lines: data.speeds.iter().map(|s| s.frf.plant.len()).collect(),
        models: models.models.iter().map(|s| s.name.clone()).collect(),
        comparison: models.comparison.clone(),
        validation: models.validation.clone(),
        campbell_points: models.campbell_points.clone(),
        uncertainty: models.uncertainty.clone(),
        ..MachineSummary::default()
    };
    // truth on the measured lines
    let truth_frd: Vec<Option<Frd>> = data
        .speeds
        .iter()
        .enumerate()
        .map(|(k, s)| {
            data.truth
                .as_ref()
                .and_then(|t| t.get(k))
                .map(|t| Frd::from_model(&t.plant, s.frf.plant.f_hz()))
                .transpose()
        })
        .collect::<Result<_, _>>()?;
    for (s, t) in data.speeds.iter().zip(&truth_frd) {
        summary
            .coupling
            .push(coupling(&s.frf.plant, band, s.speed_rpm)?);
        if let Some(t) = t {
            summary.coupling_truth.push(coupling(t, band, s.speed_rpm)?);
            summary
                .frf_error_vs_truth_pct
                .push(median_norm_error_pct(&s.frf.plant, t, band)?);
        }
        if let Some(sens) = &s.frf.s {
            summary
                .iso
                .extend(iso_rows(sens, s.speed_rpm, zones, "measured")?);
        }
    }
    if let Some(truth) = &data.truth {
        for t in truth {
            for (i, (f, peak)) in t.peak_sensitivity.iter().enumerate() {
                summary.iso.push(IsoRow {
                    speed_rpm: t.speed_rpm,
                    axis: AXES[i].into(),
                    from: "truth".into(),
                    peak: *peak,
                    f_hz: *f,
                    zone: zones.zone(*peak),
                });
            }
        }
    }
    summary.iso.extend(models.iso.iter().cloned());
    summary.iso.sort_by(|a, b| {
        a.speed_rpm
            .total_cmp(&b.speed_rpm)
            .then_with(|| axis_index(&a.axis).cmp(&axis_index(&b.axis)))
    });
    summary.worst_zone = summary
        .iso
        .iter()
        .filter(|r| r.from == "measured")
        .map(|r| r.zone)
        .max();

    let mut out = Vec::new();
    // the answer first
    out.push(summary_section(&summary, models));
    // data
    out.push(data_section(m, data));
    // the Bode matrices
    let mut blocks = vec![Block::Text(
        "The 4×4 plant FRF P̂ = T̂_ry Ŝ⁻¹ per speed (magnitude; row = output axis, column = input \
         axis), with its ±2σ band from the per-entry variance of the period average."
            .into(),
    )];
    for (k, s) in data.speeds.iter().enumerate() {
        let model_frd = models
            .models
            .iter()
            .find(|x| x.speed_rpm == s.speed_rpm)
            .map(|x| Frd::from_model(&x.model, s.frf.plant.f_hz()))
            .transpose()?;
        let mut layers = vec![BodeLayer {
            name: "measured",
            frd: &s.frf.plant,
            dashed: false,
            band: true,
            color: 0,
        }];
        if let Some(t) = &truth_frd[k] {
            layers.push(BodeLayer {
                name: "exact plant (twin)",
                frd: t,
                dashed: true,
                band: false,
                color: 1,
            });
        }
        if let Some(g) = &model_frd {
            layers.push(BodeLayer {
                name: "identified model",
                frd: g,
                dashed: true,
                band: false,
                color: 2,
            });
        }
        let err = summary
            .frf_error_vs_truth_pct
            .get(k)
            .map(|e| {
                format!(
                    " Median over {}–{} Hz of ‖P̂ − P‖₂/‖P‖₂ against the exact plant: {} %.",
                    fmt(band[0]),
                    fmt(band[1]),
                    fmt(*e)
                )
            })
            .unwrap_or_default();
        blocks.push(Block::Figure(bode_matrix(
            &format!("machine-bode-{}rpm", s.speed_rpm.round() as i64),
            &format!("4×4 plant FRF at {} rpm", fmt(s.speed_rpm)),
            &format!(
                "|P_ij| from input axis j to output axis i at {} rpm ({} lines{}).{err}",
                fmt(s.speed_rpm),
                s.frf.plant.len(),
                s.sync_removed_hz
                    .map(|f| format!(", 1× line at {} Hz removed before the FRF", fmt(f)))
                    .unwrap_or_default()
            ),
            &layers,
        )?));
    }
    out.push(section(
        "machine-bode",
        "4×4 plant FRF (Bode matrix)",
        blocks,
    ));
    // coupling
    out.push(section(
        "machine-coupling",
        "Cross-coupling against speed",
        vec![
            Block::Figure(coupling_figure(
                &summary.coupling,
                &summary.coupling_truth,
                band,
            )),
            Block::Table(coupling_table(&summary.coupling, &summary.coupling_truth)),
        ],
    ));
    // Campbell
    let max_rpm = summary
        .speeds_rpm
        .iter()
        .copied()
        .fold(0.0f64, f64::max)
        .max(1.0);
    let mut cb = Vec::new();
    let (curves, name) = if !models.campbell_curves.is_empty() {
        (models.campbell_curves.clone(), "speed-scheduled model")
    } else if let Some(cfg) = &data.twin {
        (truth_campbell(cfg, max_rpm, band[1])?, "exact model (twin)")
    } else {
        (Vec::new(), "no model")
    };
    if curves.is_empty() && models.campbell_points.is_empty() {
        cb.push(note(
            NoteKind::Info,
            "No model gives closed-loop modes yet (recorded files without an identified model): \
             the diagram shows the 1× line only.",
        ));
    }
    cb.push(Block::Figure(campbell_figure(
        &curves,
        name,
        &models.campbell_points,
        max_rpm,
        band[1],
    )));
    out.push(section("machine-campbell", "Campbell diagram", cb));
    // comparison
    let missing = "No MIMO model was identified in this run (no fitter is plugged into the \
                   workflow's model seam); the section shows what the models give once one is.";
    out.push(section(
        "machine-comparison",
        "MIMO model comparison",
        if models.comparison.is_empty() {
            vec![note(NoteKind::Info, missing)]
        } else {
            vec![Block::Table(comparison_table(&models.comparison))]
        },
    ));
    if !models.uncertainty.is_empty() {
        out.push(section(
            "machine-uncertainty",
            "Uncertainty and robust stability",
            uncertainty_blocks(&models.uncertainty),
        ));
    }
    // validation and ISO
    let mut vb = Vec::new();
    if models.validation.is_empty() {
        vb.push(note(
            NoteKind::Info,
            "Per-axis closed-loop validation: no identified model to validate in this run.",
        ));
    } else {
        vb.push(Block::Table(validation_table(&models.validation)));
    }
    if !models.sigma_max_s.is_empty() {
        vb.push(Block::Table(Table {
            id: "machine-sigma-s".into(),
            caption: "Peak of the largest singular value of S per speed (the model's loop).".into(),
            header: ["speed [rpm]", "peak σ̄(S)", "at [Hz]"]
                .map(String::from)
                .to_vec(),
            rows: models
                .sigma_max_s
                .iter()
                .map(|(s, p, f)| vec![fmt(*s), fmt(*p), fmt(*f)])
                .collect(),
            highlight: None,
        }));
    }
    if summary.iso.is_empty() {
        vb.push(note(
            NoteKind::Warning,
            "No sensitivity: the FRF files hold no S_<out>_<in> entries, so no ISO 14839-3 zone.",
        ));
    } else {
        vb.push(Block::Table(iso_table(&summary.iso, zones)));
    }
    for n in &models.notes {
        vb.push(note(NoteKind::Info, n.clone()));
    }
    out.push(section(
        "machine-validation",
        "Per-axis validation and ISO 14839-3",
        vb,
    ));
    Ok((out, summary))
}

fn axis_index(a: &str) -> usize {
    AXES.iter().position(|x| *x == a).unwrap_or(AXES.len())
}

fn summary_section(s: &MachineSummary, models: &MachineModelOutput) -> Section {
    let mut rows = vec![vec![
        "speeds".to_string(),
        format!(
            "{} rpm ({})",
            s.speeds_rpm
                .iter()
                .map(|v| fmt(*v))
                .collect::<Vec<_>>()
                .join(", "),
            if s.source == "twin" {
                format!(
                    "4-axis twin, {} design",
                    s.design.as_deref().unwrap_or("orthogonal")
                )
            } else {
                "recorded files".into()
            }
        ),
    ]];
    if let (Some(first), Some(last)) = (s.coupling.first(), s.coupling.last()) {
        rows.push(vec![
            "x–y coupling (median κ)".into(),
            format!(
                "{} at {} rpm → {} at {} rpm",
                fmt(first.xy_median),
                fmt(first.speed_rpm),
                fmt(last.xy_median),
                fmt(last.speed_rpm)
            ),
        ]);
    }
    if !s.frf_error_vs_truth_pct.is_empty() {
        rows.push(vec![
            "FRF against the exact plant".into(),
            format!(
                "median ‖P̂ − P‖₂/‖P‖₂ {} %",
                s.frf_error_vs_truth_pct
                    .iter()
                    .map(|v| fmt(*v))
                    .collect::<Vec<_>>()
                    .join(" / ")
            ),
        ]);
    }
    if let Some(z) = s.worst_zone {
        let worst = s
            .iso
            .iter()
            .filter(|r| r.from == "measured")
            .max_by(|a, b| a.peak.total_cmp(&b.peak));
        rows.push(vec![
            "ISO 14839-3 (measured S, worst axis)".into(),
            match worst {
                Some(w) => format!(
                    "zone {} (peak |S| {} on {} at {} rpm, {} Hz)",
                    zone_name(z),
                    fmt(w.peak),
                    w.axis,
                    fmt(w.speed_rpm),
                    fmt(w.f_hz)
                ),
                None => format!("zone {}", zone_name(z)),
            },
        ]);
    }
    for c in models.comparison.iter().filter(|c| c.chosen) {
        rows.push(vec![
            format!("chosen model at {} rpm", fmt(c.speed_rpm)),
            format!(
                "{} (order {}, {} unstable poles, median norm error {} %)",
                c.model,
                c.order,
                c.unstable_poles,
                fmt(c.median_norm_error_pct)
            ),
        ]);
    }
    section(
        "machine-summary",
        "Whole machine: summary",
        vec![Block::Table(Table {
            id: "machine-summary".into(),
            caption: "The whole machine in one table; every number is in summary.json under \
                      `machine`."
                .into(),
            header: vec!["quantity".into(), "value".into()],
            rows,
            highlight: None,
        })],
    )
}

fn data_section(m: &MachineSection, data: &MachineData) -> Section {
    let rows = data
        .speeds
        .iter()
        .map(|s| {
            vec![
                fmt(s.speed_rpm),
                s.source.clone(),
                if s.records.is_empty() {
                    "FRF file".into()
                } else {
                    s.records.len().to_string()
                },
                if s.period_samples > 0 {
                    s.period_samples.to_string()
                } else {
                    "—".into()
                },
                s.frf.plant.len().to_string(),
                format!(
                    "{}–{}",
                    fmt(s.frf.plant.f_hz().first().copied().unwrap_or(f64::NAN)),
                    fmt(s.frf.plant.f_hz().last().copied().unwrap_or(f64::NAN))
                ),
                s.sync_removed_hz.map_or("—".into(), fmt),
            ]
        })
        .collect();
    let mut blocks = Vec::new();
    if !m.from_files() {
        blocks.push(Block::Text(format!(
            "The 4-axis twin ({} physics, noise {}) in closed loop with its four decentralised \
             controllers; the {} design of PRBS n = {}, {} samples per bit at {} % of i_sat, {} \
             periods per experiment ({} skipped), every experiment from its periodic steady \
             state.",
            m.mode,
            if m.noise { "on" } else { "off" },
            m.design,
            m.prbs_order,
            m.samples_per_bit,
            fmt(m.level_pct),
            m.periods,
            m.skip_periods
        )));
    }
    blocks.push(Block::Table(Table {
        id: "machine-data".into(),
        caption: "Per speed: where the data come from, the experiments, the period, the FRF's \
                  lines and the 1× line removed before it."
            .into(),
        header: [
            "speed [rpm]",
            "source",
            "experiments",
            "period [samples]",
            "lines",
            "band [Hz]",
            "1× removed [Hz]",
        ]
        .map(String::from)
        .to_vec(),
        rows,
        highlight: None,
    }));
    section("machine-data", "Whole machine: data", blocks)
}

#[cfg(test)]
mod tests {
    use super::*;
    use ambid_core::c64;

    fn frd4(f: &[f64], val: impl Fn(usize, usize, usize) -> c64, var: Option<f64>) -> Frd {
        let mut v = Vec::new();
        for k in 0..f.len() {
            for j in 0..4 {
                for i in 0..4 {
                    v.push(val(k, i, j));
                }
            }
        }
        let n = v.len();
        Frd::new_matrix(f.to_vec(), 4, 4, v, var.map(|s| vec![s; n]), Some(5e-5)).unwrap()
    }

    #[test]
    fn bode_matrix_has_sixteen_panels_with_band_truth_and_model() {
        let f = [10.0, 100.0, 1000.0];
        // entry (i, j) = (1 + i + 4 j) at every line: each panel's magnitude is known
        let meas = frd4(
            &f,
            |_, i, j| c64::new((1 + i + 4 * j) as f64, 0.0),
            Some(0.25),
        );
        let truth = frd4(&f, |_, i, j| c64::new(0.0, (1 + i + 4 * j) as f64), None);
        let fig = bode_matrix(
            "b",
            "t",
            "c",
            &[
                BodeLayer {
                    name: "measured",
                    frd: &meas,
                    dashed: false,
                    band: true,
                    color: 0,
                },
                BodeLayer {
                    name: "exact",
                    frd: &truth,
                    dashed: true,
                    band: false,
                    color: 1,
                },
            ],
        )
        .unwrap();
        assert_eq!(fig.panels.len(), 16);
        assert_eq!(fig.columns, 4);
        // panel (row 2 = ya, column 1 = xb): |P| = 1 + 2 + 4 = 7, band 7 ± 2·0.5
        let p = &fig.panels[2 * 4 + 1];
        assert_eq!(p.title, "ya ← xb");
        let PanelContent::Xy(s) = &p.content else {
            panic!("xy")
        };
        assert_eq!(s.len(), 3);
        assert_eq!(s[0].y, vec![8.0; 3]);
        assert_eq!(
            s[0].style,
            Style::Band {
                lower: vec![6.0; 3]
            }
        );
        assert_eq!(s[1].y, vec![7.0; 3]);
        assert_eq!(s[2].y, vec![7.0; 3]);
        assert_eq!(s[2].style, Style::Dashed);
        // rendered: 16 panels are 16 <svg> elements
        let html = crate::report::Report {
            title: "x".into(),
            subtitle: String::new(),
            sections: vec![section("m", "m", vec![Block::Figure(fig)])],
        }
        .to_html();
        assert_eq!(html.matches("<svg").count(), 16);
        // a 2×2 response is refused with a message
        let small =
            Frd::new_matrix(vec![1.0], 2, 2, vec![c64::new(1.0, 0.0); 4], None, None).unwrap();
        let e = bode_matrix(
            "b",
            "t",
            "c",
            &[BodeLayer {
                name: "s",
                frd: &small,
                dashed: false,
                band: false,
                color: 0,
            }],
        )
        .unwrap_err();
        assert!(e.to_string().contains("2×2"), "{e}");
    }

    #[test]
    fn coupling_and_iso_from_constructed_responses() {
        let f = [5.0, 20.0, 200.0, 2000.0];
        // diagonal 2, x–y entries 0.5·line, A–B entries 0.1 (line-independent)
        let p = frd4(
            &f,
            |k, i, j| {
                let xy = (i < 2) != (j < 2);
                let v = if i == j {
                    2.0
                } else if xy {
                    0.5 * k as f64
                } else {
                    0.1
                };
                c64::new(v, 0.0)
            },
            None,
        );
        let c = coupling(&p, [10.0, 1000.0], 500.0).unwrap();
        // lines 20 Hz (k = 1) and 200 Hz (k = 2): κ_xy = 0.25, 0.5
        assert_eq!(c.lines, 2);
        assert!((c.xy_median - 0.375).abs() < 1e-15);
        assert!((c.xy_max - 0.5).abs() < 1e-15);
        assert!((c.ab_median - 0.05).abs() < 1e-15 && (c.ab_max - 0.05).abs() < 1e-15);
        assert!(coupling(&p, [3000.0, 4000.0], 0.0).is_err());
        let t = coupling_table(&[c], &[]);
        assert_eq!(t.rows[0][1], "0.375");
        assert_eq!(t.rows[0][3], "—");
        // ISO: S_ii peak per axis = (i + 1)·(line + 1) at the last line
        let s = frd4(
            &f,
            |k, i, j| {
                c64::new(
                    if i == j {
                        (i + 1) as f64 * (k + 1) as f64 / 2.0
                    } else {
                        9.0
                    },
                    0.0,
                )
            },
            None,
        );
        let z = IsoZones::default();
        let rows = iso_rows(&s, 0.0, &z, "measured").unwrap();
        let peaks: Vec<f64> = rows.iter().map(|r| r.peak).collect();
        assert_eq!(peaks, vec![2.0, 4.0, 6.0, 8.0]);
        assert!(rows.iter().all(|r| r.f_hz == 2000.0));
        let zones: Vec<Zone> = rows.iter().map(|r| r.zone).collect();
        assert_eq!(zones, vec![Zone::A, Zone::C, Zone::D, Zone::D]);
        let table = iso_table(&rows, &z);
        assert_eq!(
            table.rows[1],
            vec!["0", "xb", "measured", "4", "12.04", "2000", "C"]
        );
    }

    #[test]
    fn norm_error_is_the_largest_singular_value_ratio() {
        // P = diag(1, 2, 3, 4) (‖P‖ = 4), P̂ = P + E with E = 0.4 j at (0, 3): ‖E‖ = 0.4 → 10 %
        let f = [100.0];
        let p = frd4(
            &f,
            |_, i, j| c64::new(if i == j { (i + 1) as f64 } else { 0.0 }, 0.0),
            None,
        );
        let ph = frd4(
            &f,
            |_, i, j| {
                let d = if i == j { (i + 1) as f64 } else { 0.0 };
                c64::new(d, if (i, j) == (0, 3) { 0.4 } else { 0.0 })
            },
            None,
        );
        let e = median_norm_error_pct(&ph, &p, [10.0, 1000.0]).unwrap();
        assert!((e - 10.0).abs() < 1e-12, "{e}");
    }

    #[test]
    fn tables_and_campbell_render_the_seam_rows() {
        let rows = vec![ComparisonRow {
            speed_rpm: 15000.0,
            model: "freq ss 12".into(),
            order: 12,
            unstable_poles: 4,
            median_norm_error_pct: 0.5,
            max_entry_error_pct: 1.25,
            bic: Some(-1234.5),
            fit_y_pct: Some([90.0, 91.0, 92.0, 93.5]),
            chosen: true,
        }];
        let t = comparison_table(&rows);
        assert_eq!(
            t.rows[0],
            vec![
                "15000",
                "freq ss 12",
                "12",
                "4",
                "0.5",
                "1.25",
                "-1234",
                "90 / 91 / 92 / 93.5",
                "✓"
            ]
        );
        let v = validation_table(&[AxisValidationRow {
            speed_rpm: 0.0,
            axis: "yb".into(),
            fit_y_pct: 88.25,
            fit_i_pct: None,
            truth_fit_y_pct: Some(88.5),
            whiteness_ok: Some(true),
            independence_ok: Some(false),
        }]);
        assert_eq!(
            v.rows[0],
            vec!["0", "yb", "88.25", "—", "88.5", "pass", "fail"]
        );
        let pts = [
            ModePoint {
                speed_rpm: 0.0,
                freq_hz: 100.0,
                damping: 0.1,
                whirl: Whirl::None,
            },
            ModePoint {
                speed_rpm: 30000.0,
                freq_hz: 120.0,
                damping: 0.1,
                whirl: Whirl::Forward,
            },
            ModePoint {
                speed_rpm: 30000.0,
                freq_hz: 80.0,
                damping: 0.1,
                whirl: Whirl::Backward,
            },
        ];
        let fig = campbell_figure(&pts, "exact model (twin)", &pts[1..], 30000.0, 1000.0);
        let PanelContent::Xy(s) = &fig.panels[0].content else {
            panic!("xy")
        };
        let names: Vec<&str> = s.iter().map(|s| s.name.as_str()).collect();
        assert_eq!(
            names,
            vec![
                "exact model (twin), forward whirl",
                "exact model (twin), backward whirl",
                "exact model (twin), planar whirl",
                "identified models, forward whirl",
                "identified models, backward whirl",
                "1× (synchronous)"
            ]
        );
        // the 1× line ends at 30 000 rpm = 500 Hz
        assert_eq!(s[5].x, vec![0.0, 30000.0]);
        assert_eq!(s[5].y, vec![0.0, 500.0]);
    }
}
