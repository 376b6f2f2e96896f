//! Dense linear-algebra glue on [faer]: what the identification code needs and faer does not
//! provide directly.
//!
//! * [`expm`]: matrix exponential by Padé(13) scaling and squaring (Higham 2005).
//! * [`eigenvalues`]: eigenvalues of a general real matrix (faer's real Schur based EVD).
//! * [`roots`]: polynomial roots as eigenvalues of the balanced companion matrix.
//! * [`lstsq`]: least squares by Householder QR.
//! * [`solve`], [`solve_c64`]: square solves by LU with partial pivoting.
//! * [`singular_values`]: singular values, largest first.
//! * [`logm`]: principal matrix logarithm by inverse scaling and squaring.
//! * [`sqrtm`]: principal matrix square root by the scaled product Denman–Beavers iteration.
//! * [`generalized_eigenvalues`]: eigenvalues of the pencil $A - \lambda E$ as pairs $(\alpha, \beta)$.
//! * [`charpoly`]: characteristic polynomial $\det(zI - A)$.
//! * [`dare`]: stabilising solution of the discrete algebraic Riccati equation (doubling algorithm).
//!
//! # Matrix exponential
//! With $s = \max(0, \lceil \log_2(\lVert A \rVert_1 / \theta_{13}) \rceil)$ and the $[13/13]$ Padé
//! approximant $r_{13}(X) = q_{13}(X)^{-1} p_{13}(X)$,
//! $$ e^{A} \approx r_{13}(2^{-s}A)^{2^s}, \qquad \theta_{13} = 5.37192\ldots, $$
//! which is accurate to double precision in exact arithmetic (backward error below $2^{-53}$).
//!
//! # Matrix logarithm
//! For $A$ with no eigenvalue on the closed negative real axis, the principal logarithm is the
//! unique $X$ with $e^X = A$ and $|\operatorname{Im}\lambda(X)| < \pi$. Inverse scaling and
//! squaring takes $k$ square roots until $\lVert A^{1/2^k} - I \rVert_1 \le 1/4$ and then
//! $$ \log A = 2^k \log(I + E), \qquad
//!    \log(I + E) = \int_0^1 E (I + tE)^{-1}\,dt \approx \sum_{j=1}^{m} w_j E (I + t_j E)^{-1}, $$
//! with $m$-point Gauss–Legendre nodes $t_j$ and weights $w_j$ on $[0, 1]$ (which is the $[m/m]$ Padé
//! approximant of $\log(1+x)$; with $m = 10$ and $\lVert E \rVert \le 1/4$ its truncation error is far
//! below the unit roundoff). The square roots use the scaled product form of the Denman–Beavers
//! iteration (Higham, *Functions of Matrices*, 2008, eq. 6.29), in real arithmetic, so a real
//! matrix gets its real principal logarithm.
//!
//! # Example
//! ```
//! use ambid_core::linalg::{expm, roots};
//! use faer::mat;
//! let a = mat![[0.0, 1.0], [-1.0, 0.0]];
//! let e = expm(a.as_ref()).unwrap();
//! assert!((e[(0, 0)] - 1f64.cos()).abs() < 1e-14);
//! // z^2 - 3z + 2 = (z - 1)(z - 2)
//! let mut r: Vec<f64> = roots(&[1.0, -3.0, 2.0]).unwrap().iter().map(|z| z.re).collect();
//! r.sort_by(|a, b| a.partial_cmp(b).unwrap());
//! assert!((r[0] - 1.0).abs() < 1e-12 && (r[1] - 2.0).abs() < 1e-12);
//! ```

use crate::error::{Error, Result};
use faer::linalg::solvers::{Solve, SolveLstsq};
use faer::{c64, Mat, MatRef};

/// The entries of `a` row by row (a row-major copy), for per-sample loops that take inner
/// products with rows.
pub(crate) fn row_major(a: MatRef<'_, f64>) -> Vec<f64> {
    (0..a.nrows())
        .flat_map(|i| (0..a.ncols()).map(move |j| a[(i, j)]))
        .collect()
}

/// Induced 1-norm (maximum absolute column sum).
pub fn norm1(a: MatRef<'_, f64>) -> f64 {
    (0..a.ncols())
        .map(|j| (0..a.nrows()).map(|i| a[(i, j)].abs()).sum::<f64>())
        .fold(0.0, f64::max)
}

fn check_square(context: &'static str, a: MatRef<'_, f64>) -> Result<()> {
    if a.nrows() != a.ncols() {
        return Err(Error::DimensionMismatch {
            context,
            expected: "a square matrix".into(),
            got: format!("{}×{}", a.nrows(), a.ncols()),
        });
    }
    check_finite_mat(context, a)
}

fn check_finite_mat(context: &'static str, a: MatRef<'_, f64>) -> Result<()> {
    for j in 0..a.ncols() {
        for i in 0..a.nrows() {
            if !a[(i, j)].is_finite() {
                return Err(Error::numerical(
                    context,
                    format!("matrix entry ({i}, {j}) is not finite"),
                ));
            }
        }
    }
    Ok(())
}

