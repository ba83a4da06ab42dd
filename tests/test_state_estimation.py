import numpy as np
import pytest

from sknlss._linear._state_estimation import estimate_states


def _linear_system(n_states, n_inputs, n_outputs, seed):
    rng = np.random.default_rng(seed)
    Q, _ = np.linalg.qr(rng.standard_normal((n_states, n_states)))
    A = Q @ np.diag(rng.uniform(0.3, 0.9, n_states)) @ Q.T
    B = rng.standard_normal((n_states, n_inputs))
    C = rng.standard_normal((n_outputs, n_states))
    D = rng.standard_normal((n_outputs, n_inputs))
    return A, B, C, D


def _simulate(A, B, C, D, U, x0):
    X = np.empty((len(U), A.shape[0]))
    x = x0
    for t, u in enumerate(U):
        X[t] = x
        x = A @ x + B @ u
    return X, X @ C.T + U @ D.T


def _transformed(A, B, C, D, T):
    """The same system in the state coordinates x' = T x."""
    T_inv = np.linalg.inv(T)
    return T @ A @ T_inv, T @ B, C @ T_inv, D


def _dense_solution(U, Y, A, B, C, D, alpha):
    """Minimiser of eq. 14 by a dense least-squares solve (small records only)."""
    N, n = len(U), A.shape[0]
    rows, rhs = [], []
    for t in range(N):
        row = np.zeros((C.shape[0], N * n))
        row[:, t * n : (t + 1) * n] = C
        rows.append(row)
        rhs.append(Y[t] - D @ U[t])
    for t in range(N - 1):
        row = np.zeros((n, N * n))
        row[:, (t + 1) * n : (t + 2) * n] = np.sqrt(alpha) * np.eye(n)
        row[:, t * n : (t + 1) * n] = -np.sqrt(alpha) * A
        rows.append(row)
        rhs.append(np.sqrt(alpha) * (B @ U[t]))
    solution = np.linalg.lstsq(np.vstack(rows), np.concatenate(rhs), rcond=None)[0]
    return solution.reshape(N, n)


@pytest.mark.parametrize("n_states, n_inputs, n_outputs", [(1, 1, 1), (3, 1, 1), (3, 2, 2)])
@pytest.mark.parametrize("alpha", [0.01, 1.0, 100.0])
def test_matches_dense_least_squares(n_states, n_inputs, n_outputs, alpha):
    A, B, C, D = _linear_system(n_states, n_inputs, n_outputs, seed=1)
    rng = np.random.default_rng(2)
    U = rng.standard_normal((20, n_inputs))
    Y = rng.standard_normal((20, n_outputs))
    states = estimate_states(U, Y, [0, 20], A, B, C, D, alpha)
    np.testing.assert_allclose(states, _dense_solution(U, Y, A, B, C, D, alpha),
                               rtol=1e-8, atol=1e-10)


@pytest.mark.parametrize("alpha", [0.01, 1.0, 100.0])
def test_noise_free_states_recovered_exactly(alpha):
    A, B, C, D = _linear_system(3, 1, 1, seed=3)
    rng = np.random.default_rng(4)
    U = rng.standard_normal((500, 1))
    X, Y = _simulate(A, B, C, D, U, rng.standard_normal(3))
    np.testing.assert_allclose(estimate_states(U, Y, [0, 500], A, B, C, D, alpha), X,
                               atol=1e-8)


def test_states_up_to_similarity_within_noise_level():
    A, B, C, D = _linear_system(3, 1, 1, seed=5)
    rng = np.random.default_rng(6)
    U = rng.standard_normal((2000, 1))
    X, Y = _simulate(A, B, C, D, U, np.zeros(3))
    noise_std = 1e-3
    Y_noisy = Y + noise_std * rng.standard_normal(Y.shape)
    # The model handed to the estimator is the true one in other coordinates.
    T = rng.standard_normal((3, 3)) + 3 * np.eye(3)
    states = estimate_states(U, Y_noisy, [0, 2000], *_transformed(A, B, C, D, T), 10.0)
    error = states - X @ T.T
    state_rms = np.sqrt(np.mean((X @ T.T) ** 2, axis=0))
    assert np.sqrt(np.mean(error**2)) < 3 * noise_std
    # and the error is tiny compared with the states themselves
    assert np.all(np.sqrt(np.mean(error**2, axis=0)) < 1e-2 * state_rms)


def test_sequences_are_independent():
    A, B, C, D = _linear_system(2, 1, 1, seed=7)
    rng = np.random.default_rng(8)
    U = rng.standard_normal((70, 1))
    Y = rng.standard_normal((70, 1))
    joint = estimate_states(U, Y, [0, 30, 70], A, B, C, D, 2.0)
    first = estimate_states(U[:30], Y[:30], [0, 30], A, B, C, D, 2.0)
    second = estimate_states(U[30:], Y[30:], [0, 40], A, B, C, D, 2.0)
    np.testing.assert_allclose(joint, np.vstack([first, second]), rtol=1e-10, atol=1e-12)


def test_bad_input():
    A, B, C, D = _linear_system(2, 1, 1, seed=9)
    U, Y = np.zeros((10, 1)), np.ones((10, 1))
    with pytest.raises(ValueError, match="alpha"):
        estimate_states(U, Y, [0, 10], A, B, C, D, 0.0)
    with pytest.raises(ValueError, match="B must have shape"):
        estimate_states(U, Y, [0, 10], A, np.ones((3, 1)), C, D, 1.0)
    with pytest.raises(ValueError, match="same number of rows"):
        estimate_states(U, Y[:5], [0, 10], A, B, C, D, 1.0)
    with pytest.raises(ValueError, match="finite"):
        estimate_states(U, np.full((10, 1), np.nan), [0, 10], A, B, C, D, 1.0)
    with pytest.raises(ValueError, match="starts"):
        estimate_states(U, Y, [0, 5], A, B, C, D, 1.0)
    # a state that never reaches the output cannot be estimated from one sample
    with pytest.raises(ValueError, match="not observable"):
        estimate_states(U[:1], Y[:1], [0, 1], A, B, C, D, 1.0)


def test_ridge_makes_unobservable_states_defined():
    A = np.diag([0.5, 0.8])
    B = np.ones((2, 1))
    C = np.array([[1.0, 0.0]])  # the second state never reaches the output
    D = np.zeros((1, 1))
    rng = np.random.default_rng(10)
    U = rng.standard_normal((30, 1))
    X, Y = _simulate(A, B, C, D, U, np.zeros(2))
    with pytest.raises(ValueError, match="not observable"):
        estimate_states(U, Y, [0, 30], A, B, C, D, 1.0)
    states = estimate_states(U, Y, [0, 30], A, B, C, D, 1.0, ridge=1e-10)
    np.testing.assert_allclose(states[:, 0], X[:, 0], atol=1e-6)
    assert np.all(np.isfinite(states))
    with pytest.raises(ValueError, match="ridge"):
        estimate_states(U, Y, [0, 30], A, B, C, D, 1.0, ridge=-1.0)
