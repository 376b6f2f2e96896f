"""The Python package against independent truth and against the CLI (issue 22's parity bar).

Parity: every number the Python API returns equals the CLI's output from the same checkout to
1e-12 relative (the CLI writes 18 significant digits, so its files round-trip exactly), on the
twin's seed experiment and on a real data set (DaISy dryer). Independent truth: the twin's
exact linearised plant, the DaISy README's numpy ARX reference, and python-control evaluating
the exported model.
"""

import json
import os

import numpy as np
import pytest

import ambid
import ambid.batch as batch
from conftest import skip_visibly

RTOL = 1e-12


def rel(a, b):
    a, b = np.asarray(a), np.asarray(b)
    return float(np.max(np.abs(a - b) / np.maximum(np.abs(b), 1e-300)))


def read_csv(path):
    return np.genfromtxt(path, delimiter=",", names=True)


@pytest.fixture(scope="module")
def seed_experiment(cli, tmp_path_factory):
    d = tmp_path_factory.mktemp("sim")
    cli("simulate", "--seed", 1, "--out", d / "sim")
    return d, read_csv(d / "sim" / "data.csv")


def test_simulate_equals_the_cli_record(seed_experiment):
    _, data = seed_experiment
    rec = ambid.simulate(seed=1)
    assert rec["fs"] == 20000.0 and rec["period_samples"] == 5115
    for k in ("t", "r", "u", "i", "y"):
        assert rec[k].dtype == np.float64 and rec[k].shape == data[k].shape
        np.testing.assert_array_equal(rec[k], data[k])


def test_frf_equals_the_cli_and_is_near_the_exact_plant(cli, seed_experiment):
    d, data = seed_experiment
    cli("frf", d / "sim" / "data.csv", "--period-samples", 5115, "--skip-periods", 1, "--out", d / "frf.csv")
    ref = read_csv(d / "frf.csv")
    col = lambda k: np.ascontiguousarray(data[k])
    f = ambid.frf(col("r"), col("u"), col("y"), 20000.0, period_samples=5115, skip_periods=1)
    np.testing.assert_array_equal(f["f_hz"], ref["f_hz"])
    for py_key, cli_key in (("plant", "plant"), ("t_ry", "t_ry"), ("s", "t_ru"), ("controller", "controller")):
        assert rel(f[py_key], ref[cli_key + "_re"] + 1j * ref[cli_key + "_im"]) <= RTOL, py_key
        assert rel(f[py_key + "_std"], ref[cli_key + "_std"]) <= RTOL, py_key
    assert rel(f["coh_ry"], ref["coh_ry"]) <= RTOL
    assert rel(f["coh_ru"], ref["coh_ru"]) <= RTOL
    # independent truth: the twin's exact linearised plant (nonlinear record at 10 % of i_sat,
    # sensor noise): the median error over 10-1000 Hz is a few per cent
    t = ambid.truth(f["f_hz"])
    band = (f["f_hz"] >= 10) & (f["f_hz"] <= 1000)
    err = np.median(np.abs(f["plant"][band] - t["plant"][band]) / np.abs(t["plant"][band]))
    assert err < 0.05, err
    # and the exact loop identity S = 1 / (1 + P C) of the truth itself
    assert rel(t["s"], 1.0 / (1.0 + t["plant"] * t["controller"])) < 1e-9


def test_frf_finds_the_period_as_the_cli_does(cli, seed_experiment):
    # no period given: the period of r is found (5115), as `ambid frf` without options finds it
    d, data = seed_experiment
    cli("frf", d / "sim" / "data.csv", "--out", d / "frf_found.csv")
    ref = read_csv(d / "frf_found.csv")
    col = lambda k: np.ascontiguousarray(data[k])
    f = ambid.frf(col("r"), col("u"), col("y"), 20000.0)
    assert f["period_samples"] == 5115
    np.testing.assert_array_equal(f["f_hz"], ref["f_hz"])
    assert rel(f["plant"], ref["plant_re"] + 1j * ref["plant_im"]) <= RTOL
    given = ambid.frf(col("r"), col("u"), col("y"), 20000.0, period_samples=5115)
    np.testing.assert_array_equal(f["plant"], given["plant"])
    # a Welch option keeps Welch
    w = ambid.frf(col("r"), col("u"), col("y"), 20000.0, nperseg=4096)
    assert w["period_samples"] is None and len(w["f_hz"]) != len(f["f_hz"])


