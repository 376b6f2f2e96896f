//! Starting values for the prediction-error iteration: least squares (ARX), the simplified
//! refined instrumental variable method for $B/F$, and Hannan–Rissanen for the noise polynomials.
//! See the parent module's "Initialisation" section for the reasoning.

use super::predictor::{fill_shifted, filter, filter_many, is_stable, max_root, Polys};
use super::{Focus, Orders};
use crate::error::{Error, Result};
use faer::linalg::solvers::SolveLstsq;
use faer::Mat;

const CTX: &str = "pem initialisation";

/// One regressor column: signal, lag, sign.
type Col<'a> = (&'a [f64], usize, f64);

fn lagged(x: &[f64], k: usize, t: usize) -> f64 {
    if t >= k {
        x[t - k]
    } else {
        0.0
    }
}

/// Regressor matrix with rows $t = t_0, \dots, N-1$.
fn design(t0: usize, n: usize, cols: &[Col<'_>]) -> Mat<f64> {
    Mat::from_fn(n - t0, cols.len(), |i, j| {
        let (x, k, s) = cols[j];
        s * lagged(x, k, t0 + i)
    })
}

fn column_scales(m: &Mat<f64>) -> Vec<f64> {
    (0..m.ncols())
        .map(|j| {
            let s = (0..m.nrows())
                .map(|i| m[(i, j)].powi(2))
                .sum::<f64>()
                .sqrt();
            if s > 0.0 {
                s
            } else {
                1.0
            }
        })
        .collect()
}

/// Least squares $\Phi\theta \approx y$ with column equilibration, by [`crate::linalg::lstsq`];
/// a rank-deficient regressor becomes an error that names the likely cause.
fn regress(phi: &Mat<f64>, target: &[f64], what: &str) -> Result<Vec<f64>> {
    let s = column_scales(phi);
    let ps = Mat::from_fn(phi.nrows(), phi.ncols(), |i, j| phi[(i, j)] / s[j]);
    let rhs = Mat::from_fn(target.len(), 1, |i, _| target[i]);
    let x = crate::linalg::lstsq(ps.as_ref(), rhs.as_ref()).map_err(|e| match e {
        Error::Numerical { .. } => Error::numerical(
            CTX,
            format!(
                "the {what} regression is rank deficient: the input does not excite all parameters \
                 (a constant, periodic with too few lines, too smooth or too short input for these \
                 orders), the output does not respond to it, or the orders are higher than the \
                 data support; use a persistently exciting input or lower orders"
            ),
        ),
        other => other,
    })?;
    Ok((0..phi.ncols()).map(|j| x[(j, 0)] / s[j]).collect())
}

/// Residual of the least-squares fit without a rank test (the residual of a Householder QR
/// solve is accurate even when the coefficients are not); `None` if not finite.
fn ls_residual(phi: &Mat<f64>, target: &[f64]) -> Option<Vec<f64>> {
    let s = column_scales(phi);
    let ps = Mat::from_fn(phi.nrows(), phi.ncols(), |i, j| phi[(i, j)] / s[j]);
    let rhs = Mat::from_fn(target.len(), 1, |i, _| target[i]);
    let x = ps.qr().solve_lstsq(rhs);
    let fit = &ps * &x;
    let r: Vec<f64> = (0..target.len()).map(|i| target[i] - fit[(i, 0)]).collect();
    r.iter().all(|v| v.is_finite()).then_some(r)
}

/// Instrumental-variable solve $(Z^\top\Phi)\theta = Z^\top y$ with column equilibration.
fn iv_solve(phi: &Mat<f64>, z: &Mat<f64>, target: &[f64]) -> Option<Vec<f64>> {
    let sp = column_scales(phi);
    let sz = column_scales(z);
    let d = phi.ncols();
    let m = Mat::from_fn(d, d, |i, j| {
        (0..phi.nrows())
            .map(|t| z[(t, i)] * phi[(t, j)])
            .sum::<f64>()
            / (sz[i] * sp[j])
    });
    let rhs = Mat::from_fn(d, 1, |i, _| {
        (0..phi.nrows()).map(|t| z[(t, i)] * target[t]).sum::<f64>() / sz[i]
    });
    let x = crate::linalg::lstsq(m.as_ref(), rhs.as_ref()).ok()?;
    let th: Vec<f64> = (0..d).map(|j| x[(j, 0)] / sp[j]).collect();
    th.iter().all(|v| v.is_finite()).then_some(th)
}

fn monic(s: &[f64]) -> Vec<f64> {
    let mut p = vec![1.0];
    p.extend_from_slice(s);
    p
}

fn with_delay(nk: usize, b: &[f64]) -> Vec<f64> {
    let mut p = vec![0.0; nk];
    p.extend_from_slice(b);
    p
}

/// A SRIV estimate of F with poles up to this radius is moved inside; see [`oe_start`].
const SRIV_MAX_RADIUS: f64 = 1.02;
/// The radius it is moved to.
const SRIV_CONTRACTED: f64 = 0.9995;

/// $p_i \mapsto p_i \rho^i$: every root scaled by $\rho$ (same angle).
fn scale_radius(mut p: Vec<f64>, rho: f64) -> Vec<f64> {
    let mut s = 1.0;
    for c in p.iter_mut() {
        *c *= s;
        s *= rho;
    }
    p
}

/// Moves the roots of a start polynomial radially inside $|z| \le 0.95$ if any lies beyond
/// $0.99$: $p_i \mapsto p_i \rho^i$ scales every root by $\rho$. Used only on starting values of
/// noise polynomials, never on an estimate.
fn contract(p: Vec<f64>) -> Vec<f64> {
    let r = max_root(&p);
    if !r.is_finite() {
        return monic(&vec![0.0; p.len() - 1]);
    }
    if r > 0.99 {
        return scale_radius(p, 0.95 / r);
    }
    p
}

/// Radius to which an unstable open-loop start is moved (see [`stabilise`]).
pub(crate) const STABILISED_RADIUS: f64 = 0.99;

/// Moves every root of the monic $p$ with $|z| > $ [`STABILISED_RADIUS`] radially onto that
/// radius (same angle: a lightly damped or integrating pole keeps its frequency), leaving the
/// others where they are. Used only on a *start* for open-loop data
/// ([`super::PemOptions::with_open_loop`]); the iteration then moves the poles freely.
/// `None` if the roots cannot be computed.
pub(crate) fn stabilise(p: &[f64]) -> Option<Vec<f64>> {
    if p.len() <= 1 {
        return Some(p.to_vec());
    }
    let r = crate::linalg::roots(p).ok()?;
    if r.iter().any(|z| !z.re.is_finite() || !z.im.is_finite()) {
        return None;
    }
    let moved: Vec<faer::c64> = r
        .iter()
        .map(|z| {
            let m = z.norm();
            if m > STABILISED_RADIUS {
                *z * (STABILISED_RADIUS / m)
            } else {
                *z
            }
        })
        .collect();
    let q = crate::linalg::poly_from_roots(&moved);
    (q.len() == p.len() && is_stable(&q)).then_some(q)
}

/// $B$ (with `nk` leading zeros, `nb` coefficients) by least squares of $y$ on the lagged $u/F$
/// for a fixed stable $F$ (linear in $B$).
fn b_given_f(y: &[f64], u: &[f64], f: &[f64], nb: usize, nk: usize) -> Result<Vec<f64>> {
    let n = y.len();
    let uf = filter(&[1.0], f, u);
    let t0 = nk + nb - 1;
    let cols: Vec<Col<'_>> = (0..nb).map(|j| (uf.as_slice(), nk + j, 1.0)).collect();
    let th = regress(&design(t0, n, &cols), &y[t0..], "OE start")?;
    Ok(with_delay(nk, &th))
}

/// Order of the long ARX / AR models of the Hannan–Rissanen step.
fn long_order(n: usize, o: &Orders) -> usize {
    let want = (3 * (o.na + o.nc + o.nd + o.nf)).max(20);
    let cap = (n / 10).max(o.max_lag() + 1);
    want.min(cap).max(1)
}

fn norm(v: &[f64]) -> f64 {
    v.iter().map(|x| x * x).sum::<f64>().sqrt()
}

/// Innovations estimate $\hat e$ as the residual of a long ARX (`u = Some`) or AR model of
/// order `nl`; zero before the first full row. `None` if the data leave no residual (noise-free
/// data fitted exactly) or the fit fails.
fn innovations(y: &[f64], u: Option<(&[f64], usize)>, nl: usize) -> Option<(Vec<f64>, usize)> {
    let n = y.len();
    let mut cols: Vec<Col<'_>> = (1..=nl).map(|i| (y, i, -1.0)).collect();
    let mut t0 = nl;
    if let Some((u, nk)) = u {
        cols.extend((0..nl).map(|j| (u, nk + j, 1.0)));
        t0 = t0.max(nk + nl - 1);
    }
    if n <= t0 + 2 * cols.len() {
        return None;
    }
    let phi = design(t0, n, &cols);
    let r = ls_residual(&phi, &y[t0..])?;
    if norm(&r) <= 1e-11 * norm(&y[t0..]) {
        return None;
    }
    let mut e = vec![0.0; n];
    e[t0..].copy_from_slice(&r);
    Some((e, t0))
}

/// The F-polynomial start failed: the consistent (IV) estimate is unstable.
pub(crate) fn unstable_start(radius: f64) -> Error {
    Error::Unstable {
        context: "pem initialisation",
        reason: format!(
            "the least-squares and instrumental-variable estimates of the denominator (F; A under \
             the simulation focus) both have a pole outside the unit circle (largest |z| = {radius:.6}): the system from u to y looks unstable, and the \
             output-error predictor (B/F) u of an OE/BJ model (or B/(AF) u under the simulation \
             focus) cannot follow it. Identify the stable closed-loop map T_ry from the excitation r \
             (then P = T_ry / (1 - C T_ry)), or fit ARX/ARMAX with the prediction focus, whose \
             predictor stays stable for an unstable A"
        ),
    }
}

/// $B$ and $F$ (orders `nb`, `nf`, delay `nk`): ARX, then up to four iterations of the
/// simplified refined instrumental variable method (SRIV). An SRIV estimate of a lightly damped
/// $F$ that lands just outside the unit circle (radius below 1.02) is moved radially to 0.9995
/// as the next prefilter and start; the returned start may carry such a pole, never the
/// estimate (the iteration moves it, and fails if the optimum lies on the boundary).
///
/// With `open_loop`, an ARX and IV estimate that are both unstable (an integrator, a lightly
/// damped mode estimated just outside the circle, a coloured input) do not end the start: the
/// ARX $F$ is [`stabilise`]d, $B$ re-estimated given it, and SRIV goes on from there; the third
/// value is then the largest root radius of the unstable estimate (`None` otherwise).
pub(crate) fn oe_start(
    y: &[f64],
    u: &[f64],
    nb: usize,
    nf: usize,
    nk: usize,
    open_loop: bool,
) -> Result<(Vec<f64>, Vec<f64>, Option<f64>)> {
    let n = y.len();
    if nf == 0 {
        let t0 = nk + nb - 1;
        let cols: Vec<Col<'_>> = (0..nb).map(|j| (u, nk + j, 1.0)).collect();
        let th = regress(&design(t0, n, &cols), &y[t0..], "FIR")?;
        return Ok((with_delay(nk, &th), vec![1.0], None));
    }
    let t0 = nf.max(nk + nb - 1);
    let mut cols: Vec<Col<'_>> = (1..=nf).map(|i| (y, i, -1.0)).collect();
    cols.extend((0..nb).map(|j| (u, nk + j, 1.0)));
    let th = regress(&design(t0, n, &cols), &y[t0..], "ARX")?;
    let mut f = monic(&th[..nf]);
    let mut b = with_delay(nk, &th[nf..]);
    let mut stabilised = None;
    if !is_stable(&f) {
        // basic IV with further delayed inputs as instruments (consistent in open loop)
        let t1 = nk + nb + nf - 1;
        let iv = if n <= t1 + 2 * (nb + nf) {
            None
        } else {
            let phi = design(t1, n, &cols);
            let mut zc: Vec<Col<'_>> = (0..nf).map(|i| (u, nk + nb + i, 1.0)).collect();
            zc.extend((0..nb).map(|j| (u, nk + j, 1.0)));
            let z = design(t1, n, &zc);
            iv_solve(&phi, &z, &y[t1..]).filter(|th| is_stable(&monic(&th[..nf])))
        };
        match iv {
            Some(th) => {
                f = monic(&th[..nf]);
                b = with_delay(nk, &th[nf..]);
            }
            None if open_loop => {
                let r = max_root(&f);
                f = stabilise(&f).ok_or_else(|| unstable_start(r))?;
                // B given the stabilised F; a smooth input can leave that regression rank
                // deficient, then the ARX B is kept for the start
                if let Ok(bs) = b_given_f(y, u, &f, nb, nk) {
                    b = bs;
                }
                stabilised = Some(r);
            }
            None => return Err(unstable_start(max_root(&f))),
        }
    }
    // SRIV: prefilter by 1/F, instruments from the noise-free simulated output
    for _ in 0..4 {
        let yf = filter(&[1.0], &f, y);
        let uf = filter(&[1.0], &f, u);
        let x = filter(&b, &f, u);
        let xf = filter(&[1.0], &f, &x);
        let mut pc: Vec<Col<'_>> = (1..=nf).map(|i| (yf.as_slice(), i, -1.0)).collect();
        pc.extend((0..nb).map(|j| (uf.as_slice(), nk + j, 1.0)));
        let mut zc: Vec<Col<'_>> = (1..=nf).map(|i| (xf.as_slice(), i, -1.0)).collect();
        zc.extend((0..nb).map(|j| (uf.as_slice(), nk + j, 1.0)));
        let Some(th) = iv_solve(&design(t0, n, &pc), &design(t0, n, &zc), &yf[t0..]) else {
            break;
        };
        let mut fnew = monic(&th[..nf]);
        if !is_stable(&fnew) {
            // a lightly damped pole estimated just outside the circle: move it radially
            // inside (same frequency) and go on; further out, keep the last stable estimate
            let r = max_root(&fnew);
            if r.is_nan() || r >= SRIV_MAX_RADIUS {
                break;
            }
            fnew = scale_radius(fnew, SRIV_CONTRACTED / r);
        }
        let bnew = with_delay(nk, &th[nf..]);
        let change = fnew
            .iter()
            .zip(&f)
            .chain(bnew.iter().zip(&b))
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        let scale = fnew.iter().chain(&bnew).fold(0.0f64, |m, v| m.max(v.abs()));
        f = fnew;
        b = bnew;
        if change <= 1e-12 * scale {
            break;
        }
    }
    Ok((b, f, stabilised))
}

/// An OE start from a state-space model: N4SID of order $n_f$ (default horizon rule) on the
/// mean-free, unit-RMS $u$ (delayed by $n_k - 1$ samples) and $y$, refined by the state-space
/// prediction-error method under the simulation focus ([`refine_ss`](crate::estimate::ss_pem::refine_ss),
/// initial state estimated), whose criterion is the OE criterion in a well-conditioned
/// parameterisation; then $F$ = the refined model's denominator (a pole just outside the unit
/// circle, radius below [`SRIV_MAX_RADIUS`], is moved radially inside as for SRIV) and $B$ by
/// least squares of $y$ on the lagged $u/F$ (linear in $B$ once $F$ is fixed).
///
/// Why: the polynomial coefficients of an 8th-order $F$ with poles clustered near $z = 1$ (a
/// closed loop sampled at 20 kHz) are so ill-conditioned that Levenberg–Marquardt in them crawls
/// (on the twin's seed record OE(8, 8, 1) from SRIV was still moving after 400 iterations), while
/// the state-space refinement converges in a few. `None` when $n_k = 0$, the subspace or refinement step fails, or $F$ is clearly
/// unstable.
pub(crate) fn subspace_oe_start(
    y: &[f64],
    u: &[f64],
    nb: usize,
    nf: usize,
    nk: usize,
    ts: f64,
) -> Option<(Vec<f64>, Vec<f64>)> {
    use crate::estimate::ss_pem::{refine_ss, SsPemOptions};
    use crate::estimate::subspace::{n4sid, SubspaceOptions};
    use crate::lti::TransferFunction;
    if nk == 0 || nf == 0 {
        return None;
    }
    let n = y.len();
    let (ym, um, su, sy) = scaled_io(y, u, nk)?;
    let opts = SubspaceOptions {
        order: Some(nf),
        ..SubspaceOptions::new(ts)
    };
    let ss = n4sid(ym.as_ref(), um.as_ref(), &opts).ok()?;
    let mut model = ss.model;
    if model.is_stable().ok()? {
        let popts = SsPemOptions {
            focus: Focus::Simulation,
            ..SsPemOptions::default()
        };
        if let Ok(p) = refine_ss(ym.as_ref(), um.as_ref(), &model, None, &popts) {
            if p.fitted.model.is_stable().unwrap_or(false) {
                model = p.fitted.model;
            }
        }
    }
    let tf = TransferFunction::from_state_space(&model).ok()?;
    let den = tf.den();
    if den.len() != nf + 1 || den[0] == 0.0 {
        return None;
    }
    let mut f: Vec<f64> = den.iter().map(|c| c / den[0]).collect();
    if !is_stable(&f) {
        let r = max_root(&f);
        if r.is_nan() || r >= SRIV_MAX_RADIUS {
            return None;
        }
        f = scale_radius(f, SRIV_CONTRACTED / r);
    }
    let num = tf.num();
    if nb == nf && num.len() == nf + 1 && num[0] == 0.0 && f.as_slice() == den {
        // the model's own numerator (B from least squares given F is ill-conditioned when 1/F
        // is a steep low-pass: its lagged columns are nearly collinear)
        let b: Vec<f64> = num[1..].iter().map(|c| c / den[0] * sy / su).collect();
        return Some((with_delay(nk, &b), f));
    }
    let uf = filter(&[1.0], &f, u);
    let t0 = nk + nb - 1;
    let cols: Vec<Col<'_>> = (0..nb).map(|j| (uf.as_slice(), nk + j, 1.0)).collect();
    let th = regress(&design(t0, n, &cols), &y[t0..], "OE start").ok()?;
    Some((with_delay(nk, &th), f))
}

/// $A, B, C$ of an ARMAX model by Hannan–Rissanen: innovations from a long ARX model, then
/// least squares of $y(t) - \hat e(t)$ on $[-y(t-i), u(t-n_k-j), \hat e(t-k)]$.
fn armax_start(
    y: &[f64],
    u: &[f64],
    o: &Orders,
    nl: usize,
) -> Result<(Vec<f64>, Vec<f64>, Vec<f64>)> {
    let n = y.len();
    let (na, nb, nc, nk) = (o.na, o.nb, o.nc, o.nk);
    let arx_t0 = na.max(nk + nb - 1);
    let mut cols: Vec<Col<'_>> = (1..=na).map(|i| (y, i, -1.0)).collect();
    cols.extend((0..nb).map(|j| (u, nk + j, 1.0)));
    let arx = |cols: &[Col<'_>]| regress(&design(arx_t0, n, cols), &y[arx_t0..], "ARX");
    if nc == 0 {
        let th = arx(&cols)?;
        return Ok((monic(&th[..na]), with_delay(nk, &th[na..]), vec![1.0]));
    }
    let Some((e, te)) = innovations(y, Some((u, nk)), nl) else {
        let th = arx(&cols)?;
        return Ok((
            monic(&th[..na]),
            with_delay(nk, &th[na..]),
            monic(&vec![0.0; nc]),
        ));
    };
    let t0 = te + arx_t0.max(nc);
    if n <= t0 + 2 * o.n_params() {
        let th = arx(&cols)?;
        return Ok((
            monic(&th[..na]),
            with_delay(nk, &th[na..]),
            monic(&vec![0.0; nc]),
        ));
    }
    cols.extend((1..=nc).map(|k| (e.as_slice(), k, 1.0)));
    let target: Vec<f64> = (t0..n).map(|t| y[t] - e[t]).collect();
    let th = regress(&design(t0, n, &cols), &target, "Hannan–Rissanen ARMAX")?;
    Ok((
        monic(&th[..na]),
        with_delay(nk, &th[na..na + nb]),
        contract(monic(&th[na + nb..])),
    ))
}

/// $C, D$ of the ARMA model $D w = C e$ by Hannan–Rissanen (long AR, then least squares). Never
/// fails: if the data do not determine them (noise-free data), $C = D = 1$.
pub(crate) fn arma_start(w: &[f64], nc: usize, nd: usize, nl: usize) -> (Vec<f64>, Vec<f64>) {
    let ones = (monic(&vec![0.0; nc]), monic(&vec![0.0; nd]));
    if nc == 0 && nd == 0 {
        return ones;
    }
    let n = w.len();
    if nc == 0 {
        let cols: Vec<Col<'_>> = (1..=nd).map(|i| (w, i, -1.0)).collect();
        if n <= nd + 2 * nd {
            return ones;
        }
        return match regress(&design(nd, n, &cols), &w[nd..], "AR") {
            Ok(th) => (vec![1.0], contract(monic(&th))),
            Err(_) => ones,
        };
    }
    let Some((e, te)) = innovations(w, None, nl) else {
        return ones;
    };
    let t0 = te + nc.max(nd);
    if n <= t0 + 2 * (nc + nd) {
        return ones;
    }
    let mut cols: Vec<Col<'_>> = (1..=nd).map(|i| (w, i, -1.0)).collect();
    cols.extend((1..=nc).map(|k| (e.as_slice(), k, 1.0)));
    let target: Vec<f64> = (t0..n).map(|t| w[t] - e[t]).collect();
    match regress(&design(t0, n, &cols), &target, "ARMA") {
        Ok(th) => (contract(monic(&th[nd..])), contract(monic(&th[..nd]))),
        Err(_) => ones,
    }
}

/// Starting polynomials for `orders` under `focus` (see the module docs of `pem`).
///
/// The second value is the largest root radius of an unstable least-squares/IV denominator
/// that was stabilised for an open-loop start (see [`oe_start`]), `None` if none was.
pub(crate) fn start(
    y: &[f64],
    u: &[f64],
    o: &Orders,
    focus: Focus,
    open_loop: bool,
) -> Result<(Polys, Option<f64>)> {
    let nl = long_order(y.len(), o);
    let ones = |k: usize| monic(&vec![0.0; k]);
    match focus {
        Focus::Simulation => {
            // G = B/(A F) with one of na, nf zero (checked by the caller)
            let (b, den, st) = oe_start(y, u, o.nb, o.na + o.nf, o.nk, open_loop)?;
            let (a, f) = if o.na > 0 {
                (den, vec![1.0])
            } else {
                (vec![1.0], den)
            };
            Ok((
                Polys {
                    a,
                    b,
                    c: ones(o.nc),
                    d: ones(o.nd),
                    f,
                },
                st,
            ))
        }
        Focus::Prediction if o.na == 0 => {
            let (b, f, st) = oe_start(y, u, o.nb, o.nf, o.nk, open_loop)?;
            let v = filter(&b, &f, u);
            let w: Vec<f64> = y.iter().zip(&v).map(|(a, b)| a - b).collect();
            let (c, d) = arma_start(&w, o.nc, o.nd, nl);
            Ok((
                Polys {
                    a: vec![1.0],
                    b,
                    c,
                    d,
                    f,
                },
                st,
            ))
        }
        Focus::Prediction if o.nf > 0 => match general_start(y, u, o, nl) {
            Some(p) => Ok((p, None)),
            None => Ok((armax_path(y, u, o, nl)?, None)),
        },
        Focus::Prediction => Ok((armax_path(y, u, o, nl)?, None)),
    }
}

/// ARMAX-type start (Hannan–Rissanen for $A, B, C$; $D$ by Hannan–Rissanen on $A y - B u$;
/// $F = 1$).
fn armax_path(y: &[f64], u: &[f64], o: &Orders, nl: usize) -> Result<Polys> {
    let (a, b, mut c) = armax_start(y, u, o, nl)?;
    let mut d = monic(&vec![0.0; o.nd]);
    if o.nd > 0 {
        let ay = filter(&a, &[1.0], y);
        let bu = filter(&b, &[1.0], u);
        let w: Vec<f64> = ay.iter().zip(&bu).map(|(a, b)| a - b).collect();
        (c, d) = arma_start(&w, o.nc, o.nd, nl);
    }
    Ok(Polys {
        a,
        b,
        c,
        d,
        f: monic(&vec![0.0; o.nf]),
    })
}

/// Root groups of a real polynomial: real roots alone, complex roots with their conjugates.
fn root_groups(p: &[f64]) -> Option<Vec<Vec<faer::c64>>> {
    if p.len() <= 1 {
        return Some(Vec::new());
    }
    let r = crate::linalg::roots(p).ok()?;
    let mut out = Vec::new();
    for z in &r {
        let tol = 1e-8 * z.norm().max(1.0);
        if z.im > tol {
            out.push(vec![*z, z.conj()]);
        } else if z.im.abs() <= tol {
            out.push(vec![faer::c64::new(z.re, 0.0)]);
        }
    }
    (out.iter().map(Vec::len).sum::<usize>() == r.len()).then_some(out)
}

/// Start for the general structure with both $A$ and $F$: $G = B/(AF)$ by SRIV with a
/// denominator of order $n_a + n_f$, the noise denominator $\widehat{AD}$ of the output error by
/// Hannan–Rissanen, and $A$ = the $n_a$ roots of $\widehat{AF}$ closest to roots of
/// $\widehat{AD}$ (the factor the two share), $F$ the rest; then $C, D$ from $A y - (B/F) u$.
/// `None` when this fails (e.g. an unstable $AF$); the caller falls back to the ARMAX start.
fn general_start(y: &[f64], u: &[f64], o: &Orders, nl: usize) -> Option<Polys> {
    let (b, af, _) = oe_start(y, u, o.nb, o.na + o.nf, o.nk, false).ok()?;
    let v = filter(&b, &af, u);
    let w: Vec<f64> = y.iter().zip(&v).map(|(a, b)| a - b).collect();
    let (_, ad) = arma_start(&w, o.nc, o.na + o.nd, nl);
    let groups = root_groups(&af)?;
    let noise_roots: Vec<faer::c64> = root_groups(&ad)?.into_iter().flatten().collect();
    if groups.len() > 16 || noise_roots.is_empty() {
        return None;
    }
    let cost = |g: &[faer::c64]| {
        noise_roots
            .iter()
            .map(|z| (z - g[0]).norm())
            .fold(f64::INFINITY, f64::min)
    };
    let mut best: Option<(f64, u32)> = None;
    for mask in 0u32..(1 << groups.len()) {
        let size: usize = (0..groups.len())
            .filter(|k| mask >> k & 1 == 1)
            .map(|k| groups[k].len())
            .sum();
        if size != o.na {
            continue;
        }
        let c: f64 = (0..groups.len())
            .filter(|k| mask >> k & 1 == 1)
            .map(|k| cost(&groups[k]))
            .sum();
        if best.is_none_or(|(bc, _)| c < bc) {
            best = Some((c, mask));
        }
    }
    let (_, mask) = best?;
    let pick = |sel: bool| -> Vec<faer::c64> {
        (0..groups.len())
            .filter(|k| (mask >> k & 1 == 1) == sel)
            .flat_map(|k| groups[k].clone())
            .collect()
    };
    let a = crate::linalg::poly_from_roots(&pick(true));
    let f = crate::linalg::poly_from_roots(&pick(false));
    if a.len() != o.na + 1 || f.len() != o.nf + 1 || !is_stable(&f) {
        return None;
    }
    let ay = filter(&a, &[1.0], y);
    let vf = filter(&b, &f, u);
    let w: Vec<f64> = ay.iter().zip(&vf).map(|(a, b)| a - b).collect();
    let (c, d) = arma_start(&w, o.nc, o.nd, nl);
    Some(Polys { a, b, c, d, f })
}

/// Long-model order for the Hannan–Rissanen noise start of the simulation focus.
pub(crate) fn noise_order(n: usize, o: &Orders) -> usize {
    long_order(n, o)
}

/// An ARMAX start from the innovations form of a subspace model, for $n_a = n_b = n_c$ and
/// $n_k \ge 1$ (an ARMAX$(n, n, n, n_k)$ model *is* an $n$-th order innovations state-space
/// model $x^+ = A x + B u_{t-n_k+1} + K e$, $y = C x + e$): N4SID of order $n_a$ (default
/// horizon rule, Kalman gain from its noise covariances) on the mean-free, unit-RMS data with
/// $u$ delayed by $n_k - 1$; then $A(q) = \det(I - q^{-1}\mathbf A)$, $B(q)$ its transfer
/// function's numerator (scaled back) and $C(q) = \det(I - q^{-1}(\mathbf A - K\mathbf C))$,
/// the predictor's poles, moved radially inside $|z| = 0.95$ if a root lies beyond 0.99
/// ([`contract`]). $A$ is kept as estimated (an unstable plant in closed loop stays unstable).
/// The ARMAX iteration starts from this $C$ by variable projection ($A$, $B$ re-estimated for
/// it), so the subspace Kalman gain of closed-loop data, which can be far from the ARMAX
/// optimum's $C$, needs no separate refinement.
///
/// Why: the Hannan–Rissanen start takes the innovations from a long ARX model of order
/// $\max(20, 3(n_a + n_c))$, far too short when the innovations filter $1/C$ has poles at
/// $|z| \approx 0.99$ (an AMB loop's slow modes sampled at 20 kHz); from that start ARMAX(4, 4, 4, 1)
/// of $u \to y$ crawled 60–100 iterations along a curved valley of the polynomial coefficients
/// before its quadratic convergence set in. `None` when the orders differ, $n_k = 0$, the
/// subspace step fails or gives no Kalman gain.
pub(crate) fn subspace_armax_start(y: &[f64], u: &[f64], o: &Orders, ts: f64) -> Option<Polys> {
    if o.nk == 0 || o.na == 0 || o.nb != o.na || o.nc != o.na || o.nd != 0 || o.nf != 0 {
        return None;
    }
    let (fit, su, sy) = scaled_n4sid(y, u, o.na, o.nk, ts)?;
    let k = fit.kalman_gain.as_ref()?;
    let m = &fit.fitted.model;
    let (num, den) = m.tf_coefficients().ok()?;
    if den.len() != o.na + 1 || num.len() != o.na + 1 || den[0] == 0.0 || num[0] != 0.0 {
        return None;
    }
    let a: Vec<f64> = den.iter().map(|c| c / den[0]).collect();
    let b: Vec<f64> = num[1..].iter().map(|c| c / den[0] * sy / su).collect();
    let n = o.na;
    let akc = Mat::from_fn(n, n, |i, j| m.a()[(i, j)] - k[(i, 0)] * m.c()[(0, j)]);
    let c = crate::linalg::charpoly(akc.as_ref()).ok()?;
    if c.len() != n + 1 || c.iter().any(|v| !v.is_finite()) {
        return None;
    }
    Some(Polys {
        a,
        b: with_delay(o.nk, &b),
        c: contract(c),
        d: vec![1.0],
        f: vec![1.0],
    })
}

/// A Box–Jenkins start from the state-space OE start ([`subspace_oe_start`]) for $B, F$ and,
/// on its output error, Hannan–Rissanen for $C, D$ refined by [`refine_noise`] (iteration
/// options `lm`). `None` when the OE start is unavailable.
pub(crate) fn subspace_bj_start(
    y: &[f64],
    u: &[f64],
    o: &Orders,
    ts: f64,
    lm: &super::lm::LmOptions,
) -> Option<Polys> {
    if o.na != 0 || o.nf < 2 {
        return None;
    }
    let (b, f) = subspace_oe_start(y, u, o.nb, o.nf, o.nk, ts)?;
    let v = filter(&b, &f, u);
    let w: Vec<f64> = y.iter().zip(&v).map(|(a, b)| a - b).collect();
    let (c, d) = arma_start(&w, o.nc, o.nd, long_order(y.len(), o));
    let (c, d) = refine_noise(&w, c, d, lm);
    Some(Polys {
        a: vec![1.0],
        b,
        c,
        d,
        f,
    })
}

/// N4SID of order `n` (default horizon rule) on the unit-RMS $y$ and $u$ delayed by
/// $n_k - 1$; with the two scales (RMS of $u$, of $y$).
fn scaled_n4sid(
    y: &[f64],
    u: &[f64],
    n: usize,
    nk: usize,
    ts: f64,
) -> Option<(crate::estimate::subspace::SubspaceFit, f64, f64)> {
    use crate::estimate::subspace::{n4sid_detailed, SubspaceOptions};
    let (ym, um, su, sy) = scaled_io(y, u, nk)?;
    let opts = SubspaceOptions {
        order: Some(n),
        ..SubspaceOptions::new(ts)
    };
    let fit = n4sid_detailed(ym.as_ref(), um.as_ref(), &opts).ok()?;
    Some((fit, su, sy))
}

/// `y` and `u` aligned for the delay `nk` ≥ 1 (`y` shifted by `nk − 1`, so a subspace model with
/// one sample of delay carries the rest) and scaled to unit RMS, as columns, with the two RMS
/// values. `None` for `nk` = 0 or a zero, non-finite or too short signal.
fn scaled_io(y: &[f64], u: &[f64], nk: usize) -> Option<(Mat<f64>, Mat<f64>, f64, f64)> {
    let shift = nk.checked_sub(1)?;
    let m = y.len().checked_sub(shift)?.min(u.len());
    if m == 0 {
        return None;
    }
    let rms = |x: &[f64]| (x.iter().map(|v| v * v).sum::<f64>() / x.len() as f64).sqrt();
    let (su, sy) = (rms(&u[..m]), rms(&y[shift..shift + m]));
    if !(su > 0.0 && sy > 0.0 && su.is_finite() && sy.is_finite()) {
        return None;
    }
    let ym = Mat::from_fn(m, 1, |i, _| y[i + shift] / sy);
    let um = Mat::from_fn(m, 1, |i, _| u[i] / su);
    Some((ym, um, su, sy))
}

/// The ARMA criterion $\tfrac12\sum_t \bigl(\tfrac DC w_t\bigr)^2$ of a fixed output error $w$ over
/// $\theta = [c_1 \dots c_{n_c}, d_1 \dots d_{n_d}]$ (gradient as in the parent module:
/// $\partial\varepsilon/\partial c_i = -\frac1C \varepsilon_{t-i}$,
/// $\partial\varepsilon/\partial d_i = \frac1C w_{t-i}$).
struct ArmaCriterion<'a> {
    w: &'a [f64],
    nc: usize,
    nd: usize,
}

impl ArmaCriterion<'_> {
    fn polys(&self, x: &[f64]) -> (Vec<f64>, Vec<f64>) {
        (monic(&x[..self.nc]), monic(&x[self.nc..self.nc + self.nd]))
    }
}