/// Matrix exponential $e^{A}$ by Padé(13) scaling and squaring, on the balanced matrix
/// ($e^{A} = D\,e^{D^{-1} A D}\,D^{-1}$, see [`balance_with_scaling`]).
///
/// Complexity $O(n^3 (6 + s))$. Errors on a non-square or non-finite matrix.
pub fn expm(a: MatRef<'_, f64>) -> Result<Mat<f64>> {
    check_square("expm", a)?;
    let n = a.nrows();
    if n == 0 {
        return Ok(Mat::zeros(0, 0));
    }
    const B: [f64; 14] = [
        64764752532480000.0,
        32382376266240000.0,
        7771770303897600.0,
        1187353796428800.0,
        129060195264000.0,
        10559470521600.0,
        670442572800.0,
        33522128640.0,
        1323241920.0,
        40840800.0,
        960960.0,
        16380.0,
        182.0,
        1.0,
    ];
    const THETA13: f64 = 5.371920351148152;
    // Balance first, e^{A} = D e^{D^{-1} A D} D^{-1}: exact scaling by powers of two that makes
    // the result accurate entry by entry for badly scaled matrices (and often lowers the norm).
    let (bal, dscale) = balance_with_scaling(a);
    let a = bal.as_ref();
    let nrm = norm1(a);
    let s = if nrm > THETA13 {
        (nrm / THETA13).log2().ceil().max(0.0) as i32
    } else {
        0
    };
    let scale = 0.5f64.powi(s);
    let x = Mat::from_fn(n, n, |i, j| a[(i, j)] * scale);
    let id = Mat::<f64>::identity(n, n);
    let x2 = &x * &x;
    let x4 = &x2 * &x2;
    let x6 = &x4 * &x2;
    let lin = |c6: f64, c4: f64, c2: f64, c0: f64| {
        Mat::from_fn(n, n, |i, j| {
            c6 * x6[(i, j)] + c4 * x4[(i, j)] + c2 * x2[(i, j)] + c0 * id[(i, j)]
        })
    };
    let u_inner = &x6 * lin(B[13], B[11], B[9], 0.0) + lin(B[7], B[5], B[3], B[1]);
    let u = &x * &u_inner;
    let v = &x6 * lin(B[12], B[10], B[8], 0.0) + lin(B[6], B[4], B[2], B[0]);
    let p = &v + &u;
    let q = &v - &u;
    let mut r = q.partial_piv_lu().solve(&p);
    check_finite_mat("expm", r.as_ref())?;
    for _ in 0..s {
        r = &r * &r;
    }
    Ok(Mat::from_fn(n, n, |i, j| dscale[i] * r[(i, j)] / dscale[j]))
}

/// Eigenvalues of a general real square matrix, computed on the balanced matrix
/// ([`balance`]) so that badly scaled matrices keep their small eigenvalues accurate.
pub fn eigenvalues(a: MatRef<'_, f64>) -> Result<Vec<c64>> {
    check_square("eigenvalues", a)?;
    if a.nrows() == 0 {
        return Ok(Vec::new());
    }
    balance(a)
        .eigenvalues()
        .map_err(|e| Error::numerical("eigenvalues", format!("{e:?}")))
}

/// Parlett–Reinsch balancing: returns $D^{-1} A D$ with $D$ a diagonal of powers of two.
pub fn balance(a: MatRef<'_, f64>) -> Mat<f64> {
    balance_with_scaling(a).0
}

/// Parlett–Reinsch balancing with its scaling: returns $(B, d)$ with $B = D^{-1} A D$,
/// $D = \operatorname{diag}(d)$, every $d_i$ a power of two (so $B$ is exact in floating point).
///
/// Balancing equalises the norms of each row and its column, which makes eigenvalues and the
/// matrix exponential of badly scaled matrices (states in m, rad, A and gains of $10^4$ A/m side
/// by side) accurate componentwise, not only normwise.
pub fn balance_with_scaling(a: MatRef<'_, f64>) -> (Mat<f64>, Vec<f64>) {
    let n = a.nrows();
    let mut m = a.to_owned();
    let mut d = vec![1.0f64; n];
    let radix = 2.0f64;
    let mut converged = false;
    let mut sweeps = 0;
    while !converged && sweeps < 100 {
        converged = true;
        sweeps += 1;
        for i in 0..n {
            let mut c = 0.0;
            let mut r = 0.0;
            for j in 0..n {
                if j != i {
                    c += m[(j, i)].abs();
                    r += m[(i, j)].abs();
                }
            }
            if c == 0.0 || r == 0.0 {
                continue;
            }
            let s = c + r;
            let mut f = 1.0;
            let mut cc = c;
            let mut rr = r;
            while cc < rr / radix {
                cc *= radix;
                rr /= radix;
                f *= radix;
            }
            while cc >= rr * radix {
                cc /= radix;
                rr *= radix;
                f /= radix;
            }
            if (cc + rr) < 0.95 * s {
                converged = false;
                d[i] *= f;
                for j in 0..n {
                    m[(i, j)] /= f;
                }
                for j in 0..n {
                    m[(j, i)] *= f;
                }
            }
        }
    }
    (m, d)
}

/// Roots of the polynomial $c_0 z^{m} + c_1 z^{m-1} + \dots + c_m$ (coefficients in *descending*
/// powers, as `numpy.roots`).
///
/// Leading zeros are dropped; trailing zeros give roots at 0. The roots are the eigenvalues of the
/// balanced companion matrix. A polynomial in ascending powers of $q^{-1}$, $[1, a_1, \dots, a_n]$,
/// has the same coefficient list in descending powers of $z$, so `roots(&a)` gives its zeros in $z$.
pub fn roots(coeffs: &[f64]) -> Result<Vec<c64>> {
    crate::error::check_finite("polynomial coefficients", coeffs)?;
    let first = match coeffs.iter().position(|c| *c != 0.0) {
        Some(f) => f,
        None => {
            return Err(Error::invalid(
                "coeffs",
                "the zero polynomial has no defined roots",
            ))
        }
    };
    let c = &coeffs[first..];
    let last = c.iter().rposition(|v| *v != 0.0).unwrap_or(0);
    let n_zero = c.len() - 1 - last;
    let c = &c[..=last];
    let m = c.len() - 1;
    let mut out = Vec::with_capacity(m + n_zero);
    if m > 0 {
        let comp = Mat::from_fn(m, m, |i, j| {
            if i == 0 {
                -c[j + 1] / c[0]
            } else if i == j + 1 {
                1.0
            } else {
                0.0
            }
        });
        let bal = balance(comp.as_ref());
        out.extend(eigenvalues(bal.as_ref())?);
    }
    out.extend(std::iter::repeat_n(c64::new(0.0, 0.0), n_zero));
    Ok(out)
}

