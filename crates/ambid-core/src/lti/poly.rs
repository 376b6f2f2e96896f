//! Discrete polynomial (input–output) models of the general structure
//! $$ A(q)\, y_k = \frac{B(q)}{F(q)}\, u_k + \frac{C(q)}{D(q)}\, e_k, $$
//! polynomials in ascending powers of $q^{-1}$ with monic $A, C, D, F$ (`[1, …]`) and the input
//! delay carried by leading zeros of $B$, as MATLAB's `idpoly`. The deterministic part is
//! $G = B / (A F)$, the noise part $H = C / (A D)$.
//!
//! | structure | free polynomials |
//! |-----------|------------------|
//! | FIR       | $B$ |
//! | ARX       | $A, B$ |
//! | ARMAX     | $A, B, C$ |
//! | OE        | $B, F$ |
//! | BJ        | $B, C, D, F$ |
//! | general   | all |
//!
//! [`Structure`] also names the state-space structure (`ss`), so that one type names every
//! model structure of the project.
//!
//! # Example
//! ```
//! use ambid_core::lti::{PolyModel, Structure};
//! // OE: y = 0.2 q^-1 / (1 - 0.8 q^-1) u + e
//! let m = PolyModel::oe(vec![0.0, 0.2], vec![1.0, -0.8], 1e-3).unwrap();
//! assert_eq!(m.structure(), Structure::Oe);
//! let g = m.freq_response(&[0.0]).unwrap();
//! assert!((g[0].re - 1.0).abs() < 1e-12);
//! let y = m.simulate(&[1.0, 0.0, 0.0], None, None).unwrap();
//! assert!((y[1] - 0.2).abs() < 1e-15 && (y[2] - 0.16).abs() < 1e-15);
//! ```

use super::ss::{check_ts, StateSpace};
use super::tf::{poly_mul, TransferFunction};
use crate::error::{check_finite, Error, Result};
use faer::{c64, Mat};

/// Model structure: the one type that names a structure everywhere (polynomial models, the
/// state-space estimators, the model comparison of [`crate::validate::compare`], the command line
/// and the workflow file).
///
/// The polynomial structures tag a [`PolyModel`]; [`Structure::Ss`] is a state-space model
/// (subspace + prediction-error refinement in the time domain, frequency-domain subspace + LM on
/// FRF data) and never tags a [`PolyModel`].
///
/// Names ([`Structure::name`], [`std::fmt::Display`], [`std::str::FromStr`] and serde all use
/// them): `fir`, `arx`, `armax`, `oe`, `bj`, `general`, `ss`. Parsing ignores ASCII case and
/// surrounding blanks and also takes the aliases `box-jenkins`/`box_jenkins` for `bj`,
/// `output-error`/`output_error` for `oe` and `state-space`/`state_space`/`statespace` for `ss`.
///
/// # Example
/// ```
/// use ambid_core::lti::Structure;
/// let s: Structure = "SS".parse().unwrap();
/// assert_eq!(s, Structure::Ss);
/// assert_eq!(s.to_string(), "ss");
/// assert_eq!("box-jenkins".parse::<Structure>().unwrap(), Structure::Bj);
/// assert!(Structure::Oe.fits_frf() && !Structure::Bj.fits_frf());
/// let err = "arma".parse::<Structure>().unwrap_err().to_string();
/// assert!(err.contains("fir, arx, armax, oe, bj, general, ss"));
/// assert_eq!(serde_json::to_string(&Structure::Armax).unwrap(), "\"armax\"");
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Structure {
    /// Finite impulse response: $y = B u + e$.
    Fir,
    /// $A y = B u + e$.
    Arx,
    /// $A y = B u + C e$.
    Armax,
    /// Output error: $y = (B/F) u + e$.
    Oe,
    /// Box–Jenkins: $y = (B/F) u + (C/D) e$.
    Bj,
    /// $A y = (B/F) u + (C/D) e$.
    General,
    /// State space $x_{k+1} = A x_k + B u_k + K e_k$, $y_k = C x_k + D u_k + e_k$ (not a
    /// [`PolyModel`]).
    Ss,
}