def test_arx_on_real_data_equals_the_cli_and_the_reference(cli, real_data, tmp_path):
    path = os.path.join(real_data, "daisy-dryer", "dryer.dat")
    cli("fit", path, "--fs", 12.5, "--input", "col1", "--output", "col2",
        "--structure", "arx", "--na", 2, "--nb", 2, "--nk", 3, "--out", tmp_path / "arx.json")
    ref = json.loads((tmp_path / "arx.json").read_text())
    raw = np.loadtxt(path)
    u = np.ascontiguousarray(raw[:, 0] - ref["meta"]["detrend"]["u_mean"])
    y = np.ascontiguousarray(raw[:, 1] - ref["meta"]["detrend"]["y_mean"])
    m = ambid.fit_arx(u, y, 0.08, na=2, nb=2, nk=3)
    assert rel(m.params, ref["meta"]["params"]) <= RTOL
    assert rel(m.params_std, ref["meta"]["std"]) <= RTOL
    assert rel(m.loss, ref["meta"]["loss"]) <= RTOL
    assert rel(m.polynomials["a"], ref["a"]) <= RTOL
    assert rel(m.polynomials["b"], ref["b"]) <= RTOL
    # independent truth: the data set README's numpy ARX(2,2,3) on the first 500 samples with
    # the first half's means removed
    h = raw[:500]
    m2 = ambid.fit_arx(np.ascontiguousarray(h[:, 0] - h[:, 0].mean()),
                       np.ascontiguousarray(h[:, 1] - h[:, 1].mean()), 0.08, na=2, nb=2, nk=3)
    np.testing.assert_allclose(m2.params, [-1.2765387524, 0.3967106056, 0.0651903038, 0.0451791996], atol=2e-10)


def test_model_frequency_response_matches_python_control():
    control = pytest.importorskip("control")
    rng = np.random.default_rng(3)
    u = rng.standard_normal(2000)
    y = np.zeros_like(u)
    for k in range(2, len(u)):
        y[k] = 1.5 * y[k - 1] - 0.7 * y[k - 2] + 0.4 * u[k - 1] + 0.2 * u[k - 2] + 1e-3 * rng.standard_normal()
    m = ambid.fit_arx(u, y, 1e-3, na=2, nb=2)
    np.testing.assert_allclose(m.params, [-1.5, 0.7, 0.4, 0.2], atol=5e-3)
    f = np.linspace(1.0, 400.0, 50)
    g = m.freq_response(f)[:, 0, 0]
    sys = m.to_control()
    resp = control.frequency_response(sys, 2 * np.pi * f)
    g_ctl = np.squeeze(resp.magnitude) * np.exp(1j * np.squeeze(resp.phase))
    assert rel(g, g_ctl) < 1e-10
    # and the textbook transfer function of the estimate (a naive oracle)
    z = np.exp(2j * np.pi * f * 1e-3)
    a1, a2, b1, b2 = m.params
    g_tf = (b1 / z + b2 / z**2) / (1 + a1 / z + a2 / z**2)
    assert rel(g, g_tf) < 1e-10


