//! `lti::pid::PidSpec` against closed-form values: pure P, the Tustin integrator and derivative,
//! the bilinear frequency warping, prewarping, ZOH (step invariance and `c2d_zoh` of an
//! independently built continuous model), the computation delay and every validation error.

use ambid_core::c64;
use ambid_core::lti::{Discretisation, PidSpec, StateSpace, TransferFunction};
use ambid_core::Error;
use faer::mat;
use std::f64::consts::PI;

const TS: f64 = 1.0 / 20e3;

/// The twin's nominal controller (kp = 21000, f_i = 5 Hz, kd = 14, f_d = 4 kHz, f_l = 5 kHz).
fn nominal() -> PidSpec {
    let kp = 21_000.0;
    PidSpec::new(kp, kp * 2.0 * PI * 5.0, 14.0, TS)
        .with_derivative_cutoff_hz(4e3)
        .with_lowpass_hz(5e3)
}

fn log_grid(f0: f64, f1: f64, n: usize) -> Vec<f64> {
    (0..n)
        .map(|k| f0 * (f1 / f0).powf(k as f64 / (n - 1) as f64))
        .collect()
}

fn max_rel(got: &[c64], want: &[c64]) -> f64 {
    got.iter()
        .zip(want)
        .map(|(g, w)| (g - w).norm() / w.norm())
        .fold(0.0, f64::max)
}

fn qinv(f: f64, ts: f64) -> c64 {
    c64::from_polar(1.0, -2.0 * PI * f * ts)
}

#[test]
fn pure_p_is_kp_at_every_frequency() {
    let p = PidSpec::new(21_000.0, 0.0, 0.0, TS);
    let ss = p.state_space().unwrap();
    assert_eq!(ss.order(), 0);
    let f = [0.0, 1.0, 100.0, 5e3, 9_999.0, 10e3];
    for h in p.freq_response(&f).unwrap() {
        assert_eq!(h, c64::new(21_000.0, 0.0));
    }
    let tf = p.transfer_function().unwrap();
    assert_eq!((tf.num(), tf.den()), (&[21_000.0][..], &[1.0][..]));
    // kd = 0: a derivative corner is accepted and ignored
    let p2 = p.clone().with_derivative_cutoff_hz(1e3);
    assert_eq!(p2.state_space().unwrap().order(), 0);
    for m in [
        Discretisation::Zoh,
        Discretisation::TustinPrewarp { f_hz: 1e3 },
    ] {
        let h = p.clone().with_method(m).freq_response(&f).unwrap();
        assert!(h.iter().all(|h| *h == c64::new(21_000.0, 0.0)));
    }
}

#[test]
fn pi_diverges_at_dc_with_a_pole_at_z_equal_1() {
    let (kp, ki) = (21_000.0, 21_000.0 * 2.0 * PI * 5.0);
    let pi = PidSpec::new(kp, ki, 0.0, TS);
    let err = pi.freq_response(&[0.0]).unwrap_err();
    assert!(matches!(err, Error::Numerical { .. }), "{err}");
    let poles = pi.state_space().unwrap().poles().unwrap();
    assert_eq!(poles.len(), 1);
    assert!((poles[0] - c64::new(1.0, 0.0)).norm() < 1e-15);
    // Tustin integrator, exactly: Kp + Ki T/2 (1 + q^-1)/(1 - q^-1) = Kp − j Ki T/2 cot(θ/2),
    // θ = 2πf Ts. Evaluating at z = e^{jθ} costs about eps/θ near the pole (z − 1 cancels), so
    // the tolerance grows towards DC.
    let f = log_grid(1e-3, 9.9e3, 80);
    let h = pi.freq_response(&f).unwrap();
    for (h, &f) in h.iter().zip(&f) {
        let th = 2.0 * PI * f * TS;
        let want = c64::new(kp, -ki * TS / 2.0 / (th / 2.0).tan());
        let e = (h - want).norm() / want.norm();
        let tol = 1e-13f64.max(2e-16 / th);
        assert!(e < tol, "Tustin PI at {f} Hz: rel err {e:.2e} > {tol:.1e}");
    }
    // |C| grows like Ki/(2πf) towards DC
    let h = pi.freq_response(&[1e-6]).unwrap()[0];
    assert!((h.norm() * 2.0 * PI * 1e-6 / ki - 1.0).abs() < 1e-6);
    assert!(pi.continuous_freq_response(&[0.0]).is_err());
}

