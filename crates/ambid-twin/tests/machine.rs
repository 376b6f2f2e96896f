//! The 4-axis machine against independent truth: the single-plane twin, rigid-rotor gyroscopic
//! physics, naive DFTs of the simulation, and eigenvalues of an independently assembled loop.

#![allow(clippy::needless_range_loop)]

use ambid_twin::{
    c64, campbell, random_rig, Machine, MachineConfig, MachineSimOptions, Mode, Twin, TwinConfig,
    TwinError, UnbalanceConfig, Whirl,
};
use faer::Mat;
use std::f64::consts::PI;

fn log_grid(n: usize, f0: f64, f1: f64) -> Vec<f64> {
    (0..n)
        .map(|k| f0 * (f1 / f0).powf(k as f64 / (n - 1) as f64))
        .collect()
}

fn at_speed(cfg: &MachineConfig, rpm: f64) -> Machine {
    Machine::new(MachineConfig {
        speed_rpm: rpm,
        ..cfg.clone()
    })
    .unwrap()
}

/// Largest |P_xy| / max|P| over the lines (x–y cross terms).
fn cross_ratio(p: &[Mat<c64>]) -> f64 {
    let mut worst = 0.0f64;
    for m in p {
        let scale = (0..4)
            .flat_map(|i| (0..4).map(move |j| (i, j)))
            .map(|(i, j)| m[(i, j)].norm())
            .fold(0.0, f64::max);
        for i in 0..4 {
            for j in 0..4 {
                if (i < 2) != (j < 2) {
                    worst = worst.max(m[(i, j)].norm() / scale);
                }
            }
        }
    }
    worst
}

fn mats(frd: &ambid_core::lti::Frd) -> Vec<Mat<c64>> {
    (0..frd.len()).map(|l| frd.at(l).unwrap()).collect()
}

/// Checks the standstill physics of the machine built from the single-plane rig `tc`.
fn standstill_physics(tc: &TwinConfig) {
    let f = log_grid(200, 1.0, 5000.0);
    let twin = Twin::new(tc.clone()).unwrap();
    let siso = twin.plant_frf(&f).unwrap();
    let m = Machine::new(MachineConfig::from_twin(tc)).unwrap();
    let p = mats(&m.plant_frf(&f).unwrap());
    let c = mats(&m.controller_frf(&f).unwrap());
    // (1a) x–y cross terms vanish
    let cr = cross_ratio(&p);
    assert!(cr <= 1e-12, "cross terms at standstill: {cr:e}");
    // (1b) the x-plane 2×2 block with loop B closed (in-test algebra) = the SISO plant; y = x
    let mut worst = 0.0f64;
    let mut worst_y = 0.0f64;
    for l in 0..f.len() {
        for (o, wy) in [(0usize, false), (2, true)] {
            let pm = &p[l];
            let cb = c[l][(o + 1, o + 1)];
            let pa = pm[(o, o)]
                - pm[(o, o + 1)] * cb * pm[(o + 1, o)]
                    / (c64::new(1.0, 0.0) + pm[(o + 1, o + 1)] * cb);
            let e = (pa - siso[l]).norm() / siso[l].norm();
            if wy {
                worst_y = worst_y.max(e);
            } else {
                worst = worst.max(e);
            }
        }
        for i in 0..2 {
            for j in 0..2 {
                let (x, y) = (p[l][(i, j)], p[l][(2 + i, 2 + j)]);
                let e = (x - y).norm() / x.norm();
                // rounding of the ZOH exponential differs by position in the state vector
                assert!(
                    e <= 1e-10,
                    "y plane ≠ x plane at {} Hz: {e:e} ({i},{j})",
                    f[l]
                );
            }
        }
    }
    println!("x block vs SISO {worst:.2e}, y block vs SISO {worst_y:.2e}");
    assert!(worst <= 1e-9 && worst_y <= 1e-9, "{worst:e} {worst_y:e}");
    // the per-axis plant as a state-space model: same response, one unstable pole = the SISO one
    let siso_pole = twin.plant_unstable_poles().unwrap();
    for axis in 0..4 {
        let ss = m.axis_plant(axis).unwrap();
        let fr = m.axis_plant_frf(axis, &f).unwrap();
        let g = ss.freq_response_siso(&f).unwrap();
        for l in 0..f.len() {
            let v = fr.at(l).unwrap()[(0, 0)];
            assert!(
                (g[l] - v).norm() <= 1e-9 * v.norm(),
                "axis {axis} at {} Hz",
                f[l]
            );
        }
        let up: Vec<c64> = ss
            .poles()
            .unwrap()
            .into_iter()
            .filter(|z| z.norm() > 1.0)
            .collect();
        assert_eq!(up.len(), 1, "axis {axis}: {up:?}");
        if axis % 2 == 0 {
            assert!(
                (up[0] - siso_pole[0]).norm() < 1e-9,
                "{up:?} vs {siso_pole:?}"
            );
        }
    }
    // per-axis peak sensitivity: the A axes' equal the single-plane twin's at standstill
    let pk = m.peak_sensitivity().unwrap();
    let (fs, vs) = twin.peak_sensitivity().unwrap();
    for axis in [0, 2] {
        assert!(
            (pk[axis].1 - vs).abs() < 1e-9 * vs,
            "{:?} vs {vs}",
            pk[axis]
        );
        assert!(
            (pk[axis].0 - fs).abs() < 1e-3 * fs,
            "{:?} vs {fs}",
            pk[axis]
        );
    }
    assert!(
        (pk[1].1 - pk[3].1).abs() < 1e-9 * pk[1].1 && (pk[1].0 - pk[3].0).abs() < 1e-3 * pk[1].0
    );
    // the per-axis plant with the other three loops closed = the SISO plant for A axes
    for axis in [0, 2] {
        let pa = m.axis_plant_frf(axis, &f).unwrap();
        for l in 0..f.len() {
            let e = (pa.at(l).unwrap()[(0, 0)] - siso[l]).norm() / siso[l].norm();
            assert!(e <= 1e-9, "axis {axis} at {} Hz: {e:e}", f[l]);
        }
    }
}

