//! Helpers and argument types shared by several commands.

use super::args::DataFileArgs;
use ambid::io::csv::read_frf_csv;
use ambid::stage::{Recording, Signals};
use ambid_core::estimate::freqfit::{FreqFitOptions, FreqWeights};
use ambid_core::frf::band::{fit_band, FIT_REL_HALFWIDTH};
use ambid_core::validate::predict::InitialState;
use ambid_twin::TwinConfig;
use anyhow::{Context, Result};
use clap::{Args, ValueEnum};
use std::path::{Path, PathBuf};

#[derive(Clone, Copy, ValueEnum)]
pub enum ModeArg {
    Linear,
    Nonlinear,
}

#[derive(Args)]
pub struct RigArgs {
    /// A random rig of the twin's test family instead of the nominal one: rotor, magnets, bias
    /// and gap, amplifier and sensor bandwidths, bending mode, controller gains and noise drawn
    /// ±15–30 % from this seed, accepted only when the loop is stable with max|S| ≤ 4
    /// (`ambid_twin::rig`).
    #[arg(long)]
    pub rig_seed: Option<u64>,
}

#[derive(Args)]
pub struct TwinArgs {
    /// Twin configuration (TOML); defaults to the nominal rig (see `ambid config`).
    #[arg(long, conflicts_with = "rig_seed")]
    pub config: Option<PathBuf>,
    #[command(flatten)]
    pub rig: RigArgs,
    /// Bias current i0 in A (overrides the configuration).
    #[arg(long, allow_negative_numbers = true)]
    pub bias: Option<f64>,
    /// Nominal air gap g0 in m (overrides the configuration), e.g. 0.00041.
    #[arg(long, allow_negative_numbers = true)]
    pub gap: Option<f64>,
}

/// The machine of the twin arguments: `--config` as a `MachineConfig` TOML (as `info --axes 4`
/// and `campbell` read it) or a single-plane `TwinConfig` TOML lifted by
/// [`MachineConfig::from_twin`]; else `--rig-seed` or the nominal rig lifted; `--bias` and
/// `--gap` applied.
pub fn machine_base(a: &TwinArgs) -> Result<ambid_twin::MachineConfig> {
    use ambid_twin::MachineConfig;
    let Some(p) = &a.config else {
        return Ok(MachineConfig::from_twin(&twin_config(a)?));
    };
    let s = std::fs::read_to_string(p).with_context(|| format!("cannot read {}", p.display()))?;
    let mut cfg = match MachineConfig::from_toml_str(&s) {
        Ok(c) => c,
        Err(em) => match TwinConfig::from_toml_str(&s) {
            Ok(t) => MachineConfig::from_twin(&t),
            Err(et) => {
                return Err(ambid::error::Error::usage(format!(
                    "{}: neither a machine configuration ({em}) nor a single-plane twin \
                     configuration ({et}); see `ambid config` and docs/twin.md",
                    p.display()
                ))
                .into())
            }
        },
    };
    if let Some(b) = a.bias {
        cfg.operating_point.bias_current_a = b;
    }
    if let Some(g) = a.gap {
        cfg.operating_point.air_gap_m = g;
    }
    Ok(cfg)
}

pub fn twin_config(a: &TwinArgs) -> Result<TwinConfig> {
    let mut cfg = match &a.config {
        Some(p) => {
            let s = std::fs::read_to_string(p)
                .with_context(|| format!("cannot read {}", p.display()))?;
            TwinConfig::from_toml_str(&s).with_context(|| format!("in {}", p.display()))?
        }
        None => match a.rig.rig_seed {
            Some(seed) => ambid_twin::random_rig(seed)?,
            None => TwinConfig::default(),
        },
    };
    if let Some(b) = a.bias {
        cfg.operating_point.bias_current_a = b;
    }
    if let Some(g) = a.gap {
        cfg.operating_point.air_gap_m = g;
    }
    cfg.validate()?;
    Ok(cfg)
}

/// The PRBS order from `--prbs-order`, or from the deprecated `--order` (with its note).
pub fn prbs_order_arg(prbs_order: u32, deprecated_order: Option<u32>) -> u32 {
    match deprecated_order {
        Some(o) => {
            super::args::deprecated(
                &format!("--order {o} (the PRBS order)"),
                &format!("--prbs-order {o}"),
            );
            o
        }
        None => prbs_order,
    }
}

/// The level in % of i_sat as a fraction: `level_pct`, or the deprecated `--amplitude` fraction
/// (with its note).
pub fn level_frac(level_pct: f64, deprecated_frac: Option<f64>) -> Result<f64> {
    match deprecated_frac {
        Some(f) => {
            super::args::deprecated(
                &format!("--amplitude {f} (a fraction of i_sat)"),
                &format!("--level {}", super::args::clean(100.0 * f)),
            );
            Ok(f)
        }
        None => Ok(level_pct / 100.0),
    }
}

