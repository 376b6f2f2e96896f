"""Parallel efficiency of `ambid.batch` on a Dask LocalCluster (issue 22's bar: 64 twin records,
2 workers, results identical to the serial run, efficiency >= 80 %).

    python crates/ambid-py/benches/bench_batch.py [N_RECORDS]   # release wheel, dask installed

Records: the twin with 64 (seed, rig) pairs — 32 random test rigs (other masses, magnets,
controllers, noise) x 2 noise seeds — linear mode, steps frf → iso (the identification part of
the workflow). Three runs: serial in this process (each job's stages use every core, as a user's
serial run does), one single-threaded worker process (`engine="processes", workers=1`: the
one-worker time T_1 of the textbook efficiency), and Dask with 2 single-threaded workers.
Prints the times, the efficiency T_1 / (2 T_dask) and the serial-run ratio
T_serial / (2 T_dask), and whether every row and model is identical.
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
    t0 = time.perf_counter()
    single = batch.identify(recs, engine="processes", workers=1)
    t_single = time.perf_counter() - t0
    with LocalCluster(n_workers=2, threads_per_worker=1, dashboard_address=None) as lc, Client(lc) as c:
        c.run(lambda: __import__("ambid"))  # workers warmed up: import time is not identification
        t0 = time.perf_counter()
        par = batch.identify(recs, engine="dask", client=c)
        t_dask = time.perf_counter() - t0
    same = all(serial.rows == o.rows and serial.models == o.models for o in (par, single))
    ok = sum(r["status"] == "ok" for r in serial.rows)
    print(f"{n} records ({ok} ok): serial {t_serial:.1f} s, one single-threaded worker "
          f"{t_single:.1f} s, dask 2 workers {t_dask:.1f} s; efficiency T_1 / (2 T_dask) "
          f"{t_single / (2 * t_dask) * 100:.0f} %, T_serial / (2 T_dask) "
          f"{t_serial / (2 * t_dask) * 100:.0f} %; identical: {same}")


if __name__ == "__main__":
    main()