#[test]
fn standstill_planes_decouple_and_reproduce_the_siso_twin() {
    standstill_physics(&TwinConfig::default());
}

#[test]
fn random_rigs_standstill_and_speed_physics() {
    for seed in [1u64, 4, 9] {
        let tc = random_rig(seed).unwrap();
        standstill_physics(&tc);
        let cfg = MachineConfig::from_twin(&tc);
        // cross terms appear at speed and vanish as Ω → 0
        let f = log_grid(40, 20.0, 2000.0);
        let p0 = mats(&at_speed(&cfg, 0.0).plant_frf(&f).unwrap());
        let p1 = mats(&at_speed(&cfg, 20_000.0).plant_frf(&f).unwrap());
        let pe = mats(&at_speed(&cfg, 1e-3).plant_frf(&f).unwrap());
        assert!(cross_ratio(&p1) > 1e-3, "seed {seed}: {}", cross_ratio(&p1));
        let d: f64 = (0..f.len())
            .map(|l| (&pe[l] - &p0[l]).norm_l2() / p0[l].norm_l2())
            .fold(0.0, f64::max);
        assert!(d < 1e-6, "seed {seed}: P(Ω→0) − P(0) = {d:e}");
    }
}

#[test]
fn cross_terms_grow_with_speed_and_vanish_at_standstill() {
    let cfg = MachineConfig::default();
    // the tilt mode's frequency
    let f = [156.0];
    let mut last = -1.0;
    for rpm in [0.0, 10_000.0, 20_000.0, 30_000.0] {
        let p = at_speed(&cfg, rpm).plant_frf(&f).unwrap().at(0).unwrap();
        let cross = p[(2, 0)].norm().max(p[(3, 0)].norm()).max(p[(2, 1)].norm());
        println!("{rpm} rpm: |P_ya,xa| {:.3e}", p[(2, 0)].norm());
        if rpm == 0.0 {
            assert!(cross <= 1e-12 * p[(0, 0)].norm());
        }
        assert!(cross > last, "{rpm} rpm: {cross:e} ≤ {last:e}");
        last = cross;
    }
    // P(Ω) → P(0), linearly in Ω
    let grid = log_grid(50, 1.0, 5000.0);
    let p0 = mats(&at_speed(&cfg, 0.0).plant_frf(&grid).unwrap());
    let dist = |rpm: f64| {
        let p = mats(&at_speed(&cfg, rpm).plant_frf(&grid).unwrap());
        (0..grid.len())
            .map(|l| (&p[l] - &p0[l]).norm_l2() / p0[l].norm_l2())
            .fold(0.0, f64::max)
    };
    let (d1, d2) = (dist(1.0), dist(0.1));
    println!("|P(1 rpm) − P(0)| {d1:e}, |P(0.1 rpm) − P(0)| {d2:e}");
    assert!(d1 < 1e-3 && (d1 / d2 - 10.0).abs() < 0.5, "{d1:e} {d2:e}");
}

