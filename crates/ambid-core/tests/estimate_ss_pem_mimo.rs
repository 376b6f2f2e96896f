//! Time-domain MIMO PEM (`estimate::ss_pem`), the bar of issue 21: noise-free recovery of random
//! stable 2×2 systems and of a random open-loop-unstable 2×2 plant recorded in closed loop
//! (Markov parameters to 1e-8 of their norm, the unstable pole kept), and Monte Carlo coverage of
//! the ±1.96σ intervals of the sandwich covariance (90–98 %).
//!
//! Every truth is independent of the estimator: the Markov parameters and frequency responses of
//! the simulated system, and the characteristic polynomials of its true predictor $A - KC$.

use ambid_core::c64;
use ambid_core::estimate::pem::Focus;
use ambid_core::estimate::ss_pem::{refine_ss, SsPemFit, SsPemOptions};
use ambid_core::estimate::subspace::{n4sid, SubspaceOptions};
use ambid_core::linalg;
use ambid_core::lti::StateSpace;
use faer::{mat, Mat, MatRef};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

/// Sample time of every system here \[s\] (1 kHz).
const TS: f64 = 1e-3;
/// Markov parameters compared (h_1 … h_50; h_0 = D = 0 on both sides).
const N_MARKOV: usize = 51;
/// The bar of issue 21.
const MARKOV_TOL: f64 = 1e-8;

fn gauss(rng: &mut ChaCha8Rng) -> f64 {
    rng.sample(StandardNormal)
}

fn unif(rng: &mut ChaCha8Rng, lo: f64, hi: f64) -> f64 {
    lo + (hi - lo) * rng.random::<f64>()
}

fn randn(rng: &mut ChaCha8Rng, r: usize, c: usize) -> Mat<f64> {
    Mat::from_fn(r, c, |_, _| gauss(rng))
}

/// Real block-diagonal matrix with the given poles (one entry per complex pair, im > 0).
fn modal(poles: &[c64]) -> Mat<f64> {
    let n: usize = poles.iter().map(|p| if p.im > 0.0 { 2 } else { 1 }).sum();
    let mut a = Mat::<f64>::zeros(n, n);
    let mut s = 0;
    for p in poles {
        if p.im > 0.0 {
            a[(s, s)] = p.re;
            a[(s, s + 1)] = p.im;
            a[(s + 1, s)] = -p.im;
            a[(s + 1, s + 1)] = p.re;
            s += 2;
        } else {
            a[(s, s)] = p.re;
            s += 1;
        }
    }
    a
}

/// All eigenvalues (conjugates included) of `modal(poles)`.
fn spectrum(poles: &[c64]) -> Vec<c64> {
    poles
        .iter()
        .flat_map(|p| {
            if p.im > 0.0 {
                vec![*p, p.conj()]
            } else {
                vec![*p]
            }
        })
        .collect()
}

fn min_separation(poles: &[c64]) -> f64 {
    let s = spectrum(poles);
    let mut d = f64::INFINITY;
    for i in 0..s.len() {
        for j in 0..i {
            d = d.min((s[i] - s[j]).norm());
        }
    }
    d
}

/// A random well-conditioned basis $T$ (condition number below 10) and $T^{-1}$.
fn random_basis(rng: &mut ChaCha8Rng, n: usize) -> (Mat<f64>, Mat<f64>) {
    loop {
        let t = randn(rng, n, n);
        let sv = linalg::singular_values(t.as_ref()).unwrap();
        if sv[0] < 10.0 * sv[n - 1] {
            let ti = linalg::solve(t.as_ref(), Mat::<f64>::identity(n, n).as_ref()).unwrap();
            return (t, ti);
        }
    }
}

/// A system in modal coordinates: $A$ = `modal(poles)`, $B$, $C$ and an optional innovation gain
/// $K$ in the same coordinates, $D = 0$.
#[derive(Clone)]
struct Modal {
    poles: Vec<c64>,
    b: Mat<f64>,
    c: Mat<f64>,
    k: Option<Mat<f64>>,
}

