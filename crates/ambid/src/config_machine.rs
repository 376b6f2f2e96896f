//! The workflow file's `[machine]` section: the whole machine (4 axes) across speeds, on the
//! 4-axis twin (default) or on recorded experiments (`[[machine.files]]`). Re-exported by
//! [`crate::config`]; the procedure is [`crate::workflow::machine`].

use crate::config::{fmt_num, ConfigError, MAX_PRBS_ORDER};
use ambid_twin::{AsymmetryConfig, UnbalanceConfig};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The multi-input designs `[machine] design` accepts (`ambid_core::signal::multi`).
pub const MACHINE_DESIGNS: [&str; 3] = ["orthogonal", "sequential", "zipper"];

/// The amplitude study's levels on the twin when `[machine] amplitude_levels_pct` is not given
/// and `uncertainty = true` or `physical = true` \[% of i_sat\]: with the identification level
/// (`level_pct`, 10 by default) three levels for term (e), the plant's shift with the
/// excitation amplitude (docs/uncertainty.md, "Term (e) for the machine"), and for the physical
/// parameters extrapolated to zero amplitude (docs/physical.md, "The whole machine").
pub const DEFAULT_MACHINE_AMPLITUDE_LEVELS_PCT: [f64; 2] = [5.0, 16.0];

/// The speeds of the twin when `[machine] speeds_rpm` is not given \[rpm\]: standstill, the
/// nominal 15 000 rpm and 30 000 rpm.
pub const DEFAULT_MACHINE_SPEEDS_RPM: [f64; 3] = [0.0, 15_000.0, 30_000.0];

