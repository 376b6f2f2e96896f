//! Test helper: a naive period-averaged DFT estimator (the oracle for the twin's truth).
#![allow(dead_code)]

use ambid_twin::c64;
use std::f64::consts::PI;

/// Averages the periods `skip..` of `x` (period `n`) and returns the DFT of the average at lines
/// `1..=lmax`.
pub fn averaged_dft(x: &[f64], n: usize, skip: usize, lmax: usize) -> Vec<c64> {
    let p = x.len() / n;
    let mut avg = vec![0.0; n];
    for per in skip..p {
        for (a, v) in avg.iter_mut().zip(&x[per * n..(per + 1) * n]) {
            *a += v;
        }
    }
    let cnt = (p - skip) as f64;
    avg.iter_mut().for_each(|a| *a /= cnt);
    (1..=lmax)
        .map(|l| {
            let mut acc = c64::new(0.0, 0.0);
            for (k, &v) in avg.iter().enumerate() {
                let ph = -2.0 * PI * (l * k % n) as f64 / n as f64;
                acc += c64::from_polar(v, ph);
            }
            acc
        })
        .collect()
}

/// Every experiment of the multi-input design `exc` run on the 4-axis `machine` with the
/// options `opts(e)` of experiment `e`, as records with the design's period.
pub fn run_design(
    machine: &ambid_twin::Machine,
    exc: &ambid_core::signal::multi::MultiExcitation,
    opts: impl Fn(usize) -> ambid_twin::MachineSimOptions,
) -> Vec<ambid_core::data::IoData> {
    let n = exc.period_samples();
    exc.samples()
        .iter()
        .enumerate()
        .map(|(e, r)| {
            machine
                .simulate([&r[0], &r[1], &r[2], &r[3]], &opts(e))
                .unwrap()
                .to_iodata(Some(n))
                .unwrap()
        })
        .collect()
}

/// The plant in a random state basis $T$ ($A' = T^{-1}AT$, $B' = T^{-1}B$, $C' = CT$), $T$ near
/// the identity with seeded Gaussian entries: a model that is right up to rounding but shares
/// no matrix with the truth.
pub fn random_basis(p: &ambid_core::lti::StateSpace, seed: u64) -> ambid_core::lti::StateSpace {
    use faer::linalg::solvers::DenseSolveCore;
    use rand::SeedableRng;
    use rand_distr::{Distribution, StandardNormal};
    let n = p.order();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let t = faer::Mat::<f64>::from_fn(n, n, |i, j| {
        let g: f64 = StandardNormal.sample(&mut rng);
        if i == j {
            1.0 + 0.3 * g
        } else {
            0.3 * g / (n as f64).sqrt()
        }
    });
    let ti = t.partial_piv_lu().inverse();
    ambid_core::lti::StateSpace::discrete(
        &ti * p.a() * &t,
        &ti * p.b(),
        p.c() * &t,
        p.d().to_owned(),
        p.ts().unwrap(),
    )
    .unwrap()
}
