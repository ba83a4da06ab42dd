"""Compiled simulation and sensitivities of the decoupled polynomial state space.

The model, in normalised signal units, is

    s(t) = [x(t); u(t)],   z(t) = V^T s(t),
    x(t+1) = A x(t) + B u(t) + W_x g(z(t)),
    y(t)   = C x(t) + D u(t) + W_y g(z(t)),

where ``W = [W_x; W_y]`` and ``g_l(z) = sum_k c[l, k] z**(k + 2)``: every
branch is a univariate polynomial without constant and linear term (those would
duplicate ``A, B, C, D``).

The Jacobian of the simulated output with respect to the parameters is itself
a simulation (forward sensitivities): for any parameter ``p``,

    x_p(t+1) = (A + W_x diag(g'(z)) V_x^T) x_p(t) + direct_x,p(t),
    y_p(t)   = (C + W_y diag(g'(z)) V_x^T) x_p(t) + direct_y,p(t),

with ``V_x`` the first ``n`` rows of ``V`` and ``x_p(start) = 0``, except for
the initial-state parameters where ``x_p(start) = e_p``.

Parameter (column) order of the Jacobian: ``A, B, C, D, V, W, c`` flattened in
row-major order, then ``x0``; :func:`parameter_sizes` gives the block sizes.
"""

import numpy as np
from numba import njit

from ._base import DIVERGENCE_BOUND
from ._kernels import matmat, matvec, out_of_bounds, state_space_step


def parameter_sizes(n_states, n_inputs, n_outputs, rank, n_coefficients):
    """Sizes of the parameter blocks ``A, B, C, D, V, W, c, x0``, in Jacobian order."""
    return (
        n_states * n_states,
        n_states * n_inputs,
        n_outputs * n_states,
        n_outputs * n_inputs,
        (n_states + n_inputs) * rank,
        (n_states + n_outputs) * rank,
        rank * n_coefficients,
        n_states,
    )


@njit(cache=True)
def _branches(s, V, coefficients, z, g, dg):
    """Branch inputs ``z = V^T s``, values ``g(z)`` and derivatives ``g'(z)`` (in place)."""
    n_vars, rank = V.shape
    n_coef = coefficients.shape[1]
    for l in range(rank):
        acc = 0.0
        for j in range(n_vars):
            acc += V[j, l] * s[j]
        z[l] = acc
        value = 0.0
        slope = 0.0
        power = acc  # z**(k + 1)
        for k in range(n_coef):
            slope += (k + 2) * coefficients[l, k] * power
            power *= acc
            value += coefficients[l, k] * power
        g[l] = value
        dg[l] = slope


@njit(cache=True)
def _step(A, B, C, D, W, x, u, g, y, x_next, wg):
    """Output ``y = C x + D u + W_y g`` and next state ``A x + B u + W_x g`` (in place)."""
    n = A.shape[0]
    matvec(W, g, wg)
    state_space_step(A, B, C, D, x, u, wg[:n], wg[n:], x_next, y)


@njit(cache=True)
def simulate_decoupled(A, B, C, D, V, W, coefficients, U, starts, x0):
    """Free-run simulation of every sequence.

    Parameters
    ----------
    A, B, C, D : ndarray of shape (n, n), (n, n_u), (n_y, n), (n_y, n_u)
        Linear part.
    V : ndarray of shape (n + n_u, r)
        Input transformation of the branches.
    W : ndarray of shape (n + n_y, r)
        Output transformation ``[W_x; W_y]``.
    coefficients : ndarray of shape (r, n_coef)
        ``coefficients[l, k]`` multiplies ``z_l**(k + 2)``.
    U : ndarray of shape (N, n_u)
        Inputs; sequence ``k`` is rows ``starts[k]:starts[k + 1]``.
    starts : ndarray of shape (n_sequences + 1,)
        Sequence boundaries.
    x0 : ndarray of shape (n_sequences, n)
        Initial state of each sequence.

    Returns
    -------
    Y : ndarray of shape (N, n_y)
        Outputs, NaN after a divergence.
    X : ndarray of shape (N, n)
        States x(t), NaN after a divergence.
    diverged : bool
        True when a sequence left the bounded region.
    """
    n = A.shape[0]
    n_u = B.shape[1]
    n_y = C.shape[0]
    rank = V.shape[1]
    N = U.shape[0]
    Y = np.full((N, n_y), np.nan)
    X = np.full((N, n), np.nan)
    s = np.empty(n + n_u)
    z = np.empty(rank)
    g = np.empty(rank)
    dg = np.empty(rank)
    x = np.empty(n)
    x_next = np.empty(n)
    wg = np.empty(W.shape[0])
    diverged = False
    for k in range(starts.shape[0] - 1):
        x[:] = x0[k]
        for t in range(starts[k], starts[k + 1]):
            s[:n] = x
            s[n:] = U[t]
            _branches(s, V, coefficients, z, g, dg)
            X[t] = x
            _step(A, B, C, D, W, x, U[t], g, Y[t], x_next, wg)
            if t + 1 < starts[k + 1] and out_of_bounds(x_next, DIVERGENCE_BOUND):
                diverged = True
                break
            x[:] = x_next
    return Y, X, diverged


