//! The number of unstable open-loop poles, counted from a measured loop (generalised Nyquist).
//!
//! An AMB plant is unstable, and how many poles lie outside the unit circle is a property of the
//! data, not of a model: the loop $L = P C$ was closed and stable while it was measured, so the
//! generalised Nyquist criterion ties the count to the measured frequency response. A fitted model
//! with a different count contradicts the measurement (somewhere, often outside the fitted band),
//! and a model order below the count cannot describe the plant at all.
//!
//! # Method
//! For $z$ on the unit circle, traversed counter-clockwise and indented outwards around the
//! controller's integrators at $z = 1$, the closed loop's poles outside the circle $Z$, the open
//! loop's poles outside it $N_p$ and the counter-clockwise encirclements $N$ of the origin by
//! $d(z) = \det(I + P(z) C(z))$ satisfy $Z = N_p - N$. The loop was stable ($Z = 0$), so
//! $$N_p = N = \frac{2\,\Delta_{0^+\to\pi} \arg d - q\pi}{2\pi},$$
//! where $\Delta_{0^+\to\pi}$ is the change of the unwrapped phase from just above DC to the
//! Nyquist frequency (the lower half of the circle mirrors it, $d(\bar z) = \overline{d(z)}$) and
//! $-q\pi$ is the indentation's share for $q$ integrators ($d \sim c/(z-1)^q$ near $z = 1$). With
//! a stable controller (integrators aside) $N_p$ is the plant's count.
//!
//! The phase is known only at the measured lines. The ends are anchored where the phase is known
//! exactly: at $\omega \to 0^+$, $d \to c\,(j\omega T)^{-q}$ with $c = \det(\cdot)$ real, so the
//! phase tends to a member of $\{0, \pi\} - q\pi/2$; at Nyquist $d(-1)$ is real. The first and
//! last lines must lie within $45°$ of those anchors, and the phase must change by less than
//! [`MAX_STEP_DEG`] between adjacent lines (the lines resolve the loop's resonances); otherwise
//! the count is reported as unreliable (`unstable_poles = None`, with the reason), never guessed.
//! The raw count is a real number; it must lie within [`MAX_RESIDUAL`] of an integer.
//!
//! # Example
//! ```
//! use ambid_core::lti::{Frd, StateSpace};
//! use ambid_core::validate::nyquist::loop_unstable_poles;
//! use faer::mat;
//! // P(z) = 0.1 / (z - 1.05), unstable; C = 3: closed-loop pole 1.05 - 0.3 = 0.75
//! let ts = 1e-3;
//! let p = StateSpace::discrete(mat![[1.05]], mat![[1.0]], mat![[0.1]], mat![[0.0]], ts).unwrap();
//! let c = StateSpace::discrete(mat![[0.0]], mat![[0.0]], mat![[0.0]], mat![[3.0]], ts).unwrap();
//! let f: Vec<f64> = (1..500).map(|k| k as f64).collect();
//! let w = loop_unstable_poles(&Frd::from_model(&p, &f).unwrap(), &c).unwrap();
//! assert_eq!(w.unstable_poles, Some(1));
//! ```
use crate::error::{Error, Result};
use crate::lti::{Frd, StateSpace};
use faer::{c64, Mat};
use std::f64::consts::PI;

/// Largest phase change of $\det(I + PC)$ between adjacent lines for a reliable count \[deg\].
pub const MAX_STEP_DEG: f64 = 90.0;

/// Largest distance of the raw count from an integer for a reliable count.
pub const MAX_RESIDUAL: f64 = 0.1;

/// Largest relative standard deviation of $\det(I + PC)$ (from the FRF's variance, first order)
/// for a line to be used; noisier lines are skipped (their phase is not known to ±20°).
pub const MAX_REL_STD: f64 = 0.3;

/// Largest relative change of the plant between the first two lines (module docs).
const MAX_LOW_CHANGE: f64 = 0.5;

/// Points of the path below the first line (log-spaced from $10^{-4} f_1$).
const EXTENSION_POINTS: usize = 400;

/// Largest angle between the end lines and their anchors (module docs) \[deg\].
const MAX_END_DEG: f64 = 45.0;

