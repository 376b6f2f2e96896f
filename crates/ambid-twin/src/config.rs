//! Twin configuration: every physical and digital parameter, with the nominal rig as the default.
//!
//! The configuration reads from and writes to TOML. Every section and every field is optional
//! (missing values take the nominal default); unknown fields are errors, so a misspelt setting
//! never passes silently.
//!
//! ```toml
//! [rotor]
//! mass_kg = 5.0
//! [operating_point]
//! bias_current_a = 2.4      # +20 % bias
//! air_gap_m = 0.41e-3       # +10 µm gap
//! [sensor]
//! noise_rms_m = 0.2e-6
//! quantize = true
//! ```
//!
//! Units are SI throughout; frequencies are in Hz.

use crate::error::{Result, TwinError};
use serde::{Deserialize, Serialize};

/// Rotor: a uniform rigid body in one plane (translation of the centre of mass and tilt) plus one
/// free–free bending mode.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RotorConfig {
    /// Rotor mass $m$ \[kg\].
    pub mass_kg: f64,
    /// Rotor length $L$ \[m\] (used for the default transverse inertia $J = m L^2 / 12$).
    pub length_m: f64,
    /// Transverse moment of inertia $J$ about the centre of mass \[kg·m²\]; `None` means $m L^2/12$.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub transverse_inertia_kgm2: Option<f64>,
    /// Distance $a$ from the centre of mass to bearing (and sensor) A \[m\].
    pub bearing_a_m: f64,
    /// Distance $b$ from the centre of mass to bearing (and sensor) B \[m\], on the other side.
    pub bearing_b_m: f64,
    /// Free–free bending eigenfrequency \[Hz\].
    pub bending_freq_hz: f64,
    /// Modal damping ratio of the bending mode \[-\].
    pub bending_damping: f64,
    /// Mass-normalised bending mode-shape value $\varphi_A$ at bearing A \[kg^-½\].
    pub mode_shape_a: f64,
    /// Mass-normalised bending mode-shape value $\varphi_B$ at bearing B \[kg^-½\].
    pub mode_shape_b: f64,
}

impl Default for RotorConfig {
    fn default() -> Self {
        Self {
            mass_kg: 5.0,
            length_m: 0.5,
            transverse_inertia_kgm2: None,
            bearing_a_m: 0.2165,
            bearing_b_m: 0.2165,
            bending_freq_hz: 730.0,
            bending_damping: 0.01,
            mode_shape_a: 0.616,
            mode_shape_b: 0.616,
        }
    }
}

impl RotorConfig {
    /// Transverse inertia $J$ actually used \[kg·m²\].
    pub fn inertia(&self) -> f64 {
        self.transverse_inertia_kgm2
            .unwrap_or(self.mass_kg * self.length_m * self.length_m / 12.0)
    }
}

/// Magnets: one differential pair per bearing, identical at A and B.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct MagnetConfig {
    /// Number of turns $N$ per coil.
    pub turns: f64,
    /// Pole face area $A$ \[m²\].
    pub pole_area_m2: f64,
    /// Pole angle $\alpha$ to the bearing axis \[deg\].
    pub pole_angle_deg: f64,
    /// Control-current saturation $i_\mathrm{sat}$ \[A\]: controller clamp, DAC limit and amplifier limit.
    pub i_sat_a: f64,
}

impl Default for MagnetConfig {
    fn default() -> Self {
        Self {
            turns: 100.0,
            pole_area_m2: 4e-4,
            pole_angle_deg: 22.5,
            i_sat_a: 2.0,
        }
    }
}

/// Current amplifier (one per bearing, driving both coils of the pair).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct AmplifierConfig {
    /// Closed-loop current bandwidth (first-order lag corner) \[Hz\].
    pub bandwidth_hz: f64,
    /// Bus voltage $V_\mathrm{bus}$ \[V\] (slew limit).
    pub bus_voltage_v: f64,
    /// Coil inductance $L_c$ \[H\] (slew limit).
    pub inductance_h: f64,
    /// Coil resistance $R_c$ \[Ω\] (slew limit).
    pub resistance_ohm: f64,
}