impl Structure {
    /// Every structure, in the order of the table above (`ss` last).
    pub const ALL: [Structure; 7] = [
        Structure::Fir,
        Structure::Arx,
        Structure::Armax,
        Structure::Oe,
        Structure::Bj,
        Structure::General,
        Structure::Ss,
    ];

    /// Lower-case name as used in model files, on the command line and in workflow files
    /// (`"fir"`, `"arx"`, …, `"ss"`).
    pub fn name(self) -> &'static str {
        match self {
            Structure::Fir => "fir",
            Structure::Arx => "arx",
            Structure::Armax => "armax",
            Structure::Oe => "oe",
            Structure::Bj => "bj",
            Structure::General => "general",
            Structure::Ss => "ss",
        }
    }

    /// `true` for the polynomial structures (those that tag a [`PolyModel`]).
    pub fn is_polynomial(self) -> bool {
        self != Structure::Ss
    }

    /// `true` for the structures a fit to frequency-response data supports
    /// ([`crate::validate::compare::compare_models`]): ARX (Levy's linearised form), OE (SK + LM)
    /// and state space (frequency-domain subspace + LM). The noise models of ARMAX, BJ and the
    /// general structure are not identifiable from an FRF, and FIR is not offered.
    pub fn fits_frf(self) -> bool {
        matches!(self, Structure::Arx | Structure::Oe | Structure::Ss)
    }

    /// The structures fitted to time-domain data (`ambid fit --structure`, the workflow's
    /// time-domain candidates): every one but the general polynomial form.
    pub const TIME_DOMAIN: [Structure; 6] = [
        Structure::Fir,
        Structure::Arx,
        Structure::Armax,
        Structure::Oe,
        Structure::Bj,
        Structure::Ss,
    ];

    /// The structures [`Structure::fits_frf`] accepts: ARX, OE, SS.
    pub const FRF: [Structure; 3] = [Structure::Arx, Structure::Oe, Structure::Ss];

    /// Which of $(A, C, D, F)$ may differ from $1$ (`None` for state space).
    fn free(self) -> Option<[bool; 4]> {
        match self {
            Structure::Fir => Some([false, false, false, false]),
            Structure::Arx => Some([true, false, false, false]),
            Structure::Armax => Some([true, true, false, false]),
            Structure::Oe => Some([false, false, false, true]),
            Structure::Bj => Some([false, true, true, true]),
            Structure::General => Some([true, true, true, true]),
            Structure::Ss => None,
        }
    }
}

impl std::fmt::Display for Structure {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for Structure {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        let key = s.trim().to_ascii_lowercase();
        let found = match key.as_str() {
            "box-jenkins" | "box_jenkins" => Some(Structure::Bj),
            "output-error" | "output_error" => Some(Structure::Oe),
            "state-space" | "state_space" | "statespace" => Some(Structure::Ss),
            k => Structure::ALL.into_iter().find(|x| x.name() == k),
        };
        found.ok_or_else(|| {
            let names: Vec<&str> = Structure::ALL.iter().map(|x| x.name()).collect();
            Error::invalid(
                "structure",
                format!(
                    "unknown model structure `{}`; use one of {}",
                    s.trim(),
                    names.join(", ")
                ),
            )
        })
    }
}

/// A discrete polynomial model $A y = (B/F) u + (C/D) e$ with sample time `ts`.
#[derive(Debug, Clone, PartialEq)]
pub struct PolyModel {
    structure: Structure,
    a: Vec<f64>,
    b: Vec<f64>,
    c: Vec<f64>,
    d: Vec<f64>,
    f: Vec<f64>,
    ts: f64,
}

fn is_one(p: &[f64]) -> bool {
    p.first() == Some(&1.0) && p[1..].iter().all(|x| *x == 0.0)
}

