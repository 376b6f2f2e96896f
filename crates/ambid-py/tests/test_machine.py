"""The whole rotor from Python: the 4-axis twin's experiments and the MIMO closed-loop FRF,
against the twin's exact 4x4 plant and against each other (the FRF of the returned records
equals the acquisition's own FRF)."""

import numpy as np
import pytest

import ambid

# one speed, linear physics, a short orthogonal PRBS design (4 experiments)
QUIET = """
speeds_rpm = [12000.0]
mode = "linear"
noise = false
design = "orthogonal"
periods = 6
"""
NOISY = QUIET.replace("noise = false", "noise = true")


def rel_plant_error(p_hat, p_true):
    """Median over lines of ||P_hat - P||_2 / ||P||_2 (the issue's plant-error measure)."""
    e = [np.linalg.norm(a - b, 2) / np.linalg.norm(b, 2) for a, b in zip(p_hat, p_true)]
    return float(np.median(e))


@pytest.fixture(scope="module")
def quiet():
    return ambid.machine_experiments(QUIET, seed=3)


def test_noise_free_machine_frf_is_the_exact_plant(quiet):
    (s,) = quiet
    assert s["speed_rpm"] == 12000.0 and s["axes"] == ["xa", "xb", "ya", "yb"]
    f = s["f_hz"]
    assert s["plant"].shape == (len(f), 4, 4) and s["plant_std"].shape == (len(f), 4, 4)
    assert len(s["experiments"]) == 4
    for e in s["experiments"]:
        assert e["r"].shape == e["u"].shape == e["y"].shape and e["r"].shape[1] == 4
    p_true = s["plant_true"].freq_response(f)
    assert rel_plant_error(s["plant"], p_true) < 1e-6
    # the exact plant is unstable (the magnets' negative stiffness), as the identified one
    assert np.sum(np.abs(s["plant_true"].poles()) > 1.0) >= 4
    # S = (I + C P)^-1 with the twin's controller
    c = s["controller"].freq_response(f)
    s_true = np.linalg.inv(np.eye(4)[None] + c @ p_true)
    assert np.median(np.abs(s["s"] - s_true)) < 1e-6 * np.median(np.abs(s_true))


def test_frf_mimo_of_the_returned_records_equals_the_acquisition(quiet):
    (s,) = quiet
    exps = [{k: np.ascontiguousarray(e[k]) for k in ("r", "u", "y")} for e in s["experiments"]]
    out = ambid.frf_mimo(exps, s["fs"], period_samples=s["period_samples"], skip_periods=1)
    np.testing.assert_array_equal(out["f_hz"], s["f_hz"])
    np.testing.assert_array_equal(out["plant"], s["plant"])
    np.testing.assert_array_equal(out["t_ry"], s["t_ry"])


def test_noisy_machine_frf_is_within_its_own_std_of_the_truth():
    (s,) = ambid.machine_experiments(NOISY, seed=5)
    f = s["f_hz"]
    p_true = s["plant_true"].freq_response(f)
    band = (f >= 10.0) & (f <= 1000.0)
    z = np.abs(s["plant"] - p_true)[band] / s["plant_std"][band]
    # |error| / std of a complex Gaussian estimate: median sqrt(ln 2) = 0.83
    assert 0.5 < np.median(z) < 1.3
    assert rel_plant_error(s["plant"][band], p_true[band]) < 0.05


def test_machine_bad_input_is_typed(quiet):
    with pytest.raises(ambid.UsageError, match="axes"):
        ambid.machine_experiments("axes = 2")
    with pytest.raises(ambid.UsageError, match="unknown field|spedds"):
        ambid.machine_experiments("spedds_rpm = [0.0]")
    (s,) = quiet
    e = s["experiments"][0]
    good = {k: np.ascontiguousarray(e[k]) for k in ("r", "u", "y")}
    with pytest.raises(ambid.InputError, match="columns"):
        ambid.frf_mimo([dict(good, y=good["y"][:, :3].copy())], s["fs"], period_samples=s["period_samples"])
    with pytest.raises(ambid.InputError, match="no \"u\""):
        ambid.frf_mimo([{"r": good["r"], "y": good["y"]}], s["fs"], period_samples=s["period_samples"])
    with pytest.raises(ambid.UsageError, match="speed_rpm"):
        ambid.frf_mimo([good], s["fs"], period_samples=s["period_samples"], speed_rpm=-1.0)
    bad = dict(good, y=good["y"].copy())
    bad["y"][10, 2] = np.nan
    with pytest.raises(ambid.AmbidError):
        ambid.frf_mimo([bad] * 4, s["fs"], period_samples=s["period_samples"])
