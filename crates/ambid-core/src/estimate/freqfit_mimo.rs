//! MIMO state-space models fitted to matrix frequency-response data: a frequency-domain subspace
//! step, vector-fitting starts from its poles and from poles spread over the band, each refined
//! by Levenberg–Marquardt on the weighted complex error of every entry, the best kept (discrete
//! time, $n_y \times n_u$, open-loop unstable plants admitted and never stabilised).
//!
//! # Criterion
//! [`ss_frd_mimo`] minimises, over the $n$-th order models
//! $\hat G(z) = C (zI - A)^{-1} B + D$ ($D = 0$ unless [`MimoFreqOptions::feedthrough`]),
//! $$ V = \sum_{k=1}^{L} \sum_{i=1}^{n_y} \sum_{j=1}^{n_u} w_{k,ij}\,
//!     \bigl| \hat G_{ij}(z_k) - G_{k,ij} \bigr|^2 , \qquad z_k = e^{j\omega_k T}, $$
//! with $w_{k,ij} = 1/\sigma^2_{k,ij}$, the inverse of the variance $\sigma^2 = E|\hat G - G|^2$
//! that a nonparametric estimate carries ([`MimoWeights::InverseVariance`], the default when
//! the [`Frd`] has variances). With those weights $V$ is a sum of $L n_y n_u$ unit-variance
//! complex residuals at the true model, so $V \approx L n_y n_u - n_\theta/2$ when the model
//! class holds the plant (a check of the fit, [`MimoFreqFit::normalised_cost`]). Without
//! variances the entries are weighted by $1/(a_i b_j)^2$, $a_i b_j$ a rank-one fit of their RMS
//! over the band ([`MimoWeights::Uniform`]), so that an output in metres and one in volts count
//! alike.
//!
//! # 1. Subspace start
//! The frequency-domain subspace method of McKelvey, Akçay and Ljung (1996), with several inputs
//! and outputs: with $X_k = (\zeta_k I - A)^{-1} B$ ($n \times n_u$), $\zeta_k^p G_k = C A^p X_k +
//! \sum_{i<p} C A^{p-1-i} B \zeta_k^i + D\zeta_k^p$, so the $q n_y \times L n_u$ matrix
//! $\mathbf G = [W_q(\zeta_k) \otimes G_k]_k$ and the $q n_u \times L n_u$ matrix
//! $\mathbf U = [W_q(\zeta_k) \otimes I_{n_u}]_k$, $W_q(\zeta) = [1, \zeta, \dots, \zeta^{q-1}]^\top$,
//! satisfy $\mathbf G = \mathcal O_q \mathbf X + \Gamma_q \mathbf U$. The block column of line
//! $k$ is scaled by $\sqrt{\bar w_k}$ (a scalar per line, the mean weight of its entries in the
//! channel scaling above), real and imaginary parts are put side by side, and the LQ
//! factorisation of $[\mathbf U; \mathbf G]$ removes the input part:
//! $\mathbf G \Pi^\perp_{\mathbf U} = L_{22} Q_2^\top$. The $n$ leading left singular vectors of
//! $L_{22}$ span $\mathcal O_q$ (its singular values, [`MimoFreqFit::singular_values`] and
//! [`subspace_singular_values`], show the order); $C$ is its first block row and $A$ follows from
//! the shift invariance by least squares. The step runs in the warped variable
//! $\zeta = (z - a)/(1 - a z)$ of [`freqfit_ss`](super::freqfit_ss), which maps the band's
//! geometric centre to $\zeta = j$ (the poles of an AMB plant at 20 kHz sit near $z = 1$, where
//! the powers $z^p$ are nearly collinear). The pair $(A_\zeta, C_\zeta)$ is mapped back exactly:
//! $$ A_z = (I + a A_\zeta)^{-1} (aI + A_\zeta), \qquad C_z = C_\zeta (I - a A_z), $$
//! because $C_\zeta(\zeta I - A_\zeta)^{-1} = C_\zeta (1 - az)(zI - A_z)^{-1}(I + aA_\zeta)^{-1}$ and
//! $(1 - az)(zI - A_z)^{-1} = -aI + (I - aA_z)(zI - A_z)^{-1}$; the constant goes into $D$ and the
//! factor on the right into $B$, both of which are estimated next.
//!
//! # 1b. Vector-fitting starts
//! On noisy data the subspace poles are biased (on the 4-axis twin the start is 25–55 % off and
//! the refinement from it stops in poor local minima). The poles are therefore relocated by
//! vector fitting with poles common to all entries (Gustavsen & Semlyen 1999, the weights
//! above, unstable poles **not** flipped), twice: from the subspace step's $n$ poles and from
//! $n$ poles spread log-uniformly over the band as lightly damped pairs. For the relocated poles
//! the residues are full $n_y \times n_u$ matrices, so the vector-fitting model has up to
//! $n \min(n_y, n_u)$ states; each run gives two starts of order $n$ (details in the private
//! `vf` module):
//! * **band-balanced truncation**: the whole model (Gilbert's realisation, a state per
//!   rank-one part of each residue) balanced on the band's lines — the gramians
//!   $\operatorname{Re}\sum_k H_k H_k^{\mathsf H}$ and $\operatorname{Re}\sum_k F_k^{\mathsf H}
//!   F_k$ of $H_k = (z_kI - A)^{-1}B$, $F_k = C(z_kI - A)^{-1}$, which exist for unstable models
//!   too — and truncated to its $n$ leading states: the states that carry the response *in the
//!   band*, so the start keeps what the whole model does there (on the nominal twin at order
//!   16 it leads to 0.19 % plant error, where the rank-one start below ends at 5.5 %);
//! * **dominant rank-one parts**: the parts $\sigma_{m,r} u_{m,r} v_{m,r}^{\mathsf H}$ of the
//!   residues of largest size in the band (a repeated pole of a minimal model, e.g. four
//!   identical amplifiers, is one pole with a residue of rank up to four), one state per real
//!   pole's part and two per pair's.
//!
//! Every start (up to four; the subspace start itself only when none can be formed) is
//! *probed*: [`PROBE_ITERATIONS`] steps of the refinement below without the loop constraint
//! (the starts and the probes run in parallel; each works on its own copy, so the result does
//! not depend on the number of threads). The [`REFINED_STARTS`] lowest in weighted cost after
//! the probe are refined to the end, one after the other in that order, and the fit of lowest
//! final cost is returned. A later run is *raced* against the best final cost $V^\ast$ so far:
//! it is abandoned when neither the Gauss–Newton step's predicted reduction $\lVert z\rVert^2$
//! nor its pace over the last five steps, kept up for the rest of its iteration budget, can
//! bring its cost more than $\kappa^2\hat\sigma^2$ below $V^\ast$ ($\kappa^2$ of the stopping
//! rule below: the best run itself stopped up to that far above its minimum, so a run that
//! can end only within it of $V^\ast$ cannot be told apart from it). Both predictions are
//! optimistic, so a run that could still win goes on. A truncation that keeps noise-level states can start
//! far off (on the nominal twin at order 20 the balanced start's first stage stalled at a
//! weighted cost near 98 000, where the rank-one start's went below 5 400), and the probe is
//! what tells.
//!
//! # 2. Modal block form and the linear step
//! $A_z$ is brought to block-diagonal form by its eigenvectors: a complex pair $\lambda, \bar\lambda$
//! with eigenvector $v$ spans $[\operatorname{Re} v, \operatorname{Im} v]$; each real pole is a
//! $1 \times 1$ block (two real poles of different planes have no output that sees both, so a
//! $2 \times 2$ companion block of them would be singular). Each $2 \times 2$
//! block is put in the **delta-operator companion form**
//! $$ A_b = I + h M_b, \quad M_b = \begin{bmatrix} 0 & 1 \\ -\alpha_{b,2} & -\alpha_{b,1}\end{bmatrix},
//! \qquad \delta = \frac{z - 1}{h}, \quad h = \bigl|e^{j\omega_c T} - 1\bigr|, $$
//! with the row $o_b$ of $C_b$ whose transform below is best conditioned ($|\det \mathcal O|$ largest) fixed at $[1\;0]$ (by
//! $x' = \mathcal O x$, $\mathcal O = [c;\, c(A_b - I)/h]$, $c = C_{o_b}$), so that
//! $$ \hat G(z) = D + \sum_b C_b\, (\delta I - M_b)^{-1}\, \beta_b , \qquad
//! (\delta I - M_b)^{-1} = \frac{1}{\delta^2 + \alpha_{b,1}\delta + \alpha_{b,2}}
//! \begin{bmatrix} \delta + \alpha_{b,1} & 1 \\ -\alpha_{b,2} & \delta \end{bmatrix}, $$
//! and $B_b = h \beta_b$ (a $1 \times 1$ block: $A_b = 1 + h\lambda_b$, $C_{o_b, b} = 1$). The
//! oversampled poles near $z = 1$ make the shift-form coefficients nearly collinear; the
//! delta-form ones are not (see [`ss_pem`](super::ss_pem)). With the poles and $C$ fixed,
//! $\hat G$ is linear in $(\beta, D)$, which are fitted by weighted linear least squares (one
//! problem per input column).
//!
//! # 3. Refinement
//! Levenberg–Marquardt ([`minimize_resumed`]) over $\theta = (\alpha_b, \beta_b, \text{free rows of }
//! C_b)_b$ and $D$; per block $\dim_b(1 + n_u + n_y - 1)$ parameters, the dimension of a
//! McMillan-degree-$\dim_b$ block with given poles, so the parameterisation is locally
//! identifiable for distinct poles (repeated poles, e.g. the two identical planes of a rotor at
//! standstill, leave a mixing of their blocks free; the damped step handles the flat
//! directions). With $Y_b = C_b R_b$ and $X_b = R_b \beta_b$, $R_b = (\delta I - M_b)^{-1}$, the
//! Jacobian is analytic:
//! $\partial \hat G / \partial \beta_b[r, j] = Y_b[:, r]\, e_j^\top$,
//! $\partial \hat G / \partial C_b[i, r] = e_i\, X_b[r, :]$,
//! $\partial \hat G / \partial \alpha_{b,1} = -Y_b[:, 2]\, X_b[2, :]$,
//! $\partial \hat G / \partial \alpha_{b,2} = -Y_b[:, 2]\, X_b[1, :]$,
//! $\partial \hat G / \partial \lambda_b = Y_b X_b$. The residuals are the real and imaginary
//! parts of $\sqrt{w_{k,ij}}(\hat G_{ij}(z_k) - G_{k,ij})$, ordered by input column.
//!
//! **Variable projection.** $\hat G$ is linear in $(\beta, D)$, so the iteration runs over the
//! nonlinear parameters $\psi = (\alpha_b, \text{free rows of } C_b)_b$ alone (Golub & Pereyra
//! 1973): at every evaluation $(\beta, D)$ are the weighted least-squares solution for $\psi$
//! (one problem per input column $j$, regressor $\Phi_j(\psi)$ with thin QR factor $Q_j$), and
//! the residual is $r_j = -(I - Q_jQ_j^{\mathsf T}) W_j g_j$, the part of the data no numerator
//! can fit. The Jacobian is Kaufman's (1975): the $\psi$-columns of the Jacobian above at the
//! fitted $\beta$, projected per input column, $J_j = (I - Q_jQ_j^{\mathsf T}) \, \partial(\Phi_j
//! \beta_j)/\partial\psi$; the term it drops is proportional to the residual (zero on exact
//! data, tested against finite differences there). At order 16 on the 4×4 plant this halves the
//! unknowns of each step (64 instead of 128) and, on the nominal twin, took the fit from 14 s
//! to about 4 s with the stopping rule and the race of that time (2026-11-29 morning).
//!
//! **Structured triangle.** All that a Levenberg–Marquardt step uses of the Jacobian is the
//! triangle of $[J\;r]$ ([`LeastSquaresProblem::triangle`]), and the projected $J$ is never
//! formed: for input column $j$ the triangle of $[\Phi_j\;\tilde J_j\;r_j]$ ($\tilde J_j$ the
//! unprojected ψ-columns) holds the triangle of $[(I - Q_jQ_j^{\mathsf T})\tilde J_j\;r_j]$ as
//! its trailing block (the Schur complement of $\Phi_j^{\mathsf T}\Phi_j$ in the Gram matrix;
//! $r_j$ is already orthogonal to $\Phi_j$). The rows of output $i$ see only that output's
//! free $C$ entries (and $D_{ij}$), so they are factored per output — those columns first,
//! then the poles', the regressor's and $r$ — and the $n_y$ small triangles are stacked and
//! factored once more in the order $[\Phi_j \mid \psi \mid r]$; the input columns' trailing
//! blocks are stacked and factored last. Every factor is a Householder QR (no Gram matrix, no
//! squared condition number); a rank-deficient $\Phi_j$ (repeated poles) gives a zero row in
//! its part of the triangle and leaves the trailing block right (tested against the dense
//! projected Jacobian, full-rank and rank-deficient). At order 16 on the 4×4 twin (253 lines)
//! this replaces the $8\,096 \times 65$ QR, the thin $Q$ of every regressor and the projection
//! ($\approx 110$ Mflop per step) by sixteen $506 \times 46$ QRs and small ones ($\approx 45$
//! Mflop).
//!
//! **Stopping.** The statistical rule of [`LmOptions::with_significance_tol`] with
//! $\kappa^2 = $ [`significance_kappa2`] $= \sqrt{n_\theta/2}$: stop when what the Gauss–Newton
//! step could still gain, $\lVert z\rVert^2$, is below $\sqrt{n_\theta/2}\,\hat\sigma^2$. At
//! the exact minimiser the weighted response error of the model has energy
//! $\sigma^2\chi^2_{n_\theta}$ (one $\sigma^2$ per parameter): mean $n_\theta\sigma^2$, standard
//! deviation $\sqrt{2n_\theta}\,\sigma^2$. The rule stops when the remaining gain is below half
//! that standard deviation, so the stopped model cannot be told from the minimiser by its own
//! error (at $n_\theta = 128$: $8\hat\sigma^2$ of a mean $128\hat\sigma^2$). Until 2026-11-29 the
//! rule was $\lVert z\rVert^2 \le 0.01\,n_\theta\hat\sigma^2$: on the nominal twin at order 16
//! it took 65 steps where this one takes 36, for a plant error of 0.198 % against 0.191 %.
//! A rule per parameter ($\kappa = 0.1$, as the prediction-error estimators use) kept the
//! iteration crawling along the flat valley of the four nearly equal amplifier poles above the
//! band (it gained $2\hat\sigma^2$ in 100 steps on the nominal twin) without changing the plant
//! error.
//!
//! **Crawl stop.** Where the model class cannot hold the data (the nonlinear twin's best
//! linear approximation, whose periodic distortion the variances do not show; a poor local
//! minimum) the Gauss–Newton model keeps promising a large gain along a nearly flat direction
//! while each trust-region step delivers a sliver of it, and the rule above never fires
//! (nominal nonlinear twin, order 16: 200 steps, $\lVert z\rVert^2 \approx 1\,800\hat\sigma^2$
//! promised to the end). The iteration therefore also stops when the last [`CRAWL_WINDOW`]
//! $= 10$ accepted steps together gained less than $\kappa^2\hat\sigma^2/2$ in
//! $\tfrac12\lVert r\rVert^2$ ([`StopReason::Crawl`]): as many steps again at that pace
//! would gain less than the significance rule calls invisible. Measured 2026-11-29 with
//! `mimo_fit_sweep` (nominal twin and random rigs 1, 2, 3, 5; orders 16, 20, 24; linear and
//! nonlinear; seed 1): the 30 fits took 29 % less time in total (linear) and 37 % less
//! (nonlinear); the plant error of the order BIC chooses did not change by more than
//! 0.05 points on any of them, and the nominal nonlinear order-24 fit improved
//! (5.4 % → 1.1 %, its probes ranked differently).
//!
//! **Continuation and parallel steps.** A refinement continues its probe with the probe's trust
//! region ([`minimize_resumed`]; restarted, the radius began at its initial size and the first
//! ten steps were spent shrinking it). Within a step the input columns' linear problems and
//! their parts of the structured triangle run side by side; the cut is by input column, so it
//! depends on the data only.
//!
//! Unstable poles are admitted (the AMB plant has one per rigid-body degree of freedom and
//! axis). [`MimoFreqOptions::max_unstable_poles`] holds the fit to at most that many poles on or
//! outside the unit circle: the start mirrors ($z \mapsto 1/\bar z$) the unstable blocks whose
//! mirroring costs least, one at a time, until the count is met, refits the linear parameters,
//! and Levenberg–Marquardt rejects every trial with more unstable poles; nothing is reflected
//! after the fit, so the result is the best model in the admissible set. In
//! [`ss_frd_mimo_in_loop`] the limit defaults to the count the measured loop shows (when the
//! lines support one): without it the first stage wanders into models with spurious fast
//! unstable poles (a fit of the phase lag of the amplifiers, sensors and delay above the band)
//! that the loop constraint must then mirror away from a far-off point.
//!
//! # 4. Unresolved pairs (the damping floor)
//! The lines fix a stable pole pair's frequency and residue through the lines beside it, but
//! not its damping when its half-power bandwidth $B = -2\operatorname{Re}s/2\pi = 2\zeta f_n$
//! ($s = \ln z / T$) is below the spacing $\Delta$ of the two lines around it: between the
//! lines the response of such a pair is set by nothing measured. A refinement that uses a pair
//! for a narrow feature of one or two lines (a remnant of the 1× line, the distortion of a best
//! linear approximation) may end with $\zeta$ of $10^{-8}$ or less, and the model then
//! answers up to $10^9$ times the neighbouring lines' size at its pole (random machine rigs 13
//! and 28 of the nonlinear twin, docs/uncertainty.md); whatever evaluates the model between the
//! lines (a robust-stability test on a dense grid, a Bode plot, a controller design) sees a
//! resonance the data never showed. So, with [`MimoFreqOptions::damping_floor`] (the
//! default), after the refinement each stable complex pair inside the lines with $B < \Delta$,
//! narrowest relative to its $\Delta$ first, is moved to the bandwidths $B' = \Delta,
//! \Delta/2, \Delta/4, \dots$ (while $B' > B$; its damped frequency kept), the numerators
//! $(\beta, D)$ refitted by the linear step, and the first $B'$ is kept whose weighted cost rise
//! is within the likelihood-ratio test of one real constraint,
//! $$ 2(V' - V) \le \chi^2_{1,\,0.99}\,\max(1,\; 2V/\nu) $$
//! ([`FLOOR_CHI2_1`]; the normalised cost scales the threshold where the model class does not
//! hold the data, as in an F-test), and whose model stays admissible (the unstable-pole limit
//! and, with a controller, a stable loop). Where no $B'$ passes, the pair stays as fitted. The
//! test needs a cost in units of the noise, so the floor acts only with inverse-variance
//! weights; with uniform weights (an FRF without variances) nothing is floored. So a
//! pair is given the largest damping, at most the spacing's, that the data do not reject: a
//! real lightly damped mode with a line near its peak is kept, because moving it raises the
//! cost far beyond the threshold (test
//! `an_unresolved_spurious_pair_is_floored_and_a_real_light_mode_is_kept`: the plant's own pair
//! of bandwidth 3.2 Hz on 4 Hz lines is kept bit for bit, a pair of $\zeta = 10^{-9}$ between
//! two lines floored). The numerators alone are refitted, not $C$ or the other poles, so the
//! rise is an upper bound of the likelihood-ratio statistic and the test errs towards keeping
//! the fit. The parameter count (and so BIC) is unchanged. [`MimoFreqFit::floored`] lists the
//! pairs moved; the `[machine]` report names them.
//!
//! # 5. The returned realisation
//! Two blocks may end with a real pole (or a pair) in common to within $10^{-9}$ and residues
//! that are huge and nearly opposite: the refinement's way to write a nearly double pole in
//! modal form (repeated poles leave the blocks' mixing free, § 3). The response is accurate,
//! but the closed loop formed from that realisation is not: its state matrix carries
//! $B D_c C$ at the residues' size, and its computed poles move by far more than the model's
//! content (linear machine rig 21: gain interval 0.98…1.02 from the state matrix, 0.41…5.04
//! in 50-digit arithmetic). So the model is returned in its
//! [`StateSpace::well_conditioned`] realisation: the same response (checked to $10^{-6}$),
//! the cancellation removed by an exact similarity within each cluster of near-equal poles;
//! a model without such a cluster is returned as realised. The loop constraint of § 3 forms
//! its closed loop through [`StateSpace::feedback`], which conditions the same way.
//!
//! # Requirements on the problem
//! * a discrete-time [`Frd`] (its sample time is the model's) with at least one line in the
//!   band, finite values, and positive variances when inverse-variance weights are used;
//! * more real equations $2 L n_y n_u$ than parameters, and $2 L n_u \ge q (n_u + n_y)$ for the
//!   projection of the subspace step (the horizon $q$ defaults to
//!   $\min(\lceil n/n_y \rceil + \lceil n / (2 n_y) \rceil + 2, \cdot)$, bounded by the lines);
//! * the order at most $q n_y$; distinct (or diagonalisable repeated) poles for the block form.
//!
//! # Reference
//! B. Gustavsen, A. Semlyen, "Rational approximation of frequency domain responses by vector
//! fitting", *IEEE Trans. Power Delivery* 14(3), 1999 (the relocation; its "fast" form, with
//! each entry's own unknowns projected out, is D. Deschrijver et al., *IEEE Microwave and
//! Wireless Components Letters* 18(6), 2008);
//! G. H. Golub, V. Pereyra, "The differentiation of pseudo-inverses and nonlinear least
//! squares problems whose variables separate", *SIAM J. Numer. Anal.* 10(2), 1973; L. Kaufman,
//! "A variable projection method for solving separable nonlinear least squares problems", *BIT*
//! 15, 1975;
//! T. McKelvey, H. Akçay, L. Ljung, "Subspace-based multivariable system identification from
//! frequency response data", *IEEE Trans. Automatic Control* 41(7), 1996;
//! R. Pintelon, J. Schoukens, *System Identification: A Frequency Domain Approach*, 2nd ed.,
//! Wiley–IEEE Press, 2012 (chapter 9: the weighted least-squares criterion with the
//! nonparametric variance as weight, and its $\chi^2$ check);
//! R. H. Middleton, G. C. Goodwin, *Digital Control and Estimation: A Unified Approach*,
//! Prentice Hall, 1990 (the delta operator).
//!
//! # Example
//! A $2 \times 2$ plant with an unstable real pole and a lightly damped pair, recovered from its
//! exact response on 80 lines:
//! ```
//! use ambid_core::estimate::freqfit_mimo::{ss_frd_mimo, MimoFreqOptions};
//! use ambid_core::lti::{Frd, StateSpace};
//! use faer::mat;
//! let (r, w) = (0.995f64, 0.05f64);
//! let truth = StateSpace::discrete(
//!     mat![[1.01, 0.0, 0.0], [0.0, r * w.cos(), r * w.sin()], [0.0, -r * w.sin(), r * w.cos()]],
//!     mat![[1.0, 0.5], [0.0, 1.0], [1.0, -0.3]],
//!     mat![[1.0, 0.2, 0.0], [0.4, 0.0, 1.0]],
//!     mat![[0.0, 0.0], [0.0, 0.0]],
//!     1e-3,
//! ).unwrap();
//! let f: Vec<f64> = (1..=80).map(|k| 2.0 * k as f64).collect();
//! let frd = Frd::from_model(&truth, &f).unwrap();
//! let fit = ss_frd_mimo(&frd, 3, &MimoFreqOptions::default()).unwrap();
//! assert!(fit.errors.median_norm_relative < 1e-9);
//! let unstable = fit.model.poles().unwrap().iter().filter(|z| z.norm() > 1.0).count();
//! assert_eq!(unstable, 1);
//! ```

