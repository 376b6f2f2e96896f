//! Pole-zero analysis (`validate::pz`): modal frequency and damping recovered from roots mapped
//! exactly by z = exp(sT) at 20 kHz, the unstable real pole of an AMB, special roots (origin,
//! negative real axis, integrator), near cancellations measured in the s-plane (with an
//! independent brute-force check of the FRF effect), agreement with a transfer function's roots
//! when analysing its state-space realisation, and typed errors.

use ambid_core::error::Error;
use ambid_core::linalg::poly_from_roots;
use ambid_core::lti::{StateSpace, TransferFunction};
use ambid_core::validate::pz::{PzAnalysis, PzOptions, Root};
use faer::{c64, mat};
use std::f64::consts::PI;

const T: f64 = 5e-5; // 20 kHz

/// Continuous pole of a mode with natural frequency `f0` Hz and damping `zeta` (upper member).
fn s_mode(f0: f64, zeta: f64) -> c64 {
    let w = 2.0 * PI * f0;
    c64::new(-zeta * w, w * (1.0 - zeta * zeta).sqrt())
}

fn z_of(s: c64) -> c64 {
    (s * T).exp()
}

fn rel(a: f64, b: f64) -> f64 {
    (a - b).abs() / b.abs()
}

fn opts() -> PzOptions {
    PzOptions::default()
}

#[test]
fn modal_frequency_and_damping_are_recovered() {
    let s780 = s_mode(780.0, 0.002);
    let s50 = s_mode(50.0, 0.3);
    // deliberately unsorted and lower members first
    let poles = [z_of(s780).conj(), z_of(s50), z_of(s780), z_of(s50).conj()];
    let pz = PzAnalysis::from_roots(&poles, &[], T, &opts()).unwrap();
    assert_eq!(pz.poles.len(), 4);
    assert!(pz.zeros.is_empty() && pz.cancellations.is_empty());
    assert!(pz.unstable_poles().is_empty());
    let expect = [
        (50.0, 0.3, 1.0),
        (50.0, 0.3, -1.0),
        (780.0, 0.002, 1.0),
        (780.0, 0.002, -1.0),
    ];
    let mut worst_f = 0.0f64;
    let mut worst_z = 0.0f64;
    for (r, &(f0, zeta, sign)) in pz.poles.iter().zip(&expect) {
        let f = r.f_hz.unwrap();
        let d = r.damping.unwrap();
        worst_f = worst_f.max(rel(f, f0));
        worst_z = worst_z.max(rel(d, zeta));
        assert!(rel(f, f0) <= 1e-10, "f = {f}, expected {f0}");
        assert!(rel(d, zeta) <= 1e-10, "zeta = {d}, expected {zeta}");
        // upper member of each pair first, s in the matching half plane
        let s = r.s.unwrap();
        assert_eq!(s.im.signum(), sign);
        let s_true = s_mode(f0, zeta);
        let s_true = if sign > 0.0 { s_true } else { s_true.conj() };
        assert!((s - s_true).norm() <= 1e-9 * s_true.norm());
        // damped frequency
        assert!(rel(r.damped_hz().unwrap(), f0 * (1.0 - zeta * zeta).sqrt()) <= 1e-10);
        assert!(!r.unstable && !r.at_origin());
    }
    // the two members of a pair have bit-identical f and zeta
    assert_eq!(pz.poles[0].f_hz, pz.poles[1].f_hz);
    assert_eq!(pz.poles[2].damping, pz.poles[3].damping);
    println!("worst relative error: f {worst_f:.2e}, zeta {worst_z:.2e}");
}

#[test]
fn unstable_real_pole() {
    let w = 2.0 * PI * 30.0;
    let pu = z_of(c64::new(w, 0.0));
    let ps = z_of(c64::new(-w, 0.0));
    let pz = PzAnalysis::from_roots(&[ps, pu], &[], T, &opts()).unwrap();
    let u = pz.unstable_poles();
    assert_eq!(u.len(), 1);
    let r = u[0];
    assert!(r.z.re > 1.0 && r.unstable);
    assert!(rel(r.f_hz.unwrap(), 30.0) <= 1e-10, "{:?}", r.f_hz);
    assert_eq!(r.damping, Some(-1.0));
    assert!(rel(r.s.unwrap().re, w) <= 1e-10);
    let stable: Vec<&Root> = pz.poles.iter().filter(|r| !r.unstable).collect();
    assert_eq!(stable.len(), 1);
    assert_eq!(stable[0].damping, Some(1.0));
    assert!(rel(stable[0].f_hz.unwrap(), 30.0) <= 1e-10);
    assert!(pz.table().contains("unstable"));
}