impl Default for AmplifierConfig {
    fn default() -> Self {
        Self {
            bandwidth_hz: 2000.0,
            bus_voltage_v: 60.0,
            inductance_h: 6.3e-3,
            resistance_ohm: 1.0,
        }
    }
}

/// Displacement sensor (one per bearing, collocated).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SensorConfig {
    /// Sensitivity \[V/m\] (10 V/mm = 1e4 V/m). Used for the ADC quantisation.
    pub gain_v_per_m: f64,
    /// First-order low-pass corner \[Hz\].
    pub bandwidth_hz: f64,
    /// RMS of the white Gaussian measurement noise \[m\] (when noise is switched on).
    pub noise_rms_m: f64,
    /// Quantise the sampled sensor voltage with the ADC below.
    pub quantize: bool,
    /// ADC resolution \[bit\].
    pub adc_bits: u32,
    /// ADC full-scale range ±`adc_range_v` \[V\].
    pub adc_range_v: f64,
}

impl Default for SensorConfig {
    fn default() -> Self {
        Self {
            gain_v_per_m: 1e4,
            bandwidth_hz: 10e3,
            noise_rms_m: 0.2e-6,
            quantize: false,
            adc_bits: 16,
            adc_range_v: 10.0,
        }
    }
}

impl SensorConfig {
    /// ADC step expressed in metres, $\Delta = 2 V_\mathrm{range} / 2^{bits} / \text{gain}$.
    pub fn lsb_m(&self) -> f64 {
        2.0 * self.adc_range_v / (2f64).powi(self.adc_bits as i32) / self.gain_v_per_m
    }
}

/// Decentralised digital PID controller (identical at A and B):
/// $$C(s) = \frac{K_p + K_i/s + K_d\ s/(1+s/\omega_d)}{1+s/\omega_l},\qquad K_i = K_p\ 2\pi f_i,$$
/// discretised with Tustin at $f_s$, one sample of computation delay, output clamp at
/// $\pm i_\mathrm{sat}$ with integrator anti-windup.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ControllerConfig {
    /// Sampling frequency $f_s$ \[Hz\].
    pub fs_hz: f64,
    /// Proportional gain $K_p$ \[A/m\].
    pub kp: f64,
    /// Integrator corner $f_i$ \[Hz\], $K_i = K_p\  2\pi f_i$ \[A/(m·s)\]; 0 disables the integrator.
    pub integral_corner_hz: f64,
    /// Derivative gain $K_d$ \[A·s/m\].
    pub kd: f64,
    /// Derivative filter corner $\omega_d/2\pi$ \[Hz\].
    pub derivative_cutoff_hz: f64,
    /// Output low-pass corner $\omega_l/2\pi$ \[Hz\].
    pub lowpass_hz: f64,
}

impl Default for ControllerConfig {
    fn default() -> Self {
        Self {
            fs_hz: 20e3,
            kp: 21_000.0,
            integral_corner_hz: 5.0,
            kd: 14.0,
            derivative_cutoff_hz: 4e3,
            lowpass_hz: 5e3,
        }
    }
}

impl ControllerConfig {
    /// Integral gain $K_i = K_p\  2\pi f_i$ \[A/(m·s)\].
    pub fn ki(&self) -> f64 {
        self.kp * 2.0 * std::f64::consts::PI * self.integral_corner_hz
    }
}

/// Operating point of both bearings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct OperatingPoint {
    /// Bias current $i_0$ \[A\].
    pub bias_current_a: f64,
    /// Nominal air gap $g_0$ \[m\] (rotor centred).
    pub air_gap_m: f64,
}

impl Default for OperatingPoint {
    fn default() -> Self {
        Self {
            bias_current_a: 2.0,
            air_gap_m: 0.4e-3,
        }
    }
}