// the loops index several parallel arrays (data, weights, channel scales) by line and entry
#![allow(clippy::needless_range_loop)]

use super::pem::lm::{
    all_finite, minimize_resumed, LeastSquaresProblem, LmOptions, LmState, StopReason,
};
use crate::error::{Error, Result};
use crate::estimate::qr_stream::{r_factor_in_place, r_factor_tall};
use crate::linalg;
use crate::lti::{Frd, StateSpace};
use faer::{c64, Mat, MatRef};
use rayon::prelude::*;

mod vf;

const CTX: &str = "ss_frd_mimo";

/// The refinement's $\kappa^2$ for $n_\theta$ parameters (module docs, "Stopping"):
/// $\kappa^2 = \sqrt{n_\theta / 2}$, half the standard deviation $\sqrt{2 n_\theta}$ of the
/// exact minimiser's own response-error energy in units of $\hat\sigma^2$. The refinement stops
/// when what the Gauss–Newton step could still gain is below $\kappa^2 \hat\sigma^2$
/// ([`LmOptions::with_significance_tol`] with $\kappa$), and a raced run must be able to end at
/// least that far below the best one to go on.
pub fn significance_kappa2(n_theta: usize) -> f64 {
    (n_theta as f64 / 2.0).sqrt()
}

/// The refinement's options for a run in `layout` of at most `iterations` steps (at least 1):
/// the stopping rule with $\kappa^2$ = [`significance_kappa2`] and the crawl stop. (The
/// triangle of each step is [`Projected`]'s own, cut by input column.)
fn lm_options(layout: &Layout, iterations: usize) -> Result<LmOptions> {
    LmOptions::default()
        .with_max_iterations(iterations.max(1))?
        .with_significance_tol(significance_kappa2(layout.n_theta).sqrt())
        .map(|o| o.with_crawl_window(CRAWL_WINDOW))
}

/// Accepted steps over which the refinement's progress is measured for the crawl stop
/// ([`StopReason::Crawl`]; module docs, "Stopping").
pub const CRAWL_WINDOW: usize = 10;

/// How the entries of the FRF are weighted (module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum MimoWeights {
    /// Inverse variances when the [`Frd`] has them, else [`MimoWeights::Uniform`] (default).
    #[default]
    Auto,
    /// $w_{k,ij} = 1/\sigma^2_{k,ij}$; an error when the [`Frd`] has no variance or a zero one.
    InverseVariance,
    /// $w_{k,ij} = 1/(a_i b_j)^2$ with $a_i b_j$ a rank-one fit of the entries' RMS on the band.
    Uniform,
}

/// Options of [`ss_frd_mimo`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MimoFreqOptions {
    /// Band $[f_{\min}, f_{\max}]$ in Hz (inclusive); `None` uses every line.
    pub band_hz: Option<(f64, f64)>,
    /// Weights of the entries (default [`MimoWeights::Auto`]).
    pub weights: MimoWeights,
    /// Iteration limit of the Levenberg–Marquardt refinement (default 100; 0 keeps the start).
    pub max_iterations: usize,
    /// At most this many poles on or outside the unit circle (default `None`: unconstrained).
    /// Never a repair: the start mirrors the surplus and the refinement stays admissible.
    pub max_unstable_poles: Option<usize>,
    /// Estimate a feedthrough $D$ (default `false`: strictly proper).
    pub feedthrough: bool,
    /// Block rows $q$ of the subspace step (default: module docs).
    pub horizon: Option<usize>,
    /// A level the caller needs the weighted cost to reach (default `None`: every refinement
    /// runs to its stopping rule). A refinement is abandoned as soon as the race rule of the
    /// module docs ("Refinement") says that it cannot end at or below the level; when every
    /// refined start is abandoned, the result is the lowest-cost state reached, with
    /// [`MimoFreqFit::abandoned`] set. For a caller that only uses the fit if it reaches the
    /// level (a scan of orders that stops at the noise level, or compares by BIC with a fit
    /// it already has), the rest of such a refinement is time lost.
    pub abandon_unless: Option<CostTarget>,
    /// Give the stable pole pairs the lines do not resolve the damping of their line spacing
    /// where the data do not reject it (default `true`; module docs, "4. Unresolved pairs").
    pub damping_floor: bool,
}

/// A level of the weighted cost $V$ ([`MimoFreqOptions::abandon_unless`]), with
/// $\nu = 2Ln_yn_u - n_\theta$ the residual degrees of freedom.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum CostTarget {
    /// The noise level: $2V/\nu \le 1 + q\sqrt{2/\nu}$, the one-sided quantile $q$ of the
    /// normal approximation of $\chi^2_\nu/\nu$, which $2V/\nu$ follows when the model holds
    /// the plant and the inverse-variance weights are right ($q = 2.326$: 99 %).
    NoiseLevel {
        /// The quantile $q$.
        quantile: f64,
    },
    /// The Bayesian information criterion ([`MimoFreqFit::bic`]) at most this value.
    Bic(f64),
}

impl CostTarget {
    /// The largest weighted cost $V$ that meets the level, for `n_equations` real equations
    /// and `n_params` parameters.
    ///
    /// ```
    /// use ambid_core::estimate::freqfit_mimo::CostTarget;
    /// // ν = 1000: 2V/ν ≤ 1 + 2·√(2/1000)
    /// let v = CostTarget::NoiseLevel { quantile: 2.0 }.cost_bound(1064, 64);
    /// assert!((v - 500.0 * (1.0 + 2.0 * (0.002f64).sqrt())).abs() < 1e-9);
    /// // BIC = 2V + n_θ ln(2 L n_y n_u)
    /// let b = CostTarget::Bic(2000.0).cost_bound(1064, 64);
    /// assert!((b - 0.5 * (2000.0 - 64.0 * 1064f64.ln())).abs() < 1e-9);
    /// ```
    pub fn cost_bound(&self, n_equations: usize, n_params: usize) -> f64 {
        match *self {
            CostTarget::NoiseLevel { quantile } => {
                let nu = n_equations.saturating_sub(n_params).max(1) as f64;
                0.5 * nu * (1.0 + quantile * (2.0 / nu).sqrt())
            }
            CostTarget::Bic(b) => 0.5 * (b - n_params as f64 * (n_equations as f64).ln()),
        }
    }
}

impl Default for MimoFreqOptions {
    fn default() -> Self {
        Self {
            band_hz: None,
            weights: MimoWeights::Auto,
            max_iterations: 100,
            max_unstable_poles: None,
            feedthrough: false,
            horizon: None,
            abandon_unless: None,
            damping_floor: true,
        }
    }
}

/// Unweighted error measures of a fitted model on the lines it was fitted to.
#[derive(Debug, Clone, PartialEq)]
pub struct MimoFreqErrors {
    /// Median over the lines of $\lVert \hat G(z_k) - G_k \rVert_2 / \lVert G_k \rVert_2$
    /// (spectral norms).
    pub median_norm_relative: f64,
    /// Largest over the lines of the same ratio.
    pub max_norm_relative: f64,
    /// Per entry (row-major $i n_u + j$): median over the lines of
    /// $|\hat G_{ij} - G_{ij}| / |G_{ij}|$.
    pub median_entry_relative: Vec<f64>,
}

/// A fitted MIMO state-space model (see [`ss_frd_mimo`]).
#[derive(Debug, Clone)]
pub struct MimoFreqFit {
    /// The model (discrete, at the data's sample time; never stabilised).
    pub model: StateSpace,
    /// Number of free real parameters.
    pub n_params: usize,
    /// The weighted cost $V$ at the result.
    pub cost: f64,
    /// Number of real equations $2 L n_y n_u$.
    pub n_equations: usize,
    /// Accepted refinement steps.
    pub iterations: usize,
    /// Whether the refinement met a convergence test.
    pub converged: bool,
    /// Whether the fit was abandoned because it could not reach
    /// [`MimoFreqOptions::abandon_unless`] (the model is then where it stopped).
    pub abandoned: bool,
    /// With [`MimoFreqFit::abandoned`]: the starts after their probe, to continue the same fit
    /// ([`ss_frd_mimo_in_loop_resumed`]).
    pub probed: Option<ProbedStarts>,
    /// Unweighted error measures on the lines used.
    pub errors: MimoFreqErrors,
    /// Singular values of the subspace step's projected data (descending).
    pub singular_values: Vec<f64>,
    /// The frequencies used \[Hz\].
    pub f_hz: Vec<f64>,
    /// The pole pairs given the damping floor ([`MimoFreqOptions::damping_floor`]).
    pub floored: Vec<FlooredPair>,
}

/// A stable pole pair the lines did not resolve, moved to the damping of its line spacing
/// (module docs, "4. Unresolved pairs").
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FlooredPair {
    /// Damped frequency $\operatorname{Im} s / 2\pi$ \[Hz\] (unchanged by the floor).
    pub f_hz: f64,
    /// Damping ratio of the fit.
    pub zeta_fitted: f64,
    /// Damping ratio after the floor.
    pub zeta_floored: f64,
    /// The spacing of the two lines around it \[Hz\].
    pub spacing_hz: f64,
    /// $2(V' - V)$, the weighted cost's rise with the numerators refitted.
    pub cost_rise: f64,
}

impl MimoFreqFit {
    /// $2V / (2 L n_y n_u - n_\theta)$: about 1 when inverse-variance weights are right and the
    /// model class holds the plant; much larger when the model is too simple.
    pub fn normalised_cost(&self) -> f64 {
        2.0 * self.cost / (self.n_equations.saturating_sub(self.n_params).max(1)) as f64
    }

    /// Bayesian information criterion of the weighted cost,
    /// $2V + n_\theta \ln(2 L n_y n_u)$ (the $-2\log$-likelihood of unit-variance complex
    /// residuals up to a constant; valid with inverse-variance weights).
    pub fn bic(&self) -> f64 {
        2.0 * self.cost + self.n_params as f64 * (self.n_equations as f64).ln()
    }

    /// Number of poles on or outside the unit circle.
    ///
    /// # Errors
    /// [`Error::Numerical`] when the eigenvalues cannot be computed.
    pub fn unstable_poles(&self) -> Result<usize> {
        Ok(self
            .model
            .poles()?
            .iter()
            .filter(|z| z.norm() >= 1.0)
            .count())
    }
}

/// The lines of a matrix [`Frd`] a fit uses, in channel-scaled units (module docs).
struct Data {
    f_hz: Vec<f64>,
    z: Vec<c64>,
    /// Scaled response, line-major, column-major per line: `g[k * ny * nu + j * ny + i]`.
    g: Vec<c64>,
    /// Weights in scaled units, same layout.
    w: Vec<f64>,
    /// Their square roots (the residuals' factors), same layout.
    sw: Vec<f64>,
    ny: usize,
    nu: usize,
    ts: f64,
    /// Output scales $a_i$ and input scales $b_j$: $G = \operatorname{diag}(a) G' \operatorname{diag}(b)$.
    a: Vec<f64>,
    b: Vec<f64>,
    /// Whether the weights are the inverse variances (the cost is then on the scale of a
    /// $\chi^2$ statistic, which the damping floor's test needs).
    inverse_variance: bool,
}

impl Data {
    fn new(frd: &Frd, opts: &MimoFreqOptions) -> Result<Self> {
        let ts = frd.ts().ok_or_else(|| {
            Error::invalid(
                "frd",
                "the FRF has no sample time; frequency-domain fits are discrete-time at the data's sample time",
            )
        })?;
        let (ny, nu) = (frd.ny(), frd.nu());
        let (lo, hi) = match opts.band_hz {
            Some((lo, hi)) if !(lo.is_finite() && hi.is_finite() && lo <= hi) => {
                return Err(Error::invalid(
                    "band_hz",
                    format!("the band must be finite with f_min <= f_max, got [{lo}, {hi}] Hz"),
                ))
            }
            Some(b) => b,
            None => (f64::NEG_INFINITY, f64::INFINITY),
        };
        let var = frd.variance();
        let use_var = match opts.weights {
            MimoWeights::Auto => var.is_some(),
            MimoWeights::InverseVariance => {
                if var.is_none() {
                    return Err(Error::invalid(
                        "weights",
                        "inverse-variance weights need an FRF with variances; use uniform weights or an estimate with its variance",
                    ));
                }
                true
            }
            MimoWeights::Uniform => false,
        };
        let e = ny * nu;
        let (mut f_hz, mut g, mut v) = (Vec::new(), Vec::new(), Vec::new());
        for (k, &f) in frd.f_hz().iter().enumerate() {
            if f < lo || f > hi {
                continue;
            }
            if f <= 0.0 || f >= 0.5 / ts {
                return Err(Error::invalid(
                    "band_hz",
                    format!("the line at {f} Hz is not strictly between 0 and the Nyquist frequency {} Hz; narrow the band", 0.5 / ts),
                ));
            }
            let vals = &frd.values()[k * e..(k + 1) * e];
            if vals.iter().any(|x| !(x.re.is_finite() && x.im.is_finite())) {
                return Err(Error::NonFinite {
                    what: "frd values",
                    index: k,
                });
            }
            f_hz.push(f);
            g.extend_from_slice(vals);
            if use_var {
                if let Some(var) = var {
                    let vv = &var[k * e..(k + 1) * e];
                    if let Some(bad) = vv.iter().find(|x| !(x.is_finite() && **x > 0.0)) {
                        return Err(Error::invalid(
                            "weights",
                            format!("the variance at {f} Hz is {bad}; inverse-variance weights need positive, finite variances (narrow the band or use uniform weights)"),
                        ));
                    }
                    v.extend_from_slice(vv);
                }
            }
        }
        let l = f_hz.len();
        if l == 0 {
            return Err(Error::invalid(
                "band_hz",
                "no line of the FRF lies in the band; widen the band",
            ));
        }
        // channel scales: rank-one fit of the entries' typical size (σ or RMS)
        let size = |i: usize, j: usize| -> f64 {
            let mut s: Vec<f64> = (0..l)
                .map(|k| {
                    if use_var {
                        v[k * e + j * ny + i].sqrt()
                    } else {
                        g[k * e + j * ny + i].norm()
                    }
                })
                .collect();
            s.sort_by(f64::total_cmp);
            s[l / 2]
        };
        let mut ln = Mat::<f64>::zeros(ny, nu);
        let mut floor = f64::INFINITY;
        let mut top = 0.0f64;
        for i in 0..ny {
            for j in 0..nu {
                let s = size(i, j);
                if s > 0.0 && s.is_finite() {
                    floor = floor.min(s);
                    top = top.max(s);
                }
                ln[(i, j)] = s;
            }
        }
        if top == 0.0 {
            return Err(Error::numerical(
                CTX,
                "the response is zero on every line of the band; there is nothing to fit",
            ));
        }
        let floor = floor.max(1e-12 * top);
        for i in 0..ny {
            for j in 0..nu {
                ln[(i, j)] = ln[(i, j)].max(floor).ln();
            }
        }
        let mean_all = (0..ny)
            .flat_map(|i| (0..nu).map(move |j| (i, j)))
            .map(|(i, j)| ln[(i, j)])
            .sum::<f64>()
            / e as f64;
        let a: Vec<f64> = (0..ny)
            .map(|i| ((0..nu).map(|j| ln[(i, j)]).sum::<f64>() / nu as f64).exp())
            .collect();
        let b: Vec<f64> = (0..nu)
            .map(|j| ((0..ny).map(|i| ln[(i, j)]).sum::<f64>() / ny as f64 - mean_all).exp())
            .collect();
        let mut w = vec![0.0; l * e];
        for k in 0..l {
            for j in 0..nu {
                for i in 0..ny {
                    let s = a[i] * b[j];
                    let idx = k * e + j * ny + i;
                    g[idx] /= s;
                    w[idx] = if use_var { s * s / v[idx] } else { 1.0 };
                }
            }
        }
        let z = f_hz
            .iter()
            .map(|f| c64::from_polar(1.0, 2.0 * std::f64::consts::PI * f * ts))
            .collect();
        let sw = w.iter().map(|v| v.sqrt()).collect();
        Ok(Self {
            f_hz,
            z,
            g,
            w,
            sw,
            ny,
            nu,
            ts,
            a,
            b,
            inverse_variance: use_var,
        })
    }

