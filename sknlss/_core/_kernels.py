"""The compiled simulation kernels shared by every state-space model.

Every model of the library, linear or not, is

    x(t+1) = A x(t) + B u(t) + h_x(s(t)),
    y(t)   = C x(t) + D u(t) + h_y(s(t)),      s(t) = [x(t); u(t)],

in normalised signal units, where ``h = [h_x; h_y]`` (n_states + n_outputs
values) are the model's nonlinear terms. A model supplies its terms as three
compiled functions with the fixed signatures below (see ``sknlss._terms``);
the kernels here own everything else once for all models: the time loop, the
linear part, the initial state, the divergence rule and the forward
sensitivities.

The parameter vector of every model is

    theta = [vec(A), vec(B), vec(C), vec(D), theta_terms, x0]

(row-major ``vec``; ``x0`` only when the initial state is estimated: one
shared by all sequences, or one per sequence, in their order). Entries after
``x0`` (the output offset that
:mod:`sknlss._core._model` adds) are not read, and their columns of the
Jacobian are left at zero. The terms' parameters ``theta_terms`` are laid
out by the terms object that owns them.

**The terms contract.** With ``spec`` an integer array describing the terms'
structure and ``work`` a work array that every kernel call starts as a copy
of the terms' ``work_init`` (constants the terms read, such as the range of
their inputs beyond which they go on along their tangents, then scratch
space):

- ``evaluate(theta_terms, spec, s, n_states, h, work)`` writes ``h(s)``;
- ``state_jacobian(theta_terms, spec, s, n_states, dh_dx, work)`` writes the
  derivatives of ``h`` with respect to the states, shape
  (n_states + n_outputs, n_states); it is called right after ``evaluate`` at
  the same point and may read what ``evaluate`` left in ``work``;
- ``parameter_jacobian(theta_terms, spec, s, n_states, work, state_out,
  state_offset, output_out, output_offset)`` adds the derivatives of ``h_x``
  with respect to ``theta_terms[k]`` to ``state_out[:, state_offset + k]`` for
  the parameters that enter ``h_x`` (they come first in ``theta_terms``), and
  those of ``h_y`` to ``output_out[:, output_offset + k]`` for all of them;
  ``output_offset < 0`` means the output rows are not needed. It is called
  after the two others at the same point.

Terms without parameters are zero: ``simulate`` then skips their call, which
costs more than the arithmetic of a small linear model (the BLA, the
responses of the NL-LFR initialisation, initial-state regressions).

The compiled helpers these functions call at every sample are declared
``inline="always"``: a call that LLVM leaves out of line (a helper with
several branches, such as the basis functions) costs tens of nanoseconds,
more than the arithmetic of a small model, and inlining halved the
simulation time of a one-branch NL-LFR model with the same results to the bit.

**Forward sensitivities.** For a parameter theta_k, with
``x_k(t) = dx(t)/dtheta_k``,

    x_k(t+1) = (A + dh_x/dx) x_k(t) + d[A x + B u + h_x]/dtheta_k (direct),
    y_k(t)   = (C + dh_y/dx) x_k(t) + d[C x + D u + h_y]/dtheta_k (direct),

and ``x_k(start) = e_i`` for the i-th initial-state parameter of the
sequence (of every sequence when they share it), else 0. Only
the columns that move the state (A, B, the terms' parameters of h_x, x0) are
propagated; entries below :data:`NEGLIGIBLE_SENSITIVITY` are set to zero.

**Divergence.** A sequence diverges at the first sample whose state or output
is not finite or exceeds :data:`DIVERGENCE_BOUND` in absolute value; its
outputs and states are NaN from there to its end.
"""

import numpy as np
from numba import njit, types
from numba.core.typing.typeof import typeof_impl
from numba.experimental.function_type import _get_wrapper_address

def _cache_probe():
    return 0


def _cache_available():
    """Whether numba can cache compiled functions of this package on disk.

    numba caches next to the package or in the user's cache folder
    (``NUMBA_CACHE_DIR`` names another); where none is writable (a read-only
    install run by a user without a home folder), ``cache=True`` fails at
    decoration and would make the package fail to import. The kernels are
    then compiled in every process instead.
    """
    try:
        njit(cache=True)(_cache_probe)
    except RuntimeError:
        return False
    return True