impl Modal {
    /// Random $B$ ($n \times 2$) and $C$ ($2 \times n$), no $K$.
    fn random_2x2(rng: &mut ChaCha8Rng, poles: Vec<c64>) -> Self {
        let n = spectrum(&poles).len();
        let b = randn(rng, n, 2);
        let c = randn(rng, 2, n);
        Self {
            poles,
            b,
            c,
            k: None,
        }
    }
    /// The model (and $K$) in the basis $x_{\text{modal}} = T^{-1} x$.
    fn realise(&self, t: &Mat<f64>, ti: &Mat<f64>) -> (StateSpace, Option<Mat<f64>>) {
        let a = t * modal(&self.poles) * ti;
        let b = t * &self.b;
        let c = &self.c * ti;
        let l = c.nrows();
        let m = b.ncols();
        let g = StateSpace::discrete(a, b, c, Mat::zeros(l, m), TS).unwrap();
        (g, self.k.as_ref().map(|k| t * k))
    }
    /// In a random basis.
    fn realise_random(&self, rng: &mut ChaCha8Rng) -> (StateSpace, Option<Mat<f64>>) {
        let (t, ti) = random_basis(rng, self.b.nrows());
        self.realise(&t, &ti)
    }
    /// Every pole's modulus and angle (a real pole itself) and every entry of $B$, $C$ (not $K$)
    /// multiplied by $1 + \text{rel}\cdot\mathcal N(0, 1)$; a pole that would cross the unit
    /// circle stops half-way to it (a stable pole stays stable, an unstable one unstable).
    fn perturbed(&self, rel: f64, rng: &mut ChaCha8Rng) -> Self {
        let mut f = |x: f64| x * (1.0 + rel * gauss(rng));
        let side = |old: f64, new: f64| {
            let half = 0.5 * (1.0 + old.abs());
            if old.abs() < 1.0 {
                new.abs().min(half).copysign(new)
            } else {
                new.abs().max(half).copysign(new)
            }
        };
        let poles = self
            .poles
            .iter()
            .map(|p| {
                if p.im > 0.0 {
                    c64::from_polar(side(p.norm(), f(p.norm())), f(p.arg()))
                } else {
                    c64::new(side(p.re, f(p.re)), 0.0)
                }
            })
            .collect();
        let mut g = |x: &Mat<f64>| Mat::from_fn(x.nrows(), x.ncols(), |i, j| f(x[(i, j)]));
        let (b, c) = (g(&self.b), g(&self.c));
        Self {
            poles,
            b,
            c,
            k: self.k.clone(),
        }
    }
}

/// Four stable poles, pairwise at least 0.15 apart: a complex pair (|p| 0.6–0.97, angle
/// 0.2–2.6 rad) and either a second pair or two real poles in (−0.7, 0.95).
fn stable_poles(rng: &mut ChaCha8Rng) -> Vec<c64> {
    loop {
        let mut p = vec![c64::from_polar(unif(rng, 0.6, 0.97), unif(rng, 0.2, 2.6))];
        if rng.random::<bool>() {
            p.push(c64::from_polar(unif(rng, 0.5, 0.97), unif(rng, 0.2, 2.6)));
        } else {
            p.push(c64::new(unif(rng, -0.7, 0.95), 0.0));
            p.push(c64::new(unif(rng, -0.7, 0.95), 0.0));
        }
        if min_separation(&p) >= 0.15 {
            return p;
        }
    }
}

/// An AMB-like unstable real pole (1.02–1.05), a stable real pole and a complex pair.
fn unstable_poles(rng: &mut ChaCha8Rng) -> Vec<c64> {
    loop {
        let p = vec![
            c64::new(unif(rng, 1.02, 1.05), 0.0),
            c64::new(unif(rng, -0.6, 0.9), 0.0),
            c64::from_polar(unif(rng, 0.6, 0.95), unif(rng, 0.3, 2.5)),
        ];
        if min_separation(&p) >= 0.15 {
            return p;
        }
    }
}