/// Integrator of the continuous part in nonlinear mode.
///
/// Both integrate the same exact nonlinear right-hand side $\dot\xi = f(\xi, i_\mathrm{ref})$
/// (exact force law, amplifier output and slew limits) with the references held over a control
/// period (ZOH); see [`crate::sim`] for the schemes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Integrator {
    /// Classical RK4 with `simulation.substeps` (≥ 10) steps per control period. The default and
    /// the reference.
    #[default]
    Rk4,
    /// Exponential (Lawson / integrating-factor) RK4 with `simulation.exp_substeps` (≥ 1) steps
    /// per control period: the linearised model $A_c\xi + B_c i_\mathrm{ref}$ is propagated
    /// exactly with precomputed matrix exponentials, RK4 acts only on the nonlinear residual
    /// $f - A_c\xi - B_c i_\mathrm{ref}$ (force-law residuals and amplifier-limit corrections).
    ExpRk4,
}

impl std::fmt::Display for Integrator {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Integrator::Rk4 => "rk4",
            Integrator::ExpRk4 => "exp_rk4",
        })
    }
}

impl std::str::FromStr for Integrator {
    type Err = TwinError;
    fn from_str(s: &str) -> Result<Integrator> {
        match s.trim().to_ascii_lowercase().replace('-', "_").as_str() {
            "rk4" => Ok(Integrator::Rk4),
            "exp_rk4" | "exprk4" => Ok(Integrator::ExpRk4),
            other => Err(TwinError::InvalidArgument {
                name: "integrator",
                reason: format!("unknown integrator `{other}`; use `rk4` or `exp_rk4`"),
            }),
        }
    }
}

/// Numerical settings of the simulation (nonlinear mode only; the linear mode is exact).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SimulationConfig {
    /// Integrator of the nonlinear mode. Default: [`Integrator::Rk4`].
    pub integrator: Integrator,
    /// RK4 substeps per control period for [`Integrator::Rk4`] (≥ 10). Default 10.
    pub substeps: usize,
    /// Exponential-RK4 steps per control period for [`Integrator::ExpRk4`] (≥ 1, ≤ 1000).
    /// Default 1: one step of $T_s$ (the linear part is exact at any step; the step only limits
    /// how well RK4 follows the small nonlinear residual, see [`crate::sim`]).
    pub exp_substeps: usize,
}

impl Default for SimulationConfig {
    fn default() -> Self {
        Self {
            integrator: Integrator::Rk4,
            substeps: 10,
            exp_substeps: 1,
        }
    }
}

impl SimulationConfig {
    /// Steps per control period of the configured integrator.
    pub fn steps_per_period(&self) -> usize {
        match self.integrator {
            Integrator::Rk4 => self.substeps,
            Integrator::ExpRk4 => self.exp_substeps,
        }
    }
}

/// Complete twin configuration. `Default` is the nominal rig.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TwinConfig {
    /// Rotor.
    pub rotor: RotorConfig,
    /// Magnets.
    pub magnet: MagnetConfig,
    /// Current amplifiers.
    pub amplifier: AmplifierConfig,
    /// Displacement sensors.
    pub sensor: SensorConfig,
    /// Controllers.
    pub controller: ControllerConfig,
    /// Operating point.
    pub operating_point: OperatingPoint,
    /// Numerical settings.
    pub simulation: SimulationConfig,
}

fn positive(field: &str, v: f64) -> Result<()> {
    if !(v.is_finite() && v > 0.0) {
        return Err(TwinError::Config {
            field: field.into(),
            reason: format!("must be positive and finite, got {v}"),
        });
    }
    Ok(())
}

fn nonneg(field: &str, v: f64) -> Result<()> {
    if !(v.is_finite() && v >= 0.0) {
        return Err(TwinError::Config {
            field: field.into(),
            reason: format!("must be non-negative and finite, got {v}"),
        });
    }
    Ok(())
}

fn finite(field: &str, v: f64) -> Result<()> {
    if !v.is_finite() {
        return Err(TwinError::Config {
            field: field.into(),
            reason: format!("must be finite, got {v}"),
        });
    }
    Ok(())
}

impl TwinConfig {
    /// Parses a TOML document (missing fields take their defaults) and validates it.
    pub fn from_toml_str(s: &str) -> Result<TwinConfig> {
        let cfg: TwinConfig = toml::from_str(s).map_err(|e| TwinError::Toml(e.to_string()))?;
        cfg.validate()?;
        Ok(cfg)
    }

    /// Writes the configuration as TOML (all fields, so the file documents the rig completely).
    pub fn to_toml_string(&self) -> Result<String> {
        toml::to_string(self).map_err(|e| TwinError::TomlWrite(e.to_string()))
    }

