"""Branch terms: univariate static nonlinearities between two linear maps.

The terms are ``h(s) = W f(V^T s)`` with ``s = [x; u]``, ``r`` branches and
``f_l(z) = sum_k c[l, k] phi_k(z)`` over a univariate basis (see
:mod:`sknlss._terms._bases`). For a basis that shifts (``basis.shifted``),
each branch input has a bias ``b_l`` and the branch is anchored at ``s = 0``:
``f_l(z) = sum_k c[l, k] (phi_k(z + b_l) - phi_k(b_l))``, so that ``h(0) = 0``
and the zero state stays the rest state of the model at the mean input (a
bias moves the branch along its input, not the model's operating point).
Written as a linear-fractional model with the branch inputs
``z = Cz x + Dz u`` (plus ``b``) and outputs ``w = f(z)``,

    x(t+1) = A x + B u + Bw w,   y(t) = C x + D u + Dw w,

``V^T = [Cz, Dz]`` and ``W = [Bw; Dw]``: the NL-LFR model, and the decoupled
PNLSS model with a power basis. The terms' parameters are
``[vec(V), b, vec(c), vec(W)]`` (row-major; ``b`` only for a shifting basis),
so that the parameters entering ``h_x`` (V, b, c and the rows of W for the
states) come first.

The basis functions of every family (:mod:`sknlss._terms._bases`) are
compiled here, inlined into the kernels below: numba renews the cache of a
compiled function when its own file changes, so the code it inlines lives in
the same file.
"""

import numpy as np
from numba import njit

from .._core._kernels import CACHE, EVALUATE, PARAMETER_JACOBIAN, STATE_JACOBIAN
from .._core._model import RangedTerms, parameter_count

#: Codes of the basis families in the compiled code.
POWERS, LEGENDRE, CHEBYSHEV = 0, 1, 2
BASIS_CODES = (POWERS, LEGENDRE, CHEBYSHEV)


@njit(cache=CACHE, inline="always")
def basis_functions(code, degrees, z, out, o_values, o_slopes):
    """Values and derivatives of the basis functions of the given degrees at ``z``.

    ``code`` selects the family: powers ``z**d``, or Legendre ``P_d`` or
    Chebyshev ``T_d`` polynomials of ``tanh(z)``, which stay bounded however
    far ``z`` goes. ``degrees`` are increasing; the values and the
    derivatives with respect to ``z`` are written to ``out`` from the offsets
    ``o_values`` and ``o_slopes``, one entry per degree.
    """
    top = 0
    for d in degrees:
        top = max(top, d)
    if code == POWERS:
        for k in range(degrees.shape[0]):
            d = degrees[k]
            # Compiled code must not raise (z ** -1 at z = 0): degree 0 apart.
            out[o_values + k] = z**d if d > 0 else 1.0
            out[o_slopes + k] = d * z ** (d - 1) if d > 0 else 0.0
        return
    t = np.tanh(z)
    chain = 1.0 - t * t
    # Three-term recurrences in the degree d, carrying the polynomials of
    # degrees d - 1 and d and their derivatives; the degrees are increasing.
    p_prev, p_cur, dp_prev, dp_cur = 0.0, 1.0, 0.0, 0.0
    k = 0
    for d in range(top + 1):
        while k < degrees.shape[0] and degrees[k] == d:
            out[o_values + k] = p_cur
            out[o_slopes + k] = dp_cur * chain
            k += 1
        if d == 0:
            p_next, dp_next = t, 1.0
        elif code == LEGENDRE:
            p_next = ((2 * d + 1) * t * p_cur - d * p_prev) / (d + 1)
            dp_next = dp_prev + (2 * d + 1) * p_cur
        else:
            p_next = 2.0 * t * p_cur - p_prev
            dp_next = 2.0 * p_cur + 2.0 * t * dp_cur - dp_prev
        p_prev, p_cur, dp_prev, dp_cur = p_cur, p_next, dp_cur, dp_next


@njit(cache=CACHE)
def evaluate_basis(code, degrees, z):
    """Values and slopes of the basis functions at the points ``z``, as the
    kernels of this module compute them."""
    m = degrees.shape[0]
    out = np.empty((z.shape[0], 2 * m))
    for t in range(z.shape[0]):
        basis_functions(code, degrees, z[t], out[t], 0, m)
    return out[:, :m].copy(), out[:, m:].copy()