impl super::lm::LeastSquaresProblem for ArmaCriterion<'_> {
    fn residuals(&mut self, x: &[f64]) -> Option<Vec<f64>> {
        let (c, d) = self.polys(x);
        if !is_stable(&c) {
            return None;
        }
        let e = filter(&d, &c, self.w);
        e.iter().all(|v| v.is_finite()).then_some(e)
    }
    fn jacobian(&mut self, x: &[f64]) -> Option<Mat<f64>> {
        let (c, d) = self.polys(x);
        if !is_stable(&c) {
            return None;
        }
        // e = (D/C) w and (1/C) w at once (interleaved), then (1/C) e
        let one = [1.0];
        let mut out = filter_many(&[(&d, &c, self.w), (&one, &c, self.w)]);
        let (e, wt) = (std::mem::take(&mut out[0]), std::mem::take(&mut out[1]));
        let et = filter(&one, &c, &e);
        let n = self.w.len();
        let mut jac = Mat::zeros(n, self.nc + self.nd);
        for k in 0..self.nc {
            fill_shifted(&mut jac, k, &et, k + 1, true);
        }
        for k in 0..self.nd {
            fill_shifted(&mut jac, self.nc + k, &wt, k + 1, false);
        }
        Some(jac)
    }
}

/// The noise model $C, D$ of a fixed output error $w$ by the prediction-error method from the
/// Hannan–Rissanen start `(c, d)` (a few Levenberg–Marquardt steps on a problem with only
/// $n_c + n_d$ parameters and no input filtering). Returns the start unchanged if the
/// iteration fails. Used for the Box–Jenkins start: with $G$ at the output-error optimum and
/// the noise model at its optimum given $G$, the joint iteration starts close to the BJ
/// optimum (from the Hannan–Rissanen $C, D$ it crawled 70–100 iterations on the twin's loop).
pub(crate) fn refine_noise(
    w: &[f64],
    c: Vec<f64>,
    d: Vec<f64>,
    lm: &super::lm::LmOptions,
) -> (Vec<f64>, Vec<f64>) {
    let (nc, nd) = (c.len() - 1, d.len() - 1);
    if nc + nd == 0 || !is_stable(&c) {
        return (c, d);
    }
    let mut x0 = c[1..].to_vec();
    x0.extend_from_slice(&d[1..]);
    let mut crit = ArmaCriterion { w, nc, nd };
    match super::lm::minimize(&mut crit, &x0, lm) {
        Ok((x, _)) => {
            let (cn, dn) = crit.polys(&x);
            if is_stable(&cn) {
                (cn, dn)
            } else {
                (c, d)
            }
        }
        Err(_) => (c, d),
    }
}

