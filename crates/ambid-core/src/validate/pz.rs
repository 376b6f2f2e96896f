//! Pole-zero analysis of discrete-time models: modal frequency and damping of every pole, unstable
//! poles, non-minimum-phase zeros and near pole–zero cancellations, as used to select identified
//! plant models.
//!
//! # Mapping to the $s$-plane
//! A discrete root $z$ of a model with sample time $T$ is mapped to its continuous equivalent with
//! the principal logarithm
//! $$ s = \frac{\ln z}{T} = \frac{\ln\lvert z\rvert + j \arg z}{T}, \qquad
//!    -\pi < \arg z \le \pi, $$
//! the inverse of the exact map $z = e^{sT}$ (so $-\pi/T < \operatorname{Im} s \le \pi/T$: a root
//! is only known up to aliases $s + j 2\pi k / T$). The **natural frequency** and the **damping
//! ratio** are
//! $$ f = \frac{\lvert s\rvert}{2\pi}\ \text{Hz}, \qquad \zeta = -\frac{\operatorname{Re} s}{\lvert s\rvert}, $$
//! so $\zeta < 0$ exactly when $\lvert z\rvert > 1$; a real unstable pole has $\zeta = -1$ and a
//! stable real one $\zeta = 1$. At $z = 1$ ($s = 0$, an integrator) the ratio is $0/0$; it is
//! reported as $\zeta = 0$, the value on the stability boundary.
//!
//! Special roots:
//! * **Negative real** $z$ has $\arg z = \pi$ and maps to $s = (\ln\lvert z\rvert + j\pi)/T$, i.e.
//!   to (or, when damped, above) the **Nyquist frequency** $1/(2T)$. Such a root has no real
//!   continuous-time counterpart (it alternates in sign every sample); it is reported once, with
//!   $\operatorname{Im} s = +\pi/T$ whatever the sign of the zero imaginary part.
//! * **The origin** $z = 0$ (a pure delay, a FIR pole or a padding pole) has no finite $s$. A root
//!   with $\lvert z\rvert \le$ [`PzOptions::origin_tol`] (default $10^{-6}$: its impulse response
//!   falls by 120 dB in one sample, and a double root at the origin is computed only to about
//!   $\sqrt{\epsilon} \approx 10^{-8}$) is **at the origin**: [`Root::s`], [`Root::f_hz`] and
//!   [`Root::damping`] are then `None`.
//!
//! # Conjugate pairs and ordering
//! Every root is reported on its own: a complex pair appears twice, with conjugate $z$ and $s$ and
//! the same $f$ and $\zeta$ (they are computed from the upper half plane member, so exact
//! conjugates give bit-identical values). Poles and zeros are each sorted by natural frequency,
//! then by $\operatorname{Im} z$ descending (the upper member of a pair first), with the roots at
//! the origin last. All indices (e.g. in [`Cancellation`]) refer to these sorted lists.
//!
//! # Stability and minimum phase
//! A pole with $\lvert z\rvert > 1$ is unstable (an AMB plant has one real unstable pole per
//! rigid-body direction), a zero with $\lvert z\rvert > 1$ is non-minimum phase; both are flagged
//! in [`Root::unstable`]. Roots exactly on the unit circle are not flagged. Zeros at infinity
//! (delays) are not roots and are not listed. Note that sampling a continuous plant of relative
//! degree $\ge 3$ with a zero-order hold creates **sampling zeros**, one of which lies outside the
//! unit circle near $z \approx -3.7$; a non-minimum-phase zero near the negative real axis is
//! therefore usually an artefact of sampling, not a property of the physical plant.
//!
//! # Near cancellations
//! At high sample rates all poles of interest crowd near $z = 1$ ($\lvert z \rvert \approx 1$ for
//! every pole below a few kHz at 20 kHz), so the $z$-plane measure $\lvert p - z_0 \rvert /
//! \lvert p\rvert$ says nothing: a pair 1 % apart in frequency is $2.5\cdot 10^{-3}$ apart in $z$
//! at 780 Hz and $10^{-4}$ apart at 30 Hz. The distance is therefore taken in the $s$-plane,
//! relative to the pole's natural frequency:
//! $$ r = \frac{\min_{k \in \{-1, 0, 1\}} \lvert s_p - s_z + j 2\pi k/T\rvert}
//!             {\max(\lvert s_p\rvert,\ \omega_{\min})}, \qquad \omega_{\min} = 10^{-4}\,\pi/T, $$
//! scale invariant (the same for a 30 Hz pole and a 780 Hz mode, and for any $T$). The minimum
//! over aliases keeps two roots that straddle the negative real axis (just above and below
//! $\arg z = \pm\pi$) close; the floor $\omega_{\min}$ (1 Hz at 20 kHz) keeps poles at or near
//! $s = 0$ from demanding an exact coincidence. A pole and a zero that are both at the origin are
//! the same pure delay and have $r = 0$; a root at the origin is never paired with one that is not.
//!
//! A pair is flagged when $r \le$ [`PzOptions::cancellation_tol`] (default $0.01$: the zero lies
//! within 1 % of the pole's frequency, e.g. 7.8 Hz at 780 Hz, which is below the frequency
//! uncertainty of an identified mode and the resolution of the FRFs that models are judged
//! against; a smaller tolerance asks for a closer coincidence). Pairs are matched one to one,
//! greedily in order of increasing $r$: each pole is paired with at most one zero (its nearest
//! zero that is not already paired with a closer pole), and each zero with at most one pole.
//!
//! A flagged pair means that the model spends two parameters on a factor that nearly divides out:
//! a mode that is barely controllable or observable, or an over-fitted order. Whether removing it
//! changes the frequency response is a different question, answered by
//! [`Cancellation::frf_effect`]: since
//! $(e^{j\theta} - z_0)/(e^{j\theta} - p) = 1 + (p - z_0)/(e^{j\theta} - p)$, the factor changes the
//! response on the unit circle by at most the relative amount
//! $$ e = \max_\theta \left\lvert \frac{e^{j\theta} - z_0}{e^{j\theta} - p} - 1 \right\rvert
//!      = \frac{\lvert p - z_0\rvert}{\bigl\lvert 1 - \lvert p\rvert \bigr\rvert} $$
//! (exact, $+\infty$ for a pole on the unit circle). For a lightly damped mode $e \approx
//! r/\zeta$, which can be large even when $r$ is small: a zero 1 % from a pole with $\zeta = 0.002$
//! still changes the peak by a factor of about 5.
//!
//! # Example
//! ```
//! use ambid_core::validate::pz::{PzAnalysis, PzOptions};
//! use faer::c64;
//! use std::f64::consts::PI;
//! let t = 5e-5; // 20 kHz
//! // a 780 Hz mode with ζ = 0.002 and an unstable real pole at 30 Hz, mapped by z = exp(sT)
//! let w = 2.0 * PI * 780.0;
//! let s = c64::new(-0.002 * w, w * (1.0 - 0.002f64 * 0.002).sqrt());
//! let z = (s * t).exp();
//! let poles = [z, z.conj(), c64::new((2.0 * PI * 30.0 * t).exp(), 0.0)];
//! let pz = PzAnalysis::from_roots(&poles, &[], t, &PzOptions::default()).unwrap();
//! assert!((pz.poles[0].f_hz.unwrap() - 30.0).abs() < 1e-9);
//! assert_eq!(pz.poles[0].damping, Some(-1.0));
//! assert!((pz.poles[1].f_hz.unwrap() - 780.0).abs() < 1e-9);
//! assert!((pz.poles[1].damping.unwrap() - 0.002).abs() < 1e-12);
//! assert_eq!(pz.unstable_poles().len(), 1);
//! println!("{}", pz.table());
//! ```

