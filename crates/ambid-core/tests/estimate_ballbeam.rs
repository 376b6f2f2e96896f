//! The DaISy ball-and-beam record (`shared/data/real/daisy-ballbeam`, read in place): an unstable
//! process measured under feedback. ARX reproduces the README's 1-step fits and reports the unstable
//! poles it finds; OE (whose predictor simulates the plant) either returns a model or fails with a
//! typed `Unstable` error that says what to do — never a panic, never a silently stabilised model.

use crate::common;
use ambid_core::estimate::arx::{arx, ArxOrders};
use ambid_core::estimate::pem::{oe, PemOptions};
use ambid_core::linalg::roots;
use ambid_core::validate::fit::fit_percent;
use ambid_core::Error;

fn ballbeam() -> (Vec<f64>, Vec<f64>) {
    let rows = common::daisy("daisy-ballbeam", "ballbeam.dat", 1000);
    let mu = rows[..500].iter().map(|r| r.0).sum::<f64>() / 500.0;
    let my = rows[..500].iter().map(|r| r.1).sum::<f64>() / 500.0;
    (
        rows.iter().map(|r| r.0 - mu).collect(),
        rows.iter().map(|r| r.1 - my).collect(),
    )
}

#[test]
fn arx_reproduces_the_reference_fits_and_reports_unstable_poles() {
    let (u, y) = ballbeam();
    let (ue, ye, uv, yv) = (&u[..500], &y[..500], &u[500..], &y[500..]);
    for (n, want) in [(2usize, 96.71), (4, 97.53), (6, 97.78)] {
        let f = arx(ye, &[ue], &ArxOrders::siso(n, n, 1), 0.1).unwrap();
        let k0 = f.model.k0();
        let pred = f.model.predict(yv, &[uv]).unwrap();
        let fit = fit_percent(&yv[k0..], &pred[k0..]).unwrap();
        let poles = roots(&f.model.a).unwrap();
        let unstable = poles.iter().filter(|p| p.norm() > 1.0).count();
        println!("ballbeam ARX({n},{n},1): 1-step validation fit {fit:.2} %, {unstable} unstable pole(s)");
        assert!((fit - want).abs() < 0.01, "ARX({n}): {fit} vs {want}");
        if n >= 4 {
            assert!(
                unstable >= 1,
                "the README reports unstable A(q) for orders >= 4"
            );
        }
    }
}

#[test]
fn oe_on_the_unstable_process_is_handled_without_a_crash() {
    let (u, y) = ballbeam();
    match oe(&y[..500], &u[..500], 2, 2, 1, 0.1, &PemOptions::default()) {
        Ok((f, _)) => {
            // a stable OE model of the closed-loop record is what was estimated; say so
            let stable = f.model.poles().unwrap().iter().all(|p| p.norm() < 1.0);
            println!(
                "ballbeam OE(2,2,1): stable output-error model, loss {:.3e}",
                f.loss
            );
            assert!(
                stable,
                "an unstable OE model must be an error, not a result"
            );
        }
        Err(e) => {
            let msg = e.to_string();
            println!("ballbeam OE(2,2,1): {msg}");
            assert!(matches!(e, Error::Unstable { .. }), "{e:?}");
            assert!(msg.to_lowercase().contains("closed"), "{msg}");
        }
    }
}