    fn len(&self) -> usize {
        self.f_hz.len()
    }

    fn entries(&self) -> usize {
        self.ny * self.nu
    }

    /// Real residuals of the criterion, $2 L n_y n_u$.
    fn rows(&self) -> usize {
        2 * self.len() * self.entries()
    }
}

/// The all-pass warp of the subspace step and the delta scale (module docs).
#[derive(Debug, Clone, Copy)]
struct Warp {
    a: f64,
    h: f64,
}

impl Warp {
    fn new(f_hz: &[f64], ts: f64) -> Self {
        let f_hi = f_hz.iter().copied().fold(0.0, f64::max);
        let f_lo = f_hz.iter().copied().fold(f_hi, f64::min).max(1e-3 * f_hi);
        let pi = std::f64::consts::PI;
        let theta_c = (2.0 * pi * (f_lo * f_hi).sqrt() * ts).min(0.9 * pi);
        let t = (theta_c / 2.0).tan();
        Self {
            a: (1.0 - t) / (1.0 + t),
            h: 2.0 * (theta_c / 2.0).sin(),
        }
    }
    fn warp(&self, z: c64) -> c64 {
        (z - self.a) / (c64::new(1.0, 0.0) - z * self.a)
    }
}

/// The default horizon of the subspace step for `order` states and `ny` outputs.
fn default_horizon(order: usize, ny: usize) -> usize {
    let per = order.div_ceil(ny);
    per + order.div_ceil(2 * ny) + 2
}

/// The horizon to use (validated against the data).
fn horizon(data: &Data, order: usize, given: Option<usize>) -> Result<usize> {
    let (l, ny, nu) = (data.len(), data.ny, data.nu);
    // the projection needs at least q(nu + ny) real columns: 2 L nu ≥ q (nu + ny)
    let q_max = (2 * l * nu) / (nu + ny);
    let q_min = order.div_ceil(ny) + 1;
    let q = given.unwrap_or_else(|| default_horizon(order, ny).min(q_max));
    if q < q_min || q > q_max {
        return Err(Error::invalid(
            "horizon",
            format!(
                "the subspace step with {order} states needs a horizon in [{q_min}, {q_max}] block rows for {l} lines of a {ny}x{nu} FRF, got {q}; lower the order or widen the band"
            ),
        ));
    }
    Ok(q)
}

/// The projected data $L_{22}$ of the subspace step and its SVD: (singular values, left singular
/// vectors).
fn projected(data: &Data, warp: &Warp, q: usize) -> Result<(Vec<f64>, Mat<f64>)> {
    let (l, ny, nu, e) = (data.len(), data.ny, data.nu, data.entries());
    let zeta: Vec<c64> = data.z.iter().map(|&z| warp.warp(z)).collect();
    // scalar line weights: the mean of the entries' weights
    let sw: Vec<f64> = (0..l)
        .map(|k| (data.w[k * e..(k + 1) * e].iter().sum::<f64>() / e as f64).sqrt())
        .collect();
    let (ru, rg) = (q * nu, q * ny);
    let cols = 2 * l * nu;
    // the transpose [U; G]ᵀ: a row per real column (Re of (k, j), then Im)
    let mut mt = Mat::<f64>::zeros(cols, ru + rg);
    for k in 0..l {
        let mut pw = c64::new(sw[k], 0.0);
        for p in 0..q {
            for j in 0..nu {
                let (row_re, row_im) = (k * nu + j, l * nu + k * nu + j);
                mt[(row_re, p * nu + j)] = pw.re;
                mt[(row_im, p * nu + j)] = pw.im;
                for i in 0..ny {
                    let y = pw * data.g[k * e + j * ny + i];
                    mt[(row_re, ru + p * ny + i)] = y.re;
                    mt[(row_im, ru + p * ny + i)] = y.im;
                }
            }
            pw *= zeta[k];
        }
    }
    let r = crate::estimate::qr_stream::r_factor(mt.as_ref());
    let l22 = Mat::from_fn(
        rg,
        rg,
        |i, j| if i >= j { r[(ru + j, ru + i)] } else { 0.0 },
    );
    let svd = l22.thin_svd().map_err(|e| {
        Error::numerical(
            CTX,
            format!("the SVD of the projected data failed ({e:?}); check the data"),
        )
    })?;
    let s: Vec<f64> = svd.S().column_vector().iter().copied().collect();
    if !(s[0] > 0.0 && s[0].is_finite()) {
        return Err(Error::numerical(
            CTX,
            "the projected data vanish: the response is a constant (or a polynomial) on the band's lines; no dynamics to fit",
        ));
    }
    Ok((s, svd.U().to_owned()))
}

/// The singular values of the subspace step's projected data (descending), for choosing the
/// order: a gap after the $n$-th shows $n$ states (module docs). `max_order` sets the horizon
/// as for a fit of that order.
///
/// # Errors
/// As [`ss_frd_mimo`] for the data and the horizon.
///
/// ```
/// use ambid_core::estimate::freqfit_mimo::{subspace_singular_values, MimoFreqOptions};
/// use ambid_core::lti::{Frd, StateSpace};
/// use faer::mat;
/// let truth = StateSpace::discrete(mat![[0.9, 0.2], [-0.2, 0.9]], mat![[1.0, 0.0], [0.0, 1.0]],
///     mat![[1.0, 0.0], [0.3, 1.0]], mat![[0.0, 0.0], [0.0, 0.0]], 1e-3).unwrap();
/// let f: Vec<f64> = (1..=60).map(|k| 5.0 * k as f64).collect();
/// let sv = subspace_singular_values(&Frd::from_model(&truth, &f).unwrap(), 6,
///     &MimoFreqOptions::default()).unwrap();
/// assert!(sv[2] < 1e-9 * sv[1]); // two states
/// ```
pub fn subspace_singular_values(
    frd: &Frd,
    max_order: usize,
    opts: &MimoFreqOptions,
) -> Result<Vec<f64>> {
    if max_order == 0 {
        return Err(Error::invalid("order", "the order must be at least 1"));
    }
    let data = Data::new(frd, opts)?;
    let q = horizon(&data, max_order, opts.horizon)?;
    let warp = Warp::new(&data.f_hz, data.ts);
    Ok(projected(&data, &warp, q)?.0)
}

/// Fits an `order`-th order discrete-time $n_y \times n_u$ state-space model to the matrix FRF
/// `frd` (module docs): subspace step, two vector-fitting starts (from its poles and from poles
/// spread over the band), modal delta blocks, Levenberg–Marquardt on the weighted complex error
/// of every entry from each start, the lower final cost kept. A $1 \times 1$ [`Frd`] is the
/// single-input single-output case.
///
/// # Errors
/// * [`Error::InvalidArgument`] for order 0, a continuous [`Frd`], a bad band, missing or zero
///   variances with inverse-variance weights, a horizon outside its range, fewer real equations
///   than parameters, or a start with fewer stable poles than
///   [`MimoFreqOptions::max_unstable_poles`] requires that cannot be mirrored;
/// * [`Error::NonFinite`] for a non-finite response in the band;
/// * [`Error::Numerical`] when the subspace step is degenerate (a response without dynamics, a
///   rank-deficient shift equation, a pole at infinity, defective repeated poles, a mode that
///   no output sees) or the refinement fails; the message says what may help (usually: lower
///   the order or widen the band).
pub fn ss_frd_mimo(frd: &Frd, order: usize, opts: &MimoFreqOptions) -> Result<MimoFreqFit> {
    fit(frd, order, opts, None, None, Origin::Scratch)
}

/// [`ss_frd_mimo`] held to models whose loop with `controller` is stable: the measured closed
/// loop $u = -C y + r$ was stable, so a model whose loop with the same controller is not
/// contradicts the data (typically through spurious fast unstable poles outside the band). The
/// constraint is part of the fit, as [`MimoFreqOptions::max_unstable_poles`] is: the start
/// mirrors ($z \mapsto 1/\bar z$) the unstable blocks whose mirroring leaves the fewest unstable
/// closed-loop poles at the lowest cost until the loop is stable, and the refinement rejects
/// every trial whose loop is unstable. The plant itself is never stabilised: its unstable poles
/// stay wherever the data put them.
///
/// # Errors
/// As [`ss_frd_mimo`]; also [`Error::DimensionMismatch`] for a controller that is not
/// $n_u \times n_y$, [`Error::InvalidArgument`] for one at another sample time, and [`Error::Numerical`]
/// when no admissible start exists (check the controller, or raise the order).
/// [`Error::InvalidArgument`] when the FRF's lines give a reliable count of the loop's unstable
/// poles ([`crate::validate::nyquist::loop_unstable_poles`]: lines from near DC to near Nyquist)
/// and `order` or `max_unstable_poles` is below it.
///
/// ```
/// use ambid_core::estimate::freqfit_mimo::{ss_frd_mimo_in_loop, MimoFreqOptions};
/// use ambid_core::lti::{Frd, StateSpace};
/// use faer::mat;
/// // an unstable first-order plant under a proportional controller (closed-loop pole 0.61)
/// let p = StateSpace::discrete(mat![[1.01]], mat![[1.0]], mat![[1.0]], mat![[0.0]], 1e-3).unwrap();
/// let c = StateSpace::discrete(mat![[0.0]], mat![[0.0]], mat![[0.0]], mat![[0.4]], 1e-3).unwrap();
/// let f: Vec<f64> = (1..=40).map(|k| 10.0 * k as f64).collect();
/// let fit = ss_frd_mimo_in_loop(&Frd::from_model(&p, &f).unwrap(), 1, &MimoFreqOptions::default(), &c)
///     .unwrap();
/// assert!(fit.model.feedback(&c).unwrap().is_stable().unwrap());
/// assert!((fit.model.poles().unwrap()[0].re - 1.01).abs() < 1e-9); // still unstable
/// ```
pub fn ss_frd_mimo_in_loop(
    frd: &Frd,
    order: usize,
    opts: &MimoFreqOptions,
    controller: &StateSpace,
) -> Result<MimoFreqFit> {
    in_loop(frd, order, opts, controller, Origin::Scratch)
}

/// [`ss_frd_mimo_in_loop`] from one given start, `start` (a model of another record of the same
/// plant, e.g. the fit at a neighbouring speed): its $A$ and $C$ (in the data's channel
/// scaling) are put in modal block form, the numerators fitted to `frd` by the linear step, and
/// that single start is probed and refined as in the module docs; no vector-fitting starts, no
/// race. The order is the start's. Meant for a sequence of records of one machine whose
/// dynamics move a little from one to the next (the speeds of a Campbell run): the refinement
/// from the neighbour's optimum is short, and the models of the sequence stay in one basin.
/// Whether the result is as good as a fit from scratch is the caller's question (compare
/// [`MimoFreqFit::normalised_cost`]).
///
/// # Errors
/// As [`ss_frd_mimo_in_loop`]; also [`Error::DimensionMismatch`] for a start that is not
/// $n_y \times n_u$, and [`Error::InvalidArgument`] for one at another sample time.
///
/// ```
/// use ambid_core::estimate::freqfit_mimo::{ss_frd_mimo_in_loop, ss_frd_mimo_in_loop_from, MimoFreqOptions};
/// use ambid_core::lti::{Frd, StateSpace};
/// use faer::mat;
/// // an unstable plant whose pole moves from 1.010 to 1.012, under a proportional controller
/// let plant = |p: f64| StateSpace::discrete(mat![[p]], mat![[1.0]], mat![[1.0]], mat![[0.0]], 1e-3).unwrap();
/// let c = StateSpace::discrete(mat![[0.0]], mat![[0.0]], mat![[0.0]], mat![[0.4]], 1e-3).unwrap();
/// let f: Vec<f64> = (1..=40).map(|k| 10.0 * k as f64).collect();
/// let o = MimoFreqOptions::default();
/// let first = ss_frd_mimo_in_loop(&Frd::from_model(&plant(1.010), &f).unwrap(), 1, &o, &c).unwrap();
/// let next = ss_frd_mimo_in_loop_from(&Frd::from_model(&plant(1.012), &f).unwrap(), &o, &c, &first.model)
///     .unwrap();
/// assert!((next.model.poles().unwrap()[0].re - 1.012).abs() < 1e-9);
/// ```
pub fn ss_frd_mimo_in_loop_from(
    frd: &Frd,
    opts: &MimoFreqOptions,
    controller: &StateSpace,
    start: &StateSpace,
) -> Result<MimoFreqFit> {
    if start.noutputs() != frd.ny() || start.ninputs() != frd.nu() {
        return Err(Error::DimensionMismatch {
            context: "ss_frd_mimo_in_loop_from: the start has the FRF's shape",
            expected: format!("{} outputs x {} inputs", frd.ny(), frd.nu()),
            got: format!("{} outputs x {} inputs", start.noutputs(), start.ninputs()),
        });
    }
    same_sample_time("start", "model", start, frd)?;
    in_loop(frd, start.order(), opts, controller, Origin::Model(start))
}

/// An error unless `model` (the argument `name`, a `kind`) is discrete at the FRF's sample time.
fn same_sample_time(name: &'static str, kind: &str, model: &StateSpace, frd: &Frd) -> Result<()> {
    match (model.ts(), frd.ts()) {
        (Some(a), Some(b)) if (a - b).abs() <= 1e-12 * b.abs() => Ok(()),
        (a, b) => Err(Error::invalid(
            name,
            format!("the {name}'s sample time {a:?} s differs from the FRF's {b:?} s; give a discrete {kind} at the data's sample time"),
        )),
    }
}

/// [`ss_frd_mimo_in_loop`] continued from the probed starts of a fit that was abandoned
/// ([`MimoFreqFit::abandoned`], [`MimoFreqOptions::abandon_unless`]), on the same `frd`,
/// `controller` and options other than `abandon_unless`: the refinements run exactly as they
/// would have after the probe, so the result is the one of the same fit without a level (or,
/// with another level it cannot reach, again abandoned), without repeating the starts and
/// the probes.
///
/// # Errors
/// As [`ss_frd_mimo_in_loop`]; [`Error::InvalidArgument`] when `from` carries no probed starts
/// (it was not abandoned) or its starts do not fit this problem (another order or line count).
///
/// ```
/// use ambid_core::estimate::freqfit_mimo::{
///     ss_frd_mimo_in_loop, ss_frd_mimo_in_loop_resumed, CostTarget, MimoFreqOptions,
/// };
/// use ambid_core::lti::{Frd, StateSpace};
/// use faer::mat;
/// let plant = StateSpace::discrete(mat![[1.01]], mat![[1.0]], mat![[1.0]], mat![[0.0]], 1e-3).unwrap();
/// let c = StateSpace::discrete(mat![[0.0]], mat![[0.0]], mat![[0.0]], mat![[0.4]], 1e-3).unwrap();
/// let f: Vec<f64> = (1..=40).map(|k| 10.0 * k as f64).collect();
/// let frd = Frd::from_model(&plant, &f).unwrap();
/// let o = MimoFreqOptions::default();
/// let fit = ss_frd_mimo_in_loop(&frd, 1, &o, &c).unwrap();
/// // not abandoned: nothing to resume
/// assert!(!fit.abandoned);
/// assert!(ss_frd_mimo_in_loop_resumed(&frd, &o, &c, &fit).is_err());
/// ```
pub fn ss_frd_mimo_in_loop_resumed(
    frd: &Frd,
    opts: &MimoFreqOptions,
    controller: &StateSpace,
    from: &MimoFreqFit,
) -> Result<MimoFreqFit> {
    let probed = from.probed.as_ref().ok_or_else(|| {
        Error::invalid(
            "from",
            "the fit carries no probed starts (only an abandoned fit does); fit from scratch",
        )
    })?;
    in_loop(frd, probed.order, opts, controller, Origin::Probed(probed))
}

