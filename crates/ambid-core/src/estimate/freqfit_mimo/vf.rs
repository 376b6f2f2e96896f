//! The vector-fitting starts of [`super::fit`]: common poles relocated by the
//! Sanathanan–Koerner iteration of vector fitting (Gustavsen & Semlyen 1999) on every entry at
//! once, matrix residues fitted for the relocated poles, and two realisations of the requested
//! order: the band-balanced truncation of the whole model, and the residues' dominant rank-one
//! parts.
//!
//! # Method
//! The model in partial fractions is $G(z) \approx D + \sum_m R_m \varphi_m(z)$ with a real basis
//! $\varphi_m$: $1/(z - a)$ for a real pole, and for a pair $p, \bar p$ the two functions
//! $1/(z-p) + 1/(z-\bar p)$ and $j/(z-p) - j/(z-\bar p)$. One relocation step fits, for every
//! entry $(i, j)$ with its weights, $\sum_m c_{ij,m}\varphi_m + d_{ij} - G_{ij}\sum_m \tilde c_m
//! \varphi_m = G_{ij}$ with the scaling function $\sigma = 1 + \sum_m \tilde c_m \varphi_m$
//! common to all entries; the entries' own unknowns are eliminated by projection (the "fast"
//! form), so only $\tilde c$ is solved jointly: each entry's weighted
//! $[\Phi\,\,1 \mid -G\Phi\,\,G]$ is QR-factored, the trailing block of its triangle (the
//! shared columns projected onto the complement of its own) is stacked with the other
//! entries', and one more QR and a back substitution give $\tilde c$; the projected rows
//! themselves are never formed. The zeros of $\sigma$, the eigenvalues of
//! $A_\varphi - b_\varphi \tilde c^{\mathsf T}$ for the basis' realisation $(A_\varphi,
//! b_\varphi)$, are the new poles. Unstable poles are **not** flipped: the plant is unstable.
//!
//! A pole of multiplicity $r$ in a minimal MIMO model (the four identical amplifiers of an AMB,
//! the x and y planes of a symmetric rotor) has a residue of rank $r$; the poles here are
//! distinct and their residues full matrices. The band-balanced realisation writes every
//! rank-one part of every residue as states (Gilbert's realisation: one per part of a real pole,
//! two per part of a pair), balances the whole on the data's lines and keeps the `order` states
//! of largest band Hankel singular values. The rank-one realisation keeps, over all poles, the
//! rank-one parts $\sigma_{m,r} u_{m,r} v_{m,r}^{\mathsf H}$ of largest size in the band
//! ($\sigma_{m,r}$ times the RMS of $|\varphi_m|$ over the lines), one state per real pole's
//! part and two per pair's, until the order is reached; its output matrix holds the parts'
//! left singular vectors. The numerators are then refitted by the caller.
use super::{Data, CTX};
use crate::error::{Error, Result};
use crate::estimate::qr_stream::r_factor_tall;
use crate::linalg;
use faer::{c64, Mat};

/// A pole of the partial-fraction basis.
#[derive(Debug, Clone, Copy)]
enum Pole {
    Real(f64),
    /// The member with positive imaginary part.
    Pair(c64),
}

fn poles_of(vals: &[c64]) -> Vec<Pole> {
    let scale = vals.iter().map(|v| v.norm()).fold(1.0f64, f64::max);
    let tol = 1e-9 * scale;
    let mut out = Vec::new();
    for v in vals {
        if v.im.abs() <= tol {
            out.push(Pole::Real(v.re));
        } else if v.im > 0.0 {
            out.push(Pole::Pair(*v));
        }
    }
    out
}

fn n_basis(poles: &[Pole]) -> usize {
    poles
        .iter()
        .map(|p| match p {
            Pole::Real(_) => 1,
            Pole::Pair(_) => 2,
        })
        .sum()
}

/// The basis functions at `z` (appended to `out`); `None` when a pole lies on `z`.
fn basis(poles: &[Pole], z: c64, out: &mut Vec<c64>) -> Option<()> {
    let j = c64::new(0.0, 1.0);
    for p in poles {
        match *p {
            Pole::Real(a) => {
                let d = z - a;
                if d.norm() == 0.0 {
                    return None;
                }
                out.push(d.inv());
            }
            Pole::Pair(p) => {
                let (d1, d2) = (z - p, z - p.conj());
                if d1.norm() == 0.0 || d2.norm() == 0.0 {
                    return None;
                }
                let (f1, f2) = (d1.inv(), d2.inv());
                out.push(f1 + f2);
                out.push(j * f1 - j * f2);
            }
        }
    }
    Some(())
}

