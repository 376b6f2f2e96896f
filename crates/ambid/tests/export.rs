//! Model exports (`ambid::io::export`) checked by readers that are not ambid's writer:
//!
//! * `tests/fixtures/check_export.py` (scipy.io.loadmat, numpy.load, Python's float()) on the
//!   exports of a polynomial and a 3-state innovations model, against their JSON form — run when
//!   `python3 -c 'import scipy'` works, skipped with a note otherwise;
//! * reference `.mat` files written by scipy (`tests/fixtures/export/make_scipy_mat.py`), decoded
//!   with the small Level 5 reader below together with ambid's bytes: same variables, classes,
//!   dimensions and bit-identical values;
//! * the numbers of the MATLAB script parsed back bit for bit, and the script run in Octave when
//!   `octave` is installed (skipped otherwise).

use crate::common;
use ambid::io::export::{
    mat_bytes, matlab_script, npz_bytes, ExportError, ExportModel, ExportNames,
};
use ambid::io::model::{polynomial_json, state_space_json};
use ambid_core::lti::{PolyModel, StateSpace};
use faer::mat;
use serde_json::json;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

/// The polynomial model of `fixtures/export/make_scipy_mat.py` (`POLY`).
fn poly_model() -> PolyModel {
    PolyModel::general(
        vec![1.0, -1.5, 0.7],
        vec![0.0, 0.0, 0.5, 0.1],
        vec![1.0, 0.3],
        vec![1.0, -0.2],
        vec![1.0, -0.8, 0.1],
        5e-5,
    )
    .unwrap()
}

fn poly_names() -> ExportNames {
    ExportNames {
        name: "bearing A plant".into(),
        input: "u".into(),
        output: "bearing A's y (µm)".into(),
        noise_variance: Some(2.5e-9),
    }
}

/// The state-space model of `fixtures/export/make_scipy_mat.py` (`SS`).
fn ss_model() -> (StateSpace, Vec<f64>) {
    let ss = StateSpace::discrete(
        mat![[0.9, 0.1, 0.0], [-0.1, 0.8, 0.05], [0.0, 0.02, 0.7]],
        mat![[1.0], [0.5], [-0.25]],
        mat![[1.0, 0.0, 0.3]],
        mat![[0.0]],
        1.0 / 3.0e4,
    )
    .unwrap();
    (ss, vec![0.2, -0.1, 0.05])
}

fn ss_names() -> ExportNames {
    ExportNames {
        name: "ss3".into(),
        input: "i_ref".into(),
        output: "y".into(),
        noise_variance: None,
    }
}

fn fixture(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures")
        .join(name)
}

/// Writes `stem.{json,mat,npz,m}` into `dir`.
fn write_all(
    dir: &Path,
    stem: &str,
    model: ExportModel<'_>,
    names: &ExportNames,
    json: serde_json::Value,
) {
    std::fs::write(
        dir.join(format!("{stem}.json")),
        serde_json::to_string_pretty(&json).unwrap(),
    )
    .unwrap();
    std::fs::write(
        dir.join(format!("{stem}.mat")),
        mat_bytes(model, names).unwrap(),
    )
    .unwrap();
    std::fs::write(
        dir.join(format!("{stem}.npz")),
        npz_bytes(model, names).unwrap(),
    )
    .unwrap();
    std::fs::write(
        dir.join(format!("{stem}.m")),
        matlab_script(model, names).unwrap(),
    )
    .unwrap();
}

pub(crate) fn has_octave() -> bool {
    Command::new("octave")
        .args(["--no-gui", "--quiet", "--eval", "exit(0)"])
        .output()
        .map(|o| o.status.success())
        .unwrap_or(false)
}

fn python_has_numpy() -> bool {
    Command::new("python3")
        .args(["-c", "import numpy"])
        .output()
        .map(|o| o.status.success())
        .unwrap_or(false)
}

pub(crate) fn python_has_scipy() -> bool {
    Command::new("python3")
        .args(["-c", "import scipy, numpy"])
        .output()
        .map(|o| o.status.success())
        .unwrap_or(false)
}