/// What [`loop_unstable_poles`] finds.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct LoopWinding {
    /// Unstable open-loop poles, or `None` when the lines cannot support a count (see `reason`).
    pub unstable_poles: Option<usize>,
    /// The raw count $(2\Delta\arg d - q\pi)/(2\pi)$.
    pub raw: f64,
    /// Integrators of the controller ($q$, poles within $10^{-8}$ of $z = 1$).
    pub integrators: usize,
    /// Largest phase change between adjacent lines \[deg\].
    pub max_step_deg: f64,
    /// Lines used (those in $(0, f_s/2)$ with $\det(I + PC)$ known to [`MAX_REL_STD`]).
    pub lines: usize,
    /// Why the count is unreliable, when it is.
    pub reason: Option<String>,
}

/// Counts the unstable poles of the open loop $P C$ from the FRF of `plant` ($n_y \times n_u$,
/// discrete, lines in $(0, f_s/2)$) and the `controller` ($n_u \times n_y$, the one that
/// stabilised the loop during the measurement), by the method of the module docs.
///
/// Errors on a continuous FRF or controller, different sample times, mismatched dimensions,
/// fewer than 8 lines in $(0, f_s/2)$, or a non-finite response. An unreliable count is not an
/// error: it comes back with `unstable_poles = None` and the reason.
pub fn loop_unstable_poles(plant: &Frd, controller: &StateSpace) -> Result<LoopWinding> {
    let ts = plant.ts().ok_or_else(|| {
        Error::invalid(
            "plant",
            "the FRF has no sample time; the count works on discrete data",
        )
    })?;
    match controller.ts() {
        Some(t) if (t - ts).abs() <= 1e-9 * ts => {}
        other => {
            return Err(Error::invalid(
                "controller",
                format!("the controller's sample time {other:?} s differs from the FRF's {ts} s; give the discrete controller of the measurement"),
            ))
        }
    }
    let (ny, nu) = (plant.ny(), plant.nu());
    if controller.noutputs() != nu || controller.ninputs() != ny {
        return Err(Error::invalid(
            "controller",
            format!(
                "the controller is {}x{} but the {ny}x{nu} plant needs a {nu}x{ny} one (it maps the displacements to the controller outputs)",
                controller.noutputs(),
                controller.ninputs()
            ),
        ));
    }
    let nyq = 0.5 / ts;
    let idx: Vec<usize> = (0..plant.len())
        .filter(|&k| plant.f_hz()[k] > 0.0 && plant.f_hz()[k] < nyq)
        .collect();
    if idx.len() < 8 {
        return Err(Error::invalid(
            "plant",
            format!(
                "{} lines in (0, {nyq} Hz); the count needs at least 8 spread over the whole range",
                idx.len()
            ),
        ));
    }
    let f: Vec<f64> = idx.iter().map(|&k| plant.f_hz()[k]).collect();
    if f.windows(2).any(|w| w[1] <= w[0]) {
        return Err(Error::invalid(
            "plant",
            "the FRF's lines must increase strictly",
        ));
    }
    let cr = controller.freq_response(&f)?;
    let mut pm = Vec::with_capacity(f.len());
    let mut d = Vec::with_capacity(f.len());
    let mut keep = Vec::with_capacity(f.len());
    for (kk, &k) in idx.iter().enumerate() {
        let p = plant.at(k)?;
        let v = det_loop(&p, &cr[kk]);
        if !(v.re.is_finite() && v.im.is_finite()) {
            return Err(Error::invalid(
                "plant",
                format!("det(I + P C) is not finite at {} Hz; check the FRF", f[kk]),
            ));
        }
        // first-order relative error of d: δd/d = tr((I + L)⁻¹ δP C) = Σ δP_ij [C (I + L)⁻¹]_ji
        let rel_std = match plant.variance_at(k)? {
            Some(var) => {
                let l = Mat::<c64>::from_fn(ny, ny, |i, j| {
                    let mut acc = c64::new(f64::from(u8::from(i == j)), 0.0);
                    for t in 0..nu {
                        acc += p[(i, t)] * cr[kk][(t, j)];
                    }
                    acc
                });
                match crate::linalg::solve_c64(l.transpose(), cr[kk].transpose()) {
                    // X = (I + L)⁻ᵀ Cᵀ = (C (I + L)⁻¹)ᵀ, so [C (I + L)⁻¹]_ji = X_ij
                    Ok(x) => {
                        let mut acc = 0.0;
                        for i in 0..ny {
                            for j in 0..nu {
                                acc += var[(i, j)] * x[(i, j)].norm_sqr();
                            }
                        }
                        acc.sqrt()
                    }
                    Err(_) => f64::INFINITY,
                }
            }
            None => 0.0,
        };
        if rel_std <= MAX_REL_STD {
            pm.push(p);
            d.push(v);
            keep.push(kk);
        }
    }
    let f: Vec<f64> = keep.iter().map(|&kk| f[kk]).collect();
    if f.len() < 8 {
        return Err(Error::invalid(
            "plant",
            format!(
                "{} lines determine det(I + P C) to {:.0} % (relative standard deviation); the count needs at least 8: measure with more periods or more excitation",
                f.len(),
                100.0 * MAX_REL_STD
            ),
        ));
    }
    let q = controller
        .poles()?
        .iter()
        .filter(|z| (*z - 1.0).norm() <= 1e-8)
        .count();
    // the path below line `first`: the controller exactly, the plant as P₀ + jP₁ω (module docs)
    let below = |first: usize| -> Result<Vec<c64>> {
        let f1 = f[first];
        let grid: Vec<f64> = (0..EXTENSION_POINTS)
            .map(|i| f1 * 1e-4f64.powf(1.0 - i as f64 / EXTENSION_POINTS as f64))
            .collect();
        let cg = controller.freq_response(&grid)?;
        let p1 = &pm[first];
        Ok(grid
            .iter()
            .zip(&cg)
            .map(|(&fg, c)| {
                let pl = Mat::<c64>::from_fn(ny, nu, |i, j| {
                    c64::new(p1[(i, j)].re, p1[(i, j)].im * fg / f1)
                });
                det_loop(&pl, c)
            })
            .collect())
    };
    let path = |first: usize, step: usize| -> Result<Vec<c64>> {
        let mut out = below(first)?;
        out.extend(d.iter().skip(first).step_by(step).copied());
        Ok(out)
    };
    let mut reason = None;
    // the plant must be nearly static below the first line: its change to the second line small
    let p_change = frobenius_diff(&pm[0], &pm[1]) / frobenius(&pm[0]).max(f64::MIN_POSITIVE);
    if p_change > MAX_LOW_CHANGE {
        reason.get_or_insert(format!(
            "the plant changes by {:.0} % between the first two lines ({:.3} and {:.3} Hz): its dynamics reach below the first line, which the count cannot see; measure lower lines (longer periods)",
            100.0 * p_change,
            f[0],
            f[1]
        ));
    }
    let full = raw_count(&path(0, 1)?, q);
    if full.start.abs() > MAX_END_DEG.to_radians() {
        reason.get_or_insert(format!(
            "det(I + P C) extended below the first line ({:.3} Hz) is {:.0}° from its DC phase; measure lower lines",
            f[0],
            full.start.abs().to_degrees()
        ));
    }
    if full.max_step > MAX_STEP_DEG.to_radians() {
        reason.get_or_insert(format!(
            "the phase of det(I + P C) changes by up to {:.0}° between adjacent lines (at most {MAX_STEP_DEG}° for a count); the lines are too coarse for the loop's resonances",
            full.max_step.to_degrees()
        ));
    }
    if full.end.abs() > MAX_END_DEG.to_radians() {
        reason.get_or_insert(format!(
            "the last line ({:.1} Hz) is {:.0}° from the real axis det(I + P C) reaches at Nyquist ({nyq} Hz); measure up to Nyquist",
            f[f.len() - 1],
            full.end.abs().to_degrees()
        ));
    }
    let raw = full.raw;
    let rounded = raw.round();
    if (raw - rounded).abs() > MAX_RESIDUAL {
        reason.get_or_insert(format!("the raw count {raw:.3} is not near an integer"));
    }
    if rounded < 0.0 {
        reason.get_or_insert(format!(
            "the raw count {raw:.3} is negative: the controller is not the one that stabilised this loop, or the loop was unstable"
        ));
    }
    // resolution check: the even and the odd lines alone (twice the spacing) must agree
    for parity in 0..2 {
        let h = raw_count(&path(parity, 2)?, q).raw;
        if (h - rounded).abs() > 0.5 {
            reason.get_or_insert(format!(
                "every other line alone counts {h:.2} instead of {rounded}: the lines barely resolve the loop's phase; measure with a finer resolution (longer periods)"
            ));
        }
    }
    Ok(LoopWinding {
        unstable_poles: reason.is_none().then_some(rounded as usize),
        raw,
        integrators: q,
        max_step_deg: full.max_step.to_degrees(),
        lines: f.len(),
        reason,
    })
}