use crate::error::{Error, Result};
use crate::lti::StateSpace;
use faer::c64;
use std::cmp::Ordering;
use std::f64::consts::PI;
use std::fmt::Write as _;

/// Fraction of the Nyquist angular frequency $\pi/T$ used as the floor $\omega_{\min}$ of the
/// cancellation scale (see the module docs): 1 Hz at 20 kHz.
///
/// ```
/// use ambid_core::validate::pz::CANCELLATION_FLOOR;
/// let ts = 5e-5;
/// let floor_hz = CANCELLATION_FLOOR * std::f64::consts::PI / ts / (2.0 * std::f64::consts::PI);
/// assert!((floor_hz - 1.0).abs() < 1e-12);
/// ```
pub const CANCELLATION_FLOOR: f64 = 1e-4;

/// One pole or zero of a discrete model and its continuous-time equivalent.
///
/// ```
/// use ambid_core::validate::pz::{PzAnalysis, PzOptions};
/// use faer::c64;
/// // a pole at z = -0.5 maps above the Nyquist frequency; a pole at the origin has no s
/// let pz = PzAnalysis::from_roots(&[c64::new(-0.5, 0.0), c64::new(0.0, 0.0)], &[], 1e-3,
///                                 &PzOptions::default()).unwrap();
/// let r = &pz.poles[0];
/// assert!((r.s.unwrap().im - std::f64::consts::PI / 1e-3).abs() < 1e-9);
/// assert!(r.f_hz.unwrap() > 500.0 && !r.unstable);
/// assert!(pz.poles[1].at_origin() && pz.poles[1].f_hz.is_none());
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Root {
    /// The root in the $z$-plane.
    pub z: c64,
    /// $s = \ln(z)/T$ (principal logarithm, rad/s); `None` at the origin.
    pub s: Option<c64>,
    /// Natural frequency $\lvert s\rvert / 2\pi$ in Hz; `None` at the origin.
    pub f_hz: Option<f64>,
    /// Damping ratio $\zeta = -\operatorname{Re} s / \lvert s\rvert$ (0 for $s = 0$); `None` at the
    /// origin.
    pub damping: Option<f64>,
    /// $\lvert z\rvert > 1$: an unstable pole, or a non-minimum-phase zero.
    pub unstable: bool,
}