/// The band from `--band` (or its default `band`), or from the deprecated separate edges
/// (`names`, with a note); an edge given alone replaces that edge of `band`.
pub fn deprecated_band(
    band: (f64, f64),
    lo: Option<f64>,
    hi: Option<f64>,
    names: (&str, &str),
) -> Result<(f64, f64)> {
    if lo.is_none() && hi.is_none() {
        return Ok(band);
    }
    let (l, h) = (lo.unwrap_or(band.0), hi.unwrap_or(band.1));
    let old: Vec<String> = [(names.0, lo), (names.1, hi)]
        .iter()
        .filter_map(|(n, v)| v.map(|v| format!("{n} {v}")))
        .collect();
    super::args::deprecated(&old.join(" "), &format!("--band {l}:{h}"));
    Ok((l, h))
}

/// Initial state of the validation filters (MATLAB `compare`'s `InitialCondition`).
#[derive(Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum X0Arg {
    /// From rest (samples before the record taken as zero).
    Zero,
    /// The state that best explains the record (least squares of the free response).
    Estimate,
}

impl X0Arg {
    pub fn core(self) -> InitialState {
        match self {
            Self::Zero => InitialState::Zero,
            Self::Estimate => InitialState::Estimate,
        }
    }
}

/// The unit of a plant magnitude from the declared units of y and u.
pub fn plant_unit(y: Option<&str>, u: Option<&str>) -> String {
    match (y, u) {
        (Some(y), Some(u)) => format!("{y}/{u}"),
        (Some(y), None) => format!("{y}/(unit of u not given)"),
        (None, Some(u)) => format!("(unit of y not given)/{u}"),
        (None, None) => "(unit not given)".into(),
    }
}

/// Weights of the FRF lines.
#[derive(Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum WeightsArg {
    /// The variance evaluated at the model, sample maximum likelihood (the default), from the
    /// `plant_noise_*` columns `ambid frf` writes; state-space and output-error fits refine
    /// with it, ARX keeps the variance at the data. Without those columns, as `variance`.
    Model,
    /// All lines alike.
    Uniform,
    /// Inverse variance at the data, from the file's `<q>_std` column.
    Variance,
    /// From the coherence column (`coh_ry`).
    Coherence,
}

/// The weights in words, for a model file's metadata.
pub fn weights_name(w: &FreqWeights) -> &'static str {
    match w {
        FreqWeights::Uniform => "uniform",
        FreqWeights::InverseVariance => "inverse variance at the data",
        FreqWeights::Coherence(_) => "coherence",
        FreqWeights::Given(_) => "given",
        FreqWeights::SampleMaximumLikelihood(_) => {
            "variance at the model (sample maximum likelihood; ARX at the data)"
        }
    }
}

/// The FRF and the fit options common to `fit --quantity` and `compare-models`.
pub struct FrfInput {
    pub frd: ambid_core::lti::Frd,
    /// The quantity's noise per line as a function of its value, on every line of `frd`
    /// (`<q>_noise_*` columns, [`FrfFile::ratio_noise`](ambid::io::csv::FrfFile::ratio_noise)),
    /// when the file has it.
    pub noise: Option<Vec<ambid_core::frf::closed_loop::RatioNoise>>,
    pub opts: FreqFitOptions,
    /// The band the user gave (`--band`), `None` when it was derived from the file.
    pub explicit_band: Option<(f64, f64)>,
}

