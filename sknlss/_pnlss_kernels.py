"""Compiled simulation and sensitivity kernels of the PNLSS model.

The model, in normalised signal units, is

    x(t+1) = A x(t) + B u(t) + E zeta(x(t), u(t))
    y(t)   = C x(t) + D u(t) + F eta(x(t), u(t))

with zeta and eta monomials in s = [x; u] given by exponent arrays (see
``sknlss._polynomial``). The parameter vector is laid out as

    theta = [vec(A), vec(B), vec(C), vec(D), vec(E), vec(F), x0]

(row-major ``vec``; ``x0`` only when the initial state is estimated, shared by
all sequences).

The Jacobian of the simulated output is itself a simulation. For a parameter
theta_k, with x_k(t) = dx(t)/dtheta_k,

    x_k(t+1) = (A + E dzeta/dx(t)) x_k(t) + dF/dtheta_k(t)
    y_k(t)   = (C + F deta/dx(t)) x_k(t) + dG/dtheta_k(t)

where the direct terms are one-hot: the derivative of ``A x`` with respect to
A[i, j] is x_j in row i, and so on. Only A, B, E and x0 move the states, so the
recursion carries those columns only; C, D and F enter the output directly.
"""

import numpy as np
from numba import njit

from ._kernels import matmat, matvec, out_of_bounds, state_space_step


@njit(cache=True)
def _fill_powers(s, max_degree, powers):
    # powers[j, p] = s[j] ** p, shared by every monomial and its derivatives.
    for j in range(s.shape[0]):
        powers[j, 0] = 1.0
        for p in range(1, max_degree + 1):
            powers[j, p] = powers[j, p - 1] * s[j]


@njit(cache=True)
def _eval_monomials(powers, exponents, out):
    for k in range(exponents.shape[0]):
        value = 1.0
        for j in range(exponents.shape[1]):
            e = exponents[k, j]
            if e:
                value *= powers[j, e]
        out[k] = value


@njit(cache=True)
def _state_derivatives(powers, exponents, n_states, out):
    # out[k, i] = d monomial_k / d x_i (the derivatives with respect to u are
    # not needed: u is not a function of the parameters).
    for k in range(exponents.shape[0]):
        for i in range(n_states):
            e = exponents[k, i]
            if e == 0:
                out[k, i] = 0.0
                continue
            value = e * powers[i, e - 1]
            for j in range(exponents.shape[1]):
                if j != i:
                    ej = exponents[k, j]
                    if ej:
                        value *= powers[j, ej]
            out[k, i] = value


@njit(cache=True)
def _max_degree(state_exponents, output_exponents):
    degree = 1
    for k in range(state_exponents.shape[0]):
        degree = max(degree, state_exponents[k].max())
    for k in range(output_exponents.shape[0]):
        degree = max(degree, output_exponents[k].max())
    return degree


@njit(cache=True)
def monomial_state_derivatives(S, exponents, n_states):
    """Derivatives of the monomials with respect to the states at every row of S.

    Parameters
    ----------
    S : ndarray of shape (n_rows, n + n_u)
        Points ``[x; u]``.
    exponents : ndarray of int64 of shape (n_terms, n + n_u)
    n_states : int

    Returns
    -------
    derivatives : ndarray of shape (n_rows, n_terms, n_states)
    """
    out = np.empty((S.shape[0], exponents.shape[0], n_states))
    powers = np.empty((S.shape[1], _max_degree(exponents, exponents) + 1))
    for t in range(S.shape[0]):
        _fill_powers(S[t], powers.shape[1] - 1, powers)
        _state_derivatives(powers, exponents, n_states, out[t])
    return out


@njit(cache=True)
def simulate_pnlss(A, B, C, D, E, F, state_exponents, output_exponents, U, starts,
                   x0, bound):
    """Free-run simulation of every sequence.

    Parameters
    ----------
    A, B, C, D, E, F : ndarray
        Model matrices, shapes (n, n), (n, n_u), (n_y, n), (n_y, n_u),
        (n, n_zeta), (n_y, n_eta).
    state_exponents, output_exponents : ndarray of int64
        Exponents of zeta and eta, shapes (n_zeta, n + n_u), (n_eta, n + n_u).
    U : ndarray of shape (n_samples, n_u)
    starts : ndarray of int64 of shape (n_sequences + 1,)
    x0 : ndarray of shape (n_sequences, n)
    bound : float
        A sequence stops when a state leaves [-bound, bound] or is not finite.

    Returns
    -------
    Y : ndarray of shape (n_samples, n_y)
    X : ndarray of shape (n_samples, n)
        NaN from the first divergent sample to the end of its sequence.
    diverged : bool
    """
    n = A.shape[0]
    n_u = B.shape[1]
    n_y = C.shape[0]
    n_samples = U.shape[0]
    Y = np.empty((n_samples, n_y))
    X = np.empty((n_samples, n))
    s = np.empty(n + n_u)
    powers = np.empty((n + n_u, _max_degree(state_exponents, output_exponents) + 1))
    zeta = np.empty(state_exponents.shape[0])
    eta = np.empty(output_exponents.shape[0])
    state_term = np.empty(n)
    output_term = np.empty(n_y)
    x = np.empty(n)
    x_next = np.empty(n)
    diverged = False
    for seq in range(starts.shape[0] - 1):
        x[:] = x0[seq]
        for t in range(starts[seq], starts[seq + 1]):
            if out_of_bounds(x, bound):
                Y[t:starts[seq + 1]] = np.nan
                X[t:starts[seq + 1]] = np.nan
                diverged = True
                break
            s[:n] = x
            s[n:] = U[t]
            _fill_powers(s, powers.shape[1] - 1, powers)
            _eval_monomials(powers, state_exponents, zeta)
            _eval_monomials(powers, output_exponents, eta)
            X[t] = x
            matvec(E, zeta, state_term)
            matvec(F, eta, output_term)
            state_space_step(A, B, C, D, x, U[t], state_term, output_term, x_next, Y[t])
            x[:] = x_next
    return Y, X, diverged