impl Root {
    /// Maps `z` to its continuous equivalent (see the module docs); `z` and `ts` must be finite
    /// and `ts > 0`, `origin_tol` the radius below which `z` counts as the origin.
    pub(crate) fn new(z: c64, ts: f64, origin_tol: f64) -> Self {
        let unstable = z.norm() > 1.0;
        if z.norm() <= origin_tol {
            return Root {
                z,
                s: None,
                f_hz: None,
                damping: None,
                unstable,
            };
        }
        // Upper-half-plane member (a zero imaginary part of either sign gives arg = +π on the
        // negative real axis), so that a conjugate pair gets identical f and ζ.
        let upper = c64::new(z.re, z.im.abs());
        let su = c64::new(upper.norm().ln(), upper.im.atan2(upper.re)) / ts;
        let s = if z.im < 0.0 { su.conj() } else { su };
        let mag = su.norm();
        let damping = if mag > 0.0 { -su.re / mag } else { 0.0 };
        Root {
            z,
            s: Some(s),
            f_hz: Some(mag / (2.0 * PI)),
            damping: Some(damping),
            unstable,
        }
    }

    /// Whether the root is at the origin ($\lvert z\rvert \le$ [`PzOptions::origin_tol`]), so that
    /// it has no finite $s$, frequency or damping.
    ///
    /// ```
    /// use ambid_core::validate::pz::{PzAnalysis, PzOptions};
    /// use faer::c64;
    /// let pz = PzAnalysis::from_roots(&[c64::new(1e-9, 0.0), c64::new(0.9, 0.0)], &[], 1e-3,
    ///                                 &PzOptions::default()).unwrap();
    /// assert!(!pz.poles[0].at_origin() && pz.poles[1].at_origin());
    /// ```
    pub fn at_origin(&self) -> bool {
        self.s.is_none()
    }