/// Monic real polynomial (descending powers) with the given roots. Complex roots must come in
/// conjugate pairs; imaginary parts of the product are discarded.
pub fn poly_from_roots(r: &[c64]) -> Vec<f64> {
    let mut p = vec![c64::new(1.0, 0.0)];
    for z in r {
        let mut q = vec![c64::new(0.0, 0.0); p.len() + 1];
        for (k, pk) in p.iter().enumerate() {
            q[k] += *pk;
            q[k + 1] -= *pk * *z;
        }
        p = q;
    }
    p.into_iter().map(|z| z.re).collect()
}

/// Least-squares solution of $\min_X \lVert A X - B \rVert_F$ by Householder QR.
///
/// Requires `A` to have at least as many rows as columns and full column rank; a rank-deficient
/// problem is reported as [`Error::Numerical`].
pub fn lstsq(a: MatRef<'_, f64>, b: MatRef<'_, f64>) -> Result<Mat<f64>> {
    if a.nrows() != b.nrows() {
        return Err(Error::DimensionMismatch {
            context: "lstsq",
            expected: format!("{} right-hand-side rows", a.nrows()),
            got: format!("{}", b.nrows()),
        });
    }
    if a.nrows() < a.ncols() {
        return Err(Error::invalid(
            "a",
            format!(
                "least squares needs at least as many equations ({}) as unknowns ({}); collect more data or reduce the model order",
                a.nrows(),
                a.ncols()
            ),
        ));
    }
    check_finite_mat("lstsq", a)?;
    check_finite_mat("lstsq", b)?;
    let sv = singular_values(a)?;
    if let (Some(&smax), Some(&smin)) = (sv.first(), sv.last()) {
        if smax == 0.0 || smin <= smax * 1e-13 * (a.nrows().max(a.ncols()) as f64) {
            return Err(Error::numerical(
                "lstsq",
                format!("regressor matrix is rank deficient (singular values {smax:.3e} … {smin:.3e}); the data do not excite all parameters"),
            ));
        }
    }
    let x = a.qr().solve_lstsq(b);
    check_finite_mat("lstsq", x.as_ref())?;
    Ok(x)
}

/// Minimum-norm least-squares solution of $\min_x \lVert A x - b \rVert$ for a possibly
/// rank-deficient $A$ (one right-hand side): the truncated-SVD solution
/// $x = \sum_{\sigma_k > \tau \sigma_1} v_k\, u_k^{\mathsf T} b / \sigma_k$ with the relative
/// tolerance $\tau$ = `rtol`. The directions of $x$ the data cannot see are set to zero (e.g.
/// the unobservable states of an initial-state estimate).
///
/// # Example
/// ```
/// use ambid_core::linalg::lstsq_min_norm;
/// // two equal columns: the minimum-norm solution splits the weight equally
/// let a = faer::mat![[1.0, 1.0], [2.0, 2.0]];
/// let b = faer::mat![[2.0], [4.0]];
/// let x = lstsq_min_norm(a.as_ref(), b.as_ref(), 1e-12).unwrap();
/// assert!((x[0] - 1.0).abs() < 1e-12 && (x[1] - 1.0).abs() < 1e-12);
/// ```
///
/// # Errors
/// [`Error::DimensionMismatch`] for a `b` that is not one column of `A`'s rows; [`Error::NonFinite`];
/// [`Error::Numerical`] if the SVD fails.
pub fn lstsq_min_norm(a: MatRef<'_, f64>, b: MatRef<'_, f64>, rtol: f64) -> Result<Vec<f64>> {
    lstsq_min_norm_range(a, b, rtol, false).map(|(x, _)| x)
}

/// [`lstsq_min_norm`] and, with `range`, an orthonormal basis of $A$'s numerical range: the
/// left singular vectors $u_k$ with $\sigma_k > \tau \sigma_1$, the same ones the solution
/// uses, so that $U U^{\mathsf T}$ is the projection onto the part of the range the solution
/// sees. (A Householder $Q$ of a rank-deficient $A$ is no such basis: its columns span the
/// range plus one spurious direction per dependent column.)
///
/// # Example
/// ```
/// use ambid_core::linalg::lstsq_min_norm_range;
/// let a = faer::mat![[1.0, 1.0], [2.0, 2.0], [0.0, 0.0]];
/// let b = faer::mat![[2.0], [4.0], [1.0]];
/// let (x, u) = lstsq_min_norm_range(a.as_ref(), b.as_ref(), 1e-12, true).unwrap();
/// let u = u.unwrap();
/// assert_eq!(u.ncols(), 1); // rank one
/// assert!((u[(0, 0)].abs() - 1.0 / 5f64.sqrt()).abs() < 1e-12);
/// assert!((x[0] - 1.0).abs() < 1e-12 && (x[1] - 1.0).abs() < 1e-12);
/// ```
///
/// # Errors
/// As [`lstsq_min_norm`].
pub fn lstsq_min_norm_range(
    a: MatRef<'_, f64>,
    b: MatRef<'_, f64>,
    rtol: f64,
    range: bool,
) -> Result<(Vec<f64>, Option<Mat<f64>>)> {
    if a.nrows() != b.nrows() || b.ncols() != 1 {
        return Err(Error::DimensionMismatch {
            context: "lstsq_min_norm",
            expected: format!("{} × 1 right-hand side", a.nrows()),
            got: format!("{} × {}", b.nrows(), b.ncols()),
        });
    }
    check_finite_mat("lstsq_min_norm", a)?;
    check_finite_mat("lstsq_min_norm", b)?;
    let n = a.ncols();
    if a.nrows() == 0 || n == 0 {
        return Ok((vec![0.0; n], range.then(|| Mat::zeros(a.nrows(), 0))));
    }
    let svd = a
        .thin_svd()
        .map_err(|e| Error::numerical("lstsq_min_norm", format!("SVD failed: {e:?}")))?;
    let sv = svd.S().column_vector();
    let smax = (0..sv.nrows()).map(|k| sv[k]).fold(0.0, f64::max);
    let mut x = vec![0.0; n];
    let kept: Vec<usize> = (0..sv.nrows())
        .filter(|&k| smax > 0.0 && sv[k] > rtol * smax)
        .collect();
    let utb = svd.U().transpose() * b;
    for &k in &kept {
        let c = utb[(k, 0)] / sv[k];
        for (j, xj) in x.iter_mut().enumerate() {
            *xj += svd.V()[(j, k)] * c;
        }
    }
    let basis = range.then(|| Mat::from_fn(a.nrows(), kept.len(), |r, c| svd.U()[(r, kept[c])]));
    Ok((x, basis))
}

