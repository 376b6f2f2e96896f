//! The FRF pipeline's input checks (library level): each bad input gives an error naming the fix.

use ambid::analysis::{analyze, FrfSettings, Record};

fn prbs_like(n: usize, period: usize) -> Vec<f64> {
    (0..n)
        .map(|k| {
            if ((k % period) * 7919) % 13 < 6 {
                0.1
            } else {
                -0.1
            }
        })
        .collect()
}

#[test]
fn bad_inputs_are_named() {
    let r = prbs_like(1000, 100);
    let u: Vec<f64> = r.iter().map(|v| 0.5 * v).collect();
    let y: Vec<f64> = r.iter().map(|v| 1e-5 * v).collect();
    let rec = Record {
        r: &r,
        u: &u,
        y: &y,
        i: None,
        fs: 1000.0,
    };
    let mut ok = FrfSettings::periodic(100, 1);
    ok.band = Some((1.0, 500.0));
    ok.quality_band = Some((1.0, 500.0));
    // a binary u would look flat-topped to the limit detector; give the known limit
    ok.i_sat = Some(2.0);
    let a = analyze(&rec, &ok, None).unwrap();
    assert!(a
        .frf
        .plant
        .values()
        .iter()
        .all(|p| (p.re - 2e-5).abs() < 1e-15));
    assert!(a.warnings.is_empty(), "{:?}", a.warnings);

    let msg = |rec: &Record, s: &FrfSettings| format!("{:#}", analyze(rec, s, None).unwrap_err());
    // length mismatch
    let short = Record {
        y: &y[..999],
        ..rec
    };
    assert!(msg(&short, &ok).contains("all channels must be recorded together"));
    // non-integer number of periods
    let m = msg(
        &rec,
        &FrfSettings {
            band: ok.band,
            quality_band: ok.band,
            ..FrfSettings::periodic(300, 0)
        },
    );
    assert!(m.contains("not an integer number of periods"), "{m}");
    // fewer than 2 periods left for a variance
    let m = msg(
        &rec,
        &FrfSettings {
            band: ok.band,
            quality_band: ok.band,
            ..FrfSettings::periodic(500, 1)
        },
    );
    assert!(m.contains("at least 2"), "{m}");
    // no excitation in the requested band
    let zero = vec![0.0; 1000];
    let m = msg(&Record { r: &zero, ..rec }, &ok);
    assert!(m.contains("no power"), "{m}");
    // Welch segment longer than the record
    let m = msg(&rec, &FrfSettings::welch(5000));
    assert!(m.contains("nperseg"), "{m}");
    // NaN in the excitation (the designed signal is never repaired)
    let mut rn = r.clone();
    rn[10] = f64::NAN;
    let m = msg(&Record { r: &rn, ..rec }, &ok);
    // named as the 1-based sample number (index 10 is sample 11; issue 17: 0-based indices
    // in messages were misleading)
    assert!(m.contains("non-finite") && m.contains("sample 11"), "{m}");
}