@njit(cache=True)
def jacobian_decoupled(A, B, C, D, V, W, coefficients, U, starts, x0):
    """Simulated outputs and their Jacobian with respect to all parameters.

    Parameters are those of :func:`simulate_decoupled`.

    Returns
    -------
    Y : ndarray of shape (N, n_y)
        Simulated outputs.
    dY : ndarray of shape (N, n_y, n_params)
        ``dY[t, i, p]`` is the derivative of ``Y[t, i]`` with respect to
        parameter ``p`` in the order ``A, B, C, D, V, W, coefficients, x0``
        (each block row-major); ``x0`` is shared by all sequences.
    diverged : bool
        True when a sequence left the bounded region (its outputs and
        sensitivities are then NaN from there on).
    """
    n = A.shape[0]
    n_u = B.shape[1]
    n_y = C.shape[0]
    n_vars, rank = V.shape
    n_coef = coefficients.shape[1]
    N = U.shape[0]
    o_b = n * n
    o_c = o_b + n * n_u
    o_d = o_c + n_y * n
    o_v = o_d + n_y * n_u
    o_w = o_v + n_vars * rank
    o_coef = o_w + (n + n_y) * rank
    o_x0 = o_coef + rank * n_coef
    n_params = o_x0 + n
    n_all = n + n_y

    Y = np.full((N, n_y), np.nan)
    dY = np.full((N, n_y, n_params), np.nan)
    s = np.empty(n_vars)
    z = np.empty(rank)
    g = np.empty(rank)
    dg = np.empty(rank)
    x = np.empty(n)
    x_next = np.empty(n)
    wg = np.empty(W.shape[0])
    sens = np.empty((n, n_params))
    out = np.empty((n_all, n_params))
    M = np.empty((n_all, n))
    diverged = False
    for k in range(starts.shape[0] - 1):
        x[:] = x0[k]
        sens[:, :] = 0.0
        for i in range(n):
            sens[i, o_x0 + i] = 1.0
        for t in range(starts[k], starts[k + 1]):
            s[:n] = x
            s[n:] = U[t]
            _branches(s, V, coefficients, z, g, dg)
            # Local Jacobian of [x(t+1); y(t)] with respect to x(t).
            for i in range(n_all):
                for j in range(n):
                    acc = A[i, j] if i < n else C[i - n, j]
                    for l in range(rank):
                        acc += W[i, l] * dg[l] * V[j, l]
                    M[i, j] = acc
            # Propagated part.
            matmat(M, sens, out)
            # Direct dependence of [x(t+1); y(t)] on each parameter.
            for i in range(n):
                for j in range(n):
                    out[i, i * n + j] += x[j]
                for j in range(n_u):
                    out[i, o_b + i * n_u + j] += U[t, j]
            for i in range(n_y):
                for j in range(n):
                    out[n + i, o_c + i * n + j] += x[j]
                for j in range(n_u):
                    out[n + i, o_d + i * n_u + j] += U[t, j]
            for l in range(rank):
                for j in range(n_vars):
                    factor = dg[l] * s[j]
                    p = o_v + j * rank + l
                    for i in range(n_all):
                        out[i, p] += W[i, l] * factor
                for i in range(n_all):
                    out[i, o_w + i * rank + l] += g[l]
                power = z[l] * z[l]
                for c in range(n_coef):
                    p = o_coef + l * n_coef + c
                    for i in range(n_all):
                        out[i, p] += W[i, l] * power
                    power *= z[l]
            _step(A, B, C, D, W, x, U[t], g, Y[t], x_next, wg)
            dY[t] = out[n:]
            if t + 1 < starts[k + 1] and out_of_bounds(x_next, DIVERGENCE_BOUND):
                diverged = True
                break
            x[:] = x_next
            sens[:, :] = out[:n]
    return Y, dY, diverged
