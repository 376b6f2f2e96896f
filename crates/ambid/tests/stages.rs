//! The typed stages run on their own, from code (no workflow), give the numbers the workflow
//! records in summary.json for the same seed: amplitude study → identification level →
//! acquisition → nonparametric FRF, and the robust BLA study. The FRF is also checked against
//! the twin's exact plant (independent truth).

use ambid::analysis::{analyze, Record};
use ambid::experiment::ExcitationKind;
use ambid::stage::{
    acquire_twin, amplitude_twin, bla_twin, frf_settings, identification_plan, AcquisitionPlan,
    BlaInput, Seeds, TwinSource,
};
use ambid::study::TwinAmplitudeStudy;
use ambid::workflow::{run, Progress, Step, Verbosity, WorkflowConfig};
use ambid_twin::{Mode, TwinConfig};
use std::path::Path;

fn close(a: f64, b: f64, what: &str) {
    assert!(
        (a - b).abs() <= 1e-12 * a.abs().max(b.abs()),
        "{what}: stage {a} vs workflow {b}"
    );
}

#[test]
fn stages_on_their_own_give_the_workflow_numbers() {
    let cfg = WorkflowConfig {
        steps: Some(vec![Step::Amplitude, Step::Bla, Step::Frf]),
        ..WorkflowConfig::default()
    };
    let out = run(&cfg, Path::new("."), &mut Progress::new(Verbosity::Quiet)).unwrap();
    let sm = &out.summary;

    // the stages, from code
    let seeds = Seeds::from_workflow_seed(cfg.seed);
    let twin = TwinSource::new(TwinConfig::default(), Mode::Nonlinear).unwrap();
    let levels: Vec<f64> = cfg
        .amplitude_study
        .levels_pct
        .iter()
        .map(|l| l / 100.0)
        .collect();
    let study = TwinAmplitudeStudy {
        twin: twin.cfg.clone(),
        excitation: identification_plan(&cfg.excitation, 0.1, &seeds),
        levels: levels.clone(),
        mode: twin.mode,
        seed: seeds.amplitude,
        skip_periods: 1,
        noise: twin.noise,
        band: TwinAmplitudeStudy::default().band,
    };
    let amp = amplitude_twin(&study, None).unwrap();
    close(
        amp.chosen_pct,
        sm["amplitude"]["chosen_pct"].as_f64().unwrap(),
        "chosen level",
    );
    let wl = sm["amplitude"]["levels"].as_array().unwrap();
    assert_eq!(wl.len(), amp.levels.len());
    for (s, w) in amp.levels.iter().zip(wl) {
        close(s.mean_coh_ry, w["mean_coh_ry"].as_f64().unwrap(), "γ²_ry");
        close(
            s.mean_plant_rel_var,
            w["mean_plant_rel_var"].as_f64().unwrap(),
            "relative variance",
        );
    }

    let bla = bla_twin(&BlaInput {
        plan: ambid::bla::BlaPlan {
            twin: twin.cfg.clone(),
            mode: twin.mode,
            noise: twin.noise,
            realisations: cfg.bla.realisations,
            periods: cfg.bla.periods,
            seed: seeds.bla,
            ..ambid::bla::BlaPlan::default()
        },
        levels,
    })
    .unwrap();
    close(
        bla.recommended_pct,
        sm["bla"]["recommended_pct"].as_f64().unwrap(),
        "BLA level",
    );
    for (s, w) in bla.rows.iter().zip(sm["bla"]["levels"].as_array().unwrap()) {
        close(
            s.nl_rel,
            w["nl_rel"].as_f64().unwrap(),
            "nonlinear variance",
        );
    }

    // acquisition at the chosen level, then the FRF stage
    let frac = amp.chosen_pct / 100.0;
    let plan = AcquisitionPlan::new(
        identification_plan(&cfg.excitation, frac, &seeds),
        ExcitationKind::Noise,
        frac,
        seeds,
    );
    let acq = acquire_twin(&twin, &plan).unwrap();
    let rec = &acq.identification;
    close(
        rec.len() as f64,
        sm["identification"]["samples"].as_f64().unwrap(),
        "samples",
    );
    close(
        100.0 * rec.saturated_fraction.unwrap(),
        sm["identification"]["saturated_pct"].as_f64().unwrap(),
        "saturated",
    );
    let mut s = frf_settings(
        &cfg.frf,
        cfg.data.skip_periods,
        rec.period(),
        rec.len(),
        Some(twin.twin.i_sat()),
    );
    s.controller = Some(twin.twin.controller().clone());
    let a = analyze(
        &Record {
            r: rec.r().unwrap(),
            u: rec.u(),
            y: rec.y(),
            i: rec.i(),
            fs: rec.fs(),
        },
        &s,
        acq.noise_y.as_deref(),
    )
    .unwrap();
    let f = &sm["frf"];
    close(
        a.frf.f_hz().len() as f64,
        f["lines"].as_f64().unwrap(),
        "lines",
    );
    close(
        a.quality.mean_coherence_ry,
        f["mean_coh_ry"].as_f64().unwrap(),
        "FRF γ²_ry",
    );
    close(
        a.quality.mean_plant_rel_variance,
        f["mean_plant_rel_variance"].as_f64().unwrap(),
        "FRF relative variance",
    );
    close(
        a.quality.output_snr_db.unwrap(),
        f["output_snr_db"].as_f64().unwrap(),
        "output SNR",
    );
    // and the estimate is the twin's exact plant, within a few per cent around 200 Hz
    let k = a.frf.f_hz().iter().position(|&x| x >= 200.0).unwrap();
    let exact = twin.twin.plant_frf(&[a.frf.f_hz()[k]]).unwrap()[0];
    let rel = ((a.frf.plant.values()[k] - exact) / exact).norm();
    assert!(rel < 0.1, "plant at 200 Hz: relative error {rel}");
}