#[test]
fn tustin_derivative_at_nyquist_is_kd_omega_d() {
    // Kd s/(1+s/ωd) with s = (2/T)(z−1)/(z+1): at z = −1, s → ∞ and the part tends to Kd ωd.
    // With p = (α−ωd)/(α+ωd), g = Kd ωd α/(α+ωd): g (z−1)/(z−p) at z = −1 is 2g/(1+p) = Kd ωd.
    let (kd, fd) = (14.0, 4e3);
    let wd = 2.0 * PI * fd;
    let nyq = 0.5 / TS;
    for method in [
        Discretisation::Tustin,
        Discretisation::TustinPrewarp { f_hz: 1e3 },
        Discretisation::TustinPrewarp { f_hz: 9e3 },
    ] {
        let d = PidSpec::new(0.0, 0.0, kd, TS)
            .with_derivative_cutoff_hz(fd)
            .with_method(method);
        let h = d.freq_response(&[nyq]).unwrap()[0];
        assert!(
            (h - c64::new(kd * wd, 0.0)).norm() < 1e-12 * kd * wd,
            "{method}: {h} vs {}",
            kd * wd
        );
        // and it is zero at DC
        assert!(d.freq_response(&[0.0]).unwrap()[0].norm() < 1e-9);
    }
    // the Tustin coefficients of the module docs
    let alpha = 2.0 / TS;
    let p = (alpha - wd) / (alpha + wd);
    let g = kd * wd * alpha / (alpha + wd);
    let d = PidSpec::new(0.0, 0.0, kd, TS).with_derivative_cutoff_hz(fd);
    let f = log_grid(1.0, 9.9e3, 40);
    let want: Vec<c64> = f
        .iter()
        .map(|&f| {
            let q = qinv(f, TS);
            g * (1.0 - q) / (1.0 - p * q)
        })
        .collect();
    let e = max_rel(&d.freq_response(&f).unwrap(), &want);
    assert!(e < 1e-12, "Tustin derivative: {e:.2e}");
    // the low-pass vanishes at Nyquist
    let l = PidSpec::new(1.0, 0.0, 0.0, TS).with_lowpass_hz(5e3);
    assert!(l.freq_response(&[nyq]).unwrap()[0].norm() < 1e-12);
}

#[test]
fn tustin_is_the_continuous_response_at_the_warped_frequency() {
    let pid = nominal();
    let f = log_grid(1.0, 9.9e3, 120);
    let h = pid.freq_response(&f).unwrap();
    let fw: Vec<f64> = f.iter().map(|f| (PI * f * TS).tan() / (PI * TS)).collect();
    let want = pid.continuous_freq_response(&fw).unwrap();
    let e = max_rel(&h, &want);
    assert!(e < 1e-12, "Tustin warping identity: {e:.2e}");
    // prewarped at fp: T' = 2 tan(ωp Ts/2)/ωp, exact at fp
    for fp in [100.0, 2e3, 7.5e3] {
        let pw = nominal().with_method(Discretisation::TustinPrewarp { f_hz: fp });
        let wp = 2.0 * PI * fp;
        let t = 2.0 * (wp * TS / 2.0).tan() / wp;
        let fw: Vec<f64> = f
            .iter()
            .map(|f| (2.0 / t) * (PI * f * TS).tan() / (2.0 * PI))
            .collect();
        let e = max_rel(
            &pw.freq_response(&f).unwrap(),
            &pw.continuous_freq_response(&fw).unwrap(),
        );
        // near Nyquist the low-pass zero makes |C| small, so the relative error grows a little
        assert!(e < 1e-11, "prewarp {fp}: {e:.2e}");
        let at = pw.freq_response(&[fp]).unwrap()[0];
        let c = pw.continuous_freq_response(&[fp]).unwrap()[0];
        assert!((at - c).norm() < 1e-12 * c.norm(), "prewarp exact at {fp}");
    }
}

