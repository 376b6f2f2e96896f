"""Identification of many records as independent jobs: serially, in a local process pool, or on
a Dask cluster (``dask.distributed``, optional).

Each record is one workflow run (:func:`ambid.run`): a workflow file's TOML text with the
directory its relative paths are read from, or recorded arrays, which are written to a
temporary ``.npz`` and read through the same reader as every file. A job never raises: a
record that fails (a missing or malformed file, no excitation, an unstable fit) comes back as
its row with ``status = "error"`` and the error's type and message, and the other records
finish. Every job is deterministic (its seeds are in its settings), so the engine changes the
wall time, never a number.

>>> import ambid.batch as batch
>>> recs = [batch.Record.twin(f"seed{s}", seed=s, steps=["frf"]) for s in (1, 2)]
>>> table = batch.identify(recs)                       # doctest: +SKIP
>>> table.rows[0]["status"]                            # doctest: +SKIP
'ok'
"""

from __future__ import annotations

import os
import tempfile
from dataclasses import dataclass, field
from typing import Any, Callable, Iterable, Optional, Sequence

import numpy as np

__all__ = ["Record", "Result", "identify", "run_record", "drift", "model_key"]


@dataclass(frozen=True)
class Record:
    """One identification job: a name, the workflow TOML text, the base directory of its
    relative paths, and optionally arrays (``r``, ``u``, ``y``, ``i``; ``fs`` in the
    workflow's ``[data] fs_hz``) that the job writes to a temporary ``.npz`` named
    ``record.npz``, and text files (name -> text, e.g. a twin configuration) written beside
    it; with either, that temporary directory is the base."""

    name: str
    config: str = ""
    base: Optional[str] = None
    arrays: Optional[dict] = None
    files: Optional[dict] = None

    @staticmethod
    def twin(
        name: str,
        *,
        seed: int = 1,
        rig_seed: Optional[int] = None,
        mode: str = "nonlinear",
        steps: Optional[Sequence[str]] = None,
        extra: str = "",
    ) -> "Record":
        """A run on the embedded twin: workflow seed ``seed``, the nominal rig or random test
        rig ``rig_seed`` (its configuration embedded in the record), ``steps`` (default: all)."""
        from . import _native

        lines = [f"seed = {int(seed)}"]
        if steps is not None:
            lines.append("steps = [" + ", ".join(f'"{s}"' for s in steps) + "]")
        lines.append('source = "twin"')
        lines.append("[twin]")
        lines.append(f'mode = "{mode}"')
        files = None
        if rig_seed is not None:
            lines.append('config = "rig.toml"')
            files = {"rig.toml": _native.rig_config(int(rig_seed))}
        return Record(name, "\n".join(lines) + "\n" + extra, None, None, files)

    @staticmethod
    def from_arrays(
        name: str,
        *,
        r,
        u,
        y,
        fs: float,
        i=None,
        period_samples: Optional[int] = None,
        extra: str = "",
    ) -> "Record":
        """A recorded experiment given as arrays (closed loop, r at the controller output)."""
        arrays = {"r": r, "u": u, "y": y}
        if i is not None:
            arrays["i"] = i
        lines = ['source = "files"', "[data]", 'identification = "record.npz"', f"fs_hz = {float(fs)!r}"]
        if period_samples is not None:
            lines.append(f"period_samples = {int(period_samples)}")
        return Record(name, "\n".join(lines) + "\n" + extra, None, arrays)


@dataclass
class Result:
    """The batch's table (one row per record, in the records' order) and the models."""

    rows: list = field(default_factory=list)
    #: per record name: ``{model name: model JSON dict}`` (empty for a failed record)
    models: dict = field(default_factory=dict)

    def to_pandas(self):
        """The rows as a ``pandas.DataFrame`` (needs pandas)."""
        import pandas as pd

        return pd.DataFrame(self.rows)


def model_key(chosen: str) -> str:
    """The key in ``Result.models`` (the file name ``models/<key>.json``) of a model named as the
    summary's ``chosen_model`` names it: ``"SS 9"`` -> ``"ss9"``."""
    return chosen.lower().replace(" ", "")


def _get(d: Any, *path: str) -> Any:
    for p in path:
        if not isinstance(d, dict) or p not in d:
            return None
        d = d[p]
    return d


def _freq_response(model: dict, f_hz: np.ndarray) -> np.ndarray:
    """The plant response ``u -> y`` of a model JSON (as ``models/<name>.json`` holds it) at
    ``f_hz``: ``C (zI - A)^{-1} B + D`` (entry 0,0) of a state-space model, ``B / (A F)`` in
    powers of ``z^{-1}`` of a polynomial one."""
    z = np.exp(2j * np.pi * f_hz * float(model["ts"]))
    if model.get("kind") == "polynomial":
        def poly(c):
            return sum(ck * z ** (-k) for k, ck in enumerate(c))
        return poly(model["b"]) / (poly(model["a"]) * poly(model["f"]))
    a = np.atleast_2d(np.asarray(model["a"], dtype=float))
    b = np.atleast_2d(np.asarray(model["b"], dtype=float))
    c = np.atleast_2d(np.asarray(model["c"], dtype=float))
    d = np.atleast_2d(np.asarray(model["d"], dtype=float))
    eye = np.eye(a.shape[0])
    return np.array([(c @ np.linalg.solve(zk * eye - a, b) + d)[0, 0] for zk in z])