def test_model_save_writes_exports_that_other_readers_load(tmp_path):
    """The .npz read by numpy, the .mat by scipy.io and the .json by json give back the model;
    the MATLAB script builds an idpoly with the same coefficients."""
    sio = pytest.importorskip("scipy.io")
    rng = np.random.default_rng(4)
    u = rng.standard_normal(1500)
    y = np.zeros_like(u)
    for k in range(2, len(u)):
        y[k] = 1.2 * y[k - 1] - 0.5 * y[k - 2] + 0.3 * u[k - 1] + 1e-3 * rng.standard_normal()
    m = ambid.fit_arx(u, y, 1e-3, na=2, nb=1)
    paths = m.save(tmp_path / "arx.json")
    assert sorted(os.path.basename(p) for p in paths) == ["arx.json", "arx.m", "arx.mat", "arx.npz"]
    a = m.polynomials["a"]
    np.testing.assert_allclose(a, [1.0, *m.params[:2]], rtol=1e-15)
    npz = np.load(tmp_path / "arx.npz")
    mat = sio.loadmat(tmp_path / "arx.mat")
    for store in (npz, mat):
        keys = [k for k in store.keys() if not k.startswith("__")]
        akey = next(k for k in keys if k.lower() in ("a", "a_poly", "poly_a"))
        np.testing.assert_allclose(np.ravel(store[akey]), a, rtol=1e-15)
    assert "idpoly" in (tmp_path / "arx.m").read_text()
    assert json.loads((tmp_path / "arx.json").read_text())["kind"] == "polynomial"
    with pytest.raises(ambid.OutputError):
        m.save(tmp_path / "arx.json")  # exists, no force
    assert m.save(tmp_path / "arx.json", force=True)
    with pytest.raises(ambid.UsageError, match=".json"):
        m.save(tmp_path / "arx.txt")


def test_oe_recovers_a_known_system():
    rng = np.random.default_rng(7)
    u = rng.standard_normal(3000)
    x = np.zeros_like(u)
    for k in range(1, len(u)):
        x[k] = 0.8 * x[k - 1] + 0.5 * u[k - 1]
    y = x + 0.01 * rng.standard_normal(len(u))
    m = ambid.fit_pem(u, y, 1.0, "oe", nb=1, nf=1, nk=1)
    np.testing.assert_allclose(m.polynomials["f"], [1.0, -0.8], atol=5e-3)
    np.testing.assert_allclose(m.polynomials["b"][1], 0.5, atol=5e-3)


def test_workflow_summary_equals_the_cli(cli, tmp_path):
    cfg = 'seed = 3\nsteps = ["frf", "order", "models", "pole_zero", "validation", "iso"]\n[twin]\nmode = "linear"\n'
    (tmp_path / "wf.toml").write_text(cfg)
    cli("run", tmp_path / "wf.toml", "--out", tmp_path / "cli", "-q")
    ref = json.loads((tmp_path / "cli" / "summary.json").read_text())
    out = ambid.run(str(tmp_path / "wf.toml"))
    got = out.summary
    ref.pop("timing", None)
    got.pop("timing", None)
    assert got == ref  # exact: the same code on the same seeds
    assert "<html" in out.html().lower()
    written = out.write(tmp_path / "py")
    assert (tmp_path / "py" / "summary.json").exists() and written
    models = out.models()
    chosen = ref["models"]["chosen"].lower().replace(" ", "")
    cli_model = json.loads((tmp_path / "cli" / "models" / f"{chosen}.json").read_text())
    assert rel(np.array(models[chosen]["a"]), np.array(cli_model["a"])) <= RTOL
    with pytest.raises(ambid.OutputError):
        out.write(tmp_path / "py")  # exists, no force


# ---- bad input: typed exceptions, never a crash ------------------------------------------

def test_bad_arrays_raise_input_error():
    x = np.zeros(1000)
    with pytest.raises(ambid.InputError, match="float64"):
        ambid.frf(x.astype(np.float32), x, x, 1000.0)
    with pytest.raises(ambid.InputError, match="1-D"):
        ambid.frf(np.zeros((1000, 2)), x, x, 1000.0)
    with pytest.raises(ambid.InputError, match="contiguous"):
        ambid.frf(np.zeros(2000)[::2], x, x, 1000.0)
    with pytest.raises(ambid.InputError, match="numpy array"):
        ambid.frf([0.0] * 1000, x, x, 1000.0)
    with pytest.raises(ambid.InputError, match="recorded together"):
        ambid.frf(x, x[:900], x, 1000.0)
    y = np.random.default_rng(0).standard_normal(1000)
    y[10] = np.nan
    with pytest.raises(ambid.InputError, match="non-finite"):
        ambid.fit_arx(np.ones(1000), y, 1.0, na=1, nb=1)
    with pytest.raises(ambid.AmbidError):
        ambid.frf(x[:10], x[:10], x[:10], 1000.0)  # too short


