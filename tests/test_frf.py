"""Nonparametric FRF: robust method and Local Polynomial Method."""

from unittest import mock

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.signal import butter, lfilter, lfiltic

from sknlss._linear import _frf
from sknlss._linear._frf import lpm_frf, lpm_window, robust_frf
from sknlss.signals import multisine

# 4th-order SISO test system (two resonances), as polynomials in q^-1
POLES = np.array([0.9 * np.exp(0.3j), 0.9 * np.exp(-0.3j),
                  0.7 * np.exp(1.2j), 0.7 * np.exp(-1.2j)])
DEN = np.real(np.poly(POLES))
NUM = np.array([0.2, 0.5, -0.3, 0.1, 0.05])


def _true_frf(num, den, frequencies):
    zinv = np.exp(-2j * np.pi * frequencies)
    return np.polyval(num[::-1], zinv) / np.polyval(den[::-1], zinv)


def _periodic_data(n_periods=3, n_realizations=4, period=256, noise=0.0, seed=0):
    u, lines = multisine(period, n_periods=n_periods + 1, n_realizations=n_realizations,
                         lines="odd", band=(0.0, 0.45), random_state=seed)
    y = lfilter(NUM, DEN, u, axis=1)
    rng = np.random.default_rng(seed + 1)
    y = y + noise * rng.standard_normal(y.shape)
    # drop the first period (transient of the filter started at rest)
    u, y = u[:, period:], y[:, period:]
    starts = np.arange(n_realizations + 1) * u.shape[1]
    return u.reshape(-1, 1), y.reshape(-1, 1), starts, lines


def test_robust_frf_noise_free_exact():
    U, Y, starts, lines = _periodic_data(n_periods=2, n_realizations=4)
    est = robust_frf(U, Y, starts, 256)
    np.testing.assert_array_equal(est.frequencies, lines / 256)
    G0 = _true_frf(NUM, DEN, est.frequencies)
    rel = np.max(np.abs(est.frf[:, 0, 0] - G0) / np.abs(G0))
    assert rel < 1e-8
    assert est.frf.shape == (len(lines), 1, 1)
    assert np.max(est.noise_variance) < 1e-20 * np.mean(np.abs(G0) ** 2)
    assert np.max(est.total_variance) < 1e-20 * np.mean(np.abs(G0) ** 2)


def test_robust_frf_variances_match_monte_carlo():
    # noise only (linear system): both variances describe the scatter of the FRF
    U, Y, starts, _ = _periodic_data(n_periods=4, n_realizations=6, noise=0.05)
    est = robust_frf(U, Y, starts, 256)
    G0 = _true_frf(NUM, DEN, est.frequencies)
    err2 = np.abs(est.frf[:, 0, 0] - G0) ** 2
    for var in (est.noise_variance[:, 0, 0], est.total_variance[:, 0, 0]):
        ratio = np.mean(err2) / np.mean(var)
        assert 0.7 < ratio < 1.4


def test_robust_frf_transient_periods_dropped():
    u, _ = multisine(128, n_periods=3, n_realizations=2, random_state=3)
    y = lfilter(NUM, DEN, u, axis=1)  # starts at rest: first period transient
    U, Y, starts = u.reshape(-1, 1), y.reshape(-1, 1), np.array([0, 384, 768])
    with_transient = robust_frf(U, Y, starts, 128)
    dropped = robust_frf(U, Y, starts, 128, n_transient=1)
    G0 = _true_frf(NUM, DEN, dropped.frequencies)
    assert np.max(np.abs(dropped.frf[:, 0, 0] - G0)) < 1e-4
    assert np.max(np.abs(with_transient.frf[:, 0, 0] - G0)) > 1e-3


def test_robust_frf_mimo():
    rng = np.random.default_rng(0)
    period, n_real = 128, 4
    u, lines = multisine(period, n_periods=3, n_realizations=2 * n_real, random_state=1)
    u = u.reshape(n_real, 2, -1)
    # y1 = G11 u1 + G12 u2, y2 = G21 u1
    g11, g12, g21 = ([1.0, 0.4], [1.0, -0.5]), ([0.0, 0.3], [1.0, 0.2]), ([0.5], [1.0, -0.8])
    y1 = lfilter(*g11, u[:, 0], axis=1) + lfilter(*g12, u[:, 1], axis=1)
    y2 = lfilter(*g21, u[:, 0], axis=1)
    U = u.transpose(0, 2, 1)[:, period:].reshape(-1, 2)
    Y = np.stack([y1, y2], axis=2)[:, period:].reshape(-1, 2)
    Y = Y + 1e-12 * rng.standard_normal(Y.shape)
    starts = np.arange(n_real + 1) * 2 * period
    est = robust_frf(U, Y, starts, period)
    f = est.frequencies
    expected = np.zeros((len(f), 2, 2), dtype=complex)
    expected[:, 0, 0] = _true_frf(np.array(g11[0]), np.array(g11[1]), f)
    expected[:, 0, 1] = _true_frf(np.array(g12[0]), np.array(g12[1]), f)
    expected[:, 1, 0] = _true_frf(np.array(g21[0]), np.array(g21[1]), f)
    np.testing.assert_allclose(est.frf, expected, atol=1e-8)
    assert est.total_variance.shape == (len(f), 2, 2)