/// `[machine]`: the whole-machine procedure (`ambid run` with this section runs it instead of
/// the single-axis steps): per speed the multi-input design on the 4-axis twin, or the recorded
/// experiments of `[[machine.files]]`, → the 4×4 closed-loop FRF with the synchronous (1×) line
/// removed → the report's machine sections (docs/workflow.md, "Whole machine").
///
/// ```
/// use ambid::config::WorkflowConfig;
/// use std::path::Path;
/// let cfg = WorkflowConfig::from_toml_str(
///     "[machine]\nspeeds_rpm = [0, 15000, 30000]\ndesign = \"orthogonal\"\n",
///     Path::new("wf.toml"),
/// ).unwrap();
/// let m = cfg.machine.unwrap();
/// assert_eq!(m.speeds(), vec![0.0, 15000.0, 30000.0]);
/// // unsorted speeds are refused, and the message says what to write
/// let e = WorkflowConfig::from_toml_str("[machine]\nspeeds_rpm = [30000, 0]\n", Path::new("wf.toml"))
///     .unwrap_err();
/// assert!(e.to_string().contains("increasing order"), "{e}");
/// ```
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(default, deny_unknown_fields)]
pub struct MachineSection {
    /// Number of axes (4: `xa, xb, ya, yb`; the only value accepted).
    pub axes: usize,
    /// Speeds \[rpm\], increasing, each ≥ 0 (default on the twin: 0, 15 000, 30 000; with
    /// `files`: the files' speeds, and when given it must list the same speeds).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub speeds_rpm: Option<Vec<f64>>,
    /// Multi-input design on the twin: `orthogonal` (default, docs/frf.md "MIMO": every axis
    /// excited in every experiment with Hadamard signs, the best-conditioned input matrix),
    /// `sequential` or `zipper`.
    pub design: String,
    /// Twin physics: `nonlinear` (default, as `[twin] mode`) or `linear`.
    pub mode: String,
    /// Sensor noise on the twin (default: on).
    pub noise: bool,
    /// Sensor noise RMS \[µm\] (default: the machine configuration's, 0.2 µm on the nominal rig).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub noise_rms_um: Option<f64>,
    /// Base seed of the twin's noise (default: the workflow's `seed`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub seed: Option<u64>,
    /// A machine configuration (`MachineConfig` TOML, or a single-plane twin configuration lifted
    /// to the machine), relative to the workflow file (default: the nominal rig in both planes).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub config: Option<PathBuf>,
    /// An unbalance on the twin (default: none); its 1× line is removed before the FRF.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub unbalance: Option<UnbalanceConfig>,
    /// An x/y asymmetry of the twin's magnets (default: none).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub asymmetry: Option<AsymmetryConfig>,
    /// Excitation level: peak in % of i_sat (default 10).
    pub level_pct: f64,
    /// PRBS register order of the `orthogonal`/`sequential` designs (default 10).
    pub prbs_order: u32,
    /// Samples per PRBS bit (default 5).
    pub samples_per_bit: usize,
    /// Periods recorded per experiment (default 12: 11 averaged after the skipped one; the
    /// FRF's noise falls as 1/√(periods − 1), docs/workflow.md "Whole machine"), after a pre-roll
    /// to the periodic steady state.
    pub periods: usize,
    /// Periods dropped at the start of each record before averaging (default 1).
    pub skip_periods: usize,
    /// Band of the zippered multisine \[Hz\] (default 1–2000).
    pub band_hz: [f64; 2],
    /// Period of the zippered multisine \[s\] (default 0.25575, the seed PRBS's).
    pub period_s: f64,
    /// Band of the figures of merit (cross-coupling, medians) \[Hz\] (default 10–1000).
    pub quality_band_hz: [f64; 2],
    /// Recorded experiments, one entry per speed (default: none, the twin runs).
    pub files: Vec<MachineFile>,
    /// Parametric models of the plant: `none` (default: the measured FRFs only), `fit` (the
    /// MIMO state-space fitter, `workflow::machine_fit::FrequencyFitter`: per speed orders 16,
    /// 20, 24 in turn until one is at the noise level, closed-loop validation, Campbell diagram
    /// from the models) or `fit-all` (the same with every order fitted and BIC choosing).
    pub models: String,
    /// With `models = "fit"`/`"fit-all"`: the chosen model's uncertainty per speed, entry by
    /// entry (`validate::uncertainty::uncertainty_matrix`, raised by its joint factor), and the
    /// four controllers' robust stability against it on the fit's lines (default: off; about
    /// 3 s per speed, docs/uncertainty.md "MIMO entries").
    pub uncertainty: bool,
    /// With `uncertainty` or `physical` on the twin: the amplitude study's levels \[% of
    /// i_sat\], each a repetition of the identification design at that peak level and every
    /// speed. Their plant FRFs with the identification level's give the uncertainty's term (e)
    /// per entry (the best linear approximation's shift from its extrapolation to zero
    /// amplitude) and the physical parameters extrapolated to zero amplitude (the small-signal
    /// $k_x$ of a nonlinear magnet); levels with saturated samples are left out of the
    /// physical parameters' extrapolation, and those saturated on more than
    /// [`AMPLITUDE_MAX_SATURATED`](crate::uncertainty::AMPLITUDE_MAX_SATURATED) of the samples
    /// out of term (e). Default with
    /// `uncertainty = true` or `physical = true`: [`DEFAULT_MACHINE_AMPLITUDE_LEVELS_PCT`] (5
    /// and 16 %); `[]` runs no study (the bound and the physical parameters then hold the best
    /// linear approximation at `level_pct`, not the small-signal plant).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub amplitude_levels_pct: Option<Vec<f64>>,
    /// The whole-machine gray box per speed (default: off): $k_i$, $k_x$ of every axis' magnet,
    /// the bending mode and its shape with 95 % intervals from the measured 4×4 plant FRF
    /// (`ambid_core::estimate::graybox::fit_machine_physical`, docs/physical.md "The whole
    /// machine"); on the twin the drawing is its configuration and its values stand beside.
    pub physical: bool,
    /// With `physical` and `files`: the drawing TOML (docs/physical.md), relative to the
    /// workflow file.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub drawing: Option<PathBuf>,
    /// With `physical`, `files` and a speed above 0: the rotor's polar inertia \[kg·m²\] (the
    /// gyroscopic moments).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub polar_inertia_kgm2: Option<f64>,
}

/// One speed's recorded experiments (`[[machine.files]]`).
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct MachineFile {
    /// The speed of the records \[rpm\].
    pub speed_rpm: f64,
    /// A directory as `ambid simulate --axes 4` writes it (`exp1/data.csv`, … and `meta.json`
    /// with the speed), or a matrix FRF CSV as `ambid frf` writes it (`P_<out>_<in>_re/_im/_std`
    /// of every pair of axes), relative to the workflow file.
    pub path: PathBuf,
}