def test_unknown_options_raise_usage_error():
    with pytest.raises(ambid.UsageError, match="mode"):
        ambid.simulate(mode="quantum")
    with pytest.raises(ambid.UsageError, match="structure"):
        ambid.fit_pem(np.ones(100), np.ones(100), 1.0, "narx")
    with pytest.raises(ambid.UsageError):
        ambid.frf(np.ones(100), np.ones(100), np.ones(100), -5.0)
    with pytest.raises(ambid.UsageError):
        ambid.run("steps = [\"no-such-step\"]\n")
    with pytest.raises(TypeError):
        ambid.frf(np.ones(100), np.ones(100), np.ones(100), 1.0, no_such_option=1)
    for cls, builtin in ((ambid.UsageError, ValueError), (ambid.InputError, ValueError),
                         (ambid.ComputationError, RuntimeError), (ambid.OutputError, OSError)):
        assert issubclass(cls, ambid.AmbidError) and issubclass(cls, builtin)
    with pytest.raises(ValueError):  # caught as the built-in a Python user expects
        ambid.simulate(mode="quantum")


# ---- batch ----------------------------------------------------------------------------------

FAST = ["frf", "order", "models", "pole_zero", "validation", "iso"]


def _records():
    recs = [batch.Record.twin(f"rig{s}", seed=s, rig_seed=s, mode="linear", steps=FAST) for s in (1, 2)]
    recs.append(batch.Record.twin("nominal", seed=4, mode="linear", steps=FAST))
    recs.append(batch.Record("missing-file", 'source = "files"\n[data]\nidentification = "nope.csv"\n'))
    x = np.zeros(5000)
    recs.append(batch.Record.from_arrays("no-excitation", r=x, u=x, y=x, fs=20000.0))
    return recs


def _same(a, b):
    assert [r["record"] for r in a.rows] == [r["record"] for r in b.rows]
    for ra, rb in zip(a.rows, b.rows):
        assert ra == rb
    assert a.models == b.models


@pytest.fixture(scope="module")
def serial():
    return batch.identify(_records())


def test_batch_rows_report_failures_and_finish_the_rest(serial):
    rows = {r["record"]: r for r in serial.rows}
    for ok in ("rig1", "rig2", "nominal"):
        assert rows[ok]["status"] == "ok", rows[ok]
        assert rows[ok]["unstable_poles"] == 1
        assert rows[ok]["iso_zone"] in ("A", "B", "C", "D")
        assert rows[ok]["error_vs_truth_pct"] < 10
    assert rows["missing-file"]["status"] == "error"
    assert rows["missing-file"]["error_type"] == "InputError"
    assert "nope.csv" in rows["missing-file"]["error"]
    assert rows["no-excitation"]["status"] == "error"
    # every row matches a single run of its record
    single = ambid.run(_records()[2].config).summary
    assert rows["nominal"]["fit_y_pct"] == single["validation"]["fit_y_pct"]


def test_batch_drift_is_zero_against_itself_and_measured_otherwise(serial):
    chosen = serial.rows[2]["chosen_model"].lower().replace(" ", "")
    ref = serial.models["nominal"][chosen]
    res = batch.identify([_records()[0], _records()[2]], reference=ref)
    assert res.rows[1]["drift"] == 0.0
    assert res.rows[0]["drift"] > 0.01  # another rig's plant
    # an independent oracle of the drift's definition on two known first-order models: the
    # relative difference of b/(z - a) for a = 0.5 vs 0.6 at one frequency
    m = lambda a: {"kind": "state_space", "ts": 1.0, "a": [[a]], "b": [[1.0]], "c": [[1.0]], "d": [[0.0]]}
    z = np.exp(2j * np.pi * 0.1)
    expect = abs(1 / (z - 0.6) - 1 / (z - 0.5)) / abs(1 / (z - 0.5))
    assert abs(batch.drift(m(0.6), m(0.5), (0.1, 0.1), lines=1) - expect) < 1e-12


