#!/usr/bin/env python3
"""What an element-wise MIMO bound can reach on the half-margin bar (issue 23; docs/uncertainty.md,
"The half-margin bar against the element-wise structure").

Reads the per-rig dumps of `DUMP_MU=DIR cargo run --release -p ambid --example
uncertainty_machine_rigs -- RIGS` (JSON: the fit band's lines `f`; per line the 16 entries of the
model P^, the controller C and the exact plant P, column-major `e = i + 4 j`; the raised
element-wise bound `l`; the exact gain interval; the tool's robust margins) and computes, with
numpy only (an implementation independent of ambid's):

- the upper robust gain margin of the four controllers' gains together against the element-wise
  set |P_ij - P^_ij| <= s |P_ij - P^_ij|_exact (the *oracle*: the exact error's magnitudes with
  free phases) for s = 1, 1.5, 2, 2.5, by the Perron bound mu = rho(L |M|), M = (I + g C P^)^-1 g C,
  a 2 % gain scan and bisection, capped at the exact interval (as the tool's check on the lines);
- s*: the largest s whose margin is still at least half the exact one (the bar);
- tool_s: the s whose oracle margin equals the tool's margin on the lines (how far the tool's bound
  is, in units of the exact error, where the margin is decided);
- with --dscale, the D-scaled upper bound of mu (inf_D sigma(D M_big D^-1), 16 complex scalar
  blocks, M_big[(ij),(kl)] = L_ij M_jk) for the tool's bound, against the Perron bound.

Usage: python3 scripts/mimo_margin_oracle.py [--dscale] DIR/rig*.json
"""
import json
import sys

import numpy as np


def load(path):
    j = json.load(open(path))
    f = np.array(j["f"])
    n = len(f)

    # entry e = i + 4 j of line k sits at [k, i, j]
    def to(a):
        return np.stack([a[k].reshape(4, 4, order="F") for k in range(n)])

    ph = np.array(j["phat"]).reshape(n, 16, 2)
    c = np.array(j["c"]).reshape(n, 16, 2)
    ex = np.array(j["exact"]).reshape(n, 16, 2)
    z = lambda a: to(a[..., 0] + 1j * a[..., 1])
    return j, f, z(ph), z(c), z(ex), to(np.array(j["l"]).reshape(n, 16))


def m_of(ph, c, g):
    eye = np.eye(4)
    return np.stack([np.linalg.solve(eye + g * c[k] @ ph[k], g * c[k]) for k in range(len(ph))])


def mu_perron(L, M):
    return np.array([max(abs(np.linalg.eigvals(L[k] @ abs(M[k])))) for k in range(len(M))])


def mu_dscale(L, M):
    from scipy.optimize import minimize

    out = []
    for k in range(len(M)):
        big = np.zeros((16, 16), complex)
        for i in range(4):
            for j in range(4):
                for kk in range(4):
                    for l in range(4):
                        big[i + 4 * j, kk + 4 * l] = L[k][i, j] * M[k][j, kk]
        a = abs(big)
        w, v = np.linalg.eig(a)
        x = np.maximum(abs(v[:, np.argmax(abs(w))]), 1e-300)
        w, v = np.linalg.eig(a.T)
        y = np.maximum(abs(v[:, np.argmax(abs(w))]), 1e-300)

        def fg(s):
            d = np.exp(s)
            u, sv, vh = np.linalg.svd((d[:, None] * big) / d[None, :])
            return np.log(sv[0]), abs(u[:, 0]) ** 2 - abs(vh[0]) ** 2

        r = minimize(fg, 0.5 * np.log(y / x), jac=True, method="L-BFGS-B")
        out.append(float(np.exp(r.fun)))
    return np.array(out)


def upper_margin(ph, c, L, cap, mu=mu_perron):
    prev, g = 1.0, 1.0
    while g < cap:
        g = min(g * 1.02, cap)
        if mu(L, m_of(ph, c, g)).max() >= 1.0:
            lo, hi = prev, g
            for _ in range(12):
                mid = 0.5 * (lo + hi)
                if mu(L, m_of(ph, c, mid)).max() >= 1.0:
                    hi = mid
                else:
                    lo = mid
            return lo
        prev = g
    return cap


def geo_bisect(pred, lo, hi, steps=10):
    """Largest s in [lo, hi] with pred(s) (pred true below, false above)."""
    if not pred(lo):
        return 0.0
    if pred(hi):
        return hi
    for _ in range(steps):
        mid = np.sqrt(lo * hi)
        lo, hi = (mid, hi) if pred(mid) else (lo, mid)
    return lo


def main(args):
    dscale = "--dscale" in args
    paths = [a for a in args if a != "--dscale"]
    print("rig exact need tool | oracle x1 x1.5 x2 x2.5 | s* tool_s" + (" | tool with D-scaling" if dscale else ""))
    for p in paths:
        j, f, ph, c, ex, L = load(p)
        cap = j["exact_interval"][1]
        need = 1 + 0.5 * (cap - 1)
        err = abs(ex - ph)
        margin = lambda s: upper_margin(ph, c, s * err, cap)
        ms = [margin(s) for s in (1.0, 1.5, 2.0, 2.5)]
        sstar = geo_bisect(lambda s: margin(s) >= need, 0.05, 6.0)
        tool = j["lines_margins"][1]
        tool_s = geo_bisect(lambda s: margin(s) >= tool, 0.05, 20.0, 12)
        line = "%s %.3f %.3f %.3f | %.3f %.3f %.3f %.3f | %.2f %.2f" % (
            p.split("/")[-1][:-5], cap, need, tool, *ms, sstar, tool_s)
        if dscale:
            line += " | %.3f" % upper_margin(ph, c, L, cap, mu_dscale)
        print(line, flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