def test_robust_frf_errors():
    U, Y, starts, _ = _periodic_data(n_periods=2, n_realizations=2)
    with pytest.raises(ValueError, match="does not divide the sequence length"):
        robust_frf(U, Y, starts, 300)
    with pytest.raises(ValueError, match="at least n_inputs=2 realizations"):
        robust_frf(np.hstack([U, U[::-1]]), Y, np.array([0, len(U)]), 256)
    with pytest.raises(ValueError, match="no period is left"):
        robust_frf(U, Y, starts, 256, n_transient=512)
    with pytest.raises(ValueError, match="same number of periods"):
        robust_frf(U, Y, np.array([0, 256, len(U)]), 256)


def test_lpm_removes_transient_ratio_does_not():
    """A record starting from a nonzero state: LPM at the noise level, Y/U biased."""
    rng = np.random.default_rng(0)
    n, sigma = 2048, 0.01
    den = np.real(np.poly([0.95 * np.exp(0.2j), 0.95 * np.exp(-0.2j), 0.6]))
    num = np.array([0.0, 0.3, 0.2, 0.1])
    u = rng.standard_normal(n)
    zi = lfiltic(num, den, y=[3.0, -2.0, 1.0])
    y = lfilter(num, den, u, zi=zi)[0] + sigma * rng.standard_normal(n)

    est = lpm_frf(u[:, None], y[:, None], np.array([0, n]))
    G0 = _true_frf(num, den, est.frequencies)
    err_lpm = np.abs(est.frf[:, 0, 0] - G0)
    # noise level: the standard deviation of the ratio estimate due to the noise
    k = np.round(est.frequencies * n).astype(int)
    Uk = np.fft.fft(u)[k] / np.sqrt(n)
    noise_level = sigma / np.abs(Uk)
    ratio = (np.fft.fft(y)[k] / np.sqrt(n)) / Uk
    err_ratio = np.abs(ratio - G0)

    assert np.median(err_lpm) < 1.5 * np.median(noise_level)
    assert np.median(err_ratio) > 10 * np.median(noise_level)
    # the LPM variance describes its own error
    assert 0.5 < np.mean(err_lpm**2) / np.mean(est.total_variance) < 2.0
    assert est.noise_variance is est.total_variance


def test_lpm_band_limited_input_keeps_excited_bins():
    u, lines = multisine(512, lines="full", band=(0.0, 0.1), random_state=0)
    u = u[0]
    y = lfilter(NUM, DEN, u)
    est = lpm_frf(u[:, None], y[:, None], np.array([0, 512]), order=2)
    k = np.round(est.frequencies * 512).astype(int)
    assert set(lines) <= set(k)
    assert k.max() <= lines.max() + 5  # the window half-width beyond the band
    est_cut = lpm_frf(u[:, None], y[:, None], np.array([0, 512]), max_frequency=0.05)
    assert est_cut.frequencies.max() <= 0.05


def test_lpm_power_threshold_keeps_the_strongest_windows():
    """A band-limited random input leaks power beyond its band: a higher
    threshold keeps a subset of the bins, with the same estimates there."""
    rng = np.random.default_rng(0)
    u = lfilter(*butter(6, 0.1), rng.standard_normal(2048))
    y = lfilter(NUM, DEN, u)
    starts = np.array([0, u.size])
    loose = lpm_frf(u[:, None], y[:, None], starts, power_threshold=1e-3)
    strict = lpm_frf(u[:, None], y[:, None], starts, power_threshold=1e-2)
    assert strict.frequencies.size < loose.frequencies.size
    common = np.isin(loose.frequencies, strict.frequencies)
    assert common.sum() == strict.frequencies.size
    np.testing.assert_array_equal(loose.frf[common], strict.frf)


def test_lpm_combines_records_at_equal_frequencies():
    rng = np.random.default_rng(1)
    u = rng.standard_normal((2, 256))
    y = lfilter(NUM, DEN, u, axis=1) + 0.01 * rng.standard_normal((2, 256))
    starts = np.array([0, 256, 512])
    both = lpm_frf(u.reshape(-1, 1), y.reshape(-1, 1), starts)
    one = lpm_frf(u[0, :, None], y[0, :, None], starts[:2])
    np.testing.assert_array_equal(both.frequencies, one.frequencies)
    assert np.median(both.total_variance / one.total_variance) < 0.7


