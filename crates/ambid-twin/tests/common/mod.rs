//! Test helpers: a maximum-length PRBS and a period-averaged DFT estimator.
#![allow(dead_code)]

use ambid_twin::c64;
use std::f64::consts::PI;

/// Maximum-length PRBS of order 10 (Fibonacci LFSR, x^10 + x^7 + 1), ±`amp`, `nb` samples per
/// bit, `periods` periods of 1023·nb samples.
pub fn prbs10(amp: f64, nb: usize, periods: usize) -> Vec<f64> {
    let mut state: u16 = 0x3ff;
    let mut bits = Vec::with_capacity(1023);
    for _ in 0..1023 {
        let out = state & 1;
        bits.push(out);
        // taps 10 and 7 (bits 0 and 3 of a right-shifting register)
        let fb = (state ^ (state >> 3)) & 1;
        state = (state >> 1) | (fb << 9);
    }
    assert_eq!(
        state, 0x3ff,
        "LFSR must return to its seed after 1023 steps"
    );
    let mut v = Vec::with_capacity(1023 * nb * periods);
    for _ in 0..periods {
        for &b in &bits {
            for _ in 0..nb {
                v.push(if b == 1 { amp } else { -amp });
            }
        }
    }
    v
}

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