/// $(A_\varphi, b_\varphi)$ with $(zI - A_\varphi)^{-1} b_\varphi$ = the basis.
fn basis_realisation(poles: &[Pole]) -> (Mat<f64>, Vec<f64>) {
    let n = n_basis(poles);
    let mut a = Mat::<f64>::zeros(n, n);
    let mut b = vec![0.0; n];
    let mut s = 0;
    for p in poles {
        b[s] = if matches!(p, Pole::Real(_)) { 1.0 } else { 2.0 };
        s += put_block(&mut a, s, *p);
    }
    (a, b)
}

/// The basis at every line, line-major (`None`: a pole on a line).
fn basis_table(poles: &[Pole], data: &Data) -> Option<Vec<c64>> {
    let mut out = Vec::with_capacity(data.len() * n_basis(poles));
    for &z in &data.z {
        basis(poles, z, &mut out)?;
    }
    Some(out)
}

fn degenerate(what: &str) -> Error {
    Error::numerical(
        CTX,
        format!("the vector-fitting start is degenerate ({what}); lower the order"),
    )
}

/// Unit-norm scaling of the columns of `m` in place; the scales (1 for a zero column).
fn unit_columns(m: &mut Mat<f64>) -> Vec<f64> {
    (0..m.ncols())
        .map(|c| {
            let n = m.col(c).norm_l2();
            let s = if n > 0.0 && n.is_finite() {
                1.0 / n
            } else {
                1.0
            };
            m.col_mut(c).iter_mut().for_each(|v| *v *= s);
            s
        })
        .collect()
}

/// Smallest $|R_{ii}|$ of the first `k` columns of a factor of unit-norm columns below which
/// a column counts as a combination of the ones before it.
const DEPENDENT: f64 = 1e-11;

/// One relocation step: the zeros of σ.
///
/// Each entry's own unknowns are eliminated by the QR factorisation of its
/// $[\Phi\,\,1 \mid -G\Phi\,\,G]$ (weighted, real and imaginary parts stacked): the
/// trailing block of the triangle is the triangle of the shared columns projected onto the
/// orthogonal complement of the entry's own ones. The entries' trailing blocks are stacked
/// and factored once more, and $\tilde c$ follows by back substitution; the projected rows are
/// never formed.
fn relocate(poles: &[Pole], data: &Data) -> Result<Vec<Pole>> {
    let nb = n_basis(poles);
    let ct = sigma_coefficients(poles, data)?;
    let (a, b) = basis_realisation(poles);
    let h = Mat::<f64>::from_fn(nb, nb, |r, c| a[(r, c)] - b[r] * ct[c]);
    let vals = linalg::eigenvalues(h.as_ref()).map_err(|_| degenerate("eigenvalues failed"))?;
    if vals.iter().any(|v| !(v.re.is_finite() && v.im.is_finite())) {
        return Err(degenerate("a non-finite pole"));
    }
    Ok(poles_of(&vals))
}