/// Solves the square real system $A X = B$ by LU with partial pivoting.
pub fn solve(a: MatRef<'_, f64>, b: MatRef<'_, f64>) -> Result<Mat<f64>> {
    check_square("solve", a)?;
    let x = a.partial_piv_lu().solve(b);
    check_finite_mat("solve", x.as_ref())
        .map_err(|_| Error::numerical("solve", "matrix is singular to working precision"))?;
    Ok(x)
}

/// Solves the square complex system $A X = B$ by LU with partial pivoting.
pub fn solve_c64(a: MatRef<'_, c64>, b: MatRef<'_, c64>) -> Result<Mat<c64>> {
    if a.nrows() != a.ncols() || a.nrows() != b.nrows() {
        return Err(Error::DimensionMismatch {
            context: "solve_c64",
            expected: format!("square A and {} rows in B", a.nrows()),
            got: format!("{}×{} and {} rows", a.nrows(), a.ncols(), b.nrows()),
        });
    }
    let x = a.partial_piv_lu().solve(b);
    for j in 0..x.ncols() {
        for i in 0..x.nrows() {
            if !(x[(i, j)].re.is_finite() && x[(i, j)].im.is_finite()) {
                return Err(Error::numerical(
                    "solve_c64",
                    "matrix is singular to working precision",
                ));
            }
        }
    }
    Ok(x)
}

/// Singular values of a real matrix, largest first.
pub fn singular_values(a: MatRef<'_, f64>) -> Result<Vec<f64>> {
    check_finite_mat("singular_values", a)?;
    if a.nrows() == 0 || a.ncols() == 0 {
        return Ok(Vec::new());
    }
    let mut s = a
        .singular_values()
        .map_err(|e| Error::numerical("singular_values", format!("{e:?}")))?;
    s.sort_by(|x, y| y.total_cmp(x));
    Ok(s)
}

/// Principal matrix square root $A^{1/2}$ (eigenvalues with positive real part) by the scaled
/// product Denman–Beavers iteration.
///
/// Errors with [`Error::InvalidArgument`] if $A$ has an eigenvalue on the closed negative real
/// axis (no principal square root), and [`Error::Numerical`] if the iteration does not converge.
pub fn sqrtm(a: MatRef<'_, f64>) -> Result<Mat<f64>> {
    check_square("sqrtm", a)?;
    check_no_negative_real_eigenvalue("sqrtm", a)?;
    sqrtm_db(a)
}

fn check_no_negative_real_eigenvalue(context: &'static str, a: MatRef<'_, f64>) -> Result<()> {
    let nrm = norm1(a).max(f64::MIN_POSITIVE);
    for l in eigenvalues(a)? {
        if l.re <= 0.0 && l.im.abs() <= 1e-12 * nrm.max(l.norm()) {
            return Err(Error::invalid(
                "a",
                format!(
                    "{context}: the matrix has the eigenvalue {:.6e}{:+.3e}i on the closed negative real axis, so it has no real principal {}",
                    l.re,
                    l.im,
                    if context == "sqrtm" { "square root" } else { "logarithm" }
                ),
            ));
        }
    }
    Ok(())
}

fn sqrtm_db(a: MatRef<'_, f64>) -> Result<Mat<f64>> {
    let n = a.nrows();
    if n == 0 {
        return Ok(Mat::zeros(0, 0));
    }
    let id = Mat::<f64>::identity(n, n);
    let mut m = a.to_owned();
    let mut y = a.to_owned();
    let mut scaling = true;
    for _ in 0..100 {
        let minv = solve(m.as_ref(), id.as_ref()).map_err(|_| {
            Error::numerical("sqrtm", "singular iterate in the Denman–Beavers iteration")
        })?;
        let mut mu = 1.0;
        if scaling {
            let det = m.determinant().abs();
            if det.is_finite() && det > 0.0 {
                mu = det.powf(-1.0 / (2.0 * n as f64));
            }
        }
        let mu2 = mu * mu;
        let yn = Mat::from_fn(n, n, |i, j| 0.5 * mu * y[(i, j)])
            * Mat::from_fn(n, n, |i, j| id[(i, j)] + minv[(i, j)] / mu2);
        let mn = Mat::from_fn(n, n, |i, j| {
            0.5 * (id[(i, j)] + 0.5 * (mu2 * m[(i, j)] + minv[(i, j)] / mu2))
        });
        let dm = norm1((&mn - &id).as_ref());
        let dy = norm1((&yn - &y).as_ref());
        m = mn;
        y = yn;
        check_finite_mat("sqrtm", y.as_ref())?;
        if dm < 1e-2 {
            scaling = false;
        }
        if dm <= 4.0 * f64::EPSILON * n as f64 || dy <= 4.0 * f64::EPSILON * norm1(y.as_ref()) {
            return Ok(y);
        }
    }
    Err(Error::numerical(
        "sqrtm",
        "the Denman–Beavers iteration did not converge in 100 steps",
    ))
}

