//! # ambid-twin
//!
//! The embedded AMB digital twin: a single-plane rotor on two active magnetic bearings A and B
//! under decentralised digital PID control, simulated in closed loop (linear or nonlinear
//! physics, sensor noise, ADC quantisation, saturation), together with its **exact linearised
//! discrete-time truth**: the assembled plant $P$, the controller $C$, $T_{ry} = P/(1+PC)$,
//! $S = T_{ru} = 1/(1+PC)$, closed-loop poles and modes, peak sensitivity and the unstable plant
//! pole.
//!
//! # Closed loop and conventions
//! At bearing A (the identified axis) the excitation $r$ is added to the controller output and
//! $w$ is the position reference:
//! $$ u = C(q)\ (w - y) + r, \qquad y = P(q)\ u + v, $$
//! $$ T_{ry} = \frac{P}{1 + PC}, \qquad S = T_{ru} = \frac{1}{1 + PC}. $$
//! SI units everywhere ($r, u, i$ in A, $w, y$ in m), frequencies in Hz at every public function.
//!
//! # Timing convention
//! Sample $k$ is at $t_k = k T_s$, $T_s = 1/f_s$ (50 µs nominal).
//! 1. The controller reads $y\[k\]$: the sensor low-pass output sampled at $t_k$, plus white noise,
//!    then (optionally) quantised by the ADC.
//! 2. It computes $c\[k\] = C(q)\ (w\[k\] - y\[k\])$ (Tustin PID with filters; clamp $\pm i_\mathrm{sat}$
//!    with integrator anti-windup). The recorded output is $u\[k\] = c\[k\] + r\[k\]$, clamped to
//!    $\pm i_\mathrm{sat}$ (DAC/software limit, counted in [`SimMeta`]).
//! 3. One sample of computation delay: $u\[k\]$ is the amplifier's current reference, held (ZOH)
//!    during $[t_{k+1}, t_{k+2})$.
//! 4. $i\[k\]$ is the actual coil control current at $t_k$.
//!
//! Hence the assembled plant $P$ (recorded $u$ → recorded $y$) **contains** the computation delay,
//! the ZOH, the amplifier, the magnet, the rotor (with loop B closed by its own controller and its
//! own delay), the sensor low-pass and the sampling, while $C$ is the pure Tustin PID (no delay).
//! Then $T_{ry} = P/(1+PC)$ and $S = 1/(1+PC)$ hold exactly for the recorded $r$, $u$, $y$: the
//! linear twin, noise off, reproduces them to rounding error (see `tests/simulation.rs`).
//!
//! # The model
//! See [`model`] for the derivation (rotor coordinates, bearing geometry, magnet linearisation
//! $k_i = 4 k i_0/g_0^2$, $k_x = 4 k i_0^2/g_0^3$, ZOH, Tustin, assembly), [`sim`] for the
//! simulation (modes, amplifier slew and output limits, touchdown, pre-roll) and
//! [`UnstablePolePrediction`] for the physics of the plant's unstable pole.
//!
//! Nominal rig (the [`TwinConfig`] default): $m = 5$ kg, $L = 0.5$ m, $J = mL^2/12$,
//! bearings at $\pm 0.2165$ m, bending mode 730 Hz / 1 % / $\varphi = 0.616$ kg$^{-1/2}$;
//! $N = 100$, $A = 4\cdot10^{-4}$ m², $\alpha = 22.5°$, $g_0 = 0.4$ mm, $i_0 = 2$ A
//! ($k_i \approx 58.05$ N/A, $k_x \approx 2.90\cdot10^5$ N/m), $i_\mathrm{sat} = 2$ A; amplifier
//! 2 kHz, 60 V, 6.3 mH, 1 Ω; sensor 10 V/mm, 10 kHz, 0.2 µm RMS, ADC 16 bit ±10 V (off by
//! default); PID $K_p = 21\ 000$ A/m, $K_i = K_p\ 2\pi\ 5$ Hz, $K_d = 14$ A·s/m,
//! $\omega_d = 2\pi\ 4$ kHz, $\omega_l = 2\pi\ 5$ kHz, $f_s = 20$ kHz.
//! It gives closed-loop modes at 97.4 Hz (ζ = 0.149), 156.3 Hz (ζ = 0.274) and 780.2 Hz
//! (ζ = 0.019), peak $|S| = 2.58$ at 96.9 Hz, and one unstable plant pole at
//! $s = +408.8$ rad/s ($z = 1.02065$).
//!
//! Not modelled: gravity (horizontal axis or compensated), gyroscopics (standstill), eddy
//! currents and magnetic saturation of the iron, sensor runout.
//!
//! # The whole rotor
//! [`Machine`] (module [`machine`], simulation in [`sim4`]) is the 4-axis twin: both planes, four
//! radial axes `xa, xb, ya, yb` ([`AXES`]), gyroscopic coupling at speed, optional unbalance and
//! x/y magnet asymmetry, with the exact 4×4 truth ($P$, $C$, $T_{ry}$, $S$ as `Frd`), closed-loop
//! modes with forward/backward whirl labels and a [`campbell`] diagram. At standstill each plane
//! reproduces the single-plane [`Twin`], which stays unchanged.
//!
//! # Example
//! ```
//! use ambid_twin::{Twin, TwinConfig, SimOptions, Mode};
//! let twin = Twin::new(TwinConfig::from_toml_str("[operating_point]\nbias_current_a = 2.4\n").unwrap()).unwrap();
//! let modes = twin.closed_loop_modes();
//! assert_eq!(modes.len(), 3);
//! let r = vec![0.0; 200];
//! let rec = twin.simulate(&r, &SimOptions { mode: Mode::Nonlinear, seed: 1, ..Default::default() }).unwrap();
//! assert!(rec.meta.saturated_fraction == 0.0);
//! ```
#![warn(missing_docs)]

pub mod config;
pub mod error;
pub mod machine;
pub mod model;
pub mod rig;
pub mod sim;
pub mod sim4;
mod twin;

pub use config::{
    AmplifierConfig, ControllerConfig, Integrator, MagnetConfig, Mode, OperatingPoint, RotorConfig,
    SensorConfig, SimulationConfig, TwinConfig,
};
pub use error::{Result, TwinError};
pub use faer::c64;
pub use machine::{
    campbell, AsymmetryConfig, CampbellPoint, Machine, MachineConfig, MachineMode, UnbalanceConfig,
    Whirl, AXES,
};
pub use model::{LinearParams, UnstablePolePrediction};
pub use rig::{random_machine_rig, random_rig, MACHINE_RIG_ASYMMETRY};
pub use sim::{Channels, SimMeta, SimOptions, SimRecord};
pub use sim4::{MachineRecord, MachineSimMeta, MachineSimOptions};
pub use twin::{ClosedLoopMode, Twin, LIGHTLY_DAMPED};