/// Where a fit starts.
#[derive(Clone, Copy)]
enum Origin<'a> {
    /// The subspace and vector-fitting starts (module docs).
    Scratch,
    /// One given model ([`ss_frd_mimo_in_loop_from`]).
    Model(&'a StateSpace),
    /// The probed starts of an abandoned fit ([`ss_frd_mimo_in_loop_resumed`]).
    Probed(&'a ProbedStarts),
}

/// The starts of an abandoned fit after their probe, for [`ss_frd_mimo_in_loop_resumed`].
#[derive(Debug, Clone)]
pub struct ProbedStarts {
    order: usize,
    n_equations: usize,
    runs: Vec<Run>,
}

/// The checks of [`ss_frd_mimo_in_loop`], then the fit (from `warm`).
fn in_loop(
    frd: &Frd,
    order: usize,
    opts: &MimoFreqOptions,
    controller: &StateSpace,
    warm: Origin<'_>,
) -> Result<MimoFreqFit> {
    if controller.ninputs() != frd.ny() || controller.noutputs() != frd.nu() {
        return Err(Error::DimensionMismatch {
            context: "ss_frd_mimo_in_loop: the controller maps the plant's outputs to its inputs",
            expected: format!("{} outputs x {} inputs", frd.nu(), frd.ny()),
            got: format!(
                "{} outputs x {} inputs",
                controller.noutputs(),
                controller.ninputs()
            ),
        });
    }
    same_sample_time("controller", "controller", controller, frd)?;
    // the unstable poles the measured loop shows (generalised Nyquist): an order or a limit
    // below that count cannot describe the plant
    let measured = crate::validate::nyquist::loop_unstable_poles(frd, controller)
        .ok()
        .and_then(|w| w.unstable_poles);
    if let Some(k) = measured {
        if order < k {
            return Err(Error::invalid(
                "order",
                format!(
                    "the order {order} is below the {k} unstable poles the measured loop shows (the winding of det(I + P C) over the FRF's lines, validate::nyquist); use an order of at least {k}, plus the states of the stable modes"
                ),
            ));
        }
        if let Some(m) = opts.max_unstable_poles.filter(|&m| m < k) {
            return Err(Error::invalid(
                "max_unstable_poles",
                format!(
                    "max_unstable_poles = {m} but the measured loop shows {k} unstable poles (the winding of det(I + P C), validate::nyquist); raise it to {k} or leave it unset"
                ),
            ));
        }
    }
    fit(frd, order, opts, Some(controller), measured, warm)
}

fn fit(
    frd: &Frd,
    order: usize,
    opts: &MimoFreqOptions,
    controller: Option<&StateSpace>,
    measured_unstable: Option<usize>,
    warm: Origin<'_>,
) -> Result<MimoFreqFit> {
    if order == 0 {
        return Err(Error::invalid(
            "order",
            "the model order must be at least 1",
        ));
    }
    let data = Data::new(frd, opts)?;
    let (l, ny, nu) = (data.len(), data.ny, data.nu);
    let n_eq = data.rows();
    let n_params_est = order * (nu + ny) + if opts.feedthrough { ny * nu } else { 0 };
    if n_eq <= n_params_est {
        return Err(Error::invalid(
            "order",
            format!(
                "{n_params_est} parameters for {n_eq} real equations ({l} lines of a {ny}x{nu} FRF); lower the order or widen the band"
            ),
        ));
    }
    let q = horizon(&data, order, opts.horizon)?;
    if order > q * ny {
        return Err(Error::invalid(
            "order",
            format!(
                "the order {order} exceeds the subspace dimension {} (horizon {q} x {ny} outputs); raise the horizon",
                q * ny
            ),
        ));
    }
    let warp = Warp::new(&data.f_hz, data.ts);
    let (sv, u) = projected(&data, &warp, q)?;

    let delta: Vec<c64> = data.z.iter().map(|&z| (z - 1.0) / warp.h).collect();
    let starts = match warm {
        Origin::Probed(_) => Vec::new(),
        Origin::Model(m) => {
            // the given model in the data's channel scaling: C' = diag(1/a) C
            let c = Mat::from_fn(m.noutputs(), m.order(), |i, j| m.c()[(i, j)] / data.a[i]);
            let (layout, mut theta) = to_blocks(
                &m.a().to_owned(),
                &c,
                warp.h,
                data.ny,
                data.nu,
                opts.feedthrough,
            )?;
            Problem::new(&data, &layout, &delta, None).fit_linear(&mut theta)?;
            vec![(layout, theta)]
        }
        Origin::Scratch => {
            let (a_z, c_z) = subspace_pair(&u, order, q, ny, &warp)?;
            starts(&data, &delta, &a_z, &c_z, order, warp.h, opts)?
        }
    };
    let limit = opts.max_unstable_poles.or(measured_unstable);
    // the caller's level as a bound on V (the parameter count of every start is the layout's)
    let external = opts
        .abandon_unless
        .map(|t| t.cost_bound(n_eq, starts.first().map_or(n_params_est, |s| s.0.n_theta)));
    // a single start (the warm one) is not ranked, so its probe is raced as well
    let race_probe = matches!(warm, Origin::Model(_));
    // every start probed; the most promising ones refined to the end; the lowest final cost
    // wins (the first error when none succeeds); the starts run in parallel, each on its own
    // data, so the result does not depend on the number of threads
    let mut first_err = None;
    let runs: Vec<Run> = if let Origin::Probed(p) = warm {
        if p.order != order || p.n_equations != n_eq {
            return Err(Error::invalid(
                "from",
                format!(
                    "the probed starts are of order {} on {} equations, this problem is order {order} on {n_eq}; resume on the FRF, band and options of the abandoned fit",
                    p.order, p.n_equations
                ),
            ));
        }
        p.runs.clone()
    } else {
        let probed: Vec<Result<Run>> = starts
            .into_par_iter()
            .map(|(layout, theta)| {
                let race = external.filter(|_| race_probe);
                probe(&data, &delta, layout, theta, opts, limit, race)
            })
            .collect();
        let mut runs = Vec::new();
        for r in probed {
            match r {
                Ok(r) => runs.push(r),
                Err(e) => {
                    first_err.get_or_insert(e);
                }
            }
        }
        runs.sort_by(|a, b| a.cost.total_cmp(&b.cost));
        runs.truncate(REFINED_STARTS);
        runs
    };
    // kept for a resumption only where the fit can be abandoned
    let probed_runs = external.map(|_| runs.clone());
    // refined in the order of the probe, each later one raced against the best final cost so
    // far (sequential, so that the result does not depend on timing)
    // with the caller's level: a run is raced against it while no run has ended, and one
    // abandoned there ends the fit (so the result is either the one without the level, or
    // abandoned); the probed starts go with it, for a resumption
    let mut best: Option<Refined> = None;
    let mut best_abandoned: Option<Refined> = None;
    // a probe abandoned (a single start from a given model) leaves nothing to resume
    let mut probe_abandoned = false;
    for run in runs {
        if run.abandoned {
            probe_abandoned = true;
            best_abandoned =
                refine(&data, &delta, run, opts, controller, limit, None, None)?.map(|(r, _)| r);
            break;
        }
        let ext = external.filter(|_| best.is_none());
        match refine(
            &data,
            &delta,
            run,
            opts,
            controller,
            limit,
            best.as_ref().map(|b| b.0),
            ext,
        ) {
            Ok(Some((r, false))) => {
                if best.as_ref().is_none_or(|b| r.0 < b.0) {
                    best = Some(r);
                }
            }
            Ok(Some((r, true))) if ext.is_some() => {
                best_abandoned = Some(r);
                break;
            }
            Ok(_) => {}
            Err(e) => {
                first_err.get_or_insert(e);
            }
        }
    }
    let abandoned = best_abandoned.is_some();
    let (mut cost, layout, mut theta, iterations, converged) =
        match (best_abandoned.or(best), first_err) {
            (Some(b), _) => b,
            (None, Some(e)) => return Err(e),
            (None, None) => {
                return Err(Error::numerical(
                    CTX,
                    "no start was formed; lower the order",
                ))
            }
        };
    // the floor's test needs a cost in units of the noise: inverse-variance weights only
    let floored = if opts.damping_floor && !abandoned && data.inverse_variance {
        floor_unresolved(
            &data, &delta, &layout, &mut theta, &mut cost, controller, limit,
        )
    } else {
        Vec::new()
    };
    // § 5: without cancelling residues, so that its closed loop can be formed
    let model = layout.realise(&theta, &data)?.well_conditioned();
    let errors = errors_of(&model, &data)?;
    Ok(MimoFreqFit {
        model,
        n_params: layout.n_theta,
        cost,
        n_equations: n_eq,
        iterations,
        converged,
        abandoned,
        probed: probed_runs
            .filter(|_| abandoned && !probe_abandoned)
            .map(|runs| ProbedStarts {
                order,
                n_equations: n_eq,
                runs,
            }),
        errors,
        singular_values: sv,
        f_hz: data.f_hz.clone(),
        floored,
    })
}

/// The $\chi^2_1$ 99 % point: a floor whose cost rise $2(V' - V)$ exceeds it (times the
/// normalised cost) is rejected by the data (module docs, "4. Unresolved pairs").
///
/// $\chi^2_1$ is the square of a standard normal, so its 99 % point is the square of the
/// normal's 99.5 % point, 2.575 829 303 548 9:
/// ```
/// use ambid_core::estimate::freqfit_mimo::FLOOR_CHI2_1;
/// assert!((FLOOR_CHI2_1.sqrt() - 2.575_829_303_548_9).abs() < 1e-12);
/// ```
pub const FLOOR_CHI2_1: f64 = 6.634_896_601_021_214;

/// The spacing of the two lines of `f_hz` (ascending) around `f`; `None` outside them.
fn local_spacing(f_hz: &[f64], f: f64) -> Option<f64> {
    let k = f_hz.partition_point(|&x| x <= f);
    (k > 0 && k < f_hz.len()).then(|| f_hz[k] - f_hz[k - 1])
}

/// The damping floor of the module docs ("4. Unresolved pairs") on the fitted θ: each stable
/// complex pair inside the lines whose half-power bandwidth is below the spacing of the lines
/// around it, narrowest (relative to the spacing) first, is moved to that bandwidth at its
/// damped frequency, the numerators refitted; kept where the weighted cost rises by at most
/// [`FLOOR_CHI2_1`] times $\max(1, 2V/\nu)$ and the model stays admissible (the unstable-pole
/// limit and, with a controller, a stable loop). Updates `cost`.
fn floor_unresolved(
    data: &Data,
    delta: &[c64],
    layout: &Layout,
    theta: &mut Vec<f64>,
    cost: &mut f64,
    controller: Option<&StateSpace>,
    limit: Option<usize>,
) -> Vec<FlooredPair> {
    use std::f64::consts::PI;
    let mut prob = Problem::new(data, layout, delta, limit);
    prob.controller = controller;
    let dof = data.rows().saturating_sub(layout.n_theta).max(1) as f64;
    let scale = (2.0 * *cost / dof).max(1.0);
    // (bandwidth / spacing, block, s of the upper pole, spacing)
    let mut unresolved: Vec<(f64, usize, c64, f64)> = Vec::new();
    for (i, b) in layout.blocks.iter().enumerate() {
        if b.dim != 2 {
            continue;
        }
        let [Some(z1), Some(z2)] = layout.block_poles(theta, b) else {
            continue;
        };
        let z = if z1.im >= z2.im { z1 } else { z2 };
        if z.im <= 0.0 || z.norm() >= 1.0 {
            continue;
        }
        let s = z.ln() / data.ts;
        // half-power bandwidth 2|Re s| / 2π
        let bw = -s.re / PI;
        if let Some(sp) = local_spacing(&data.f_hz, s.im / (2.0 * PI)) {
            if bw < sp {
                unresolved.push((bw / sp, i, s, sp));
            }
        }
    }
    unresolved.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut out = Vec::new();
    for (rel, i, s, sp) in unresolved {
        let b = &layout.blocks[i];
        // the bandwidths Δ, Δ/2, Δ/4, … down to the fitted one: the largest the data accept
        let mut bw = sp;
        while bw > rel * sp {
            let s2 = c64::new(-PI * bw, s.im);
            bw /= 2.0;
            let d = ((s2 * data.ts).exp() - 1.0) / layout.h;
            let mut trial = theta.clone();
            // δ² + α1 δ + α2 = (δ − d)(δ − d̄)
            trial[b.off] = -2.0 * d.re;
            trial[b.off + 1] = d.norm_sqr();
            if prob.fit_linear(&mut trial).is_err() {
                continue;
            }
            let Some(r) = prob.residuals(&trial) else {
                continue;
            };
            let c = r.iter().map(|x| x * x).sum::<f64>();
            let rise = 2.0 * (c - *cost);
            if rise <= FLOOR_CHI2_1 * scale {
                out.push(FlooredPair {
                    f_hz: s.im / (2.0 * PI),
                    zeta_fitted: -s.re / s.norm(),
                    zeta_floored: -s2.re / s2.norm(),
                    spacing_hz: sp,
                    cost_rise: rise,
                });
                *theta = trial;
                *cost = c;
                break;
            }
        }
    }
    out
}

/// The subspace step's $(A_z, C_z)$ (module docs, step 1): the shift invariance of the
/// `order` leading left singular vectors `u` of the projected data in $\zeta$, mapped back to $z$.
fn subspace_pair(
    u: &Mat<f64>,
    order: usize,
    q: usize,
    ny: usize,
    warp: &Warp,
) -> Result<(Mat<f64>, Mat<f64>)> {
    let o = u.subcols(0, order);
    let o_up = o.subrows(0, (q - 1) * ny).to_owned();
    let o_dn = o.subrows(ny, (q - 1) * ny).to_owned();
    let a_zeta = linalg::lstsq(o_up.as_ref(), o_dn.as_ref()).map_err(|e| {
        Error::numerical(
            CTX,
            format!("the shift equation of the subspace step is degenerate ({e}); lower the order or raise the horizon"),
        )
    })?;
    let c_zeta = o.subrows(0, ny).to_owned();
    let eye = Mat::<f64>::identity(order, order);
    let den = &eye + &a_zeta * warp.a;
    let num = &a_zeta + &eye * warp.a;
    let a_z = linalg::solve(den.as_ref(), num.as_ref()).map_err(|_| {
        Error::numerical(
            CTX,
            "the subspace step placed a pole at infinity; lower the order or narrow the band",
        )
    })?;
    let c_z = &c_zeta * (&eye - &a_z * warp.a);
    if a_z
        .col_iter()
        .flat_map(|c| c.iter().copied())
        .any(|v| !v.is_finite())
    {
        return Err(Error::numerical(
            CTX,
            "the subspace step produced a non-finite state matrix; lower the order",
        ));
    }
    Ok((a_z, c_z))
}

/// Levenberg–Marquardt iterations every start gets before the most promising are kept.
pub const PROBE_ITERATIONS: usize = 20;

/// Starts refined to the end after the probe (the lowest weighted cost after it).
pub const REFINED_STARTS: usize = 2;

/// One start on its way through the refinement.
#[derive(Debug, Clone)]
struct Run {
    layout: Layout,
    theta: Vec<f64>,
    /// Accepted steps so far.
    iterations: usize,
    /// The weighted cost without the loop constraint.
    cost: f64,
    /// Whether the probe's iteration converged (it ends the fit when the budget is the probe).
    converged: bool,
    /// The trust region where the probe stopped, for the refinement to continue from.
    state: Option<LmState>,
    /// Whether the probe was abandoned (raced against the caller's level).
    abandoned: bool,
}

/// The probe of one start: the unstable-pole limit imposed, then [`PROBE_ITERATIONS`] steps
/// without the loop constraint (module docs, "Refinement"); raced against the cost `race`
/// when given (with the whole iteration budget as what is left).
fn probe(
    data: &Data,
    delta: &[c64],
    layout: Layout,
    mut theta: Vec<f64>,
    opts: &MimoFreqOptions,
    limit: Option<usize>,
    race: Option<f64>,
) -> Result<Run> {
    let lm = lm_options(&layout, PROBE_ITERATIONS.min(opts.max_iterations))?;
    let mut prob = Problem::new(data, &layout, delta, limit);
    if let Some(lim) = limit {
        prob.constrain_start(&mut theta, lim)?;
    }
    let mut iterations = 0;
    let mut converged = true;
    let mut state = None;
    let mut abandoned = false;
    if opts.max_iterations > 0 {
        let race = race.map(|b| Race::new(b, opts.max_iterations));
        let (th, report, st) = minimize_projected(&mut prob, &theta, &lm, race, None)?;
        theta = th;
        iterations = report.iterations;
        abandoned = report.reason == StopReason::Abandoned;
        converged = report.reason.converged() && !abandoned;
        state = Some(st);
    }
    let cost = prob
        .residuals(&theta)
        .map_or(f64::INFINITY, |r| r.iter().map(|x| x * x).sum::<f64>());
    Ok(Run {
        layout,
        theta,
        iterations,
        cost,
        converged,
        state,
        abandoned,
    })
}

/// What [`refine`] returns: (cost, layout, θ, iterations, converged).
type Refined = (f64, Layout, Vec<f64>, usize, bool);

/// The rest of the refinement of a probed start: (with a controller) the unconstrained stage
/// continued, the mirroring to a stable loop and the constrained stage; else the one stage
/// continued. The result and whether the run was abandoned (then the state where it stopped)
/// because it cannot reach the final cost `bound` of a better-ranked start or the caller's
/// level `external` ([`Race`]); `Ok(None)` when an abandoned run's state cannot be evaluated.
#[allow(clippy::too_many_arguments)]
fn refine(
    data: &Data,
    delta: &[c64],
    run: Run,
    opts: &MimoFreqOptions,
    controller: Option<&StateSpace>,
    limit: Option<usize>,
    bound: Option<f64>,
    external: Option<f64>,
) -> Result<Option<(Refined, bool)>> {
    let Run {
        layout,
        mut theta,
        mut iterations,
        mut converged,
        state,
        abandoned,
        ..
    } = run;
    let mut prob = Problem::new(data, &layout, delta, limit);
    let cost_of = |prob: &mut Problem<'_>, theta: &[f64]| {
        prob.residuals(theta)
            .map(|r| r.iter().map(|x| x * x).sum::<f64>())
    };
    if abandoned {
        let c = cost_of(&mut prob, &theta);
        return Ok(c.map(|c| ((c, layout, theta, iterations, false), true)));
    }
    let rest = opts
        .max_iterations
        .saturating_sub(iterations.min(PROBE_ITERATIONS));
    let lm = |n: usize| lm_options(&layout, n);
    // a run that cannot end more than the stopping rule's κ²σ̂² below the best one cannot be
    // told apart from it (the best one itself stopped up to that far above its minimum)
    let dof = data.rows().saturating_sub(layout.n_theta).max(1) as f64;
    let margin = |b: f64| significance_kappa2(layout.n_theta) * b / dof;
    let level = match (bound.map(|b| b - margin(b)), external) {
        (Some(b), Some(e)) => Some(b.min(e)),
        (b, e) => b.or(e),
    };
    let race = |budget: usize| level.map(|b| Race::new(b, budget));
    if rest > 0 {
        // the stage without the loop constraint, continued: the path from the start to the
        // optimum crosses loop-unstable models, and a trust region held on the admissible set
        // stalls on its boundary; the second stage mirrors what the loop cannot have and
        // refines inside it
        // continued with the probe's trust region (a fresh one would first have to shrink)
        let (th, report, _) = minimize_projected(&mut prob, &theta, &lm(rest)?, race(rest), state)?;
        if report.reason == StopReason::Abandoned {
            let c = cost_of(&mut prob, &th);
            let it = iterations + report.iterations;
            return Ok(c.map(|c| ((c, layout, th, it, false), true)));
        }
        theta = th;
        iterations += report.iterations;
        converged = report.reason.converged();
    }
    if controller.is_some() {
        prob.controller = controller;
        prob.stable_loop_start(&mut theta)?;
        if opts.max_iterations > 0 {
            let budget = opts.max_iterations;
            let (th, report, _) =
                minimize_projected(&mut prob, &theta, &lm(budget)?, race(budget), None)?;
            if report.reason == StopReason::Abandoned {
                let c = cost_of(&mut prob, &th);
                let it = iterations + report.iterations;
                return Ok(c.map(|c| ((c, layout, th, it, false), true)));
            }
            theta = th;
            iterations += report.iterations;
            converged = report.reason.converged();
        }
    }
    let r = prob.residuals(&theta).ok_or_else(|| {
        Error::numerical(
            CTX,
            "the fitted model's response is not finite on the data's lines (a pole on a line); lower the order",
        )
    })?;
    let cost = r.iter().map(|x| x * x).sum::<f64>();
    Ok(Some(((cost, layout, theta, iterations, converged), false)))
}

/// Accepted steps over which [`Race`] measures a run's pace.
const RACE_WINDOW: usize = 5;

/// The abandonment rule of a refinement that runs after a better-ranked start has finished
/// with weighted cost `bound` (module docs, "Refinement"): the run is ended when neither the
/// Gauss–Newton step's predicted reduction nor its pace over the last [`RACE_WINDOW`] steps,
/// kept up for the rest of its iteration budget, can bring its cost below `bound`. Both are
/// optimistic (the first overestimates in a curved valley, the second holds while the run still
/// descends fast), so a run that could still win goes on.
struct Race {
    bound: f64,
    budget: usize,
    /// Weighted cost ($\lVert r\rVert^2$) at each iteration so far.
    history: Vec<f64>,
}

impl Race {
    fn new(bound: f64, budget: usize) -> Self {
        Self {
            bound,
            budget,
            history: Vec::new(),
        }
    }

    /// Records the iteration's cost $\lVert r\rVert^2$ and the predicted reduction
    /// $\lVert z\rVert^2$; whether the run is to end.
    fn lost(&mut self, cost: f64, predicted: f64) -> bool {
        self.history.push(cost);
        let it = self.history.len() - 1;
        if cost - predicted <= self.bound || it < RACE_WINDOW {
            return false;
        }
        let pace = (self.history[it - RACE_WINDOW] - cost) / RACE_WINDOW as f64;
        let left = self.budget.saturating_sub(it) as f64;
        cost - pace.max(0.0) * left > self.bound
    }
}

/// A solution of [`scaled_lstsq`] and, when asked for, an orthonormal basis of its regressor's
/// range.
type Solved = (Vec<f64>, Option<Mat<f64>>);

/// Least squares of one right-hand side with unit-norm columns, by Householder QR; when the
/// scaled regressor is numerically rank deficient (repeated poles that no output tells apart),
/// the minimum-norm solution of its numerically visible part. With `basis`, also an orthonormal
/// basis of the regressor's range: the thin $Q$ of the QR, or in the rank-deficient case the
/// left singular vectors the minimum-norm solution keeps. `aug` is $[\Phi\; g]$: the
/// regressor with the right-hand side as its last column.
fn scaled_lstsq(mut aug: Mat<f64>, basis: bool) -> Result<Solved> {
    let nc = aug.ncols().saturating_sub(1);
    if aug.ncols() == 0 || aug.nrows() < nc {
        return Err(Error::invalid(
            "order",
            "fewer equations than numerator parameters",
        ));
    }
    let mut scale = vec![1.0; nc];
    for (c, sc) in scale.iter_mut().enumerate() {
        let n = aug.col(c).norm_l2();
        if n > 0.0 && n.is_finite() {
            *sc = 1.0 / n;
            aug.col_mut(c).iter_mut().for_each(|v| *v *= *sc);
        }
    }
    if !(0..=nc).all(|c| all_finite(aug.col_as_slice(c))) {
        return Err(Error::numerical(CTX, "a non-finite regressor"));
    }
    // the unit-norm columns make |R_ii| the distance of column i from the span of the others
    // before it: a tiny one is a (numerically) repeated column
    let tiny = |r: MatRef<'_, f64>| (0..nc).any(|i| r[(i, i)].abs() <= 1e-10);
    let (ms, rhs) = (aug.subcols(0, nc), aug.subcols(nc, 1));
    // the basis of the rank-deficient case is the kept left singular vectors: faer's thin Q
    // of a rank-deficient matrix spans its range plus one spurious direction per dependent
    // column, which the projection would remove from the Jacobian too
    let (x, q) = if basis {
        let qr = ms.qr();
        if tiny(qr.thin_R()) {
            linalg::lstsq_min_norm_range(ms, rhs, 1e-10, true)?
        } else {
            let x = faer::linalg::solvers::SolveLstsq::solve_lstsq(&qr, rhs);
            (
                x.col(0).iter().copied().collect(),
                Some(qr.compute_thin_Q()),
            )
        }
    } else {
        // the triangle [R z; 0 ρ] of [Φ g]: R x = z when Φ has full numerical rank; else the
        // minimum-norm solution of the triangle's own system, which is the original one's
        // (‖Φx − g‖² = ‖Rx − z‖² + ρ², and R has Φ's singular values)
        let t = r_factor_tall(aug);
        if tiny(t.as_ref()) {
            linalg::lstsq_min_norm_range(t.subcols(0, nc), t.subcols(nc, 1), 1e-10, false)?
        } else {
            let mut x = vec![0.0; nc];
            for i in (0..nc).rev() {
                let acc: f64 = (i + 1..nc).map(|c| t[(i, c)] * x[c]).sum();
                x[i] = (t[(i, nc)] - acc) / t[(i, i)];
            }
            (x, None)
        }
    };
    if x.iter().any(|v| !v.is_finite()) {
        return Err(Error::numerical(CTX, "a non-finite solution"));
    }
    let x = x.iter().zip(&scale).map(|(v, s)| v * s).collect();
    Ok((x, q))
}

