"""ambid: closed-loop black-box identification of active magnetic bearing (AMB) systems.

The Python face of the Rust toolkit: numpy arrays in and out, the same numbers as the
``ambid`` command line (the same library functions run underneath), long computations
release the GIL.

Quick start::

    import ambid
    rec = ambid.simulate(seed=1)                      # the twin's seed experiment
    frf = ambid.frf(rec["r"], rec["u"], rec["y"], rec["fs"],
                    period_samples=rec["period_samples"])
    out = ambid.run()                                 # the whole workflow on the twin
    out.write("report")                               # report.html, summary.json, models/

Errors are typed: :class:`UsageError` (a setting; a ``ValueError``), :class:`InputError` (the
data: dtype, shape, NaN, lengths; a ``ValueError``), :class:`ComputationError` (a fit that
failed; a ``RuntimeError``), :class:`OutputError` (a write; an ``OSError``), all subclasses of
:class:`AmbidError`; each message says what is wrong and what to do.
"""

from __future__ import annotations

import json
from typing import Any, Optional

from . import _native
from ._native import (
    AmbidError,
    ComputationError,
    InputError,
    Model,
    OutputError,
    UsageError,
    fit_frf,
    fit_ss,
    frf,
    frf_local,
    order_scan,
    controller,
    twin_plant,
    validate,
    simulate,
    spectra,
    periodic_frf,
    machine_experiments,
    frf_mimo,
    bla,
    bla_study,
    amplitude_study,
    n4sid,
    ss,
    truth,
)

__all__ = [
    "AmbidError",
    "UsageError",
    "InputError",
    "ComputationError",
    "OutputError",
    "Model",
    "Outcome",
    "excite",
    "frf",
    "frf_local",
    "spectra",
    "machine_experiments",
    "bla",
    "bla_study",
    "amplitude_study",
    "frf_mimo",
    "periodic_frf",
    "n4sid",
    "ss",
    "fit_arx",
    "order_scan",
    "validate",
    "controller",
    "twin_plant",
    "fit_pem",
    "fit_ss",
    "fit_frf",
    "simulate",
    "truth",
    "run",
    "to_control",
    "frf_to_pandas",
    "__version__",
]

__version__ = _native.version()


def fit_arx(u, y, ts: float, *, na: int, nb: int, nk: int = 1) -> Model:
    """Least-squares ARX(na, nb, nk) model of ``u -> y`` (``ambid fit --structure arx``).

    ``na = 0`` gives the FIR model. ``u`` and ``y`` are 1-D float64 arrays of equal length,
    ``ts`` the sample time in seconds.

    >>> import numpy as np, ambid
    >>> rng = np.random.default_rng(0)
    >>> u = rng.standard_normal(500)
    >>> y = np.zeros(500)
    >>> for k in range(1, 500):
    ...     y[k] = 0.5 * y[k - 1] + 2.0 * u[k - 1]
    >>> m = ambid.fit_arx(u, y, 1.0, na=1, nb=1)
    >>> [round(float(v), 6) for v in m.params]
    [-0.5, 2.0]
    """
    return _native.fit_arx(u, y, ts, na=na, nb=nb, nk=nk)


def fit_pem(u, y, ts: float, structure: str, **orders: int) -> Model:
    """Prediction-error model of ``u -> y``: ``structure`` is ``"armax"``, ``"oe"`` or
    ``"bj"``; the orders as keywords (``na, nb, nc, nd, nf, nk``) and ``max_iterations``.

    >>> import numpy as np, ambid
    >>> rng = np.random.default_rng(0)
    >>> u = rng.standard_normal(2000)
    >>> x = np.zeros(2000)
    >>> for k in range(1, 2000):
    ...     x[k] = 0.8 * x[k - 1] + 0.5 * u[k - 1]
    >>> m = ambid.fit_pem(u, x + 0.01 * rng.standard_normal(2000), 1.0, "oe", nb=1, nf=1)
    >>> [round(float(v), 2) for v in m.polynomials["f"]]
    [1.0, -0.8]
    """
    return _native.fit_pem(u, y, ts, structure, **orders)


def excite(kind: str, fs: float = 20000.0, **params) -> dict:
    """An excitation signal (``ambid excite``): ``kind`` is ``"prbs"``, ``"chirp"``,
    ``"noise"`` or ``"multisine"``; ``params`` are the Rust spec's fields (``PrbsSpec``:
    ``order, samples_per_bit, periods, amplitude, offset``, defaulting to the seed paper's
    n = 10, Nb = 5, 20 periods, amplitude 1). Returns ``values``, ``ts``, ``period_samples``,
    ``periods`` and the band ``report`` (band, resolution, duration, RMS, peak, crest factor).

    >>> import ambid
    >>> e = ambid.excite("prbs", 20000.0, order=10, amplitude=0.2)
    >>> e["period_samples"], e["report"]["crest_factor"]
    (5115, 1.0)
    """
    return _native.excite(kind, fs, json.dumps(params))


class Outcome:
    """What :func:`run` produced: the summary (a dict, ``summary.json``), the HTML report and
    the exported models; :meth:`write` writes them as ``ambid run --out`` does."""

    def __init__(self, native: "_native.Outcome"):
        self._native = native
        self.summary: dict[str, Any] = json.loads(native.summary_json())

    def html(self) -> str:
        """The offline HTML report."""
        return self._native.html()

    def models(self) -> dict[str, dict[str, Any]]:
        """The exported state-space models by name, as the JSON ``ambid fit`` writes."""
        return {name: json.loads(text) for name, text in self._native.models()}

    def write(self, out, *, force: bool = False) -> list:
        """Writes ``report.html``, ``summary.json``, ``figures/``, ``tables/`` and ``models/``
        into ``out`` atomically (an existing directory is replaced only with ``force``)."""
        return self._native.write(str(out), force=force)


def run(config: Optional[str] = None, *, base: Optional[str] = None) -> Outcome:
    """The whole workflow (``ambid run``). ``config`` is the workflow file's TOML text, or a
    path to it; ``None`` runs the default workflow on the embedded twin. Relative paths in the
    file are read from ``base`` (default: the file's directory, else the working directory).

    >>> import ambid
    >>> out = ambid.run('steps = ["frf", "order", "models"]')
    >>> "chosen" in out.summary["models"]
    True
    """
    import os

    text = ""
    if config is not None:
        if "\n" not in config and os.path.isfile(config):
            base = base or os.path.dirname(os.path.abspath(config))
            with open(config, encoding="utf-8") as fh:
                text = fh.read()
        else:
            text = config
    return Outcome(_native.run(text, base=base))


def to_control(model: Model):
    """The model as a ``control.StateSpace`` (python-control, discrete time ``model.ts``)."""
    try:
        import control
    except ImportError as e:  # pragma: no cover - exercised only without python-control
        raise ImportError(
            "to_control() needs python-control: pip install control"
        ) from e
    return control.ss(model.a, model.b, model.c, model.d, model.ts)


def frf_to_pandas(result: dict):
    """The FRF dict of :func:`frf` as a ``pandas.DataFrame`` indexed by ``f_hz`` (needs pandas)."""
    import pandas as pd

    cols = {
        k: v
        for k, v in result.items()
        if hasattr(v, "shape") and getattr(v, "shape", None) == result["f_hz"].shape and k != "f_hz"
    }
    return pd.DataFrame(cols, index=pd.Index(result["f_hz"], name="f_hz"))

