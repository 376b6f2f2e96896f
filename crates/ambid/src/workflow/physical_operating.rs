//! The `physical` step's part from the operating-point study: the gray box at each operating
//! point and the magnet law $k_i = 4ki_0/g^2$, $k_x = 4ki_0^2/g^3$ through them (the magnet
//! constant and the effective air gap; `ambid::physical::operating`), as a report table and
//! `summary.json`'s `physical.operating`.

use super::Ctx;
use crate::physical::operating::{estimate_at_operating_points, OperatingFrf, Predicted};
use crate::physical::{estimate, Drawing, PhysicalOptions};
use crate::report::{Block, NoteKind, Table};
use ambid_core::lti::StateSpace;

/// `summary.json`'s `physical.operating`.
#[derive(Debug, Clone, serde::Serialize)]
pub struct MagnetLawSummary {
    /// The operating points, nominal first: name, bias current \[A\], gap offset \[m\].
    pub cases: Vec<(String, f64, f64)>,
    /// The magnet constant $k$ \[N m²/A²\]: estimate, standard deviation, 95 % interval, twin.
    pub force_constant: super::steps_robust::PhysicalRow,
    /// The effective nominal air gap \[m\], the same fields.
    pub air_gap_m: super::steps_robust::PhysicalRow,
    /// $\chi^2$ of the law and its degrees of freedom.
    pub chi2: f64,
    /// Degrees of freedom $2J - 2$.
    pub dof: usize,
    /// The variance factor (1 unless $\chi^2$ exceeds its 95 % point).
    pub variance_scale: f64,
    /// $k_i$ \[N/A\] at the nominal point from every operating point.
    pub pooled_k_i: Predicted,
    /// $k_x$ \[N/m\] at the nominal point from every operating point.
    pub pooled_k_x: Predicted,
    /// Each operating point's own gap $i_0 k_i/k_x$ \[m\] and its interval.
    pub gaps_from_ratio: Vec<(f64, (f64, f64))>,
}

/// Each operating point's bias current and gap offset: on the twin from the study's cases, on
/// files from `[operating_point] files` (`bias_current_a`, `gap_offset_um`); `Err(reason)`
/// when a file does not give them.
fn set_points(
    ctx: &Ctx<'_>,
    out: &crate::study::OperatingPointOutcome,
) -> Result<Vec<(f64, f64)>, String> {
    if ctx.twin.is_some() {
        let g0 = out.cases[0].air_gap_m;
        return Ok(out
            .cases
            .iter()
            .map(|c| (c.bias_current_a, c.air_gap_m - g0))
            .collect());
    }
    ctx.cfg
        .operating_point
        .files
        .iter()
        .map(|f| match (f.bias_current_a, f.gap_offset_um) {
            (Some(b), Some(g)) => Ok((b, g * 1e-6)),
            _ => Err(format!(
                "the recorded operating point `{}` does not give bias_current_a and gap_offset_um in [operating_point] files",
                f.name
            )),
        })
        .collect()
}

