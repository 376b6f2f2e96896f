#!/usr/bin/env python3
"""Is ambid's weight fit the limit of the looseness bar? A global search of the same fit
(issue 23; docs/uncertainty.md, "A global search of the weight's fit").

Reads the per-run dumps of `DUMP_SERIES=DIR cargo run --release -p ambid --example
uncertainty_workflow_rigs -- RIGS linear|nonlinear` (one CSV per run, named
`<mode>_<rig>_raise<g>.csv`, with the columns `f_hz`, `bound` (the bound l on the weight's
lines), `weight` (|W| of ambid's raised weight) and `error` (the chosen model's true relative
error against the twin's exact plant); g is the joint raise ambid applied to its weight).

For each run it fits, with scipy's differential evolution (an implementation independent of
ambid's Levenberg-Marquardt fit and its starts), the continuous-time weight of order 4

    W(s) = g * prod_i (s^2 + 2 zz_i wz_i s + wz_i^2) / wz_i^2 / ((s^2 + 2 zp_i wp_i s + wp_i^2) / wp_i^2),

i = 1, 2 (zeta in 0.01..5, so real pairs too; corners from a decade below the lowest line to
5 kHz), to the same criterion ambid's mode-shaped family is judged by: the gain g puts |W| above
l on 98 % of the lines, and the geometric mean of |W|/l over the lines is minimised. The
result is raised by the run's own joint raise g (ambid's, not recomputed for the new shape) and
judged as the sweeps judge ambid's: the fraction of the 10-1000 Hz lines where it covers the
true error, and its looseness median |W| / median error on those lines.

Usage: python3 scripts/weight_global_fit.py 'DIR/linear_*.csv'   (prints one row per run and a
summary; about 10 s per run)
"""
import glob
import re
import sys

import numpy as np
from scipy.optimize import differential_evolution

COVER = 0.98
PAIRS = 2


def log_mag(p, w):
    """ln|W(jw)|/g for the factor parameters p (ln wz, ln zz, ln wp, ln zp per pair)."""
    s = 1j * w
    out = np.zeros_like(w)
    for i in range(PAIRS):
        wz, zz, wp, zp = np.exp(p[4 * i:4 * i + 4])
        out += np.log(np.abs(s * s + 2 * zz * wz * s + wz * wz) / wz**2)
        out -= np.log(np.abs(s * s + 2 * zp * wp * s + wp * wp) / wp**2)
    return out


def raised_log_ratio(p, w, log_l):
    """ln(|W_k|/l_k) with the gain raised to cover COVER of the lines."""
    d = log_mag(p, w) - log_l
    return d - np.quantile(d, 1 - COVER)


def fit(f, bound, seed=0):
    w = 2 * np.pi * f
    log_l = np.log(bound)
    lo, hi = np.log(w[0] / 10), np.log(2 * np.pi * 5000)
    z = (np.log(0.01), np.log(5))
    res = differential_evolution(
        lambda p: np.mean(raised_log_ratio(p, w, log_l)),
        [(lo, hi), z, (lo, hi), z] * PAIRS,
        seed=seed, popsize=40, maxiter=400, tol=1e-8, polish=True)
    return np.exp(raised_log_ratio(res.x, w, log_l))  # |W_k| / l_k


def main():
    files = sorted(glob.glob(sys.argv[1]), key=lambda s: int(s.rsplit("/", 1)[-1].split("_")[1]))
    rows = []
    for fn in files:
        d = np.genfromtxt(fn, delimiter=",", names=True)
        g = float(re.search(r"raise([0-9.eE+-]+)\.csv$", fn).group(1))
        f, bound, weight, err = d["f_hz"], d["bound"], d["weight"], d["error"]
        band = (f >= 10) & (f <= 1000)
        me = np.median(err[band])
        w_de = fit(f, bound) * bound * g
        r = (np.median(weight[band]) / me, np.mean(weight[band] >= err[band]),
             np.median(w_de[band]) / me, np.mean(w_de[band] >= err[band]))
        rows.append(r)
        name = fn.rsplit("/", 1)[-1].split("_raise")[0]
        print(f"{name}: raise {g:.3f}, ambid looseness {r[0]:.2f} covers {r[1]:.3f} | "
              f"global order 4 looseness {r[2]:.2f} covers {r[3]:.3f}", flush=True)
    a = np.array(rows)
    q = np.quantile(a[:, 2] / a[:, 0], [0.1, 0.5, 0.9])
    print(f"runs {len(a)}: looseness median ambid {np.median(a[:, 0]):.2f}, global {np.median(a[:, 2]):.2f}; "
          f"global/ambid 10/50/90 % {q[0]:.2f}/{q[1]:.2f}/{q[2]:.2f}; <= 3: ambid {(a[:, 0] <= 3).sum()}, "
          f"global {(a[:, 2] <= 3).sum()}; covering >= 95 % of the lines: ambid {(a[:, 1] >= 0.95).sum()}, "
          f"global {(a[:, 3] >= 0.95).sum()}")


if __name__ == "__main__":
    main()