#[test]
fn gyroscopic_sign_convention_forward_whirl_stiffens() {
    // a rigid rotor analogue: the gyroscopic term couples θ̇_y into θ̈_x with −Ω J_p/J_t and θ̇_x
    // into θ̈_y with +Ω J_p/J_t (rotation about +z)
    let cfg = MachineConfig {
        speed_rpm: 30_000.0,
        ..Default::default()
    };
    let m = Machine::new(cfg.clone()).unwrap();
    let a = m.continuous_model().a();
    let g = cfg.omega() * cfg.polar_inertia() / cfg.rotor.inertia();
    // states: q_x (0..3), q_y (3..6), q̇_x (6..9), q̇_y (9..12); θ_x = 1, θ_y = 4
    assert!((a[(7, 10)] + g).abs() <= 1e-14 * g && (a[(10, 7)] - g).abs() <= 1e-14 * g);
    // default polar inertia: solid steel cylinder of 5 kg and 0.5 m
    let r = (5.0 / (PI * 7850.0 * 0.5f64)).sqrt();
    assert!((cfg.polar_inertia() - 0.5 * 5.0 * r * r).abs() < 1e-15);
    assert!((cfg.polar_inertia() - 1.0137e-3).abs() < 1e-6);
}

#[test]
fn campbell_forward_tilt_rises_backward_falls() {
    let cfg = MachineConfig::default();
    let speeds = [0.0, 10_000.0, 20_000.0, 30_000.0];
    let c = campbell(&cfg, &speeds, 1000.0).unwrap();
    let tilt = |pt: &ambid_twin::CampbellPoint| -> Vec<ambid_twin::MachineMode> {
        pt.modes
            .iter()
            .copied()
            .filter(|m| m.freq_hz > 120.0 && m.freq_hz < 250.0)
            .collect()
    };
    let t0 = tilt(&c[0]);
    assert_eq!(t0.len(), 2);
    assert!(t0.iter().all(|m| m.whirl == Whirl::None));
    // a double eigenvalue of the 36-state loop is computed to ≈ 1e-6 (its sensitivity)
    assert!((t0[0].damped_freq_hz - t0[1].damped_freq_hz).abs() < 1e-5 * t0[0].damped_freq_hz);
    // at standstill: each single-plane mode twice
    let siso = Twin::new(TwinConfig::default())
        .unwrap()
        .closed_loop_modes();
    assert_eq!(c[0].modes.len(), 2 * siso.len());
    for (k, m) in c[0].modes.iter().enumerate() {
        let s = siso[k / 2];
        assert!(
            (m.freq_hz - s.freq_hz).abs() < 1e-5 * s.freq_hz,
            "{m:?} vs {s:?}"
        );
        assert!((m.damping - s.damping).abs() < 1e-5);
    }
    let (mut f_prev, mut b_prev) = (t0[0].damped_freq_hz, t0[0].damped_freq_hz);
    let mut splits = Vec::new();
    for (k, pt) in c.iter().enumerate().skip(1) {
        assert!((pt.sync_hz - speeds[k] / 60.0).abs() < 1e-12 * speeds[k]);
        let t = tilt(pt);
        assert_eq!(t.len(), 2, "{:?}", t);
        let fw = t.iter().find(|m| m.whirl == Whirl::Forward).unwrap();
        let bw = t.iter().find(|m| m.whirl == Whirl::Backward).unwrap();
        println!(
            "{} rpm: forward {:.3} Hz ({:.3}), backward {:.3} Hz ({:.3})",
            speeds[k],
            fw.damped_freq_hz,
            fw.forward_fraction,
            bw.damped_freq_hz,
            bw.forward_fraction
        );
        assert!(fw.damped_freq_hz > f_prev && bw.damped_freq_hz < b_prev);
        // rigid-rotor physics: J_t ω² − J_p Ω ω − k = 0 splits the pair by J_p Ω / J_t
        let split =
            cfg.polar_inertia() * speeds[k] * 2.0 * PI / 60.0 / cfg.rotor.inertia() / (2.0 * PI);
        let got = fw.damped_freq_hz - bw.damped_freq_hz;
        // (a rigid rotor on springs and dampers splits the damped frequencies by exactly J_pΩ/J_t;
        // the PID's frequency-dependent stiffness widens it here by ≈ 20 %)
        println!("split {got:.4} Hz, rigid-rotor J_pΩ/(2πJ_t) {split:.4} Hz");
        assert!(
            got / split > 1.0 && got / split < 1.4,
            "split {got} vs {split}"
        );
        splits.push(got / speeds[k]);
        assert!(fw.forward_fraction > 0.9 && bw.forward_fraction < 0.1);
        f_prev = fw.damped_freq_hz;
        b_prev = bw.damped_freq_hz;
    }
    // the split grows in proportion to the speed (gyroscopic moment ∝ Ω), to first order
    assert!((splits[2] / splits[0] - 1.0).abs() < 0.05, "{splits:?}");
}