/// The coefficients $\tilde c$ of σ of one relocation step ([`relocate`]).
fn sigma_coefficients(poles: &[Pole], data: &Data) -> Result<Vec<f64>> {
    let (l, e) = (data.len(), data.entries());
    let nb = n_basis(poles);
    let phi = basis_table(poles, data).ok_or_else(|| degenerate("a pole on a line"))?;
    let p = nb + 1;
    let mut stacked = Mat::<f64>::zeros(e * p, p);
    for ent in 0..e {
        // [Φ 1] (own unknowns) and [−G Φ | G] (shared unknowns, right-hand side), weighted,
        // filled column by column
        let mut m = Mat::<f64>::zeros(2 * l, 2 * p);
        for c in 0..nb {
            for k in 0..l {
                let idx = k * e + ent;
                let v = phi[k * nb + c] * data.sw[idx];
                let u = -data.g[idx] * v;
                let own = m.col_as_slice_mut(c);
                own[2 * k] = v.re;
                own[2 * k + 1] = v.im;
                let rest = m.col_as_slice_mut(p + c);
                rest[2 * k] = u.re;
                rest[2 * k + 1] = u.im;
            }
        }
        for k in 0..l {
            let idx = k * e + ent;
            let sw = data.sw[idx];
            m.col_as_slice_mut(nb)[2 * k] = sw;
            let rhs = m.col_as_slice_mut(2 * p - 1);
            rhs[2 * k] = data.g[idx].re * sw;
            rhs[2 * k + 1] = data.g[idx].im * sw;
        }
        // unit-norm own columns: |R_ii| is the distance from the span of the ones before
        let mut own = m.as_mut().subcols_mut(0, p).to_owned();
        unit_columns(&mut own);
        m.as_mut().subcols_mut(0, p).copy_from(own.as_ref());
        // the trailing block is read only when the leading one has full rank (checked here), so
        // the unblocked factor's rounding-level reflectors of dependent columns never matter
        let r = r_factor_tall(m);
        if r.nrows() < 2 * p || (0..p).any(|i| r[(i, i)].abs() <= DEPENDENT) {
            return Err(degenerate("a rank-deficient basis"));
        }
        stacked
            .as_mut()
            .subrows_mut(ent * p, p)
            .copy_from(r.as_ref().submatrix(p, p, p, p));
    }
    let mut shared = stacked.as_ref().subcols(0, nb).to_owned();
    let scale = unit_columns(&mut shared);
    stacked
        .as_mut()
        .subcols_mut(0, nb)
        .copy_from(shared.as_ref());
    let t = r_factor_tall(stacked);
    if (0..nb).any(|i| t[(i, i)].abs() <= DEPENDENT) {
        return Err(degenerate("a rank-deficient relocation"));
    }
    let mut ct = vec![0.0; nb];
    for i in (0..nb).rev() {
        let acc: f64 = (i + 1..nb).map(|c| t[(i, c)] * ct[c]).sum();
        ct[i] = (t[(i, nb)] - acc) / t[(i, i)];
    }
    for (c, s) in ct.iter_mut().zip(&scale) {
        *c *= s;
    }
    Ok(ct)
}

/// Matrix residues for fixed poles: per basis function an $n_y \times n_u$ real coefficient
/// matrix (column-major), and $D$.
fn residues(poles: &[Pole], data: &Data) -> Result<Vec<Mat<f64>>> {
    let (l, e, ny) = (data.len(), data.entries(), data.ny);
    let nb = n_basis(poles);
    let phi = basis_table(poles, data).ok_or_else(|| degenerate("a pole on a line"))?;
    let mut out = vec![Mat::<f64>::zeros(data.ny, data.nu); nb];
    for ent in 0..e {
        let (i, j) = (ent % ny, ent / ny);
        let mut m = Mat::<f64>::zeros(2 * l, nb + 1);
        let mut rhs = Mat::<f64>::zeros(2 * l, 1);
        for k in 0..l {
            let idx = k * e + ent;
            let sw = data.sw[idx];
            for c in 0..nb {
                let v = phi[k * nb + c] * sw;
                m[(2 * k, c)] = v.re;
                m[(2 * k + 1, c)] = v.im;
            }
            m[(2 * k, nb)] = sw;
            rhs[(2 * k, 0)] = data.g[idx].re * sw;
            rhs[(2 * k + 1, 0)] = data.g[idx].im * sw;
        }
        let x = linalg::lstsq(m.as_ref(), rhs.as_ref())
            .map_err(|_| degenerate("rank-deficient residues"))?;
        for (c, r) in out.iter_mut().enumerate() {
            r[(i, j)] = x[(c, 0)];
        }
    }
    Ok(out)
}

/// The vector-fitting starts: $(A, C)$ of dimension `order` in $z$, channel-scaled units, from
/// `start` (poles in $z$, conjugate pairs complete) after at most `iterations` relocations,
/// realised twice: the band-balanced truncation of the whole fit (when it can be formed) and
/// the dominant rank-one parts (when there are enough); an error when neither can be.
pub(super) fn start(
    data: &Data,
    order: usize,
    start: &[c64],
    iterations: usize,
) -> Result<Vec<(Mat<f64>, Mat<f64>)>> {
    let mut poles = poles_of(start);
    for _ in 0..iterations {
        let new = relocate(&poles, data)?;
        let change = max_change(&poles, &new);
        poles = new;
        if change < 1e-9 {
            break;
        }
    }
    let res = residues(&poles, data)?;
    let mut out = Vec::new();
    if let Some(r) = realise_balanced(&poles, &res, data, order)? {
        out.push(r);
    }
    match realise(&poles, &res, data, order) {
        Ok(r) => out.push(r),
        Err(e) if out.is_empty() => return Err(e),
        Err(_) => {}
    }
    Ok(out)
}

