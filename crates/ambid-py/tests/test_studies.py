"""The BLA and amplitude studies from Python against analytic systems simulated here (a known
FIR plant, open and closed loop, linear or with a cubic term) and against ambid.frf."""

import numpy as np
import pytest

import ambid

N, P, FS = 256, 5, 1000.0
H = np.array([0.0, 0.5, 0.3, -0.1])  # y_k = sum_j h_j u_{k-j}: one-sample delay, stable FIR
# a random-odd-style grid: odd lines, one in four of them left out to detect odd nonlinear
# distortion (the even lines detect even distortion)
BINS = np.array([k for i, k in enumerate(range(1, 100, 2)) if i % 4 != 3])


def multisine(seed, rms):
    rng = np.random.default_rng(seed)
    x = np.zeros(N // 2 + 1, complex)
    x[BINS] = np.exp(2j * np.pi * rng.random(len(BINS)))
    s = np.fft.irfft(x, N)
    return np.tile(s * rms / np.std(s), P)


def fir_response(f):
    z = np.exp(-2j * np.pi * f / FS)
    return sum(h * z ** j for j, h in enumerate(H))


def open_loop(seed, rms, cubic=0.0, noise=1e-3):
    u = multisine(seed, rms)
    x = np.convolve(u, H)[: len(u)]
    y = x + cubic * x ** 3 + noise * np.random.default_rng(1000 + seed).standard_normal(len(u))
    return {"u": u, "y": y}


def closed_loop(seed, rms, c=0.8, noise=1e-3):
    """u = -c y + r, y = H u + v, simulated sample by sample (h_0 = 0: no algebraic loop)."""
    r = multisine(seed, rms)
    v = noise * np.random.default_rng(2000 + seed).standard_normal(len(r))
    u, y = np.zeros(len(r)), np.zeros(len(r))
    for k in range(len(r)):
        y[k] = sum(H[j] * u[k - j] for j in range(1, len(H)) if k - j >= 0) + v[k]
        u[k] = -c * y[k] + r[k]
    return {"r": r, "u": u, "y": y}


def test_bla_of_a_linear_system_is_its_frf_with_no_nonlinear_variance():
    reals = [open_loop(m, 1.0) for m in range(6)]
    out = ambid.bla(reals, FS, period_samples=N, skip_periods=1, band=(1.0, 400.0))
    f = out["f_hz"]
    np.testing.assert_allclose(f, BINS[BINS * FS / N <= 400.0] * FS / N)
    g = fir_response(f)
    z = np.abs(out["g"] - g) / out["g_std"]
    assert np.median(z) < 2.0 and np.max(np.abs(out["g"] - g) / np.abs(g)) < 0.02
    fig = out["figures"]
    assert out["realisations"] == 6 and out["periods"] == P - 1
    # linear: the nonlinear variance is zero within its standard error
    assert abs(fig["nl_rel"]) < 3 * fig["nl_rel_se"] + 1e-12


def test_bla_detects_a_cubic_nonlinearity():
    lin = ambid.bla([open_loop(m, 1.0) for m in range(6)], FS, period_samples=N)["figures"]
    nl = ambid.bla([open_loop(m, 1.0, cubic=0.3) for m in range(6)], FS, period_samples=N)
    assert nl["figures"]["nl_rel"] > 10 * max(lin["nl_rel"], lin["nl_rel_se"])
    assert nl["figures"]["nl_rel"] > 3 * nl["figures"]["nl_rel_se"]
    # odd nonlinearity: the odd detection lines rise above the noise, far more than the even
    assert nl["odd_db"] > nl["even_db"] + 10.0


def test_closed_loop_bla_gives_the_plant_and_the_loop():
    reals = [closed_loop(m, 1.0) for m in range(4)]
    out = ambid.bla(reals, FS, period_samples=N)
    f = out["f_hz"]
    g = fir_response(f)
    assert np.max(np.abs(out["g"] - g) / np.abs(g)) < 0.02
    s_true = 1.0 / (1.0 + 0.8 * g)
    assert np.max(np.abs(out["s"] - s_true) / np.abs(s_true)) < 0.02
    assert np.max(np.abs(out["t_ry"] - g * s_true) / np.abs(g * s_true)) < 0.02


def test_bla_study_rows_equal_the_single_levels_and_recommend_the_cleaner_level():
    levels = {2.0: [open_loop(m, 0.02) for m in range(4)],
              20.0: [open_loop(10 + m, 0.2) for m in range(4)]}
    st = ambid.bla_study(levels, FS, period_samples=N)
    assert [r["level_pct"] for r in st["rows"]] == [2.0, 20.0]
    for row, (pct, reals) in zip(st["rows"], sorted(levels.items())):
        one = ambid.bla(reals, FS, period_samples=N, level_pct=pct)["figures"]
        assert row["noise_rel"] == one["noise_rel"] and row["nl_rel"] == one["nl_rel"]
    # additive noise, linear system: 10x the level, 100x less relative noise variance
    ratio = st["rows"][0]["noise_rel"] / st["rows"][1]["noise_rel"]
    assert 50 < ratio < 200
    assert st["recommended_pct"] == 20.0 and st["reasoning"]


def test_amplitude_study_on_twin_records():
    recs = []
    for k, lvl in enumerate((0.02, 0.08)):
        r = ambid.simulate(seed=10 + k, mode="linear", level=lvl, periods=6)
        recs.append({"level_pct": 100 * lvl, "r": r["r"], "u": r["u"], "y": r["y"], "i": r["i"]})
    out = ambid.amplitude_study(recs, 20000.0, period_samples=5115, band=(10.0, 1000.0))
    rows = out["rows"]
    assert [r["level_pct"] for r in rows] == [2.0, 8.0]
    # 4x the level: the plant's relative variance falls by 16x or more (more: at 2 % some
    # lines are near the noise, where the variance of the ratio grows faster than 1/SNR)
    assert 12 < rows[0]["mean_plant_rel_var"] / rows[1]["mean_plant_rel_var"] < 100
    assert rows[1]["mean_coh_ry"] > rows[0]["mean_coh_ry"]
    # each level's plant is the period-averaged FRF of ambid.frf on the same band
    one = ambid.frf(recs[1]["r"], recs[1]["u"], recs[1]["y"], 20000.0, period_samples=5115,
                    band=(10.0, 1000.0), quality_band=(10.0, 1000.0), screen=False)
    p = out["plants"][1]
    np.testing.assert_array_equal(p["f_hz"], one["f_hz"])
    np.testing.assert_array_equal(p["plant"], one["plant"])
    # and near the exact plant
    truth = ambid.truth(p["f_hz"])["plant"]
    assert np.median(np.abs(p["plant"] - truth) / np.abs(truth)) < 0.05


def test_study_bad_input_is_typed():
    reals = [open_loop(m, 1.0) for m in range(3)]
    with pytest.raises(ambid.InputError, match="no \"y\""):
        ambid.bla([reals[0], {"u": reals[1]["u"]}], FS, period_samples=N)
    with pytest.raises(ambid.AmbidError, match="at least 2 realisations"):
        ambid.bla(reals[:1], FS, period_samples=N)
    with pytest.raises(ambid.UsageError, match="period_samples"):
        ambid.bla(reals, FS, period_samples=1)
    with pytest.raises(ambid.InputError, match="level"):
        ambid.bla_study({"high": reals}, FS, period_samples=N)
    with pytest.raises(ambid.InputError, match="level_pct"):
        ambid.amplitude_study([{"r": reals[0]["u"], "u": reals[0]["u"], "y": reals[0]["y"]}],
                              FS, period_samples=N)