/// The slowest closed-loop decay, as the number of samples to shrink a transient by `tol`.
fn settle_for(m: &Machine, tol: f64) -> usize {
    let rho = m
        .closed_loop_poles()
        .unwrap()
        .iter()
        .map(|z| z.norm())
        .fold(0.0, f64::max);
    (tol.ln() / rho.ln()).ceil() as usize
}

fn dft(x: &[f64], line: usize) -> c64 {
    let n = x.len();
    x.iter()
        .enumerate()
        .map(|(k, &v)| c64::from_polar(v, -2.0 * PI * (line * k % n) as f64 / n as f64))
        .sum()
}

#[test]
fn linear_simulation_reproduces_t_ry_and_s_columns() {
    let cfg = MachineConfig {
        speed_rpm: 30_000.0,
        asymmetry: ambid_twin::AsymmetryConfig {
            ki_rel: 0.03,
            kx_rel: -0.02,
            ki_rel_b: -0.05,
            kx_rel_b: 0.04,
        },
        ..Default::default()
    };
    let m = Machine::new(cfg).unwrap();
    let n = 2000; // 10 Hz resolution
    let lines: Vec<usize> = (1..=200).step_by(7).collect(); // 10 Hz … 1.97 kHz
    let f: Vec<f64> = lines
        .iter()
        .map(|&l| l as f64 * m.fs() / n as f64)
        .collect();
    let tr = m.t_ry_frf(&f).unwrap();
    let s = m.sensitivity_frf(&f).unwrap();
    let settle = settle_for(&m, 1e-13);
    for axis in [0usize, 3] {
        let r: Vec<f64> = (0..n)
            .map(|k| {
                lines
                    .iter()
                    .enumerate()
                    .map(|(q, &l)| {
                        let ph = PI * (q * q) as f64 / lines.len() as f64;
                        0.004 * (2.0 * PI * (l * k) as f64 / n as f64 + ph).cos()
                    })
                    .sum()
            })
            .collect();
        let z = vec![0.0; n];
        let mut rs: [&[f64]; 4] = [&z, &z, &z, &z];
        rs[axis] = &r;
        let rec = m
            .simulate(
                rs,
                &MachineSimOptions {
                    noise: false,
                    settle_samples: settle,
                    ..Default::default()
                },
            )
            .unwrap();
        assert!(rec.meta.saturated_fraction.iter().all(|&v| v == 0.0));
        let mut worst = 0.0f64;
        for (q, &l) in lines.iter().enumerate() {
            let rl = dft(&rec.r[axis], l);
            let tcol = tr.at(q).unwrap();
            let scol = s.at(q).unwrap();
            let tscale = (0..4).map(|i| tcol[(i, axis)].norm()).fold(0.0, f64::max);
            let sscale = (0..4).map(|i| scol[(i, axis)].norm()).fold(0.0, f64::max);
            for i in 0..4 {
                let ty = dft(&rec.y[i], l) / rl;
                let su = dft(&rec.u[i], l) / rl;
                worst = worst.max((ty - tcol[(i, axis)]).norm() / tscale);
                worst = worst.max((su - scol[(i, axis)]).norm() / sscale);
            }
        }
        println!("axis {axis}: worst relative column error {worst:.2e} (settle {settle})");
        assert!(worst <= 1e-8, "axis {axis}: {worst:e}");
    }
}

