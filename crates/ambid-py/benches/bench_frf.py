"""Overhead of the Python layer on the period-averaged FRF (issue 22's bar: within 10 % of the
Rust benchmark `cargo bench -p ambid --bench frf -- analysis_periodic`).

    python crates/ambid-py/benches/bench_frf.py     # with a release wheel installed

Same workload as the Rust bench: the linear twin's seed record (102 300 samples; the sensor
noise level differs, which does not change the work), 20 periods of 5 115 samples, first
dropped. Prints the median and the fastest of 7 repeats of 50 calls.
"""

import timeit

import numpy as np

import ambid

rec = ambid.simulate(seed=1, mode="linear")
r, u, y = (np.ascontiguousarray(rec[k]) for k in ("r", "u", "y"))
for screen in (False, True):
    call = lambda: ambid.frf(r, u, y, 20000.0, period_samples=5115, skip_periods=1, screen=screen)
    call()
    runs = np.array(timeit.repeat(call, number=50, repeat=7)) / 50
    print(f"ambid.frf(screen={screen}): median {np.median(runs) * 1e3:.3f} ms, fastest {runs.min() * 1e3:.3f} ms")