def test_batch_process_pool_equals_serial(serial):
    _same(batch.identify(_records(), engine="processes", workers=2), serial)


def test_batch_on_dask_equals_serial(serial):
    try:
        from dask.distributed import Client, LocalCluster
    except ImportError:
        skip_visibly("dask.distributed is not installed: the Dask batch check was not run")
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as lc, Client(lc) as c:
        _same(batch.identify(_records(), engine="dask", client=c), serial)


# ---- excitation ------------------------------------------------------------------------------

def test_prbs_equals_the_cli_and_is_an_m_sequence(cli, tmp_path):
    cli("excite", "prbs", "--level", 10, "--i-sat", 2, "--out", tmp_path / "prbs.csv")
    ref = read_csv(tmp_path / "prbs.csv")
    e = ambid.excite("prbs", 20000.0, amplitude=0.2)
    np.testing.assert_array_equal(e["values"], ref["r"])
    assert e["period_samples"] == 5115 and e["periods"] == 20
    rep = e["report"]
    assert rep["crest_factor"] == 1.0 and abs(rep["resolution_hz"] - 20000.0 / 5115) < 1e-12
    # independent: an m-sequence of order 10 has 1023 bits per period, 512 of one sign and
    # 511 of the other, and a two-valued circular autocorrelation (1023 at lag 0, -1 elsewhere)
    bits = np.sign(e["values"][: 5115 : 5])
    assert len(bits) == 1023 and sorted([np.sum(bits > 0), np.sum(bits < 0)]) == [511, 512]
    ac = np.array([np.dot(bits, np.roll(bits, k)) for k in range(1023)])
    assert ac[0] == 1023 and np.all(ac[1:] == -1)


def test_excitation_options_are_checked():
    with pytest.raises(ambid.UsageError, match="unknown option `ordr`"):
        ambid.excite("prbs", 20000.0, ordr=9)
    with pytest.raises(ambid.UsageError, match="unknown excitation"):
        ambid.excite("square", 20000.0)
    with pytest.raises(ambid.UsageError, match="missing field"):
        ambid.excite("chirp", 20000.0)
    with pytest.raises(ambid.AmbidError):
        ambid.excite("prbs", 20000.0, order=1)


# ---- state-space fits -----------------------------------------------------------------------

def _response(a, b, c, f, ts):
    """C (zI - A)^{-1} B at f (numpy, the oracle): shape (L, ny, nu)."""
    z = np.exp(2j * np.pi * f * ts)
    return np.array([c @ np.linalg.solve(zk * np.eye(a.shape[0]) - a, b) for zk in z])


def test_fit_frf_recovers_an_unstable_two_by_two_plant():
    r, w = 0.995, 0.05
    a = np.array([[1.01, 0, 0], [0, r * np.cos(w), r * np.sin(w)], [0, -r * np.sin(w), r * np.cos(w)]])
    b = np.array([[1.0, 0.5], [0.0, 1.0], [1.0, -0.3]])
    c = np.array([[1.0, 0.2, 0.0], [0.4, 0.0, 1.0]])
    f = np.arange(1, 81) * 2.0
    g = _response(a, b, c, f, 1e-3)
    m = ambid.fit_frf(f, np.ascontiguousarray(g), 1e-3, 3)
    assert rel(m.freq_response(f), g) < 1e-8
    assert np.sum(np.abs(m.poles()) >= 1.0) == 1
    # the 1x1 case of the same function
    m1 = ambid.fit_frf(f, np.ascontiguousarray(g[:, 0, 0]), 1e-3, 3)
    assert rel(m1.freq_response(f)[:, 0, 0], g[:, 0, 0]) < 1e-8
    with pytest.raises(ambid.InputError, match="lines"):
        ambid.fit_frf(f[:10], np.ascontiguousarray(g), 1e-3, 3)
    with pytest.raises(ambid.InputError, match="complex128"):
        ambid.fit_frf(f, np.abs(g), 1e-3, 3)