impl PolyModel {
    /// Builds a model, checking that $A, C, D, F$ are monic (`p[0] == 1` to 1e-12), all
    /// coefficients are finite, $B$ is non-empty, `ts > 0`, and that polynomials fixed by the
    /// `structure` equal `[1]` (trailing zeros allowed).
    pub fn new(
        structure: Structure,
        a: Vec<f64>,
        b: Vec<f64>,
        c: Vec<f64>,
        d: Vec<f64>,
        f: Vec<f64>,
        ts: f64,
    ) -> Result<Self> {
        check_ts(ts)?;
        let Some(free) = structure.free() else {
            return Err(Error::invalid(
                "structure",
                "a state-space structure (`ss`) is not a polynomial model; build a StateSpace instead",
            ));
        };
        let names: [&'static str; 4] = ["a", "c", "d", "f"];
        let polys = [&a, &c, &d, &f];
        for (k, (name, p)) in names.iter().zip(polys).enumerate() {
            check_finite(name, p)?;
            match p.first() {
                Some(x) if (x - 1.0).abs() <= 1e-12 => {}
                _ => {
                    return Err(Error::invalid(
                        name,
                        "must be monic: [1, c1, c2, …] in ascending powers of q^-1",
                    ))
                }
            }
            if !free[k] && !is_one(p) {
                return Err(Error::invalid(
                    name,
                    format!(
                        "a {} model fixes this polynomial to [1]; use Structure::General for a free one",
                        structure.name()
                    ),
                ));
            }
        }
        check_finite("b", &b)?;
        if b.is_empty() {
            return Err(Error::invalid("b", "B needs at least one coefficient"));
        }
        let mono = |mut p: Vec<f64>| {
            p[0] = 1.0;
            p
        };
        Ok(Self {
            structure,
            a: mono(a),
            b,
            c: mono(c),
            d: mono(d),
            f: mono(f),
            ts,
        })
    }

    /// FIR model $y = B u + e$.
    pub fn fir(b: Vec<f64>, ts: f64) -> Result<Self> {
        Self::new(
            Structure::Fir,
            vec![1.0],
            b,
            vec![1.0],
            vec![1.0],
            vec![1.0],
            ts,
        )
    }
    /// ARX model $A y = B u + e$.
    pub fn arx(a: Vec<f64>, b: Vec<f64>, ts: f64) -> Result<Self> {
        Self::new(Structure::Arx, a, b, vec![1.0], vec![1.0], vec![1.0], ts)
    }
    /// ARMAX model $A y = B u + C e$.
    pub fn armax(a: Vec<f64>, b: Vec<f64>, c: Vec<f64>, ts: f64) -> Result<Self> {
        Self::new(Structure::Armax, a, b, c, vec![1.0], vec![1.0], ts)
    }
    /// Output-error model $y = (B/F) u + e$.
    pub fn oe(b: Vec<f64>, f: Vec<f64>, ts: f64) -> Result<Self> {
        Self::new(Structure::Oe, vec![1.0], b, vec![1.0], vec![1.0], f, ts)
    }
    /// Box–Jenkins model $y = (B/F) u + (C/D) e$.
    pub fn bj(b: Vec<f64>, c: Vec<f64>, d: Vec<f64>, f: Vec<f64>, ts: f64) -> Result<Self> {
        Self::new(Structure::Bj, vec![1.0], b, c, d, f, ts)
    }
    /// General model $A y = (B/F) u + (C/D) e$.
    pub fn general(
        a: Vec<f64>,
        b: Vec<f64>,
        c: Vec<f64>,
        d: Vec<f64>,
        f: Vec<f64>,
        ts: f64,
    ) -> Result<Self> {
        Self::new(Structure::General, a, b, c, d, f, ts)
    }

    /// Structure tag.
    pub fn structure(&self) -> Structure {
        self.structure
    }
    /// $A$ (monic).
    pub fn a(&self) -> &[f64] {
        &self.a
    }
    /// $B$ (delay as leading zeros).
    pub fn b(&self) -> &[f64] {
        &self.b
    }
    /// $C$ (monic).
    pub fn c(&self) -> &[f64] {
        &self.c
    }
    /// $D$ (monic).
    pub fn d(&self) -> &[f64] {
        &self.d
    }
    /// $F$ (monic).
    pub fn f(&self) -> &[f64] {
        &self.f
    }
    /// Sample time in seconds.
    pub fn ts(&self) -> f64 {
        self.ts
    }
    /// Input delay $n_k$: the number of leading zeros of $B$.
    pub fn delay(&self) -> usize {
        self.b.iter().take_while(|x| **x == 0.0).count()
    }

    /// Deterministic part $G = B / (A F)$.
    pub fn g(&self) -> Result<TransferFunction> {
        TransferFunction::new(self.b.clone(), poly_mul(&self.a, &self.f), self.ts)
    }

    /// Noise part $H = C / (A D)$.
    pub fn h(&self) -> Result<TransferFunction> {
        TransferFunction::new(self.c.clone(), poly_mul(&self.a, &self.d), self.ts)
    }

    /// Frequency response of $G$ at each frequency (Hz).
    pub fn freq_response(&self, f_hz: &[f64]) -> Result<Vec<c64>> {
        self.g()?.freq_response(f_hz)
    }

    /// Frequency response of $H$ at each frequency (Hz).
    pub fn noise_response(&self, f_hz: &[f64]) -> Result<Vec<c64>> {
        self.h()?.freq_response(f_hz)
    }

    /// Poles of $G$ in $z$: roots of $A F$ (plus poles at the origin from a longer $B$).
    pub fn poles(&self) -> Result<Vec<c64>> {
        self.g()?.poles()
    }

    /// Finite zeros of $G$ in $z$: roots of $B$ (the delay is a zero at infinity).
    pub fn zeros(&self) -> Result<Vec<c64>> {
        self.g()?.zeros()
    }

    /// Poles of $H$ in $z$: roots of $A D$.
    pub fn noise_poles(&self) -> Result<Vec<c64>> {
        self.h()?.poles()
    }

    /// Zeros of $H$ in $z$: roots of $C$.
    pub fn noise_zeros(&self) -> Result<Vec<c64>> {
        self.h()?.zeros()
    }

    /// State-space realisation with one output and two inputs $[u, e]$: the block-diagonal
    /// union of the controllable canonical forms of $G$ (first states) and $H$ (last states),
    /// $y = G u + H e$. Not minimal when $A \ne 1$ (its roots appear in both blocks).
    pub fn to_state_space(&self) -> Result<StateSpace> {
        let g = self.g()?.to_state_space()?;
        let h = self.h()?.to_state_space()?;
        let (n1, n2) = (g.order(), h.order());
        let a = Mat::from_fn(n1 + n2, n1 + n2, |i, j| match (i < n1, j < n1) {
            (true, true) => g.a()[(i, j)],
            (false, false) => h.a()[(i - n1, j - n1)],
            _ => 0.0,
        });
        let b = Mat::from_fn(n1 + n2, 2, |i, j| match (i < n1, j) {
            (true, 0) => g.b()[(i, 0)],
            (false, 1) => h.b()[(i - n1, 0)],
            _ => 0.0,
        });
        let c = Mat::from_fn(1, n1 + n2, |_, j| {
            if j < n1 {
                g.c()[(0, j)]
            } else {
                h.c()[(0, j - n1)]
            }
        });
        let d = Mat::from_fn(
            1,
            2,
            |_, j| if j == 0 { g.d()[(0, 0)] } else { h.d()[(0, 0)] },
        );
        StateSpace::discrete(a, b, c, d, self.ts)
    }

    /// Simulates $y = G u + H e$ (with $e = 0$ when `noise` is `None`) from the initial state
    /// `x0` of [`to_state_space`](Self::to_state_space) (zeros if `None`).
    pub fn simulate(
        &self,
        u: &[f64],
        noise: Option<&[f64]>,
        x0: Option<&[f64]>,
    ) -> Result<Vec<f64>> {
        if let Some(e) = noise {
            if e.len() != u.len() {
                return Err(Error::DimensionMismatch {
                    context: "PolyModel::simulate noise length",
                    expected: u.len().to_string(),
                    got: e.len().to_string(),
                });
            }
        }
        let ss = self.to_state_space()?;
        let um = Mat::from_fn(u.len(), 2, |k, j| {
            if j == 0 {
                u[k]
            } else {
                noise.map_or(0.0, |e| e[k])
            }
        });
        let y = ss.simulate(um.as_ref(), x0)?;
        Ok((0..u.len()).map(|k| y[(k, 0)]).collect())
    }
}