#: Whether the compiled functions are cached on disk (see ``_cache_available``).
CACHE = _cache_available()

#: Largest absolute normalised state or output value a simulation may reach
#: before it is declared divergent. Normalised signals have unit standard
#: deviation, so any physically meaningful trajectory stays many orders of
#: magnitude below it.
DIVERGENCE_BOUND = 1e6

#: State sensitivities below this size in absolute value are set to zero. A
#: sensitivity that decays (that of the initial state through a stable A) would
#: otherwise pass through the subnormal numbers, whose arithmetic is many times
#: slower on x86 (it doubled the time of a whole kernel call); at this size it
#: is hundreds of orders of magnitude below anything the cost can resolve.
NEGLIGIBLE_SENSITIVITY = 1e-280

_F1 = types.float64[::1]
_F2 = types.float64[:, ::1]
_F3 = types.float64[:, :, ::1]
_I1 = types.int64[::1]
_INT = types.int64

#: Signatures of the three functions every model's terms provide.
EVALUATE = types.void(_F1, _I1, _F1, _INT, _F1, _F1)
STATE_JACOBIAN = types.void(_F1, _I1, _F1, _INT, _F2, _F1)
PARAMETER_JACOBIAN = types.void(_F1, _I1, _F1, _INT, _F1, _F2, _INT, _F2, _INT)


class _FunctionPointer(types.WrapperAddressProtocol):
    """A compiled function passed to the kernels by address.

    Passing the dispatcher itself works too, but numba then resolves it at
    every call (tens of microseconds, more than a short simulation takes).
    """

    def __init__(self, function, signature):
        self._address = _get_wrapper_address(function, signature)
        self._signature = signature
        self.numba_type = types.FunctionType(signature)

    def __wrapper_address__(self):
        return self._address

    def signature(self):
        return self._signature


@typeof_impl.register(_FunctionPointer)
def _typeof_function_pointer(value, context):
    # numba's generic rule for the wrapper-address protocol builds this same
    # type anew at every kernel call (tens of microseconds per pointer).
    return value.numba_type


_POINTERS = {}


def function_pointer(function, signature):
    """The address of a compiled function with an explicit signature, for the kernels."""
    key = (function, signature)
    if key not in _POINTERS:
        _POINTERS[key] = _FunctionPointer(function, signature)
    return _POINTERS[key]


@njit(cache=CACHE, inline="always")
def _escaped(values, count, bound):
    """Whether one of the first ``count`` values is not finite or exceeds
    ``bound`` in absolute value."""
    failed = False
    for i in range(count):
        if not abs(values[i]) <= bound:
            failed = True
    return failed


@njit(cache=CACHE, inline="always")
def _step(A, B, C, D, h, s, x_next, y):
    """One sample of the model from the terms' values ``h`` at ``s = [x; u]``:
    writes ``x(t+1)`` to ``x_next`` and ``y(t)`` to ``y``; returns whether an
    output escaped :data:`DIVERGENCE_BOUND`."""
    n, n_u, n_y = A.shape[0], B.shape[1], C.shape[0]
    for i in range(n):
        acc = h[i]
        for j in range(n):
            acc += A[i, j] * s[j]
        for j in range(n_u):
            acc += B[i, j] * s[n + j]
        x_next[i] = acc
    for i in range(n_y):
        acc = h[n + i]
        for j in range(n):
            acc += C[i, j] * s[j]
        for j in range(n_u):
            acc += D[i, j] * s[n + j]
        y[i] = acc
    return _escaped(y, n_y, DIVERGENCE_BOUND)


@njit(cache=CACHE)
def _linear_part(theta, n, n_u, n_y):
    """Views of A, B, C, D in ``theta`` and the offset of the terms' parameters."""
    o_b = n * n
    o_c = o_b + n * n_u
    o_d = o_c + n_y * n
    o_terms = o_d + n_y * n_u
    A = theta[:o_b].reshape((n, n))
    B = theta[o_b:o_c].reshape((n, n_u))
    C = theta[o_c:o_d].reshape((n_y, n))
    D = theta[o_d:o_terms].reshape((n_y, n_u))
    return A, B, C, D, o_terms