#[test]
fn special_roots_origin_nyquist_integrator() {
    let poles = [
        c64::new(0.0, 0.0),
        c64::new(-1.0, -0.0), // negative zero imaginary part: still +Nyquist
        c64::new(1.0, 0.0),
        c64::new(-0.5, 0.0),
    ];
    let pz = PzAnalysis::from_roots(&poles, &[], T, &opts()).unwrap();
    // sorted: integrator (0 Hz), Nyquist (-1), above Nyquist (-0.5), origin last
    let r0 = &pz.poles[0];
    assert_eq!(
        (r0.f_hz, r0.damping, r0.unstable),
        (Some(0.0), Some(0.0), false)
    );
    let r1 = &pz.poles[1];
    assert_eq!(r1.z.re, -1.0);
    assert!(rel(r1.f_hz.unwrap(), 0.5 / T) <= 1e-14);
    assert!(rel(r1.s.unwrap().im, PI / T) <= 1e-14);
    assert_eq!(r1.damping, Some(0.0));
    assert!(!r1.unstable);
    let r2 = &pz.poles[2];
    assert_eq!(r2.z.re, -0.5);
    assert!(rel(r2.s.unwrap().im, PI / T) <= 1e-14);
    assert!(rel(r2.s.unwrap().re, 0.5f64.ln() / T) <= 1e-14);
    assert!(r2.f_hz.unwrap() > 0.5 / T && r2.damping.unwrap() > 0.0);
    let r3 = &pz.poles[3];
    assert!(r3.at_origin() && r3.s.is_none() && r3.f_hz.is_none() && r3.damping.is_none());
    assert!(!r3.unstable);
    let t = pz.table();
    assert!(t.contains("origin"), "{t}");
    // origin_tol moves the boundary
    let tiny = [c64::new(1e-7, 0.0)];
    assert!(PzAnalysis::from_roots(&tiny, &[], T, &opts())
        .unwrap()
        .poles[0]
        .at_origin());
    let strict = PzOptions {
        origin_tol: 0.0,
        ..opts()
    };
    let r = PzAnalysis::from_roots(&tiny, &[], T, &strict)
        .unwrap()
        .poles[0];
    assert!(!r.at_origin());
    assert!(rel(r.s.unwrap().re, 1e-7f64.ln() / T) <= 1e-14);
}

/// max over a dense unit-circle grid of |(e^{jθ} − z0)/(e^{jθ} − p) − 1|
fn brute_frf_effect(p: c64, z0: c64) -> f64 {
    let n = 2_000_000;
    (0..n)
        .map(|k| {
            let e = c64::from_polar(1.0, 2.0 * PI * k as f64 / n as f64);
            ((e - z0) / (e - p) - c64::new(1.0, 0.0)).norm()
        })
        .fold(0.0, f64::max)
}

#[test]
fn near_cancellation_in_the_s_plane() {
    // lightly damped 780 Hz mode with a zero 0.5 % of |s_p| away (at an arbitrary angle),
    // a 50 Hz mode with a zero 20 % away, and the unstable 30 Hz pole without a zero
    let sp1 = s_mode(780.0, 0.002);
    let sz1 = sp1 + sp1.norm() * 0.005 * c64::from_polar(1.0, 0.7);
    let sp2 = s_mode(50.0, 0.3);
    let sz2 = sp2 + sp2.norm() * 0.2 * c64::from_polar(1.0, -2.0);
    let pu = z_of(c64::new(2.0 * PI * 30.0, 0.0));
    let poles = [z_of(sp1), z_of(sp1).conj(), z_of(sp2), z_of(sp2).conj(), pu];
    let zeros = [z_of(sz1), z_of(sz1).conj(), z_of(sz2), z_of(sz2).conj()];
    let pz = PzAnalysis::from_roots(&poles, &zeros, T, &opts()).unwrap();
    // the z-plane measure would be useless here: |p - z|/|p| is ~1e-3 for the flagged pair
    let zrel = (z_of(sp1) - z_of(sz1)).norm() / z_of(sp1).norm();
    println!("z-plane relative distance of the 0.5 % pair: {zrel:.3e}");
    assert!(zrel < 0.002);

    assert_eq!(pz.cancellations.len(), 2, "{}", pz.table());
    for c in &pz.cancellations {
        let p = &pz.poles[c.pole];
        let z = &pz.zeros[c.zero];
        assert!(rel(p.f_hz.unwrap(), 780.0) < 1e-9);
        assert_eq!(p.z.im.signum(), z.z.im.signum()); // paired with its own half plane
        assert!(rel(c.relative, 0.005) <= 1e-8, "relative = {}", c.relative);
        assert!(rel(c.s_distance, 0.005 * sp1.norm()) <= 1e-8);
        assert!(rel(c.distance, (p.z - z.z).norm()) <= 1e-15);
        // the FRF effect against a brute-force maximum over the unit circle
        let brute = brute_frf_effect(p.z, z.z);
        println!(
            "pole #{} zero #{}: relative {:.6e}, frf effect {:.6} (brute force {:.6})",
            c.pole, c.zero, c.relative, c.frf_effect, brute
        );
        assert!(brute <= c.frf_effect * (1.0 + 1e-9));
        assert!(brute >= c.frf_effect * (1.0 - 1e-3));
        // ζ = 0.002: the nearly cancelling zero still changes the peak by ≈ 0.005/0.002
        assert!(c.frf_effect > 2.0 && c.frf_effect < 3.0);
        assert_eq!(pz.cancellation_of_pole(c.pole), Some(c));
    }
    // the 50 Hz pair is not flagged, and neither is anything with a tighter tolerance
    assert!(pz
        .cancellations
        .iter()
        .all(|c| rel(pz.poles[c.pole].f_hz.unwrap(), 50.0) > 0.5));
    let tight = PzOptions {
        cancellation_tol: 0.004,
        ..opts()
    };
    assert!(PzAnalysis::from_roots(&poles, &zeros, T, &tight)
        .unwrap()
        .cancellations
        .is_empty());
    // ... but a loose tolerance flags the 20 % pair too
    let loose = PzOptions {
        cancellation_tol: 0.25,
        ..opts()
    };
    assert_eq!(
        PzAnalysis::from_roots(&poles, &zeros, T, &loose)
            .unwrap()
            .cancellations
            .len(),
        4
    );

    let table = pz.table();
    println!("{table}");
    for c in &pz.cancellations {
        assert!(table.contains(&format!("cancels zero #{}", c.zero)));
        assert!(table.contains(&format!("cancels pole #{}", c.pole)));
    }
    assert!(table.contains("Near cancellations (2)"));
    assert!(table.contains("unstable"));
}

