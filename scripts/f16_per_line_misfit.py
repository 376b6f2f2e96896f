"""Is the F-16's per-line misfit a fixed per-line error? (docs/uncertainty.md, "Real data: a
held-out measurement").

Plain numpy, independent of ambid. For each acceleration of the F-16 ground vibration test
(level 1, ../shared/data/real/f16-gvt), the FRF Y/U of periods 2-5 and of periods 6-9 on the
2-15 Hz lines; from each, the residual of a local quadratic over 7 lines (its smooth part
removed). Printed: the residual's median magnitude, the periods' noise (median |G_a - G_b|/sqrt 2),
the correlation of the two halves' residuals, and the lag-1 correlation over the lines.
A residual several times the noise and correlated 1.0 between the halves is a fixed per-line
error that both measurements share; its lag-1 correlation tells how rough it is over the lines
(after the local fit, white residuals give about -0.48 and a smooth error a value near or above
0). The measured -0.25 is rough, close to white: what one multisine realisation's nonlinear
distortion looks like, and what any window of lines averages away.

    python3 scripts/f16_per_line_misfit.py [path/to/F16Data_FullMSine_Level1.csv]
"""
import sys
import numpy as np

path = sys.argv[1] if len(sys.argv) > 1 else "../shared/data/real/f16-gvt/F16Data_FullMSine_Level1.csv"
d = np.genfromtxt(path, delimiter=",", skip_header=1)[:, :5]
N = 8192
f = np.arange(N // 2 + 1) * 400.0 / N
lines = np.flatnonzero((f >= 2.0) & (f <= 15.0))


def frf(p0, p1, col):
    u = np.mean([np.fft.rfft(d[p * N:(p + 1) * N, 0]) for p in range(p0, p1)], axis=0)
    y = np.mean([np.fft.rfft(d[p * N:(p + 1) * N, col]) for p in range(p0, p1)], axis=0)
    return (y / u)[lines]


def residual(g, half=3):
    r = np.zeros_like(g)
    for i in range(len(g)):
        lo, hi = max(0, i - half), min(len(g), i + half + 1)
        a = np.vander(np.arange(lo, hi) - i, 3)
        c = np.linalg.lstsq(a, g[lo:hi], rcond=None)[0]
        r[i] = g[i] - c[-1]
    return r


for col, name in ((2, "acceleration 1"), (3, "acceleration 2"), (4, "acceleration 3")):
    ga, gb = frf(1, 5, col), frf(5, 9, col)
    ra, rb = residual(ga), residual(gb)
    noise = np.median(np.abs(ga - gb)) / np.sqrt(2)
    corr = np.real(np.vdot(ra, rb)) / np.sqrt(np.vdot(ra, ra).real * np.vdot(rb, rb).real)
    lag1 = np.real(np.vdot(ra[:-1], ra[1:])) / np.vdot(ra, ra).real
    print(f"{name}: residual {np.median(np.abs(ra)):.2e}, noise {noise:.2e} "
          f"({np.median(np.abs(ra)) / noise:.1f}x), halves' correlation {corr:.2f}, lag-1 {lag1:.2f}")