/// The phase bookkeeping of one set of lines (module docs), angles in rad.
struct Raw {
    /// The raw count.
    raw: f64,
    /// First line's phase minus its DC anchor.
    start: f64,
    /// Nyquist anchor minus the last line's phase.
    end: f64,
    /// Largest phase change between adjacent lines.
    max_step: f64,
}

/// The raw count from $d$ at increasing lines in $(0, f_s/2)$ with `q` integrators.
fn raw_count(d: &[c64], q: usize) -> Raw {
    // start anchor: {0, π} − qπ/2, the member nearest to the first line's phase
    let a0 = d[0].arg();
    let base = -(q as f64) * PI / 2.0;
    let nearest = |x: f64, y: f64| if x.abs() <= y.abs() { x } else { y };
    let start = nearest(wrap(a0 - base), wrap(a0 - base - PI));
    let mut total = start;
    let mut max_step: f64 = 0.0;
    for w in d.windows(2) {
        let s = (w[1] / w[0]).arg();
        max_step = max_step.max(s.abs());
        total += s;
    }
    // end anchor: d(−1) is real
    let al = d[d.len() - 1].arg();
    let end = nearest(wrap(-al), wrap(PI - al));
    total += end;
    Raw {
        raw: (2.0 * total - q as f64 * PI) / (2.0 * PI),
        start,
        end,
        max_step,
    }
}