impl Default for MachineSection {
    fn default() -> Self {
        Self {
            axes: 4,
            speeds_rpm: None,
            design: "orthogonal".into(),
            mode: "nonlinear".into(),
            noise: true,
            noise_rms_um: None,
            seed: None,
            config: None,
            unbalance: None,
            asymmetry: None,
            physical: false,
            drawing: None,
            polar_inertia_kgm2: None,
            level_pct: 10.0,
            prbs_order: 10,
            samples_per_bit: 5,
            periods: 12,
            skip_periods: 1,
            band_hz: [1.0, 2000.0],
            period_s: 0.25575,
            quality_band_hz: [10.0, 1000.0],
            files: Vec::new(),
            models: "none".into(),
            uncertainty: false,
            amplitude_levels_pct: None,
        }
    }
}

/// Checks that `speeds` increase strictly and are finite and ≥ 0; `key` names them.
fn check_speeds(key: &str, speeds: &[f64]) -> Result<(), String> {
    let list = |v: &[f64]| v.iter().map(|s| fmt_num(*s)).collect::<Vec<_>>().join(", ");
    if speeds.is_empty() {
        return Err(format!(
            "{key} lists no speed; give at least one, e.g. speeds_rpm = [0, 15000, 30000]"
        ));
    }
    if let Some(s) = speeds.iter().find(|s| !(s.is_finite() && **s >= 0.0)) {
        return Err(format!(
            "{key} has {}: every speed must be a finite number of rpm ≥ 0 (the sense of rotation \
             is fixed by the twin's conventions, docs/conventions.md; give the magnitude)",
            fmt_num(*s)
        ));
    }
    if let Some(k) = (1..speeds.len()).find(|&k| speeds[k] == speeds[k - 1]) {
        return Err(format!(
            "{key} lists {} rpm twice; give every speed once, e.g. [{}]",
            fmt_num(speeds[k]),
            list(&dedup_sorted(speeds))
        ));
    }
    if (1..speeds.len()).any(|k| speeds[k] < speeds[k - 1]) {
        return Err(format!(
            "{key} = [{}] must be in increasing order; write [{}]",
            list(speeds),
            list(&dedup_sorted(speeds))
        ));
    }
    Ok(())
}

fn dedup_sorted(v: &[f64]) -> Vec<f64> {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    s.dedup();
    s
}

impl MachineSection {
    /// The speeds of the procedure \[rpm\]: the files' (in the order given) when there are
    /// files, else `speeds_rpm`, else `DEFAULT_MACHINE_SPEEDS_RPM` (0, 15 000, 30 000 rpm).
    pub fn speeds(&self) -> Vec<f64> {
        if !self.files.is_empty() {
            return self.files.iter().map(|f| f.speed_rpm).collect();
        }
        self.speeds_rpm
            .clone()
            .unwrap_or_else(|| DEFAULT_MACHINE_SPEEDS_RPM.to_vec())
    }

    /// The amplitude study's levels \[% of i_sat\] (`amplitude_levels_pct`): as given, else
    /// [`DEFAULT_MACHINE_AMPLITUDE_LEVELS_PCT`] on the twin with `uncertainty = true` or
    /// `physical = true`, else none.
    ///
    /// ```
    /// use ambid::config::MachineSection;
    /// let mut m = MachineSection { models: "fit".into(), uncertainty: true, ..Default::default() };
    /// assert_eq!(m.amplitude_levels(), vec![5.0, 16.0]);
    /// m.amplitude_levels_pct = Some(vec![]);
    /// assert!(m.amplitude_levels().is_empty());
    /// let p = MachineSection { physical: true, ..Default::default() };
    /// assert_eq!(p.amplitude_levels(), vec![5.0, 16.0]);
    /// assert!(MachineSection::default().amplitude_levels().is_empty());
    /// ```
    pub fn amplitude_levels(&self) -> Vec<f64> {
        match &self.amplitude_levels_pct {
            Some(v) => v.clone(),
            None if (self.uncertainty || self.physical) && self.files.is_empty() => {
                DEFAULT_MACHINE_AMPLITUDE_LEVELS_PCT.to_vec()
            }
            None => Vec::new(),
        }
    }