#[cfg(test)]
mod tests {
    use super::super::lm::LeastSquaresProblem;
    use super::*;

    /// The ARMA Jacobian as computed before `filter_many` and `fill_shifted` (the oracle).
    fn old_arma_jacobian(w: &[f64], nc: usize, nd: usize, x: &[f64]) -> Mat<f64> {
        let (c, d) = (monic(&x[..nc]), monic(&x[nc..nc + nd]));
        let e = filter(&d, &c, w);
        let et = filter(&[1.0], &c, &e);
        let wt = filter(&[1.0], &c, w);
        Mat::from_fn(w.len(), nc + nd, |t, k| {
            if k < nc {
                -lagged(&et, k + 1, t)
            } else {
                lagged(&wt, k - nc + 1, t)
            }
        })
    }

    #[test]
    fn arma_jacobian_is_bit_identical_to_the_old_one() {
        use rand::{RngExt, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(18);
        for (nc, nd, n) in [
            (4, 0, 1500),
            (2, 2, 2100),
            (1, 3, 5),
            (0, 2, 300),
            (3, 1, 1024),
        ] {
            let w: Vec<f64> = (0..n).map(|_| rng.random_range(-2.0..2.0)).collect();
            // C = (1 − 0.5 q⁻¹)^nc (stable), D random
            let mut c = vec![1.0];
            for _ in 0..nc {
                c = super::super::predictor::mul(&c, &[1.0, -0.5]);
            }
            let mut x = c[1..].to_vec();
            x.extend((0..nd).map(|_| rng.random_range(-0.9..0.9)));
            let mut crit = ArmaCriterion { w: &w, nc, nd };
            let new = crit.jacobian(&x).unwrap();
            let old = old_arma_jacobian(&w, nc, nd, &x);
            for k in 0..nc + nd {
                let bits = |j: &Mat<f64>| -> Vec<u64> {
                    j.col_as_slice(k).iter().map(|v| v.to_bits()).collect()
                };
                assert_eq!(bits(&new), bits(&old), "column {k} of ({nc}, {nd})");
            }
        }
    }
}