#[test]
fn scipy_and_numpy_read_the_exports() {
    let dir = common::tmpdir("export-check");
    let poly = poly_model();
    let pn = poly_names();
    let meta = json!({"export_model_name": "bearing_A_plant", "noise_variance": 2.5e-9});
    write_all(
        &dir,
        "poly",
        ExportModel::Poly(&poly),
        &pn,
        polynomial_json(&poly, &pn.input, &pn.output, meta),
    );
    let (ss, k) = ss_model();
    let sn = ss_names();
    let meta = json!({"export_model_name": "ss3", "pem": {"kalman_gain": k}});
    write_all(
        &dir,
        "ss3",
        ExportModel::StateSpace(&ss, Some(&k)),
        &sn,
        state_space_json(&ss, &sn.input, &sn.output, meta),
    );
    if !python_has_scipy() {
        common::skip(
            "export: check_export.py (scipy/numpy read the .mat/.npz/.m exports bit for bit)",
            "python3 with numpy and scipy not available (bash .ci/run installs them)",
        );
        return;
    }
    let out = Command::new("python3")
        .arg(fixture("check_export.py"))
        .arg(&dir)
        .output()
        .unwrap();
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    println!("{text}");
    assert!(out.status.success(), "check_export.py failed:\n{text}");
    assert!(text.contains("check_export: OK"), "{text}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// One decoded MAT variable: class, dimensions and the values column by column (numbers) or
/// the text (char arrays).
#[derive(Debug, PartialEq)]
struct MatVar {
    class: u8,
    dims: Vec<usize>,
    numbers: Vec<u64>,
    text: Option<String>,
}

fn u32_at(b: &[u8], i: usize) -> u32 {
    u32::from_le_bytes(b[i..i + 4].try_into().unwrap())
}

/// Splits a little-endian sequence of Level 5 data elements into (type, data), handling the
/// small (≤ 4 bytes, packed into the tag) and the normal format.
fn elements(mut b: &[u8]) -> Vec<(u32, &[u8])> {
    let mut out = Vec::new();
    while b.len() >= 8 {
        let first = u32_at(b, 0);
        if first >> 16 != 0 {
            let (ty, n) = (first & 0xffff, (first >> 16) as usize);
            out.push((ty, &b[4..4 + n]));
            b = &b[8..];
        } else {
            let n = u32_at(b, 4) as usize;
            out.push((first, &b[8..8 + n]));
            b = &b[(8 + n).div_ceil(8) * 8..];
        }
    }
    assert!(b.is_empty(), "trailing bytes");
    out
}

/// A minimal Level 5 reader for uncompressed real double and char matrices.
fn read_mat(bytes: &[u8]) -> BTreeMap<String, MatVar> {
    assert!(bytes.starts_with(b"MATLAB 5.0 MAT-file"));
    assert_eq!(&bytes[124..128], &[0x00, 0x01, b'I', b'M']);
    let mut vars = BTreeMap::new();
    for (ty, body) in elements(&bytes[128..]) {
        assert_eq!(ty, 14, "only miMATRIX (uncompressed) expected");
        let sub = elements(body);
        assert_eq!(sub.len(), 4, "flags, dims, name, real part");
        assert_eq!(sub[0].0, 6);
        let class = sub[0].1[0];
        assert_eq!(sub[0].1[1], 0, "no complex/global/logical flags");
        assert_eq!(sub[1].0, 5);
        let dims: Vec<usize> = sub[1]
            .1
            .chunks(4)
            .map(|c| i32::from_le_bytes(c.try_into().unwrap()) as usize)
            .collect();
        assert_eq!(sub[2].0, 1);
        let name = String::from_utf8(sub[2].1.to_vec()).unwrap();
        let (ty, data) = sub[3];
        let (numbers, text) = match (class, ty) {
            (6, 9) => (
                data.chunks(8)
                    .map(|c| u64::from_le_bytes(c.try_into().unwrap()))
                    .collect(),
                None,
            ),
            (4, 4) | (4, 17) => {
                let units: Vec<u16> = data
                    .chunks(2)
                    .map(|c| u16::from_le_bytes([c[0], c[1]]))
                    .collect();
                (vec![], Some(String::from_utf16(&units).unwrap()))
            }
            (4, 16) => (vec![], Some(String::from_utf8(data.to_vec()).unwrap())),
            other => panic!("{name}: unexpected class/type {other:?}"),
        };
        vars.insert(
            name,
            MatVar {
                class,
                dims,
                numbers,
                text,
            },
        );
    }
    vars
}

pub(crate) fn bits(v: &[f64]) -> Vec<u64> {
    v.iter().map(|x| x.to_bits()).collect()
}

#[test]
fn mat_matches_scipy_savemat() {
    let poly = poly_model();
    let ours = read_mat(&mat_bytes(ExportModel::Poly(&poly), &poly_names()).unwrap());
    let scipy = read_mat(&std::fs::read(fixture("export/poly_scipy.mat")).unwrap());
    // the reader itself against the literal values (so it cannot agree with us by mistake)
    assert_eq!(scipy["A"].numbers, bits(&[1.0, -1.5, 0.7]));
    assert_eq!(scipy["A"].dims, [1, 3]);
    assert_eq!(scipy["nk"].numbers, bits(&[2.0]));
    assert_eq!(
        scipy["output_name"].text.as_deref(),
        Some("bearing A's y (µm)")
    );
    assert_eq!(ours, scipy);

    let (ss, k) = ss_model();
    let ours = read_mat(&mat_bytes(ExportModel::StateSpace(&ss, Some(&k)), &ss_names()).unwrap());
    let scipy = read_mat(&std::fs::read(fixture("export/ss_scipy.mat")).unwrap());
    assert_eq!(scipy["A"].dims, [3, 3]);
    // column-major: first column of A
    assert_eq!(scipy["A"].numbers[..3], bits(&[0.9, -0.1, 0.0]));
    assert_eq!(scipy["K"].dims, [3, 1]);
    assert_eq!(scipy["Ts"].numbers, bits(&[1.0 / 3.0e4]));
    assert_eq!(ours, scipy);
}

/// Numeric assignments `X = …;` of an ambid MATLAB script: name → (rows, values row by row).
pub(crate) fn script_numbers(text: &str) -> BTreeMap<String, (usize, Vec<f64>)> {
    let mut out = BTreeMap::new();
    let mut lines = text.lines();
    while let Some(line) = lines.next() {
        let Some((name, rhs)) = line.split_once(" = ") else {
            continue;
        };
        if name.is_empty() || !name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') {
            continue;
        }
        let mut rhs = rhs.to_string();
        if rhs == "[" {
            for l in lines.by_ref() {
                rhs.push_str(l);
                if l == "];" {
                    break;
                }
            }
        }
        let rhs = rhs.trim_end_matches(';');
        if let Some(dims) = rhs.strip_prefix("zeros(") {
            let rows: usize = dims.split(',').next().unwrap().trim().parse().unwrap();
            out.insert(name.to_string(), (rows, vec![]));
        } else if let Some(body) = rhs.strip_prefix('[') {
            let body = body.trim_end_matches(']');
            let rows: Vec<&str> = body.split(';').collect();
            let values = rows
                .iter()
                .flat_map(|r| r.split(','))
                .map(|x| x.trim().parse::<f64>().unwrap())
                .collect();
            out.insert(name.to_string(), (rows.len(), values));
        } else if let Ok(x) = rhs.parse::<f64>() {
            // other right-hand sides (`complex(…)`, calls) are not numbers of the export
            out.insert(name.to_string(), (1, vec![x]));
        }
    }
    out
}

fn row_major(m: faer::MatRef<'_, f64>) -> Vec<f64> {
    (0..m.nrows())
        .flat_map(|i| (0..m.ncols()).map(move |j| m[(i, j)]))
        .collect()
}

#[test]
fn matlab_script_numbers_round_trip_bit_for_bit() {
    let poly = poly_model();
    let text = matlab_script(ExportModel::Poly(&poly), &poly_names()).unwrap();
    let got = script_numbers(&text);
    let want: BTreeMap<String, (usize, Vec<f64>)> = [
        ("A", poly.a().to_vec()),
        ("B", poly.b().to_vec()),
        ("C", poly.c().to_vec()),
        ("D", poly.d().to_vec()),
        ("F", poly.f().to_vec()),
        ("Ts", vec![poly.ts()]),
        ("nk", vec![2.0]),
        ("noise_variance", vec![2.5e-9]),
    ]
    .into_iter()
    .map(|(k, v)| (k.to_string(), (1, v)))
    .collect();
    assert_eq!(
        got.keys().collect::<Vec<_>>(),
        want.keys().collect::<Vec<_>>()
    );
    for (name, (rows, values)) in &want {
        assert_eq!(got[name].0, *rows, "{name}");
        assert_eq!(bits(&got[name].1), bits(values), "{name}");
    }
    // the exact coefficient strings (C's %.17g)
    assert!(
        text.contains("\nA = [1, -1.5, 0.69999999999999996];\n"),
        "{text}"
    );
    assert!(text.contains("\nB = [0, 0, 0.5, 0.10000000000000001];\n"));
    assert!(text.contains("\nTs = 5.0000000000000002e-05;\n"));
    assert!(text.contains(
        "  bearing_A_plant = idpoly(A, B, C, D, F, noise_variance, Ts, 'InputName', 'u', 'OutputName', char(["
    ));
    // without idpoly (Octave): the plain vectors of G = B/(A F), and tf where it exists
    assert!(text.contains("\n  Gnum = B;\n  Gden = conv(A, F);\n"));
    assert!(text.contains("    bearing_A_plant = tf(Gnum, Gden, Ts, 'Variable', 'z^-1', "));
    assert!(text.contains(&format!("ambid {}", env!("CARGO_PKG_VERSION"))));
    assert!(text.contains("nb = 2 (after the delay)") && text.contains("nk = 2"));

    let (ss, k) = ss_model();
    let text = matlab_script(ExportModel::StateSpace(&ss, Some(&k)), &ss_names()).unwrap();
    let got = script_numbers(&text);
    assert_eq!(got["A"].0, 3);
    assert_eq!(bits(&got["A"].1), bits(&row_major(ss.a())));
    assert_eq!(got["B"].0, 3);
    assert_eq!(bits(&got["B"].1), bits(&row_major(ss.b())));
    assert_eq!(bits(&got["C"].1), bits(&row_major(ss.c())));
    assert_eq!(bits(&got["D"].1), bits(&row_major(ss.d())));
    assert_eq!((got["K"].0, bits(&got["K"].1)), (3, bits(&k)));
    assert_eq!(bits(&got["Ts"].1), bits(&[1.0 / 3.0e4]));
    assert_eq!(got.len(), 6);
    assert!(text.contains(
        "  ss3 = idss(A, B, C, D, K, zeros(3, 1), Ts, 'InputName', 'i_ref', 'OutputName', 'y');"
    ));
    assert!(text.contains("  ss3 = ss(A, B, C, D, Ts, 'InputName', 'i_ref', 'OutputName', 'y');"));

    // without K: idss gets a zero gain and no K variable is defined
    let text = matlab_script(ExportModel::StateSpace(&ss, None), &ss_names()).unwrap();
    assert!(!script_numbers(&text).contains_key("K"));
    assert!(text.contains("idss(A, B, C, D, zeros(3, 1), zeros(3, 1), Ts,"));
}

/// A script file, its model and names, and the variables to print (column-major values).
type OctaveCase<'a> = (
    &'a str,
    ExportModel<'a>,
    ExportNames,
    Vec<(&'a str, Vec<f64>)>,
);

#[test]
fn octave_runs_the_script() {
    if !has_octave() {
        common::skip(
            "export: the exported MATLAB scripts run in Octave",
            "octave not installed (bash .ci/run installs it with apt-get)",
        );
        return;
    }
    let dir = common::tmpdir("export-octave");
    let poly = poly_model();
    let (ss, k) = ss_model();
    let cases: [OctaveCase<'_>; 2] = [
        (
            "poly_model.m",
            ExportModel::Poly(&poly),
            poly_names(),
            vec![
                ("A", vec![1.0, -1.5, 0.7]),
                ("B", vec![0.0, 0.0, 0.5, 0.1]),
                ("F", vec![1.0, -0.8, 0.1]),
                ("Ts", vec![5e-5]),
                ("noise_variance", vec![2.5e-9]),
                // Octave has no idpoly: the script falls back to the plain vectors
                ("Gnum", vec![0.0, 0.0, 0.5, 0.1]),
            ],
        ),
        (
            "ss_model.m",
            ExportModel::StateSpace(&ss, Some(&k)),
            ss_names(),
            vec![
                // column-major, as Octave's A(:)
                ("A", vec![0.9, -0.1, 0.0, 0.1, 0.8, 0.02, 0.0, 0.05, 0.7]),
                ("K", k.clone()),
                ("Ts", vec![1.0 / 3.0e4]),
            ],
        ),
    ];
    for (file, model, names, want) in cases {
        let path = dir.join(file);
        std::fs::write(&path, matlab_script(model, &names).unwrap()).unwrap();
        let prints: String = want
            .iter()
            .map(|(v, _)| format!("printf('{v}'); printf(' %.17g', {v}(:)); printf('\\n');"))
            .collect();
        let out = Command::new("octave")
            .args(["--no-gui", "--quiet", "--eval"])
            .arg(format!("run('{}'); {prints}", path.display()))
            .output()
            .unwrap();
        let stdout = String::from_utf8_lossy(&out.stdout);
        assert!(
            out.status.success(),
            "octave failed on {file}: {stdout}{}",
            String::from_utf8_lossy(&out.stderr)
        );
        for (v, values) in want {
            let line = stdout
                .lines()
                .find(|l| l.split_whitespace().next() == Some(v))
                .unwrap_or_else(|| panic!("{v} not printed: {stdout}"));
            let got: Vec<f64> = line
                .split_whitespace()
                .skip(1)
                .map(|x| x.parse().unwrap())
                .collect();
            assert_eq!(bits(&got), bits(&values), "{file}: {v}");
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn bad_input_is_an_error_not_a_panic() {
    let (ss, _) = ss_model();
    let names = ss_names();
    for k in [vec![0.1, f64::NAN, 0.0], vec![f64::NEG_INFINITY, 0.0, 0.0]] {
        let model = ExportModel::StateSpace(&ss, Some(&k));
        for result in [
            mat_bytes(model, &names).map(|_| ()),
            npz_bytes(model, &names).map(|_| ()),
            matlab_script(model, &names).map(|_| ()),
        ] {
            let err = result.unwrap_err();
            assert!(
                matches!(err, ExportError::NonFinite { what: "K", .. }),
                "{err}"
            );
            assert!(err.to_string().contains("not finite"), "{err}");
        }
    }
    let short = [0.1];
    let err = mat_bytes(ExportModel::StateSpace(&ss, Some(&short)), &names).unwrap_err();
    assert!(
        err.to_string().contains("K must be n×ny = 3 entries"),
        "{err}"
    );
    // names with anything in them still give a valid identifier and a loadable file
    let odd = ExportNames {
        name: "\n'; delete('*'); %".into(),
        input: "a\nb'".into(),
        output: String::new(),
        noise_variance: None,
    };
    let text = matlab_script(ExportModel::StateSpace(&ss, None), &odd).unwrap();
    assert!(text.contains("\n  m____delete________ = idss("), "{text}");
    assert!(text.contains("'InputName', char([97, 10, 98, 39]), 'OutputName', ''"));
    let vars = read_mat(&mat_bytes(ExportModel::StateSpace(&ss, None), &odd).unwrap());
    assert_eq!(vars["input_name"].text.as_deref(), Some("a\nb'"));
    assert_eq!(vars["output_name"].dims, [0, 0]);
    assert!(!vars.contains_key("K"));
}

#[test]
fn exports_are_reproducible() {
    let poly = poly_model();
    let m = ExportModel::Poly(&poly);
    let n = poly_names();
    assert_eq!(mat_bytes(m, &n).unwrap(), mat_bytes(m, &n).unwrap());
    assert_eq!(npz_bytes(m, &n).unwrap(), npz_bytes(m, &n).unwrap());
    assert_eq!(matlab_script(m, &n).unwrap(), matlab_script(m, &n).unwrap());
}

#[test]
fn static_gain_exports_empty_matrices() {
    // n = 0: a pure gain y = 2 u
    let ss = StateSpace::discrete(
        faer::Mat::zeros(0, 0),
        faer::Mat::zeros(0, 1),
        faer::Mat::zeros(1, 0),
        mat![[2.0]],
        1e-3,
    )
    .unwrap();
    let model = ExportModel::StateSpace(&ss, Some(&[]));
    let vars = read_mat(&mat_bytes(model, &ss_names()).unwrap());
    assert_eq!(vars["A"].dims, [0, 0]);
    assert_eq!(vars["B"].dims, [0, 1]);
    assert_eq!(vars["C"].dims, [1, 0]);
    assert_eq!(vars["K"].dims, [0, 1]);
    assert_eq!(vars["D"].numbers, bits(&[2.0]));
    let text = matlab_script(model, &ss_names()).unwrap();
    assert!(
        text.contains(
            "\nA = zeros(0, 0);\nB = zeros(0, 1);\nC = zeros(1, 0);\nD = [2];\nK = zeros(0, 1);\n"
        ),
        "{text}"
    );
    assert!(text.contains("idss(A, B, C, D, K, zeros(0, 1), Ts,"));
    let bytes = npz_bytes(model, &ss_names()).unwrap();
    let mut zip = zip::ZipArchive::new(std::io::Cursor::new(bytes)).unwrap();
    let mut buf = Vec::new();
    std::io::Read::read_to_end(&mut zip.by_name("B.npy").unwrap(), &mut buf).unwrap();
    let b = npyz::NpyFile::new(std::io::Cursor::new(buf)).unwrap();
    assert_eq!(b.shape(), &[0, 1]);
    assert!(b.into_vec::<f64>().unwrap().is_empty());
}

/// `docs/examples/<name>`, and the text of `docs/export.md`.
fn doc_example(name: &str) -> (PathBuf, String, String) {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let path = root.join("docs/examples").join(name);
    let code = std::fs::read_to_string(&path).unwrap();
    let doc = std::fs::read_to_string(root.join("docs/export.md")).unwrap();
    (path, code, doc)
}

#[test]
fn the_docs_quote_the_example_scripts_verbatim() {
    for name in ["load_model.py", "load_model.m"] {
        let (_, code, doc) = doc_example(name);
        assert!(
            doc.contains(code.trim_end()),
            "docs/export.md does not contain docs/examples/{name} verbatim: copy the file into its code block"
        );
        assert!(doc.contains(&format!("docs/examples/{name}")), "{name}");
    }
}

/// Frequencies of the checks: where the twin's loop has its dynamics, up to near Nyquist.
const CHECK_F_HZ: [f64; 6] = [5.0, 50.0, 300.0, 900.0, 2500.0, 8000.0];

/// `(stem, structure, exported as polynomials)` of the models fitted by `ambid fit` in
/// [`fitted_exports`].
const FITTED: [(&str, &str, bool); 4] = [
    ("arx4", "arx", true),
    ("oe4", "oe", true),
    ("bj4", "bj", true),
    ("ss4", "ss", false),
];

/// A short closed-loop record of random rig 7 (linear twin, 3 PRBS periods, 15 345 samples) and
/// ARX/OE/BJ/SS models of r → y (the stable T_ry) fitted to it by `ambid fit`, each with its
/// exports written by `ambid::io::model::write_model_exports` beside the JSON file.
fn fitted_exports(name: &str) -> common::TmpDir {
    let d = common::tmpdir(name);
    let o = common::ambid(&[
        "simulate",
        "--rig-seed",
        "7",
        "--mode",
        "linear",
        "--periods",
        "3",
        "--seed",
        "11",
        "--out",
        common::s(&d.join("rec")),
    ]);
    assert!(o.status.success(), "{}", common::text(&o));
    let data = d.join("rec/data.csv");
    for (stem, structure, _) in FITTED {
        let mut args = vec![
            "fit",
            common::s(&data),
            "--input",
            "r",
            "--output",
            "y",
            "--structure",
            structure,
        ];
        let orders: &[&str] = match structure {
            "arx" => &["--na", "4", "--nb", "4"],
            "oe" => &["--nb", "4", "--nf", "4"],
            "bj" => &["--nb", "4", "--nf", "4", "--nc", "2", "--nd", "2"],
            _ => &["--order", "4"],
        };
        args.extend_from_slice(orders);
        let out = d.join(format!("{stem}.json"));
        args.extend_from_slice(&["--out", common::s(&out)]);
        let o = common::ambid(&args);
        assert!(o.status.success(), "{stem}: {}", common::text(&o));
        let written = ambid::io::model::write_model_exports(&out).unwrap();
        assert_eq!(written.len(), 3);
    }
    d
}

/// ambid's own frequency response and unstable-pole count of a model file (its JSON, read as
/// ambid's `validate` reads it).
fn ambid_response(json: &Path) -> (Vec<faer::c64>, usize) {
    let m = ambid::io::model::read_model_json(json).unwrap();
    let g = m.freq_response_siso(&CHECK_F_HZ).unwrap();
    let unstable = m
        .poles()
        .unwrap()
        .iter()
        .filter(|z| z.norm() >= 1.0)
        .count();
    (g, unstable)
}

/// Parses the `G f re im` and `unstable poles: n` lines of the example scripts.
fn parse_example_output(out: &str) -> (Vec<(f64, faer::c64)>, usize) {
    let g = out
        .lines()
        .filter_map(|l| l.strip_prefix("G "))
        .map(|l| {
            let v: Vec<f64> = l.split_whitespace().map(|x| x.parse().unwrap()).collect();
            (v[0], faer::c64::new(v[1], v[2]))
        })
        .collect();
    let unstable = out
        .lines()
        .find_map(|l| l.strip_prefix("unstable poles: "))
        .unwrap_or_else(|| panic!("no pole count in: {out}"))
        .trim()
        .parse()
        .unwrap();
    (g, unstable)
}

/// Checks an example's output against ambid's numbers: the same frequencies, the response to
/// 1e-9 relative (two implementations of the same rational function in double precision: ambid
/// evaluates a state-space realisation, the example polynomials or (zI − A)⁻¹), and the same
/// number of unstable poles.
fn check_against_ambid(json: &Path, out: &str, what: &str) {
    let (want, unstable) = ambid_response(json);
    let (got, got_unstable) = parse_example_output(out);
    assert_eq!(got.len(), CHECK_F_HZ.len(), "{what}: {out}");
    for ((f, g), (f0, w)) in got.iter().zip(CHECK_F_HZ.iter().zip(&want)) {
        assert_eq!(f, f0, "{what}");
        let rel = (g - w).norm() / w.norm();
        assert!(
            rel < 1e-9,
            "{what} at {f} Hz: {g} vs ambid {w} (relative {rel:.2e})"
        );
    }
    assert_eq!(got_unstable, unstable, "{what}: unstable poles");
}

#[test]
fn the_docs_python_example_runs_on_arx_oe_bj_and_ss_exports() {
    if !python_has_numpy() {
        common::skip(
            "export: docs/examples/load_model.py on ARX/OE/BJ/SS exports",
            "python3 with numpy not available (bash .ci/run installs it)",
        );
        return;
    }
    let d = fitted_exports("export-python-example");
    let (example, _, _) = doc_example("load_model.py");
    for (stem, structure, poly) in FITTED {
        let npz = d.join(format!("{stem}.npz"));
        let mut cmd = Command::new("python3");
        cmd.arg(&example).arg(&npz);
        for f in CHECK_F_HZ {
            cmd.arg(f.to_string());
        }
        let o = cmd.output().unwrap();
        let out = common::text(&o);
        assert!(o.status.success(), "{stem}: {out}");
        assert!(
            out.contains(&format!("structure {structure},")),
            "{stem}: {out}"
        );
        check_against_ambid(&d.join(format!("{stem}.json")), &out, stem);
        // polynomial models as idpoly, state space as idss
        let script = std::fs::read_to_string(d.join(format!("{stem}.m"))).unwrap();
        let call = if poly {
            "= idpoly(A, B, C, D, F, noise_variance, Ts,"
        } else {
            "= idss("
        };
        assert!(script.contains(call), "{stem}: {script}");
    }
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn the_docs_matlab_example_runs_in_octave_on_arx_oe_bj_and_ss_exports() {
    if !has_octave() {
        common::skip(
            "export: docs/examples/load_model.m in Octave on ARX/OE/BJ/SS exports",
            "octave not installed (bash .ci/run installs it with apt-get)",
        );
        return;
    }
    let d = fitted_exports("export-octave-example");
    let (example, _, _) = doc_example("load_model.m");
    let f_list: Vec<String> = CHECK_F_HZ.iter().map(|f| f.to_string()).collect();
    for (stem, structure, _) in FITTED {
        let script = d.join(format!("{stem}.m"));
        let o = Command::new("octave")
            .args(["--no-gui", "--quiet", "--eval"])
            .arg(format!(
                "model_file = '{}'; f_hz = [{}]; run('{}')",
                script.display(),
                f_list.join(", "),
                example.display()
            ))
            .output()
            .unwrap();
        let out = common::text(&o);
        assert!(o.status.success(), "{stem}: {out}");
        assert!(
            out.contains(&format!("structure {structure},")),
            "{stem}: {out}"
        );
        check_against_ambid(&d.join(format!("{stem}.json")), &out, stem);
    }
    let _ = std::fs::remove_dir_all(&d);
}

/// Evaluation condition number of a polynomial in q⁻¹ at q⁻¹ = `qinv`: Σ|c_k| / |c(q⁻¹)| (the
/// relative error of evaluating it in double precision is at most about this times 1e-16).
fn eval_cond(c: &[f64], qinv: faer::c64) -> f64 {
    let v = c
        .iter()
        .rev()
        .fold(faer::c64::new(0.0, 0.0), |acc, &x| acc * qinv + x);
    c.iter().map(|x| x.abs()).sum::<f64>() / v.norm()
}

/// The workflow's frequency-domain ARX and OE fits are held in companion form and exported
/// through `polynomial_form`. On the exact (open-loop unstable) plants of random rigs 1–20:
/// * the plant's transfer function `num/den` (`TransferFunction::from_state_space`), put in
///   companion form as the workflow holds it, comes back with the same coefficients bit for bit
///   and so the same unstable poles (none reflected);
/// * the plant's own (physical) realisation, converted through its characteristic polynomial,
///   has the plant's frequency response on 40 log-spaced lines from 1 Hz to 0.45 fs to within
///   what double precision allows a polynomial there: 1e-10 × (Σ|den_k| / |den(e^{-jωTs})|), a
///   coefficient accuracy of 1e-10 (the eigenvalue route's, measured ≤ 3.3e-11 on these
///   plants) times the evaluation condition number
///   of the denominator, which at 20 kHz is large at low frequencies (all poles near z = 1).
#[test]
fn polynomial_form_keeps_the_plant_of_20_random_rigs() {
    use ambid::io::export::polynomial_form;
    use ambid_core::lti::TransferFunction;
    let (mut worst_ratio, mut worst_rel) = (0.0f64, 0.0f64);
    for rig in 1..=20u64 {
        let twin = ambid_twin::Twin::new(ambid_twin::random_rig(rig).unwrap()).unwrap();
        let plant = twin.plant();
        let ts = plant.ts().unwrap();
        let f: Vec<f64> = (0..40).map(|i| (0.45 / ts).powf(i as f64 / 39.0)).collect();
        let want = twin.plant_frf(&f).unwrap();
        let unstable_want = twin.plant_unstable_poles().unwrap().len();
        assert!(unstable_want >= 1, "rig {rig}: the AMB plant is unstable");
        let tf = TransferFunction::from_state_space(plant).unwrap();
        let companion = tf.to_state_space().unwrap();
        for structure in ["arx", "oe"] {
            let p = polynomial_form(structure, &companion).unwrap();
            assert_eq!(p.structure().name(), structure);
            let den = if structure == "arx" { p.a() } else { p.f() };
            assert_eq!(bits(p.b()), bits(tf.num()), "rig {rig} {structure}: B");
            assert_eq!(bits(den), bits(tf.den()), "rig {rig} {structure}: den");
            assert_eq!(p.b()[0], 0.0, "rig {rig}: strictly proper plant, nk ≥ 1");
            let unstable = TransferFunction::new(vec![1.0], den.to_vec(), ts)
                .unwrap()
                .poles()
                .unwrap()
                .iter()
                .filter(|z| z.norm() >= 1.0)
                .count();
            assert_eq!(unstable, unstable_want, "rig {rig} {structure}");
        }
        // the physical realisation: through the characteristic polynomial
        let p = polynomial_form("oe", plant).unwrap();
        for (fi, w) in f.iter().zip(&want) {
            let qinv = faer::c64::from_polar(1.0, -2.0 * std::f64::consts::PI * fi * ts);
            let ev = |c: &[f64]| {
                c.iter()
                    .rev()
                    .fold(faer::c64::new(0.0, 0.0), |a, &x| a * qinv + x)
            };
            let rel = (ev(p.b()) / ev(p.f()) - w).norm() / w.norm();
            let tol = 1e-10 * eval_cond(p.f(), qinv);
            worst_ratio = worst_ratio.max(rel / tol);
            worst_rel = worst_rel.max(rel);
            assert!(rel <= tol, "rig {rig} at {fi:.1} Hz: {rel:.2e} > {tol:.2e}");
        }
        assert!(polynomial_form("ss", &companion).is_none());
    }
    println!(
        "physical realisations: worst FRF error {worst_rel:.2e}, worst error / tolerance {worst_ratio:.2e}"
    );
}