/// A start of the refinement: its block layout and θ.
type Start = (Layout, Vec<f64>);

/// Relocations of the vector-fitting start.
const VF_ITERATIONS: usize = 30;

/// The starts of the refinement, each in block form with its numerators fitted: the
/// vector-fitting starts from the subspace step's poles and from poles spread over the band
/// (module docs, "Start"); the subspace start itself only when neither can be formed.
fn starts(
    data: &Data,
    delta: &[c64],
    a_z: &Mat<f64>,
    c_z: &Mat<f64>,
    order: usize,
    h: f64,
    opts: &MimoFreqOptions,
) -> Result<Vec<(Layout, Vec<f64>)>> {
    let blocks = |(a, c): (Mat<f64>, Mat<f64>)| -> Result<(Layout, Vec<f64>)> {
        let (layout, mut theta) = to_blocks(&a, &c, h, data.ny, data.nu, opts.feedthrough)?;
        Problem::new(data, &layout, delta, None).fit_linear(&mut theta)?;
        Ok((layout, theta))
    };
    let sub_poles = linalg::eigenvalues(a_z.as_ref())?;
    let spread = vf::spread_poles(data, order);
    // the two vector-fitting runs and their starts in parallel, collected in a fixed order
    let made: Vec<Vec<Result<Start>>> = [&sub_poles, &spread]
        .into_par_iter()
        .map(|poles| match vf::start(data, order, poles, VF_ITERATIONS) {
            Ok(realisations) => realisations.into_iter().map(blocks).collect(),
            Err(e) => vec![Err(e)],
        })
        .collect();
    let mut out = Vec::new();
    let mut first_err = None;
    for r in made.into_iter().flatten() {
        match r {
            Ok(s) => out.push(s),
            Err(e) => {
                first_err.get_or_insert(e);
            }
        }
    }
    if out.is_empty() {
        match blocks((a_z.clone(), c_z.clone())) {
            Ok(s) => out.push(s),
            Err(e) => return Err(first_err.unwrap_or(e)),
        }
    }
    Ok(out)
}

/// The unweighted error measures of `model` on the data's lines, in the original units.
fn errors_of(model: &StateSpace, data: &Data) -> Result<MimoFreqErrors> {
    let (l, ny, nu, e) = (data.len(), data.ny, data.nu, data.entries());
    let resp = model.freq_response(&data.f_hz)?;
    let mut norm_rel = Vec::with_capacity(l);
    let mut entry_rel = vec![Vec::with_capacity(l); e];
    for k in 0..l {
        let gk = Mat::<c64>::from_fn(ny, nu, |i, j| {
            data.g[k * e + j * ny + i] * (data.a[i] * data.b[j])
        });
        let diff = Mat::<c64>::from_fn(ny, nu, |i, j| resp[k][(i, j)] - gk[(i, j)]);
        let nd = spectral_norm(&diff)?;
        let ng = spectral_norm(&gk)?;
        norm_rel.push(if ng > 0.0 { nd / ng } else { f64::INFINITY });
        for i in 0..ny {
            for j in 0..nu {
                let g = gk[(i, j)].norm();
                entry_rel[i * nu + j].push(if g > 0.0 {
                    diff[(i, j)].norm() / g
                } else {
                    f64::INFINITY
                });
            }
        }
    }
    let max_norm_relative = norm_rel.iter().copied().fold(0.0, f64::max);
    Ok(MimoFreqErrors {
        median_norm_relative: median(&mut norm_rel),
        max_norm_relative,
        median_entry_relative: entry_rel.iter_mut().map(|v| median(v)).collect(),
    })
}

/// Median of a non-empty slice (sorted in place); NaN for an empty one.
fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// Largest singular value of a complex matrix.
pub(crate) fn spectral_norm(m: &Mat<c64>) -> Result<f64> {
    let sv = m
        .singular_values()
        .map_err(|e| Error::numerical(CTX, format!("singular values failed: {e:?}")))?;
    Ok(sv.iter().fold(0.0f64, |a, v| a.max(*v)))
}

/// One block of the modal form.
#[derive(Debug, Clone, Copy)]
struct Block {
    /// 1 or 2 states.
    dim: usize,
    /// First parameter of the block in θ: α (dim), β (dim × nu, row-major), free C rows.
    off: usize,
    /// Output row of $C_b$ fixed at $[1\;0]$ (or 1).
    fixed_row: usize,
}

/// Where everything lives in θ.
#[derive(Debug, Clone)]
struct Layout {
    blocks: Vec<Block>,
    n: usize,
    ny: usize,
    nu: usize,
    h: f64,
    d_off: Option<usize>,
    n_theta: usize,
}

impl Layout {
    fn beta_idx(&self, b: &Block, r: usize, j: usize) -> usize {
        b.off + b.dim + r * self.nu + j
    }
    fn c_idx(&self, b: &Block, o: usize, r: usize) -> Option<usize> {
        if o == b.fixed_row {
            return None;
        }
        let rank = if o < b.fixed_row { o } else { o - 1 };
        Some(b.off + b.dim + b.dim * self.nu + rank * b.dim + r)
    }
    fn c_val(&self, th: &[f64], b: &Block, o: usize, r: usize) -> f64 {
        match self.c_idx(b, o, r) {
            Some(i) => th[i],
            None => f64::from(u8::from(r == 0)),
        }
    }
    fn d_val(&self, th: &[f64], i: usize, j: usize) -> f64 {
        self.d_off.map_or(0.0, |off| th[off + i * self.nu + j])
    }
    /// Poles in $z$ of a block.
    fn block_poles(&self, th: &[f64], b: &Block) -> [Option<c64>; 2] {
        if b.dim == 2 {
            let (a1, a2) = (th[b.off], th[b.off + 1]);
            let disc = a1 * a1 - 4.0 * a2;
            let (d1, d2) = if disc >= 0.0 {
                let s = disc.sqrt();
                (
                    c64::new((-a1 + s) / 2.0, 0.0),
                    c64::new((-a1 - s) / 2.0, 0.0),
                )
            } else {
                let s = (-disc).sqrt();
                (c64::new(-a1 / 2.0, s / 2.0), c64::new(-a1 / 2.0, -s / 2.0))
            };
            [Some(d1 * self.h + 1.0), Some(d2 * self.h + 1.0)]
        } else {
            [Some(c64::new(1.0 + self.h * th[b.off], 0.0)), None]
        }
    }
    fn unstable(&self, th: &[f64]) -> usize {
        self.blocks
            .iter()
            .flat_map(|b| self.block_poles(th, b))
            .flatten()
            .filter(|z| z.norm() >= 1.0)
            .count()
    }
    /// The model of θ in the original units.
    fn realise(&self, th: &[f64], data: &Data) -> Result<StateSpace> {
        let (n, ny, nu, h) = (self.n, self.ny, self.nu, self.h);
        let mut a = Mat::<f64>::zeros(n, n);
        let mut bm = Mat::<f64>::zeros(n, nu);
        let mut c = Mat::<f64>::zeros(ny, n);
        let mut s = 0;
        for b in &self.blocks {
            if b.dim == 2 {
                a[(s, s)] = 1.0;
                a[(s, s + 1)] = h;
                a[(s + 1, s)] = -h * th[b.off + 1];
                a[(s + 1, s + 1)] = 1.0 - h * th[b.off];
            } else {
                a[(s, s)] = 1.0 + h * th[b.off];
            }
            for r in 0..b.dim {
                for j in 0..nu {
                    bm[(s + r, j)] = h * th[self.beta_idx(b, r, j)] * data.b[j];
                }
                for o in 0..ny {
                    c[(o, s + r)] = self.c_val(th, b, o, r) * data.a[o];
                }
            }
            s += b.dim;
        }
        let d = Mat::from_fn(ny, nu, |i, j| self.d_val(th, i, j) * data.a[i] * data.b[j]);
        if th.iter().any(|v| !v.is_finite()) {
            return Err(Error::numerical(
                CTX,
                "the refinement produced non-finite parameters; lower the order or narrow the band",
            ));
        }
        StateSpace::discrete(a, bm, c, d, data.ts)
    }
}

/// Block decomposition of $(A, C)$ (module docs): the layout and θ with $\beta = 0$, $D = 0$.
fn to_blocks(
    a: &Mat<f64>,
    c: &Mat<f64>,
    h: f64,
    ny: usize,
    nu: usize,
    feedthrough: bool,
) -> Result<(Layout, Vec<f64>)> {
    let n = a.nrows();
    let eig = a.eigen().map_err(|e| {
        Error::numerical(
            CTX,
            format!("the eigendecomposition of the start failed ({e:?}); lower the order"),
        )
    })?;
    let (vecs, vals) = (eig.U(), eig.S());
    let scale = (0..n).map(|k| vals[k].norm()).fold(1.0f64, f64::max);
    let tol = 1e-10 * scale;
    let mut complex: Vec<usize> = (0..n).filter(|&k| vals[k].im > tol).collect();
    complex.sort_by(|&x, &y| vals[x].im.total_cmp(&vals[y].im));
    let n_neg = (0..n).filter(|&k| vals[k].im < -tol).count();
    if n_neg != complex.len() {
        return Err(Error::numerical(
            CTX,
            "the eigenvalues of the start do not come in conjugate pairs; lower the order",
        ));
    }
    let mut real: Vec<usize> = (0..n).filter(|&k| vals[k].im.abs() <= tol).collect();
    real.sort_by(|&x, &y| vals[x].re.total_cmp(&vals[y].re));
    // basis columns, grouped per block
    let mut t = Mat::<f64>::zeros(n, n);
    let mut dims = Vec::new();
    let mut col = 0;
    for &k in &complex {
        let v = vecs.col(k);
        let nv = v
            .iter()
            .map(|x| x.norm_sqr())
            .sum::<f64>()
            .sqrt()
            .max(f64::MIN_POSITIVE);
        for r in 0..n {
            t[(r, col)] = v[r].re / nv;
            t[(r, col + 1)] = v[r].im / nv;
        }
        col += 2;
        dims.push(2);
    }
    // real poles: one 1 × 1 block each (a pair of real poles of different planes has no output
    // that sees both, so a 2 × 2 companion block of them would be singular)
    for &k in &real {
        let v = vecs.col(k);
        let nv = v.iter().map(|x| x.re * x.re).sum::<f64>().sqrt();
        if nv.is_nan() || nv <= 0.0 {
            return Err(Error::numerical(
                CTX,
                "a real pole of the start has a complex eigenvector; lower the order",
            ));
        }
        for r in 0..n {
            t[(r, col)] = v[r].re / nv;
        }
        col += 1;
        dims.push(1);
    }
    let sv = linalg::singular_values(t.as_ref())?;
    if sv.last().copied().unwrap_or(0.0) <= 1e-10 * sv[0] {
        return Err(Error::numerical(
            CTX,
            "the start has (nearly) defective repeated poles, so it cannot be put in modal block form; lower the order",
        ));
    }
    let tinv = linalg::solve(t.as_ref(), Mat::<f64>::identity(n, n).as_ref())?;
    let ab = &tinv * a * &t;
    let cb = c * &t;
    let mut blocks = Vec::new();
    let mut theta = Vec::new();
    let mut state = 0;
    for &dim in &dims {
        let ad = ab.submatrix(state, state, dim, dim);
        let cbk = cb.subcols(state, dim);
        // the output row whose companion transform is best conditioned: |det O| for a pair
        // (zero when the row does not see the mode), |c| for a real pole
        let score = |row: usize| -> f64 {
            if dim == 2 {
                let c0 = [cbk[(row, 0)], cbk[(row, 1)]];
                let c1 = [
                    c0[0] * (ad[(0, 0)] - 1.0) + c0[1] * ad[(1, 0)],
                    c0[0] * ad[(0, 1)] + c0[1] * (ad[(1, 1)] - 1.0),
                ];
                (c0[0] * c1[1] - c0[1] * c1[0]).abs()
            } else {
                cbk[(row, 0)].abs()
            }
        };
        let fixed_row = (0..ny)
            .max_by(|&x, &y| score(x).total_cmp(&score(y)))
            .unwrap_or(0);
        let o = if dim == 2 {
            let c0 = [cbk[(fixed_row, 0)], cbk[(fixed_row, 1)]];
            let c1 = [
                (c0[0] * (ad[(0, 0)] - 1.0) + c0[1] * ad[(1, 0)]) / h,
                (c0[0] * ad[(0, 1)] + c0[1] * (ad[(1, 1)] - 1.0)) / h,
            ];
            faer::mat![[c0[0], c0[1]], [c1[0], c1[1]]]
        } else {
            faer::mat![[cbk[(fixed_row, 0)]]]
        };
        let osv = linalg::singular_values(o.as_ref())?;
        if osv.last().copied().unwrap_or(0.0) <= 1e-9 * osv[0].max(f64::MIN_POSITIVE) {
            return Err(Error::numerical(
                CTX,
                "a mode of the start is (nearly) unobservable from every output; lower the order",
            ));
        }
        let oinv = linalg::solve(o.as_ref(), Mat::<f64>::identity(dim, dim).as_ref())?;
        let off = theta.len();
        if dim == 2 {
            // M = (A_b − I)/h: α1 = −tr M, α2 = det M
            let m00 = (ad[(0, 0)] - 1.0) / h;
            let m11 = (ad[(1, 1)] - 1.0) / h;
            let m01 = ad[(0, 1)] / h;
            let m10 = ad[(1, 0)] / h;
            theta.push(-(m00 + m11));
            theta.push(m00 * m11 - m01 * m10);
        } else {
            theta.push((ad[(0, 0)] - 1.0) / h);
        }
        theta.extend(std::iter::repeat_n(0.0, dim * nu));
        let cnew = cbk * &oinv;
        for oo in 0..ny {
            if oo != fixed_row {
                for r in 0..dim {
                    theta.push(cnew[(oo, r)]);
                }
            }
        }
        blocks.push(Block {
            dim,
            off,
            fixed_row,
        });
        state += dim;
    }
    let d_off = if feedthrough {
        let off = theta.len();
        theta.extend(std::iter::repeat_n(0.0, ny * nu));
        Some(off)
    } else {
        None
    };
    let n_theta = theta.len();
    Ok((
        Layout {
            blocks,
            n,
            ny,
            nu,
            h,
            d_off,
            n_theta,
        },
        theta,
    ))
}

/// The weighted least-squares problem of the refinement (module docs).
struct Problem<'a> {
    data: &'a Data,
    layout: &'a Layout,
    delta: Vec<c64>,
    limit: Option<usize>,
    /// Trials whose loop with this controller is unstable are inadmissible.
    controller: Option<&'a StateSpace>,
}

/// $R_b(\delta)$ of a block as a row-major 2×2 (or 1×1 in `[0]`).
fn resolvent(th: &[f64], b: &Block, delta: c64) -> Option<[c64; 4]> {
    if b.dim == 2 {
        let (a1, a2) = (th[b.off], th[b.off + 1]);
        let d = delta * delta + delta * a1 + a2;
        if d.norm() == 0.0 {
            return None;
        }
        let inv = c64::new(1.0, 0.0) / d;
        Some([
            (delta + a1) * inv,
            inv,
            c64::new(-a2, 0.0) * inv,
            delta * inv,
        ])
    } else {
        let d = delta - th[b.off];
        if d.norm() == 0.0 {
            return None;
        }
        Some([
            c64::new(1.0, 0.0) / d,
            c64::default(),
            c64::default(),
            c64::default(),
        ])
    }
}

impl<'a> Problem<'a> {
    /// The problem on `data` in `layout` at the lines' δ, without the loop constraint.
    fn new(data: &'a Data, layout: &'a Layout, delta: &[c64], limit: Option<usize>) -> Self {
        Self {
            data,
            layout,
            delta: delta.to_vec(),
            limit,
            controller: None,
        }
    }

    /// $Y = C_b R_b$ and (with `with_x`) $X = R_b \beta_b$ of every block at every line, flat:
    /// `ys[(k n + s) n_y + i]`, `xs[(k n + s) n_u + j]` for line $k$ and state $s$ (`xs` empty
    /// without `with_x`); `None` when a pole lies on a line.
    fn line_tables(&self, th: &[f64], with_x: bool) -> Option<(Vec<c64>, Vec<c64>)> {
        let lay = self.layout;
        let (ny, nu, n, l) = (lay.ny, lay.nu, lay.n, self.data.len());
        let mut ys = vec![c64::default(); l * n * ny];
        let mut xs = vec![c64::default(); if with_x { l * n * nu } else { 0 }];
        let mut yb = vec![c64::default(); 2 * ny];
        let mut xb = vec![c64::default(); 2 * nu];
        for (k, &dk) in self.delta.iter().enumerate() {
            let mut s = 0;
            for b in &lay.blocks {
                let rb = resolvent(th, b, dk)?;
                self.y_block(th, b, &rb, &mut yb);
                if with_x {
                    self.x_block(th, b, &rb, &mut xb);
                }
                for rr in 0..b.dim {
                    let at = k * n + s + rr;
                    ys[at * ny..(at + 1) * ny].copy_from_slice(&yb[rr * ny..(rr + 1) * ny]);
                    if with_x {
                        xs[at * nu..(at + 1) * nu].copy_from_slice(&xb[rr * nu..(rr + 1) * nu]);
                    }
                }
                s += b.dim;
            }
        }
        Some((ys, xs))
    }

    /// $Y_b = C_b R_b$ ($n_y \times \dim$, column-major `y[r * ny + i]`) at line `k`.
    fn y_block(&self, th: &[f64], b: &Block, rb: &[c64; 4], out: &mut [c64]) {
        let ny = self.layout.ny;
        for i in 0..ny {
            if b.dim == 2 {
                let (c0, c1) = (
                    self.layout.c_val(th, b, i, 0),
                    self.layout.c_val(th, b, i, 1),
                );
                out[i] = rb[0] * c0 + rb[2] * c1;
                out[ny + i] = rb[1] * c0 + rb[3] * c1;
            } else {
                out[i] = rb[0] * self.layout.c_val(th, b, i, 0);
            }
        }
    }

    /// $X_b = R_b \beta_b$ ($\dim \times n_u$, row-major `x[r * nu + j]`).
    fn x_block(&self, th: &[f64], b: &Block, rb: &[c64; 4], out: &mut [c64]) {
        let nu = self.layout.nu;
        for j in 0..nu {
            if b.dim == 2 {
                let (b0, b1) = (
                    th[self.layout.beta_idx(b, 0, j)],
                    th[self.layout.beta_idx(b, 1, j)],
                );
                out[j] = rb[0] * b0 + rb[1] * b1;
                out[nu + j] = rb[2] * b0 + rb[3] * b1;
            } else {
                out[j] = rb[0] * th[self.layout.beta_idx(b, 0, j)];
            }
        }
    }

