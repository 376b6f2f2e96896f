//! Interconnection of state-space models: series, parallel and feedback.
//!
//! With $G_i = (A_i, B_i, C_i, D_i)$ and the stacked state $x = [x_1; x_2]$:
//!
//! * series, $y = G_2 G_1 u$ (the output of $G_1$ drives $G_2$):
//!   $$ A = \begin{bmatrix} A_1 & 0 \\ B_2 C_1 & A_2 \end{bmatrix},\;
//!   B = \begin{bmatrix} B_1 \\ B_2 D_1 \end{bmatrix},\;
//!   C = \begin{bmatrix} D_2 C_1 & C_2 \end{bmatrix},\; D = D_2 D_1; $$
//! * parallel, $y = (G_1 + G_2) u$: block-diagonal $A$, stacked $B$, $C = [C_1\; C_2]$,
//!   $D = D_1 + D_2$;
//! * feedback, $u_1 = r + \sigma y_2$, $y_2 = G_2 y_1$ ($\sigma = -1$ for negative feedback),
//!   so $y_1 = (I - \sigma G_1 G_2)^{-1} G_1 r$; it exists when $I - \sigma D_1 D_2$ is invertible
//!   (a well-posed loop).
//!
//! Both models must have the same sample time (or both be continuous).
//!
//! # Example
//! ```
//! use ambid_core::lti::StateSpace;
//! use faer::mat;
//! // integrator 0.1/(z - 1) in negative unity feedback: pole at z = 0.9
//! let g = StateSpace::discrete(mat![[1.0]], mat![[0.1]], mat![[1.0]], mat![[0.0]], 1e-3).unwrap();
//! let k = StateSpace::discrete(
//!     faer::Mat::zeros(0, 0), faer::Mat::zeros(0, 1), faer::Mat::zeros(1, 0), mat![[1.0]], 1e-3,
//! ).unwrap();
//! let cl = g.feedback(&k).unwrap();
//! assert!((cl.poles().unwrap()[0].re - 0.9).abs() < 1e-14);
//! ```

use super::ss::StateSpace;
use crate::error::{Error, Result};
use crate::linalg;
use faer::Mat;

/// Sign of a feedback connection.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum FeedbackSign {
    /// $u_1 = r - y_2$ (the default).
    #[default]
    Negative,
    /// $u_1 = r + y_2$.
    Positive,
}

impl FeedbackSign {
    /// $-1$ or $+1$.
    pub fn value(self) -> f64 {
        match self {
            FeedbackSign::Negative => -1.0,
            FeedbackSign::Positive => 1.0,
        }
    }
}

/// Checks that two sample times agree (both continuous, or equal to 1e-12 relative).
pub(crate) fn check_same_ts(left: Option<f64>, right: Option<f64>) -> Result<()> {
    match (left, right) {
        (None, None) => Ok(()),
        (Some(a), Some(b)) if (a - b).abs() <= 1e-12 * a.abs().max(b.abs()) => Ok(()),
        _ => Err(Error::SampleTimeMismatch {
            left: left.unwrap_or(0.0),
            right: right.unwrap_or(0.0),
        }),
    }
}

fn dims(context: &'static str, expected: usize, got: usize) -> Result<()> {
    if expected != got {
        return Err(Error::DimensionMismatch {
            context,
            expected: expected.to_string(),
            got: got.to_string(),
        });
    }
    Ok(())
}

impl StateSpace {
    /// Series connection $y = G_{\text{next}}\, G_{\text{self}}\, u$: the outputs of `self` drive
    /// the inputs of `next` (MATLAB `series(self, next)`).
    pub fn series(&self, next: &StateSpace) -> Result<StateSpace> {
        check_same_ts(self.ts(), next.ts())?;
        dims(
            "series (outputs of the first vs inputs of the second)",
            self.noutputs(),
            next.ninputs(),
        )?;
        let (n1, n2) = (self.order(), next.order());
        let (a1, b1, c1, d1) = (self.a(), self.b(), self.c(), self.d());
        let (a2, b2, c2, d2) = (next.a(), next.b(), next.c(), next.d());
        let b2c1 = b2 * c1;
        let b2d1 = b2 * d1;
        let d2c1 = d2 * c1;
        let a = Mat::from_fn(n1 + n2, n1 + n2, |i, j| match (i < n1, j < n1) {
            (true, true) => a1[(i, j)],
            (true, false) => 0.0,
            (false, true) => b2c1[(i - n1, j)],
            (false, false) => a2[(i - n1, j - n1)],
        });
        let b = Mat::from_fn(n1 + n2, self.ninputs(), |i, j| {
            if i < n1 {
                b1[(i, j)]
            } else {
                b2d1[(i - n1, j)]
            }
        });
        let c = Mat::from_fn(next.noutputs(), n1 + n2, |i, j| {
            if j < n1 {
                d2c1[(i, j)]
            } else {
                c2[(i, j - n1)]
            }
        });
        let d = d2 * d1;
        StateSpace::new(a, b, c, d, self.ts())
    }