    /// Damped natural frequency $\lvert\operatorname{Im} s\rvert / 2\pi$ in Hz (the frequency of
    /// the oscillation of the mode); `None` at the origin.
    ///
    /// ```
    /// use ambid_core::validate::pz::{PzAnalysis, PzOptions};
    /// use faer::c64;
    /// let t = 1e-3;
    /// let z = (c64::new(-10.0, 2.0 * std::f64::consts::PI * 100.0) * t).exp();
    /// let pz = PzAnalysis::from_roots(&[z], &[], t, &PzOptions::default()).unwrap();
    /// assert!((pz.poles[0].damped_hz().unwrap() - 100.0).abs() < 1e-9);
    /// ```
    pub fn damped_hz(&self) -> Option<f64> {
        self.s.map(|s| s.im.abs() / (2.0 * PI))
    }
}

/// A near pole–zero cancellation: pole `pole` and zero `zero` (indices into
/// [`PzAnalysis::poles`] and [`PzAnalysis::zeros`]) with relative $s$-plane distance `relative`
/// at most [`PzOptions::cancellation_tol`].
///
/// ```
/// use ambid_core::validate::pz::{PzAnalysis, PzOptions};
/// use faer::c64;
/// let t = 1e-3;
/// let p = (c64::new(-5.0, 300.0) * t).exp();
/// let z = (c64::new(-5.0, 301.0) * t).exp(); // 1 rad/s away, |s_p| ≈ 300 rad/s
/// let pz = PzAnalysis::from_roots(&[p, p.conj()], &[z, z.conj()], t, &PzOptions::default())
///     .unwrap();
/// assert_eq!(pz.cancellations.len(), 2);
/// let c = &pz.cancellations[0];
/// assert!((c.relative - 1.0 / 5.0f64.hypot(300.0)).abs() < 1e-9);
/// assert!(c.frf_effect > 0.1); // ζ ≈ 0.017: the pair still shapes the response
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Cancellation {
    /// Index of the pole in [`PzAnalysis::poles`].
    pub pole: usize,
    /// Index of the zero in [`PzAnalysis::zeros`].
    pub zero: usize,
    /// $z$-plane distance $\lvert p - z_0\rvert$.
    pub distance: f64,
    /// $s$-plane distance (rad/s), the smallest over the aliases $\pm j 2\pi/T$; 0 for two roots
    /// at the origin.
    pub s_distance: f64,
    /// `s_distance` $/ \max(\lvert s_p\rvert, \omega_{\min})$, the measure compared with the
    /// tolerance (see the module docs); 0 for two roots at the origin.
    pub relative: f64,
    /// Largest relative change of the frequency response caused by the factor
    /// $(z - z_0)/(z - p)$ on the unit circle, $\lvert p - z_0\rvert / \lvert 1 - \lvert p\rvert
    /// \rvert$ ($+\infty$ for a pole on the unit circle).
    pub frf_effect: f64,
}

/// Options of [`PzAnalysis`].
///
/// ```
/// use ambid_core::validate::pz::PzOptions;
/// let o = PzOptions { cancellation_tol: 0.005, ..PzOptions::default() };
/// assert_eq!(o.origin_tol, 1e-6);
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PzOptions {
    /// Largest relative $s$-plane distance of a flagged pole–zero pair (default 0.01, see the
    /// module docs). Must be finite and $\ge 0$; 0 flags exact coincidences only.
    pub cancellation_tol: f64,
    /// Radius below which a root counts as being at the origin (default $10^{-6}$). Must be
    /// finite, $\ge 0$ and $< 1$.
    pub origin_tol: f64,
}

impl Default for PzOptions {
    fn default() -> Self {
        Self {
            cancellation_tol: 0.01,
            origin_tol: 1e-6,
        }
    }
}