/// Nodes and weights of the `m`-point Gauss–Legendre rule on $[0, 1]$ (Newton on $P_m$).
fn gauss_legendre_01(m: usize) -> Vec<(f64, f64)> {
    let mut out = Vec::with_capacity(m);
    for i in 0..m {
        let mut x = (std::f64::consts::PI * (i as f64 + 0.75) / (m as f64 + 0.5)).cos();
        let mut dp = 1.0;
        for _ in 0..100 {
            // Legendre recurrence for P_m(x) and P_{m-1}(x)
            let (mut p0, mut p1) = (1.0, x);
            for k in 2..=m {
                let kf = k as f64;
                let p2 = ((2.0 * kf - 1.0) * x * p1 - (kf - 1.0) * p0) / kf;
                p0 = p1;
                p1 = p2;
            }
            dp = m as f64 * (x * p1 - p0) / (x * x - 1.0);
            let dx = p1 / dp;
            x -= dx;
            if dx.abs() < 1e-16 {
                break;
            }
        }
        let w = 2.0 / ((1.0 - x * x) * dp * dp);
        out.push((0.5 * (x + 1.0), 0.5 * w));
    }
    out
}

/// Principal matrix logarithm $\log A$ by inverse scaling and squaring (see the module docs).
///
/// Errors with [`Error::InvalidArgument`] if $A$ has an eigenvalue on the closed negative real axis
/// (then no real principal logarithm exists), on a non-square or non-finite matrix, and with
/// [`Error::Numerical`] if a square root fails to converge.
///
/// ```
/// use ambid_core::linalg::{expm, logm};
/// use faer::mat;
/// let x = mat![[-0.3, 2.0], [-1.0, -0.1]];
/// let l = logm(expm(x.as_ref()).unwrap().as_ref()).unwrap();
/// assert!((&l - &x).norm_max() < 1e-13);
/// ```
pub fn logm(a: MatRef<'_, f64>) -> Result<Mat<f64>> {
    check_square("logm", a)?;
    let n = a.nrows();
    if n == 0 {
        return Ok(Mat::zeros(0, 0));
    }
    check_no_negative_real_eigenvalue("logm", a)?;
    let id = Mat::<f64>::identity(n, n);
    let mut x = a.to_owned();
    let mut k = 0i32;
    while norm1((&x - &id).as_ref()) > 0.25 {
        if k >= 1000 {
            return Err(Error::numerical(
                "logm",
                "too many square roots; the matrix is too close to singular",
            ));
        }
        x = sqrtm_db(x.as_ref())?;
        k += 1;
    }
    let e = &x - &id;
    let mut l = Mat::<f64>::zeros(n, n);
    for (t, w) in gauss_legendre_01(10) {
        let m = Mat::from_fn(n, n, |i, j| id[(i, j)] + t * e[(i, j)]);
        // E (I + tE)^{-1} = (I + tE)^{-1} E since they commute
        let s = solve(m.as_ref(), e.as_ref())?;
        l += Mat::from_fn(n, n, |i, j| w * s[(i, j)]);
    }
    let scale = 2f64.powi(k);
    let out = Mat::from_fn(n, n, |i, j| l[(i, j)] * scale);
    check_finite_mat("logm", out.as_ref())?;
    Ok(out)
}

/// Eigenvalues of the square pencil $A - \lambda E$, returned as homogeneous pairs
/// $(\alpha, \beta)$ with $\lambda = \alpha / \beta$ ($\beta = 0$ is an infinite eigenvalue),
/// by faer's QZ-based generalized eigendecomposition.
pub fn generalized_eigenvalues(a: MatRef<'_, f64>, e: MatRef<'_, f64>) -> Result<Vec<(c64, c64)>> {
    check_square("generalized_eigenvalues", a)?;
    check_square("generalized_eigenvalues", e)?;
    if a.nrows() != e.nrows() {
        return Err(Error::DimensionMismatch {
            context: "generalized_eigenvalues",
            expected: format!("{}×{}", a.nrows(), a.nrows()),
            got: format!("{}×{}", e.nrows(), e.ncols()),
        });
    }
    if a.nrows() == 0 {
        return Ok(Vec::new());
    }
    let g = a
        .generalized_eigen(e)
        .map_err(|err| Error::numerical("generalized_eigenvalues", format!("{err:?}")))?;
    let sa = g.S_a().column_vector();
    let sb = g.S_b().column_vector();
    Ok((0..a.nrows()).map(|i| (sa[i], sb[i])).collect())
}

/// Characteristic polynomial $\det(zI - A) = z^n + c_1 z^{n-1} + \dots + c_n$, coefficients in
/// descending powers of $z$ (equivalently ascending powers of $q^{-1}$), from the eigenvalues
/// of $A$ (as `numpy.poly`). Accurate for the orders met in identification (up to about 20).
pub fn charpoly(a: MatRef<'_, f64>) -> Result<Vec<f64>> {
    let ev = eigenvalues(a)?;
    Ok(poly_from_roots(&ev))
}