    /// Parallel connection $y = (G_{\text{self}} + G_{\text{other}})\, u$.
    pub fn parallel(&self, other: &StateSpace) -> Result<StateSpace> {
        check_same_ts(self.ts(), other.ts())?;
        dims("parallel (inputs)", self.ninputs(), other.ninputs())?;
        dims("parallel (outputs)", self.noutputs(), other.noutputs())?;
        let (n1, n2) = (self.order(), other.order());
        let a = Mat::from_fn(n1 + n2, n1 + n2, |i, j| match (i < n1, j < n1) {
            (true, true) => self.a()[(i, j)],
            (false, false) => other.a()[(i - n1, j - n1)],
            _ => 0.0,
        });
        let b = Mat::from_fn(n1 + n2, self.ninputs(), |i, j| {
            if i < n1 {
                self.b()[(i, j)]
            } else {
                other.b()[(i - n1, j)]
            }
        });
        let c = Mat::from_fn(self.noutputs(), n1 + n2, |i, j| {
            if j < n1 {
                self.c()[(i, j)]
            } else {
                other.c()[(i, j - n1)]
            }
        });
        let d = self.d() + other.d();
        StateSpace::new(a, b, c, d, self.ts())
    }

    /// Negative feedback $y = (I + G K)^{-1} G r$ with `k` in the feedback path.
    pub fn feedback(&self, k: &StateSpace) -> Result<StateSpace> {
        self.feedback_with_sign(k, FeedbackSign::Negative)
    }

    /// Feedback with the given sign: $u = r + \sigma K y$, $y = G u$, so
    /// $y = (I - \sigma G K)^{-1} G r$. The result maps $r$ to $y$ (outputs of `self`).
    ///
    /// Both parts enter in their [`StateSpace::well_conditioned`] realisation (the same model;
    /// bit for bit the given one unless near-equal poles carry cancelling residues), so that the
    /// closed loop's poles are those of the models and not of their rounding. The result's
    /// states are those of the two realisations, $x = (x_1, x_2)$.
    ///
    /// Errors if $I - \sigma D_G D_K$ is singular (an algebraic loop without a solution).
    pub fn feedback_with_sign(&self, k: &StateSpace, sign: FeedbackSign) -> Result<StateSpace> {
        check_same_ts(self.ts(), k.ts())?;
        let (g, k) = (self.well_conditioned(), k.well_conditioned());
        let this = &g;
        let k = &k;
        dims(
            "feedback (plant outputs vs feedback inputs)",
            this.noutputs(),
            k.ninputs(),
        )?;
        dims(
            "feedback (feedback outputs vs plant inputs)",
            k.noutputs(),
            this.ninputs(),
        )?;
        let s = sign.value();
        let (n1, n2) = (this.order(), k.order());
        let (p, m) = (this.noutputs(), this.ninputs());
        let (a1, b1, c1, d1) = (this.a(), this.b(), this.c(), this.d());
        let (a2, b2, c2, d2) = (k.a(), k.b(), k.c(), k.d());
        // y1 = E (C1 x1 + s D1 C2 x2 + D1 r),  E = (I - s D1 D2)^{-1}
        let d1d2 = d1 * d2;
        let emat = Mat::from_fn(p, p, |i, j| f64::from(u8::from(i == j)) - s * d1d2[(i, j)]);
        let d1c2 = d1 * c2;
        let rhs_c = Mat::from_fn(p, n1 + n2, |i, j| {
            if j < n1 {
                c1[(i, j)]
            } else {
                s * d1c2[(i, j - n1)]
            }
        });
        let ill = |_| {
            Error::numerical(
                "feedback",
                "I - sign·D_G·D_K is singular: the loop is not well posed",
            )
        };
        let cy = linalg::solve(emat.as_ref(), rhs_c.as_ref()).map_err(ill)?;
        let dy = linalg::solve(emat.as_ref(), d1).map_err(ill)?;
        // u1 = s (C2 x2 + D2 y1) + r
        let d2cy = d2 * &cy;
        let d2dy = d2 * &dy;
        let cu = Mat::from_fn(m, n1 + n2, |i, j| {
            s * (d2cy[(i, j)] + if j >= n1 { c2[(i, j - n1)] } else { 0.0 })
        });
        let du = Mat::from_fn(m, m, |i, j| f64::from(u8::from(i == j)) + s * d2dy[(i, j)]);
        let b1cu = b1 * &cu;
        let b2cy = b2 * &cy;
        let a = Mat::from_fn(n1 + n2, n1 + n2, |i, j| {
            if i < n1 {
                b1cu[(i, j)] + if j < n1 { a1[(i, j)] } else { 0.0 }
            } else {
                b2cy[(i - n1, j)] + if j >= n1 { a2[(i - n1, j - n1)] } else { 0.0 }
            }
        });
        let b1du = b1 * &du;
        let b2dy = b2 * &dy;
        let b = Mat::from_fn(n1 + n2, m, |i, j| {
            if i < n1 {
                b1du[(i, j)]
            } else {
                b2dy[(i - n1, j)]
            }
        });
        StateSpace::new(a, b, cy, dy, this.ts())
    }
}
