"""The lower-level stages (spectra, n4sid, ss) against independent implementations: scipy's
Welch estimates, the exact Markov parameters of a known system, a naive per-frequency solve."""

import numpy as np
import pytest

import ambid


def test_spectra_equal_scipy_welch_csd_and_coherence():
    signal = pytest.importorskip("scipy.signal")
    rng = np.random.default_rng(7)
    n, fs = 40_000, 2000.0
    x = rng.standard_normal(n)
    y = np.convolve(x, [0.5, 0.3, -0.2], mode="same") + 0.3 * rng.standard_normal(n)
    z = rng.standard_normal(n) + 0.1 * x
    chans = [x, y, z]
    for window, nper, detrend, scaling in (("hann", 1024, "constant", "density"),
                                            ("hamming", 700, "linear", "spectrum")):
        s = ambid.spectra(chans, fs, nperseg=nper, window=window, detrend=detrend, scaling=scaling)
        f, pxx = signal.welch(np.stack(chans), fs=fs, nperseg=nper, window=window,
                              detrend=detrend, scaling=scaling)
        np.testing.assert_allclose(s["f_hz"], f, rtol=1e-14)
        assert s["csd"].shape == (3, 3, len(f)) and s["segments"] == (n - nper // 2) // (nper - nper // 2)
        for i in range(3):
            np.testing.assert_allclose(s["csd"][i, i].real, pxx[i], rtol=1e-10)
            for j in range(3):
                # scipy's csd(a, b) is E[conj(A) B]: ambid's csd[i, j] is the same convention
                _, pij = signal.csd(chans[i], chans[j], fs=fs, nperseg=nper, window=window,
                                    detrend=detrend, scaling=scaling)
                scale = np.sqrt(pxx[i] * pxx[j])
                assert np.max(np.abs(s["csd"][i, j] - pij) / scale) < 1e-10, (i, j)
        _, cxy = signal.coherence(x, y, fs=fs, nperseg=nper, window=window, detrend=detrend)
        np.testing.assert_allclose(s["coherence"][0, 1], cxy, atol=1e-10)
        np.testing.assert_allclose(s["coherence"][1, 0], cxy, atol=1e-10)
        np.testing.assert_array_equal(s["coherence"][2, 2], 1.0)


def test_spectra_segment_comes_from_the_record_length():
    # the rule of `ambid frf`: the largest power of two <= N/8, clamped to 64 ... 8192
    rng = np.random.default_rng(1)
    for n, nper in ((20_000, 2048), (300, 64), (200_000, 8192)):
        s = ambid.spectra([rng.standard_normal(n)], 1000.0)
        assert len(s["f_hz"]) == nper // 2 + 1, n
        assert s["segments"] == (n - nper // 2) // (nper - nper // 2), n


def test_spectra_refuse_bad_settings():
    x = np.random.default_rng(0).standard_normal(1000)
    with pytest.raises(ambid.UsageError, match="detrend"):
        ambid.spectra([x, x], 100.0, nperseg=128, detrend="quadratic")
    with pytest.raises(ambid.UsageError, match="window"):
        ambid.spectra([x], 100.0, nperseg=128, window="kaiser-bessel")
    with pytest.raises(ambid.InputError, match=r"channels\[1\]"):
        ambid.spectra([x, x.astype(np.float32)], 100.0, nperseg=128)
    with pytest.raises(ambid.AmbidError):
        ambid.spectra([x, x[:999]], 100.0, nperseg=128)
    with pytest.raises(ambid.InputError, match="empty"):
        ambid.spectra([], 100.0)


def random_system(rng, n, m, p, unstable=False):
    """A random discrete system with poles at known radii (one outside the circle if asked)."""
    r = rng.uniform(0.5, 0.95, n)
    if unstable:
        r[0] = 1.05
    a = np.diag(r * np.sign(rng.standard_normal(n)))
    q, _ = np.linalg.qr(rng.standard_normal((n, n)))
    a = q @ a @ q.T
    return a, rng.standard_normal((n, m)), rng.standard_normal((p, n)), np.zeros((p, m))


def markov(a, b, c, k):
    out, x = [], b
    for _ in range(k):
        out.append(c @ x)
        x = a @ x
    return np.array(out)


def simulate(a, b, c, u):
    x = np.zeros(a.shape[0])
    y = np.empty((u.shape[0], c.shape[0]))
    for t in range(u.shape[0]):
        y[t] = c @ x
        x = a @ x + b @ u[t]
    return y


def test_n4sid_recovers_a_noise_free_two_by_two_system():
    rng = np.random.default_rng(3)
    a, b, c, d = random_system(rng, 4, 2, 2)
    u = rng.standard_normal((3000, 2))
    y = simulate(a, b, c, u)
    out = ambid.n4sid(u, y, 1e-3, order=4, block_rows=8)
    m = out["model"]
    assert out["order"] == 4 and out["block_rows"] == 8 and m.order == 4
    assert m.a.shape == (4, 4) and m.b.shape == (4, 2) and m.c.shape == (2, 4)
    truth = markov(a, b, c, 20)
    est = markov(m.a, m.b, m.c, 20)
    assert np.max(np.abs(est - truth)) <= 1e-8 * np.max(np.abs(truth))
    # the fifth singular value is the numerical zero of an order-4 system
    sv = out["singular_values"]
    assert sv[4] < 1e-8 * sv[0]
    np.testing.assert_allclose(np.sort(np.abs(m.poles())), np.sort(np.abs(np.linalg.eigvals(a))),
                               rtol=1e-8)


def test_n4sid_one_channel_accepts_1d_and_refines():
    rng = np.random.default_rng(5)
    a, b, c, _ = random_system(rng, 2, 1, 1)
    u = rng.standard_normal(4000)
    y = simulate(a, b, c, u[:, None])[:, 0] + 0.01 * rng.standard_normal(4000)
    plain = ambid.n4sid(u, y, 1.0, order=2)
    refined = ambid.n4sid(u, y, 1.0, order=2, refine="simulation")
    f = np.linspace(0.01, 0.45, 30)
    z = np.exp(2j * np.pi * f)
    h_true = np.array([(c @ np.linalg.solve(zk * np.eye(2) - a, b))[0, 0] for zk in z])
    for out in (plain, refined):
        h = out["model"].freq_response(f)[:, 0, 0]
        assert np.median(np.abs(h - h_true) / np.abs(h_true)) < 0.01
    with pytest.raises(ambid.UsageError, match="refine"):
        ambid.n4sid(u, y, 1.0, order=2, refine="both")


def test_ss_model_frequency_response_equals_a_naive_solve_and_keeps_unstable_poles():
    rng = np.random.default_rng(11)
    a, b, c, d = random_system(rng, 5, 2, 3, unstable=True)
    d = rng.standard_normal((3, 2))
    m = ambid.ss(a, b, c, d, 5e-5)
    f = np.linspace(10.0, 9000.0, 57)
    h = m.freq_response(f)
    for k, fk in enumerate(f):
        z = np.exp(2j * np.pi * fk * 5e-5)
        ref = c @ np.linalg.solve(z * np.eye(5) - a, b) + d
        assert np.max(np.abs(h[k] - ref)) <= 1e-11 * np.max(np.abs(ref))
    assert np.sum(np.abs(m.poles()) > 1.0) == 1
    with pytest.raises(ambid.InputError, match="B: expected 5×2, got 4×2"):
        ambid.ss(a, b[:4], c, d, 5e-5)
    with pytest.raises(ambid.InputError, match="2-D"):
        ambid.ss(a, b[:, 0], c, d, 5e-5)
    with pytest.raises(ambid.InputError, match="non-finite|NaN|finite"):
        ambid.ss(np.full((5, 5), np.nan), b, c, d, 5e-5)


def naive_periodic_frf(r, u, y, n, skip):
    """Period-averaged closed-loop FRF with the standard deviations of the means, numpy only."""
    p = len(r) // n - skip
    x = np.stack([r, u, y])[:, skip * n:(skip + p) * n].reshape(3, p, n)
    sp = np.fft.rfft(x, axis=2)
    m = sp.mean(axis=1)
    dev = sp - m[:, None, :]
    amp = np.abs(m[0])
    lines = np.nonzero(amp > 1e-6 * amp[1:].max())[0]
    lines = lines[lines > 0]
    m, dev = m[:, lines], dev[:, :, lines]
    cov = np.einsum("ipk,jpk->ijk", dev, dev.conj()) / (p - 1) / p

    def ratio(a, b, ia, ib):
        h = a / b
        var = np.abs(h) ** 2 * (cov[ia, ia].real / np.abs(a) ** 2 + cov[ib, ib].real / np.abs(b) ** 2
                                - 2 * (cov[ia, ib] / (a * b.conj())).real)
        return h, np.sqrt(np.maximum(var, 0.0))

    return lines, ratio(m[2], m[0], 2, 0), ratio(m[1], m[0], 1, 0), ratio(m[2], m[1], 2, 1)


def test_periodic_frf_equals_a_naive_numpy_oracle_and_the_exact_plant():
    rec = ambid.simulate(seed=1, mode="linear")
    n, fs = rec["period_samples"], rec["fs"]
    out = ambid.periodic_frf(rec["r"], rec["u"], rec["y"], fs, period_samples=n, skip_periods=1)
    lines, t_ry, s, plant = naive_periodic_frf(rec["r"], rec["u"], rec["y"], n, 1)
    np.testing.assert_allclose(out["f_hz"], lines * fs / n, rtol=1e-14)
    for key, (h, sd) in (("t_ry", t_ry), ("s", s), ("plant", plant)):
        # the two implementations sum in different orders (ambid averages periods in time
        # before one FFT); the round-off, relative to lines 1e-3 below the peak, stays far
        # below each line's own standard deviation
        assert np.max(np.abs(out[key] - h) / sd) < 1e-7, key
        assert np.max(np.abs(out[key] - h)) < 1e-8 * np.max(np.abs(h)), key
        np.testing.assert_allclose(out[key + "_std"], sd, rtol=1e-6, atol=1e-12 * np.max(sd))
    # the exact plant lies within a few of the stated standard deviations on most lines
    p_true = ambid.truth(out["f_hz"])["plant"]
    z = np.abs(out["plant"] - p_true) / out["plant_std"]
    assert np.median(z) < 2.0
    with pytest.raises(ambid.AmbidError):
        ambid.periodic_frf(rec["r"], rec["u"], rec["y"][:-1], fs, period_samples=n)