    /// Whether the data are recorded files (else the twin).
    pub fn from_files(&self) -> bool {
        !self.files.is_empty()
    }

    /// Checks every value (called by [`crate::config::WorkflowConfig::check`]); `steps_given`
    /// says whether the file (or `--steps`) lists single-axis steps.
    ///
    /// # Errors
    /// [`ConfigError::Invalid`] naming the key, what is wrong and what to write instead.
    pub fn check(&self, path: &Path, steps_given: bool) -> Result<(), ConfigError> {
        self.check_inner(steps_given)
            .map_err(|message| ConfigError::Invalid {
                path: path.to_path_buf(),
                message,
            })
    }

    fn check_inner(&self, steps_given: bool) -> Result<(), String> {
        if self.axes != 4 {
            return Err(format!(
                "machine.axes = {}: the whole-machine procedure identifies the 4 radial axes \
                 (xa, xb, ya, yb); write axes = 4, or remove the [machine] section for the \
                 single-axis procedure",
                self.axes
            ));
        }
        if steps_given {
            return Err(
                "`steps` (or --steps) selects steps of the single-axis procedure, but this file \
                 has a [machine] section, which runs the whole-machine procedure instead; remove \
                 `steps`, or remove [machine] to run the single-axis steps"
                    .into(),
            );
        }
        if !MACHINE_DESIGNS.contains(&self.design.as_str()) {
            return Err(format!(
                "machine.design = \"{}\" is not one of \"orthogonal\" (default), \"sequential\", \
                 \"zipper\"",
                self.design
            ));
        }
        if !["none", "fit", "fit-all"].contains(&self.models.as_str()) {
            return Err(format!(
                "machine.models = \"{}\" is not one of \"none\" (default: the measured FRFs \
                 only), \"fit\" (MIMO state-space models of the plant per speed, orders up to \
                 the first at the noise level), \"fit-all\" (every candidate order fitted)",
                self.models
            ));
        }
        if self.uncertainty && self.models == "none" {
            return Err(
                "machine.uncertainty = true needs a model: set machine.models = \"fit\" (or \"fit-all\")"
                    .into(),
            );
        }
        if let Some(levels) = &self.amplitude_levels_pct {
            if !self.files.is_empty() && !levels.is_empty() {
                return Err(
                    "machine.amplitude_levels_pct runs the amplitude study on the twin; recorded \
                     files at several levels are not read yet — remove amplitude_levels_pct (the \
                     bound then has no term (e))"
                        .into(),
                );
            }
            if !self.uncertainty && !self.physical && !levels.is_empty() {
                return Err(
                    "machine.amplitude_levels_pct feeds the uncertainty bound's term (e) and the \
                     physical parameters at zero amplitude: set machine.uncertainty = true or \
                     machine.physical = true, or remove amplitude_levels_pct"
                        .into(),
                );
            }
            if let Some(l) = levels
                .iter()
                .find(|l| !(l.is_finite() && **l > 0.0 && **l <= 100.0))
            {
                return Err(format!(
                    "machine.amplitude_levels_pct has {}: every level must be in (0, 100] % of \
                     i_sat, e.g. [5, 16]",
                    fmt_num(*l)
                ));
            }
            let mut sorted = levels.clone();
            sorted.push(self.level_pct);
            sorted.sort_by(f64::total_cmp);
            if sorted.windows(2).any(|w| w[0] == w[1]) {
                return Err(format!(
                    "machine.amplitude_levels_pct = [{}] repeats a level or the identification \
                     level level_pct = {}: give levels other than it and each once, e.g. [5, 16]",
                    levels
                        .iter()
                        .map(|v| fmt_num(*v))
                        .collect::<Vec<_>>()
                        .join(", "),
                    fmt_num(self.level_pct)
                ));
            }
        }
        if self.physical && !self.files.is_empty() {
            if self.drawing.is_none() {
                return Err(
                    "machine.physical = true with [[machine.files]] needs machine.drawing, the \
                     drawing TOML (mass_kg, inertia_kgm2, bearing_a_m, bearing_b_m, \
                     amplifier_bandwidth_hz, sensor_bandwidth_hz; docs/physical.md)"
                        .into(),
                );
            }
            let spinning = self.files.iter().any(|f| f.speed_rpm > 0.0);
            match self.polar_inertia_kgm2 {
                Some(j) if !(j.is_finite() && j > 0.0) => {
                    return Err(format!(
                        "machine.polar_inertia_kgm2 = {} must be positive, kg·m²",
                        fmt_num(j)
                    ))
                }
                None if spinning => {
                    return Err("machine.physical = true with files above 0 rpm needs \
                                machine.polar_inertia_kgm2, the rotor's polar inertia in kg·m² \
                                (the gyroscopic moments; a solid cylinder: m r²/2)"
                        .into())
                }
                _ => {}
            }
        } else if self.drawing.is_some() || self.polar_inertia_kgm2.is_some() {
            return Err(
                "machine.drawing and machine.polar_inertia_kgm2 describe recorded \
                        files for machine.physical = true; on the twin its configuration is \
                        the drawing — remove them, or set physical = true with files"
                    .into(),
            );
        }
        if !["nonlinear", "linear"].contains(&self.mode.as_str()) {
            return Err(format!(
                "machine.mode = \"{}\" is not one of \"nonlinear\", \"linear\"",
                self.mode
            ));
        }
        if let Some(s) = &self.speeds_rpm {
            check_speeds("machine.speeds_rpm", s)?;
        }
        if !self.files.is_empty() {
            let fs: Vec<f64> = self.files.iter().map(|f| f.speed_rpm).collect();
            check_speeds("the speed_rpm of [[machine.files]]", &fs)?;
            if let Some(s) = &self.speeds_rpm {
                if s != &fs {
                    return Err(format!(
                        "machine.speeds_rpm = [{}], but [[machine.files]] are at [{}] rpm: the \
                         speeds are those of the files; remove speeds_rpm, or make it list the \
                         files' speeds",
                        s.iter().map(|v| fmt_num(*v)).collect::<Vec<_>>().join(", "),
                        fs.iter()
                            .map(|v| fmt_num(*v))
                            .collect::<Vec<_>>()
                            .join(", ")
                    ));
                }
            }
            for (key, given) in [
                ("config", self.config.is_some()),
                ("unbalance", self.unbalance.is_some()),
                ("asymmetry", self.asymmetry.is_some()),
                ("noise_rms_um", self.noise_rms_um.is_some()),
            ] {
                if given {
                    return Err(format!(
                        "machine.{key} sets up the twin, but [[machine.files]] gives recorded \
                         experiments; remove {key}, or remove the files to run the twin"
                    ));
                }
            }
        }
        if !(self.level_pct.is_finite() && self.level_pct > 0.0 && self.level_pct <= 100.0) {
            return Err(format!(
                "machine.level_pct = {} must be in (0, 100] % of i_sat, e.g. 10",
                fmt_num(self.level_pct)
            ));
        }
        if !(2..=MAX_PRBS_ORDER).contains(&self.prbs_order) {
            return Err(format!(
                "machine.prbs_order = {} must be between 2 and {MAX_PRBS_ORDER}, e.g. 10",
                self.prbs_order
            ));
        }
        if self.samples_per_bit == 0 {
            return Err("machine.samples_per_bit = 0 must be at least 1, e.g. 5".into());
        }
        if self.periods < self.skip_periods.saturating_add(2) {
            return Err(format!(
                "machine.periods = {} with skip_periods = {}: the period average needs at least 2 \
                 periods after the skipped ones (and 2 for a variance); give periods ≥ {}",
                self.periods,
                self.skip_periods,
                self.skip_periods + 2
            ));
        }
        if let Some(v) = self.noise_rms_um {
            if !(v.is_finite() && v >= 0.0) {
                return Err(format!(
                    "machine.noise_rms_um = {} must be ≥ 0 µm, e.g. 0.2",
                    fmt_num(v)
                ));
            }
        }
        for (key, [a, b]) in [
            ("machine.band_hz", self.band_hz),
            ("machine.quality_band_hz", self.quality_band_hz),
        ] {
            if !(a.is_finite() && b.is_finite() && 0.0 <= a && a < b) {
                return Err(format!(
                    "{key} = [{}, {}] must be an increasing pair of frequencies in Hz, e.g. [10, \
                     1000]",
                    fmt_num(a),
                    fmt_num(b)
                ));
            }
        }
        if !(self.period_s.is_finite() && self.period_s > 0.0) {
            return Err(format!(
                "machine.period_s = {} must be a positive duration in s, e.g. 0.25575",
                fmt_num(self.period_s)
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use crate::config::WorkflowConfig;
    use std::path::Path;

    fn err(toml: &str) -> String {
        WorkflowConfig::from_toml_str(toml, Path::new("wf.toml"))
            .map(|_| ())
            .unwrap_err()
            .to_string()
    }

    #[test]
    fn machine_section_defaults_and_refusals() {
        let p = Path::new("wf.toml");
        // no [machine]: the single-axis workflow, nothing changes
        let c = WorkflowConfig::from_toml_str("seed = 3\n", p).unwrap();
        assert!(c.machine.is_none());
        // an empty [machine]: the twin at the default speeds, the documented default design
        let m = WorkflowConfig::from_toml_str("[machine]\n", p)
            .unwrap()
            .machine
            .unwrap();
        assert_eq!(m.speeds(), vec![0.0, 15000.0, 30000.0]);
        assert_eq!(m.design, "orthogonal");
        assert!(!m.from_files());
        let e = err("[machine]\nspeeds_rpm = [0, 15000, 15000]\n");
        assert!(
            e.contains("15000 rpm twice") && e.contains("[0, 15000]"),
            "{e}"
        );
        let e = err("[machine]\nspeeds_rpm = [30000, 0]\n");
        assert!(e.contains("write [0, 30000]"), "{e}");
        let e = err("[machine]\nspeeds_rpm = [-100]\n");
        assert!(e.contains("-100") && e.contains("≥ 0"), "{e}");
        let e = err("[machine]\nspeeds_rpm = []\n");
        assert!(e.contains("lists no speed"), "{e}");
        let e = err("[machine]\naxes = 2\n");
        assert!(e.contains("axes = 4"), "{e}");
        let e = err("[machine]\ndesign = \"hadamard\"\n");
        assert!(e.contains("hadamard") && e.contains("orthogonal"), "{e}");
        let e = err("steps = [\"frf\"]\n[machine]\n");
        assert!(e.contains("remove `steps`"), "{e}");
        let e = err("[machine]\nperiods = 2\n");
        assert!(e.contains("periods ≥ 3"), "{e}");
        let e = err(
            "[machine]\nspeeds_rpm = [0, 100]\n[[machine.files]]\nspeed_rpm = 0\npath = \"a\"\n",
        );
        assert!(e.contains("files' speeds"), "{e}");
        let e = err("[machine]\nunbalance = { mass_kg = 1e-3 }\n[[machine.files]]\nspeed_rpm = 0\npath = \"a\"\n");
        assert!(e.contains("remove unbalance"), "{e}");
        let e = err("[machine]\nspeed = 3\n");
        assert!(e.contains("speed"), "{e}");
    }

    #[test]
    fn the_example_machine_block_parses_to_the_defaults() {
        // `ambid init`'s commented [machine] block, uncommented (without the files entry)
        let ex = crate::config::EXAMPLE;
        let start = ex.find("# [machine]").unwrap();
        let end = ex.find("# [[machine.files]]").unwrap();
        let block: String = ex[start..end]
            .lines()
            .map(|l| l.strip_prefix("# ").unwrap_or(l))
            .map(|l| format!("{l}\n"))
            .collect();
        let m = WorkflowConfig::from_toml_str(&block, Path::new("wf.toml"))
            .unwrap()
            .machine
            .unwrap();
        let d = super::MachineSection::default();
        assert_eq!(m.speeds(), d.speeds());
        assert_eq!(
            (
                m.design.as_str(),
                m.mode.as_str(),
                m.periods,
                m.prbs_order,
                m.level_pct
            ),
            (
                d.design.as_str(),
                d.mode.as_str(),
                d.periods,
                d.prbs_order,
                d.level_pct
            )
        );
        assert_eq!(m.quality_band_hz, d.quality_band_hz);
        assert_eq!(m.unbalance.unwrap().mass_kg, 1e-3);
    }
}
