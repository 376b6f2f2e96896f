//! The whole rotor: a 4-axis twin with gyroscopic coupling at speed (the [`Machine`]).
//!
//! The single-plane [`Twin`](crate::Twin) models the x–z plane with bearing A identified and loop
//! B closed. The [`Machine`] models **both planes** (x–z and y–z), hence four radial axes in the
//! fixed order [`AXES`] = `xa, xb, ya, yb` (bearing A/B, direction x/y) — the order of the inputs
//! and the outputs of every matrix here. Each axis has its magnet pair, amplifier, sensor,
//! one-sample computation delay and Tustin PID exactly as in the single-plane twin (one
//! controller design for the A axes, one for the B axes).
//!
//! # Rotor and gyroscopics
//! Per plane $p \in \{x, y\}$ the coordinates are $q_p = (z_p, \theta_p, \eta_p)$: translation of
//! the centre of mass, the slope $\theta_p = \partial p/\partial z$ of the rotor axis, and the
//! bending modal coordinate. The displacement at bearing A (axial position $-a$) is
//! $p_A = z_p - a\theta_p + \varphi_A\eta_p$, at B ($+b$) $p_B = z_p + b\theta_p + \varphi_B\eta_p$,
//! as in [`model`](crate::model). The rotor spins at $\Omega$ **about $+z$ by the right-hand rule**
//! (from $+x$ toward $+y$). With the transverse inertia $J_t$ and the polar inertia $J_p$ the
//! angular momentum of the tilted rotor gives (generalised forces $Q$ from virtual work)
//! $$ J_t\ddot\theta_x + \Omega J_p\dot\theta_y = Q_{\theta x}, \qquad
//!    J_t\ddot\theta_y - \Omega J_p\dot\theta_x = Q_{\theta y}. $$
//! In the complex tilt $\vartheta = \theta_x + j\theta_y$ this reads
//! $J_t\ddot\vartheta - j\Omega J_p\dot\vartheta = Q$: a whirl $\vartheta = e^{j\omega t}$ with
//! $\omega > 0$ turns in the sense of rotation (**forward whirl**) and is stiffened by the
//! gyroscopic moment — its frequency rises with speed — while the backward whirl
//! ($\omega < 0$) falls. Translation and bending carry no gyroscopic term (the bending mode is
//! treated as planar; its small gyroscopic part is neglected).
//!
//! The polar inertia defaults to a solid cylinder of the rotor's mass $m$ and length $L$:
//! $J_p = m r^2/2$ with the radius [`MachineConfig::rotor_radius_m`] or, when absent, the radius of
//! a steel cylinder ($\rho = 7850$ kg/m³) of that mass and length, $r = \sqrt{m/(\pi\rho L)}$. At the
//! nominal rig ($m = 5$ kg, $L = 0.5$ m): $r = 20.14$ mm, $J_p = 1.014\cdot10^{-3}$ kg·m²
//! (against $J_t = mL^2/12 = 0.1042$ kg·m²).
//!
//! # Unbalance
//! An unbalance mass $m_u$ at eccentricity $e$, axial position $z_u$ (from the centre of mass,
//! bearing B side positive) and phase $\varphi_u$ rotates with the rotor and exerts the force
//! $$ F_x + jF_y = m_u e\,\Omega^2\, e^{j(\Omega t + \varphi_u)} $$
//! at $z_u$ (generalised force $(1, z_u, 0)^\top F$ in each plane; the bending mode is not
//! excited by it). The simulation propagates it exactly: the force is the output of the
//! oscillator $\dot c = -\Omega s$, $\dot s = \Omega c$ appended to the continuous model before
//! the ZOH discretisation.
//!
//! # Asymmetry
//! [`AsymmetryConfig`] scales $k_i$ and $k_x$ of the two y magnets by $(1 + \delta_i)$ and
//! $(1 + \delta_x)$, and those of the two bearing-B magnets by $(1 + \delta_{i,B})$ and
//! $(1 + \delta_{x,B})$ (the factors multiply at `yb`), in the linear model (truth and linear
//! simulation); the controllers are not retuned. The nonlinear simulation realises both
//! factors $f_i$, $f_x$ of a magnet through its force constant and air gap: since
//! $k_i = 4k i_0/g_0^2$ and $k_x = 4k i_0^2/g_0^3$, the gap $g_0 f_i/f_x$ and the force constant
//! $k f_i (f_i/f_x)^2$ give exactly $f_i k_i$ and $f_x k_x$ at the bias current, so its
//! linearisation is the linear model's.
//!
//! # Discrete model and truth
//! The 20-state continuous model $\xi = (q_x, q_y, \dot q_x, \dot q_y, i, y_s)$ (currents and sensor
//! states in axis order) is discretised exactly (ZOH). The **plant** $P$ (24 states) adds the four
//! delay registers $d^+ = u$: recorded $u$ → recorded $y$, all four loops open (unstable). The
//! controller $C = \operatorname{diag}(C_A, C_B, C_A, C_B)$ is the Tustin PID of each axis
//! (12 states). With $u = C(w - y) + r$ the closed loop (36 states, inputs $(r, w)$, outputs
//! $(y, u)$) gives
//! $$ T_{ry} = (I + PC)^{-1}P, \qquad S = T_{ru} = (I + CP)^{-1}, \qquad P = T_{ry}S^{-1}. $$
//! The speed is a parameter of the model: build one [`Machine`] per speed (see [`campbell`]).
//!
//! # Whirl direction of a mode
//! For a closed-loop eigenvalue $z$ (upper half plane) with eigenvector $v$, the rotor
//! displacements at bearing $B \in \{A, B\}$ move as $x_B = \operatorname{Re}(v_{xB} z^k)$,
//! $y_B = \operatorname{Re}(v_{yB} z^k)$, so the orbit $x_B + jy_B = a_f\,z^k + a_b\,\bar z^k$ with
//! the forward and backward circular parts $a_f = (v_{xB} + jv_{yB})/2$ and
//! $a_b = \overline{(v_{xB} - jv_{yB})}/2$. The mode is [`Whirl::Forward`] when
//! $\sum_B |a_f|^2 > \sum_B |a_b|^2$ (both bearings), [`Whirl::Backward`] when less, and
//! [`Whirl::None`] at $\Omega = 0$ (the modes are planar; a symmetric rotor has every mode twice
//! and any combination of the two planes is an eigenvector) or when the two parts are equal to
//! 1e-9.
//!
//! # Example
//! ```
//! use ambid_twin::{Machine, MachineConfig};
//! let cfg = MachineConfig { speed_rpm: 20_000.0, ..Default::default() };
//! let m = Machine::new(cfg).unwrap();
//! let p = m.plant_frf(&[150.0]).unwrap();
//! assert_eq!((p.ny(), p.nu()), (4, 4));
//! // at speed the x–y cross terms are no longer zero
//! assert!(p.at(0).unwrap()[(2, 0)].norm() > 0.0);
//! let s = m.sensitivity_frf(&[150.0]).unwrap();
//! assert!(s.at(0).unwrap()[(0, 0)].norm() > 0.1);
//! ```