@njit(cache=CACHE)
def _terms_buffers(theta, n, n_u, n_y, n_terms, work_init):
    """The terms' parameters in ``theta``, and the arrays the terms' functions
    write to: ``h``, ``dh/dx`` and a fresh work array."""
    o_terms = _linear_part(theta, n, n_u, n_y)[4]
    return (theta[o_terms : o_terms + n_terms], np.empty(n + n_y), np.empty((n + n_y, n)),
            work_init.copy())


@njit(
    types.Tuple((_F2, _F2, types.boolean))(
        _F1, _INT, _INT, _I1, _F1, _F2, _I1, _F2, types.FunctionType(EVALUATE)
    ),
    cache=CACHE,
)
def simulate(theta, n_outputs, n_terms, spec, work_init, U, starts, x0, evaluate):
    """Free-run simulation of every sequence.

    Parameters
    ----------
    theta : ndarray of shape (n_params,)
        Parameters (a trailing initial state in it is ignored: ``x0`` is used).
    n_outputs, n_terms : int
        Number of outputs and of the terms' parameters.
    spec : ndarray of int64
        Structure of the terms.
    work_init : ndarray of shape (work_size,)
        Initial content of the terms' work array (see the terms contract).
    U : ndarray of shape (n_samples, n_inputs)
    starts : ndarray of int64 of shape (n_sequences + 1,)
    x0 : ndarray of shape (n_sequences, n_states)
    evaluate : compiled function
        The terms' ``evaluate``.

    Returns
    -------
    Y : ndarray of shape (n_samples, n_outputs)
    X : ndarray of shape (n_samples, n_states)
        NaN from the first divergent sample to the end of its sequence.
    diverged : bool
    """
    n = x0.shape[1]
    n_u = U.shape[1]
    n_y = n_outputs
    A, B, C, D, o_terms = _linear_part(theta, n, n_u, n_y)
    theta_terms = theta[o_terms : o_terms + n_terms]
    n_samples = U.shape[0]
    Y = np.empty((n_samples, n_y))
    X = np.empty((n_samples, n))
    # s = [x; u] holds the current state. One inlined helper holds the step of
    # both kernels; against the same loops written out in each kernel it
    # measured 4 % slower here and 1 % in sensitivities, with the same results
    # to the bit (writing Y[t, i] in the helper instead of the row Y[t]
    # measured 12 % slower).
    s = np.empty(n + n_u)
    # Zero for terms without parameters, whose call is skipped (see above).
    h = np.zeros(n + n_y)
    work = work_init.copy()
    x_next = np.empty(n)
    diverged = False
    for seq in range(starts.shape[0] - 1):
        begin, end = starts[seq], starts[seq + 1]
        for i in range(n):
            s[i] = x0[seq, i]
        for t in range(begin, end):
            failed = _escaped(s, n, DIVERGENCE_BOUND)
            if not failed:
                for j in range(n_u):
                    s[n + j] = U[t, j]
                if n_terms > 0:
                    evaluate(theta_terms, spec, s, n, h, work)
                failed = _step(A, B, C, D, h, s, x_next, Y[t])
            if failed:
                Y[t:end] = np.nan
                X[t:end] = np.nan
                diverged = True
                break
            for i in range(n):
                X[t, i] = s[i]
                s[i] = x_next[i]
    return Y, X, diverged