    /// The model's response at every line (scaled units), same layout as the data.
    fn response(&self, th: &[f64]) -> Option<Vec<c64>> {
        let (ny, nu) = (self.layout.ny, self.layout.nu);
        let e = ny * nu;
        let mut out = vec![c64::default(); self.data.len() * e];
        let mut yb = vec![c64::default(); 2 * ny];
        for (k, &dk) in self.delta.iter().enumerate() {
            let g = &mut out[k * e..(k + 1) * e];
            for i in 0..ny {
                for j in 0..nu {
                    g[j * ny + i] = c64::new(self.layout.d_val(th, i, j), 0.0);
                }
            }
            for b in &self.layout.blocks {
                let rb = resolvent(th, b, dk)?;
                self.y_block(th, b, &rb, &mut yb);
                // Y_b β_b
                for j in 0..nu {
                    for i in 0..ny {
                        let mut acc = c64::default();
                        for r in 0..b.dim {
                            acc += yb[r * ny + i] * th[self.layout.beta_idx(b, r, j)];
                        }
                        g[j * ny + i] += acc;
                    }
                }
            }
        }
        out.iter()
            .all(|v| v.re.is_finite() && v.im.is_finite())
            .then_some(out)
    }

    /// Fits β and D by weighted linear least squares with the poles and $C$ fixed.
    fn fit_linear(&self, th: &mut [f64]) -> Result<()> {
        self.linear_part(th, false).map(|_| ())
    }

    /// [`Self::fit_linear`]; with `basis`, also an orthonormal basis of each input column's
    /// weighted regressor (rows as in the residuals of that column: line, output, re/im), for
    /// the projection of the Jacobian ([`Projected`]).
    fn linear_part(&self, th: &mut [f64], basis: bool) -> Result<Vec<Mat<f64>>> {
        let lay = self.layout;
        let (ny, nu, l) = (lay.ny, lay.nu, self.data.len());
        let e = ny * nu;
        let nd = if lay.d_off.is_some() { ny } else { 0 };
        let ncol = lay.n + nd;
        let (ys, _) = self.line_tables(th, false).ok_or_else(|| {
            Error::numerical(
                CTX,
                "a pole of the start lies on a line of the data; lower the order",
            )
        })?;
        // one weighted least-squares problem per input column, side by side
        let solved: Vec<Result<Solved>> = (0..nu)
            .into_par_iter()
            .map(|j| {
                // filled column by column (rows: line, output, re/im)
                // [Φ g]: the regressor and the right-hand side as its last column
                let mut m = Mat::<f64>::zeros(2 * l * ny, ncol + 1);
                let sw = |k: usize, i: usize| self.data.sw[k * e + j * ny + i];
                for s in 0..lay.n {
                    let col = m.col_as_slice_mut(s);
                    for k in 0..l {
                        for i in 0..ny {
                            let v = ys[(k * lay.n + s) * ny + i] * sw(k, i);
                            let row = 2 * (k * ny + i);
                            col[row] = v.re;
                            col[row + 1] = v.im;
                        }
                    }
                }
                for i in 0..nd {
                    let col = m.col_as_slice_mut(lay.n + i);
                    for k in 0..l {
                        col[2 * (k * ny + i)] = sw(k, i);
                    }
                }
                let col = m.col_as_slice_mut(ncol);
                for k in 0..l {
                    for i in 0..ny {
                        let v = self.data.g[k * e + j * ny + i] * sw(k, i);
                        let row = 2 * (k * ny + i);
                        col[row] = v.re;
                        col[row + 1] = v.im;
                    }
                }
                scaled_lstsq(m, basis)
            })
            .collect();
        let mut bases = Vec::with_capacity(if basis { nu } else { 0 });
        for (j, sol) in solved.into_iter().enumerate() {
            let (x, q) = sol.map_err(|e| {
                Error::numerical(
                    CTX,
                    format!(
                        "the linear step (numerators) is rank deficient ({e}); lower the order"
                    ),
                )
            })?;
            if let Some(q) = q {
                bases.push(q);
            }
            let mut s = 0;
            for b in &lay.blocks {
                for r in 0..b.dim {
                    th[lay.beta_idx(b, r, j)] = x[s + r];
                }
                s += b.dim;
            }
            if let Some(off) = lay.d_off {
                for i in 0..ny {
                    th[off + i * nu + j] = x[lay.n + i];
                }
            }
        }
        Ok(bases)
    }

    /// Number of unstable poles of the loop of θ's model with the controller (0 without one);
    /// `None` when the loop cannot be formed.
    fn loop_unstable(&self, th: &[f64]) -> Option<usize> {
        let Some(c) = self.controller else {
            return Some(0);
        };
        let model = self.layout.realise(th, self.data).ok()?;
        let poles = model.feedback(c).ok()?.poles().ok()?;
        Some(poles.iter().filter(|z| z.norm() >= 1.0).count())
    }

    /// One trial per block of θ with a pole on or outside the unit circle: that block's poles
    /// mirrored and the linear parameters refitted (blocks whose refit fails are left out).
    fn mirrored_trials(&self, th: &[f64]) -> Vec<Vec<f64>> {
        let lay = self.layout;
        lay.blocks
            .iter()
            .filter_map(|b| {
                let poles = lay.block_poles(th, b);
                if !poles.iter().flatten().any(|z| z.norm() >= 1.0) {
                    return None;
                }
                let mut trial = th.to_vec();
                mirror_block(&mut trial, lay, b, &poles);
                self.fit_linear(&mut trial).ok().map(|()| trial)
            })
            .collect()
    }

    /// Mirrors unstable blocks of the start until its loop with the controller is stable: each
    /// round the mirroring that leaves the fewest unstable loop poles, then the lowest cost.
    fn stable_loop_start(&mut self, th: &mut Vec<f64>) -> Result<()> {
        let none = || {
            Error::numerical(
                CTX,
                "no start gives a stable loop with the controller (the measured loop was stable): check that the controller is the one of the measurement, or change the order",
            )
        };
        let mut now = self.loop_unstable(th).ok_or_else(none)?;
        while now > 0 {
            let mut best: Option<(usize, f64, Vec<f64>)> = None;
            for trial in self.mirrored_trials(th) {
                let Some(u) = self.loop_unstable(&trial) else {
                    continue;
                };
                let saved = self.controller.take();
                let r = self.residuals(&trial);
                self.controller = saved;
                if let Some(r) = r {
                    let cost = r.iter().map(|x| x * x).sum::<f64>();
                    if best
                        .as_ref()
                        .is_none_or(|(bu, bc, _)| (u, cost) < (*bu, *bc))
                    {
                        best = Some((u, cost, trial));
                    }
                }
            }
            match best {
                Some((u, _, t)) if u < now => {
                    now = u;
                    *th = t;
                }
                _ => return Err(none()),
            }
        }
        Ok(())
    }

    /// Mirrors unstable blocks of the start (cheapest first) until at most `lim` poles are on or
    /// outside the unit circle, refitting the linear parameters after each.
    fn constrain_start(&mut self, th: &mut Vec<f64>, lim: usize) -> Result<()> {
        let lay = self.layout;
        while lay.unstable(th) > lim {
            let mut best: Option<(f64, Vec<f64>)> = None;
            // the trials are scored without the limit (and the loop): one mirroring at a time
            // may leave more than `lim` unstable poles on the way
            let (saved_limit, saved_controller) = (self.limit.take(), self.controller.take());
            for trial in self.mirrored_trials(th) {
                if let Some(r) = self.residuals(&trial) {
                    let cost = r.iter().map(|x| x * x).sum::<f64>();
                    if best.as_ref().is_none_or(|(c, _)| cost < *c) {
                        best = Some((cost, trial));
                    }
                }
            }
            (self.limit, self.controller) = (saved_limit, saved_controller);
            match best {
                Some((_, t)) => *th = t,
                None => {
                    return Err(Error::numerical(
                        CTX,
                        format!("the start has more than {lim} unstable poles and none of its unstable blocks can be mirrored; raise the order or check max_unstable_poles"),
                    ))
                }
            }
        }
        Ok(())
    }
}

/// Replaces the poles of block `b` by their mirror images (the stable ones stay).
fn mirror_block(th: &mut [f64], lay: &Layout, b: &Block, poles: &[Option<c64>; 2]) {
    let mirrored: Vec<c64> = poles.iter().flatten().map(|&z| mirror(z)).collect();
    let ds: Vec<c64> = mirrored.iter().map(|z| (z - 1.0) / lay.h).collect();
    if b.dim == 2 {
        // δ² + α1 δ + α2 = (δ − d1)(δ − d2)
        th[b.off] = -(ds[0] + ds[1]).re;
        th[b.off + 1] = (ds[0] * ds[1]).re;
    } else {
        th[b.off] = ds[0].re;
    }
}

/// $z \mapsto 1/\bar z$ for $|z| \ge 1$, pulled just inside the unit circle.
fn mirror(z: c64) -> c64 {
    let r = z.norm();
    let out = if r >= 1.0 { z / (r * r) } else { z };
    if out.norm() >= 1.0 - 1e-9 {
        out * ((1.0 - 1e-6) / out.norm())
    } else {
        out
    }
}

impl LeastSquaresProblem for Problem<'_> {
    fn residuals(&mut self, th: &[f64]) -> Option<Vec<f64>> {
        if let Some(lim) = self.limit {
            if self.layout.unstable(th) > lim {
                return None;
            }
        }
        if self.controller.is_some() && self.loop_unstable(th)? > 0 {
            return None;
        }
        let resp = self.response(th)?;
        let (ny, nu, l) = (self.layout.ny, self.layout.nu, self.data.len());
        let e = ny * nu;
        // rows input-column-major (input, line, output, re/im): the order of the linear step's
        // regressor, so that the projection of [`Projected`] works on contiguous blocks
        let mut r = Vec::with_capacity(2 * resp.len());
        for j in 0..nu {
            for k in 0..l {
                for i in 0..ny {
                    let idx = k * e + j * ny + i;
                    let sw = self.data.sw[idx];
                    let d = (resp[idx] - self.data.g[idx]) * sw;
                    r.push(d.re);
                    r.push(d.im);
                }
            }
        }
        Some(r)
    }

    fn jacobian(&mut self, th: &[f64]) -> Option<Mat<f64>> {
        let all: Vec<Option<usize>> = (0..self.layout.n_theta).map(Some).collect();
        self.jacobian_cols(th, &all, self.layout.n_theta)
    }
}

impl Problem<'_> {
    /// The Jacobian's columns of the θ indices that `cols` maps to a column (`cols[t]`, of
    /// `ncols`); rows as [`LeastSquaresProblem::residuals`].
    fn jacobian_cols(&self, th: &[f64], cols: &[Option<usize>], ncols: usize) -> Option<Mat<f64>> {
        let lay = self.layout;
        let (ny, nu, l) = (lay.ny, lay.nu, self.data.len());
        let e = ny * nu;
        let m = 2 * l * e;
        let mut jac = Mat::<f64>::zeros(m, ncols);
        let mut yb = vec![c64::default(); 2 * ny];
        let mut xb = vec![c64::default(); 2 * nu];
        for (k, &dk) in self.delta.iter().enumerate() {
            let base = k * e;
            let put = |jac: &mut Mat<f64>, i: usize, j: usize, t: usize, v: c64| {
                if let Some(col) = cols[t] {
                    let row = 2 * ((j * l + k) * ny + i);
                    let s = self.data.sw[base + j * ny + i];
                    jac[(row, col)] = v.re * s;
                    jac[(row + 1, col)] = v.im * s;
                }
            };
            for b in &lay.blocks {
                let rb = resolvent(th, b, dk)?;
                self.y_block(th, b, &rb, &mut yb);
                self.x_block(th, b, &rb, &mut xb);
                // α
                if b.dim == 2 {
                    for i in 0..ny {
                        for j in 0..nu {
                            put(&mut jac, i, j, b.off, -(yb[ny + i] * xb[nu + j]));
                            put(&mut jac, i, j, b.off + 1, -(yb[ny + i] * xb[j]));
                        }
                    }
                } else {
                    for i in 0..ny {
                        for j in 0..nu {
                            put(&mut jac, i, j, b.off, yb[i] * xb[j]);
                        }
                    }
                }
                // β_b[r, j]: column j, every output
                for r in 0..b.dim {
                    for j in 0..nu {
                        let t = lay.beta_idx(b, r, j);
                        for i in 0..ny {
                            put(&mut jac, i, j, t, yb[r * ny + i]);
                        }
                    }
                }
                // C_b[o, r]: row o, every input
                for o in 0..ny {
                    for r in 0..b.dim {
                        if let Some(t) = lay.c_idx(b, o, r) {
                            for j in 0..nu {
                                put(&mut jac, o, j, t, xb[r * nu + j]);
                            }
                        }
                    }
                }
            }
            if let Some(off) = lay.d_off {
                for i in 0..ny {
                    for j in 0..nu {
                        put(&mut jac, i, j, off + i * nu + j, c64::new(1.0, 0.0));
                    }
                }
            }
        }
        Some(jac)
    }
}

impl Problem<'_> {
    /// The upper triangle ($(n_\psi + 1) \times (n_\psi + 1)$) of the variable projection's
    /// $[J\;r]$, where $J$ holds the columns `cols` (ψ, of `ncols`) of the Jacobian at θ
    /// projected per input column onto the orthogonal complement of that column's regressor
    /// $\Phi_j$, and `r` the residuals at θ (already orthogonal to every $\Phi_j$), without
    /// forming $J$ (module docs, "Structured triangle").
    ///
    /// For input column $j$, the triangle of $[\Phi_j\;J_j\;r_j]$ holds that of the
    /// projected $[P_j J_j\;r_j]$ as its trailing block (the Schur complement of
    /// $\Phi_j^\top\Phi_j$ in the Gram matrix). Its rows of output $i$ see only the $C$
    /// parameters (and $D_{ij}$) of that output, so the rows are factored per output — the
    /// parameters of output $i$, then the columns every output sees — and the stacked factors
    /// once more in the order $[\Phi_j \mid \psi \mid r]$; the trailing blocks of the input
    /// columns are stacked and factored last. Every step is a Householder QR, so the Gram matrix
    /// is that of the dense projected $[J\;r]$ up to rounding, with $n_y$ times fewer rows per
    /// factor for the output-specific columns. The per-output factors, of which only the Gram
    /// matrix is used, are unblocked ([`r_factor_tall`], about twice as fast on these
    /// $2L \times 49$ blocks); the factors whose trailing block is read are faer's
    /// ([`r_factor_in_place`]), which leaves a dependent column's row at zero so that the trailing
    /// block stays the projected part when $\Phi_j$ is rank deficient.
    fn projected_triangle(
        &self,
        th: &[f64],
        cols: &[Option<usize>],
        ncols: usize,
        r: &[f64],
    ) -> Option<Mat<f64>> {
        let lay = self.layout;
        let (ny, nu, l, n) = (lay.ny, lay.nu, self.data.len(), lay.n);
        let e = ny * nu;
        let nd = if lay.d_off.is_some() { ny } else { 0 };
        // columns of the factor of one input column: [D (ny) | Φ (n) | ψ (ncols) | r]
        let n_lin = nd + n;
        let kk = n_lin + ncols + 1;
        let rcol = kk - 1;
        // per output: its own columns (D_i, the free C entries of row i) first, then the ones
        // every output sees (Φ, α, r); each as (global column, source)
        #[derive(Clone, Copy)]
        enum Src {
            D,
            Phi(usize),
            /// ∂/∂α: (state of Y, state of X, sign) of −Y[:, s]X[s', :] (or +Y X for a real pole)
            Alpha(usize, usize, f64),
            /// ∂/∂C[i, s]: X[s, :]
            C(usize),
            R,
        }
        let mut shared: Vec<(usize, Src)> = (0..n).map(|s| (nd + s, Src::Phi(s))).collect();
        let mut own: Vec<Vec<(usize, Src)>> = vec![Vec::new(); ny];
        let mut s0 = 0;
        for b in &lay.blocks {
            if b.dim == 2 {
                if let Some(c) = cols[b.off] {
                    shared.push((n_lin + c, Src::Alpha(s0 + 1, s0 + 1, -1.0)));
                }
                if let Some(c) = cols[b.off + 1] {
                    shared.push((n_lin + c, Src::Alpha(s0 + 1, s0, -1.0)));
                }
            } else if let Some(c) = cols[b.off] {
                shared.push((n_lin + c, Src::Alpha(s0, s0, 1.0)));
            }
            for (o, own_o) in own.iter_mut().enumerate() {
                for rr in 0..b.dim {
                    if let Some(c) = lay.c_idx(b, o, rr).and_then(|t| cols[t]) {
                        own_o.push((n_lin + c, Src::C(s0 + rr)));
                    }
                }
            }
            s0 += b.dim;
        }
        shared.push((rcol, Src::R));
        for (i, own_i) in own.iter_mut().enumerate() {
            if nd > 0 {
                own_i.insert(0, (i, Src::D));
            }
            own_i.extend_from_slice(&shared);
        }
        let (ys, xs) = self.line_tables(th, true)?;
        let p = ncols + 1;
        let tails: Vec<Mat<f64>> = (0..nu)
            .into_par_iter()
            .map(|j| {
                let mut stacked: Vec<Mat<f64>> = Vec::with_capacity(ny);
                for (i, own_i) in own.iter().enumerate() {
                    let mut w = Mat::<f64>::zeros(2 * l, own_i.len());
                    let sw = |k: usize| self.data.sw[k * e + j * ny + i];
                    for (c, &(_, src)) in own_i.iter().enumerate() {
                        let col = w.col_as_slice_mut(c);
                        // one loop per kind of column (the kind decided once per column)
                        match src {
                            Src::D => fill_pairs(col, |k| c64::new(sw(k), 0.0)),
                            Src::Phi(s) => fill_pairs(col, |k| ys[(k * n + s) * ny + i] * sw(k)),
                            Src::Alpha(sy, sx, sign) => fill_pairs(col, |k| {
                                ys[(k * n + sy) * ny + i]
                                    * xs[(k * n + sx) * nu + j]
                                    * (sign * sw(k))
                            }),
                            Src::C(s) => fill_pairs(col, |k| xs[(k * n + s) * nu + j] * sw(k)),
                            Src::R => fill_pairs(col, |k| {
                                let at = 2 * ((j * l + k) * ny + i);
                                c64::new(r[at], r[at + 1])
                            }),
                        }
                    }
                    stacked.push(r_factor_tall(w));
                }
                let rows: usize = stacked.iter().map(|t| t.nrows()).sum();
                let mut big = Mat::<f64>::zeros(rows.max(kk), kk);
                let mut at = 0;
                for (t, own_i) in stacked.iter().zip(&own) {
                    for row in 0..t.nrows() {
                        for (c, &(g, _)) in own_i.iter().enumerate() {
                            big[(at + row, g)] = t[(row, c)];
                        }
                    }
                    at += t.nrows();
                }
                let tri = r_factor_in_place(big);
                Mat::from_fn(p, p, |a, b| tri[(n_lin + a, n_lin + b)])
            })
            .collect();
        let all = Mat::<f64>::from_fn(nu * p, p, |a, b| tails[a / p][(a % p, b)]);
        let t = r_factor_in_place(all);
        (0..p)
            .all(|c| t.col(c).iter().all(|v| v.is_finite()))
            .then_some(t)
    }
}

/// Writes $f(k)$ as the real and imaginary parts of rows $2k$ and $2k + 1$ of `col`.
#[inline(always)]
fn fill_pairs(col: &mut [f64], f: impl Fn(usize) -> c64) {
    for (k, pair) in col.chunks_exact_mut(2).enumerate() {
        let v = f(k);
        pair[0] = v.re;
        pair[1] = v.im;
    }
}