use crate::config::{
    AmplifierConfig, ControllerConfig, MagnetConfig, OperatingPoint, RotorConfig, SensorConfig,
    SimulationConfig, TwinConfig,
};
use crate::error::{Result, TwinError};
use crate::model::{Physics, Pid};
use crate::twin::{z_to_s, LIGHTLY_DAMPED};
use ambid_core::lti::{Frd, StateSpace};
use faer::{c64, Mat};
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

/// The four radial axes in the order of every input and output: bearing A x, bearing B x,
/// bearing A y, bearing B y.
pub const AXES: [&str; 4] = ["xa", "xb", "ya", "yb"];

/// Density used to derive the default rotor radius (steel) \[kg/m³\].
pub const STEEL_DENSITY: f64 = 7850.0;

/// Number of states of the continuous 4-axis model.
pub(crate) const NX4: usize = 20;
/// Index of the first current state (axis order).
pub(crate) const I_CUR: usize = 12;
/// Index of the first sensor state (axis order).
pub(crate) const I_SEN: usize = 16;

/// An unbalance: a rotating force $m_u e \Omega^2$ at 1× the rotation frequency.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct UnbalanceConfig {
    /// Unbalance mass $m_u$ \[kg\].
    pub mass_kg: f64,
    /// Its eccentricity (radius) $e$ \[m\].
    pub eccentricity_m: f64,
    /// Axial position $z_u$ from the centre of mass, bearing B side positive \[m\].
    pub axial_position_m: f64,
    /// Phase $\varphi_u$ of the force at $t = 0$, from $+x$ toward $+y$ \[deg\].
    pub phase_deg: f64,
}

impl Default for UnbalanceConfig {
    /// 1 g at 1 mm ($m_u e = 10^{-6}$ kg·m), at the centre of mass, phase 0.
    fn default() -> Self {
        Self {
            mass_kg: 1e-3,
            eccentricity_m: 1e-3,
            axial_position_m: 0.0,
            phase_deg: 0.0,
        }
    }
}

/// A small asymmetry of the magnets: relative changes of $k_i$ and $k_x$ of the y magnets
/// (x/y asymmetry) and of the bearing-B magnets (A/B asymmetry, both planes). They multiply:
/// the magnet at `yb` has $k_i (1 + \delta_i)(1 + \delta_{i,B})$.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct AsymmetryConfig {
    /// $\delta_i$: $k_{i,y} = (1 + \delta_i) k_i$ (dimensionless, $|\delta_i| < 0.5$).
    pub ki_rel: f64,
    /// $\delta_x$: $k_{x,y} = (1 + \delta_x) k_x$ (dimensionless, $|\delta_x| < 0.5$).
    pub kx_rel: f64,
    /// $\delta_{i,B}$: $k_{i,B} = (1 + \delta_{i,B}) k_i$ at bearing B (both planes;
    /// dimensionless, $|\delta_{i,B}| < 0.5$; default 0).
    pub ki_rel_b: f64,
    /// $\delta_{x,B}$: $k_{x,B} = (1 + \delta_{x,B}) k_x$ at bearing B (default 0).
    pub kx_rel_b: f64,
}

impl AsymmetryConfig {
    /// The factors $(1 + \delta)$ of $k_i$ and $k_x$ of each axis, in the order [`AXES`].
    pub fn factors(&self) -> ([f64; 4], [f64; 4]) {
        let f = |d_y: f64, d_b: f64| {
            std::array::from_fn(|a| {
                let (plane, bearing) = (a / 2, a % 2);
                (1.0 + if plane == 1 { d_y } else { 0.0 })
                    * (1.0 + if bearing == 1 { d_b } else { 0.0 })
            })
        };
        (f(self.ki_rel, self.ki_rel_b), f(self.kx_rel, self.kx_rel_b))
    }
}

/// Configuration of the 4-axis machine. Every field is optional in TOML (defaults: the nominal
/// single-plane rig in both planes, standstill, no unbalance, no asymmetry); unknown fields are
/// errors.
///
/// ```
/// use ambid_twin::MachineConfig;
/// let cfg = MachineConfig::from_toml_str(
///     "speed_rpm = 30000.0\n[unbalance]\nmass_kg = 2e-3\n[asymmetry]\nki_rel = 0.02\n",
/// ).unwrap();
/// assert_eq!(cfg.speed_rpm, 30000.0);
/// assert!((cfg.polar_inertia() - 1.0137e-3).abs() < 1e-6);
/// ```
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct MachineConfig {
    /// Rotor (same in both planes).
    pub rotor: RotorConfig,
    /// Magnets (the y magnets modified by `asymmetry`).
    pub magnet: MagnetConfig,
    /// Amplifiers (all four).
    pub amplifier: AmplifierConfig,
    /// Sensors (all four; independent noise streams).
    pub sensor: SensorConfig,
    /// Controller of the A axes (`xa`, `ya`).
    pub controller_a: ControllerConfig,
    /// Controller of the B axes (`xb`, `yb`); its `fs_hz` must equal `controller_a.fs_hz`.
    pub controller_b: ControllerConfig,
    /// Operating point (all four magnets).
    pub operating_point: OperatingPoint,
    /// Simulation settings (nonlinear mode).
    pub simulation: SimulationConfig,
    /// Rotor speed \[rpm\], ≥ 0, rotation about $+z$ (default 0).
    pub speed_rpm: f64,
    /// Polar inertia $J_p$ \[kg·m²\]; default: solid cylinder, see [`MachineConfig::polar_inertia`].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub polar_inertia_kgm2: Option<f64>,
    /// Rotor radius \[m\] for the default polar inertia; default $\sqrt{m/(\pi\rho L)}$, steel.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rotor_radius_m: Option<f64>,
    /// Optional unbalance (none by default).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub unbalance: Option<UnbalanceConfig>,
    /// Optional x/y asymmetry of the magnets (none by default).
    pub asymmetry: AsymmetryConfig,
}

fn cfg_err(field: &str, reason: String) -> TwinError {
    TwinError::Config {
        field: field.into(),
        reason,
    }
}

impl MachineConfig {
    /// The machine whose both planes are the single-plane rig `cfg` (both controllers =
    /// `cfg.controller`), at standstill, without unbalance or asymmetry.
    pub fn from_twin(cfg: &TwinConfig) -> MachineConfig {
        MachineConfig {
            rotor: cfg.rotor.clone(),
            magnet: cfg.magnet.clone(),
            amplifier: cfg.amplifier.clone(),
            sensor: cfg.sensor.clone(),
            controller_a: cfg.controller.clone(),
            controller_b: cfg.controller.clone(),
            operating_point: cfg.operating_point.clone(),
            simulation: cfg.simulation.clone(),
            ..Default::default()
        }
    }