/// Steady-state Kalman gain of `g` for unit process and measurement noise: $A - KC$ is stable
/// whenever $(A, C)$ is detectable, so it is an admissible predictor gain for an unstable start.
fn kalman_gain(g: &StateSpace) -> Mat<f64> {
    let (a, c) = (g.a(), g.c());
    let (n, l) = (g.order(), g.noutputs());
    let p = linalg::dare(
        a.transpose(),
        c.transpose(),
        Mat::<f64>::identity(n, n).as_ref(),
        Mat::<f64>::identity(l, l).as_ref(),
        None,
    )
    .unwrap();
    let s = c * &p * c.transpose() + Mat::<f64>::identity(l, l);
    // K = A P Cᵀ S⁻¹, S symmetric
    let kt = linalg::solve(s.as_ref(), (c * &p * a.transpose()).as_ref()).unwrap();
    kt.transpose().to_owned()
}

fn spectral_radius(a: MatRef<'_, f64>) -> f64 {
    linalg::eigenvalues(a)
        .unwrap()
        .iter()
        .map(|z| z.norm())
        .fold(0.0, f64::max)
}

/// $\lVert [h_k - \hat h_k]_k \rVert_F / \lVert [h_k]_k \rVert_F$ over the first `n` Markov
/// parameters (all four entries): the models compared up to similarity.
fn markov_rel_error(truth: &StateSpace, est: &StateSpace, n: usize) -> f64 {
    let (ht, he) = (
        truth.impulse_response(n).unwrap(),
        est.impulse_response(n).unwrap(),
    );
    let (mut num, mut den) = (0.0, 0.0);
    for (t, e) in ht.iter().zip(&he) {
        num += (t - e).squared_norm_l2();
        den += t.squared_norm_l2();
    }
    (num / den).sqrt()
}

/// No loss tolerance (the default 1e-10 is meant for noisy data and would stop a noise-free fit
/// early) and up to 200 iterations: the solver runs until the trust region collapses at the
/// rounding floor.
fn exact_opts(focus: Focus) -> SsPemOptions {
    SsPemOptions {
        focus,
        lm: SsPemOptions::default()
            .lm
            .with_loss_tol(0.0)
            .unwrap()
            .with_max_iterations(200)
            .unwrap(),
        ..SsPemOptions::default()
    }
}

fn fit(
    y: &Mat<f64>,
    u: &Mat<f64>,
    start: &StateSpace,
    k: Option<&Mat<f64>>,
    focus: Focus,
) -> SsPemFit {
    refine_ss(
        y.as_ref(),
        u.as_ref(),
        start,
        k.map(|k| k.as_ref()),
        &exact_opts(focus),
    )
    .unwrap()
}

/// N4SID of order `n` with a fixed horizon of 10 block rows (noise-free data need no ladder).
fn subspace_start(y: &Mat<f64>, u: &Mat<f64>, n: usize) -> StateSpace {
    let opts = SubspaceOptions {
        order: Some(n),
        block_rows: Some(10),
        ..SubspaceOptions::new(TS)
    };
    n4sid(y.as_ref(), u.as_ref(), &opts).unwrap().model
}