@njit(
    types.Tuple((_F2, _F2, _F3, _F3, types.boolean))(
        _F1, _INT, _INT, _INT, _I1, _F1, _F2, _I1, _F2, types.boolean, types.boolean, _I1,
        types.boolean, types.FunctionType(EVALUATE), types.FunctionType(STATE_JACOBIAN),
        types.FunctionType(PARAMETER_JACOBIAN),
    ),
    cache=CACHE,
)
def sensitivities(theta, n_outputs, n_terms, n_state_terms, spec, work_init, U, starts,
                  x0, estimate_x0, x0_per_sequence, jacobian_rows, with_local, evaluate,
                  state_jacobian, parameter_jacobian):
    """Simulated outputs and states, and the outputs' Jacobian with respect to theta.

    Parameters are those of :func:`simulate`, plus

    n_state_terms : int
        Number of the terms' parameters that enter ``h_x``; they come first
        in ``theta_terms``.
    estimate_x0 : bool
        Whether theta ends with the initial state (its sensitivity starts at
        the identity in every sequence).
    x0_per_sequence : bool
        Whether theta holds one initial state per sequence (n_sequences *
        n_states values, in the order of the sequences) rather than one
        shared by all.
    jacobian_rows : ndarray of int64 of shape (n_samples,)
        Row of ``J`` receiving the derivatives of sample t, or -1 to skip the
        sample (e.g. a transient outside the cost): only the rows the cost
        needs are stored.
    with_local : bool
        Also return the local Jacobians of the state map on those rows (the
        stability penalty needs them, and they are computed here anyway).
    state_jacobian, parameter_jacobian : compiled functions
        The terms' other two functions.

    Returns
    -------
    Y : ndarray of shape (n_samples, n_outputs)
    X : ndarray of shape (n_samples, n_states)
    J : ndarray of shape (max(jacobian_rows) + 1, n_outputs, n_params)
    local : ndarray of shape (max(jacobian_rows) + 1, n_states, n_states)
        ``A + dh_x/dx`` on the rows of J, as :func:`local_jacobians` gives it
        (no rows without ``with_local``).
    diverged : bool
        When True, ``Y``, ``X`` and ``J`` are incomplete and must not be used.
    """
    n = x0.shape[1]
    n_u = U.shape[1]
    n_y = n_outputs
    n_params = theta.shape[0]
    A, B, C, D, o_terms = _linear_part(theta, n, n_u, n_y)
    theta_terms = theta[o_terms : o_terms + n_terms]
    o_b = n * n
    o_c = o_b + n * n_u
    o_d = o_c + n_y * n
    o_x0 = o_terms + n_terms
    # The state sensitivities hold the columns that move the state, in the
    # order A, B, the terms' state prefix, x0; their columns in theta:
    n_x0 = n if estimate_x0 else 0
    n_moving = o_c + n_state_terms + n_x0
    columns = np.empty(n_moving, dtype=np.int64)
    for k in range(o_c):
        columns[k] = k
    for k in range(n_state_terms):
        columns[o_c + k] = o_terms + k
    for k in range(n_x0):
        columns[o_c + n_state_terms + k] = o_x0 + k

    n_samples = U.shape[0]
    Y = np.empty((n_samples, n_y))
    X = np.empty((n_samples, n))
    n_rows = 0
    for t in range(n_samples):
        n_rows = max(n_rows, jacobian_rows[t] + 1)
    J = np.zeros((n_rows, n_y, n_params))
    local = np.empty((n_rows if with_local else 0, n, n))
    unused_rows = np.zeros((n_y, n_params))
    # As in simulate, s = [x; u] holds the current state.
    s = np.empty(n + n_u)
    h = np.empty(n + n_y)
    work = work_init.copy()
    M = np.empty((n + n_y, n))
    x_next = np.empty(n)
    current = np.zeros((n, n_moving))
    following = np.empty((n, n_moving))
    output_row = np.empty(n_moving)
    for seq in range(starts.shape[0] - 1):
        for i in range(n):
            s[i] = x0[seq, i]
        if x0_per_sequence:
            for k in range(n_x0):
                columns[o_c + n_state_terms + k] = o_x0 + seq * n + k
        current[:] = 0.0
        for i in range(n_x0):
            current[i, n_moving - n_x0 + i] = 1.0
        for t in range(starts[seq], starts[seq + 1]):
            if _escaped(s, n, DIVERGENCE_BOUND):
                return Y, X, J, local, True
            for j in range(n_u):
                s[n + j] = U[t, j]
            evaluate(theta_terms, spec, s, n, h, work)
            if _step(A, B, C, D, h, s, x_next, Y[t]):
                return Y, X, J, local, True
            for i in range(n):
                X[t, i] = s[i]
            # Local Jacobians of [x(t+1); y(t)] with respect to x(t): [A; C] + dh/dx.
            state_jacobian(theta_terms, spec, s, n, M, work)
            for i in range(n):
                for j in range(n):
                    M[i, j] += A[i, j]
            for i in range(n_y):
                for j in range(n):
                    M[n + i, j] += C[i, j]
            # Propagated part and direct dependence of the linear part. The
            # innermost loops run along the sensitivity columns (contiguous,
            # so they vectorise); every entry sums its products in the order
            # j = 0, 1, ... all the same.
            for i in range(n):
                # 0.0 + p, as the sum started from zero would give (-0.0 included).
                weight = M[i, 0]
                for c in range(n_moving):
                    following[i, c] = 0.0 + weight * current[0, c]
                for j in range(1, n):
                    weight = M[i, j]
                    for c in range(n_moving):
                        following[i, c] += weight * current[j, c]
                for j in range(n):
                    following[i, i * n + j] += s[j]
                for j in range(n_u):
                    following[i, o_b + i * n_u + j] += s[n + j]
            row = jacobian_rows[t]
            if row < 0:
                parameter_jacobian(theta_terms, spec, s, n, work, following, o_c,
                                   unused_rows, -1)
            else:
                out = J[row]
                for i in range(n_y):
                    for c in range(n_moving):
                        output_row[c] = 0.0
                    for j in range(n):
                        weight = M[n + i, j]
                        for c in range(n_moving):
                            output_row[c] += weight * current[j, c]
                    for c in range(n_moving):
                        out[i, columns[c]] = output_row[c]
                    for j in range(n):
                        out[i, o_c + i * n + j] += s[j]
                    for j in range(n_u):
                        out[i, o_d + i * n_u + j] += s[n + j]
                parameter_jacobian(theta_terms, spec, s, n, work, following, o_c, out,
                                   o_terms)
                if with_local:
                    for i in range(n):
                        for j in range(n):
                            local[row, i, j] = M[i, j]
            for i in range(n):
                s[i] = x_next[i]
                for c in range(n_moving):
                    # Written back rather than swapping the two arrays: the
                    # same values, 8 % to 24 % faster (measured with 2 to 5
                    # states).
                    value = following[i, c]
                    current[i, c] = 0.0 if abs(value) < NEGLIGIBLE_SENSITIVITY else value
    return Y, X, J, local, False