/// ψ and θ of one evaluation of [`Projected`].
type Evaluated = (Vec<f64>, Vec<f64>);

/// The refinement's problem in the nonlinear parameters alone (variable projection, Golub &
/// Pereyra 1973): ψ = (α, free rows of $C$); β and $D$ are the weighted least-squares solution
/// for ψ ([`Problem::fit_linear`]) at every evaluation, so the residual is the part of the data
/// that no numerator can fit. The Jacobian is Kaufman's: the columns of the full Jacobian in ψ
/// at the fitted β, projected per input column onto the orthogonal complement of that column's
/// regressor (the term the projection drops is of the order of the residual times the
/// derivative of the pseudo-inverse, zero on exact data).
struct Projected<'p, 'a> {
    prob: &'p mut Problem<'a>,
    /// θ indices of ψ.
    nl: Vec<usize>,
    /// ψ's column of each θ index (`None` for the linear parameters).
    cols: Vec<Option<usize>>,
    /// θ of the start; every entry outside ψ is a linear parameter, refitted at each evaluation.
    theta: Vec<f64>,
    /// The abandonment rule, when a better start has finished.
    race: Option<Race>,
    /// ψ and θ of the last residual evaluation.
    last: Option<Evaluated>,
}

impl<'p, 'a> Projected<'p, 'a> {
    fn new(prob: &'p mut Problem<'a>, theta: &[f64]) -> Self {
        let lay = prob.layout;
        let mut linear = vec![false; lay.n_theta];
        for b in &lay.blocks {
            for r in 0..b.dim {
                for j in 0..lay.nu {
                    linear[lay.beta_idx(b, r, j)] = true;
                }
            }
        }
        if let Some(off) = lay.d_off {
            for v in &mut linear[off..off + lay.ny * lay.nu] {
                *v = true;
            }
        }
        let nl: Vec<usize> = (0..lay.n_theta).filter(|&i| !linear[i]).collect();
        let mut cols = vec![None; lay.n_theta];
        for (c, &t) in nl.iter().enumerate() {
            cols[t] = Some(c);
        }
        Self {
            prob,
            nl,
            cols,
            theta: theta.to_vec(),
            race: None,
            last: None,
        }
    }

    fn psi(&self, theta: &[f64]) -> Vec<f64> {
        self.nl.iter().map(|&i| theta[i]).collect()
    }

    /// θ of ψ with the linear parameters fitted (and the bases of the projection).
    fn theta_of(&self, psi: &[f64], basis: bool) -> Option<(Vec<f64>, Vec<Mat<f64>>)> {
        let mut th = self.theta.clone();
        for (&i, &v) in self.nl.iter().zip(psi) {
            th[i] = v;
        }
        let q = self.prob.linear_part(&mut th, basis).ok()?;
        Some((th, q))
    }
}

impl LeastSquaresProblem for Projected<'_, '_> {
    fn residuals(&mut self, psi: &[f64]) -> Option<Vec<f64>> {
        // θ kept: an accepted trial's triangle is asked for next
        let (th, _) = self.theta_of(psi, false)?;
        let r = self.prob.residuals(&th)?;
        self.last = Some((psi.to_vec(), th));
        Some(r)
    }

    /// The dense projected Jacobian (the reference of [`Self::triangle`], which the
    /// iteration uses instead).
    fn jacobian(&mut self, psi: &[f64]) -> Option<Mat<f64>> {
        let (th, bases) = self.theta_of(psi, true)?;
        let mut jac = self.prob.jacobian_cols(&th, &self.cols, self.nl.len())?;
        let rows = jac.nrows() / bases.len().max(1);
        // the rows of input column j are contiguous and ordered as its regressor's; the
        // columns' projections side by side, each in place on its own rows
        let mut blocks = Vec::with_capacity(bases.len());
        let mut rest = jac.as_mut();
        for _ in 0..bases.len() {
            let (block, tail) = rest.split_at_row_mut(rows);
            blocks.push(block);
            rest = tail;
        }
        blocks
            .into_par_iter()
            .zip(bases.par_iter())
            .for_each(|(mut block, q)| {
                let t = q.transpose() * block.as_ref();
                faer::linalg::matmul::matmul(
                    block.as_mut(),
                    faer::Accum::Add,
                    q,
                    &t,
                    -1.0,
                    faer::Par::Seq,
                );
            });
        Some(jac)
    }

    /// The triangle of the projected $[J\;r]$ from the structure of the unprojected
    /// Jacobian ([`Problem::projected_triangle`]), without forming $J$ or the bases.
    fn triangle(&mut self, psi: &[f64], r: &[f64], _part_rows: usize) -> Result<Mat<f64>> {
        let th = match self.last.take() {
            Some((p, th)) if p == psi => th,
            _ => {
                self.theta_of(psi, false)
                    .ok_or_else(|| {
                        Error::numerical(
                            CTX,
                            "the numerators cannot be fitted at an accepted point",
                        )
                    })?
                    .0
            }
        };
        self.prob
            .projected_triangle(&th, &self.cols, self.nl.len(), r)
            .ok_or_else(|| Error::numerical(CTX, "the Jacobian is not finite at an accepted point"))
    }

    fn abandon(&mut self, cost: f64, predicted_reduction: f64) -> bool {
        self.race
            .as_mut()
            .is_some_and(|r| r.lost(2.0 * cost, 2.0 * predicted_reduction))
    }
}

/// Levenberg–Marquardt on `prob` from θ over the nonlinear parameters ([`Projected`]); θ with
/// its linear parameters fitted comes back with the report.
fn minimize_projected(
    prob: &mut Problem<'_>,
    theta: &[f64],
    lm: &LmOptions,
    race: Option<Race>,
    resume: Option<LmState>,
) -> Result<(Vec<f64>, super::pem::lm::LmReport, LmState)> {
    let mut proj = Projected::new(prob, theta);
    proj.race = race;
    let psi0 = proj.psi(theta);
    let (psi, report, state) = minimize_resumed(&mut proj, &psi0, lm, resume)?;
    let (th, _) = proj.theta_of(&psi, false).ok_or_else(|| {
        Error::numerical(
            CTX,
            "the numerators of the refined poles cannot be fitted (a rank-deficient linear step); lower the order",
        )
    })?;
    Ok((th, report, state))
}