#[test]
fn closed_loop_model_modes_and_sensitivity_peaks_agree() {
    let m = at_speed(&MachineConfig::default(), 25_000.0);
    // (a) the closed-loop state space reproduces the FRF algebra
    let f = [3.0, 97.0, 156.0, 780.0, 3000.0];
    let g = m.closed_loop().freq_response(&f).unwrap();
    let tr = m.t_ry_frf(&f).unwrap();
    let s = m.sensitivity_frf(&f).unwrap();
    for l in 0..f.len() {
        let (t, sm) = (tr.at(l).unwrap(), s.at(l).unwrap());
        for i in 0..4 {
            for j in 0..4 {
                assert!((g[l][(i, j)] - t[(i, j)]).norm() <= 1e-10 * t.norm_l2());
                assert!((g[l][(4 + i, j)] - sm[(i, j)]).norm() <= 1e-10 * sm.norm_l2());
            }
        }
    }
    // (b) the modes are the eigenvalues of a closed loop assembled here from P and C
    let (p, c) = (m.plant(), m.controller());
    let (np, nc) = (p.order(), c.order());
    let a = Mat::<f64>::from_fn(np + nc, np + nc, |i, j| {
        let (ap, bp, cp) = (p.a(), p.b(), p.c());
        let (ac, bc, cc, dc) = (c.a(), c.b(), c.c(), c.d());
        match (i < np, j < np) {
            (true, true) => {
                let mut v = ap[(i, j)];
                for k in 0..4 {
                    for l in 0..4 {
                        v -= bp[(i, k)] * dc[(k, l)] * cp[(l, j)];
                    }
                }
                v
            }
            (true, false) => (0..4).map(|k| bp[(i, k)] * cc[(k, j - np)]).sum(),
            (false, true) => -(0..4).map(|k| bc[(i - np, k)] * cp[(k, j)]).sum::<f64>(),
            (false, false) => ac[(i - np, j - np)],
        }
    });
    let eig = a.eigenvalues().unwrap();
    let modes = m.closed_loop_pole_pairs().unwrap();
    for md in &modes {
        let d = eig
            .iter()
            .map(|z| (z - md.z).norm())
            .fold(f64::INFINITY, f64::min);
        assert!(d < 1e-9, "{md:?}: nearest eigenvalue {d:e}");
    }
    let count = eig
        .iter()
        .filter(|z| z.im > 1e-12 && z.norm() > 1e-12)
        .count();
    assert_eq!(count, modes.len());
    // (c) the peaks of |S_xa,xa| sit at lightly damped modes (within the half-power width)
    let grid: Vec<f64> = (0..3000).map(|k| 20.0 + k as f64 * 0.5).collect();
    let sv: Vec<f64> = mats(&m.sensitivity_frf(&grid).unwrap())
        .iter()
        .map(|x| x[(0, 0)].norm())
        .collect();
    let lm = m.closed_loop_modes().unwrap();
    let mut peaks = 0;
    for k in 1..grid.len() - 1 {
        if sv[k] > sv[k - 1] && sv[k] > sv[k + 1] && sv[k] > 1.5 {
            peaks += 1;
            let ok = lm.iter().any(|md| {
                (grid[k] - md.damped_freq_hz).abs() <= 2.0 * md.damping * md.freq_hz + 1.0
            });
            assert!(ok, "peak of |S| at {} Hz not at a mode: {lm:?}", grid[k]);
        }
    }
    assert!(peaks >= 1);
    // (d) each axis's plant with the other three loops closed closes the loop of S's diagonal:
    //     S_ii = 1/(1 + C_i P_i)
    let f = log_grid(60, 2.0, 4000.0);
    let s = m.sensitivity_frf(&f).unwrap();
    let c = m.controller_frf(&f).unwrap();
    for axis in 0..4 {
        let pa = m.axis_plant_frf(axis, &f).unwrap();
        for l in 0..f.len() {
            let pi = pa.at(l).unwrap()[(0, 0)];
            let ci = c.at(l).unwrap()[(axis, axis)];
            let sii = s.at(l).unwrap()[(axis, axis)];
            let e = (c64::new(1.0, 0.0) / (c64::new(1.0, 0.0) + ci * pi) - sii).norm() / sii.norm();
            assert!(e < 1e-10, "axis {axis} at {} Hz: {e:e}", f[l]);
        }
    }
}

#[test]
fn unbalance_gives_a_synchronous_line_with_the_predicted_amplitude() {
    // 12 000 rpm = 200 Hz = 100 samples per revolution at 20 kHz
    let cfg = MachineConfig {
        speed_rpm: 12_000.0,
        unbalance: Some(UnbalanceConfig {
            mass_kg: 2e-3,
            eccentricity_m: 1e-3,
            axial_position_m: 0.1,
            phase_deg: 30.0,
        }),
        ..Default::default()
    };
    let m = Machine::new(cfg).unwrap();
    assert_eq!(m.sync_hz(), 200.0);
    let n = 2000;
    let z = vec![0.0; n];
    let rec = m
        .simulate(
            [&z, &z, &z, &z],
            &MachineSimOptions {
                noise: false,
                settle_samples: settle_for(&m, 1e-13),
                ..Default::default()
            },
        )
        .unwrap();
    let truth = m.unbalance_response().unwrap();
    let line = 20; // 200 Hz
    for a in 0..4 {
        let y = dft(&rec.y[a], line) * (2.0 / n as f64);
        let e = (y - truth[a]).norm() / truth[a].norm();
        println!(
            "axis {a}: |Y| {:.4e} m, truth {:.4e} m, rel {e:.1e}",
            y.norm(),
            truth[a].norm()
        );
        assert!(e <= 1e-8, "axis {a}: {e:e}");
        // only the 1× line (and nothing else)
        let other = (1..n / 2)
            .filter(|&l| l != line)
            .map(|l| dft(&rec.y[a], l).norm())
            .fold(0.0, f64::max)
            * (2.0 / n as f64);
        assert!(other <= 1e-9 * y.norm(), "axis {a}: other lines {other:e}");
    }
    // symmetric rotor: the orbit is a forward circle, y lags x by 90°
    for b in 0..2 {
        let (x, y) = (truth[b], truth[2 + b]);
        assert!((y - x * c64::new(0.0, -1.0)).norm() <= 1e-9 * x.norm());
    }
    // the force's order of magnitude: F0 = m e Ω² ≈ 3.16 N moves the rotor by F/k_eff, µm scale
    assert!(truth[0].norm() > 1e-8 && truth[0].norm() < 1e-4);
}