/// One random stable 2×2 system of order 4 (seed `2100 + seed`), $N = 1500$ samples of white
/// inputs, noise-free output; refined under both focuses from two starts. Returns the worst
/// Markov error; panics above [`MARKOV_TOL`].
fn stable_case(seed: u64) -> f64 {
    let n = 1500;
    let mut worst: f64 = 0.0;
    let mut rng = ChaCha8Rng::seed_from_u64(2100 + seed);
    let poles = stable_poles(&mut rng);
    let sys = Modal::random_2x2(&mut rng, poles.clone());
    let (truth, _) = sys.realise_random(&mut rng);
    assert!(spectral_radius(truth.a()) < 1.0);
    let u = randn(&mut rng, n, 2);
    let y = truth.simulate(u.as_ref(), None).unwrap();
    // starts: the N4SID model (the pipeline; on noise-free data it is already exact to rounding),
    // and the truth 3 % off (poles, B, C in modal coordinates) in another random basis, so that
    // the PEM itself has to do the work
    let sub = subspace_start(&y, &u, 4);
    let (pert, _) = sys.perturbed(0.03, &mut rng).realise_random(&mut rng);
    for (name, start) in [("N4SID", &sub), ("truth +3 %", &pert)] {
        assert!(
            spectral_radius(start.a()) < 1.0,
            "seed {seed}: {name} start unstable"
        );
        let e0 = markov_rel_error(&truth, start, N_MARKOV);
        for focus in [Focus::Simulation, Focus::Prediction] {
            // K starts at 0 under the prediction focus (A is stable)
            let f = fit(&y, &u, start, None, focus);
            let err = markov_rel_error(&truth, &f.fitted.model, N_MARKOV);
            eprintln!(
                "stable seed {seed} (poles {:.3?}), start {name} ({e0:.1e}), {focus:?}: \
                 Markov error {err:.2e}, {} iterations, {:?}",
                spectrum(&poles),
                f.report.iterations,
                f.report.reason
            );
            assert!(
                err <= MARKOV_TOL,
                "seed {seed}, {name}, {focus:?}: Markov error {err:e}"
            );
            worst = worst.max(err);
        }
    }
    worst
}

#[test]
fn noise_free_random_stable_2x2_systems_are_recovered_to_1e_8() {
    let worst = (0..8).map(stable_case).fold(0.0, f64::max);
    eprintln!("stable 2×2, 8 systems: worst Markov error {worst:.2e}");
}

/// Observer-based output feedback $u = -K(q)\,y + r$ for `g`: LQR gain $F$ and Kalman gain $L$
/// (unit weights), controller $x_c^+ = (A - BF - LC)x_c + L y$, $u = -F x_c + r$ (the
/// excitation is added at the controller output and the controller sees only $y$). Returns the
/// closed loop from $r$ to $[y; u]$.
fn closed_loop(g: &StateSpace) -> StateSpace {
    let (a, b, c) = (g.a(), g.b(), g.c());
    let (n, m, l) = (g.order(), g.ninputs(), g.noutputs());
    let x = linalg::dare(
        a,
        b,
        Mat::<f64>::identity(n, n).as_ref(),
        Mat::<f64>::identity(m, m).as_ref(),
        None,
    )
    .unwrap();
    let r = b.transpose() * &x * b + Mat::<f64>::identity(m, m);
    let f = linalg::solve(r.as_ref(), (b.transpose() * &x * a).as_ref()).unwrap();
    let lg = kalman_gain(g);
    let ac = a - b * &f - &lg * c;
    let bf = b * &f;
    let lc = &lg * c;
    let acl = Mat::from_fn(2 * n, 2 * n, |i, j| match (i < n, j < n) {
        (true, true) => a[(i, j)],
        (true, false) => -bf[(i, j - n)],
        (false, true) => lc[(i - n, j)],
        (false, false) => ac[(i - n, j - n)],
    });
    let bcl = Mat::from_fn(2 * n, m, |i, j| if i < n { b[(i, j)] } else { 0.0 });
    let ccl = Mat::from_fn(l + m, 2 * n, |i, j| match (i < l, j < n) {
        (true, true) => c[(i, j)],
        (false, false) => -f[(i - l, j - n)],
        _ => 0.0,
    });
    let dcl = Mat::from_fn(
        l + m,
        m,
        |i, j| if i >= l && i - l == j { 1.0 } else { 0.0 },
    );
    StateSpace::discrete(acl, bcl, ccl, dcl, TS).unwrap()
}

