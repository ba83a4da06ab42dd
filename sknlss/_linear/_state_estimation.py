"""Regularised least-squares estimation of a state sequence from a linear model.

Given a linear model (A, B, C, D) and a record (u, y), the state sequence of
paper eq. 14 minimises

    sum_t ||y(t) - C x(t) - D u(t)||^2 + alpha sum_t ||x(t+1) - A x(t) - B u(t)||^2.

The cost couples each state only to its two neighbours in time, so its normal
equations are block tridiagonal with n x n blocks: a symmetric banded system of
half-bandwidth 2n - 1, factorised by banded Cholesky in O(N n^3) time and
O(N n^2) memory.
"""

import numpy as np
from scipy.linalg import LinAlgError, cho_solve_banded, cholesky_banded

from .._core._optimize import one_blas_thread


# Squared Cholesky pivots (Schur complements) below this fraction of the
# largest diagonal entry of the normal matrix count as zero: rounding leaves
# pivots of about 1e-16 of it where the matrix is singular, while the ridge
# the estimators add keeps every pivot above 1e-9 of it.
_PIVOT_TOLERANCE = 1e-12


def _check_model(A, B, C, D, n_inputs, n_outputs):
    A, B, C, D = (np.asarray(M, dtype=np.float64) for M in (A, B, C, D))
    n = A.shape[0] if A.ndim == 2 else -1
    expected = {
        "A": (A, (n, n)),
        "B": (B, (n, n_inputs)),
        "C": (C, (n_outputs, n)),
        "D": (D, (n_outputs, n_inputs)),
    }
    for name, (M, shape) in expected.items():
        if n < 1 or M.shape != shape:
            raise ValueError(
                f"{name} must have shape {shape} for {n_inputs} input(s), "
                f"{n_outputs} output(s) and A of shape (n_states, n_states); "
                f"got {M.shape}."
            )
        if not np.all(np.isfinite(M)):
            raise ValueError(f"{name} contains non-finite values.")
    return A, B, C, D


def _banded_normal_matrix(A, C, alpha, ridge, n_samples):
    """Lower banded storage of the block-tridiagonal normal matrix."""
    n = A.shape[0]
    CtC = C.T @ C + ridge * np.eye(n)
    inner = CtC + alpha * (A.T @ A + np.eye(n))
    # The first state has no predecessor and the last no successor.
    first = inner - alpha * np.eye(n)
    last = CtC + alpha * np.eye(n) if n_samples > 1 else CtC
    sub = -alpha * A  # block (t + 1, t)
    # Element (t*n + i, s*n + j) of the full matrix goes to band row
    # (t - s)*n + i - j, column s*n + j; all inner blocks are equal.
    # Fortran order lets LAPACK factorise it in place.
    ab = np.zeros((2 * n, n_samples * n), order="F")
    for j in range(n):
        for i in range(j, n):
            ab[i - j, j::n] = inner[i, j]
            ab[i - j, j] = first[i, j]
            ab[i - j, (n_samples - 1) * n + j] = last[i, j]
        for i in range(n):
            ab[n + i - j, j : (n_samples - 1) * n : n] = sub[i, j]
    return ab