#[test]
fn bad_configurations_and_inputs_get_typed_errors() {
    let bad = |cfg: MachineConfig, field: &str| match Machine::new(cfg) {
        Err(TwinError::Config { field: f, reason }) => {
            assert_eq!(f, field, "{reason}");
            assert!(!reason.is_empty());
        }
        other => panic!("expected Config error on {field}, got {other:?}"),
    };
    let d = MachineConfig::default;
    bad(
        MachineConfig {
            polar_inertia_kgm2: Some(-1e-3),
            ..d()
        },
        "polar_inertia_kgm2",
    );
    bad(
        MachineConfig {
            speed_rpm: f64::NAN,
            ..d()
        },
        "speed_rpm",
    );
    bad(
        MachineConfig {
            speed_rpm: -100.0,
            ..d()
        },
        "speed_rpm",
    );
    bad(
        MachineConfig {
            rotor_radius_m: Some(0.0),
            ..d()
        },
        "rotor_radius_m",
    );
    let mut c = d();
    c.controller_b.fs_hz = 10e3;
    bad(c, "controller_b.fs_hz");
    let mut c = d();
    c.controller_b.kp = -1.0;
    bad(c, "controller_b.kp");
    bad(
        MachineConfig {
            unbalance: Some(UnbalanceConfig {
                mass_kg: -1.0,
                ..Default::default()
            }),
            ..d()
        },
        "unbalance.mass_kg",
    );
    bad(
        MachineConfig {
            asymmetry: ambid_twin::AsymmetryConfig {
                ki_rel: 0.0,
                kx_rel: f64::INFINITY,
                ..Default::default()
            },
            ..d()
        },
        "asymmetry.kx_rel",
    );
    assert!(matches!(
        MachineConfig::from_toml_str("speed_rmp = 3.0"),
        Err(TwinError::Toml(_))
    ));
    // TOML round trip
    let c = MachineConfig {
        speed_rpm: 5000.0,
        unbalance: Some(UnbalanceConfig::default()),
        ..d()
    };
    assert_eq!(
        MachineConfig::from_toml_str(&c.to_toml_string().unwrap()).unwrap(),
        c
    );
    // simulation inputs
    let m = Machine::new(d()).unwrap();
    let (a, b) = (vec![0.0; 10], vec![0.0; 9]);
    assert!(matches!(
        m.simulate([&a, &a, &b, &a], &MachineSimOptions::default()),
        Err(TwinError::LengthMismatch { what: "r_ya", .. })
    ));
    let mut nan = a.clone();
    nan[3] = f64::NAN;
    assert!(matches!(
        m.simulate([&a, &nan, &a, &a], &MachineSimOptions::default()),
        Err(TwinError::NonFinite {
            what: "r_xb",
            index: 3
        })
    ));
    let e: Vec<f64> = vec![];
    assert!(m
        .simulate([&e, &e, &e, &e], &MachineSimOptions::default())
        .is_err());
    assert!(m.axis_plant_frf(4, &[1.0]).is_err());
    assert!(campbell(&d(), &[0.0], f64::NAN).is_err());
}

#[test]
fn noise_streams_are_independent_and_reproducible_and_iodata_names() {
    let m = Machine::new(MachineConfig::default()).unwrap();
    let z = vec![0.0; 3000];
    let o = MachineSimOptions {
        seed: 11,
        ..Default::default()
    };
    let a = m.simulate([&z, &z, &z, &z], &o).unwrap();
    let b = m.simulate([&z, &z, &z, &z], &o).unwrap();
    assert_eq!(a, b);
    // different axes see different noise: sample correlation of y_xa and y_ya small
    let corr = |x: &[f64], y: &[f64]| {
        let sxy: f64 = x.iter().zip(y).map(|(a, b)| a * b).sum();
        let sxx: f64 = x.iter().map(|a| a * a).sum();
        let syy: f64 = y.iter().map(|a| a * a).sum();
        sxy / (sxx * syy).sqrt()
    };
    assert!(corr(&a.y[0], &a.y[2]).abs() < 0.1);
    assert!(a.y[0] != a.y[2]);
    let data = a.to_iodata(None).unwrap();
    for ax in ambid_twin::AXES {
        for l in ["r", "u", "y", "i"] {
            assert_eq!(data.channel(&format!("{l}_{ax}")).unwrap().len(), 3000);
        }
    }
}