impl PzOptions {
    fn validate(&self) -> Result<()> {
        if !(self.cancellation_tol.is_finite() && self.cancellation_tol >= 0.0) {
            return Err(Error::invalid(
                "cancellation_tol",
                format!(
                    "must be finite and non-negative (got {}); the default is 0.01",
                    self.cancellation_tol
                ),
            ));
        }
        if !(self.origin_tol.is_finite() && (0.0..1.0).contains(&self.origin_tol)) {
            return Err(Error::invalid(
                "origin_tol",
                format!(
                    "must be finite, non-negative and below 1 (got {}); the default is 1e-6",
                    self.origin_tol
                ),
            ));
        }
        Ok(())
    }
}

/// Pole-zero analysis of a discrete model (see the module docs).
///
/// ```
/// use ambid_core::lti::TransferFunction;
/// use ambid_core::validate::pz::{PzAnalysis, PzOptions};
/// // (1 - 0.9 q^-1) / ((1 - 0.5 q^-1)(1 - 1.2 q^-1)): an unstable pole at z = 1.2
/// let g = TransferFunction::new(vec![1.0, -0.9], vec![1.0, -1.7, 0.6], 1e-3).unwrap();
/// let pz = PzAnalysis::from_state_space(&g.to_state_space().unwrap(), &PzOptions::default())
///     .unwrap();
/// assert_eq!((pz.poles.len(), pz.zeros.len()), (2, 2)); // zeros at 0.9 and the origin
/// assert!(pz.zeros[1].at_origin());
/// assert!((pz.unstable_poles()[0].z.re - 1.2).abs() < 1e-12);
/// assert!(pz.cancellations.is_empty());
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct PzAnalysis {
    /// Poles, sorted by natural frequency (roots at the origin last).
    pub poles: Vec<Root>,
    /// Finite zeros, sorted the same way.
    pub zeros: Vec<Root>,
    /// Near cancellations, in order of increasing [`Cancellation::relative`].
    pub cancellations: Vec<Cancellation>,
    /// Sample time in seconds.
    pub ts: f64,
    /// Why the zeros were not computed, when [`from_state_space`](Self::from_state_space)
    /// skipped them (a controllable and observable part larger than
    /// [`ZEROS_MAX_ORDER`](crate::lti::ZEROS_MAX_ORDER)); `None` when `zeros` is complete.
    pub zeros_skipped: Option<String>,
}

/// Order: finite roots by natural frequency, then Im z descending, then Re z; the origin last.
fn root_order(a: &Root, b: &Root) -> Ordering {
    match (a.f_hz, b.f_hz) {
        (Some(fa), Some(fb)) => fa
            .total_cmp(&fb)
            .then(b.z.im.total_cmp(&a.z.im))
            .then(a.z.re.total_cmp(&b.z.re)),
        (Some(_), None) => Ordering::Less,
        (None, Some(_)) => Ordering::Greater,
        (None, None) => b.z.im.total_cmp(&a.z.im).then(a.z.re.total_cmp(&b.z.re)),
    }
}

fn check_roots(what: &'static str, r: &[c64]) -> Result<()> {
    match r
        .iter()
        .position(|z| !(z.re.is_finite() && z.im.is_finite()))
    {
        Some(index) => Err(Error::NonFinite { what, index }),
        None => Ok(()),
    }
}

