"""Parametric linear models: subspace, refinement, balancing, simulation, x0."""

import numpy as np
import pytest
from scipy.linalg import solve_discrete_lyapunov
from scipy.signal import dlsim

from sknlss._linear._realization import (
    balanced_realization,
    estimate_initial_state,
    frf_subspace,
    n_block_rows,
    pole_radius_limit,
    refine_frf,
    simulate_linear,
    ss_frf,
    stabilize,
)


def _random_stable(n, n_u, n_y, seed=0, radius=0.9):
    rng = np.random.default_rng(seed)
    A = rng.standard_normal((n, n))
    A *= radius / np.max(np.abs(np.linalg.eigvals(A)))
    return (A, rng.standard_normal((n, n_u)), rng.standard_normal((n_y, n)),
            rng.standard_normal((n_y, n_u)))


def _sorted_poles(A):
    return np.sort_complex(np.linalg.eigvals(A))


def test_ss_frf_matches_impulse_response_dft():
    A, B, C, D = _random_stable(3, 1, 1, radius=0.5)
    n = 256
    impulse = np.zeros(n)
    impulse[0] = 1.0
    h = dlsim((A, B, C, D, 1.0), impulse)[1][:, 0]
    f = np.arange(1, n // 2) / n
    G = ss_frf(A, B, C, D, f)[:, 0, 0]
    np.testing.assert_allclose(G, np.fft.fft(h)[1 : n // 2], atol=1e-10)


@pytest.mark.parametrize("n_u, n_y", [(1, 1), (2, 1), (2, 3)])
def test_subspace_exact_on_noise_free_frf(n_u, n_y):
    A, B, C, D = _random_stable(4, n_u, n_y, seed=n_u + n_y)
    f = np.arange(1, 60) / 128
    G = ss_frf(A, B, C, D, f)
    A1, B1, C1, D1 = frf_subspace(f, G, np.ones(G.shape), 4)
    np.testing.assert_allclose(_sorted_poles(A1), _sorted_poles(A), atol=1e-8)
    np.testing.assert_allclose(ss_frf(A1, B1, C1, D1, f), G, atol=1e-8)


def test_refine_frf_recovers_perturbed_model():
    A, B, C, D = _random_stable(3, 1, 1, seed=4)
    # one pole lies at Nyquist: measured up to it, so that the data reach it
    f = np.arange(1, 129) / 256
    G = ss_frf(A, B, C, D, f)
    rng = np.random.default_rng(0)
    A0 = A + 0.02 * rng.standard_normal(A.shape)
    A1, B1, C1, D1, result = refine_frf(A0, B, C, D, f, G, np.ones(G.shape))
    assert result.loss_history[-1] < 1e-20
    np.testing.assert_allclose(_sorted_poles(A1), _sorted_poles(A), atol=1e-8)


@pytest.mark.filterwarnings("ignore::sklearn.exceptions.ConvergenceWarning")
def test_refine_frf_keeps_the_model_stable():
    # the best fit of an unstable FRF is on the stability boundary
    A, B, C, D = np.array([[1.05]]), np.array([[1.0]]), np.array([[1.0]]), np.zeros((1, 1))
    f = np.arange(1, 50) / 128
    G = ss_frf(A, B, C, D, f)
    A1, B1, C1, D1, _ = refine_frf(np.array([[0.5]]), B, C, D, f, G, np.ones(G.shape),
                                   max_iter=30)
    assert np.max(np.abs(np.linalg.eigvals(A1))) < 1.0


def test_stabilize_reflects_unstable_poles():
    A = np.diag([1.25, 0.5])
    np.testing.assert_allclose(np.sort(np.linalg.eigvals(stabilize(A)).real), [0.5, 0.8])
    stable = np.array([[0.5, 0.2], [-0.1, 0.3]])
    assert stabilize(stable) is stable


def test_pole_radius_limit_follows_the_measured_band():
    f = np.arange(1, 63) / 1024  # a record of 1024 samples excited below 0.06
    poles = np.array([0.999, -0.999, 0.99 * np.exp(2j * np.pi * 30 / 1024),
                      0.5 * np.exp(2j * np.pi * 0.2)])
    limit = pole_radius_limit(poles, f)
    # near DC: time constant at most 1 / (2 pi f_min) samples
    np.testing.assert_allclose(limit[0], np.exp(-2 * np.pi / 1024))
    # out of band: damping at least 2 pi times the distance to the band
    np.testing.assert_allclose(limit[1], np.exp(-2 * np.pi * (0.5 - 62 / 1024)))
    np.testing.assert_allclose(limit[3], np.exp(-2 * np.pi * (0.2 - 62 / 1024)))
    # on a measured frequency the data determine the damping: only stability
    assert limit[2] == 1.0 - 1e-9
    np.testing.assert_array_equal(limit, pole_radius_limit(np.conj(poles), f))


def test_stabilize_pulls_unsupported_poles_to_the_limit():
    f = np.arange(1, 63) / 1024
    A = np.diag([1.002, -0.9999, 0.9])
    poles = np.sort(np.linalg.eigvals(stabilize(A, f)).real)
    expected = [-np.exp(-2 * np.pi * (0.5 - 62 / 1024)), 0.9, np.exp(-2 * np.pi / 1024)]
    np.testing.assert_allclose(poles, expected, rtol=1e-5)
    assert np.all(np.abs(poles) < pole_radius_limit(poles.astype(complex), f))


def test_balanced_realization():
    A, B, C, D = _random_stable(4, 2, 2, seed=5)
    Ab, Bb, Cb, Db, hsv = balanced_realization(A, B, C, D)
    Wc = solve_discrete_lyapunov(Ab, Bb @ Bb.T)
    Wo = solve_discrete_lyapunov(Ab.T, Cb.T @ Cb)
    np.testing.assert_allclose(Wc, np.diag(hsv), atol=1e-10)
    np.testing.assert_allclose(Wo, np.diag(hsv), atol=1e-10)
    assert np.all(np.diff(hsv) <= 0)
    f = np.linspace(0.01, 0.49, 30)
    np.testing.assert_allclose(ss_frf(Ab, Bb, Cb, Db, f), ss_frf(A, B, C, D, f), atol=1e-10)
    # deterministic up to the state signs: the same model from a transformed one
    T = np.random.default_rng(1).standard_normal((4, 4))
    Ti = np.linalg.inv(T)
    again = balanced_realization(Ti @ A @ T, Ti @ B, C @ T, D)
    np.testing.assert_allclose(again[0], Ab, atol=1e-8)


def test_balanced_realization_leaves_non_minimal_model():
    A, B, C = np.diag([0.5, 0.3]), np.array([[1.0], [0.0]]), np.array([[1.0, 1.0]])
    out = balanced_realization(A, B, C, np.zeros((1, 1)))
    assert out[0] is A and out[4] is None


def test_simulate_linear_matches_scipy_and_stops_on_divergence():
    A, B, C, D = _random_stable(3, 2, 2, seed=6)
    rng = np.random.default_rng(0)
    U = rng.standard_normal((200, 2))
    x0 = rng.standard_normal(3)
    starts = np.array([0, 120, 200])
    Y, X, diverged = simulate_linear(A, B, C, D, U, starts, np.vstack([x0, x0]))
    for begin, end in zip(starts[:-1], starts[1:]):
        _, y_ref, x_ref = dlsim((A, B, C, D, 1.0), U[begin:end], x0=x0)
        np.testing.assert_allclose(Y[begin:end], y_ref, atol=1e-10)
        np.testing.assert_allclose(X[begin:end], x_ref, atol=1e-10)
    assert not diverged
    Y, _, diverged = simulate_linear(np.array([[2.0]]), np.ones((1, 1)), np.ones((1, 1)),
                                     np.zeros((1, 1)), np.zeros((100, 1)),
                                     np.array([0, 100]), np.ones((1, 1)))
    assert diverged and np.isnan(Y[-1, 0]) and np.isfinite(Y[0, 0])


def test_estimate_initial_state_recovers_shared_state_and_offset():
    A, B, C, D = _random_stable(3, 1, 2, seed=7, radius=0.95)
    rng = np.random.default_rng(0)
    U = rng.standard_normal((300, 1))
    starts = np.array([0, 150, 300])
    x0 = np.array([2.0, -1.0, 0.5])
    Y = simulate_linear(A, B, C, D, U, starts, np.vstack([x0, x0]))[0] + [0.3, -0.2]
    mask = np.ones(300, dtype=bool)
    x0_hat, offset = estimate_initial_state(A, B, C, D, U, Y, starts, mask)
    np.testing.assert_allclose(x0_hat, x0, atol=1e-8)
    np.testing.assert_allclose(offset, [0.3, -0.2], atol=1e-8)


def test_n_block_rows_too_few_frequencies():
    assert n_block_rows(2, 100, 1) == 5
    with pytest.raises(ValueError, match="n_states=6 is too large"):
        n_block_rows(6, 3, 1)