/// δ at the data's lines for the warp's scale (tests of this module and of `vf`).
#[cfg(test)]
fn deltas(data: &Data, warp: &Warp) -> Vec<c64> {
    data.z.iter().map(|&z| (z - 1.0) / warp.h).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use faer::mat;
    use faer::prelude::Solve;
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn plant() -> StateSpace {
        let (r, w) = (0.99f64, 0.08f64);
        StateSpace::discrete(
            mat![
                [1.02, 0.0, 0.0, 0.0],
                [0.0, r * w.cos(), r * w.sin(), 0.0],
                [0.0, -r * w.sin(), r * w.cos(), 0.0],
                [0.0, 0.0, 0.0, 0.6]
            ],
            mat![[1.0, 0.5], [0.0, 1.0], [1.0, -0.3], [0.2, 0.7]],
            mat![
                [1.0, 0.2, 0.0, 0.5],
                [0.4, 0.0, 1.0, -0.2],
                [0.1, 0.3, 0.2, 1.0]
            ],
            mat![[0.0, 0.0], [0.0, 0.0], [0.0, 0.0]],
            1e-3,
        )
        .unwrap()
    }

    /// The exact response of [`plant`] on 40 lines as data, the true model's block layout and
    /// θ (numerators not yet fitted) and δ.
    fn true_blocks(feedthrough: bool) -> (Data, Layout, Vec<f64>, Vec<c64>) {
        let truth = plant();
        let f: Vec<f64> = (1..=40).map(|k| 4.0 * k as f64).collect();
        let frd = Frd::from_model(&truth, &f).unwrap();
        let opts = MimoFreqOptions {
            feedthrough,
            max_iterations: 0,
            ..Default::default()
        };
        let data = Data::new(&frd, &opts).unwrap();
        let warp = Warp::new(&data.f_hz, data.ts);
        let a = truth.a().to_owned();
        let c = Mat::from_fn(3, 4, |i, j| truth.c()[(i, j)] / data.a[i]);
        let (layout, th) = to_blocks(&a, &c, warp.h, 3, 2, feedthrough).unwrap();
        let delta = deltas(&data, &warp);
        (data, layout, th, delta)
    }

    /// `frd` (an exact response) with noise uniform on $[-s, s]$, $s$ = `rel` × |entry|, on
    /// each part of every entry (seeded), and its variance $2s^2/3$.
    fn with_uniform_noise(frd: &Frd, rel: f64, seed: u64) -> Frd {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let noisy: Vec<c64> = frd
            .values()
            .iter()
            .map(|v| {
                let s = rel * v.norm();
                v + c64::new(
                    s * rng.random_range(-1.0..1.0),
                    s * rng.random_range(-1.0..1.0),
                )
            })
            .collect();
        let var: Vec<f64> = frd
            .values()
            .iter()
            .map(|v| 2.0 * (rel * v.norm()).powi(2) / 3.0)
            .collect();
        Frd::new_matrix(
            frd.f_hz().to_vec(),
            frd.ny(),
            frd.nu(),
            noisy,
            Some(var),
            frd.ts(),
        )
        .unwrap()
    }

    /// The problem's Jacobian at `x` against central differences of its residuals.
    fn check_jacobian(prob: &mut impl LeastSquaresProblem, x: &[f64]) {
        let jac = prob.jacobian(x).unwrap();
        for p in 0..x.len() {
            let hstep = 1e-6 * x[p].abs().max(1e-3);
            let mut xp = x.to_vec();
            xp[p] += hstep;
            let mut xm = x.to_vec();
            xm[p] -= hstep;
            let rp = prob.residuals(&xp).unwrap();
            let rm = prob.residuals(&xm).unwrap();
            let scale = (0..rp.len())
                .map(|i| jac[(i, p)].abs())
                .fold(1e-12, f64::max);
            for i in 0..rp.len() {
                let fd = (rp[i] - rm[i]) / (2.0 * hstep);
                assert!(
                    (fd - jac[(i, p)]).abs() <= 1e-5 * scale,
                    "param {p} row {i}: fd {fd} vs {}",
                    jac[(i, p)]
                );
            }
        }
    }

    #[test]
    fn jacobian_matches_finite_differences() {
        for feedthrough in [false, true] {
            let (data, layout, mut th, delta) = true_blocks(feedthrough);
            let mut prob = Problem::new(&data, &layout, &delta, None);
            prob.fit_linear(&mut th).unwrap();
            // move off the optimum so every column is exercised
            for (i, v) in th.iter_mut().enumerate() {
                *v *= 1.0 + 0.01 * ((i * 7 % 5) as f64 - 2.0);
            }
            check_jacobian(&mut prob, &th);
        }
    }

    #[test]
    fn projected_jacobian_is_the_derivative_of_the_projected_residual_on_exact_data() {
        // at the true poles and C the projected residual is zero, where Kaufman's Jacobian is
        // the exact derivative (the term it drops is proportional to the residual)
        for feedthrough in [false, true] {
            let (data, layout, mut th, delta) = true_blocks(feedthrough);
            let mut prob = Problem::new(&data, &layout, &delta, None);
            prob.fit_linear(&mut th).unwrap();
            let mut proj = Projected::new(&mut prob, &th);
            let psi = proj.psi(&th);
            assert_eq!(psi.len(), 4 + 4 * 2, "α and the free rows of C");
            let r0 = proj.residuals(&psi).unwrap();
            let r0n = r0.iter().map(|v| v * v).sum::<f64>().sqrt();
            assert!(r0n < 1e-9, "exact data: the projected residual is {r0n}");
            check_jacobian(&mut proj, &psi);
        }
    }

    /// Gram matrix of the upper triangle `t`.
    fn gram(t: &Mat<f64>) -> Mat<f64> {
        t.transpose() * t
    }

    #[test]
    fn the_structured_triangle_has_the_gram_matrix_of_the_dense_projected_jacobian() {
        // off the optimum (ψ moved) and, in the last case, with two blocks of equal poles and
        // equal C (a rank-deficient regressor): TᵀT = [J r]ᵀ[J r] of the dense projected
        // Jacobian (the oracle: Kaufman's columns projected with explicit bases)
        for (feedthrough, repeated) in [(false, false), (true, false), (false, true)] {
            let (data, layout, mut th, delta) = true_blocks(feedthrough);
            let mut prob = Problem::new(&data, &layout, &delta, None);
            prob.fit_linear(&mut th).unwrap();
            let mut proj = Projected::new(&mut prob, &th);
            let mut psi = proj.psi(&th);
            for (k, v) in psi.iter_mut().enumerate() {
                *v *= 1.0 + 0.03 * ((k as f64) * 1.7).sin();
            }
            if repeated {
                // the two real poles' blocks made proportional (equal α, C columns
                // proportional; their fixed entries sit in different rows)
                let real: Vec<&Block> = layout.blocks.iter().filter(|b| b.dim == 1).collect();
                let (b0, b1) = (real[0], real[1]);
                let map = |t: usize| proj.cols[t].unwrap();
                psi[map(b1.off)] = psi[map(b0.off)];
                let v: Vec<f64> = (0..layout.ny)
                    .map(|o| layout.c_idx(b0, o, 0).map_or(1.0, |t| psi[map(t)]))
                    .collect();
                for o in 0..layout.ny {
                    if let Some(t) = layout.c_idx(b1, o, 0) {
                        psi[map(t)] = v[o] / v[b1.fixed_row];
                    }
                }
            }
            let (_, bases) = proj.theta_of(&psi, true).unwrap();
            let nd = if feedthrough { layout.ny } else { 0 };
            let rank = layout.n + nd - usize::from(repeated);
            assert!(
                bases.iter().all(|q| q.ncols() == rank),
                "the regressor's rank"
            );
            let r = proj.residuals(&psi).unwrap();
            let rn = r.iter().map(|v| v * v).sum::<f64>().sqrt();
            assert!(rn > 1e-3, "off the optimum: ‖r‖ = {rn}");
            let jac = proj.jacobian(&psi).unwrap();
            let dense = Mat::from_fn(jac.nrows(), jac.ncols() + 1, |i, j| {
                if j < jac.ncols() {
                    jac[(i, j)]
                } else {
                    r[i]
                }
            });
            let want = dense.transpose() * &dense;
            let t = proj.triangle(&psi, &r, 1 << 20).unwrap();
            assert_eq!((t.nrows(), t.ncols()), (psi.len() + 1, psi.len() + 1));
            for i in 0..t.nrows() {
                for j in 0..i {
                    assert_eq!(t[(i, j)], 0.0, "upper triangular");
                }
            }
            let got = gram(&t);
            let scale = (0..want.nrows()).map(|i| want[(i, i)]).fold(0.0, f64::max);
            let err = (&got - &want).norm_max() / scale;
            assert!(
                err < 1e-10,
                "feedthrough {feedthrough}, repeated {repeated}: Gram error {err:e}"
            );
        }
    }

    #[test]
    fn a_raced_run_is_abandoned_only_when_neither_prediction_reaches_the_bound() {
        // bound 100, budget 20 iterations
        let mut race = Race::new(100.0, 20);
        // the first RACE_WINDOW iterations are never abandoned
        for k in 0..RACE_WINDOW {
            assert!(!race.lost(200.0 - k as f64, 0.0));
        }
        // cost 195, pace 1 per step, 15 steps left: 180 > 100, and the Gauss–Newton step
        // predicts 50: 145 > 100 → lost
        assert!(race.lost(195.0, 50.0));
        // a Gauss–Newton prediction that reaches the bound keeps it going
        let mut race = Race::new(100.0, 20);
        for k in 0..=RACE_WINDOW {
            race.lost(200.0 - k as f64, 0.0);
        }
        assert!(!race.lost(193.0, 94.0));
        // a pace that reaches it within the budget too: 20 per step from 300, 13 steps left
        let mut race = Race::new(100.0, 20);
        for k in 0..=RACE_WINDOW {
            race.lost(400.0 - 20.0 * k as f64, 0.0);
        }
        assert!(!race.lost(260.0, 0.0));
        // …but not with fewer steps left
        let mut race = Race::new(100.0, 10);
        for k in 0..=RACE_WINDOW {
            race.lost(400.0 - 20.0 * k as f64, 0.0);
        }
        assert!(race.lost(260.0, 0.0));
    }

    #[test]
    fn exact_data_is_recovered_with_and_without_feedthrough() {
        let truth = plant();
        let f: Vec<f64> = (1..=60).map(|k| 3.0 * k as f64).collect();
        let frd = Frd::from_model(&truth, &f).unwrap();
        let fit = ss_frd_mimo(&frd, 4, &MimoFreqOptions::default()).unwrap();
        assert!(fit.errors.median_norm_relative < 1e-9, "{:?}", fit.errors);
        assert_eq!(fit.unstable_poles().unwrap(), 1);
        let mut pt = truth.poles().unwrap();
        let mut pf = fit.model.poles().unwrap();
        let key = |z: &c64| (z.re * 1e6).round() as i64 * 1000 + (z.im * 1e3).round() as i64;
        pt.sort_by_key(key);
        pf.sort_by_key(key);
        for (a, b) in pt.iter().zip(&pf) {
            assert!((a - b).norm() < 1e-8, "{a:?} {b:?}");
        }
        // with a feedthrough in the truth
        let with_d = StateSpace::discrete(
            truth.a().to_owned(),
            truth.b().to_owned(),
            truth.c().to_owned(),
            mat![[0.1, 0.0], [0.0, -0.2], [0.05, 0.3]],
            1e-3,
        )
        .unwrap();
        let frd = Frd::from_model(&with_d, &f).unwrap();
        let opts = MimoFreqOptions {
            feedthrough: true,
            ..Default::default()
        };
        let fit = ss_frd_mimo(&frd, 4, &opts).unwrap();
        assert!(fit.errors.median_norm_relative < 1e-9, "{:?}", fit.errors);
        assert!((fit.model.d()[(2, 1)] - 0.3).abs() < 1e-8);
    }

    /// The damping floor (module docs, "4. Unresolved pairs") on noisy lines of [`plant`],
    /// 4 Hz apart. A model of the plant plus a pair of $\zeta = 10^{-9}$ at 42 Hz, between two
    /// lines, with its numerators fitted to the noise, answers $10^5$ times the plant at 42 Hz;
    /// the floor moves that pair to a damping the lines accept and its peak to the plant's size.
    /// The plant's own pair at 12.7 Hz has a half-power bandwidth of 3.2 Hz, also below the
    /// spacing, but the lines beside its peak pin it down: it is kept, bit for bit.
    #[test]
    fn an_unresolved_spurious_pair_is_floored_and_a_real_light_mode_is_kept() {
        use std::f64::consts::PI;
        let truth = plant();
        let ts = 1e-3;
        let f: Vec<f64> = (1..=40).map(|k| 4.0 * k as f64).collect();
        let frd = with_uniform_noise(&Frd::from_model(&truth, &f).unwrap(), 1e-3, 11);
        let opts = MimoFreqOptions {
            max_iterations: 0,
            ..Default::default()
        };
        let data = Data::new(&frd, &opts).unwrap();
        let warp = Warp::new(&data.f_hz, data.ts);
        let delta = deltas(&data, &warp);
        // the plant plus the spurious pair
        let (f_s, zeta) = (42.0, 1e-9);
        let w = 2.0 * PI * f_s;
        let z = (c64::new(-zeta * w, w * (1.0 - zeta * zeta).sqrt()) * ts).exp();
        let mut a = Mat::<f64>::zeros(6, 6);
        a.as_mut().submatrix_mut(0, 0, 4, 4).copy_from(truth.a());
        a[(4, 4)] = z.re;
        a[(4, 5)] = z.im;
        a[(5, 4)] = -z.im;
        a[(5, 5)] = z.re;
        let c = Mat::from_fn(3, 6, |i, j| {
            let v = if j < 4 {
                truth.c()[(i, j)]
            } else {
                0.3 + 0.1 * (i + j) as f64
            };
            v / data.a[i]
        });
        let (layout, mut th) = to_blocks(&a, &c, warp.h, 3, 2, false).unwrap();
        let mut prob = Problem::new(&data, &layout, &delta, None);
        prob.fit_linear(&mut th).unwrap();
        let mut cost: f64 = prob.residuals(&th).unwrap().iter().map(|x| x * x).sum();
        let peak = |m: &StateSpace| {
            let g = Frd::from_model(m, &[f_s]).unwrap();
            let g = g.at(0).unwrap();
            (0..3)
                .flat_map(|i| (0..2).map(move |j| (i, j)))
                .map(|(i, j)| g[(i, j)].norm())
                .fold(0.0, f64::max)
        };
        let plant_peak = peak(&truth);
        let before = layout.realise(&th, &data).unwrap();
        assert!(
            peak(&before) > 1e3 * plant_peak,
            "{} {plant_peak}",
            peak(&before)
        );
        let cost_before = cost;
        let floored = floor_unresolved(&data, &delta, &layout, &mut th, &mut cost, None, None);
        assert_eq!(floored.len(), 1, "{floored:?}");
        let p = floored[0];
        assert!(
            (p.f_hz - f_s).abs() < 1e-6 && (p.spacing_hz - 4.0).abs() < 1e-9,
            "{p:?}"
        );
        assert!((p.zeta_fitted - zeta).abs() < 1e-10, "{p:?}");
        // one of Δ, Δ/2, …: half-power bandwidth 2ζf_n = 4 / 2^k Hz, f_n = f_d / √(1 − ζ²)
        let bw = 2.0 * p.zeta_floored * p.f_hz / (1.0 - p.zeta_floored.powi(2)).sqrt();
        let k = (4.0 / bw).log2();
        assert!(
            k > -1e-6 && (k - k.round()).abs() < 1e-3 && p.zeta_floored > 1e-4,
            "{p:?}"
        );
        let dof = (data.rows() - layout.n_theta) as f64;
        assert!(
            p.cost_rise <= FLOOR_CHI2_1 * (2.0 * cost_before / dof).max(1.0),
            "{p:?}"
        );
        assert!((2.0 * (cost - cost_before) - p.cost_rise).abs() < 1e-9);
        let after = layout.realise(&th, &data).unwrap();
        assert!(
            peak(&after) < 2.0 * plant_peak,
            "{} {plant_peak}",
            peak(&after)
        );
        // the plant's pair: the same poles as before the floor
        let pair = |m: &StateSpace| {
            m.poles()
                .unwrap()
                .into_iter()
                .filter(|z| z.im > 0.0 && (z.arg() / (2.0 * PI * ts) - 12.73).abs() < 0.1)
                .collect::<Vec<_>>()
        };
        let (pb, pa) = (pair(&before), pair(&after));
        assert_eq!(pb.len(), 1);
        assert!((pb[0] - pa[0]).norm() < 1e-12, "{pb:?} {pa:?}");
        // without variances (uniform weights) the cost has no noise scale: nothing is floored,
        // and an exact response is fitted exactly, light pair and all (a pair of bandwidth
        // 1.6 Hz on lines 2 Hz apart, the Python package's test case)
        let (r, w) = (0.995f64, 0.05f64);
        let light = StateSpace::discrete(
            mat![
                [1.01, 0.0, 0.0],
                [0.0, r * w.cos(), r * w.sin()],
                [0.0, -r * w.sin(), r * w.cos()]
            ],
            mat![[1.0, 0.5], [0.0, 1.0], [1.0, -0.3]],
            mat![[1.0, 0.2, 0.0], [0.4, 0.0, 1.0]],
            mat![[0.0, 0.0], [0.0, 0.0]],
            ts,
        )
        .unwrap();
        let lines: Vec<f64> = (1..=80).map(|k| 2.0 * k as f64).collect();
        let exact = Frd::from_model(&light, &lines).unwrap();
        for frd in [exact.clone(), exact.entry(0, 0).unwrap()] {
            let fit = ss_frd_mimo(&frd, 3, &MimoFreqOptions::default()).unwrap();
            assert!(fit.floored.is_empty(), "{:?}", fit.floored);
            assert!(fit.errors.max_norm_relative < 1e-9, "{:?}", fit.errors);
        }
    }

    #[test]
    fn the_unstable_limit_holds_and_nothing_is_reflected_without_it() {
        let truth = plant();
        let f: Vec<f64> = (1..=60).map(|k| 3.0 * k as f64).collect();
        let frd = Frd::from_model(&truth, &f).unwrap();
        let opts = MimoFreqOptions {
            max_unstable_poles: Some(0),
            ..Default::default()
        };
        let fit = ss_frd_mimo(&frd, 4, &opts).unwrap();
        assert_eq!(fit.unstable_poles().unwrap(), 0);
        // the best stable model cannot reproduce an unstable plant
        assert!(fit.errors.median_norm_relative > 1e-3, "{:?}", fit.errors);
    }

    #[test]
    fn a_start_with_several_surplus_unstable_poles_is_mirrored_one_by_one() {
        // two unstable real poles: a limit of 0 mirrors both (the first mirroring alone still
        // leaves one above the limit, so the trials are scored without it)
        let (r, w) = (0.99f64, 0.08f64);
        let truth = StateSpace::discrete(
            mat![
                [1.02, 0.0, 0.0, 0.0],
                [0.0, 1.01, 0.0, 0.0],
                [0.0, 0.0, r * w.cos(), r * w.sin()],
                [0.0, 0.0, -r * w.sin(), r * w.cos()]
            ],
            mat![[1.0, 0.5], [0.3, 1.0], [1.0, -0.3], [0.0, 1.0]],
            mat![[1.0, 0.2, 0.0, 0.5], [0.4, 1.0, 1.0, -0.2]],
            mat![[0.0, 0.0], [0.0, 0.0]],
            1e-3,
        )
        .unwrap();
        let f: Vec<f64> = (1..=60).map(|k| 3.0 * k as f64).collect();
        let frd = Frd::from_model(&truth, &f).unwrap();
        for lim in [0usize, 1, 2] {
            let opts = MimoFreqOptions {
                max_unstable_poles: Some(lim),
                ..Default::default()
            };
            let fit = ss_frd_mimo(&frd, 4, &opts).unwrap();
            assert!(fit.unstable_poles().unwrap() <= lim, "limit {lim}");
            if lim == 2 {
                assert!(fit.errors.median_norm_relative < 1e-8, "{:?}", fit.errors);
            } else {
                // a stable pole cannot reproduce an unstable one
                assert!(fit.errors.median_norm_relative > 1e-4, "{:?}", fit.errors);
            }
        }
    }

    #[test]
    fn an_order_below_the_measured_unstable_count_is_refused() {
        // two unstable real poles coupled through B, a PI controller per axis (stable loop)
        let ts = 1e-3;
        let p = StateSpace::discrete(
            mat![[1.02, 0.0, 0.0], [0.0, 1.01, 0.0], [0.0, 0.0, 0.7]],
            mat![[1.0, 0.3], [0.2, 1.0], [1.0, 1.0]],
            mat![[0.02, 0.0, 0.01], [0.0, 0.02, -0.01]],
            mat![[0.0, 0.0], [0.0, 0.0]],
            ts,
        )
        .unwrap();
        let diag = |v: f64| mat![[v, 0.0], [0.0, v]];
        let c = StateSpace::discrete(diag(1.0), diag(0.02), diag(3.0), diag(3.0), ts).unwrap();
        assert!(p.feedback(&c).unwrap().is_stable().unwrap());
        let f: Vec<f64> = (1..1000).map(|k| k as f64 * 0.5).collect();
        let frd = Frd::from_model(&p, &f).unwrap();
        let e = ss_frd_mimo_in_loop(&frd, 1, &MimoFreqOptions::default(), &c).unwrap_err();
        assert!(
            matches!(e, Error::InvalidArgument { name: "order", .. }),
            "{e}"
        );
        assert!(e.to_string().contains("at least 2"), "{e}");
        let lim = MimoFreqOptions {
            max_unstable_poles: Some(1),
            ..Default::default()
        };
        let e = ss_frd_mimo_in_loop(&frd, 3, &lim, &c).unwrap_err();
        assert!(e.to_string().contains("raise it to 2"), "{e}");
        // the order that can hold the count is fitted, with both unstable poles
        let fit = ss_frd_mimo_in_loop(&frd, 3, &MimoFreqOptions::default(), &c).unwrap();
        assert_eq!(fit.unstable_poles().unwrap(), 2);
        assert!(fit.errors.median_norm_relative < 1e-6, "{:?}", fit.errors);
    }

    /// A plant with two unstable poles `p1`, `p2` and an input gain `g` that move with the
    /// speed (1 ms sample time).
    fn moving_plant(p1: f64, p2: f64, g: f64) -> StateSpace {
        StateSpace::discrete(
            mat![[p1, 0.0, 0.0], [0.0, p2, 0.0], [0.0, 0.0, 0.7]],
            mat![[1.0, 0.3], [0.2, g], [1.0, 1.0]],
            mat![[0.02, 0.0, 0.01], [0.0, 0.02, -0.01]],
            mat![[0.0, 0.0], [0.0, 0.0]],
            1e-3,
        )
        .unwrap()
    }

    /// The stabilising controller of [`moving_plant`], the lines, and the in-loop fit of order
    /// 3 at the first speed (exact data).
    fn neighbour_case() -> (StateSpace, Vec<f64>, MimoFreqFit) {
        let diag = |v: f64| mat![[v, 0.0], [0.0, v]];
        let c = StateSpace::discrete(diag(1.0), diag(0.02), diag(3.0), diag(3.0), 1e-3).unwrap();
        let f: Vec<f64> = (1..1000).map(|k| k as f64 * 0.5).collect();
        let frd = Frd::from_model(&moving_plant(1.02, 1.01, 1.0), &f).unwrap();
        let first = ss_frd_mimo_in_loop(&frd, 3, &MimoFreqOptions::default(), &c).unwrap();
        (c, f, first)
    }

    /// A fit from a neighbour's model (the same two-unstable-pole plant with its poles and
    /// one input gain moved a few per cent, as a speed moves a rotor's modes): the moved plant
    /// is recovered to the exact data's precision from the neighbour's model alone, and a start
    /// of another shape or sample time is refused.
    #[test]
    fn a_fit_from_a_neighbours_model_recovers_the_moved_plant() {
        let (ts, o) = (1e-3, MimoFreqOptions::default());
        let (c, f, first) = neighbour_case();
        let moved = moving_plant(1.025, 1.008, 1.05);
        assert!(moved.feedback(&c).unwrap().is_stable().unwrap());
        let frd = Frd::from_model(&moved, &f).unwrap();
        let next = ss_frd_mimo_in_loop_from(&frd, &o, &c, &first.model).unwrap();
        assert_eq!(next.model.order(), 3);
        assert_eq!(next.unstable_poles().unwrap(), 2);
        assert!(next.errors.median_norm_relative < 1e-6, "{:?}", next.errors);
        let mut poles: Vec<f64> = next.model.poles().unwrap().iter().map(|p| p.re).collect();
        poles.sort_by(f64::total_cmp);
        for (p, t) in poles.iter().zip([0.7, 1.008, 1.025]) {
            assert!((p - t).abs() < 1e-6, "{poles:?}");
        }
        // a start of another shape, or at another sample time
        let siso =
            StateSpace::discrete(mat![[0.5]], mat![[1.0]], mat![[1.0]], mat![[0.0]], ts).unwrap();
        let e = ss_frd_mimo_in_loop_from(&frd, &o, &c, &siso).unwrap_err();
        assert!(matches!(e, Error::DimensionMismatch { .. }), "{e}");
        let slow = StateSpace::discrete(
            first.model.a().to_owned(),
            first.model.b().to_owned(),
            first.model.c().to_owned(),
            first.model.d().to_owned(),
            2.0 * ts,
        )
        .unwrap();
        let e = ss_frd_mimo_in_loop_from(&frd, &o, &c, &slow).unwrap_err();
        assert!(e.to_string().contains("sample time"), "{e}");
    }

    /// [`MimoFreqOptions::abandon_unless`]: a level every state reaches changes nothing (the
    /// same bits as without it); a level no model can reach ends the refinement after the
    /// race's first window with the state where it stopped, marked abandoned; the bounds are
    /// the closed forms of [`CostTarget`].
    #[test]
    fn a_fit_held_to_an_unreachable_level_is_abandoned_and_a_reachable_one_changes_nothing() {
        let o = MimoFreqOptions::default();
        let (c, f, first) = neighbour_case();
        let frd = Frd::from_model(&moving_plant(1.04, 1.0, 1.3), &f).unwrap();
        let free = ss_frd_mimo_in_loop_from(&frd, &o, &c, &first.model).unwrap();
        assert!(!free.abandoned);
        // a level every state meets: the same computation
        let easy = MimoFreqOptions {
            abandon_unless: Some(CostTarget::Bic(f64::INFINITY)),
            ..o
        };
        let same = ss_frd_mimo_in_loop_from(&frd, &easy, &c, &first.model).unwrap();
        assert!(!same.abandoned);
        assert_eq!(same.cost.to_bits(), free.cost.to_bits());
        assert_eq!(same.model.a().to_owned(), free.model.a().to_owned());
        assert_eq!(same.iterations, free.iterations);
        // a level below every cost: abandoned after the race's window of steps (the fit from
        // the neighbour's model takes more than that on its own)
        assert!(free.iterations > RACE_WINDOW, "{}", free.iterations);
        let hard = MimoFreqOptions {
            abandon_unless: Some(CostTarget::Bic(-1e12)),
            ..o
        };
        let given_up = ss_frd_mimo_in_loop_from(&frd, &hard, &c, &first.model).unwrap();
        assert!(given_up.abandoned);
        assert!(
            given_up.iterations < free.iterations,
            "{}",
            given_up.iterations
        );
        assert!(
            given_up.cost >= free.cost,
            "{} vs {}",
            given_up.cost,
            free.cost
        );
        // a fit from a given model abandoned in its probe has no probed starts to resume
        assert!(given_up.probed.is_none() || given_up.iterations > PROBE_ITERATIONS);
        // from scratch: abandoned in a refinement, then resumed without the level, it is the
        // fit without the level, to the bit
        // (noisy lines with their variances, an order below the plant's: a long refinement)
        let frd = with_uniform_noise(&frd, 0.02, 7);
        let scratch = ss_frd_mimo_in_loop(&frd, 2, &o, &c).unwrap();
        let held = ss_frd_mimo_in_loop(&frd, 2, &hard, &c).unwrap();
        eprintln!(
            "scratch {} steps, held {} steps (abandoned {})",
            scratch.iterations, held.iterations, held.abandoned
        );
        assert!(held.abandoned && held.probed.is_some());
        let resumed = ss_frd_mimo_in_loop_resumed(&frd, &o, &c, &held).unwrap();
        assert!(!resumed.abandoned && resumed.probed.is_none());
        assert_eq!(resumed.cost.to_bits(), scratch.cost.to_bits());
        assert_eq!(resumed.model.a().to_owned(), scratch.model.a().to_owned());
        assert_eq!(resumed.iterations, scratch.iterations);
        // resumed against the level again: abandoned again; a finished fit has nothing to resume
        assert!(
            ss_frd_mimo_in_loop_resumed(&frd, &hard, &c, &held)
                .unwrap()
                .abandoned
        );
        let e = ss_frd_mimo_in_loop_resumed(&frd, &o, &c, &scratch).unwrap_err();
        assert!(e.to_string().contains("no probed starts"), "{e}");
        // another order's problem refuses the starts
        let other = Frd::from_model(&moving_plant(1.04, 1.0, 1.3), &f[..500]).unwrap();
        let e = ss_frd_mimo_in_loop_resumed(&other, &o, &c, &held).unwrap_err();
        assert!(e.to_string().contains("equations"), "{e}");
        // the closed forms
        let (n_eq, n_p) = (free.n_equations, free.n_params);
        let nu = (n_eq - n_p) as f64;
        let v = CostTarget::NoiseLevel { quantile: 2.326 }.cost_bound(n_eq, n_p);
        assert!((2.0 * v / nu - (1.0 + 2.326 * (2.0 / nu).sqrt())).abs() < 1e-12);
        let b = CostTarget::Bic(free.bic()).cost_bound(n_eq, n_p);
        assert!(
            (b - free.cost).abs() <= 1e-9 * free.cost.max(1.0),
            "{b} vs {}",
            free.cost
        );
    }

    #[test]
    fn the_projection_basis_of_a_rank_deficient_regressor_spans_its_range_only() {
        // 300 × 6 with column 4 = column 1 − 2 · column 2: the projection onto the range is
        // that of the five independent columns (normal equations, the oracle)
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let mut a = Mat::<f64>::from_fn(300, 6, |_, _| rng.random::<f64>() - 0.5);
        for r in 0..300 {
            a[(r, 4)] = a[(r, 1)] - 2.0 * a[(r, 2)];
        }
        let rhs = Mat::<f64>::from_fn(300, 1, |_, _| rng.random::<f64>() - 0.5);
        let aug = Mat::<f64>::from_fn(300, 7, |r, c| if c < 6 { a[(r, c)] } else { rhs[(r, 0)] });
        let (x, q) = scaled_lstsq(aug.clone(), true).unwrap();
        let (x2, none) = scaled_lstsq(aug, false).unwrap();
        assert!(none.is_none());
        for (u, v) in x.iter().zip(&x2) {
            assert!((u - v).abs() < 1e-10 * (1.0 + u.abs()), "{u} against {v}");
        }
        let q = q.unwrap();
        assert_eq!(q.ncols(), 5, "one basis vector per independent column");
        let ind = Mat::<f64>::from_fn(300, 5, |r, c| a[(r, [0, 1, 2, 3, 5][c])]);
        let gram = ind.transpose() * &ind;
        let v = Mat::<f64>::from_fn(300, 1, |_, _| rng.random::<f64>() - 0.5);
        let coef = gram.partial_piv_lu().solve(ind.transpose() * &v);
        let oracle = &ind * coef;
        let ours = &q * (q.transpose() * &v);
        let err = (&ours - &oracle).norm_l2() / v.norm_l2();
        assert!(err < 1e-10, "projection error {err:e}");
        // the solution is a least-squares one: its residual is orthogonal to the range
        let xm = Mat::<f64>::from_fn(6, 1, |r, _| x[r]);
        let res = &rhs - &a * xm;
        let along = (ind.transpose() * &res).norm_l2() / rhs.norm_l2();
        assert!(along < 1e-10, "residual along the range {along:e}");
    }

    #[test]
    fn bad_input_is_refused() {
        let truth = plant();
        let f: Vec<f64> = (1..=10).map(|k| 3.0 * k as f64).collect();
        let frd = Frd::from_model(&truth, &f).unwrap();
        let o = MimoFreqOptions::default();
        assert!(matches!(
            ss_frd_mimo(&frd, 0, &o),
            Err(Error::InvalidArgument { .. })
        ));
        // 10 lines of a 3×2 FRF: 120 equations, order 30 has 150 parameters
        assert!(matches!(
            ss_frd_mimo(&frd, 30, &o),
            Err(Error::InvalidArgument { .. })
        ));
        let iv = MimoFreqOptions {
            weights: MimoWeights::InverseVariance,
            ..Default::default()
        };
        let err = ss_frd_mimo(&frd, 2, &iv).unwrap_err();
        assert!(err.to_string().contains("variances"), "{err}");
        let band = MimoFreqOptions {
            band_hz: Some((1000.0, 2000.0)),
            ..Default::default()
        };
        assert!(ss_frd_mimo(&frd, 2, &band).is_err());
        let cont = Frd::new_matrix(
            f.clone(),
            1,
            1,
            f.iter().map(|_| c64::new(1.0, 0.0)).collect(),
            None,
            None,
        )
        .unwrap();
        assert!(ss_frd_mimo(&cont, 1, &o).is_err());
    }
}