impl PzAnalysis {
    /// Analyses the poles (eigenvalues of $A$) and transmission zeros of a discrete state-space
    /// model. The model must be square (as many outputs as inputs; see
    /// [`StateSpace::zeros`]).
    ///
    /// Errors: [`Error::TimeDomain`] for a continuous model, [`Error::DimensionMismatch`] for a
    /// non-square one, and those of [`from_roots`](Self::from_roots).
    ///
    /// ```
    /// use ambid_core::lti::StateSpace;
    /// use ambid_core::validate::pz::{PzAnalysis, PzOptions};
    /// use faer::mat;
    /// let g = StateSpace::discrete(mat![[0.5]], mat![[1.0]], mat![[1.0]], mat![[1.0]], 1e-3)
    ///     .unwrap();
    /// let pz = PzAnalysis::from_state_space(&g, &PzOptions::default()).unwrap();
    /// assert!((pz.zeros[0].z.re + 0.5).abs() < 1e-12); // 1 + 1/(z - 0.5) = (z + 0.5)/(z - 0.5)
    /// let c = StateSpace::continuous(mat![[-1.0]], mat![[1.0]], mat![[1.0]], mat![[0.0]]).unwrap();
    /// assert!(PzAnalysis::from_state_space(&c, &PzOptions::default()).is_err());
    /// ```
    pub fn from_state_space(m: &StateSpace, opts: &PzOptions) -> Result<Self> {
        let ts = m.ts().ok_or_else(|| {
            Error::TimeDomain(
                "pole-zero analysis needs a discrete-time model; this one is continuous \
                 (discretise it first, e.g. with c2d_zoh)"
                    .into(),
            )
        })?;
        opts.validate()?;
        let poles = m.poles()?;
        match m.zeros() {
            Ok(zeros) => Self::from_roots(&poles, &zeros, ts, opts),
            Err(Error::InvalidArgument {
                name: "model order",
                reason,
            }) => {
                let mut pz = Self::from_roots(&poles, &[], ts, opts)?;
                pz.zeros_skipped = Some(reason);
                Ok(pz)
            }
            Err(e) => Err(e),
        }
    }

    /// Analyses given poles and zeros (in $z$) of a model with sample time `ts` seconds. The
    /// returned lists are sorted (see the module docs), not in the order given.
    ///
    /// Errors: [`Error::InvalidArgument`] for a `ts` that is not finite and positive or for bad
    /// options (a negative or non-finite tolerance), [`Error::NonFinite`] for a root with a NaN or
    /// infinite part.
    ///
    /// ```
    /// use ambid_core::validate::pz::{PzAnalysis, PzOptions};
    /// use faer::c64;
    /// let p = [c64::new(0.9, 0.1), c64::new(0.9, -0.1)];
    /// let pz = PzAnalysis::from_roots(&p, &[c64::new(1.5, 0.0)], 1e-3, &PzOptions::default())
    ///     .unwrap();
    /// assert_eq!(pz.poles[0].z, p[0]); // upper member first
    /// assert_eq!(pz.poles[0].f_hz, pz.poles[1].f_hz);
    /// assert_eq!(pz.nonminimum_phase_zeros().len(), 1);
    /// assert!(PzAnalysis::from_roots(&p, &[], 0.0, &PzOptions::default()).is_err());
    /// ```
    pub fn from_roots(poles: &[c64], zeros: &[c64], ts: f64, opts: &PzOptions) -> Result<Self> {
        if !(ts.is_finite() && ts > 0.0) {
            return Err(Error::invalid(
                "ts",
                format!("the sample time must be finite and positive (got {ts} s)"),
            ));
        }
        opts.validate()?;
        check_roots("poles", poles)?;
        check_roots("zeros", zeros)?;
        let mk = |r: &[c64]| {
            let mut v: Vec<Root> = r
                .iter()
                .map(|&z| Root::new(z, ts, opts.origin_tol))
                .collect();
            v.sort_by(root_order);
            v
        };
        let poles = mk(poles);
        let zeros = mk(zeros);
        let cancellations = match_pairs(&poles, &zeros, ts, opts.cancellation_tol);
        Ok(PzAnalysis {
            poles,
            zeros,
            cancellations,
            ts,
            zeros_skipped: None,
        })
    }

    /// The unstable poles ($\lvert z\rvert > 1$), in the order of [`poles`](Self::poles).
    ///
    /// ```
    /// use ambid_core::validate::pz::{PzAnalysis, PzOptions};
    /// use faer::c64;
    /// let pz = PzAnalysis::from_roots(&[c64::new(1.01, 0.0), c64::new(0.99, 0.0)], &[], 1e-3,
    ///                                 &PzOptions::default()).unwrap();
    /// let u = pz.unstable_poles();
    /// assert_eq!(u.len(), 1);
    /// assert!(u[0].damping.unwrap() == -1.0);
    /// ```
    pub fn unstable_poles(&self) -> Vec<&Root> {
        self.poles.iter().filter(|r| r.unstable).collect()
    }