#[test]
fn continuous_model_matches_the_formula() {
    for spec in [
        nominal(),
        PidSpec::new(5.0, 0.0, 0.0, TS).with_lowpass_hz(300.0),
        PidSpec::new(5.0, 30.0, 0.0, TS),
        PidSpec::new(0.0, 0.0, 2.0, TS).with_derivative_cutoff_hz(50.0),
        PidSpec::new(1.0, 0.0, 2.0, TS)
            .with_derivative_cutoff_hz(50.0)
            .with_lowpass_hz(f64::INFINITY),
    ] {
        let f = log_grid(0.1, 1e5, 50);
        let c = spec.continuous_state_space().unwrap();
        let e = max_rel(
            &c.freq_response_siso(&f).unwrap(),
            &spec.continuous_freq_response(&f).unwrap(),
        );
        assert!(e < 1e-12, "{spec}: {e:.2e}");
    }
}

/// The nominal C(s) = ωl/(s+ωl) [Kp + Ki/s + Kd ωd − Kd ωd²/(s+ωd)] in partial fractions,
/// r0/s + rd/(s+ωd) + rl/(s+ωl): residues at 0, −ωd and −ωl.
fn residues(kp: f64, ki: f64, kd: f64, wd: f64, wl: f64) -> [f64; 3] {
    let r0 = ki;
    let rd = wl / (wl - wd) * (-kd * wd * wd);
    let rl = wl * (kp - ki / wl + kd * wd - kd * wd * wd / (wd - wl));
    [r0, rd, rl]
}

#[test]
fn zoh_equals_the_step_invariant_partial_fractions_and_c2d_zoh_of_the_modal_form() {
    let (kp, ki, kd) = (21_000.0, 21_000.0 * 2.0 * PI * 5.0, 14.0);
    let (wd, wl) = (2.0 * PI * 4e3, 2.0 * PI * 5e3);
    let spec = nominal().with_method(Discretisation::Zoh);
    let [r0, rd, rl] = residues(kp, ki, kd, wd, wl);
    let f = log_grid(1.0, 9.9e3, 120);
    let got = spec.freq_response(&f).unwrap();
    // closed form: ZOH{1/s} = T q^-1/(1 − q^-1), ZOH{1/(s+p)} = (1 − e^{−pT})/p · q^-1/(1 − e^{−pT} q^-1)
    let first = |p: f64, q: c64| {
        let a = (-p * TS).exp();
        (1.0 - a) / p * q / (1.0 - a * q)
    };
    let want: Vec<c64> = f
        .iter()
        .map(|&f| {
            let q = qinv(f, TS);
            r0 * TS * q / (1.0 - q) + rd * first(wd, q) + rl * first(wl, q)
        })
        .collect();
    let e = max_rel(&got, &want);
    println!("ZOH vs closed-form partial fractions: max rel err {e:.2e}");
    assert!(e < 1e-11, "ZOH closed form: {e:.2e}");
    // c2d_zoh of the modal (diagonal) realisation, independent of PidSpec's
    let modal = StateSpace::continuous(
        mat![[0.0, 0.0, 0.0], [0.0, -wd, 0.0], [0.0, 0.0, -wl]],
        mat![[1.0], [1.0], [1.0]],
        mat![[r0, rd, rl]],
        mat![[0.0]],
    )
    .unwrap();
    let want = modal.c2d_zoh(TS).unwrap().freq_response_siso(&f).unwrap();
    let e = max_rel(&got, &want);
    println!("ZOH vs c2d_zoh(modal continuous): max rel err {e:.2e}");
    assert!(e < 1e-11, "ZOH vs c2d_zoh: {e:.2e}");
    // and c2d_zoh of PidSpec's own continuous model, and its state space
    let own = spec
        .continuous_state_space()
        .unwrap()
        .c2d_zoh(TS)
        .unwrap()
        .freq_response_siso(&f)
        .unwrap();
    assert!(max_rel(&got, &own) < 1e-14);
    let ss = spec.state_space().unwrap();
    assert!(max_rel(&ss.freq_response_siso(&f).unwrap(), &got) < 1e-14);
}