def estimate_states(U, Y, starts, A, B, C, D, alpha, *, ridge=0.0):
    """State sequence of a linear model fitted to a record (paper eq. 14).

    Parameters
    ----------
    U : array-like of shape (n_samples, n_inputs)
        Input signal.
    Y : array-like of shape (n_samples, n_outputs)
        Output signal.
    starts : array-like of int of shape (n_sequences + 1,)
        Sequence ``k`` occupies rows ``starts[k]:starts[k + 1]``; the state
        equation does not link the last state of one sequence to the first of
        the next.
    A : array-like of shape (n_states, n_states)
    B : array-like of shape (n_states, n_inputs)
    C : array-like of shape (n_outputs, n_states)
    D : array-like of shape (n_outputs, n_inputs)
        Linear model, e.g. the Best Linear Approximation.
    alpha : float
        Positive weight of the state-equation residuals relative to the
        output residuals. Large values trust the linear model; small values
        let the states deviate from it to follow the measured output.
    ridge : float, default=0.0
        Non-negative weight of an added term ``ridge * sum_t ||x(t)||^2``. A
        tiny value makes the problem well posed when some states are not
        observable, picking the smallest such states.

    Returns
    -------
    states : ndarray of shape (n_samples, n_states)
        Minimiser ``x(t)`` of the regularised least-squares cost.

    Raises
    ------
    ValueError
        If the shapes disagree, a value is not finite, ``alpha`` is not
        positive, ``ridge`` is negative, or the normal equations are singular
        (the pair (A, C) is not observable from a sequence this short and
        ``ridge`` is zero).

    Examples
    --------
    >>> import numpy as np
    >>> from sknlss._linear._state_estimation import estimate_states
    >>> A, B, C, D = [[0.5]], [[1.0]], [[1.0]], [[0.0]]
    >>> u = np.ones((5, 1))
    >>> y = np.array([[0.0], [1.0], [1.5], [1.75], [1.875]])
    >>> estimate_states(u, y, [0, 5], A, B, C, D, alpha=1.0).ravel().round(3)
    array([0.   , 1.   , 1.5  , 1.75 , 1.875])
    """
    U = np.asarray(U, dtype=np.float64)
    Y = np.asarray(Y, dtype=np.float64)
    if U.ndim != 2 or Y.ndim != 2 or U.shape[0] != Y.shape[0]:
        raise ValueError(
            "U and Y must be 2-D arrays with the same number of rows; got shapes "
            f"{U.shape} and {Y.shape}."
        )
    if not (np.all(np.isfinite(U)) and np.all(np.isfinite(Y))):
        raise ValueError("U and Y must contain only finite values.")
    if not (np.isscalar(alpha) and np.isfinite(alpha) and alpha > 0):
        raise ValueError(f"alpha must be a positive finite number, got {alpha!r}.")
    if not (np.isscalar(ridge) and np.isfinite(ridge) and ridge >= 0):
        raise ValueError(f"ridge must be a non-negative finite number, got {ridge!r}.")
    A, B, C, D = _check_model(A, B, C, D, U.shape[1], Y.shape[1])
    starts = np.asarray(starts, dtype=np.int64)
    if (starts.ndim != 1 or starts.size < 2 or starts[0] != 0
            or starts[-1] != U.shape[0] or np.any(np.diff(starts) < 1)):
        raise ValueError(
            "starts must increase strictly from 0 to n_samples "
            f"({U.shape[0]}); got {starts.tolist()}."
        )
    n = A.shape[0]
    states = np.empty((U.shape[0], n))
    # Thin products and a narrow band: extra BLAS threads only add overhead
    # (several times slower on a loaded 2-core machine).
    with one_blas_thread():
        for begin, end in zip(starts[:-1], starts[1:]):
            states[begin:end] = _solve_sequence(U[begin:end], Y[begin:end], A, B, C, D,
                                                alpha, ridge)
    return states


def _solve_sequence(U, Y, A, B, C, D, alpha, ridge):
    n_samples, n = U.shape[0], A.shape[0]
    BU = U[:-1] @ B.T
    rhs = (Y - U @ D.T) @ C
    rhs[:-1] -= alpha * BU @ A
    rhs[1:] += alpha * BU
    ab = _banded_normal_matrix(A, C, alpha, ridge, n_samples)
    scale = np.abs(ab[0]).max()
    singular = ValueError(
        "The state-estimation normal equations are singular: the states of this "
        f"linear model are not observable from a sequence of {n_samples} samples."
    )
    try:
        factor = cholesky_banded(ab, lower=True, check_finite=False)
    except LinAlgError as exc:
        raise singular from exc
    # A singular matrix can still factor, rounding leaving a pivot of the
    # order of eps times its scale: the rank is decided with a tolerance.
    if not np.min(factor[0]) ** 2 > _PIVOT_TOLERANCE * scale:
        raise singular
    solution = cho_solve_banded((factor, True), rhs.ravel(), overwrite_b=True,
                                check_finite=False)
    return solution.reshape(n_samples, n)