@pytest.mark.parametrize("lengths", [(300, 301), (301, 300)])
def test_lpm_of_records_without_a_common_frequency(lengths):
    # Records of 300 and 301 samples share no DFT bin: each estimate must stay
    # at its own frequency, whichever record comes first.
    rng = np.random.default_rng(2)
    u = rng.standard_normal((sum(lengths), 1))
    starts = np.concatenate([[0], np.cumsum(lengths)])
    y = np.concatenate([lfilter(NUM, DEN, u[a:b, 0]) for a, b in zip(starts[:-1], starts[1:])])
    estimate = lpm_frf(u, y[:, None], starts)
    assert np.all(np.diff(estimate.frequencies) > 0)
    true = _true_frf(NUM, DEN, estimate.frequencies)
    error = np.abs(estimate.frf[:, 0, 0] - true) / np.abs(true)
    # (The local polynomials bias the sharp resonance a little.)
    assert np.median(error) < 0.01 and error.max() < 0.1


def test_robust_frf_names_a_realization_without_input():
    U, Y, starts, _ = _periodic_data(n_periods=2, n_realizations=4)
    U[starts[2]:starts[3]] = 0.0  # a noise-only record among the realizations
    with pytest.raises(ValueError, match=r"sequence\(s\) \[2\].*no power at the excited"):
        robust_frf(U, Y, starts, 256)


def test_lpm_window_defaults_and_fallbacks():
    assert lpm_window(1, 2, 500) == (9, 2)  # 6 unknowns, 3 degrees of freedom
    assert lpm_window(2, 2, 500) == (13, 2)  # 9 unknowns, 4 degrees of freedom
    assert lpm_window(1, 2, 7) == (7, 2)  # shrinks to one degree of freedom
    assert lpm_window(1, 2, 5) == (5, 1)  # then lowers the degree
    assert lpm_window(3, 2, 4) == (4, 0)  # one window, no variance
    with pytest.raises(ValueError, match="too short for the Local Polynomial"):
        lpm_window(1, 2, 5, bandwidth=4)


def test_lpm_too_short_record_has_no_variance():
    rng = np.random.default_rng(0)
    U, Y = rng.standard_normal((10, 3)), rng.standard_normal((10, 1))
    est = lpm_frf(U, Y, np.array([0, 10]))
    assert est.total_variance is None and np.all(np.isfinite(est.frf))


@settings(max_examples=40, deadline=None)
@given(n=st.integers(3, 3000), n_inputs=st.integers(1, 2), n_outputs=st.integers(1, 2),
       block=st.integers(1, 40), cut=st.sampled_from([None, 0.001, 0.05, 0.3]),
       seed=st.integers(0, 2**16))
def test_lpm_blocks_of_bins_change_nothing(n, n_inputs, n_outputs, block, cut, seed):
    """The windows are fitted a block of bins at a time to bound the memory:
    the estimate (or the error) is the same, to the bit, whatever the block size."""
    rng = np.random.default_rng(seed)
    U = rng.standard_normal((n, n_inputs))
    Y = lfilter(NUM, DEN, U[:, :1], axis=0) + 0.1 * rng.standard_normal((n, n_outputs))
    starts = np.array([0, n])

    def estimate():
        try:
            return lpm_frf(U, Y, starts, max_frequency=cut)
        except ValueError as error:
            return str(error)

    whole = estimate()
    with mock.patch.object(_frf, "_LPM_BLOCK", block):
        blocks = estimate()
    if isinstance(whole, str):
        assert blocks == whole
        return
    np.testing.assert_array_equal(blocks.frequencies, whole.frequencies)
    np.testing.assert_array_equal(blocks.frf, whole.frf)
    if whole.total_variance is None:
        assert blocks.total_variance is None
    else:
        np.testing.assert_array_equal(blocks.total_variance, whole.total_variance)


def test_lpm_record_with_collinear_inputs_gives_no_bins():
    # Its windows cannot separate the inputs: the other record alone makes the
    # estimate; when every record is so, the error says why.
    rng = np.random.default_rng(0)
    U = rng.standard_normal((1024, 2))
    U[512:, 1] = 2.0 * U[512:, 0]
    Y = lfilter(NUM, DEN, U.sum(axis=1))[:, None]
    both = lpm_frf(U, Y, np.array([0, 512, 1024]))
    first = lpm_frf(U[:512], Y[:512], np.array([0, 512]))
    np.testing.assert_array_equal(both.frequencies, first.frequencies)
    np.testing.assert_array_equal(both.frf, first.frf)
    with pytest.raises(ValueError, match="collinear in every window"):
        lpm_frf(U[512:], Y[512:], np.array([0, 512]))


def test_lpm_record_without_bins_in_the_band_keeps_its_variance_status():
    # A record with no bin below max_frequency still says whether its windows
    # would have had a variance, so that records are sorted as before.
    rng = np.random.default_rng(0)
    U, Y = rng.standard_normal((40, 1)), rng.standard_normal((40, 1))
    (_, G, var, _), _ = _frf._lpm_record(U, Y, 2, None, 0.001)
    assert G.shape == (0, 1, 1) and var is not None and var.shape == (0, 1, 1)
    U2 = rng.standard_normal((7, 2))
    (_, _, var, _), _ = _frf._lpm_record(U2, Y[:7], 2, None, 0.001)
    assert var is None  # three bins for three unknowns: no degree of freedom