/// Markov tolerance of the start with the unstable pole moved inside the unit circle. This
/// start goes beyond the bar (its point is that the PEM takes the pole out again); in a sweep of
/// 60 seeds it reached at most 2.3e-9 except on seed 15, where the refinement stops at 5.6e-8
/// with a loss of 4.6e-24 (the same data from the other two starts reach 6.6e-29 and 2.1e-25):
/// a rounding floor of the coordinates it converged to (K is free on noise-free data), which
/// `LmOptions::exhaustive` does not lower.
const INSIDE_START_TOL: f64 = 1e-7;

/// One random open-loop-unstable 2×2 plant of order 4 (seed `2150 + seed`) in closed loop,
/// $N = 2000$ samples of white excitation $r$, noise-free; the plant refined from the recorded
/// $(u, y)$ under the prediction focus from three starts. Returns the worst Markov error of the
/// two starts the bar is about; panics when a start misses its tolerance or the unstable pole.
fn unstable_case(seed: u64) -> f64 {
    let n = 2000;
    let mut worst: f64 = 0.0;
    let mut rng = ChaCha8Rng::seed_from_u64(2150 + seed);
    let poles = unstable_poles(&mut rng);
    let p_u = poles[0].re;
    let sys = Modal::random_2x2(&mut rng, poles.clone());
    let (plant, _) = sys.realise_random(&mut rng);
    let cl = closed_loop(&plant);
    let rho_cl = spectral_radius(cl.a());
    assert!(
        rho_cl < 0.99,
        "seed {seed}: closed loop not stable ({rho_cl})"
    );
    let r = randn(&mut rng, n, 2);
    let yu = cl.simulate(r.as_ref(), None).unwrap();
    let y = yu.subcols(0, 2).to_owned();
    let u = yu.subcols(2, 2).to_owned();
    // the plant from the recorded (u, y): u is correlated with y through the loop.
    // starts: N4SID on (u, y) (noise-free, so the closed loop does not bias it), the truth 3 %
    // off (poles, B, C in modal coordinates) in another random basis, and the latter with its
    // unstable pole moved inside, to 0.98 (the PEM has to take it out of the unit circle); the
    // predictor gain of each start is its own Kalman gain (A − KC stable)
    let sub = subspace_start(&y, &u, 4);
    let pert_sys = sys.perturbed(0.03, &mut rng);
    let (pert, _) = pert_sys.realise_random(&mut rng);
    let mut inside = pert_sys.clone();
    inside.poles[0] = c64::new(0.98, 0.0);
    let (inside, _) = inside.realise_random(&mut rng);
    for (name, start, tol) in [
        ("N4SID", &sub, MARKOV_TOL),
        ("truth +3 %", &pert, MARKOV_TOL),
        (
            "truth +3 %, unstable pole at 0.98",
            &inside,
            INSIDE_START_TOL,
        ),
    ] {
        let k = kalman_gain(start);
        let e0 = markov_rel_error(&plant, start, N_MARKOV);
        let rho0 = spectral_radius(start.a());
        let f = fit(&y, &u, start, Some(&k), Focus::Prediction);
        let err = markov_rel_error(&plant, &f.fitted.model, N_MARKOV);
        let est = f.fitted.model.poles().unwrap();
        let outside: Vec<c64> = est.iter().copied().filter(|z| z.norm() >= 1.0).collect();
        eprintln!(
            "unstable seed {seed} (plant poles {:.4?}, closed-loop radius {rho_cl:.3}), start \
             {name} (Markov error {e0:.1e}, spectral radius {rho0:.4}): Markov error {err:.2e}, \
             estimated unstable poles {outside:.10?}, {} iterations, {:?}",
            spectrum(&poles),
            f.report.iterations,
            f.report.reason
        );
        assert!(err <= tol, "seed {seed}, {name}: Markov error {err:e}");
        // exactly one pole outside the unit circle, at the plant's: never stabilised
        assert_eq!(outside.len(), 1, "seed {seed}, {name}: {est:?}");
        assert!(
            (outside[0] - c64::new(p_u, 0.0)).norm() < tol,
            "seed {seed}, {name}: unstable pole {:?} vs {p_u}",
            outside[0]
        );
        if tol == MARKOV_TOL {
            worst = worst.max(err);
        }
    }
    worst
}