#[test]
fn zoh_parts_are_step_invariant() {
    // integrator: Ki T q^-1/(1 − q^-1)
    let ki = 300.0;
    let i = PidSpec::new(0.0, ki, 0.0, TS).with_method(Discretisation::Zoh);
    let f = log_grid(0.5, 9.9e3, 30);
    let want: Vec<c64> = f
        .iter()
        .map(|&f| {
            let q = qinv(f, TS);
            ki * TS * q / (1.0 - q)
        })
        .collect();
    assert!(max_rel(&i.freq_response(&f).unwrap(), &want) < 1e-12);
    // derivative: Kd ωd [1 − (1 − a) q^-1/(1 − a q^-1)], a = e^{−ωd T}; at Nyquist
    // Kd ωd · 2/(1 + a)
    let (kd, wd) = (14.0, 2.0 * PI * 4e3);
    let a = (-wd * TS).exp();
    let d = PidSpec::new(0.0, 0.0, kd, TS)
        .with_derivative_cutoff_hz(4e3)
        .with_method(Discretisation::Zoh);
    // = Kd ωd (1 − q^-1)/(1 − a q^-1), with 1 − q^-1 = 2j sin(θ/2) e^{−jθ/2} (no cancellation)
    let want: Vec<c64> = f
        .iter()
        .map(|&f| {
            let th = 2.0 * PI * f * TS;
            let one_minus_q = c64::new(0.0, 2.0 * (th / 2.0).sin()) * qinv(f / 2.0, TS);
            kd * wd * one_minus_q / (1.0 - a * qinv(f, TS))
        })
        .collect();
    let e = max_rel(&d.freq_response(&f).unwrap(), &want);
    println!("ZOH derivative: max rel err {e:.2e}");
    assert!(e < 1e-11, "ZOH derivative: {e:.2e}");
    let h = d.freq_response(&[0.5 / TS]).unwrap()[0];
    assert!((h - c64::new(kd * wd * 2.0 / (1.0 + a), 0.0)).norm() < 1e-12 * kd * wd);
    // step response of the ZOH equivalent equals the continuous step response at the samples
    let (kp, wl) = (2.0, 2.0 * PI * 500.0);
    let l = PidSpec::new(kp, 0.0, 0.0, TS)
        .with_lowpass_hz(500.0)
        .with_method(Discretisation::Zoh);
    let y = l
        .state_space()
        .unwrap()
        .simulate_siso(&[1.0; 20], None)
        .unwrap();
    for (k, y) in y.iter().enumerate() {
        let want = kp * (1.0 - (-wl * k as f64 * TS).exp());
        assert!((y - want).abs() < 1e-13 * kp, "k = {k}: {y} vs {want}");
    }
}

#[test]
fn transfer_function_matches_state_space() {
    for spec in [
        nominal(),
        nominal().with_method(Discretisation::Zoh),
        nominal().with_method(Discretisation::TustinPrewarp { f_hz: 1e3 }),
        nominal().with_delay_samples(2),
        PidSpec::new(3.0, 0.0, 0.0, TS).with_delay_samples(1),
    ] {
        let tf = spec.transfer_function().unwrap();
        let f = log_grid(1.0, 9.9e3, 60);
        let e = max_rel(
            &tf.freq_response(&f).unwrap(),
            &spec.freq_response(&f).unwrap(),
        );
        assert!(e < 1e-9, "{spec}: {e:.2e}");
        let back = TransferFunction::from_state_space(&spec.state_space().unwrap()).unwrap();
        assert_eq!(back.ts(), TS);
    }
}

#[test]
fn delay_multiplies_by_q_to_the_minus_d() {
    let base = nominal();
    let f = log_grid(1.0, 9.9e3, 50);
    let h0 = base.freq_response(&f).unwrap();
    for d in [1usize, 3] {
        let spec = base.clone().with_delay_samples(d);
        let ss = spec.state_space().unwrap();
        assert_eq!(ss.order(), 3 + d);
        let want: Vec<c64> = h0
            .iter()
            .zip(&f)
            .map(|(h, &f)| h * qinv(f, TS).powi(d as i32))
            .collect();
        assert!(max_rel(&spec.freq_response(&f).unwrap(), &want) < 1e-12);
        let e_ss = max_rel(&ss.freq_response_siso(&f).unwrap(), &want);
        println!("delay {d}: state-space {e_ss:.2e}");
        assert!(e_ss < 1e-12, "{e_ss}");
        let tf = spec.transfer_function().unwrap();
        assert!(tf.num()[..d].iter().all(|b| *b == 0.0) && tf.num()[d] != 0.0);
        // impulse response: d leading zeros, then the undelayed one
        let h = ss.impulse_response_siso(6 + d).unwrap();
        let h0 = base
            .state_space()
            .unwrap()
            .impulse_response_siso(6)
            .unwrap();
        assert!(h[..d].iter().all(|x| *x == 0.0));
        for (a, b) in h[d..].iter().zip(&h0) {
            assert!((a - b).abs() <= 1e-12 * b.abs().max(1.0));
        }
    }
}