/// Reads quantity `q` of an FRF CSV with sample rate `fs` and builds the fit options.
pub fn frf_input(
    path: &Path,
    quantity: &str,
    fs: Option<f64>,
    band: Option<(f64, f64)>,
    weights: WeightsArg,
    max_iterations: usize,
) -> Result<FrfInput> {
    let file = read_frf_csv(path)?;
    // the sample rate: --fs, else the `fs_hz` column that `ambid frf` writes
    let fs = match (fs, file.extra("fs_hz").ok().and_then(|c| c.first().copied())) {
        (Some(fs), _) => fs,
        (None, Some(fs)) => fs,
        (None, None) => return Err(ambid::error::Error::usage("this FRF file has no `fs_hz` column: give the sample rate of the data with --fs (e.g. --fs 20000)".to_string()).into()),
    };
    if !(fs.is_finite() && fs > 0.0) {
        return Err(ambid::error::Error::usage(format!(
            "the sample rate must be positive and finite, got {fs:e} Hz"
        ))
        .into());
    }
    let frd = file.frd(quantity, 1.0 / fs)?;
    // the band: --band, else where the file measures the quantity reliably (band::fit_band)
    let fit_band = match band {
        Some(b) => {
            let f = frd.f_hz();
            let inside = f.iter().filter(|x| **x >= b.0 && **x <= b.1).count();
            if inside == 0 {
                return Err(ambid::error::Error::usage(format!(
                    "--band {}:{} holds no line of {} (its lines lie in {:.4}–{:.4} Hz): give a band that overlaps them",
                    b.0,
                    b.1,
                    path.display(),
                    f.first().copied().unwrap_or(f64::NAN),
                    f.last().copied().unwrap_or(f64::NAN)
                ))
                .into());
            }
            b
        }
        None => {
            let d = fit_band(&frd, FIT_REL_HALFWIDTH)?;
            println!("{}", d.describe());
            d.band
        }
    };
    let noise = file.ratio_noise(quantity)?;
    let weights = match (weights, &noise) {
        (WeightsArg::Model, Some(n)) if frd.variance().is_some() => {
            FreqWeights::SampleMaximumLikelihood(n.clone())
        }
        (WeightsArg::Model, None) if frd.variance().is_some() => {
            println!(
                "weights: the variance at the data (the file has no `{quantity}_noise_*` columns for the variance at the model)"
            );
            FreqWeights::InverseVariance
        }
        (WeightsArg::Model | WeightsArg::Variance, _) if frd.variance().is_none() => {
            eprintln!("note: `{quantity}_std` is zero everywhere (exact data): uniform weights");
            FreqWeights::Uniform
        }
        (WeightsArg::Uniform, _) => FreqWeights::Uniform,
        (WeightsArg::Model | WeightsArg::Variance, _) => FreqWeights::InverseVariance,
        (WeightsArg::Coherence, _) => FreqWeights::Coherence(
            file.extra("coh_ry")
                .context("coherence weights need the `coh_ry` column of `ambid frf`")?
                .to_vec(),
        ),
    };
    let opts = FreqFitOptions {
        band_hz: Some(fit_band),
        weights,
        max_iterations,
        ..FreqFitOptions::default()
    };
    Ok(FrfInput {
        frd,
        noise,
        opts,
        explicit_band: band,
    })
}

/// The columns `input` and `output` of the record `p`, read with `file`, as a one-axis
/// [`Recording`] (the core's data contract): `u`, `y` and, when the file has the excitation
/// column (`--excitation`, default `r`), `r` (a closed-loop experiment, for `--loop auto`).
pub fn read_io(
    p: &Path,
    file: &DataFileArgs,
    (input, output): (&str, &str),
    excitation: &str,
) -> Result<Recording> {
    let d = file
        .file
        .read_columns(p, file.fs, &[input, output, excitation])?;
    let r = if d.has(excitation) {
        Some(d.column_raw(excitation)?.to_vec())
    } else {
        None
    };
    Ok(Recording::from_signals(
        d.ts,
        None,
        Signals {
            r,
            u: d.column(input)?.to_vec(),
            y: d.column(output)?.to_vec(),
            i: None,
            w: None,
        },
        d.has(excitation),
        p.display().to_string(),
    )?)
}

/// Reads a validation record, checks its sample time against the estimation data's and removes
/// the estimation data's means (`mu` from u, `my` from y).
pub fn read_validation(
    p: &Path,
    file: &DataFileArgs,
    input: &str,
    output: &str,
    ts: f64,
    mu: f64,
    my: f64,
) -> Result<(Vec<f64>, Vec<f64>)> {
    let rec = read_io(p, file, (input, output), "r")?;
    let (mut u, mut y, tsv) = (rec.u().to_vec(), rec.y().to_vec(), rec.ts());
    if ((tsv - ts) / ts).abs() > 1e-9 {
        return Err(ambid::error::Error::input(format!(
            "the validation data are sampled at {} Hz, the estimation data at {} Hz",
            1.0 / tsv,
            1.0 / ts
        ))
        .into());
    }
    u.iter_mut().for_each(|v| *v -= mu);
    y.iter_mut().for_each(|v| *v -= my);
    Ok((u, y))
}

/// The mean of `x`.
pub fn mean(x: &[f64]) -> f64 {
    x.iter().sum::<f64>() / x.len() as f64
}

/// The least-squares work a time-domain fit may ask for: $N p^2 \le 2\cdot10^{10}$ multiply–adds
/// (about 5 s on one core) for $N$ samples and $p$ parameters, e.g. 447 parameters on the seed
/// record of 102 300 samples; with [`ambid::workflow::config::SAMPLES_PER_PARAMETER`] samples per
/// parameter at least and every polynomial or state-space order at most
/// [`ambid::workflow::config::MAX_MODEL_ORDER`] (FIR/ARX numerators may be longer, within the
/// work bound). A hostile `--na 5000 --nb 5000` on 20 000 samples ran > 60 s at 3.9 GB.
pub const MAX_LS_WORK: f64 = 2e10;