/// The band-balanced truncation of the whole partial-fraction model (module docs): every pole
/// with its whole residue (Gilbert's realisation: a state per rank-one part of a real pole's
/// residue, two per part of a pair's), balanced on the data's lines
/// ([`band_balanced`](crate::estimate::scheduled::band_balanced)) and truncated to `order`
/// states; `None` when the realisation has fewer states than `order` or cannot be balanced.
fn realise_balanced(
    poles: &[Pole],
    res: &[Mat<f64>],
    data: &Data,
    order: usize,
) -> Result<Option<(Mat<f64>, Mat<f64>)>> {
    let (ny, nu) = (data.ny, data.nu);
    let j = c64::new(0.0, 1.0);
    // (pole, u, σ v̄): the part σ u vᴴ of the pole's residue
    let mut parts: Vec<(Pole, Vec<c64>, Vec<c64>)> = Vec::new();
    let mut top = 0.0f64;
    let mut s = 0;
    for p in poles {
        let r = match *p {
            Pole::Real(_) => {
                let r = Mat::<c64>::from_fn(ny, nu, |a, b| c64::new(res[s][(a, b)], 0.0));
                s += 1;
                r
            }
            Pole::Pair(_) => {
                let r = Mat::<c64>::from_fn(ny, nu, |a, b| {
                    c64::new(res[s][(a, b)], 0.0) + j * res[s + 1][(a, b)]
                });
                s += 2;
                r
            }
        };
        let svd = r.svd().map_err(|_| degenerate("SVD of a residue failed"))?;
        let sv = svd.S().column_vector();
        for k in 0..sv.nrows().min(ny).min(nu) {
            let sg = sv[k].re;
            top = top.max(sg);
            let u: Vec<c64> = (0..ny).map(|i| svd.U()[(i, k)]).collect();
            let v: Vec<c64> = (0..nu).map(|i| svd.V()[(i, k)].conj() * sg).collect();
            parts.push((*p, u, v));
        }
    }
    // parts at rounding level of the largest carry no state
    parts.retain(|(_, _, v)| v.iter().map(|x| x.norm_sqr()).sum::<f64>().sqrt() > 1e-12 * top);
    let big: usize = parts
        .iter()
        .map(|(p, _, _)| if matches!(p, Pole::Real(_)) { 1 } else { 2 })
        .sum();
    if big < order {
        return Ok(None);
    }
    let mut a = Mat::<f64>::zeros(big, big);
    let mut b = Mat::<f64>::zeros(big, nu);
    let mut c = Mat::<f64>::zeros(ny, big);
    let mut st = 0;
    for (p, u, v) in &parts {
        match *p {
            Pole::Real(x) => {
                a[(st, st)] = x;
                for q in 0..nu {
                    b[(st, q)] = v[q].re;
                }
                for i in 0..ny {
                    c[(i, st)] = u[i].re;
                }
                st += 1;
            }
            Pole::Pair(z) => {
                // u v̄ᵀ/(z − p) + its conjugate, with the state x = (Re ξ, Im ξ) of the
                // complex state ξ' = p ξ + v̄ᵀ w and y = 2 Re(u ξ)
                a[(st, st)] = z.re;
                a[(st, st + 1)] = -z.im;
                a[(st + 1, st)] = z.im;
                a[(st + 1, st + 1)] = z.re;
                for q in 0..nu {
                    b[(st, q)] = v[q].re;
                    b[(st + 1, q)] = v[q].im;
                }
                for i in 0..ny {
                    c[(i, st)] = 2.0 * u[i].re;
                    c[(i, st + 1)] = -2.0 * u[i].im;
                }
                st += 2;
            }
        }
    }
    let full = crate::lti::StateSpace::discrete(a, b, c, Mat::zeros(ny, nu), data.ts)?;
    let Some(bal) = crate::estimate::scheduled::band_balanced(&full, &data.z) else {
        return Ok(None);
    };
    Ok(Some((
        bal.a().submatrix(0, 0, order, order).to_owned(),
        bal.c().subcols(0, order).to_owned(),
    )))
}