    /// Parses TOML and validates.
    pub fn from_toml_str(s: &str) -> Result<MachineConfig> {
        let cfg: MachineConfig = toml::from_str(s).map_err(|e| TwinError::Toml(e.to_string()))?;
        cfg.validate()?;
        Ok(cfg)
    }

    /// Writes TOML.
    pub fn to_toml_string(&self) -> Result<String> {
        toml::to_string(self).map_err(|e| TwinError::TomlWrite(e.to_string()))
    }

    /// The single-plane configuration of one plane with controller `ctl` (x plane: as given; the
    /// asymmetry is applied separately to the y plane's physics).
    pub(crate) fn plane(&self, ctl: &ControllerConfig) -> TwinConfig {
        TwinConfig {
            rotor: self.rotor.clone(),
            magnet: self.magnet.clone(),
            amplifier: self.amplifier.clone(),
            sensor: self.sensor.clone(),
            controller: ctl.clone(),
            operating_point: self.operating_point.clone(),
            simulation: self.simulation.clone(),
        }
    }

    /// Rotor radius \[m\]: `rotor_radius_m`, or $\sqrt{m/(\pi\rho L)}$ with $\rho$ = [`STEEL_DENSITY`].
    pub fn rotor_radius(&self) -> f64 {
        self.rotor_radius_m.unwrap_or_else(|| {
            (self.rotor.mass_kg / (PI * STEEL_DENSITY * self.rotor.length_m)).sqrt()
        })
    }

    /// Polar inertia $J_p$ \[kg·m²\]: `polar_inertia_kgm2`, or $m r^2/2$ with
    /// $r$ = [`MachineConfig::rotor_radius`] (nominal: $1.0137\cdot10^{-3}$ kg·m²).
    pub fn polar_inertia(&self) -> f64 {
        self.polar_inertia_kgm2.unwrap_or_else(|| {
            let r = self.rotor_radius();
            0.5 * self.rotor.mass_kg * r * r
        })
    }

    /// Rotor speed $\Omega$ \[rad/s\].
    pub fn omega(&self) -> f64 {
        self.speed_rpm * 2.0 * PI / 60.0
    }

    /// Validates every field: the single-plane checks for both controllers, then the speed,
    /// inertias, unbalance and asymmetry. Errors name the field and what to change.
    pub fn validate(&self) -> Result<()> {
        self.plane(&self.controller_a).validate()?;
        self.plane(&self.controller_b)
            .validate()
            .map_err(|e| match e {
                TwinError::Config { field, reason } => {
                    cfg_err(&field.replace("controller.", "controller_b."), reason)
                }
                other => other,
            })?;
        if self.controller_a.fs_hz != self.controller_b.fs_hz {
            return Err(cfg_err(
                "controller_b.fs_hz",
                format!(
                    "all four controllers run on one clock: controller_b.fs_hz = {} Hz differs from \
                     controller_a.fs_hz = {} Hz; set both to the same sampling frequency",
                    self.controller_b.fs_hz, self.controller_a.fs_hz
                ),
            ));
        }
        if !(self.speed_rpm.is_finite() && self.speed_rpm >= 0.0) {
            return Err(cfg_err(
                "speed_rpm",
                format!(
                    "must be finite and ≥ 0 (rotation about +z; a negative speed is the same machine \
                     mirrored), got {}",
                    self.speed_rpm
                ),
            ));
        }
        if let Some(j) = self.polar_inertia_kgm2 {
            if !(j.is_finite() && j > 0.0) {
                return Err(cfg_err(
                    "polar_inertia_kgm2",
                    format!("must be positive and finite, got {j}; omit it for the solid-cylinder default"),
                ));
            }
        }
        if let Some(r) = self.rotor_radius_m {
            if !(r.is_finite() && r > 0.0) {
                return Err(cfg_err(
                    "rotor_radius_m",
                    format!("must be positive and finite, got {r}"),
                ));
            }
        }
        if let Some(u) = &self.unbalance {
            for (f, v) in [
                ("unbalance.mass_kg", u.mass_kg),
                ("unbalance.eccentricity_m", u.eccentricity_m),
            ] {
                if !(v.is_finite() && v >= 0.0) {
                    return Err(cfg_err(
                        f,
                        format!("must be non-negative and finite, got {v}"),
                    ));
                }
            }
            for (f, v) in [
                ("unbalance.axial_position_m", u.axial_position_m),
                ("unbalance.phase_deg", u.phase_deg),
            ] {
                if !v.is_finite() {
                    return Err(cfg_err(f, format!("must be finite, got {v}")));
                }
            }
        }
        for (f, v) in [
            ("asymmetry.ki_rel", self.asymmetry.ki_rel),
            ("asymmetry.kx_rel", self.asymmetry.kx_rel),
            ("asymmetry.ki_rel_b", self.asymmetry.ki_rel_b),
            ("asymmetry.kx_rel_b", self.asymmetry.kx_rel_b),
        ] {
            if !(v.is_finite() && v.abs() < 0.5) {
                return Err(cfg_err(
                    f,
                    format!("must be a small relative change, |δ| < 0.5, got {v}"),
                ));
            }
        }
        Ok(())
    }
}

/// Whirl direction of a closed-loop mode (see the [module documentation](self)).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Whirl {
    /// The orbit turns with the rotation (from $+x$ toward $+y$).
    Forward,
    /// The orbit turns against the rotation.
    Backward,
    /// Planar (standstill) or undecided.
    None,
}

/// A closed-loop pole pair of the machine with its whirl direction.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct MachineMode {
    /// Natural frequency $|s|/2\pi$ \[Hz\], $s = \ln z/T_s$.
    pub freq_hz: f64,
    /// Damped frequency $\operatorname{Im}(s)/2\pi$ \[Hz\].
    pub damped_freq_hz: f64,
    /// Damping ratio $-\operatorname{Re}(s)/|s|$.
    pub damping: f64,
    /// Forward share of the orbit energy at the bearings, $\sum|a_f|^2/\sum(|a_f|^2+|a_b|^2)$.
    pub forward_fraction: f64,
    /// Whirl direction.
    pub whirl: Whirl,
    /// The discrete pole (upper half plane); serialised as `[re, im]`.
    #[serde(serialize_with = "ser_c64")]
    pub z: c64,
}

fn ser_c64<S: serde::Serializer>(z: &c64, s: S) -> std::result::Result<S::Ok, S::Error> {
    [z.re, z.im].serialize(s)
}