    /// Checks every value: positive masses, lengths, gaps, bandwidths and gains where physics
    /// needs them, finite everything, $i_0 > 0$, $g_0 > 0$, $i_\mathrm{sat} > 0$, $f_s > 0$,
    /// substeps ≥ 10 (for `rk4`), exp_substeps in 1..=1000, sensor and filter corners below… nothing else (Nyquist is allowed to be
    /// violated by a continuous-time corner: it is physics, not a sampled filter).
    pub fn validate(&self) -> Result<()> {
        let r = &self.rotor;
        positive("rotor.mass_kg", r.mass_kg)?;
        positive("rotor.length_m", r.length_m)?;
        if let Some(j) = r.transverse_inertia_kgm2 {
            positive("rotor.transverse_inertia_kgm2", j)?;
        }
        positive("rotor.bearing_a_m", r.bearing_a_m)?;
        positive("rotor.bearing_b_m", r.bearing_b_m)?;
        positive("rotor.bending_freq_hz", r.bending_freq_hz)?;
        nonneg("rotor.bending_damping", r.bending_damping)?;
        finite("rotor.mode_shape_a", r.mode_shape_a)?;
        finite("rotor.mode_shape_b", r.mode_shape_b)?;
        let m = &self.magnet;
        positive("magnet.turns", m.turns)?;
        positive("magnet.pole_area_m2", m.pole_area_m2)?;
        finite("magnet.pole_angle_deg", m.pole_angle_deg)?;
        if !(0.0..90.0).contains(&m.pole_angle_deg) {
            return Err(TwinError::Config {
                field: "magnet.pole_angle_deg".into(),
                reason: format!(
                    "must lie in [0, 90) degrees (cos α > 0), got {}",
                    m.pole_angle_deg
                ),
            });
        }
        positive("magnet.i_sat_a", m.i_sat_a)?;
        let a = &self.amplifier;
        positive("amplifier.bandwidth_hz", a.bandwidth_hz)?;
        positive("amplifier.bus_voltage_v", a.bus_voltage_v)?;
        positive("amplifier.inductance_h", a.inductance_h)?;
        nonneg("amplifier.resistance_ohm", a.resistance_ohm)?;
        let s = &self.sensor;
        positive("sensor.gain_v_per_m", s.gain_v_per_m)?;
        positive("sensor.bandwidth_hz", s.bandwidth_hz)?;
        nonneg("sensor.noise_rms_m", s.noise_rms_m)?;
        positive("sensor.adc_range_v", s.adc_range_v)?;
        if !(2..=32).contains(&s.adc_bits) {
            return Err(TwinError::Config {
                field: "sensor.adc_bits".into(),
                reason: format!("must be between 2 and 32, got {}", s.adc_bits),
            });
        }
        let c = &self.controller;
        positive("controller.fs_hz", c.fs_hz)?;
        positive("controller.kp", c.kp)?;
        nonneg("controller.integral_corner_hz", c.integral_corner_hz)?;
        nonneg("controller.kd", c.kd)?;
        positive("controller.derivative_cutoff_hz", c.derivative_cutoff_hz)?;
        positive("controller.lowpass_hz", c.lowpass_hz)?;
        let o = &self.operating_point;
        positive("operating_point.bias_current_a", o.bias_current_a)?;
        positive("operating_point.air_gap_m", o.air_gap_m)?;
        if !(1..=1000).contains(&self.simulation.exp_substeps) {
            return Err(TwinError::Config {
                field: "simulation.exp_substeps".into(),
                reason: format!(
                    "exponential RK4 needs between 1 and 1000 steps per control period, got {}",
                    self.simulation.exp_substeps
                ),
            });
        }
        if self.simulation.integrator == Integrator::Rk4
            && !(10..=10_000).contains(&self.simulation.substeps)
        {
            return Err(TwinError::Config {
                field: "simulation.substeps".into(),
                reason: format!(
                    "RK4 needs between 10 and 10000 substeps per control period, got {}",
                    self.simulation.substeps
                ),
            });
        }
        if a.bus_voltage_v <= a.resistance_ohm * (o.bias_current_a + m.i_sat_a) {
            return Err(TwinError::Config {
                field: "amplifier.bus_voltage_v".into(),
                reason: format!(
                    "the bus voltage {} V cannot even hold the largest coil current {} A through {} Ω; \
                     raise the bus voltage or lower bias/i_sat",
                    a.bus_voltage_v,
                    o.bias_current_a + m.i_sat_a,
                    a.resistance_ohm
                ),
            });
        }
        Ok(())
    }
}