fn sorted(p: &[Pole]) -> Vec<c64> {
    let mut v: Vec<c64> = p
        .iter()
        .map(|p| match *p {
            Pole::Real(x) => c64::new(x, 0.0),
            Pole::Pair(z) => z,
        })
        .collect();
    v.sort_by(|a, b| a.re.total_cmp(&b.re).then(a.im.total_cmp(&b.im)));
    v
}

fn max_change(a: &[Pole], b: &[Pole]) -> f64 {
    let (a, b) = (sorted(a), sorted(b));
    if a.len() != b.len() {
        return f64::INFINITY;
    }
    a.iter()
        .zip(&b)
        .map(|(x, y)| (x - y).norm())
        .fold(0.0, f64::max)
}

/// The realisation of the dominant rank-one parts (module docs).
fn realise(
    poles: &[Pole],
    res: &[Mat<f64>],
    data: &Data,
    order: usize,
) -> Result<(Mat<f64>, Mat<f64>)> {
    let (l, ny) = (data.len() as f64, data.ny);
    let j = c64::new(0.0, 1.0);
    // (importance, pole index, left singular vector)
    let mut parts: Vec<(f64, usize, Vec<c64>)> = Vec::new();
    let mut s = 0;
    for (pi, p) in poles.iter().enumerate() {
        let (pz, r) = match *p {
            Pole::Real(x) => {
                let r = Mat::<c64>::from_fn(ny, data.nu, |a, b| c64::new(res[s][(a, b)], 0.0));
                s += 1;
                (c64::new(x, 0.0), r)
            }
            Pole::Pair(z) => {
                let r = Mat::<c64>::from_fn(ny, data.nu, |a, b| {
                    c64::new(res[s][(a, b)], 0.0) + j * res[s + 1][(a, b)]
                });
                s += 2;
                (z, r)
            }
        };
        let gain = (data
            .z
            .iter()
            .map(|&z| (z - pz).inv().norm_sqr())
            .sum::<f64>()
            / l)
            .sqrt();
        let svd = r.svd().map_err(|_| degenerate("SVD of a residue failed"))?;
        let sv = svd.S().column_vector();
        for k in 0..sv.nrows().min(ny) {
            let u: Vec<c64> = (0..ny).map(|i| svd.U()[(i, k)]).collect();
            parts.push((sv[k].re * gain, pi, u));
        }
    }
    parts.sort_by(|a, b| b.0.total_cmp(&a.0));
    let mut chosen: Vec<&(f64, usize, Vec<c64>)> = Vec::new();
    let mut dim = 0;
    for part in &parts {
        let d = match poles[part.1] {
            Pole::Real(_) => 1,
            Pole::Pair(_) => 2,
        };
        if dim + d <= order && part.0 > 0.0 {
            chosen.push(part);
            dim += d;
        }
        if dim == order {
            break;
        }
    }
    if dim < order {
        return Err(degenerate("fewer significant modes than the order"));
    }
    let mut a = Mat::<f64>::zeros(order, order);
    let mut c = Mat::<f64>::zeros(ny, order);
    let mut s = 0;
    for (_, pi, u) in chosen {
        let d = put_block(&mut a, s, poles[*pi]);
        for i in 0..ny {
            c[(i, s)] = u[i].re;
            if d == 2 {
                c[(i, s + 1)] = u[i].im;
            }
        }
        s += d;
    }
    Ok((a, c))
}

/// Writes the real block of `pole` into `a` at state `s` ($[a]$, or
/// $\begin{bmatrix}\operatorname{Re} p & \operatorname{Im} p \\ -\operatorname{Im} p &
/// \operatorname{Re} p\end{bmatrix}$, whose eigenvector $[1, j]^{\mathsf T}$ belongs to $p$);
/// returns its dimension.
fn put_block(a: &mut Mat<f64>, s: usize, pole: Pole) -> usize {
    match pole {
        Pole::Real(x) => {
            a[(s, s)] = x;
            1
        }
        Pole::Pair(p) => {
            a[(s, s)] = p.re;
            a[(s, s + 1)] = p.im;
            a[(s + 1, s)] = -p.im;
            a[(s + 1, s + 1)] = p.re;
            2
        }
    }
}