#[test]
fn cancellation_matching_is_one_to_one_and_alias_aware() {
    // a double real pole with one zero in between: one pair only
    let p = z_of(c64::new(-2.0 * PI * 100.0, 0.0));
    let z = z_of(c64::new(-2.0 * PI * 100.2, 0.0));
    let pz = PzAnalysis::from_roots(&[p, p], &[z], T, &opts()).unwrap();
    assert_eq!(pz.cancellations.len(), 1);
    assert!(rel(pz.cancellations[0].relative, 0.002) < 1e-8);
    // two roots straddling the negative real axis are close although their principal s differ
    // by almost j2π/T
    let pz = PzAnalysis::from_roots(
        &[c64::new(-0.95, 1e-6)],
        &[c64::new(-0.95, -1e-6)],
        T,
        &opts(),
    )
    .unwrap();
    assert_eq!(pz.cancellations.len(), 1);
    let c = pz.cancellations[0];
    assert!(c.s_distance < 1e-4 / T, "{c:?}");
    // two roots at the origin are the same delay; one at the origin is never paired otherwise
    let pz = PzAnalysis::from_roots(
        &[c64::new(0.0, 0.0), c64::new(0.5, 0.0)],
        &[c64::new(0.0, 0.0)],
        T,
        &opts(),
    )
    .unwrap();
    assert_eq!(pz.cancellations.len(), 1);
    assert_eq!(
        (pz.cancellations[0].pole, pz.cancellations[0].relative),
        (1, 0.0)
    );
    // z-plane-near but far in relative s-plane terms at low frequency: a 1 Hz pole with a zero
    // at 2 Hz is |Δz| ≈ 3e-4 apart yet not flagged
    let p = z_of(c64::new(-2.0 * PI * 1.0, 0.0));
    let z = z_of(c64::new(-2.0 * PI * 2.0, 0.0));
    assert!((p - z).norm() < 1e-3);
    assert!(PzAnalysis::from_roots(&[p], &[z], T, &opts())
        .unwrap()
        .cancellations
        .is_empty());
}

/// Greedy nearest matching of two unordered root sets; asserts and returns the worst distance.
fn match_sets(a: &[c64], b: &[c64], tol: f64) -> f64 {
    assert_eq!(a.len(), b.len());
    let mut used = vec![false; b.len()];
    let mut worst = 0.0f64;
    for x in a {
        let (j, d) = b
            .iter()
            .enumerate()
            .filter(|(j, _)| !used[*j])
            .map(|(j, y)| (j, (x - y).norm()))
            .min_by(|u, v| u.1.total_cmp(&v.1))
            .unwrap();
        used[j] = true;
        worst = worst.max(d);
    }
    assert!(worst <= tol, "worst root mismatch {worst:e}");
    worst
}