    /// The non-minimum-phase zeros ($\lvert z\rvert > 1$), in the order of
    /// [`zeros`](Self::zeros).
    ///
    /// ```
    /// use ambid_core::validate::pz::{PzAnalysis, PzOptions};
    /// use faer::c64;
    /// let pz = PzAnalysis::from_roots(&[], &[c64::new(-3.7, 0.0), c64::new(0.5, 0.0)], 1e-3,
    ///                                 &PzOptions::default()).unwrap();
    /// assert_eq!(pz.nonminimum_phase_zeros()[0].z.re, -3.7);
    /// ```
    pub fn nonminimum_phase_zeros(&self) -> Vec<&Root> {
        self.zeros.iter().filter(|r| r.unstable).collect()
    }

    /// The cancellation of pole `i`, if it is flagged.
    ///
    /// ```
    /// use ambid_core::validate::pz::{PzAnalysis, PzOptions};
    /// use faer::c64;
    /// let pz = PzAnalysis::from_roots(&[c64::new(0.9, 0.0)], &[c64::new(0.9, 0.0)], 1e-3,
    ///                                 &PzOptions::default()).unwrap();
    /// assert_eq!(pz.cancellation_of_pole(0).unwrap().zero, 0);
    /// ```
    pub fn cancellation_of_pole(&self, i: usize) -> Option<&Cancellation> {
        self.cancellations.iter().find(|c| c.pole == i)
    }

    /// A plain-text report: the sample time, the poles and zeros with $z$, $\lvert z\rvert$,
    /// natural frequency, damping and flags ("unstable", "non-minimum phase", "origin",
    /// "cancels zero/pole #k"), and the near cancellations.
    ///
    /// ```
    /// use ambid_core::validate::pz::{PzAnalysis, PzOptions};
    /// use faer::c64;
    /// let pz = PzAnalysis::from_roots(&[c64::new(1.01, 0.0)], &[c64::new(1.01001, 0.0)], 1e-3,
    ///                                 &PzOptions::default()).unwrap();
    /// let t = pz.table();
    /// assert!(t.contains("unstable") && t.contains("non-minimum phase"));
    /// assert!(t.contains("cancels zero #0") && t.contains("Near cancellations"));
    /// ```
    pub fn table(&self) -> String {
        let mut out = String::new();
        let _ = writeln!(
            out,
            "Pole-zero analysis (Ts = {:e} s, Nyquist {} Hz)",
            self.ts,
            fmt_num(0.5 / self.ts)
        );
        self.write_roots(&mut out, "Poles", &self.poles, true);
        match &self.zeros_skipped {
            Some(why) => {
                let _ = writeln!(out, "Zeros: not computed ({why})");
            }
            None => self.write_roots(&mut out, "Zeros", &self.zeros, false),
        }
        if self.cancellations.is_empty() {
            let _ = writeln!(out, "Near cancellations: none");
        } else {
            let _ = writeln!(out, "Near cancellations ({}):", self.cancellations.len());
            let _ = writeln!(
                out,
                "  {:>5} {:>5} {:>12} {:>12} {:>12} {:>12}",
                "pole", "zero", "|p-z|", "|sp-sz|", "relative", "frf effect"
            );
            for c in &self.cancellations {
                let _ = writeln!(
                    out,
                    "  {:>5} {:>5} {:>12.4e} {:>12.4e} {:>12.4e} {:>12.4e}",
                    c.pole, c.zero, c.distance, c.s_distance, c.relative, c.frf_effect
                );
            }
        }
        out
    }