/// Starting poles spread over the band: `n` poles as pairs at the band's frequencies
/// (log-spaced) with 1 % damping, and one real pole at the band's centre when `n` is odd.
pub(super) fn spread_poles(data: &Data, n: usize) -> Vec<c64> {
    let (lo, hi) = (
        data.f_hz.first().copied().unwrap_or(1.0),
        data.f_hz.last().copied().unwrap_or(1.0),
    );
    let pairs = n / 2;
    let mut out = Vec::with_capacity(n);
    for k in 0..pairs {
        let f = if pairs > 1 {
            lo * (hi / lo).powf(k as f64 / (pairs - 1) as f64)
        } else {
            (lo * hi).sqrt()
        };
        let w = 2.0 * std::f64::consts::PI * f;
        let s = c64::new(-0.01 * w, w);
        let z = (s * data.ts).exp();
        out.push(z);
        out.push(z.conj());
    }
    if n % 2 == 1 {
        let w = 2.0 * std::f64::consts::PI * (lo * hi).sqrt();
        out.push(c64::new((-w * data.ts).exp(), 0.0));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::super::{deltas, to_blocks, Data, MimoFreqOptions, Problem, Warp};
    use super::*;
    use crate::lti::{Frd, StateSpace};
    use faer::mat;

    /// 2 × 2, poles 1.02 (unstable), 0.6, and the pair 0.99 e^{±0.08j} twice (two blocks with
    /// different input and output directions: a residue of rank 2).
    fn plant() -> StateSpace {
        let (r, w) = (0.99f64, 0.08f64);
        let (c, s) = (r * w.cos(), r * w.sin());
        StateSpace::discrete(
            mat![
                [1.02, 0.0, 0.0, 0.0, 0.0, 0.0],
                [0.0, c, s, 0.0, 0.0, 0.0],
                [0.0, -s, c, 0.0, 0.0, 0.0],
                [0.0, 0.0, 0.0, c, s, 0.0],
                [0.0, 0.0, 0.0, -s, c, 0.0],
                [0.0, 0.0, 0.0, 0.0, 0.0, 0.6]
            ],
            mat![
                [1.0, 0.5],
                [0.0, 1.0],
                [1.0, -0.3],
                [0.7, 0.1],
                [-0.4, 0.6],
                [0.2, 0.7]
            ],
            mat![
                [1.0, 0.2, 0.0, 0.9, -0.3, 0.5],
                [0.4, 0.0, 1.0, 0.1, 0.8, -0.2]
            ],
            mat![[0.0, 0.0], [0.0, 0.0]],
            1e-3,
        )
        .unwrap()
    }

    fn data() -> Data {
        let f: Vec<f64> = (1..=60).map(|k| 3.0 * k as f64).collect();
        let frd = Frd::from_model(&plant(), &f).unwrap();
        Data::new(&frd, &MimoFreqOptions::default()).unwrap()
    }

    #[test]
    fn relocation_finds_the_poles_and_keeps_the_unstable_one() {
        let data = data();
        // four distinct poles (as pairs spread over the band) for the 1 + 1 + pair of the truth
        let mut poles = poles_of(&spread_poles(&data, 4));
        for _ in 0..30 {
            poles = relocate(&poles, &data).unwrap();
        }
        let got = sorted(&poles);
        let (r, w) = (0.99f64, 0.08f64);
        let want = [
            c64::new(0.6, 0.0),
            c64::from_polar(r, w),
            c64::new(1.02, 0.0),
        ];
        assert_eq!(got.len(), 3, "{got:?}");
        for (g, t) in got.iter().zip(&want) {
            assert!((g - t).norm() < 1e-8, "{got:?} vs {want:?}");
        }
    }

    #[test]
    fn both_realisations_hold_the_rank_two_residue_and_reproduce_the_data() {
        let data = data();
        let truth = plant();
        // first the band-balanced truncation, then the rank-one parts
        let starts = start(&data, 6, &spread_poles(&data, 4), 30).unwrap();
        assert_eq!(starts.len(), 2);
        let pair = c64::from_polar(0.99, 0.08);
        for (a, c) in starts {
            let mut ev = linalg::eigenvalues(a.as_ref()).unwrap();
            ev.sort_by(|x, y| x.re.total_cmp(&y.re).then(x.im.total_cmp(&y.im)));
            assert_eq!(ev.len(), 6);
            // the pair appears twice, the real poles once
            assert_eq!(
                ev.iter().filter(|z| (*z - pair).norm() < 1e-7).count(),
                2,
                "{ev:?}"
            );
            for p in [1.02, 0.6] {
                assert_eq!(
                    ev.iter()
                        .filter(|z| (*z - c64::new(p, 0.0)).norm() < 1e-7)
                        .count(),
                    1,
                    "{ev:?}"
                );
            }
            // with the numerators fitted, each start reproduces the response exactly
            let warp = Warp::new(&data.f_hz, data.ts);
            let (layout, mut th) = to_blocks(&a, &c, warp.h, 2, 2, false).unwrap();
            let prob = Problem::new(&data, &layout, &deltas(&data, &warp), None);
            prob.fit_linear(&mut th).unwrap();
            let model = layout.realise(&th, &data).unwrap();
            let (got, want) = (
                model.freq_response(&data.f_hz).unwrap(),
                truth.freq_response(&data.f_hz).unwrap(),
            );
            for (g, w) in got.iter().zip(&want) {
                for i in 0..2 {
                    for j in 0..2 {
                        let d = (g[(i, j)] - w[(i, j)]).norm();
                        assert!(d <= 1e-8 * w[(i, j)].norm().max(1.0), "{d}");
                    }
                }
            }
        }
    }

    #[test]
    fn the_relocation_solves_the_dense_projected_least_squares_problem() {
        // oracle: every entry's own unknowns projected out explicitly (normal equations of
        // the entry's [Φ 1]), the projected rows of all entries stacked and solved by the
        // normal equations of the whole
        let data = data();
        let poles = poles_of(&spread_poles(&data, 4));
        let (l, e) = (data.len(), data.entries());
        let nb = n_basis(&poles);
        let phi = basis_table(&poles, &data).unwrap();
        let mut big_a = Mat::<f64>::zeros(2 * l * e, nb);
        let mut big_b = Mat::<f64>::zeros(2 * l * e, 1);
        for ent in 0..e {
            let own = Mat::<f64>::from_fn(2 * l, nb + 1, |row, c| {
                let (k, idx) = (row / 2, (row / 2) * e + ent);
                let v = if c < nb {
                    phi[k * nb + c] * data.sw[idx]
                } else {
                    c64::new(data.sw[idx], 0.0)
                };
                if row % 2 == 0 {
                    v.re
                } else {
                    v.im
                }
            });
            let rest = Mat::<f64>::from_fn(2 * l, nb + 1, |row, c| {
                let (k, idx) = (row / 2, (row / 2) * e + ent);
                let g = data.g[idx] * data.sw[idx];
                let v = if c < nb { -g * phi[k * nb + c] } else { g };
                if row % 2 == 0 {
                    v.re
                } else {
                    v.im
                }
            });
            let gram = own.transpose() * &own;
            let x = linalg::solve(gram.as_ref(), (own.transpose() * &rest).as_ref()).unwrap();
            let proj = &rest - &own * &x;
            for r in 0..2 * l {
                for m in 0..nb {
                    big_a[(ent * 2 * l + r, m)] = proj[(r, m)];
                }
                big_b[(ent * 2 * l + r, 0)] = proj[(r, nb)];
            }
        }
        let gram = big_a.transpose() * &big_a;
        let want = linalg::solve(gram.as_ref(), (big_a.transpose() * &big_b).as_ref()).unwrap();
        let got = sigma_coefficients(&poles, &data).unwrap();
        let norm = want.norm_l2();
        let err = (0..nb)
            .map(|c| (got[c] - want[(c, 0)]).powi(2))
            .sum::<f64>()
            .sqrt()
            / norm;
        assert!(err < 1e-8, "relative error {err:e} of σ's coefficients");
    }

    #[test]
    fn a_start_with_too_few_modes_is_a_typed_error() {
        let data = data();
        // two poles cannot carry a 12th-order model (at most 2 × rank 2 × 2 states)
        let err = start(&data, 12, &spread_poles(&data, 2), 5).unwrap_err();
        assert!(err.to_string().contains("vector-fitting start"), "{err}");
    }
}