#[test]
fn state_space_agrees_with_transfer_function_roots() {
    // AMB-like plant: unstable 30 Hz pole, its stable mirror, a 780 Hz bending mode (ζ = 0.002),
    // with a lightly damped anti-resonance at 700 Hz, a real zero and a one-sample delay
    let s780 = s_mode(780.0, 0.002);
    let s700 = s_mode(700.0, 0.003);
    let poles_true = [
        z_of(c64::new(2.0 * PI * 30.0, 0.0)),
        z_of(c64::new(-2.0 * PI * 30.0, 0.0)),
        z_of(s780),
        z_of(s780).conj(),
    ];
    let zeros_true = [z_of(s700), z_of(s700).conj(), c64::new(-0.9, 0.0)];
    let den = poly_from_roots(&poles_true);
    let mut num = vec![0.0]; // one-sample delay: a leading zero in q^-1
    num.extend(poly_from_roots(&zeros_true).iter().map(|c| 1e-3 * c));
    let tf = TransferFunction::new(num, den, T).unwrap();
    let ss = tf.to_state_space().unwrap();
    let pz = PzAnalysis::from_state_space(&ss, &opts()).unwrap();
    assert_eq!(pz.ts, T);
    let p: Vec<c64> = pz.poles.iter().map(|r| r.z).collect();
    let z: Vec<c64> = pz.zeros.iter().map(|r| r.z).collect();
    let wp = match_sets(&p, &tf.poles().unwrap(), 1e-9);
    let wz = match_sets(&z, &tf.zeros().unwrap(), 1e-9);
    println!("max |root(SS) - root(TF)|: poles {wp:.2e}, zeros {wz:.2e}");
    // and with the constructed truth
    match_sets(&p, &poles_true, 1e-7);
    match_sets(&z, &zeros_true, 1e-7);
    assert_eq!(pz.unstable_poles().len(), 1);
    assert!(rel(pz.unstable_poles()[0].f_hz.unwrap(), 30.0) < 1e-6);
    let bend = pz
        .poles
        .iter()
        .find(|r| (r.f_hz.unwrap() - 780.0).abs() < 1.0)
        .unwrap();
    assert!(rel(bend.damping.unwrap(), 0.002) < 1e-4, "{bend:?}");
    assert!(pz.nonminimum_phase_zeros().is_empty());
    // the 700 Hz zero is 10 % from the 780 Hz pole: not a cancellation
    assert!(pz.cancellations.is_empty(), "{}", pz.table());

    // MIMO non-square: no transmission zeros
    let g = StateSpace::discrete(
        mat![[0.5]],
        mat![[1.0, 0.0]],
        mat![[1.0]],
        mat![[0.0, 0.0]],
        T,
    )
    .unwrap();
    assert!(matches!(
        PzAnalysis::from_state_space(&g, &opts()),
        Err(Error::DimensionMismatch { .. })
    ));
}

#[test]
fn bad_input_gives_typed_errors() {
    let p = [c64::new(0.5, 0.0)];
    let c = StateSpace::continuous(mat![[-1.0]], mat![[1.0]], mat![[1.0]], mat![[0.0]]).unwrap();
    assert!(matches!(
        PzAnalysis::from_state_space(&c, &opts()),
        Err(Error::TimeDomain(_))
    ));
    assert!(matches!(
        PzAnalysis::from_roots(&[p[0], c64::new(f64::NAN, 0.0)], &[], T, &opts()),
        Err(Error::NonFinite {
            what: "poles",
            index: 1
        })
    ));
    assert!(matches!(
        PzAnalysis::from_roots(&p, &[c64::new(0.0, f64::INFINITY)], T, &opts()),
        Err(Error::NonFinite {
            what: "zeros",
            index: 0
        })
    ));
    for tol in [-0.01, f64::NAN, f64::INFINITY] {
        let o = PzOptions {
            cancellation_tol: tol,
            ..opts()
        };
        assert!(matches!(
            PzAnalysis::from_roots(&p, &[], T, &o),
            Err(Error::InvalidArgument {
                name: "cancellation_tol",
                ..
            })
        ));
    }
    for tol in [-1e-9, 1.0, f64::NAN] {
        let o = PzOptions {
            origin_tol: tol,
            ..opts()
        };
        assert!(matches!(
            PzAnalysis::from_roots(&p, &[], T, &o),
            Err(Error::InvalidArgument {
                name: "origin_tol",
                ..
            })
        ));
    }
    for ts in [0.0, -T, f64::NAN, f64::INFINITY] {
        assert!(matches!(
            PzAnalysis::from_roots(&p, &[], ts, &opts()),
            Err(Error::InvalidArgument { name: "ts", .. })
        ));
    }
    // a negative tolerance is refused even for a state-space model
    let d = StateSpace::discrete(mat![[0.5]], mat![[1.0]], mat![[1.0]], mat![[0.0]], T).unwrap();
    let o = PzOptions {
        cancellation_tol: -1.0,
        ..opts()
    };
    assert!(matches!(
        PzAnalysis::from_state_space(&d, &o),
        Err(Error::InvalidArgument { .. })
    ));
}
