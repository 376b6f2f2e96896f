"""Type stubs of the native module (crates/ambid-py/src/lib.rs)."""

from os import PathLike
from typing import Any, Optional, Tuple

import numpy as np
import numpy.typing as npt

F64 = npt.NDArray[np.float64]
C128 = npt.NDArray[np.complex128]

class AmbidError(Exception): ...
class UsageError(AmbidError, ValueError): ...
class InputError(AmbidError, ValueError): ...
class ComputationError(AmbidError, RuntimeError): ...
class OutputError(AmbidError, OSError): ...

class Model:
    @property
    def structure(self) -> str: ...
    @property
    def ts(self) -> float: ...
    @property
    def order(self) -> int: ...
    @property
    def a(self) -> F64: ...
    @property
    def b(self) -> F64: ...
    @property
    def c(self) -> F64: ...
    @property
    def d(self) -> F64: ...
    @property
    def params(self) -> F64: ...
    @property
    def params_std(self) -> Optional[F64]: ...
    @property
    def loss(self) -> float: ...
    @property
    def noise_variance(self) -> float: ...
    @property
    def n_samples(self) -> int: ...
    @property
    def polynomials(self) -> Optional[dict[str, F64]]: ...
    def poles(self) -> C128: ...
    def freq_response(self, f_hz: F64) -> C128: ...
    def to_control(self) -> Any: ...
    def to_json(self) -> str: ...
    def save(self, path: "str | PathLike[str]", *, force: bool = False) -> list[str]: ...

class Outcome:
    def summary_json(self) -> str: ...
    def html(self) -> str: ...
    def write(self, out: "str | PathLike[str]", *, force: bool = False) -> list[str]: ...
    def models(self) -> list[Tuple[str, str]]: ...

def version() -> str: ...
def frf(
    r: F64,
    u: F64,
    y: F64,
    fs: float,
    *,
    period_samples: Optional[int] = None,
    skip_periods: int = 1,
    nperseg: Optional[int] = None,
    band: Optional[Tuple[float, float]] = None,
    quality_band: Optional[Tuple[float, float]] = None,
    i_sat: Optional[float] = None,
    screen: bool = True,
    noise: Optional[F64] = None,
    current: Optional[F64] = None,
) -> dict[str, Any]: ...
def fit_arx(u: F64, y: F64, ts: float, *, na: int, nb: int, nk: int = 1) -> Model: ...
def fit_pem(
    u: F64,
    y: F64,
    ts: float,
    structure: str,
    *,
    na: int = 0,
    nb: int = 1,
    nc: int = 0,
    nd: int = 0,
    nf: int = 0,
    nk: int = 1,
    max_iterations: int = 100,
) -> Model: ...
def simulate(
    *,
    seed: int = 1,
    rig_seed: Optional[int] = None,
    mode: str = "nonlinear",
    noise: bool = True,
    prbs_order: int = 10,
    samples_per_bit: int = 5,
    periods: int = 20,
    level: float = 0.1,
) -> dict[str, Any]: ...
def truth(f_hz: F64, *, rig_seed: Optional[int] = None) -> dict[str, Any]: ...
def rig_config(seed: int) -> str: ...
def run(config: str = "", *, base: "Optional[str | PathLike[str]]" = None) -> Outcome: ...
def excite(kind: str, fs: float, params: str) -> dict[str, Any]: ...
def fit_frf(
    f_hz: F64,
    g: C128,
    ts: float,
    order: int,
    *,
    std: Optional[F64] = None,
    band: Optional[Tuple[float, float]] = None,
    max_unstable_poles: Optional[int] = None,
    feedthrough: bool = False,
    max_iterations: int = 100,
) -> Model: ...
def fit_ss(
    u: F64,
    y: F64,
    ts: float,
    *,
    order: Optional[int] = None,
    feedthrough: bool = False,
    max_iterations: int = 100,
) -> Model: ...
def frf_local(
    r: F64,
    u: F64,
    y: F64,
    fs: float,
    *,
    method: str = "lpm",
    band: Optional[Tuple[float, float]] = None,
    degree: Optional[int] = None,
    half_width: Optional[int] = None,
    lrm_degrees: Tuple[int, int, int] = (2, 2, 2),
) -> dict[str, Any]: ...
def order_scan(
    u: F64,
    y: F64,
    *,
    na_max: int = 10,
    nb_max: int = 10,
    nk: list[int] = [1],
    validation: Optional[Tuple[F64, F64]] = None,
) -> dict[str, Any]: ...
def twin_plant(*, rig_seed: Optional[int] = None) -> Model: ...
def controller(path: "Optional[str | PathLike[str]]" = None, *, rig_seed: Optional[int] = None) -> Model: ...
def validate(
    model: Model,
    controller: Model,
    r: F64,
    u: F64,
    y: F64,
    fs: float,
    *,
    w: Optional[F64] = None,
    skip: int = 0,
    lags: int = 25,
    windows: int = 20,
) -> dict[str, Any]: ...
def spectra(
    channels: list[F64],
    fs: float,
    *,
    nperseg: Optional[int] = None,
    noverlap: Optional[int] = None,
    window: str = "hann",
    detrend: str = "constant",
    scaling: str = "density",
) -> dict[str, Any]: ...
def n4sid(
    u: F64,
    y: F64,
    ts: float,
    *,
    order: Optional[int] = None,
    max_order: int = 10,
    block_rows: Optional[int] = None,
    feedthrough: bool = False,
    refine: Optional[str] = None,
) -> dict[str, Any]: ...
def ss(a: F64, b: F64, c: F64, d: F64, ts: float) -> Model: ...
def periodic_frf(
    r: F64,
    u: F64,
    y: F64,
    fs: float,
    *,
    period_samples: int,
    skip_periods: int = 1,
    threshold: float = 1e-6,
) -> dict[str, Any]: ...
def machine_experiments(machine: str = "", *, seed: int = 1) -> list[dict[str, Any]]: ...
def frf_mimo(
    experiments: list[dict[str, F64]],
    fs: float,
    *,
    period_samples: int,
    skip_periods: int = 1,
    band: Optional[Tuple[float, float]] = None,
    speed_rpm: float = 0.0,
) -> dict[str, Any]: ...
def bla(
    realisations: list[dict[str, F64]],
    fs: float,
    *,
    period_samples: int,
    skip_periods: int = 1,
    band: Optional[Tuple[float, float]] = None,
    level_pct: Optional[float] = None,
) -> dict[str, Any]: ...
def bla_study(
    levels: dict[float, list[dict[str, F64]]],
    fs: float,
    *,
    period_samples: int,
    skip_periods: int = 1,
    band: Optional[Tuple[float, float]] = None,
) -> dict[str, Any]: ...
def amplitude_study(
    records: list[dict[str, Any]],
    fs: float,
    *,
    period_samples: int,
    skip_periods: int = 1,
    band: Optional[Tuple[float, float]] = None,
    noise: Optional[F64] = None,
) -> dict[str, Any]: ...