def test_fit_ss_recovers_a_noise_free_system():
    rng = np.random.default_rng(11)
    a = np.array([[1.6, -0.8], [1.0, 0.0]])
    b = np.array([[1.0], [0.0]])
    c = np.array([[0.3, 0.2]])
    u = rng.standard_normal(3000)
    x = np.zeros(2)
    y = np.zeros_like(u)
    for k in range(len(u)):
        y[k] = (c @ x)[0]
        x = a @ x + b[:, 0] * u[k]
    m = ambid.fit_ss(u, y, 1.0, order=2)
    f = np.linspace(0.01, 0.45, 40)
    assert rel(m.freq_response(f), _response(a, b, c, f, 1.0)) < 1e-6


def test_machine_workflow_equals_the_cli(cli, tmp_path):
    """The whole machine (4-axis twin, two speeds, the measured 4x4 FRF, Campbell, ISO per
    axis) through `ambid.run` with a `[machine]` section: the MIMO entry point as it stands."""
    cfg = 'seed = 7\n[machine]\nspeeds_rpm = [0, 30000]\nmode = "linear"\nprbs_order = 8\nperiods = 4\n'
    (tmp_path / "wf.toml").write_text(cfg)
    cli("run", tmp_path / "wf.toml", "--out", tmp_path / "cli", "-q")
    ref = json.loads((tmp_path / "cli" / "summary.json").read_text())
    got = ambid.run(cfg).summary
    ref.pop("timing", None)
    got.pop("timing", None)
    assert got == ref


@pytest.mark.parametrize("method,args", [("lpm", dict(degree=2, half_width=3)), ("lrm", dict(lrm_degrees=(2, 2, 2)))])
def test_local_methods_equal_the_cli(cli, seed_experiment, tmp_path, method, args):
    _, data = seed_experiment
    n = 20000  # not a whole number of periods: the non-periodic local method
    cols = {k: np.ascontiguousarray(data[k][:n]) for k in ("t", "r", "u", "y")}
    np.savetxt(tmp_path / "rec.csv", np.column_stack([cols[k] for k in ("t", "r", "u", "y")]),
               fmt="%.17e", delimiter=",", header="t,r,u,y", comments="")
    flags = ["--method", method, "--band", "10:1000"]
    if method == "lpm":
        flags += ["--lpm-degree", 2, "--lpm-half-width", 3]
    else:
        flags += ["--lrm-degrees", "2,2,2"]
    cli("frf", tmp_path / "rec.csv", *flags, "--out", tmp_path / "local.csv")
    ref = read_csv(tmp_path / "local.csv")
    f = ambid.frf_local(cols["r"], cols["u"], cols["y"], 20000.0, method=method, band=(10.0, 1000.0), **args)
    np.testing.assert_array_equal(f["f_hz"], ref["f_hz"])
    for py_key, cli_key in (("plant", "plant"), ("t_ry", "t_ry"), ("s", "t_ru")):
        assert rel(f[py_key], ref[cli_key + "_re"] + 1j * ref[cli_key + "_im"]) <= RTOL, py_key
        assert rel(f[py_key + "_std"], ref[cli_key + "_std"]) <= RTOL, py_key
    # and consistent with the exact plant within its own stated uncertainty (median over the
    # band of |P - P_true| / std; the nonlinear twin adds a small bias)
    t = ambid.truth(f["f_hz"])
    z = np.median(np.abs(f["plant"] - t["plant"]) / f["plant_std"])
    assert z < 3.0, z
    with pytest.raises(ambid.UsageError, match="unknown method"):
        ambid.frf_local(cols["r"], cols["u"], cols["y"], 20000.0, method="spline")