/// The physics of the two planes and the gyroscopic constant, shared by truth and simulation.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Physics4 {
    /// x plane, y plane (the y plane with the x/y-asymmetric magnets).
    pub pl: [Physics; 2],
    /// $k_i$ of each axis (order [`AXES`], every asymmetry applied) \[N/A\].
    pub ki: [f64; 4],
    /// $k_x$ of each axis \[N/m\].
    pub kx: [f64; 4],
    /// The factor of each axis' magnet force constant $k$ (nonlinear simulation).
    pub k_scale: [f64; 4],
    /// The factor of each axis' magnet air gap $g_0$ (nonlinear simulation).
    pub g_scale: [f64; 4],
    /// $J_p/J_t$.
    pub jp_over_jt: f64,
    pub omega: f64,
    /// Unbalance: $(F_0 = m_u e\Omega^2, z_u, \varphi_u)$.
    pub unb: Option<(f64, f64, f64)>,
}

impl Physics4 {
    pub fn new(cfg: &MachineConfig) -> Physics4 {
        let px = Physics::new(&cfg.plane(&cfg.controller_a));
        let mut py = px;
        py.ki *= 1.0 + cfg.asymmetry.ki_rel;
        py.kx *= 1.0 + cfg.asymmetry.kx_rel;
        let (fi, fx) = cfg.asymmetry.factors();
        let omega = cfg.omega();
        let unb = cfg.unbalance.as_ref().map(|u| {
            (
                u.mass_kg * u.eccentricity_m * omega * omega,
                u.axial_position_m,
                u.phase_deg.to_radians(),
            )
        });
        Physics4 {
            pl: [px, py],
            ki: fi.map(|f| f * px.ki),
            kx: fx.map(|f| f * px.kx),
            // k_i = 4k i0/g0², k_x = 4k i0²/g0³: the gap g0 f_i/f_x and the force constant
            // k f_i (f_i/f_x)² give the factors f_i and f_x exactly
            k_scale: std::array::from_fn(|a| fi[a] * (fi[a] / fx[a]).powi(2)),
            g_scale: std::array::from_fn(|a| fi[a] / fx[a]),
            jp_over_jt: cfg.polar_inertia() / px.j,
            omega,
            unb,
        }
    }

    /// The continuous model, 20 states (plus 2 oscillator states when `with_unbalance`), inputs
    /// the four current references, outputs the four sensor states.
    pub fn continuous_model(&self, with_unbalance: bool) -> Result<StateSpace> {
        let n = NX4 + if with_unbalance { 2 } else { 0 };
        let mut a = Mat::<f64>::zeros(n, n);
        let mut b = Mat::<f64>::zeros(n, 4);
        for (p, ph) in self.pl.iter().enumerate() {
            let (ca, cb) = (ph.c_a(), ph.c_b());
            let minv = [1.0 / ph.m, 1.0 / ph.j, 1.0];
            let (q0, v0) = (3 * p, 6 + 3 * p);
            let (ia, ib) = (I_CUR + 2 * p, I_CUR + 2 * p + 1);
            let (sa, sb) = (I_SEN + 2 * p, I_SEN + 2 * p + 1);
            let (ki, kx) = (&self.ki[2 * p..2 * p + 2], &self.kx[2 * p..2 * p + 2]);
            for r in 0..3 {
                a[(q0 + r, v0 + r)] = 1.0;
                for c in 0..3 {
                    a[(v0 + r, q0 + c)] = minv[r] * (kx[0] * ca[r] * ca[c] + kx[1] * cb[r] * cb[c]);
                }
                a[(v0 + r, ia)] = minv[r] * ca[r] * ki[0];
                a[(v0 + r, ib)] = minv[r] * cb[r] * ki[1];
                a[(sa, q0 + r)] = ph.ws * ca[r];
                a[(sb, q0 + r)] = ph.ws * cb[r];
            }
            a[(v0 + 2, q0 + 2)] -= ph.wb * ph.wb;
            a[(v0 + 2, v0 + 2)] -= 2.0 * ph.zb * ph.wb;
            for (i, s) in [(ia, sa), (ib, sb)] {
                a[(i, i)] = -ph.wa;
                b[(i, i - I_CUR)] = ph.wa;
                a[(s, s)] = -ph.ws;
            }
        }
        // gyroscopics: θ̈_x = … − Ω J_p/J_t θ̇_y,  θ̈_y = … + Ω J_p/J_t θ̇_x
        let g = self.omega * self.jp_over_jt;
        a[(7, 10)] = -g;
        a[(10, 7)] = g;
        if with_unbalance {
            let (f0, zu, _) = self.unb.unwrap_or((0.0, 0.0, 0.0));
            let (ic, is) = (NX4, NX4 + 1);
            a[(ic, is)] = -self.omega;
            a[(is, ic)] = self.omega;
            for (p, ph) in self.pl.iter().enumerate() {
                let col = if p == 0 { ic } else { is };
                a[(6 + 3 * p, col)] = f0 / ph.m;
                a[(6 + 3 * p + 1, col)] = f0 * zu / ph.j;
            }
        }
        let mut c = Mat::<f64>::zeros(4, n);
        for k in 0..4 {
            c[(k, I_SEN + k)] = 1.0;
        }
        Ok(StateSpace::continuous(a, b, c, Mat::zeros(4, 4))?)
    }
}

/// The 4-axis machine: configuration, exact linearised discrete-time truth and (see
/// [`Machine::simulate`]) the closed-loop simulation. See the [module documentation](self).
///
/// ```
/// use ambid_twin::{Machine, MachineConfig, UnbalanceConfig, Whirl};
/// let m = Machine::new(MachineConfig {
///     speed_rpm: 30_000.0,
///     unbalance: Some(UnbalanceConfig::default()),
///     ..Default::default()
/// })
/// .unwrap();
/// // six lightly damped modes: translation, tilt and bending, each as a forward/backward pair
/// let modes = m.closed_loop_modes().unwrap();
/// assert_eq!(modes.len(), 6);
/// assert!(modes.iter().any(|md| md.whirl == Whirl::Forward));
/// // axis xa with the three other loops closed: one unstable pole
/// let pa = m.axis_plant(0).unwrap();
/// assert_eq!(pa.poles().unwrap().iter().filter(|z| z.norm() > 1.0).count(), 1);
/// // per-axis peak sensitivity and the 1× response to the unbalance
/// let peaks = m.peak_sensitivity().unwrap();
/// assert!(peaks.iter().all(|&(_, s)| s > 1.0 && s < 4.0));
/// let y1x = m.unbalance_response().unwrap();
/// assert!(y1x[0].norm() > 0.0);
/// ```
#[derive(Debug, Clone)]
pub struct Machine {
    pub(crate) cfg: MachineConfig,
    pub(crate) ph: Physics4,
    /// PIDs in axis order (A, B, A, B).
    pub(crate) pids: [Pid; 4],
    pub(crate) ts: f64,
    continuous: StateSpace,
    /// Discrete model without the unbalance oscillator (20 states).
    pub(crate) discrete: StateSpace,
    /// Discrete model with the unbalance oscillator (22 states), when configured.
    pub(crate) discrete_unb: Option<StateSpace>,
    controller: StateSpace,
    plant: StateSpace,
    closed: StateSpace,
}