@njit(
    _F3(_F1, _INT, _INT, _INT, _I1, _F1, _F2, types.FunctionType(EVALUATE),
        types.FunctionType(STATE_JACOBIAN)),
    cache=CACHE,
)
def local_jacobians(theta, n_states, n_outputs, n_terms, spec, work_init, S, evaluate,
                    state_jacobian):
    """Jacobians of ``[x(t+1); y(t)]`` with respect to ``x(t)`` at the points ``S``.

    Parameters
    ----------
    theta, n_outputs, n_terms, spec, work_init, evaluate, state_jacobian
        As in :func:`sensitivities`.
    n_states : int
        Number of states.
    S : ndarray of shape (n_points, n_states + n_inputs)
        Points ``[x; u]``.

    Returns
    -------
    jacobians : ndarray of shape (n_points, n_states + n_outputs, n_states)
        ``[A; C] + dh/dx`` at every point.
    """
    n, n_y = n_states, n_outputs
    A, B, C, D, o_terms = _linear_part(theta, n, S.shape[1] - n, n_y)
    theta_terms = theta[o_terms : o_terms + n_terms]
    h = np.empty(n + n_y)
    work = work_init.copy()
    out = np.empty((S.shape[0], n + n_y, n))
    s = np.empty(S.shape[1])
    for t in range(S.shape[0]):
        s[:] = S[t]
        evaluate(theta_terms, spec, s, n, h, work)
        state_jacobian(theta_terms, spec, s, n, out[t], work)
        for i in range(n):
            for j in range(n):
                out[t, i, j] += A[i, j]
        for i in range(n_y):
            for j in range(n):
                out[t, n + i, j] += C[i, j]
    return out


