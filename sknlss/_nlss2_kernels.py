"""Compiled simulation and forward sensitivities of the NLSS2 model.

The model, in normalised signal units, is

    x(t+1) = A x(t) + B u(t) + f_NL(x(t), u(t))
    y(t)   = C x(t) + D u(t) + g_NL(x(t), u(t)),

where each of the ``n_states + n_outputs`` components of ``[f_NL; g_NL]`` is its
own one-hidden-layer network of ``n_neurons`` units on ``z = [x; u]``:

    o_j(z) = sum_{k in block j} v_k s(W_k z + b_k) + c_j,

block ``j`` being hidden units ``j * n_neurons`` to ``(j + 1) * n_neurons - 1``.
Components ``0 .. n_states - 1`` form ``f_NL``, the others ``g_NL``. All hidden
units are stored stacked: ``W`` (n_hidden, n_states + n_inputs), ``b`` and ``v``
(n_hidden,), ``c`` (n_states + n_outputs,).

The parameter vector is ``[vec(A), vec(B), vec(C), vec(D), vec(W), b, v, c]``
(row-major ``vec``), followed by ``x0`` when the initial state is estimated.
"""

import math

import numpy as np
from numba import njit

from ._base import DIVERGENCE_BOUND
from ._kernels import out_of_bounds, state_space_step

#: Activation codes understood by the kernels.
ACTIVATIONS = {"sigmoid": 0, "tanh": 1}


@njit(cache=True)
def _activate(a, activation, h, dh):
    """Unit outputs ``h`` and their derivatives ``dh`` for pre-activations ``a``."""
    for k in range(a.shape[0]):
        if activation == 0:
            # exp(-a) overflows to inf for very negative a, giving the right limit 0.
            s = 1.0 / (1.0 + math.exp(-a[k]))
            h[k] = s
            dh[k] = s * (1.0 - s)
        else:
            s = math.tanh(a[k])
            h[k] = s
            dh[k] = 1.0 - s * s


@njit(cache=True)
def _network(x, u, W, b, v, c, n_neurons, activation, z, a, h, dh, out):
    """Evaluate all network components at ``z = [x; u]`` into ``out``."""
    n = x.shape[0]
    for i in range(n):
        z[i] = x[i]
    for i in range(u.shape[0]):
        z[n + i] = u[i]
    for k in range(W.shape[0]):
        acc = b[k]
        for i in range(z.shape[0]):
            acc += W[k, i] * z[i]
        a[k] = acc
    _activate(a, activation, h, dh)
    for j in range(c.shape[0]):
        acc = c[j]
        for k in range(j * n_neurons, (j + 1) * n_neurons):
            acc += v[k] * h[k]
        out[j] = acc


@njit(cache=True)
def simulate_nlss2(U, starts, x0, A, B, C, D, W, b, v, c, n_neurons, activation):
    """Free-run simulation of every sequence.

    Parameters
    ----------
    U : ndarray of shape (n_samples, n_inputs)
    starts : ndarray of int64 of shape (n_sequences + 1,)
    x0 : ndarray of shape (n_sequences, n_states)
    A, B, C, D : ndarray
        Linear part.
    W, b, v, c : ndarray
        Stacked networks (see the module docstring).
    n_neurons : int
    activation : int
        Code from :data:`ACTIVATIONS`.

    Returns
    -------
    Y : ndarray of shape (n_samples, n_outputs)
        NaN after a divergence, to the end of that sequence.
    X : ndarray of shape (n_samples, n_states)
    diverged : bool
    """
    n_samples = U.shape[0]
    n = A.shape[0]
    n_y = C.shape[0]
    n_u = B.shape[1]
    Y = np.full((n_samples, n_y), np.nan)
    X = np.full((n_samples, n), np.nan)
    z = np.empty(n + n_u)
    a = np.empty(W.shape[0])
    h = np.empty(W.shape[0])
    dh = np.empty(W.shape[0])
    out = np.empty(c.shape[0])
    x = np.empty(n)
    x_next = np.empty(n)
    diverged = False
    for seq in range(starts.shape[0] - 1):
        x[:] = x0[seq]
        for t in range(starts[seq], starts[seq + 1]):
            if out_of_bounds(x, DIVERGENCE_BOUND):
                diverged = True
                break
            X[t] = x
            u = U[t]
            _network(x, u, W, b, v, c, n_neurons, activation, z, a, h, dh, out)
            state_space_step(A, B, C, D, x, u, out[:n], out[n:], x_next, Y[t])
            x[:] = x_next
    return Y, X, diverged