# spec = [rank, n_functions, basis code, shift (0 or 1), degrees ...]
# work = [lower (r), upper (r), g (r), g' (r), phi (r x n_functions),
#         phi' (r x n_functions)], and with shift [g'(b) (r), the basis at the
#         biases (r x n_functions), scratch (n_functions), ready (1)]; the range
#         [lower, upper] of each branch input, beyond which its function
#         continues linearly, is set by work_init. The anchors (the basis at the
#         biases, and g'(b)) depend on the parameters only, which are fixed
#         during a kernel call: the first evaluation of the call computes them
#         and sets ready (work starts as a copy of work_init in every call).
_HEADER = 4


@njit(cache=CACHE, inline="always")
def _layout(spec, n_vars):
    """Number of branches and of basis functions, whether the branch inputs
    have biases, and the offsets of b, c and W in the terms' parameters."""
    rank, n_fun, shifted = spec[0], spec[1], spec[3] != 0
    o_bias = n_vars * rank
    o_coef = o_bias + rank if shifted else o_bias
    o_w = o_coef + rank * n_fun
    return rank, n_fun, shifted, o_bias, o_coef, o_w


@njit(cache=CACHE, inline="always")
def _work_layout(rank, n_fun):
    """Offsets in ``work`` of g, g', phi, phi', g'(b), the basis at b, the
    scratch and the ready flag."""
    o_phi = 4 * rank
    o_dphi = o_phi + rank * n_fun
    o_anchor_slope = o_dphi + rank * n_fun
    o_anchor = o_anchor_slope + rank
    o_scratch = o_anchor + rank * n_fun
    return (2 * rank, 3 * rank, o_phi, o_dphi, o_anchor_slope, o_anchor, o_scratch,
            o_scratch + n_fun)


def _work_size(rank, n_fun, shifted):
    return 4 * rank + 2 * rank * n_fun + (rank * (n_fun + 1) + n_fun + 1 if shifted else 0)


@njit(cache=CACHE, inline="always")
def _continued_basis(code, degrees, z, lower, upper, work, o_values, o_slopes):
    """The basis functions at ``z``, and their slopes, written to ``work``:
    beyond the range [lower, upper], along their tangents at the nearer end."""
    inside = min(max(z, lower), upper)
    basis_functions(code, degrees, inside, work, o_values, o_slopes)
    if inside != z:
        for k in range(degrees.shape[0]):
            work[o_values + k] += work[o_slopes + k] * (z - inside)


@njit(EVALUATE, cache=CACHE)
def _evaluate(theta, spec, s, n, h, work):
    n_vars = s.shape[0]
    rank, n_fun, shifted, o_bias, o_coef, o_w = _layout(spec, n_vars)
    code = spec[2]
    degrees = spec[_HEADER : _HEADER + n_fun]
    o_g, o_dg, o_phi, o_dphi, o_anchor_slope, o_anchor, o_scratch, o_ready = _work_layout(
        rank, n_fun)
    if shifted and work[o_ready] == 0.0:
        for l in range(rank):
            _continued_basis(code, degrees, theta[o_bias + l], work[l], work[rank + l], work,
                             o_anchor + l * n_fun, o_scratch)
            anchor_slope = 0.0
            for k in range(n_fun):
                anchor_slope += theta[o_coef + l * n_fun + k] * work[o_scratch + k]
            work[o_anchor_slope + l] = anchor_slope
        work[o_ready] = 1.0
    for l in range(rank):
        z = theta[o_bias + l] if shifted else 0.0
        for j in range(n_vars):
            z += theta[j * rank + l] * s[j]
        o_values, o_slopes = o_phi + l * n_fun, o_dphi + l * n_fun
        _continued_basis(code, degrees, z, work[l], work[rank + l], work, o_values, o_slopes)
        if shifted:
            for k in range(n_fun):
                work[o_values + k] -= work[o_anchor + l * n_fun + k]
        g = 0.0
        dg = 0.0
        for k in range(n_fun):
            c = theta[o_coef + l * n_fun + k]
            g += c * work[o_values + k]
            dg += c * work[o_slopes + k]
        work[o_g + l] = g
        work[o_dg + l] = dg
    for i in range(h.shape[0]):
        acc = 0.0
        for l in range(rank):
            acc += theta[o_w + i * rank + l] * work[o_g + l]
        h[i] = acc


@njit(STATE_JACOBIAN, cache=CACHE)
def _state_jacobian(theta, spec, s, n, dh_dx, work):
    rank, n_fun, _, _, _, o_w = _layout(spec, s.shape[0])
    o_dg = _work_layout(rank, n_fun)[1]
    for i in range(dh_dx.shape[0]):
        for j in range(n):
            acc = 0.0
            for l in range(rank):
                acc += theta[o_w + i * rank + l] * work[o_dg + l] * theta[j * rank + l]
            dh_dx[i, j] = acc