/// Plant and controller matrices per line.
type PerLine2 = (Vec<Mat<c64>>, Vec<Mat<c64>>);

/// The block-diagonal controller $\operatorname{diag}(C_A, C_B, C_A, C_B)$ as one discrete model.
fn block_diag_controller(pids: &[Pid; 4], ts: f64) -> Result<StateSpace> {
    controller_without(pids, None, ts)
}

/// The block-diagonal controller with axis `skip` (if any) removed: no states, zero gain.
fn controller_without(pids: &[Pid; 4], skip: Option<usize>, ts: f64) -> Result<StateSpace> {
    let axes: Vec<usize> = (0..4).filter(|&k| Some(k) != skip).collect();
    let n = 3 * axes.len();
    let mut a = Mat::<f64>::zeros(n, n);
    let mut b = Mat::<f64>::zeros(n, 4);
    let mut c = Mat::<f64>::zeros(4, n);
    let mut d = Mat::<f64>::zeros(4, 4);
    for (slot, &k) in axes.iter().enumerate() {
        let (ac, bc, cc, dc) = pids[k].matrices();
        let o = 3 * slot;
        for i in 0..3 {
            for j in 0..3 {
                a[(o + i, o + j)] = ac[i][j];
            }
            b[(o + i, k)] = bc[i];
            c[(k, o + i)] = cc[i];
        }
        d[(k, k)] = dc;
    }
    Ok(StateSpace::discrete(a, b, c, d, ts)?)
}

impl Machine {
    /// Builds the machine at the configured speed: validates, linearises, discretises (ZOH),
    /// assembles plant, controller and closed loop, and checks closed-loop stability.
    ///
    /// Errors: [`TwinError::Config`] for a bad configuration, [`TwinError::UnstableClosedLoop`]
    /// when the linearised closed loop is not asymptotically stable at this speed.
    pub fn new(cfg: MachineConfig) -> Result<Machine> {
        cfg.validate()?;
        let ph = Physics4::new(&cfg);
        let pa = Pid::new(&cfg.plane(&cfg.controller_a));
        let pb = Pid::new(&cfg.plane(&cfg.controller_b));
        let pids = [pa, pb, pa, pb];
        let ts = ph.pl[0].ts;
        let continuous = ph.continuous_model(false)?;
        let discrete = continuous.c2d_zoh(ts)?;
        let discrete_unb = if cfg.unbalance.is_some() {
            Some(ph.continuous_model(true)?.c2d_zoh(ts)?)
        } else {
            None
        };
        let controller = block_diag_controller(&pids, ts)?;
        // plant: (ξ, d), d⁺ = u, y = y_s
        let np = NX4 + 4;
        let mut ap = Mat::<f64>::zeros(np, np);
        let mut bp = Mat::<f64>::zeros(np, 4);
        let mut cp = Mat::<f64>::zeros(4, np);
        for i in 0..NX4 {
            for j in 0..NX4 {
                ap[(i, j)] = discrete.a()[(i, j)];
            }
            for k in 0..4 {
                ap[(i, NX4 + k)] = discrete.b()[(i, k)];
            }
        }
        for k in 0..4 {
            bp[(NX4 + k, k)] = 1.0;
            cp[(k, I_SEN + k)] = 1.0;
        }
        let plant = StateSpace::discrete(ap, bp, cp, Mat::zeros(4, 4), ts)?;
        let closed = close_loops(&plant, &controller, ts)?;
        let m = Machine {
            cfg,
            ph,
            pids,
            ts,
            continuous,
            discrete,
            discrete_unb,
            controller,
            plant,
            closed,
        };
        let poles = m.closed.poles()?;
        let worst = poles
            .iter()
            .copied()
            .max_by(|a, b| a.norm().total_cmp(&b.norm()))
            .unwrap_or(c64::new(0.0, 0.0));
        if worst.norm() >= 1.0 {
            let s = z_to_s(if worst.im < 0.0 { worst.conj() } else { worst }, ts);
            return Err(TwinError::UnstableClosedLoop {
                max_pole_magnitude: worst.norm(),
                s_re: s.re,
                s_im: s.im,
                hint: format!(
                    "the four decentralised loops do not stabilise the rotor at {} rpm; lower the speed, \
                     check the controllers (controller_a, controller_b) or the asymmetry",
                    m.cfg.speed_rpm
                ),
            });
        }
        Ok(m)
    }

    /// The configuration.
    pub fn config(&self) -> &MachineConfig {
        &self.cfg
    }

    /// Sample time $T_s$ \[s\].
    pub fn ts(&self) -> f64 {
        self.ts
    }

    /// Sampling frequency \[Hz\].
    pub fn fs(&self) -> f64 {
        1.0 / self.ts
    }

    /// Rotor speed $\Omega$ \[rad/s\].
    pub fn omega(&self) -> f64 {
        self.ph.omega
    }

    /// Synchronous (1×) frequency $\Omega/2\pi$ \[Hz\].
    pub fn sync_hz(&self) -> f64 {
        self.ph.omega / (2.0 * PI)
    }

    /// Control-current saturation $i_\mathrm{sat}$ \[A\] (all axes).
    pub fn i_sat(&self) -> f64 {
        self.ph.pl[0].i_sat
    }

    /// The linearised magnets of the four axes (order [`AXES`], every asymmetry applied):
    /// $(k_i, k_x)$ \[N/A\], \[N/m\].
    ///
    /// ```
    /// use ambid_twin::{AsymmetryConfig, Machine, MachineConfig};
    /// let asymmetry = AsymmetryConfig { ki_rel_b: 0.1, ..Default::default() };
    /// let m = Machine::new(MachineConfig { asymmetry, ..Default::default() }).unwrap();
    /// let (ki, kx) = m.axis_magnets();
    /// assert!((ki[1] / ki[0] - 1.1).abs() < 1e-12 && ki[3] == ki[1] && kx[1] == kx[0]);
    /// ```
    pub fn axis_magnets(&self) -> ([f64; 4], [f64; 4]) {
        (self.ph.ki, self.ph.kx)
    }

    /// The 20-state continuous model: inputs the four current references, outputs the four
    /// sensor states (axis order).
    pub fn continuous_model(&self) -> &StateSpace {
        &self.continuous
    }