#[test]
fn nonlinear_mode_matches_linear_at_small_amplitude() {
    // every magnet its own k_i and k_x (δ_x ≠ δ_i): the nonlinear force law realises both
    let cfg = MachineConfig {
        speed_rpm: 20_000.0,
        asymmetry: ambid_twin::AsymmetryConfig {
            ki_rel: 0.08,
            kx_rel: -0.07,
            ki_rel_b: -0.06,
            kx_rel_b: 0.09,
        },
        ..Default::default()
    };
    let m = Machine::new(cfg).unwrap();
    let n = 600;
    let r: Vec<f64> = (0..n).map(|k| 0.01 * (k as f64 * 0.05).sin()).collect();
    let r2: Vec<f64> = (0..n).map(|k| 0.01 * (k as f64 * 0.031).cos()).collect();
    let run = |mode| {
        m.simulate(
            [&r, &r2, &r2, &r],
            &MachineSimOptions {
                mode,
                noise: false,
                ..Default::default()
            },
        )
        .unwrap()
    };
    let (lin, nl) = (run(Mode::Linear), run(Mode::Nonlinear));
    for a in 0..4 {
        let rms = (lin.y[a].iter().map(|v| v * v).sum::<f64>() / n as f64).sqrt();
        let err = lin.y[a]
            .iter()
            .zip(&nl.y[a])
            .map(|(p, q)| (p - q).abs())
            .fold(0.0, f64::max);
        println!("axis {a}: rms {rms:.3e}, max |lin − nl| {err:.3e}");
        assert!(
            rms > 0.0 && err < 2e-3 * rms,
            "axis {a}: {err:e} vs {rms:e}"
        );
    }
}

#[test]
fn position_reference_is_tracked_and_nonlinear_unbalance_matches_linear() {
    // integral action: a constant reference on xa is reached exactly, the other axes stay at 0
    let m = Machine::new(MachineConfig {
        speed_rpm: 15_000.0,
        ..Default::default()
    })
    .unwrap();
    let n = 500;
    let z = vec![0.0; n];
    let w0 = 20e-6;
    let rec = m
        .simulate(
            [&z, &z, &z, &z],
            &MachineSimOptions {
                noise: false,
                w: Some([vec![w0; n], z.clone(), z.clone(), z.clone()]),
                settle_samples: settle_for(&m, 1e-12),
                ..Default::default()
            },
        )
        .unwrap();
    assert!(
        (rec.y[0][n - 1] - w0).abs() < 1e-9 * w0,
        "{}",
        rec.y[0][n - 1]
    );
    for a in 1..4 {
        assert!(
            rec.y[a][n - 1].abs() < 1e-9 * w0,
            "axis {a}: {}",
            rec.y[a][n - 1]
        );
    }
    assert_eq!(rec.w[0][7], w0);
    // the nonlinear physics with the unbalance oscillator agrees with the exact linear update at
    // a small orbit
    let m = Machine::new(MachineConfig {
        speed_rpm: 12_000.0,
        unbalance: Some(UnbalanceConfig {
            axial_position_m: -0.05,
            phase_deg: 70.0,
            ..Default::default()
        }),
        ..Default::default()
    })
    .unwrap();
    let run = |mode| {
        m.simulate(
            [&z, &z, &z, &z],
            &MachineSimOptions {
                mode,
                noise: false,
                settle_samples: 200,
                ..Default::default()
            },
        )
        .unwrap()
    };
    let (lin, nl) = (run(Mode::Linear), run(Mode::Nonlinear));
    assert!(lin.meta.unbalance && nl.meta.unbalance);
    for a in 0..4 {
        let rms = (lin.y[a].iter().map(|v| v * v).sum::<f64>() / n as f64).sqrt();
        let err = lin.y[a]
            .iter()
            .zip(&nl.y[a])
            .map(|(p, q)| (p - q).abs())
            .fold(0.0, f64::max);
        println!("unbalance axis {a}: rms {rms:.3e}, max |lin − nl| {err:.3e}");
        assert!(
            rms > 1e-9 && err < 2e-3 * rms,
            "axis {a}: {err:e} vs {rms:e}"
        );
    }
}