@njit(cache=CACHE, inline="always")
def _add_rows(theta, spec, s, work, first_row, out, out_offset):
    """Derivatives of ``h[first_row:first_row + len(out)]`` with respect to V,
    b, c and W added to ``out`` from column ``out_offset``."""
    rank, n_fun, shifted, o_bias, o_coef, o_w = _layout(spec, s.shape[0])
    o_g, o_dg, o_phi, _, o_anchor_slope, _, _, _ = _work_layout(rank, n_fun)
    for r in range(out.shape[0]):
        i = first_row + r
        row = out[r]
        for l in range(rank):
            w = theta[o_w + i * rank + l]
            slope = w * work[o_dg + l]
            for j in range(s.shape[0]):
                row[out_offset + j * rank + l] += slope * s[j]
            if shifted:
                row[out_offset + o_bias + l] += slope - w * work[o_anchor_slope + l]
            for k in range(n_fun):
                row[out_offset + o_coef + l * n_fun + k] += w * work[o_phi + l * n_fun + k]
            row[out_offset + o_w + i * rank + l] += work[o_g + l]


@njit(PARAMETER_JACOBIAN, cache=CACHE)
def _parameter_jacobian(theta, spec, s, n, work, state_out, state_offset, output_out,
                        output_offset):
    _add_rows(theta, spec, s, work, 0, state_out, state_offset)
    if output_offset >= 0:
        _add_rows(theta, spec, s, work, n, output_out, output_offset)


class BranchTerms(RangedTerms):
    """``h(s) = W f(V^T s + b)`` with ``rank`` univariate branches over ``basis``.

    Parameters
    ----------
    n_states, n_inputs, n_outputs : int
        Dimensions.
    rank : int
        Number of branches.
    basis : basis object
        Univariate basis of the branches (:mod:`sknlss._terms._bases`); the
        biases ``b`` are parameters when ``basis.shifted``.
    input_range : ndarray of shape (2, rank), default=None
        Lower and upper ends of the range of each branch input inside which
        its function is the basis combination; beyond, the function continues
        along its tangent at the nearer end. ``None``: the basis combination
        everywhere.
    reach : float, default=1.0
        The basis combination holds out to ``reach`` times the half-width of
        ``input_range`` about its centre, the tangents beyond; ``inf``: the
        basis combination everywhere (the range is then only a record of
        where the branch inputs went).
    """

    evaluate = staticmethod(_evaluate)
    state_jacobian = staticmethod(_state_jacobian)
    parameter_jacobian = staticmethod(_parameter_jacobian)

    def __init__(self, n_states, n_inputs, n_outputs, rank, basis, input_range=None,
                 reach=1.0):
        degrees = basis.degrees
        shifted = basis.shifted
        n_fun = len(degrees)
        self.basis = basis
        self.dimensions = (n_states, n_inputs, n_outputs)
        self.rank = rank
        self.blocks = self.layout(n_states, n_inputs, n_outputs, rank, n_fun, shifted)
        self.spec = np.concatenate([[rank, n_fun, basis.code, shifted],
                                    degrees]).astype(np.int64)
        self.work_size = _work_size(rank, n_fun, shifted)
        # Every block but the rows of W for the outputs enters h_x.
        self.n_state_params = parameter_count(self.blocks) - n_outputs * rank
        # The range of the branch inputs heads the work.
        self._set_range(input_range, reach, rank)

    def with_input_range(self, values, S, reach=1.0):
        """The same terms with the range that the branch inputs take at the
        points ``S = [x; u]`` (parameter blocks ``values``), held out to
        ``reach`` times its half-width. The range of a shifted branch also
        holds its bias, the input at ``s = 0`` where it is anchored, so that
        the anchor is the value the fit used."""
        Z = S @ values["V"]
        if "bias" in values:
            Z = np.vstack([Z + values["bias"], values["bias"]])
        return BranchTerms(*self.dimensions, self.rank, self.basis,
                           np.vstack([Z.min(axis=0), Z.max(axis=0)]), reach)

    @staticmethod
    def layout(n_states, n_inputs, n_outputs, rank, n_functions, shifted=False):
        """The parameter blocks ``(name, shape)``, known before the terms are
        built (``shifted``: the branch inputs have biases)."""
        bias = [("bias", (rank,))] if shifted else []
        return [("V", (n_states + n_inputs, rank)), *bias,
                ("coefficients", (rank, n_functions)), ("W", (n_states + n_outputs, rank))]

    def decay_mask(self):
        """The branch coefficients and the output directions W are decayed; the
        input directions V and biases b are not (their scale trades with the
        coefficients', and a bias only moves a branch along its input)."""
        mask = np.ones(self.n_params, dtype=bool)
        mask[: parameter_count([block for block in self.blocks
                                if block[0] in ("V", "bias")])] = False
        return mask