    fn write_roots(&self, out: &mut String, title: &str, roots: &[Root], is_pole: bool) {
        let _ = writeln!(out, "{title} ({}):", roots.len());
        if roots.is_empty() {
            return;
        }
        let _ = writeln!(
            out,
            "  {:>3} {:>14} {:>14} {:>12} {:>12} {:>10}  note",
            "#", "Re z", "Im z", "|z|", "f [Hz]", "zeta"
        );
        for (i, r) in roots.iter().enumerate() {
            let mut notes: Vec<String> = Vec::new();
            if r.unstable {
                notes.push(
                    if is_pole {
                        "unstable"
                    } else {
                        "non-minimum phase"
                    }
                    .into(),
                );
            }
            if r.at_origin() {
                notes.push("origin".into());
            }
            for c in &self.cancellations {
                if is_pole && c.pole == i {
                    notes.push(format!("cancels zero #{}", c.zero));
                } else if !is_pole && c.zero == i {
                    notes.push(format!("cancels pole #{}", c.pole));
                }
            }
            let (f, d) = match (r.f_hz, r.damping) {
                (Some(f), Some(d)) => (fmt_num(f), format!("{d:.4e}")),
                _ => ("-".into(), "-".into()),
            };
            let line = format!(
                "  {:>3} {:>14.10} {:>14.10} {:>12.10} {:>12} {:>10}  {}",
                i,
                r.z.re,
                r.z.im,
                r.z.norm(),
                f,
                d,
                notes.join(", ")
            );
            let _ = writeln!(out, "{}", line.trim_end());
        }
    }
}

/// A frequency with 7 significant digits (fixed point between 0.01 and 10^6).
fn fmt_num(x: f64) -> String {
    if x == 0.0 {
        "0".into()
    } else if x.abs() >= 1e6 || x.abs() < 1e-2 {
        format!("{x:.6e}")
    } else {
        let decimals = (6 - x.abs().log10().floor() as i32).max(0) as usize;
        format!("{x:.decimals$}")
    }
}

/// One-to-one greedy matching of poles to zeros by increasing relative s-plane distance.
fn match_pairs(poles: &[Root], zeros: &[Root], ts: f64, tol: f64) -> Vec<Cancellation> {
    let period = 2.0 * PI / ts;
    let floor = CANCELLATION_FLOOR * PI / ts;
    let mut cand: Vec<Cancellation> = Vec::new();
    for (i, p) in poles.iter().enumerate() {
        for (j, z) in zeros.iter().enumerate() {
            let (s_distance, relative) = match (p.s, z.s) {
                (Some(sp), Some(sz)) => {
                    let d = sp - sz;
                    let sd = [-1.0, 0.0, 1.0]
                        .iter()
                        .map(|k| (d + c64::new(0.0, k * period)).norm())
                        .fold(f64::INFINITY, f64::min);
                    (sd, sd / sp.norm().max(floor))
                }
                (None, None) => (0.0, 0.0),
                _ => continue,
            };
            if relative <= tol {
                let distance = (p.z - z.z).norm();
                let gap = (1.0 - p.z.norm()).abs();
                let frf_effect = if distance == 0.0 {
                    0.0
                } else if gap > 0.0 {
                    distance / gap
                } else {
                    f64::INFINITY
                };
                cand.push(Cancellation {
                    pole: i,
                    zero: j,
                    distance,
                    s_distance,
                    relative,
                    frf_effect,
                });
            }
        }
    }
    cand.sort_by(|a, b| {
        a.relative
            .total_cmp(&b.relative)
            .then(a.distance.total_cmp(&b.distance))
            .then(a.pole.cmp(&b.pole))
            .then(a.zero.cmp(&b.zero))
    });
    let mut pole_used = vec![false; poles.len()];
    let mut zero_used = vec![false; zeros.len()];
    let mut out = Vec::new();
    for c in cand {
        if !pole_used[c.pole] && !zero_used[c.zero] {
            pole_used[c.pole] = true;
            zero_used[c.zero] = true;
            out.push(c);
        }
    }
    out
}