/// Stabilising solution of the discrete algebraic Riccati equation (DARE)
/// $$ A^\top X A - X - (A^\top X B + S)(R + B^\top X B)^{-1}(B^\top X A + S^\top) + Q = 0, $$
/// the convention of `scipy.linalg.solve_discrete_are(a, b, q, r, s=s)` ($S = 0$ when `s` is
/// `None`): the symmetric $X$ for which the closed loop $A - B F$,
/// $F = (R + B^\top X B)^{-1}(B^\top X A + S^\top)$, has every eigenvalue strictly inside the unit
/// circle.
///
/// The Kalman filter of $x_{k+1} = A x_k + w_k$, $y_k = C x_k + v_k$ with
/// $\mathrm E\,[w; v][w; v]^\top = [Q, S; S^\top, R]$ is the dual problem: its a-priori error
/// covariance is `dare(Aᵀ, Cᵀ, Q, R, Some(S))` and its gain
/// $K = (A P C^\top + S)(C P C^\top + R)^{-1}$.
///
/// # Algorithm: structure-preserving doubling (SDA)
/// Removing the cross term with $\hat A = A - B R^{-1} S^\top$, $G = B R^{-1} B^\top$,
/// $H = Q - S R^{-1} S^\top$ turns the equation into the fixed point
/// $X = \hat A^\top X (I + G X)^{-1} \hat A + H$ (push-through identity
/// $X - XB(R + B^\top X B)^{-1} B^\top X = X (I + G X)^{-1}$). Starting from
/// $(A_0, G_0, H_0) = (\hat A, G, H)$, with $W_k = I + G_k H_k$,
/// $$ A_{k+1} = A_k W_k^{-1} A_k,\quad G_{k+1} = G_k + A_k W_k^{-1} G_k A_k^\top,\quad
///    H_{k+1} = H_k + A_k^\top H_k W_k^{-1} A_k. $$
/// Each step doubles the horizon of the underlying symplectic pencil: $H_k$ is the Riccati
/// iteration after $2^k$ steps, so when the pencil has no eigenvalue on the unit circle (and the
/// stabilising solution exists) $H_k \to X$ quadratically,
/// $\lVert H_k - X \rVert = O(\rho(A - BF)^{2^{k+1}})$, while $A_k \to 0$. A closed loop with spectral
/// radius $1 - 10^{-6}$ converges in about 25 steps of $O(n^3)$ work each.
///
/// Stopping: when $\lVert H_{k+1} - H_k \rVert_1 \le 10^{-13} \lVert H_{k+1} \rVert_1$ or
/// $\lVert A_{k+1} \rVert_1 \le 10^{-8}$ (further updates are then below rounding), at most 100 steps.
/// Checks on the result: it is finite, the closed loop $A - BF$ has spectral radius $< 1$, and the
/// relative residual (the 1-norm of the left-hand side over the sum of the 1-norms of its four
/// terms) is below $10^{-8}$; typical residuals are $10^{-15}$–$10^{-13}$. $X$ is symmetrised after
/// every step.
///
/// # Requirements on the problem
/// $R$ symmetric positive definite; $Q$ symmetric (for a positive semidefinite $X$ also
/// $[Q, S; S^\top, R] \succeq 0$); $(A, B)$ stabilisable and no mode of $\hat A$ on the unit circle
/// unobservable from $H$. Then the stabilising solution exists and is unique.
///
/// # Errors
/// [`Error::DimensionMismatch`] for inconsistent shapes; [`Error::Numerical`] for non-finite
/// entries; [`Error::InvalidArgument`] when $Q$ or $R$ is not symmetric (relative asymmetry above
/// $10^{-10}$) or $R$ is not positive definite; [`Error::Numerical`] when no stabilising solution
/// exists (no convergence in 100 steps, a singular $W_k$, or a closed loop that is not stable) or
/// the result fails the residual check.
///
/// # Reference
/// E. K.-W. Chu, H.-Y. Fan, W.-W. Lin, "A structure-preserving doubling algorithm for
/// continuous-time algebraic Riccati equations", *Linear Algebra Appl.* 396 (2005); W.-W. Lin,
/// S.-F. Xu, "Convergence analysis of structure-preserving doubling algorithms for Riccati-type
/// matrix equations", *SIAM J. Matrix Anal. Appl.* 28 (2006).
///
/// # Example
/// ```
/// use ambid_core::linalg::dare;
/// use faer::mat;
/// // scalar: x = a² x − a² x² / (1 + x) + 1 with a = 2 has the stabilising root x = 2 + √5
/// let a = mat![[2.0]];
/// let one = mat![[1.0]];
/// let x = dare(a.as_ref(), one.as_ref(), one.as_ref(), one.as_ref(), None).unwrap();
/// assert!((x[(0, 0)] - (2.0 + 5f64.sqrt())).abs() < 1e-12);
/// // an unstable mode that B cannot reach has no stabilising solution
/// let a = mat![[2.0, 0.0], [0.0, 0.5]];
/// let b = mat![[0.0], [1.0]];
/// let q = mat![[1.0, 0.0], [0.0, 1.0]];
/// assert!(dare(a.as_ref(), b.as_ref(), q.as_ref(), one.as_ref(), None).is_err());
/// ```
pub fn dare(
    a: MatRef<'_, f64>,
    b: MatRef<'_, f64>,
    q: MatRef<'_, f64>,
    r: MatRef<'_, f64>,
    s: Option<MatRef<'_, f64>>,
) -> Result<Mat<f64>> {
    check_square("dare: A", a)?;
    let n = a.nrows();
    let m = b.ncols();
    let shape = |ctx: &'static str, want: (usize, usize), got: MatRef<'_, f64>| {
        if (got.nrows(), got.ncols()) != want {
            Err(Error::DimensionMismatch {
                context: ctx,
                expected: format!("{}×{}", want.0, want.1),
                got: format!("{}×{}", got.nrows(), got.ncols()),
            })
        } else {
            Ok(())
        }
    };
    shape("dare: B", (n, m), b)?;
    shape("dare: Q", (n, n), q)?;
    shape("dare: R", (m, m), r)?;
    check_finite_mat("dare: B", b)?;
    check_finite_mat("dare: Q", q)?;
    check_finite_mat("dare: R", r)?;
    let s = match s {
        Some(s) => {
            shape("dare: S", (n, m), s)?;
            check_finite_mat("dare: S", s)?;
            s.to_owned()
        }
        None => Mat::zeros(n, m),
    };
    let q = symmetric_part("q", q)?;
    let r = symmetric_part("r", r)?;
    if n == 0 {
        return Ok(Mat::zeros(0, 0));
    }
    let (rinv_bt, rinv_st) = if m == 0 {
        (Mat::zeros(0, n), Mat::zeros(0, n))
    } else {
        let llt = r.llt(faer::Side::Lower).map_err(|_| {
            Error::invalid(
                "r",
                "R must be symmetric positive definite (the input weight, or the measurement-noise \
                 covariance of a Kalman filter); add a small positive diagonal if it is singular",
            )
        })?;
        (llt.solve(b.transpose()), llt.solve(s.transpose()))
    };
    let id = Mat::<f64>::identity(n, n);
    let mut ak = a - b * &rinv_st;
    let mut g = symmetrised(&(b * &rinv_bt));
    let mut h = symmetrised(&(&q - &s * &rinv_st));
    let mut converged = false;
    for _ in 0..100 {
        let w = &id + &g * &h;
        let lu = w.partial_piv_lu();
        let x1 = lu.solve(&ak);
        let x2 = lu.solve(&g);
        if !(is_finite(x1.as_ref()) && is_finite(x2.as_ref())) {
            return Err(no_stabilising(
                "I + G_k H_k became singular in the doubling iteration",
            ));
        }
        let a_next = &ak * &x1;
        let g_next = symmetrised(&(&g + &ak * &x2 * ak.transpose()));
        let h_next = symmetrised(&(&h + ak.transpose() * &h * &x1));
        if !(is_finite(h_next.as_ref()) && is_finite(g_next.as_ref())) {
            return Err(no_stabilising("the doubling iteration diverged"));
        }
        let delta = norm1((&h_next - &h).as_ref());
        let hn = norm1(h_next.as_ref());
        ak = a_next;
        g = g_next;
        h = h_next;
        if delta <= 1e-13 * hn || norm1(ak.as_ref()) <= 1e-8 {
            converged = true;
            break;
        }
    }
    if !converged {
        return Err(no_stabilising(
            "the doubling iteration did not converge in 100 steps (eigenvalues on or very near the \
             unit circle)",
        ));
    }
    let x = h;
    // closed loop and residual
    let btx = b.transpose() * &x;
    let rbxb = &r + &btx * b;
    let bxa_s = &btx * a + s.transpose();
    let f = if m == 0 {
        Mat::zeros(0, n)
    } else {
        solve(rbxb.as_ref(), bxa_s.as_ref())
            .map_err(|_| no_stabilising("R + BᵀXB is singular at the computed solution"))?
    };
    let acl = a - b * &f;
    let rho = eigenvalues(acl.as_ref())?
        .iter()
        .map(|z| z.norm())
        .fold(0.0, f64::max);
    if rho >= 1.0 {
        return Err(no_stabilising(&format!(
            "the computed solution leaves a closed-loop pole at |z| = {rho:.6}"
        )));
    }
    let axa = a.transpose() * &x * a;
    let term = bxa_s.transpose() * &f;
    let res = &axa - &x - &term + &q;
    let scale = norm1(axa.as_ref()) + norm1(x.as_ref()) + norm1(term.as_ref()) + norm1(q.as_ref());
    let rel = norm1(res.as_ref()) / scale.max(f64::MIN_POSITIVE);
    if rel > 1e-8 {
        return Err(Error::numerical(
            "dare",
            format!(
                "the solution is inaccurate (relative residual {rel:.2e}); the problem is too close \
                 to having no stabilising solution, or badly scaled: rescale the states or inputs"
            ),
        ));
    }
    Ok(x)
}