@njit(cache=True)
def jacobian_pnlss(A, B, C, D, E, F, state_exponents, output_exponents, U, starts,
                   x0, estimate_x0, bound, jacobian_rows):
    """Simulated outputs and states, and the outputs' Jacobian with respect to theta.

    Parameters are those of :func:`simulate_pnlss`, plus

    estimate_x0 : bool
        Whether theta ends with the initial state (its sensitivity starts at
        the identity in every sequence).
    jacobian_rows : ndarray of int64 of shape (n_samples,)
        Row of ``J`` receiving the derivatives of sample t, or -1 to skip the
        sample (e.g. a transient outside the cost): only the rows the cost
        needs are stored.

    Returns
    -------
    Y : ndarray of shape (n_samples, n_y)
    X : ndarray of shape (n_samples, n)
    J : ndarray of shape (max(jacobian_rows) + 1, n_y, n_params)
        dY/dtheta, laid out as described in the module docstring.
    diverged : bool
        When True, ``Y``, ``X`` and ``J`` are incomplete and must not be used.
    """
    n = A.shape[0]
    n_u = B.shape[1]
    n_y = C.shape[0]
    n_zeta = state_exponents.shape[0]
    n_eta = output_exponents.shape[0]
    n_samples = U.shape[0]
    # Offsets of the parameter blocks in theta.
    o_b = n * n
    o_c = o_b + n * n_u
    o_d = o_c + n_y * n
    o_e = o_d + n_y * n_u
    o_f = o_e + n * n_zeta
    o_x0 = o_f + n_y * n_eta
    n_params = o_x0 + (n if estimate_x0 else 0)
    # Local columns of the state sensitivity: A, B, E, x0 blocks in this order.
    l_e = n * n + n * n_u
    l_x0 = l_e + n * n_zeta
    n_state_params = l_x0 + (n if estimate_x0 else 0)
    global_col = np.empty(n_state_params, dtype=np.int64)
    for k in range(l_e):
        global_col[k] = k
    for k in range(n * n_zeta):
        global_col[l_e + k] = o_e + k
    for k in range(n_state_params - l_x0):
        global_col[l_x0 + k] = o_x0 + k

    Y = np.empty((n_samples, n_y))
    X = np.empty((n_samples, n))
    n_rows = 0
    for t in range(n_samples):
        n_rows = max(n_rows, jacobian_rows[t] + 1)
    J = np.zeros((n_rows, n_y, n_params))
    s = np.empty(n + n_u)
    powers = np.empty((n + n_u, _max_degree(state_exponents, output_exponents) + 1))
    zeta = np.empty(n_zeta)
    eta = np.empty(n_eta)
    dzeta = np.empty((n_zeta, n))
    deta = np.empty((n_eta, n))
    state_term = np.empty(n)
    output_term = np.empty(n_y)
    jac_x = np.empty((n, n))
    jac_y = np.empty((n_y, n))
    x = np.empty(n)
    x_next = np.empty(n)
    sens = np.zeros((n, n_state_params))
    sens_next = np.empty((n, n_state_params))
    for seq in range(starts.shape[0] - 1):
        x[:] = x0[seq]
        sens[:] = 0.0
        for i in range(n_state_params - l_x0):
            sens[i, l_x0 + i] = 1.0
        for t in range(starts[seq], starts[seq + 1]):
            if out_of_bounds(x, bound):
                return Y, X, J, True
            s[:n] = x
            s[n:] = U[t]
            _fill_powers(s, powers.shape[1] - 1, powers)
            _eval_monomials(powers, state_exponents, zeta)
            _eval_monomials(powers, output_exponents, eta)
            _state_derivatives(powers, state_exponents, n, dzeta)
            _state_derivatives(powers, output_exponents, n, deta)
            X[t] = x
            matmat(E, dzeta, jac_x)
            jac_x += A
            matmat(F, deta, jac_y)
            jac_y += C
            matvec(E, zeta, state_term)
            matvec(F, eta, output_term)
            state_space_step(A, B, C, D, x, U[t], state_term, output_term, x_next, Y[t])
            # Output sensitivity.
            row = jacobian_rows[t]
            if row >= 0:
                for i in range(n_y):
                    for col in range(n_state_params):
                        acc = 0.0
                        for j in range(n):
                            acc += jac_y[i, j] * sens[j, col]
                        J[row, i, global_col[col]] = acc
                    for j in range(n):
                        J[row, i, o_c + i * n + j] = x[j]
                    for j in range(n_u):
                        J[row, i, o_d + i * n_u + j] = U[t, j]
                    for j in range(n_eta):
                        J[row, i, o_f + i * n_eta + j] = eta[j]
            # State sensitivity.
            matmat(jac_x, sens, sens_next)
            for i in range(n):
                for j in range(n):
                    sens_next[i, i * n + j] += x[j]
                for j in range(n_u):
                    sens_next[i, o_b + i * n_u + j] += U[t, j]
                for j in range(n_zeta):
                    sens_next[i, l_e + i * n_zeta + j] += zeta[j]
            x[:] = x_next
            sens[:] = sens_next
    return Y, X, J, False
