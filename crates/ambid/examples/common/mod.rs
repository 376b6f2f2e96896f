//! What the rig-sweep examples share.

/// The rigs (or seeds) of a command-line argument: `A-B` (inclusive) or `a,b,c`.
pub fn range(s: &str) -> Vec<u64> {
    match s.split_once('-') {
        Some((a, b)) => (a.parse().expect("a number")..=b.parse().expect("a number")).collect(),
        None => s.split(',').map(|x| x.parse().expect("a number")).collect(),
    }
}

/// The workflow with `steps` on `random_rig(rig)` with noise seed `rig` and twin mode `mode`
/// (`linear` or `nonlinear`), the rig's configuration written to `dir/rig<rig>.toml`: the rig's
/// configuration and the run's outcome.
#[allow(dead_code)] // not every sweep runs the workflow
pub fn workflow_on_rig(
    rig: u64,
    mode: &str,
    steps: &[ambid::workflow::Step],
    dir: &std::path::Path,
) -> (
    ambid_twin::TwinConfig,
    Result<ambid::workflow::Outcome, ambid::error::Error>,
) {
    workflow_on_rig_seed(rig, rig, mode, steps, dir)
}

/// [`workflow_on_rig`] with the noise seed `seed` instead of `rig`.
#[allow(dead_code)]
pub fn workflow_on_rig_seed(
    rig: u64,
    seed: u64,
    mode: &str,
    steps: &[ambid::workflow::Step],
    dir: &std::path::Path,
) -> (
    ambid_twin::TwinConfig,
    Result<ambid::workflow::Outcome, ambid::error::Error>,
) {
    use ambid::workflow::{run, Progress, Verbosity, WorkflowConfig};
    let cfg = ambid_twin::random_rig(rig).expect("a random rig");
    let path = dir.join(format!("rig{rig}.toml"));
    std::fs::write(&path, cfg.to_toml_string().expect("TOML")).expect("the rig file written");
    let mut wf = WorkflowConfig {
        steps: Some(steps.to_vec()),
        seed,
        ..WorkflowConfig::default()
    };
    wf.twin.mode = mode.into();
    wf.twin.config = Some(path);
    // EXCITATION=noise|chirp|…: the workflow's excitation kind instead of its default PRBS
    if let Ok(kind) = std::env::var("EXCITATION") {
        wf.excitation.kind = kind;
    }
    // FRF_BAND=lo,hi: the FRF's band given ([frf] band_hz) instead of derived from the excitation
    if let Ok(b) = std::env::var("FRF_BAND") {
        let v: Vec<f64> = b
            .split(',')
            .map(|x| x.parse().expect("FRF_BAND=lo,hi"))
            .collect();
        wf.frf.band_hz = Some([v[0], v[1]]);
    }
    let out = run(&wf, dir, &mut Progress::new(Verbosity::Quiet));
    (cfg, out)
}