/// Simulation mode.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Mode {
    /// Linearised force law, linear amplifier and sensor, continuous part integrated exactly (ZOH).
    #[default]
    Linear,
    /// Exact force law, amplifier saturation and slew limit, RK4 with ≥ 10 substeps per period.
    Nonlinear,
}

impl std::str::FromStr for Mode {
    type Err = TwinError;
    fn from_str(s: &str) -> Result<Mode> {
        match s.trim().to_ascii_lowercase().as_str() {
            "linear" => Ok(Mode::Linear),
            "nonlinear" | "non-linear" => Ok(Mode::Nonlinear),
            other => Err(TwinError::InvalidArgument {
                name: "mode",
                reason: format!("unknown mode `{other}`; use `linear` or `nonlinear`"),
            }),
        }
    }
}

impl std::fmt::Display for Mode {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Mode::Linear => "linear",
            Mode::Nonlinear => "nonlinear",
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn toml_roundtrip_and_defaults() {
        let c = TwinConfig::default();
        let s = c.to_toml_string().unwrap();
        let back = TwinConfig::from_toml_str(&s).unwrap();
        assert_eq!(c, back);
        let partial =
            TwinConfig::from_toml_str("[operating_point]\nbias_current_a = 2.4\n").unwrap();
        assert_eq!(partial.operating_point.bias_current_a, 2.4);
        assert_eq!(partial.rotor, RotorConfig::default());
    }

    #[test]
    fn unknown_field_and_bad_values() {
        let e = TwinConfig::from_toml_str("[rotor]\nmas_kg = 5.0\n").unwrap_err();
        assert!(matches!(e, TwinError::Toml(_)), "{e}");
        assert!(e.to_string().contains("mas_kg"), "{e}");
        let e = TwinConfig::from_toml_str("[operating_point]\nair_gap_m = -1e-4\n").unwrap_err();
        assert!(e.to_string().contains("operating_point.air_gap_m"), "{e}");
        let e = TwinConfig::from_toml_str("[simulation]\nsubsteps = 4\n").unwrap_err();
        assert!(e.to_string().contains("substeps"), "{e}");
        let e = TwinConfig::from_toml_str("[rotor\n").unwrap_err();
        assert!(matches!(e, TwinError::Toml(_)));
    }

    #[test]
    fn integrator_settings() {
        let c = TwinConfig::from_toml_str(
            "[simulation]\nintegrator = \"exp_rk4\"\nexp_substeps = 2\nsubsteps = 4\n",
        )
        .unwrap();
        assert_eq!(c.simulation.integrator, Integrator::ExpRk4);
        assert_eq!(c.simulation.steps_per_period(), 2);
        assert_eq!(TwinConfig::default().simulation.integrator, Integrator::Rk4);
        let e =
            TwinConfig::from_toml_str("[simulation]\nintegrator = \"exp_rk4\"\nexp_substeps = 0\n")
                .unwrap_err();
        assert!(e.to_string().contains("exp_substeps"), "{e}");
        assert!(TwinConfig::from_toml_str("[simulation]\nintegrator = \"euler\"\n").is_err());
        assert_eq!("exp-rk4".parse::<Integrator>().unwrap(), Integrator::ExpRk4);
        assert_eq!(Integrator::ExpRk4.to_string(), "exp_rk4");
    }

    #[test]
    fn mode_parse() {
        assert_eq!("Linear".parse::<Mode>().unwrap(), Mode::Linear);
        assert_eq!("nonlinear".parse::<Mode>().unwrap(), Mode::Nonlinear);
        assert!("foo".parse::<Mode>().is_err());
        assert_eq!(Mode::Nonlinear.to_string(), "nonlinear");
    }
}