#[test]
fn noise_free_unstable_2x2_plant_is_recovered_in_closed_loop_with_its_unstable_pole() {
    let worst = (0..8).map(unstable_case).fold(0.0, f64::max);
    eprintln!("unstable 2×2 in closed loop, 8 plants: worst Markov error {worst:.2e}");
}

/// Both noise-free cases over 60 seeds each (about 15 s in debug).
#[test]
#[ignore = "the sweep behind the 8-seed tests; run with --ignored"]
fn noise_free_sweep_over_60_seeds() {
    let ws = (0..60).map(stable_case).fold(0.0, f64::max);
    let wu = (0..60).map(unstable_case).fold(0.0, f64::max);
    eprintln!("60 seeds: worst Markov error stable {ws:.2e}, unstable in closed loop {wu:.2e}");
}

/// The Monte Carlo system: two lightly damped modes, 2 inputs, 2 outputs, an innovation gain
/// (modal coordinates), and its realisation in a fixed non-modal basis.
fn mc_system() -> (Modal, StateSpace, Mat<f64>) {
    let sys = Modal {
        poles: vec![c64::from_polar(0.9, 0.5), c64::from_polar(0.8, 1.6)],
        b: mat![[1.0, 0.2], [0.0, -0.5], [0.4, 1.0], [-0.3, 0.6]],
        c: mat![[1.0, 0.0, 0.5, -0.2], [0.3, 1.0, -0.4, 0.6]],
        k: Some(mat![[0.2, -0.1], [0.1, 0.15], [-0.1, 0.2], [0.05, -0.1]]),
    };
    let t = mat![
        [1.0, 0.3, -0.2, 0.1],
        [0.2, 1.0, 0.4, -0.3],
        [-0.1, 0.2, 1.0, 0.5],
        [0.3, -0.4, 0.1, 1.0]
    ];
    let ti = linalg::solve(t.as_ref(), Mat::<f64>::identity(4, 4).as_ref()).unwrap();
    let (g, k) = sys.realise(&t, &ti);
    (sys, g, k.unwrap())
}

/// Output of the innovation model $x^+ = Ax + Bu + Ke$, $y = Cx + Du + e$.
fn innovation_output(g: &StateSpace, k: &Mat<f64>, u: &Mat<f64>, e: &Mat<f64>) -> Mat<f64> {
    let (n, m, l) = (g.order(), g.ninputs(), g.noutputs());
    let b = Mat::from_fn(
        n,
        m + l,
        |i, j| if j < m { g.b()[(i, j)] } else { k[(i, j - m)] },
    );
    let d = Mat::from_fn(l, m + l, |i, j| {
        if j < m {
            g.d()[(i, j)]
        } else if i == j - m {
            1.0
        } else {
            0.0
        }
    });
    let aug = StateSpace::discrete(g.a().to_owned(), b, g.c().to_owned(), d, TS).unwrap();
    let w = Mat::from_fn(u.nrows(), m + l, |t, j| {
        if j < m {
            u[(t, j)]
        } else {
            e[(t, j - m)]
        }
    });
    aug.simulate(w.as_ref(), None).unwrap()
}

/// Monic quadratics $z^2 + a_1 z + a_2$ of complex pairs of `poles`, sorted by imaginary part
/// (the order of the 2×2 blocks of `refine_ss`'s parameterisation for complex poles).
fn pair_polys(poles: &[c64]) -> Vec<(f64, f64)> {
    let mut up: Vec<c64> = poles.iter().copied().filter(|z| z.im > 0.0).collect();
    up.sort_by(|x, y| x.im.total_cmp(&y.im));
    up.iter().map(|z| (-2.0 * z.re, z.norm_sqr())).collect()
}