/// Refuses a model too large for the record (`params` parameters on `n` samples) or for the
/// work bound [`MAX_LS_WORK`], as a usage error naming the options.
pub fn check_model_size(n: usize, params: usize, what: &str) -> Result<()> {
    use ambid::workflow::config::SAMPLES_PER_PARAMETER;
    let per = n / SAMPLES_PER_PARAMETER.max(1);
    let work_cap = (MAX_LS_WORK / n.max(1) as f64).sqrt().floor() as usize;
    let cap = per.min(work_cap);
    if params > cap {
        return Err(ambid::error::Error::usage(format!(
            "{what} has {params} parameters, more than the {cap} this record of {n} samples supports ({SAMPLES_PER_PARAMETER} samples per parameter, and N·p² ≤ {MAX_LS_WORK:e} least-squares work); give smaller orders"
        ))
        .into());
    }
    Ok(())
}

/// What `uncertainty` and `physical` read: the plant FRF with its standard deviations on the band
/// (given, or where the file measures it reliably), the nominal model and the loop's controller,
/// its sample time checked against the FRF's.
pub struct ModelOnFrf {
    pub frd: ambid_core::lti::Frd,
    pub band: (f64, f64),
    pub model: ambid_core::lti::StateSpace,
    pub controller: ambid::io::ControllerModel,
}

/// The quantity's noise per line on an FRF's band (`FrfInput::noise` on its lines).
pub type BandNoise = Option<Vec<ambid_core::frf::closed_loop::RatioNoise>>;

/// The FRF file's `quantity` on `band` (or the file's reliable band), that band and the
/// quantity's noise description on its lines when the file has one; an FRF whose standard
/// deviations are all zero is refused (`needs` says what they are needed for).
pub fn frf_with_variance(
    frf: &Path,
    quantity: &str,
    fs: Option<f64>,
    band: Option<(f64, f64)>,
    needs: &str,
) -> Result<(ambid_core::lti::Frd, (f64, f64), BandNoise)> {
    let input = frf_input(frf, quantity, fs, band, WeightsArg::Variance, 1)?;
    if input.frd.variance().is_none() {
        return Err(ambid::error::Error::input(format!(
            "{}: `{quantity}_std` is zero everywhere; {needs}",
            frf.display()
        ))
        .into());
    }
    let band = input.opts.band_hz.unwrap_or((0.0, f64::INFINITY));
    let frd = input.frd.band(band.0, band.1)?;
    let noise = match &input.noise {
        Some(n) => Some(
            ambid::uncertainty::noise_on_lines(input.frd.f_hz(), n, &frd)
                .with_context(|| format!("{}: the `{quantity}_noise_*` columns", frf.display()))?,
        ),
        None => None,
    };
    Ok((frd, band, noise))
}

/// The plant FRF with its standard deviations on the band (given, or the file's reliable band),
/// that band, the nominal model and the FRF's noise description on the band
/// ([`frf_with_variance`]): [`ModelOnFrf`] without the controller.
pub fn frf_and_model(
    frf: &Path,
    quantity: &str,
    fs: Option<f64>,
    band: Option<(f64, f64)>,
    model: &Path,
    needs: &str,
) -> Result<(
    ambid_core::lti::Frd,
    (f64, f64),
    ambid_core::lti::StateSpace,
    BandNoise,
)> {
    let (frd, band, noise) = frf_with_variance(frf, quantity, fs, band, needs)?;
    let model = ambid::io::model::read_model_json(model)?;
    Ok((frd, band, model, noise))
}

/// The loop's controller file, its sample time checked against the FRF's `frd`.
pub fn controller_for(
    controller: &Path,
    frd: &ambid_core::lti::Frd,
) -> Result<ambid::io::ControllerModel> {
    let controller = ambid::io::read_controller(controller)?;
    controller.check_ts(frd.ts().unwrap_or(1.0 / controller.fs_hz()))?;
    Ok(controller)
}

/// Reads [`ModelOnFrf`]; `needs` says what the standard deviations are needed for (the error
/// when they are all zero).
pub fn model_on_frf(
    frf: &Path,
    quantity: &str,
    fs: Option<f64>,
    band: Option<(f64, f64)>,
    model: &Path,
    controller: &Path,
    needs: &str,
) -> Result<ModelOnFrf> {
    let (frd, band, model, _) = frf_and_model(frf, quantity, fs, band, model, needs)?;
    let controller = controller_for(controller, &frd)?;
    Ok(ModelOnFrf {
        frd,
        band,
        model,
        controller,
    })
}
