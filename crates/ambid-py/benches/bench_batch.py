"""Parallel efficiency of `ambid.batch` on a Dask LocalCluster (issue 22's bar: 64 twin records,
2 workers, results identical to the serial run, efficiency >= 80 %).

    python crates/ambid-py/benches/bench_batch.py [N_RECORDS]   # release wheel, dask installed

Records: the twin with 64 (seed, rig) pairs — 32 random test rigs (other masses, magnets,
controllers, noise) x 2 noise seeds — linear mode, steps frf → iso (the identification part of
the workflow). Efficiency = T_serial / (workers x T_dask). Prints both times, the efficiency and
whether every row and model is identical.
"""

import sys
import time

import ambid.batch as batch

STEPS = ["frf", "order", "models", "pole_zero", "validation", "iso"]


def main() -> None:
    from dask.distributed import Client, LocalCluster

    n = int(sys.argv[1]) if len(sys.argv) > 1 else 64
    recs = [
        batch.Record.twin(f"r{k:03d}", seed=k + 1, rig_seed=k // 2 + 1, mode="linear", steps=STEPS)
        for k in range(n)
    ]
    t0 = time.perf_counter()
    serial = batch.identify(recs)
    t_serial = time.perf_counter() - t0
    with LocalCluster(n_workers=2, threads_per_worker=1, dashboard_address=None) as lc, Client(lc) as c:
        c.run(lambda: __import__("ambid"))  # workers warmed up: import time is not identification
        t0 = time.perf_counter()
        par = batch.identify(recs, engine="dask", client=c)
        t_dask = time.perf_counter() - t0
    same = serial.rows == par.rows and serial.models == par.models
    ok = sum(r["status"] == "ok" for r in serial.rows)
    print(f"{n} records ({ok} ok): serial {t_serial:.1f} s, dask 2 workers {t_dask:.1f} s, "
          f"efficiency {t_serial / (2 * t_dask) * 100:.0f} %, identical: {same}")


if __name__ == "__main__":
    main()
