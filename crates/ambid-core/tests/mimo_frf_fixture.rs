//! `frf::mimo::periodic` against a plain-numpy reference (`tests/fixtures/mimo_frf/make_fixture.py`:
//! 3 experiments, 2 inputs, 3 outputs, correlated (u, y) noise, M > n_r so the least-squares
//! path is used). Every value, variance, coherence and condition number to 1e-10 relative.

use ambid_core::data::IoData;
use ambid_core::frf::mimo::{periodic, MimoOptions};
use ambid_core::lti::Frd;

const DIR: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/fixtures/mimo_frf");

fn read_input() -> IoData {
    let text = std::fs::read_to_string(format!("{DIR}/input.csv")).unwrap();
    let mut lines = text.lines();
    let names: Vec<String> = lines.next().unwrap().split(',').map(String::from).collect();
    let mut exps: Vec<Vec<Vec<f64>>> = Vec::new();
    for l in lines {
        let v: Vec<f64> = l.split(',').map(|x| x.parse().unwrap()).collect();
        let e = v[0] as usize;
        if exps.len() <= e {
            exps.push(vec![Vec::new(); names.len() - 1]);
        }
        for (c, x) in v[1..].iter().enumerate() {
            exps[e][c].push(*x);
        }
    }
    let recs: Vec<IoData> = exps
        .into_iter()
        .map(|ch| {
            IoData::new(names[1..].iter().cloned().zip(ch).collect(), 1e-3, Some(32)).unwrap()
        })
        .collect();
    IoData::from_experiments(recs).unwrap()
}

fn close(a: f64, b: f64, scale: f64) -> bool {
    (a - b).abs() <= 1e-10 * scale.max(1e-300)
}

#[test]
fn matches_the_numpy_reference() {
    let data = read_input();
    let frf = periodic(&data, &MimoOptions::new().skip(1)).unwrap();
    assert_eq!(frf.periods, 4);
    assert_eq!(frf.lines, (1..=16).collect::<Vec<_>>());
    let text = std::fs::read_to_string(format!("{DIR}/expected.csv")).unwrap();
    let mut checked = 0;
    for row in text.lines().skip(1) {
        let f: Vec<&str> = row.split(',').collect();
        let k: usize = f[0].parse().unwrap();
        let li = frf.lines.iter().position(|&l| l == k).unwrap();
        let (i, j): (usize, usize) = (f[2].parse().unwrap(), f[3].parse().unwrap());
        let (re, im, var): (f64, f64, f64) = (
            f[4].parse().unwrap(),
            f[5].parse().unwrap(),
            f[6].parse().unwrap(),
        );
        let g: Option<&Frd> = match f[1] {
            "T" => Some(&frf.t_ry),
            "S" => Some(&frf.s),
            "P" => Some(&frf.plant),
            _ => None,
        };
        match g {
            Some(g) => {
                let z = g.at(li).unwrap()[(i, j)];
                let mag = re.hypot(im);
                assert!(close(z.re, re, mag) && close(z.im, im, mag), "{row}: {z}");
                let v = g.variance_at(li).unwrap().unwrap()[(i, j)];
                assert!(close(v, var, var), "{row}: var {v}");
            }
            None => {
                let got = match f[1] {
                    "coh" => frf.coherence[li * 3 + i],
                    "cohu" => frf.coherence_u[li * 2 + i],
                    "cond_r" => frf.cond_r[li],
                    "cond_u" => frf.cond_u[li],
                    q => panic!("unknown quantity {q}"),
                };
                assert!(close(got, re, re), "{row}: {got}");
            }
        }
        checked += 1;
    }
    assert_eq!(checked, 368);
}