    /// Its exact ZOH discretisation.
    pub fn discrete_model(&self) -> &StateSpace {
        &self.discrete
    }

    /// The discrete plant $P$ (24 states, 4×4): recorded $u$ → recorded $y$, all loops open,
    /// including the computation delays (unstable).
    pub fn plant(&self) -> &StateSpace {
        &self.plant
    }

    /// The discrete controller $C = \operatorname{diag}(C_A, C_B, C_A, C_B)$ (12 states):
    /// $w - y \to u$ (no delay, no clamp).
    pub fn controller(&self) -> &StateSpace {
        &self.controller
    }

    /// The discrete closed loop (36 states): inputs $(r, w)$ (8), outputs $(y, u)$ (8), each in
    /// axis order.
    pub fn closed_loop(&self) -> &StateSpace {
        &self.closed
    }

    /// Exact $P(e^{j2\pi fT_s})$, 4×4 per line.
    pub fn plant_frf(&self, f_hz: &[f64]) -> Result<Frd> {
        let p = self.plant_mats(f_hz)?;
        Ok(Frd::from_matrices(f_hz, &p, None, Some(self.ts))?)
    }

    /// Exact $C(e^{j2\pi fT_s})$, diagonal 4×4 per line.
    pub fn controller_frf(&self, f_hz: &[f64]) -> Result<Frd> {
        let c = self.controller_mats(f_hz)?;
        Ok(Frd::from_matrices(f_hz, &c, None, Some(self.ts))?)
    }

    fn pc(&self, f_hz: &[f64]) -> Result<PerLine2> {
        Ok((self.plant_mats(f_hz)?, self.controller_mats(f_hz)?))
    }

    /// $P(z) = z^{-1} C_s (zI - A_d)^{-1} B_d$ per line by a dense complex LU (row operations
    /// never mix decoupled blocks, so a decoupled machine gives exactly zero cross terms).
    fn plant_mats(&self, f_hz: &[f64]) -> Result<Vec<Mat<c64>>> {
        use faer::linalg::solvers::Solve;
        check_freqs(f_hz)?;
        let (a, b) = (self.discrete.a(), self.discrete.b());
        let rhs = Mat::<c64>::from_fn(NX4, 4, |i, j| c64::new(b[(i, j)], 0.0));
        f_hz.iter()
            .map(|&f| {
                let z = c64::from_polar(1.0, 2.0 * PI * f * self.ts);
                let m = Mat::<c64>::from_fn(NX4, NX4, |i, j| {
                    let v = c64::new(-a[(i, j)], 0.0);
                    if i == j {
                        v + z
                    } else {
                        v
                    }
                });
                let lu = m.partial_piv_lu();
                let mut x = lu.solve(&rhs);
                // one step of iterative refinement
                let res = &rhs - &m * &x;
                x += lu.solve(&res);
                let zi = z.inv();
                let out = Mat::from_fn(4, 4, |i, j| x[(I_SEN + i, j)] * zi);
                if out
                    .col_iter()
                    .all(|c| c.iter().all(|v| v.re.is_finite() && v.im.is_finite()))
                {
                    Ok(out)
                } else {
                    Err(TwinError::InvalidArgument {
                        name: "f_hz",
                        reason: format!(
                            "{f} Hz coincides with a pole of the plant; choose other frequencies"
                        ),
                    })
                }
            })
            .collect()
    }

    /// $C = \operatorname{diag}(C_A, C_B, C_A, C_B)$ per line, exactly diagonal.
    fn controller_mats(&self, f_hz: &[f64]) -> Result<Vec<Mat<c64>>> {
        check_freqs(f_hz)?;
        let ca = self.pids[0]
            .state_space(self.ts)?
            .freq_response_siso(f_hz)?;
        let cb = self.pids[1]
            .state_space(self.ts)?
            .freq_response_siso(f_hz)?;
        Ok(ca
            .iter()
            .zip(&cb)
            .map(|(&a, &b)| {
                let d = [a, b, a, b];
                Mat::from_fn(4, 4, |i, j| if i == j { d[i] } else { c64::new(0.0, 0.0) })
            })
            .collect())
    }

    /// Exact $T_{ry} = (I + PC)^{-1}P$ ($r \to y$), 4×4 per line.
    pub fn t_ry_frf(&self, f_hz: &[f64]) -> Result<Frd> {
        let (p, c) = self.pc(f_hz)?;
        let v = p
            .iter()
            .zip(&c)
            .map(|(p, c)| solve(&(identity(4) + p * c), p))
            .collect::<Result<Vec<_>>>()?;
        Ok(Frd::from_matrices(f_hz, &v, None, Some(self.ts))?)
    }

    /// Exact $S = T_{ru} = (I + CP)^{-1}$ ($r \to u$), 4×4 per line.
    pub fn sensitivity_frf(&self, f_hz: &[f64]) -> Result<Frd> {
        let (p, c) = self.pc(f_hz)?;
        let v = p
            .iter()
            .zip(&c)
            .map(|(p, c)| solve(&(identity(4) + c * p), &identity(4)))
            .collect::<Result<Vec<_>>>()?;
        Ok(Frd::from_matrices(f_hz, &v, None, Some(self.ts))?)
    }

    /// The plant of axis `axis` (index into [`AXES`]) with the other three loops closed by their
    /// controllers (SISO, $u_i \to y_i$):
    /// $P_i = P_{ii} - P_{io}C_o(I + P_{oo}C_o)^{-1}P_{oi}$, $o$ the other three axes.
    pub fn axis_plant_frf(&self, axis: usize, f_hz: &[f64]) -> Result<Frd> {
        if axis >= 4 {
            return Err(TwinError::InvalidArgument {
                name: "axis",
                reason: format!("axis index {axis} out of range; use 0..4 for xa, xb, ya, yb"),
            });
        }
        let (p, c) = self.pc(f_hz)?;
        let o: Vec<usize> = (0..4).filter(|&k| k != axis).collect();
        let v = p
            .iter()
            .zip(&c)
            .map(|(p, c)| {
                let poo = Mat::from_fn(3, 3, |i, j| p[(o[i], o[j])]);
                let co = Mat::from_fn(3, 3, |i, j| c[(o[i], o[j])]);
                let poi = Mat::from_fn(3, 1, |i, _| p[(o[i], axis)]);
                let pio = Mat::from_fn(1, 3, |_, j| p[(axis, o[j])]);
                let x = solve(&(identity(3) + &poo * &co), &poi)?;
                let corr = &pio * &co * &x;
                Ok(Mat::from_fn(1, 1, |_, _| p[(axis, axis)] - corr[(0, 0)]))
            })
            .collect::<Result<Vec<_>>>()?;
        Ok(Frd::from_matrices(f_hz, &v, None, Some(self.ts))?)
    }