/// `x` wrapped into $(-\pi, \pi]$.
fn wrap(x: f64) -> f64 {
    let y = (x + PI).rem_euclid(2.0 * PI) - PI;
    if y <= -PI {
        y + 2.0 * PI
    } else {
        y
    }
}

/// $\det(I + P C)$.
fn det_loop(p: &Mat<c64>, c: &Mat<c64>) -> c64 {
    let (ny, nu) = (p.nrows(), p.ncols());
    det(Mat::<c64>::from_fn(ny, ny, |i, j| {
        let mut acc = c64::new(f64::from(u8::from(i == j)), 0.0);
        for l in 0..nu {
            acc += p[(i, l)] * c[(l, j)];
        }
        acc
    }))
}

fn frobenius(a: &Mat<c64>) -> f64 {
    a.col_iter()
        .flat_map(|c| c.iter().map(|v| v.norm_sqr()).collect::<Vec<_>>())
        .sum::<f64>()
        .sqrt()
}

fn frobenius_diff(a: &Mat<c64>, b: &Mat<c64>) -> f64 {
    frobenius(&Mat::from_fn(a.nrows(), a.ncols(), |i, j| {
        a[(i, j)] - b[(i, j)]
    }))
}

/// Determinant by LU with partial pivoting.
fn det(mut m: Mat<c64>) -> c64 {
    let n = m.nrows();
    let mut out = c64::new(1.0, 0.0);
    for k in 0..n {
        let p = (k..n)
            .max_by(|&a, &b| m[(a, k)].norm().total_cmp(&m[(b, k)].norm()))
            .unwrap_or(k);
        if m[(p, k)].norm() == 0.0 {
            return c64::default();
        }
        if p != k {
            for j in 0..n {
                let t = m[(k, j)];
                m[(k, j)] = m[(p, j)];
                m[(p, j)] = t;
            }
            out = -out;
        }
        let piv = m[(k, k)];
        out *= piv;
        for i in k + 1..n {
            let l = m[(i, k)] / piv;
            for j in k + 1..n {
                let t = m[(k, j)];
                m[(i, j)] -= l * t;
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use faer::mat;

    const TS: f64 = 1e-3;

    fn lines(n: usize) -> Vec<f64> {
        (1..n).map(|k| k as f64 * 500.0 / n as f64).collect()
    }

    /// A discrete PI controller per axis: k (1 + ki / (z − 1)), block diagonal.
    fn pi_controller(n: usize, k: f64, ki: f64) -> StateSpace {
        StateSpace::discrete(
            Mat::<f64>::identity(n, n),
            Mat::<f64>::from_fn(n, n, |i, j| if i == j { ki } else { 0.0 }),
            Mat::<f64>::from_fn(n, n, |i, j| if i == j { k } else { 0.0 }),
            Mat::<f64>::from_fn(n, n, |i, j| if i == j { k } else { 0.0 }),
            TS,
        )
        .unwrap()
    }

    /// A discrete PD controller $k_p + k_d (1 - z^{-1})$ from a grid of gains whose loop with `p`
    /// is stable (its poles checked), if any.
    fn stabilising_pd(p: &StateSpace) -> Option<StateSpace> {
        for kp in [0.5, 1.0, 2.0, 5.0, 10.0, 20.0, 50.0] {
            for kd in [0.0, 1.0, 3.0, 10.0, 30.0, 100.0] {
                let c = StateSpace::discrete(
                    mat![[0.0]],
                    mat![[1.0]],
                    mat![[-kd]],
                    mat![[kp + kd]],
                    TS,
                )
                .ok()?;
                if p.feedback(&c).ok()?.is_stable().ok()? {
                    return Some(c);
                }
            }
        }
        None
    }

    #[test]
    fn determinant_matches_the_expansion() {
        let m = mat![
            [c64::new(1.0, 2.0), c64::new(0.5, 0.0), c64::new(0.0, -1.0)],
            [c64::new(0.0, 1.0), c64::new(2.0, 0.0), c64::new(1.0, 1.0)],
            [c64::new(3.0, 0.0), c64::new(-1.0, 0.5), c64::new(0.0, 0.0)]
        ];
        let e = |i: usize, j: usize| m[(i, j)];
        let want = e(0, 0) * (e(1, 1) * e(2, 2) - e(1, 2) * e(2, 1))
            - e(0, 1) * (e(1, 0) * e(2, 2) - e(1, 2) * e(2, 0))
            + e(0, 2) * (e(1, 0) * e(2, 1) - e(1, 1) * e(2, 0));
        assert!((det(m.clone()) - want).norm() < 1e-12);
    }

    #[test]
    fn counts_match_the_poles_of_stable_loops() {
        // SISO: P = b / ((z − a1)(z − a2)), every combination of stable/unstable poles, a
        // proportional controller chosen so the loop is stable (checked on its poles)
        let cases = [(0.9, 0.8, 0), (1.03, 0.8, 1), (1.03, 1.06, 2)];
        for (a1, a2, want) in cases {
            let p = StateSpace::discrete(
                mat![[a1, 1.0], [0.0, a2]],
                mat![[0.0], [1.0]],
                mat![[0.01, 0.0]],
                mat![[0.0]],
                TS,
            )
            .unwrap();
            let c = stabilising_pd(&p).expect("a stabilising PD gain");
            let w = loop_unstable_poles(&Frd::from_model(&p, &lines(2000)).unwrap(), &c).unwrap();
            assert_eq!(w.unstable_poles, Some(want), "{a1} {a2}: {w:?}");
            assert!((w.raw - want as f64).abs() < 1e-3, "{w:?}");
        }
    }

    #[test]
    fn integrators_and_a_coupled_two_by_two_plant() {
        // two unstable real poles coupled through B, a PI controller per axis
        let p = StateSpace::discrete(
            mat![[1.02, 0.0, 0.0], [0.0, 1.01, 0.0], [0.0, 0.0, 0.7]],
            mat![[1.0, 0.3], [0.2, 1.0], [1.0, 1.0]],
            mat![[0.02, 0.0, 0.01], [0.0, 0.02, -0.01]],
            mat![[0.0, 0.0], [0.0, 0.0]],
            TS,
        )
        .unwrap();
        let c = pi_controller(2, 3.0, 0.02);
        assert!(p.feedback(&c).unwrap().is_stable().unwrap());
        let w = loop_unstable_poles(&Frd::from_model(&p, &lines(2000)).unwrap(), &c).unwrap();
        assert_eq!(w.integrators, 2);
        assert_eq!(w.unstable_poles, Some(2), "{w:?}");
        // the same loop, P stable: nothing unstable counted despite the integrators
        let ps = StateSpace::discrete(
            mat![[0.98, 0.0, 0.0], [0.0, 0.99, 0.0], [0.0, 0.0, 0.7]],
            mat![[1.0, 0.3], [0.2, 1.0], [1.0, 1.0]],
            mat![[0.02, 0.0, 0.01], [0.0, 0.02, -0.01]],
            mat![[0.0, 0.0], [0.0, 0.0]],
            TS,
        )
        .unwrap();
        assert!(ps.feedback(&c).unwrap().is_stable().unwrap());
        let w = loop_unstable_poles(&Frd::from_model(&ps, &lines(2000)).unwrap(), &c).unwrap();
        assert_eq!(w.unstable_poles, Some(0), "{w:?}");
    }

    #[test]
    fn coarse_lines_and_missing_ends_are_unreliable_not_guessed() {
        // det(I + L) = m_k e^{jφ_k} on 40 lines with a static unit controller: L = d − 1
        let c =
            StateSpace::discrete(mat![[0.0]], mat![[0.0]], mat![[0.0]], mat![[1.0]], TS).unwrap();
        let f: Vec<f64> = (1..=40).map(|k| k as f64 * 12.0).collect();
        let frd = |mag: &dyn Fn(usize) -> f64, phase: &dyn Fn(usize) -> f64| {
            let v = (0..f.len())
                .map(|k| c64::from_polar(mag(k), phase(k)) - 1.0)
                .collect();
            Frd::new(f.clone(), v, None, Some(TS)).unwrap()
        };
        let two = |_: usize| 2.0;
        // half a turn from DC to Nyquist (4.6° per line): one unstable pole
        let turn = |k: usize| PI * k as f64 / 39.0;
        let w = loop_unstable_poles(&frd(&two, &turn), &c).unwrap();
        assert_eq!(w.unstable_poles, Some(1), "{w:?}");
        // nearly the same half turn made between two lines: a 162° step is not resolved
        let jump = |k: usize| if k >= 20 { 0.9 * PI } else { 0.0 };
        let w = loop_unstable_poles(&frd(&two, &jump), &c).unwrap();
        assert_eq!(w.unstable_poles, None, "{w:?}");
        assert!(w.reason.as_deref().unwrap().contains("too coarse"), "{w:?}");
        // the loop still changing fast at the first lines: dynamics below the first line
        let fast = |k: usize| if k == 0 { 6.0 } else { 2.0 };
        let w = loop_unstable_poles(&frd(&fast, &turn), &c).unwrap();
        assert_eq!(w.unstable_poles, None, "{w:?}");
        assert!(w.reason.as_deref().unwrap().contains("first line"), "{w:?}");
        // ending 90° from the real axis at the last line: no Nyquist anchor
        let short = |k: usize| 0.5 * PI * k as f64 / 39.0;
        let w = loop_unstable_poles(&frd(&two, &short), &c).unwrap();
        assert_eq!(w.unstable_poles, None, "{w:?}");
        assert!(w.reason.as_deref().unwrap().contains("Nyquist"), "{w:?}");
        // a lightly damped pair at 100 Hz and an unstable pole: dense lines count it; lines
        // that stop at 100 Hz lack the Nyquist anchor and are either flagged or still right
        let r: f64 = 0.999;
        let th = 2.0 * PI * 100.0 * TS;
        let p = StateSpace::discrete(
            mat![
                [1.03, 0.0, 0.0],
                [0.0, r * th.cos(), r * th.sin()],
                [0.0, -r * th.sin(), r * th.cos()]
            ],
            mat![[1.0], [0.0], [1.0]],
            mat![[0.01, 0.02, 0.0]],
            mat![[0.0]],
            TS,
        )
        .unwrap();
        let c = stabilising_pd(&p).expect("a stabilising PD gain");
        let dense = loop_unstable_poles(&Frd::from_model(&p, &lines(5000)).unwrap(), &c).unwrap();
        assert_eq!(dense.unstable_poles, Some(1), "{dense:?}");
        let low: Vec<f64> = (1..200).map(|k| k as f64 * 0.5).collect();
        let w = loop_unstable_poles(&Frd::from_model(&p, &low).unwrap(), &c).unwrap();
        assert!(
            w.unstable_poles.is_none() || w.unstable_poles == Some(1),
            "{w:?}"
        );
    }

    #[test]
    fn bad_input_is_refused() {
        let p =
            StateSpace::discrete(mat![[1.05]], mat![[1.0]], mat![[0.1]], mat![[0.0]], TS).unwrap();
        let c =
            StateSpace::discrete(mat![[0.0]], mat![[0.0]], mat![[0.0]], mat![[3.0]], TS).unwrap();
        let frd = Frd::from_model(&p, &lines(100)).unwrap();
        // too few lines
        let few = Frd::from_model(&p, &[10.0, 20.0, 30.0]).unwrap();
        assert!(matches!(
            loop_unstable_poles(&few, &c),
            Err(Error::InvalidArgument { .. })
        ));
        // wrong sample time
        let c2 =
            StateSpace::discrete(mat![[0.0]], mat![[0.0]], mat![[0.0]], mat![[3.0]], 2e-3).unwrap();
        let e = loop_unstable_poles(&frd, &c2).unwrap_err();
        assert!(e.to_string().contains("sample time"), "{e}");
        // wrong dimensions
        let c3 = StateSpace::discrete(
            mat![[0.0]],
            mat![[0.0, 0.0]],
            mat![[0.0]],
            mat![[3.0, 1.0]],
            TS,
        )
        .unwrap();
        let e = loop_unstable_poles(&frd, &c3).unwrap_err();
        assert!(e.to_string().contains("1x1"), "{e}");
    }
}