fn invalid_name(spec: &PidSpec) -> (&'static str, String) {
    match spec.state_space() {
        Err(Error::InvalidArgument { name, reason }) => (name, reason),
        other => panic!("expected InvalidArgument, got {other:?}"),
    }
}

#[test]
fn every_invalid_field_is_named_with_a_reason() {
    let base = nominal();
    let mut cases: Vec<(PidSpec, &str, &str)> = Vec::new();
    for ts in [0.0, -1e-4, f64::NAN, f64::INFINITY] {
        cases.push((PidSpec { ts, ..base.clone() }, "ts", "positive"));
    }
    for v in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
        cases.push((
            PidSpec {
                kp: v,
                ..base.clone()
            },
            "kp",
            "finite",
        ));
        cases.push((
            PidSpec {
                ki: v,
                ..base.clone()
            },
            "ki",
            "finite",
        ));
        cases.push((
            PidSpec {
                kd: v,
                ..base.clone()
            },
            "kd",
            "finite",
        ));
    }
    cases.push((
        PidSpec {
            kp: -1.0,
            ..base.clone()
        },
        "kp",
        "w - y",
    ));
    cases.push((
        PidSpec {
            kd: -1.0,
            ..base.clone()
        },
        "kd",
        ">= 0",
    ));
    cases.push((PidSpec::new(0.0, 0.0, 0.0, TS), "kp", "all zero"));
    cases.push((
        PidSpec {
            derivative_cutoff_hz: None,
            ..base.clone()
        },
        "derivative_cutoff_hz",
        "pure derivative",
    ));
    cases.push((
        base.clone().with_derivative_cutoff_hz(f64::INFINITY),
        "derivative_cutoff_hz",
        "improper",
    ));
    cases.push((
        base.clone().with_derivative_cutoff_hz(10e3),
        "derivative_cutoff_hz",
        "Nyquist frequency fs/2 = 10000 Hz",
    ));
    cases.push((
        base.clone().with_derivative_cutoff_hz(f64::NAN),
        "derivative_cutoff_hz",
        "positive",
    ));
    cases.push((
        base.clone().with_derivative_cutoff_hz(-5.0),
        "derivative_cutoff_hz",
        "positive",
    ));
    cases.push((base.clone().with_lowpass_hz(12e3), "lowpass_hz", "Nyquist"));
    cases.push((base.clone().with_lowpass_hz(0.0), "lowpass_hz", "positive"));
    cases.push((
        base.clone()
            .with_method(Discretisation::TustinPrewarp { f_hz: 10e3 }),
        "prewarp_hz",
        "Nyquist",
    ));
    cases.push((
        base.clone()
            .with_method(Discretisation::TustinPrewarp { f_hz: f64::NAN }),
        "prewarp_hz",
        "finite",
    ));
    cases.push((
        base.clone()
            .with_delay_samples(PidSpec::MAX_DELAY_SAMPLES + 1),
        "delay_samples",
        "plant",
    ));
    for (spec, name, phrase) in cases {
        let (got, reason) = invalid_name(&spec);
        assert_eq!(got, name, "{spec:?}: {reason}");
        assert!(
            reason.contains(phrase),
            "{name}: `{reason}` lacks `{phrase}`"
        );
        // every public conversion validates
        assert!(spec.transfer_function().is_err());
        assert!(spec.freq_response(&[10.0]).is_err());
        assert!(spec.continuous_freq_response(&[10.0]).is_err());
    }
    // non-finite frequencies
    assert!(matches!(
        base.freq_response(&[1.0, f64::NAN]),
        Err(Error::NonFinite {
            what: "f_hz",
            index: 1
        })
    ));
    // the largest delay is accepted
    assert!(base
        .with_delay_samples(PidSpec::MAX_DELAY_SAMPLES)
        .state_space()
        .is_ok());
}

#[test]
fn display_lists_the_parts() {
    let s = nominal().with_delay_samples(1).to_string();
    for part in [
        "kp = 21000",
        "kd = 14",
        "4000 Hz",
        "5000 Hz",
        "fs = 20000",
        "Tustin",
        "delay 1",
    ] {
        assert!(s.contains(part), "`{s}` lacks `{part}`");
    }
    let z = PidSpec::new(1.0, 0.0, 0.0, 1e-3).with_method(Discretisation::Zoh);
    assert!(z.to_string().contains("ZOH"));
}