/// The blocks and summary (module docs); an info note instead when the study did not run or a
/// step of the estimate fails.
pub(super) fn operating_blocks(
    ctx: &Ctx<'_>,
    model: &StateSpace,
    drawing: &Drawing,
    ctrl: &StateSpace,
    truth: Option<(f64, f64)>,
) -> (Vec<Block>, Option<MagnetLawSummary>) {
    let Some(out) = ctx.operating_point.as_ref() else {
        return (Vec::new(), None);
    };
    let skip = |why: String| {
        (
            vec![Ctx::note(
                NoteKind::Info,
                format!("No magnet law from the operating-point study: {why}."),
            )],
            None,
        )
    };
    let points = match set_points(ctx, out) {
        Ok(p) => p,
        Err(why) => return skip(why),
    };
    let opts = PhysicalOptions::default();
    let nominal = match estimate(&out.plants[0], model, drawing, ctrl, &opts) {
        Ok(f) => f,
        Err(e) => return skip(format!("the gray box at the nominal operating point: {e}")),
    };
    let others: Vec<OperatingFrf<'_>> = points[1..]
        .iter()
        .zip(&out.plants[1..])
        .map(|(&(bias, offset), frd)| OperatingFrf {
            bias_current_a: bias,
            gap_offset_m: offset,
            frd,
        })
        .collect();
    let est =
        match estimate_at_operating_points(&nominal, points[0].0, &others, drawing, ctrl, &opts) {
            Ok(e) => e,
            Err(e) => return skip(e.to_string()),
        };
    let law = &est.law;
    let (ki, kx) = match law.predict(points[0].0, 0.0) {
        Ok(p) => p,
        Err(e) => return skip(e.to_string()),
    };
    let row = |name: &'static str, k: usize, value: f64, twin: Option<f64>| {
        super::steps_robust::PhysicalRow {
            name,
            estimate: value,
            std: law.std[k],
            interval: law.intervals[k],
            twin,
        }
    };
    let rows_k = row("force_constant", 0, law.force_constant, truth.map(|t| t.0));
    let rows_g = row("air_gap_m", 1, law.air_gap_m, truth.map(|t| t.1));
    let mut header: Vec<String> = ["quantity", "estimate", "std", "95 % interval"]
        .map(String::from)
        .to_vec();
    if truth.is_some() {
        header.push("twin".into());
    }
    let line = |label: &str, v: f64, sd: f64, (lo, hi): (f64, f64), twin: Option<f64>| {
        let mut r = vec![
            label.to_string(),
            format!("{v:.5e}"),
            format!("{sd:.2e}"),
            format!("{lo:.5e} … {hi:.5e}"),
        ];
        if truth.is_some() {
            r.push(twin.map_or("–".into(), |t| format!("{t:.5e}")));
        }
        r
    };
    let twin_nominal = ctx.twin.as_ref().map(|t| t.twin.linear_params());
    let law_rows = vec![
        line(
            "magnet constant k [N m²/A²]",
            law.force_constant,
            law.std[0],
            law.intervals[0],
            truth.map(|t| t.0),
        ),
        line(
            "effective air gap g₀ [m]",
            law.air_gap_m,
            law.std[1],
            law.intervals[1],
            truth.map(|t| t.1),
        ),
        line(
            "k_i at nominal, pooled [N/A]",
            ki.value,
            ki.std,
            ki.interval,
            twin_nominal.map(|l| l.k_i),
        ),
        line(
            "k_x at nominal, pooled [N/m]",
            kx.value,
            kx.std,
            kx.interval,
            twin_nominal.map(|l| l.k_x),
        ),
    ];
    let fits = std::iter::once(&nominal).chain(&est.fits);
    let case_rows: Vec<Vec<String>> = out
        .cases
        .iter()
        .zip(&points)
        .zip(fits)
        .enumerate()
        .map(|(n, ((case, &(bias, offset)), fit))| {
            let (g, (glo, ghi)) = law.gaps_from_ratio[n];
            let r = law.residuals[n];
            vec![
                case.name.clone(),
                format!("{bias:.4}"),
                format!("{:+.2}", offset * 1e6),
                format!("{:.5e} ± {:.1e}", fit.params.k_i, fit.std[0]),
                format!("{:.5e} ± {:.1e}", fit.params.k_x, fit.std[1]),
                format!("{g:.5e} ({glo:.5e} … {ghi:.5e})"),
                format!("{:+.2}, {:+.2}", r[0], r[1]),
            ]
        })
        .collect();
    let mut blocks = vec![
        Block::Text(format!(
            "The gray box at each of the operating-point study's {} operating points (the starts of the others from the nominal one's estimate), and the magnet law k_i = 4 k i₀/g², k_x = 4 k i₀²/g³ with g = g₀ + offset through their k_i, k_x and covariances: the magnet constant k and the effective nominal air gap g₀ (which the drawing's mechanical gap does not give: it includes the iron path). χ² = {:.2} on {} degrees of freedom tests the law. Each point's own gap i₀ k_i/k_x needs only its bias current and the static ratio, not the rotor's mass (docs/physical.md).",
            points.len(),
            law.chi2,
            law.dof
        )),
        Block::Table(Table {
            id: "magnet_law".into(),
            caption: "The magnet law through the operating points, with 95 % intervals.".into(),
            header,
            rows: law_rows,
            ..Table::default()
        }),
        Block::Table(Table {
            id: "operating_points_physical".into(),
            caption: "The gray box at each operating point: k_i, k_x with their standard deviations, the point's own gap from its ratio with its 95 % interval, and its whitened residuals against the law (k_i, k_x).".into(),
            header: ["operating point", "bias [A]", "gap offset [µm]", "k_i [N/A]", "k_x [N/m]", "gap from ratio [m]", "residuals"]
                .map(String::from)
                .to_vec(),
            rows: case_rows,
            ..Table::default()
        }),
    ];
    if law.variance_scale > 1.0 {
        blocks.push(Ctx::note(
            NoteKind::Warning,
            format!(
                "The magnet law misfits the operating points beyond their intervals (χ² {:.1} on {} dof, above its 95 % point): the intervals were widened by {:.2}. On a nonlinear magnet the estimates at a finite excitation are the best linear approximation's, whose shift differs between operating points (docs/physical.md); iron saturation or a wrong bias or offset also show here.",
                law.chi2, law.dof, law.variance_scale
            ),
        ));
    }
    let summary = MagnetLawSummary {
        cases: out
            .cases
            .iter()
            .zip(&points)
            .map(|(c, &(b, o))| (c.name.clone(), b, o))
            .collect(),
        force_constant: rows_k,
        air_gap_m: rows_g,
        chi2: law.chi2,
        dof: law.dof,
        variance_scale: law.variance_scale,
        pooled_k_i: ki,
        pooled_k_x: kx,
        gaps_from_ratio: law.gaps_from_ratio.clone(),
    };
    (blocks, Some(summary))
}