fn no_stabilising(why: &str) -> Error {
    Error::numerical(
        "dare",
        format!(
            "no stabilising solution: {why}; check that (A, B) is stabilisable and that no mode on \
             the unit circle is unobservable from Q"
        ),
    )
}

fn is_finite(m: MatRef<'_, f64>) -> bool {
    (0..m.ncols()).all(|j| (0..m.nrows()).all(|i| m[(i, j)].is_finite()))
}

fn symmetrised(m: &Mat<f64>) -> Mat<f64> {
    Mat::from_fn(m.nrows(), m.ncols(), |i, j| 0.5 * (m[(i, j)] + m[(j, i)]))
}

/// The symmetric part of a square matrix, after checking that it is symmetric to $10^{-10}$
/// relative to its largest entry.
fn symmetric_part(name: &'static str, m: MatRef<'_, f64>) -> Result<Mat<f64>> {
    let mut big = 0.0f64;
    let mut asym = 0.0f64;
    for j in 0..m.ncols() {
        for i in 0..m.nrows() {
            big = big.max(m[(i, j)].abs());
            asym = asym.max((m[(i, j)] - m[(j, i)]).abs());
        }
    }
    if asym > 1e-10 * big {
        return Err(Error::invalid(
            name,
            format!(
                "the matrix must be symmetric (largest |m_ij − m_ji| = {asym:.3e} against entries \
                 up to {big:.3e}); pass (M + Mᵀ)/2"
            ),
        ));
    }
    Ok(symmetrised(&m.to_owned()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use faer::mat;

    #[test]
    fn expm_rotation_and_scaling() {
        // exp([[0, w], [-w, 0]] t) is a rotation; large norm exercises scaling and squaring.
        for &w in &[0.1, 1.0, 30.0, 1000.0] {
            let a = mat![[0.0, w], [-w, 0.0]];
            let e = expm(a.as_ref()).unwrap();
            assert!((e[(0, 0)] - w.cos()).abs() < 1e-12 * w.max(1.0));
            assert!((e[(0, 1)] - w.sin()).abs() < 1e-12 * w.max(1.0));
        }
        // Jordan block: exp([[l, 1], [0, l]]) = e^l [[1, 1], [0, 1]]
        let a = mat![[-2.0, 1.0], [0.0, -2.0]];
        let e = expm(a.as_ref()).unwrap();
        let el = (-2.0f64).exp();
        assert!((e[(0, 0)] - el).abs() < 1e-15 && (e[(0, 1)] - el).abs() < 1e-15);
        assert!(e[(1, 0)].abs() < 1e-15);
    }

    #[test]
    fn badly_scaled_matrices_are_accurate_entry_by_entry() {
        // S A S^{-1} with S = diag(1e-6, 1, 1e6, 1e3): exp and eigenvalues follow exactly, so each
        // entry of expm(S A S^{-1}) must equal S_i exp(A)_ij / S_j to working precision.
        let a = mat![
            [-1.0, 2.0, 0.5, 0.0],
            [-3.0, -0.5, 0.0, 1.0],
            [0.2, 0.0, -2.0, 4.0],
            [0.0, -1.0, -4.0, -0.3]
        ];
        let sc = [1e-6, 1.0, 1e6, 1e3];
        let b = Mat::from_fn(4, 4, |i, j| sc[i] * a[(i, j)] / sc[j]);
        let ea = expm(a.as_ref()).unwrap();
        let eb = expm(b.as_ref()).unwrap();
        for i in 0..4 {
            for j in 0..4 {
                let want = sc[i] * ea[(i, j)] / sc[j];
                assert!(
                    (eb[(i, j)] - want).abs() <= 1e-13 * want.abs().max(1e-300),
                    "({i},{j}): {} vs {want}",
                    eb[(i, j)]
                );
            }
        }
        let mut la: Vec<c64> = eigenvalues(a.as_ref()).unwrap();
        let mut lb: Vec<c64> = eigenvalues(b.as_ref()).unwrap();
        let key = |z: &c64| (z.re * 1e6).round() as i64 * 1_000_000 + (z.im * 1e6).round() as i64;
        la.sort_by_key(key);
        lb.sort_by_key(key);
        for (x, y) in la.iter().zip(&lb) {
            assert!((x - y).norm() < 1e-12 * x.norm(), "{x} vs {y}");
        }
    }

    #[test]
    fn roots_known_polynomials() {
        // (z-1)(z-2)(z-3)(z+0.5)
        let r = [1.0, 2.0, 3.0, -0.5].map(|x| c64::new(x, 0.0));
        let p = poly_from_roots(&r);
        let mut got: Vec<f64> = roots(&p).unwrap().iter().map(|z| z.re).collect();
        got.sort_by(|a, b| a.total_cmp(b));
        for (g, w) in got.iter().zip([-0.5, 1.0, 2.0, 3.0]) {
            assert!((g - w).abs() < 1e-9, "{g} vs {w}");
        }
        // trailing zeros and leading zeros
        let got = roots(&[0.0, 1.0, 0.0, 4.0, 0.0]).unwrap();
        assert_eq!(got.len(), 3);
        assert!(got.iter().filter(|z| z.norm() < 1e-15).count() == 1);
        assert!(got.iter().any(|z| (z - c64::new(0.0, 2.0)).norm() < 1e-12));
        assert!(roots(&[0.0, 0.0]).is_err());
        assert!(roots(&[1.0, f64::NAN]).is_err());
    }

    #[test]
    fn lstsq_recovers_exact_solution_and_flags_rank_deficiency() {
        let a = mat![[1.0, 0.0], [1.0, 1.0], [1.0, 2.0], [1.0, 3.0]];
        let b = mat![[1.0], [3.0], [5.0], [7.0]];
        let x = lstsq(a.as_ref(), b.as_ref()).unwrap();
        assert!((x[(0, 0)] - 1.0).abs() < 1e-13 && (x[(1, 0)] - 2.0).abs() < 1e-13);
        let a = mat![[1.0, 2.0], [2.0, 4.0], [3.0, 6.0]];
        let b = mat![[1.0], [2.0], [3.0]];
        assert!(matches!(
            lstsq(a.as_ref(), b.as_ref()),
            Err(Error::Numerical { .. })
        ));
    }

    #[test]
    fn gauss_legendre_integrates_polynomials_exactly() {
        let q = gauss_legendre_01(10);
        let wsum: f64 = q.iter().map(|(_, w)| w).sum();
        assert!((wsum - 1.0).abs() < 1e-15);
        // integral of t^19 over [0, 1] = 1/20
        let i: f64 = q.iter().map(|(t, w)| w * t.powi(19)).sum();
        assert!((i - 0.05).abs() < 1e-15);
    }

    #[test]
    fn sqrtm_squares_back() {
        let a = mat![[4.0, 1.0, 0.0], [0.5, 3.0, -1.0], [0.0, 2.0, 5.0]];
        let r = sqrtm(a.as_ref()).unwrap();
        assert!((&(&r * &r) - &a).norm_max() < 1e-13);
        assert!(sqrtm(mat![[-1.0]].as_ref()).is_err());
    }
}