def test_order_scan_on_real_data_equals_the_cli_and_the_direct_fit(cli, real_data, tmp_path):
    path = os.path.join(real_data, "daisy-dryer", "dryer.dat")
    cli("order", path, "--fs", 12.5, "--input", "col1", "--output", "col2",
        "--na-max", 4, "--nb-max", 4, "--nk", 3, "--out", tmp_path / "order.csv")
    ref = read_csv(tmp_path / "order.csv")
    raw = np.loadtxt(path)
    u = np.ascontiguousarray(raw[:, 0] - raw[:, 0].mean())
    y = np.ascontiguousarray(raw[:, 1] - raw[:, 1].mean())
    s = ambid.order_scan(u, y, na_max=4, nb_max=4, nk=[3])
    assert len(s["loss"]) == 16
    np.testing.assert_array_equal(s["na"], ref["na"])
    np.testing.assert_array_equal(s["nb"], ref["nb"])
    for k in ("loss", "aic", "bic", "fpe"):
        assert rel(s[k], ref[k]) <= 1e-11, k
    # the scan's ARX(2,2,3) loss against a naive numpy least-squares oracle on the same
    # samples (every model of the scan starts at the common k0)
    k = int(np.flatnonzero((s["na"] == 2) & (s["nb"] == 2))[0])
    k0 = s["k0"]
    t = np.arange(k0, len(y))
    phi = np.column_stack([-y[t - 1], -y[t - 2], u[t - 3], u[t - 4]])
    theta, *_ = np.linalg.lstsq(phi, y[t], rcond=None)
    loss = np.mean((y[t] - phi @ theta) ** 2)
    assert abs(s["loss"][k] - loss) <= 1e-9 * loss
    # its parameters [a1, a2, b1, b2] are the oracle's
    np.testing.assert_allclose(s["params"][k], theta, rtol=1e-8)
    # validation columns on the second half
    h = len(u) // 2
    sv = ambid.order_scan(u[:h].copy(), y[:h].copy(), na_max=3, nb_max=3, nk=[3],
                          validation=(u[h:].copy(), y[h:].copy()))
    assert np.all(np.isfinite(sv["val_fit"])) and sv["best_val"] is not None
    assert 80.0 < sv["val_fit"][sv["best_val"]] < 100.0


def test_validation_of_the_exact_plant_on_a_noise_free_linear_record():
    """Independent truth: on the linear twin without sensor noise, the twin's exact plant with
    its controller reproduces the recorded loop (fit ~100 %); a plant with a 30 % gain error
    does not; a model whose loop is unstable is refused."""
    rec = ambid.simulate(seed=2, mode="linear", noise=False, periods=4)
    p, c = ambid.twin_plant(), ambid.controller()
    assert p.ts == c.ts == 1 / rec["fs"]
    assert np.sum(np.abs(p.poles()) >= 1.0) == 1  # the unstable plant, never stabilised
    v = ambid.validate(p, c, rec["r"], rec["u"], rec["y"], rec["fs"])
    assert v["fit_y_pct"] > 100 - 1e-9 and v["fit_u_pct"] > 100 - 1e-9, v
    assert np.max(np.abs(v["y_simulated"] - rec["y"])) < 1e-10 * np.max(np.abs(rec["y"]))
    assert np.all(np.abs(v["closed_loop_poles"]) < 1.0)
    # the peak sensitivity against a naive oracle: max |1 / (1 + P C)| on a dense grid
    f = np.geomspace(1.0, 0.49 * rec["fs"], 20000)
    s_abs = np.abs(1.0 / (1.0 + p.freq_response(f)[:, 0, 0] * c.freq_response(f)[:, 0, 0]))
    assert abs(v["peak_sensitivity"] - s_abs.max()) < 2e-3 * s_abs.max()
    # ISO 14839-3's zone limits on the peak sensitivity (3, 4, 5: 9.5, 12, 14 dB)
    peak = s_abs.max()
    assert v["iso_zone"] == ("A" if peak < 3 else "B" if peak < 4 else "C" if peak < 5 else "D")
    # the same plant with 30 % more gain: a clearly worse fit (its loop is still stable)
    worse = ambid.fit_frf(np.linspace(10, 2000, 200), np.ascontiguousarray(1.3 * p.freq_response(np.linspace(10, 2000, 200))[:, 0, 0]), p.ts, p.order, max_unstable_poles=1)
    v2 = ambid.validate(worse, c, rec["r"], rec["u"], rec["y"], rec["fs"])
    assert v2["fit_y_pct"] < v["fit_y_pct"] - 5
    with pytest.raises(ambid.InputError):
        ambid.validate(p, c, rec["r"][:-1].copy(), rec["u"], rec["y"], rec["fs"])