def drift(model: dict, reference: dict, band_hz: tuple, lines: int = 200) -> float:
    """Median over ``lines`` log-spaced frequencies in ``band_hz`` of
    ``|G(f) - G_ref(f)| / |G_ref(f)|``: how far a re-identified plant moved from a reference."""
    f = np.geomspace(band_hz[0], band_hz[1], lines)
    g, g0 = _freq_response(model, f), _freq_response(reference, f)
    return float(np.median(np.abs(g - g0) / np.abs(g0)))


def run_record(record: Record, reference: Optional[dict] = None) -> tuple:
    """Runs one record; never raises. Returns ``(row, models)``."""
    from . import run

    row: dict = {"record": record.name, "status": "ok", "error_type": None, "error": None}
    models: dict = {}
    try:
        with tempfile.TemporaryDirectory(prefix="ambid-batch-") as tmp:
            base = record.base
            if record.arrays is not None or record.files is not None:
                base = tmp
            if record.arrays:
                np.savez(
                    os.path.join(tmp, "record.npz"),
                    **{k: np.ascontiguousarray(v, dtype=float) for k, v in record.arrays.items()},
                )
            for fname, text in (record.files or {}).items():
                with open(os.path.join(tmp, fname), "w", encoding="utf-8") as fh:
                    fh.write(text)
            out = run(record.config, base=base)
        s = out.summary
        chosen = _get(s, "models", "chosen")
        row.update(
            {
                "chosen_model": chosen,
                "fit_y_pct": _get(s, "validation", "fit_y_pct"),
                "fit_u_pct": _get(s, "validation", "fit_u_pct"),
                "iso_zone": _get(s, "iso", "zone"),
                "unstable_poles": _get(s, "pole_zero", "chosen_unstable_poles"),
                "frf_lines": _get(s, "frf", "lines"),
                "frf_mean_coh_ry": _get(s, "frf", "mean_coh_ry"),
                "error_vs_truth_pct": _get(s, "models", "chosen_error_vs_truth_pct"),
                "drift": None,
            }
        )
        models = out.models()
        if reference is not None and chosen is not None:
            key = model_key(chosen)
            lo, hi = _get(s, "frf", "quality_band_lo_hz"), _get(s, "frf", "quality_band_hi_hz")
            if key in models and lo is not None and hi is not None:
                row["drift"] = drift(models[key], reference, (lo, hi))
    except Exception as e:  # a job must not take the batch down: its row says what failed
        row.update({"status": "error", "error_type": type(e).__name__, "error": str(e)})
    return row, models


def _job(args: tuple) -> tuple:
    return run_record(*args)


def _job_in_worker(args: tuple) -> tuple:
    # in a pool, the records are the parallelism: one thread per job, as Dask's workers set
    # OMP/MKL/OpenBLAS to one thread (the Rust thread pool reads this at its first use in the
    # worker process; a value the user set is kept)
    os.environ.setdefault("RAYON_NUM_THREADS", "1")
    return run_record(*args)


def identify(
    records: Iterable[Record],
    *,
    engine: str = "serial",
    workers: Optional[int] = None,
    client: Any = None,
    reference: Optional[dict] = None,
    progress: Optional[Callable[[int, int], None]] = None,
) -> Result:
    """Identifies every record as an independent job and returns one table.

    ``engine``: ``"serial"`` (in this process), ``"processes"`` (a local process pool of
    ``workers``, default the CPU count) or ``"dask"`` (``client``: a ``dask.distributed``
    ``Client``, e.g. on a ``LocalCluster`` or a real scheduler's address). ``reference``: a
    model JSON dict (as :meth:`ambid.Outcome.models` gives) against which each chosen model's
    drift is measured. The rows come back in the records' order whatever the engine.
    """
    recs = list(records)
    names = [r.name for r in recs]
    if len(set(names)) != len(names):
        from . import UsageError

        raise UsageError("record names must be unique: they key the result's models")
    jobs = [(r, reference) for r in recs]
    if engine == "serial":
        outs = []
        for k, j in enumerate(jobs):
            outs.append(_job(j))
            if progress:
                progress(k + 1, len(jobs))
    elif engine == "processes":
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor

        # spawned, not forked: a fork of a process whose Rust thread pool is running leaves
        # the child's pool without its threads (the child would wait for them forever)
        ctx = multiprocessing.get_context("spawn")
        with ProcessPoolExecutor(max_workers=workers, mp_context=ctx) as ex:
            outs = list(ex.map(_job_in_worker, jobs))
    elif engine == "dask":
        if client is None:
            from . import UsageError

            raise UsageError('engine="dask" needs client=dask.distributed.Client(...)')
        futures = client.map(_job_in_worker, jobs, pure=False)
        outs = client.gather(futures)
    else:
        from . import UsageError

        raise UsageError(f'unknown engine "{engine}": use "serial", "processes" or "dask"')
    result = Result()
    for (row, models), name in zip(outs, names):
        result.rows.append(row)
        result.models[name] = models
    return result