@njit(cache=True)
def simulate_nlss2_jacobian(U, starts, x0, A, B, C, D, W, b, v, c, n_neurons,
                            activation, estimate_x0):
    """Simulated output and its derivatives with respect to all parameters.

    The sensitivities ``S = dx/dtheta`` follow the recursion
    ``S(t+1) = (A + df/dx) S(t) + (direct dependence of f on theta)``, and
    ``dy/dtheta = (C + dg/dx) S(t) + (direct dependence of g on theta)``. With
    ``estimate_x0`` the initial state shared by all sequences is the last
    ``n_states`` parameters: each sequence starts from ``S = [0, I]``.

    Parameters
    ----------
    U, starts, x0, A, B, C, D, W, b, v, c, n_neurons, activation
        As in :func:`simulate_nlss2`.
    estimate_x0 : bool
        Append the derivatives with respect to the initial state.

    Returns
    -------
    Y : ndarray of shape (n_samples, n_outputs)
    dY : ndarray of shape (n_samples, n_outputs, n_params)
    diverged : bool
        When True, ``Y`` and ``dY`` are incomplete and must not be used.
    """
    n_samples = U.shape[0]
    n = A.shape[0]
    n_y = C.shape[0]
    n_u = B.shape[1]
    n_z = n + n_u
    n_hidden = W.shape[0]
    # Offsets of the parameter groups in theta.
    o_b = n * n
    o_c = o_b + n * n_u
    o_d = o_c + n_y * n
    o_w = o_d + n_y * n_u
    o_hb = o_w + n_hidden * n_z
    o_v = o_hb + n_hidden
    o_oc = o_v + n_hidden
    o_x0 = o_oc + n + n_y
    n_params = o_x0 + (n if estimate_x0 else 0)

    Y = np.full((n_samples, n_y), np.nan)
    dY = np.zeros((n_samples, n_y, n_params))
    z = np.empty(n_z)
    a = np.empty(n_hidden)
    h = np.empty(n_hidden)
    dh = np.empty(n_hidden)
    out = np.empty(c.shape[0])
    x = np.empty(n)
    x_next = np.empty(n)
    S = np.zeros((n, n_params))
    S_next = np.zeros((n, n_params))
    # Total state Jacobians of the state and output equations.
    Mx = np.empty((n, n))
    My = np.empty((n_y, n))
    diverged = False
    for seq in range(starts.shape[0] - 1):
        x[:] = x0[seq]
        S[:] = 0.0
        if estimate_x0:
            for i in range(n):
                S[i, o_x0 + i] = 1.0
        for t in range(starts[seq], starts[seq + 1]):
            if out_of_bounds(x, DIVERGENCE_BOUND):
                diverged = True
                return Y, dY, diverged
            u = U[t]
            _network(x, u, W, b, v, c, n_neurons, activation, z, a, h, dh, out)
            # Jacobians of the network components with respect to x.
            for j in range(n + n_y):
                for i in range(n):
                    acc = 0.0
                    for k in range(j * n_neurons, (j + 1) * n_neurons):
                        acc += v[k] * dh[k] * W[k, i]
                    if j < n:
                        Mx[j, i] = A[j, i] + acc
                    else:
                        My[j - n, i] = C[j - n, i] + acc
            state_space_step(A, B, C, D, x, u, out[:n], out[n:], x_next, Y[t])
            # Output sensitivities.
            for r in range(n_y):
                row = dY[t, r]
                for i in range(n):
                    m = My[r, i]
                    if m != 0.0:
                        for p in range(n_params):
                            row[p] += m * S[i, p]
                for i in range(n):
                    row[o_c + r * n + i] += x[i]
                for i in range(n_u):
                    row[o_d + r * n_u + i] += u[i]
                _add_network_terms(row, n + r, n_neurons, v, h, dh, z,
                                   o_w, o_hb, o_v, o_oc)
            # State sensitivities.
            for r in range(n):
                row = S_next[r]
                row[:] = 0.0
                for i in range(n):
                    m = Mx[r, i]
                    if m != 0.0:
                        for p in range(n_params):
                            row[p] += m * S[i, p]
                for i in range(n):
                    row[r * n + i] += x[i]
                for i in range(n_u):
                    row[o_b + r * n_u + i] += u[i]
                _add_network_terms(row, r, n_neurons, v, h, dh, z,
                                   o_w, o_hb, o_v, o_oc)
            x[:] = x_next
            S[:] = S_next
    return Y, dY, diverged


@njit(cache=True)
def _add_network_terms(row, j, n_neurons, v, h, dh, z, o_w, o_hb, o_v, o_oc):
    """Add the direct derivatives of network component ``j`` to ``row``."""
    n_z = z.shape[0]
    for k in range(j * n_neurons, (j + 1) * n_neurons):
        g = v[k] * dh[k]
        for i in range(n_z):
            row[o_w + k * n_z + i] += g * z[i]
        row[o_hb + k] += g
        row[o_v + k] += h[k]
    row[o_oc + j] += 1.0