    /// The plant of axis `axis` with the other three loops closed, as a discrete SISO model
    /// (24 + 9 states; $u_i \to y_i$): the closed loop with controller $i$ removed, from $r_i$ to
    /// $y_i$. Its frequency response is [`Machine::axis_plant_frf`]; at standstill it is the
    /// single-plane twin's plant with one unstable pole.
    pub fn axis_plant(&self, axis: usize) -> Result<StateSpace> {
        if axis >= 4 {
            return Err(TwinError::InvalidArgument {
                name: "axis",
                reason: format!("axis index {axis} out of range; use 0..4 for xa, xb, ya, yb"),
            });
        }
        let ctl = controller_without(&self.pids, Some(axis), self.ts)?;
        let cl = close_loops(&self.plant, &ctl, self.ts)?;
        let n = cl.order();
        let b = Mat::from_fn(n, 1, |i, _| cl.b()[(i, axis)]);
        let c = Mat::from_fn(1, n, |_, j| cl.c()[(axis, j)]);
        Ok(StateSpace::discrete(
            cl.a().to_owned(),
            b,
            c,
            Mat::zeros(1, 1),
            self.ts,
        )?)
    }

    /// Peak of $|S_{ii}|$ per axis ([`AXES`] order) over 1 Hz … $f_s/2$ (ISO 14839-3 judges each
    /// axis by its own sensitivity): a 4000-point log grid, then golden-section refinement
    /// between the grid neighbours of the maximum, as [`Twin::peak_sensitivity`](crate::Twin::peak_sensitivity).
    /// Returns `(f_hz, |S_ii|)` per axis.
    pub fn peak_sensitivity(&self) -> Result<[(f64, f64); 4]> {
        let n = 4000;
        let (f0, f1) = (1.0f64, self.fs() / 2.0);
        let grid: Vec<f64> = (0..n)
            .map(|k| f0 * (f1 / f0).powf(k as f64 / (n - 1) as f64))
            .collect();
        let s = self.sensitivity_frf(&grid)?;
        let mut out = [(0.0, 0.0); 4];
        for (axis, o) in out.iter_mut().enumerate() {
            let mag = |f: f64| -> Result<f64> {
                Ok(self.sensitivity_frf(&[f])?.at(0)?[(axis, axis)].norm())
            };
            let mut kmax = 0;
            let mut vmax = 0.0;
            for k in 0..n {
                let v = s.at(k)?[(axis, axis)].norm();
                if v > vmax {
                    (kmax, vmax) = (k, v);
                }
            }
            let (mut lo, mut hi) = (grid[kmax.saturating_sub(1)], grid[(kmax + 1).min(n - 1)]);
            let gr = (5f64.sqrt() - 1.0) / 2.0;
            let mut x1 = hi - gr * (hi - lo);
            let mut x2 = lo + gr * (hi - lo);
            let (mut m1, mut m2) = (mag(x1)?, mag(x2)?);
            for _ in 0..60 {
                if m1 > m2 {
                    hi = x2;
                    x2 = x1;
                    m2 = m1;
                    x1 = hi - gr * (hi - lo);
                    m1 = mag(x1)?;
                } else {
                    lo = x1;
                    x1 = x2;
                    m1 = m2;
                    x2 = lo + gr * (hi - lo);
                    m2 = mag(x2)?;
                }
                if hi - lo < 1e-9 * hi {
                    break;
                }
            }
            let fb = 0.5 * (lo + hi);
            let vb = mag(fb)?;
            *o = if vb > vmax {
                (fb, vb)
            } else {
                (grid[kmax], vmax)
            };
        }
        Ok(out)
    }

    /// Poles of the discrete closed loop, in $z$.
    pub fn closed_loop_poles(&self) -> Result<Vec<c64>> {
        Ok(self.closed.poles()?)
    }

    /// Every complex closed-loop pole pair as a [`MachineMode`] with its whirl direction, sorted
    /// by natural frequency.
    pub fn closed_loop_pole_pairs(&self) -> Result<Vec<MachineMode>> {
        let a = self.closed.a().to_owned();
        let eig = a.eigen().map_err(|e| TwinError::InvalidArgument {
            name: "closed_loop",
            reason: format!("the eigendecomposition of the closed-loop matrix failed: {e:?}"),
        })?;
        let (u, s) = (eig.U(), eig.S());
        let ph = &self.ph.pl;
        let mut out = Vec::new();
        for k in 0..a.nrows() {
            let z = s[k];
            if !(z.im > 1e-12 && z.norm() > 1e-12) {
                continue;
            }
            let sc = z_to_s(z, self.ts);
            let mut ef = 0.0;
            let mut eb = 0.0;
            for (cx, cy) in [(ph[0].c_a(), ph[1].c_a()), (ph[0].c_b(), ph[1].c_b())] {
                let mut vx = c64::new(0.0, 0.0);
                let mut vy = c64::new(0.0, 0.0);
                for r in 0..3 {
                    vx += u[(r, k)] * cx[r];
                    vy += u[(3 + r, k)] * cy[r];
                }
                let j = c64::new(0.0, 1.0);
                ef += (vx + j * vy).norm_sqr();
                eb += (vx - j * vy).norm_sqr();
            }
            let frac = if ef + eb > 0.0 { ef / (ef + eb) } else { 0.5 };
            let whirl = if self.ph.omega == 0.0 || (frac - 0.5).abs() < 1e-9 {
                Whirl::None
            } else if frac > 0.5 {
                Whirl::Forward
            } else {
                Whirl::Backward
            };
            out.push(MachineMode {
                freq_hz: sc.norm() / (2.0 * PI),
                damped_freq_hz: sc.im / (2.0 * PI),
                damping: -sc.re / sc.norm(),
                forward_fraction: frac,
                whirl,
                z,
            });
        }
        out.sort_by(|a, b| a.freq_hz.total_cmp(&b.freq_hz));
        Ok(out)
    }

    /// The lightly damped closed-loop modes (damping below [`LIGHTLY_DAMPED`]), sorted by
    /// frequency: at the nominal rig each single-plane mode (≈ 97, 156, 780 Hz) twice (x and y),
    /// split into a forward and a backward whirl at speed.
    pub fn closed_loop_modes(&self) -> Result<Vec<MachineMode>> {
        Ok(self
            .closed_loop_pole_pairs()?
            .into_iter()
            .filter(|m| m.damping < LIGHTLY_DAMPED)
            .collect())
    }