/// The static plant of one plane from the physics, independently of the machine's code:
/// $K q = \Phi K_i i$ with $K = \operatorname{diag}(0, 0, \omega_b^2) - \Phi K_x \Phi^\top$ and
/// $y = \Phi^\top q$ (amplifier, sensor, ZOH and delay have unit gain at DC), so
/// $P(0) = \Phi^\top K^{-1}\Phi K_i$ (3 × 3 solved by Cramer's rule).
fn static_plane(r: &ambid_twin::RotorConfig, ki: [f64; 2], kx: [f64; 2]) -> [[f64; 2]; 2] {
    let phi = [
        [1.0, -r.bearing_a_m, r.mode_shape_a],
        [1.0, r.bearing_b_m, r.mode_shape_b],
    ];
    let wb = 2.0 * PI * r.bending_freq_hz;
    let mut k = [[0.0f64; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            k[i][j] = -(kx[0] * phi[0][i] * phi[0][j] + kx[1] * phi[1][i] * phi[1][j]);
        }
    }
    k[2][2] += wb * wb;
    let det3 = |m: &[[f64; 3]; 3]| {
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
            - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    };
    let d = det3(&k);
    let mut out = [[0.0; 2]; 2];
    for col in 0..2 {
        let rhs: Vec<f64> = (0..3).map(|i| phi[col][i] * ki[col]).collect();
        let q: Vec<f64> = (0..3)
            .map(|c| {
                let mut m = k;
                for i in 0..3 {
                    m[i][c] = rhs[i];
                }
                det3(&m) / d
            })
            .collect();
        for row in 0..2 {
            out[row][col] = (0..3).map(|i| phi[row][i] * q[i]).sum();
        }
    }
    out
}

#[test]
fn bearing_asymmetry_sets_each_axis_magnet_and_the_static_plant() {
    for (rig, speed) in [(0u64, 0.0), (7, 0.0), (23, 12_000.0)] {
        let tc = if rig == 0 {
            TwinConfig::default()
        } else {
            ambid_twin::random_rig(rig).unwrap()
        };
        let asymmetry = ambid_twin::AsymmetryConfig {
            ki_rel: 0.04,
            kx_rel: -0.03,
            ki_rel_b: -0.08,
            kx_rel_b: 0.06,
        };
        let cfg = MachineConfig {
            asymmetry,
            speed_rpm: speed,
            ..MachineConfig::from_twin(&tc)
        };
        let m = Machine::new(cfg).unwrap();
        let lp = ambid_twin::Twin::new(tc.clone()).unwrap().linear_params();
        let (ki, kx) = m.axis_magnets();
        let want_i = [1.0, 0.92, 1.04, 1.04 * 0.92].map(|f| f * lp.k_i);
        let want_x = [1.0, 1.06, 0.97, 0.97 * 1.06].map(|f| f * lp.k_x);
        for a in 0..4 {
            assert!(
                (ki[a] / want_i[a] - 1.0).abs() < 1e-12,
                "rig {rig} k_i[{a}]"
            );
            assert!(
                (kx[a] / want_x[a] - 1.0).abs() < 1e-12,
                "rig {rig} k_x[{a}]"
            );
        }
        // the static plant: gyroscopics act on velocities only, so also at speed
        let p0 = m.plant_frf(&[1e-4]).unwrap().at(0).unwrap();
        for plane in 0..2 {
            let s = static_plane(
                &tc.rotor,
                [want_i[2 * plane], want_i[2 * plane + 1]],
                [want_x[2 * plane], want_x[2 * plane + 1]],
            );
            for r in 0..2 {
                for c in 0..2 {
                    let got = p0[(2 * plane + r, 2 * plane + c)];
                    // relative to the plane's largest static gain (the off-diagonal is ~0)
                    let scale = s[0][0].abs().max(s[1][1].abs());
                    let rel = (got.re - s[r][c]).abs() / scale;
                    assert!(
                        rel < 1e-6,
                        "rig {rig} plane {plane} ({r},{c}): {got} vs {}",
                        s[r][c]
                    );
                }
            }
            // the two planes do not couple at DC
            let x = p0[(2 * plane, 2 - 2 * plane)].norm() / s[0][0].abs();
            assert!(x < 1e-6, "rig {rig} plane {plane}: cross-plane {x:e}");
        }
    }
    // out of range: typed error naming the field
    let bad = MachineConfig {
        asymmetry: ambid_twin::AsymmetryConfig {
            kx_rel_b: 0.7,
            ..Default::default()
        },
        ..Default::default()
    };
    let e = Machine::new(bad).unwrap_err().to_string();
    assert!(e.contains("asymmetry.kx_rel_b"), "{e}");
}