/// What [`monte_carlo`] measured: ±1.96σ hits and totals of the predictor polynomials and of
/// the FRF at 0 Hz and Nyquist, and the ratio of the Monte Carlo RMS error to the RMS predicted
/// std of each α and of the complex FRF at three frequencies.
struct McStats {
    alpha: (usize, usize),
    frf: (usize, usize),
    alpha_ratio: [f64; 4],
    frf_ratio: [f64; 3],
}

impl McStats {
    fn coverage(&self) -> (f64, f64, f64) {
        let c = |(h, t): (usize, usize)| h as f64 / t as f64;
        let pooled = c((self.alpha.0 + self.frf.0, self.alpha.1 + self.frf.1));
        (c(self.alpha), c(self.frf), pooled)
    }
}

/// `runs` realisations of $N$ = `n` samples of the innovation model of [`mc_system`] (white
/// unit inputs, correlated white innovations), each refined by `refine_ss` (prediction focus,
/// default options) from the truth 2 % off; the ±1.96σ intervals of the sandwich covariance
/// against the truth.
fn monte_carlo(runs: u64, n: usize) -> McStats {
    let (sys, truth, k) = mc_system();
    // innovation covariance Λ = L Lᵀ with correlated channels
    let le = mat![[0.3, 0.0], [0.1, 0.2]];
    // truths: the predictor's block polynomials (parameters (α1, α2) = (a1 + 2, a2 + a1 + 1) of
    // each 2×2 block, module docs of ss_pem) and the real-valued FRF at 0 Hz and Nyquist
    let abar = truth.a() - &k * truth.c();
    let pbar = linalg::eigenvalues(abar.as_ref()).unwrap();
    assert!(pbar.iter().all(|z| z.im.abs() > 0.05 && z.norm() < 1.0));
    let alpha_true: Vec<f64> = pair_polys(&pbar)
        .iter()
        .flat_map(|&(a1, a2)| [a1 + 2.0, a2 + a1 + 1.0])
        .collect();
    assert_eq!(alpha_true.len(), 4);
    let f_real = [0.0, 0.5 / TS];
    let g_real = truth.freq_response(&f_real).unwrap();
    // FRF at other frequencies: only |Ĝ − G| against the combined std (no per-part std there)
    let f_cplx = [20.0, 80.0, 250.0];
    let g_cplx = truth.freq_response(&f_cplx).unwrap();
    let (mut sq_err, mut pred_var) = ([0.0; 3], [0.0; 3]);
    let (mut a_sq_err, mut a_pred_var) = ([0.0; 4], [0.0; 4]);
    let (mut inside_alpha, mut inside_frf, mut total_alpha, mut total_frf) = (0, 0, 0, 0);
    let block = 2 + 2 * 4 + 2; // per 2×2 block: (α1, α2), G_b (2 × (m + l)), one free C row
    for run in 0..runs {
        let mut rng = ChaCha8Rng::seed_from_u64(21_000 + run);
        let u = randn(&mut rng, n, 2);
        let w = randn(&mut rng, n, 2);
        let e = &w * le.transpose();
        let y = innovation_output(&truth, &k, &u, &e);
        // start: the truth 2 % off (poles, B, C in modal coordinates) in a random basis, with the
        // truth's K in that basis
        let (start, ks) = sys.perturbed(0.02, &mut rng).realise_random(&mut rng);
        let f = refine_ss(
            y.as_ref(),
            u.as_ref(),
            &start,
            ks.as_ref().map(|k| k.as_ref()),
            &SsPemOptions::default(),
        )
        .unwrap();
        let sd = f.fitted.std().expect("covariance");
        let th = &f.fitted.params;
        // the fitted predictor's poles are those of the θ polynomials (layout check)
        let g = &f.fitted.model;
        let kf = f.kalman_gain.as_ref().unwrap();
        let pfit = pair_polys(&linalg::eigenvalues((g.a() - kf * g.c()).as_ref()).unwrap());
        assert_eq!(pfit.len(), 2, "run {run}: predictor poles not two pairs");
        for (b, &(a1, a2)) in pfit.iter().enumerate() {
            let (al1, al2) = (th[block * b], th[block * b + 1]);
            assert!(
                (al1 - (a1 + 2.0)).abs() < 1e-9 && (al2 - (a2 + a1 + 1.0)).abs() < 1e-9,
                "run {run}: θ layout changed"
            );
        }
        for (j, &want) in alpha_true.iter().enumerate() {
            let idx = block * (j / 2) + j % 2;
            total_alpha += 1;
            if (th[idx] - want).abs() <= 1.96 * sd[idx] {
                inside_alpha += 1;
            }
            a_sq_err[j] += (th[idx] - want).powi(2);
            a_pred_var[j] += sd[idx].powi(2);
        }
        // FRF at 0 Hz and Nyquist: real, so the std is that of the real part
        let gr = g.freq_response(&f_real).unwrap();
        let sr = f.frequency_response_std(&f_real).unwrap();
        for q in 0..f_real.len() {
            for (o, c) in [(0, 0), (0, 1), (1, 0), (1, 1)] {
                assert!(gr[q][(o, c)].im.abs() < 1e-9 * gr[q][(o, c)].norm().max(1.0));
                total_frf += 1;
                if (gr[q][(o, c)].re - g_real[q][(o, c)].re).abs() <= 1.96 * sr[q][(o, c)] {
                    inside_frf += 1;
                }
            }
        }
        let gc = g.freq_response(&f_cplx).unwrap();
        let sc = f.frequency_response_std(&f_cplx).unwrap();
        for q in 0..f_cplx.len() {
            for (o, c) in [(0, 0), (0, 1), (1, 0), (1, 1)] {
                sq_err[q] += (gc[q][(o, c)] - g_cplx[q][(o, c)]).norm_sqr();
                pred_var[q] += sc[q][(o, c)].powi(2);
            }
        }
    }
    let stats = McStats {
        alpha: (inside_alpha, total_alpha),
        frf: (inside_frf, total_frf),
        alpha_ratio: std::array::from_fn(|j| (a_sq_err[j] / a_pred_var[j]).sqrt()),
        frf_ratio: std::array::from_fn(|q| (sq_err[q] / pred_var[q]).sqrt()),
    };
    let (ca, cf, pooled) = stats.coverage();
    eprintln!(
        "{runs} realisations of N = {n}: ±1.96σ coverage of the predictor polynomials \
         {inside_alpha}/{total_alpha} = {ca:.3}, of the FRF at 0 Hz and Nyquist \
         {inside_frf}/{total_frf} = {cf:.3}, pooled {pooled:.3}"
    );
    eprintln!(
        "  Monte Carlo RMS error / RMS predicted std: α {:.3?}; complex FRF (4 entries) at {f_cplx:?} Hz {:.3?}",
        stats.alpha_ratio, stats.frf_ratio
    );
    stats
}

fn assert_honest(s: &McStats) {
    let (ca, cf, pooled) = s.coverage();
    assert!((0.90..=0.98).contains(&pooled), "pooled coverage {pooled}");
    // neither family alone may be far off either
    assert!((0.88..=0.99).contains(&ca), "predictor polynomials: {ca}");
    assert!((0.88..=0.99).contains(&cf), "FRF at 0 Hz and Nyquist: {cf}");
    for r in s.alpha_ratio.iter().chain(&s.frf_ratio) {
        assert!((0.8..=1.25).contains(r), "RMS error / predicted std {r}");
    }
}

#[test]
fn mimo_intervals_cover_90_to_98_percent_over_120_realisations() {
    assert_honest(&monte_carlo(120, 2000));
}

/// The same with more and longer records (`cargo test --release -- --ignored`).
#[test]
#[ignore = "about 40 s in debug; the 120-realisation version runs by default"]
fn mimo_intervals_cover_90_to_98_percent_over_500_long_realisations() {
    assert_honest(&monte_carlo(500, 5000));
}