    /// Steady-state complex amplitudes of the recorded displacements $y$ (4, axis order) under
    /// the configured unbalance: $y_k = \operatorname{Re}(Y e^{j\Omega kT_s})$. Zeros without an
    /// unbalance. Computed from the exact discrete model with the unbalance oscillator.
    pub fn unbalance_response(&self) -> Result<Vec<c64>> {
        let (Some(d), Some((_, _, phase))) = (&self.discrete_unb, self.ph.unb) else {
            return Ok(vec![c64::new(0.0, 0.0); 4]);
        };
        // closed loop driven by G w_k, w_k = Re(w0 e^{jΩkT}), w0 = e^{jφ}(1, −j)
        let n = self.closed.order();
        let zl = c64::from_polar(1.0, self.ph.omega * self.ts);
        let w0 = [
            c64::from_polar(1.0, phase),
            c64::from_polar(1.0, phase) * c64::new(0.0, -1.0),
        ];
        let mut rhs = Mat::<c64>::zeros(n, 1);
        for i in 0..NX4 {
            rhs[(i, 0)] = d.a()[(i, NX4)] * w0[0] + d.a()[(i, NX4 + 1)] * w0[1];
        }
        let a = self.closed.a();
        let m = Mat::<c64>::from_fn(n, n, |i, j| {
            let v = c64::new(-a[(i, j)], 0.0);
            if i == j {
                v + zl
            } else {
                v
            }
        });
        let x = solve(&m, &rhs)?;
        Ok((0..4).map(|k| x[(I_SEN + k, 0)]).collect())
    }
}

/// One point of a Campbell diagram: the true closed-loop modes at one speed.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CampbellPoint {
    /// Rotor speed \[rpm\].
    pub speed_rpm: f64,
    /// The 1× (synchronous) line $\Omega/2\pi$ \[Hz\].
    pub sync_hz: f64,
    /// Lightly damped closed-loop modes up to `f_max_hz`, sorted by frequency, with whirl labels.
    pub modes: Vec<MachineMode>,
}

/// Campbell diagram: the true closed-loop modes (damping below [`LIGHTLY_DAMPED`], natural
/// frequency ≤ `f_max_hz`) of the machine `cfg` rebuilt at each speed of `speeds_rpm`, with
/// forward/backward labels and the 1× line.
///
/// ```
/// use ambid_twin::{campbell, MachineConfig, Whirl};
/// let c = campbell(&MachineConfig::default(), &[0.0, 30_000.0], 300.0).unwrap();
/// assert!((c[1].sync_hz - 500.0).abs() < 1e-9);
/// assert!(c[0].modes.iter().all(|m| m.whirl == Whirl::None));
/// assert!(c[1].modes.iter().any(|m| m.whirl == Whirl::Forward));
/// ```
pub fn campbell(
    cfg: &MachineConfig,
    speeds_rpm: &[f64],
    f_max_hz: f64,
) -> Result<Vec<CampbellPoint>> {
    if !(f_max_hz.is_finite() && f_max_hz > 0.0) {
        return Err(TwinError::InvalidArgument {
            name: "f_max_hz",
            reason: format!("must be positive and finite, got {f_max_hz}"),
        });
    }
    speeds_rpm
        .iter()
        .map(|&speed_rpm| {
            let m = Machine::new(MachineConfig {
                speed_rpm,
                ..cfg.clone()
            })?;
            Ok(CampbellPoint {
                speed_rpm,
                sync_hz: m.sync_hz(),
                modes: m
                    .closed_loop_modes()?
                    .into_iter()
                    .filter(|md| md.freq_hz <= f_max_hz)
                    .collect(),
            })
        })
        .collect()
}

/// The closed loop $u = C(w - y) + r$ around a plant without feedthrough: states (plant,
/// controller), inputs $(r, w)$, outputs $(y, u)$.
fn close_loops(p: &StateSpace, c: &StateSpace, ts: f64) -> Result<StateSpace> {
    let (np, nc) = (p.order(), c.order());
    let n = np + nc;
    let (ap, bp, cp) = (p.a(), p.b(), p.c());
    let (ac, bc, cc, dc) = (c.a(), c.b(), c.c(), c.d());
    let dccp = dc * cp; // 4 × np
    let mut a = Mat::<f64>::zeros(n, n);
    let bpdccp = bp * &dccp;
    let bpcc = bp * cc;
    let bccp = bc * cp;
    for i in 0..np {
        for j in 0..np {
            a[(i, j)] = ap[(i, j)] - bpdccp[(i, j)];
        }
        for j in 0..nc {
            a[(i, np + j)] = bpcc[(i, j)];
        }
    }
    for i in 0..nc {
        for j in 0..np {
            a[(np + i, j)] = -bccp[(i, j)];
        }
        for j in 0..nc {
            a[(np + i, np + j)] = ac[(i, j)];
        }
    }
    let mut b = Mat::<f64>::zeros(n, 8);
    let bpdc = bp * dc;
    for i in 0..np {
        for k in 0..4 {
            b[(i, k)] = bp[(i, k)];
            b[(i, 4 + k)] = bpdc[(i, k)];
        }
    }
    for i in 0..nc {
        for k in 0..4 {
            b[(np + i, 4 + k)] = bc[(i, k)];
        }
    }
    let mut cm = Mat::<f64>::zeros(8, n);
    let mut d = Mat::<f64>::zeros(8, 8);
    for k in 0..4 {
        for j in 0..np {
            cm[(k, j)] = cp[(k, j)];
            cm[(4 + k, j)] = -dccp[(k, j)];
        }
        for j in 0..nc {
            cm[(4 + k, np + j)] = cc[(k, j)];
        }
        d[(4 + k, k)] = 1.0;
        for j in 0..4 {
            d[(4 + k, 4 + j)] = dc[(k, j)];
        }
    }
    Ok(StateSpace::discrete(a, b, cm, d, ts)?)
}

fn check_freqs(f_hz: &[f64]) -> Result<()> {
    if let Some(index) = f_hz.iter().position(|f| !f.is_finite()) {
        return Err(TwinError::NonFinite {
            what: "f_hz",
            index,
        });
    }
    Ok(())
}

fn identity(n: usize) -> Mat<c64> {
    Mat::from_fn(n, n, |i, j| {
        if i == j {
            c64::new(1.0, 0.0)
        } else {
            c64::new(0.0, 0.0)
        }
    })
}

/// Solves $A X = B$ (complex, square $A$) by LU with full pivoting; a typed error when $A$ is
/// singular to working precision.
fn solve(a: &Mat<c64>, b: &Mat<c64>) -> Result<Mat<c64>> {
    use faer::linalg::solvers::Solve;
    let x = a.full_piv_lu().solve(b);
    let ok = x
        .col_iter()
        .all(|c| c.iter().all(|v| v.re.is_finite() && v.im.is_finite()));
    if !ok {
        return Err(TwinError::InvalidArgument {
            name: "frequency",
            reason:
                "the loop matrix is singular at this frequency (a closed-loop pole on the unit \
                     circle); choose other frequencies"
                    .into(),
        });
    }
    Ok(x)
}