@njit(
    _F2(_F1, _INT, _INT, _INT, _INT, _I1, _F1, _F2, _F3, types.float64,
        types.FunctionType(EVALUATE), types.FunctionType(STATE_JACOBIAN),
        types.FunctionType(PARAMETER_JACOBIAN)),
    cache=CACHE,
)
def curvature_contraction(theta, n_states, n_outputs, n_terms, n_state_terms, spec,
                          work_init, S, G, step, evaluate, state_jacobian,
                          parameter_jacobian):
    """``sum_ij G[t, i, j] d^2 h_x,i / dx_j dtheta_k`` at the points ``S``.

    The derivative of ``sum_ij G_ij (dh_x/dx)_ij`` with respect to the terms'
    parameters that enter ``h_x``, by central differences in the states of
    the terms' parameter Jacobian (2 n evaluations per point, whatever the
    number of parameters).

    Parameters
    ----------
    theta, n_outputs, n_terms, n_state_terms, spec, work_init
        As in :func:`sensitivities`.
    n_states : int
    S : ndarray of shape (n_points, n_states + n_inputs)
        Points ``[x; u]``.
    G : ndarray of shape (n_points, n_states, n_states)
        Weights of the entries of ``dh_x/dx``.
    step : float
        Difference step in the states.
    evaluate, state_jacobian, parameter_jacobian : compiled functions
        The terms' functions.

    Returns
    -------
    contraction : ndarray of shape (n_points, n_state_terms)
    """
    n, n_y = n_states, n_outputs
    theta_terms, h, dh_dx, work = _terms_buffers(theta, n, S.shape[1] - n, n_y, n_terms,
                                                 work_init)
    upper = np.empty((n, n_state_terms))
    lower = np.empty((n, n_state_terms))
    unused = np.empty((n_y, 1))
    s = np.empty(S.shape[1])
    out = np.zeros((S.shape[0], n_state_terms))
    for t in range(S.shape[0]):
        for j in range(n):
            for sign, target in ((1.0, upper), (-1.0, lower)):
                s[:] = S[t]
                s[j] += sign * step
                target[:] = 0.0
                evaluate(theta_terms, spec, s, n, h, work)
                state_jacobian(theta_terms, spec, s, n, dh_dx, work)
                parameter_jacobian(theta_terms, spec, s, n, work, target, 0, unused, -1)
            for i in range(n):
                weight = G[t, i, j] / (2.0 * step)
                for k in range(n_state_terms):
                    out[t, k] += weight * (upper[i, k] - lower[i, k])
    return out


@njit(
    _F1(_F1, _INT, _INT, _INT, _INT, _I1, _F1, _F2, types.FunctionType(EVALUATE),
        types.FunctionType(STATE_JACOBIAN), types.FunctionType(PARAMETER_JACOBIAN)),
    cache=CACHE,
)
def parameter_rms(theta, n_states, n_outputs, n_terms, n_state_terms, spec, work_init, S,
                  evaluate, state_jacobian, parameter_jacobian):
    """RMS over the points ``S`` of the direct derivative of ``h`` with respect
    to each of the terms' parameters (the size of each parameter's
    contribution per unit of the parameter).

    Returns
    -------
    rms : ndarray of shape (n_terms,)
    """
    n, n_y = n_states, n_outputs
    theta_terms, h, dh_dx, work = _terms_buffers(theta, n, S.shape[1] - n, n_y, n_terms,
                                                 work_init)
    state_out = np.empty((n, n_state_terms))
    output_out = np.empty((n_y, n_terms))
    s = np.empty(S.shape[1])
    total = np.zeros(n_terms)
    for t in range(S.shape[0]):
        s[:] = S[t]
        state_out[:] = 0.0
        output_out[:] = 0.0
        evaluate(theta_terms, spec, s, n, h, work)
        state_jacobian(theta_terms, spec, s, n, dh_dx, work)
        parameter_jacobian(theta_terms, spec, s, n, work, state_out, 0, output_out, 0)
        for k in range(n_terms):
            acc = 0.0
            for i in range(n_y):
                acc += output_out[i, k] ** 2
            if k < n_state_terms:
                for i in range(n):
                    acc += state_out[i, k] ** 2
            total[k] += acc
    return np.sqrt(total / max(S.shape[0], 1))


# ---------------------------------------------------------------- no terms
@njit(EVALUATE, cache=CACHE)
def no_terms_evaluate(theta_terms, spec, s, n_states, h, work):
    """Terms of a linear model: zero."""
    h[:] = 0.0


@njit(STATE_JACOBIAN, cache=CACHE)
def no_terms_state_jacobian(theta_terms, spec, s, n_states, dh_dx, work):
    """State derivatives of the zero terms."""
    dh_dx[:] = 0.0


@njit(PARAMETER_JACOBIAN, cache=CACHE)
def no_terms_parameter_jacobian(theta_terms, spec, s, n_states, work, state_out,
                                state_offset, output_out, output_offset):
    """The zero terms have no parameters."""
