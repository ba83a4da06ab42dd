"""Polynomial terms of the PNLSS model.

The nonlinear terms of a PNLSS model are ``h_x = E zeta(s)`` and
``h_y = F eta(s)``, where zeta and eta hold monomials in the stacked vector
``s = [x; u]``. A set of monomials is represented by an integer exponent array
of shape (n_monomials, n_states + n_inputs): row k holds the power of each
variable in monomial k. The terms' parameters are ``[vec(E), vec(F)]``
(row-major).

The monomials are evaluated by the compiled routines here only, for the
simulation kernels and for the batch functions :func:`evaluate_monomials` and
:func:`monomial_jacobian`.
"""

from itertools import combinations_with_replacement
from math import comb
from numbers import Integral

import numpy as np
from numba import njit

from .._core._kernels import CACHE, EVALUATE, PARAMETER_JACOBIAN, STATE_JACOBIAN
from .._core._model import RangedTerms

#: Monomial selections understood by :func:`monomial_exponents`.
STRUCTURES = ("full", "states_only", "no_cross_products", "inputs_only", "empty")
#: Largest total degree of a monomial: a higher power overflows double
#: precision as soon as its variable reaches 2 in magnitude (2**1024 is beyond
#: the largest float), which normalised signals do; the compiled evaluation
#: also tabulates every power up to it.
MAX_DEGREE = 1023


def _as_degrees(degree):
    """Return the sorted unique degrees (each >= 2) from an int or iterable."""
    if isinstance(degree, Integral) and not isinstance(degree, bool):
        degrees = [int(degree)]
    else:
        try:
            degrees = list(degree)
        except TypeError:
            raise ValueError(
                f"degree must be an int or an iterable of ints, got {degree!r}."
            ) from None
        if not degrees or not all(
            isinstance(d, Integral) and not isinstance(d, bool) for d in degrees
        ):
            raise ValueError(
                f"degree must be an int or a non-empty iterable of ints, got {degree!r}."
            )
        degrees = [int(d) for d in degrees]
    if min(degrees) < 2 or max(degrees) > MAX_DEGREE:
        raise ValueError(
            f"Polynomial degrees must be >= 2 (the linear part is A, B, C, D) and at "
            f"most {MAX_DEGREE}, got degree={degree!r}."
        )
    return sorted(set(degrees))


def _validate_exponents(exponents, n_vars):
    """Check an explicit exponent array and return it as int64."""
    arr = np.asarray(exponents, dtype=np.float64)
    if arr.ndim != 2 or arr.shape[1] != n_vars:
        raise ValueError(
            f"An explicit exponent array must have shape (n_terms, {n_vars}) "
            f"(n_states + n_inputs columns), got shape {arr.shape}."
        )
    if not np.all(np.isfinite(arr)) or not np.all(arr == np.round(arr)) or np.any(arr < 0):
        raise ValueError("The exponent array must hold non-negative integers.")
    total = arr.sum(axis=1)
    if np.any(total < 2) or np.any(total > MAX_DEGREE):
        raise ValueError(
            "Every monomial must have total degree >= 2 (the linear part is "
            f"A, B, C, D) and at most {MAX_DEGREE}."
        )
    arr = arr.astype(np.int64)
    if len(np.unique(arr, axis=0)) != len(arr):
        raise ValueError("The exponent array has duplicate rows.")
    return np.ascontiguousarray(arr)


def n_monomials(n_states, n_inputs, degree, structure="full"):
    """Number of rows of :func:`monomial_exponents`, counted without listing them.

    A model's size is checked against the data and the memory before its
    monomials are listed: with many states there can be billions of them.

    Parameters
    ----------
    n_states, n_inputs, degree, structure
        As in :func:`monomial_exponents`.

    Returns
    -------
    count : int
    """
    n_vars = int(n_states) + int(n_inputs)
    if not isinstance(structure, str):
        return len(_validate_exponents(structure, n_vars))
    if structure not in STRUCTURES:
        raise ValueError(
            f"structure must be one of {STRUCTURES} or an exponent array, "
            f"got {structure!r}."
        )
    if structure == "no_cross_products":
        return n_vars * len(_as_degrees(degree))
    # Monomials of total degree d in k variables: multisets of size d.
    k = {"full": n_vars, "states_only": int(n_states), "inputs_only": int(n_inputs),
         "empty": 0}[structure]
    return sum(comb(k + d - 1, d) for d in _as_degrees(degree)) if k else 0


def monomial_exponents(n_states, n_inputs, degree, structure="full"):
    """Exponents of the monomials in s = [x; u] used by a PNLSS model.

    Parameters
    ----------
    n_states : int
        Number of states (the first ``n_states`` variables of s).
    n_inputs : int
        Number of inputs (the last ``n_inputs`` variables of s).
    degree : int or iterable of int
        Total degrees of the monomials, each >= 2, e.g. ``(2, 3)``.
    structure : {"full", "states_only", "no_cross_products", "inputs_only", \
            "empty"} or array-like of shape (n_terms, n_states + n_inputs)
        Which monomials to keep: all of them, those in x only, the pure powers
        of single variables only, those in u only, or none. An explicit
        exponent array is validated and returned as is (``degree`` is then
        ignored).

    Returns
    -------
    exponents : ndarray of shape (n_terms, n_states + n_inputs), dtype int64
        Ordered by degree, then in the order of
        :func:`itertools.combinations_with_replacement` over the variable
        indices.

    Examples
    --------
    >>> from sknlss._terms._polynomial import monomial_exponents
    >>> monomial_exponents(1, 1, 2)
    array([[2, 0],
           [1, 1],
           [0, 2]])
    """
    n_vars = int(n_states) + int(n_inputs)
    if not isinstance(structure, str):
        return _validate_exponents(structure, n_vars)
    if structure not in STRUCTURES:
        raise ValueError(
            f"structure must be one of {STRUCTURES} or an exponent array, "
            f"got {structure!r}."
        )
    allowed = {
        "full": range(n_vars),
        "no_cross_products": range(n_vars),
        "states_only": range(n_states),
        "inputs_only": range(n_states, n_vars),
        "empty": range(0),
    }[structure]
    rows = []
    for d in _as_degrees(degree):
        for combo in combinations_with_replacement(range(n_vars), d):
            if not set(combo) <= set(allowed):
                continue
            if structure == "no_cross_products" and len(set(combo)) > 1:
                continue
            row = np.zeros(n_vars, dtype=np.int64)
            np.add.at(row, list(combo), 1)
            rows.append(row)
    if not rows:
        return np.zeros((0, n_vars), dtype=np.int64)
    return np.array(rows, dtype=np.int64)


# ------------------------------------------------------- compiled evaluation
# The monomials are evaluated from integer tables (the "spec") built once per
# exponent array, into a flat scratch array ("work"):
#
# spec = [n_vars, n_monomials, width, n_factors, n_diff, n_entries,
#         factors (n_monomials x (n_factors + 1)),
#         derivative entries (n_entries x (n_factors + 2))]
# work = [powers (n_vars x width), monomials (n_monomials),
#         derivatives (n_monomials x n_diff)]
#
# (the terms append the box of the tangent continuation, see below)
#
# with ``work[j * width + p] = s_j ** p`` and n_factors the largest number of
# variables in a monomial. Row k of ``factors`` holds the number of variables
# of monomial k, then the positions in work of their powers, whose product is
# the monomial, in the order of the variables. There is a derivative entry for
# each monomial k and variable i that it contains: the position
# ``k * n_diff + i`` of the derivative, the exponent e of s_i, the position of
# ``s_i ** (e - 1)`` and those of the other factors, padded with position 0
# (``s_0 ** 0 = 1``); the derivatives of the monomials without s_i are zero
# and never computed. The compiled functions index the flat arrays directly:
# views made at every sample would cost more than the arithmetic.
_HEADER = 6


def _monomial_spec(exponents, n_diff):
    """The integer tables of the monomials ``exponents`` (see above), with
    derivatives with respect to the first ``n_diff`` variables."""
    exponents = np.asarray(exponents, dtype=np.int64)
    n_monomials, n_vars = exponents.shape
    width = _max_degree(exponents) + 1
    n_factors = max(1, int(np.count_nonzero(exponents, axis=1).max(initial=0)))
    factors = np.zeros((n_monomials, n_factors + 1), dtype=np.int64)
    entries = []
    for k, row in enumerate(exponents):
        present = [(j, int(e)) for j, e in enumerate(row) if e]
        factors[k, : len(present) + 1] = [len(present), *(j * width + e for j, e in present)]
        for i in range(n_diff):
            if row[i]:
                others = [j * width + e for j, e in present if j != i]
                entry = np.zeros(n_factors + 2, dtype=np.int64)
                entry[: 3 + len(others)] = [k * n_diff + i, row[i], i * width + row[i] - 1,
                                            *others]
                entries.append(entry)
    header = [n_vars, n_monomials, width, n_factors, n_diff, len(entries)]
    return np.concatenate([header, factors.ravel(), *entries]).astype(np.int64)


@njit(cache=CACHE, inline="always")
def _work_size(spec):
    """Size of the monomials' work (where the terms' box starts)."""
    n_vars, n_monomials, width, n_diff = spec[0], spec[1], spec[2], spec[4]
    return n_vars * width + n_monomials * (1 + n_diff)


@njit(cache=CACHE, inline="always")
def _fill_monomials(spec, s, work):
    """Powers of ``s`` and the monomials, into work."""
    n_vars, n_monomials, width, n_factors = spec[0], spec[1], spec[2], spec[3]
    for j in range(n_vars):
        base = j * width
        work[base] = 1.0
        for p in range(1, width):
            work[base + p] = work[base + p - 1] * s[j]
    o_values = n_vars * width
    for k in range(n_monomials):
        value = 1.0
        row = _HEADER + k * (n_factors + 1)
        for f in range(spec[row]):
            value *= work[spec[row + 1 + f]]
        work[o_values + k] = value


@njit(cache=CACHE, inline="always")
def _fill_derivatives(spec, work):
    """The nonzero derivatives of the monomials, into work (after
    :func:`_fill_monomials`); the others are left as they were."""
    n_vars, n_monomials, width, n_factors, n_entries = (spec[0], spec[1], spec[2], spec[3],
                                                        spec[5])
    o_entries = _HEADER + n_monomials * (n_factors + 1)
    o_out = n_vars * width + n_monomials
    for q in range(n_entries):
        row = o_entries + q * (n_factors + 2)
        value = spec[row + 1] * work[spec[row + 2]]
        for f in range(n_factors - 1):
            value *= work[spec[row + 3 + f]]
        work[o_out + spec[row]] = value


def _max_degree(exponents):
    return max(1, int(exponents.max(initial=0)))


@njit(cache=CACHE)
def _batch_values(S, spec, work):
    n_vars, n_monomials, width = spec[0], spec[1], spec[2]
    o_values = n_vars * width
    values = np.empty((S.shape[0], n_monomials))
    for t in range(S.shape[0]):
        _fill_monomials(spec, S[t], work)
        for k in range(n_monomials):
            values[t, k] = work[o_values + k]
    return values


@njit(cache=CACHE)
def _batch_derivatives(S, spec, work):
    n_vars, n_monomials, width = spec[0], spec[1], spec[2]
    o_out = n_vars * width + n_monomials
    derivatives = np.empty((S.shape[0], n_monomials, n_vars))
    work[o_out:] = 0.0
    for t in range(S.shape[0]):
        _fill_monomials(spec, S[t], work)
        _fill_derivatives(spec, work)
        for k in range(n_monomials):
            for i in range(n_vars):
                derivatives[t, k, i] = work[o_out + k * n_vars + i]
    return derivatives


def _as_points(S, exponents, n_diff):
    S = np.ascontiguousarray(S, dtype=np.float64)
    spec = _monomial_spec(exponents, n_diff)
    return S, spec, np.empty(_work_size(spec))


def evaluate_monomials(S, exponents):
    """Evaluate monomials at the rows of S.

    Parameters
    ----------
    S : ndarray of shape (n_samples, n_vars)
        Points (stacked [x; u] per row).
    exponents : ndarray of shape (n_terms, n_vars)
        Exponent array from :func:`monomial_exponents`.

    Returns
    -------
    values : ndarray of shape (n_samples, n_terms)
    """
    return _batch_values(*_as_points(S, exponents, 0))


def monomial_jacobian(S, exponents):
    """Derivatives of the monomials with respect to each variable.

    Parameters
    ----------
    S : ndarray of shape (n_samples, n_vars)
        Points (stacked [x; u] per row).
    exponents : ndarray of shape (n_terms, n_vars)
        Exponent array from :func:`monomial_exponents`.

    Returns
    -------
    jacobian : ndarray of shape (n_samples, n_terms, n_vars)
        ``jacobian[t, k, j]`` is the derivative of monomial k with respect
        to variable j at the point ``S[t]``.
    """
    S, spec, work = _as_points(S, exponents, np.shape(exponents)[1])
    return _batch_derivatives(S, spec, work)


# ------------------------------------------------------------------ the terms
# zeta and eta usually hold the same monomials (the "full" structures of both
# equations), so each distinct monomial is evaluated once. The terms' spec is
#
#   [monomials' spec of the distinct rows of [state exponents; output exponents],
#    positions of the zeta monomials among them (n_zeta), those of eta (n_eta),
#    for each state j the zeta monomials that contain x_j (n_states + 1 bounds,
#    then the indices), the same for eta,
#    the offsets in spec of the zeta positions, the eta positions, the zeta
#    bounds and the eta bounds, then n_zeta, n_eta]
#
# Derivatives are taken with respect to the states, and the sums of the state
# Jacobian skip the monomials without x_j: their terms are exact zeros.
_TAIL = 6


@njit(cache=CACHE, inline="always")
def _offsets(spec):
    """n_zeta, n_eta, the offsets in spec of the zeta and eta positions and of
    their tables of monomials by state, and the offsets in work of the
    monomials and of their derivatives."""
    n_vars, n_monomials, width = spec[0], spec[1], spec[2]
    o_tail = spec.shape[0] - _TAIL
    o_values = n_vars * width
    return (spec[o_tail + 4], spec[o_tail + 5], spec[o_tail], spec[o_tail + 1],
            spec[o_tail + 2], spec[o_tail + 3], o_values, o_values + n_monomials)


def _containing(exponents, n_states):
    """For each state j, the rows of ``exponents`` with a nonzero power of
    x_j: bounds (n_states + 1) and row indices."""
    rows = [np.flatnonzero(exponents[:, j]) for j in range(n_states)]
    bounds = np.concatenate([[0], np.cumsum([len(r) for r in rows], dtype=np.int64)])
    return bounds, np.concatenate([np.zeros(0, dtype=np.int64), *rows])


# Beyond a box [lower, upper] of the points s (the range that each variable
# took on the estimation record, possibly widened), the monomials go on along
# their tangent planes at the nearest point c = clip(s) of the box:
#
#   m(s) = m(c) + sum_j dm/ds_j(c) (s_j - c_j),
#
# whose derivative with respect to a state x_i is dm/dx_i(c) when x_i is
# clipped, and dm/dx_i(c) + sum_j d2m/dx_i ds_j(c) (s_j - c_j) when it is
# not; or they are held at m(c), whose derivative is dm/dx_i(c) when x_i is
# not clipped and zero when it is. The terms' work array ends with
# [lower (n_vars), upper (n_vars), c (n_vars), clipped, held], ``clipped``
# telling the state Jacobian whether the point of the last evaluation was
# outside; an unbounded box leaves every point inside, where nothing else
# changes.
@njit(cache=CACHE, inline="always")
def _inside(s, work, o_box):
    n_vars = s.shape[0]
    for j in range(n_vars):
        if not work[o_box + j] <= s[j] <= work[o_box + n_vars + j]:
            return False
    return True


@njit(cache=CACHE, inline="always")
def _factor(spec, width, row, f):
    """Variable and exponent of factor ``f`` of the monomial at ``row``."""
    j = spec[row + 1 + f] // width
    return j, spec[row + 1 + f] - j * width


@njit(cache=CACHE)
def _fill_clipped_monomials(spec, s, work, o_box):
    """The monomials at the nearest point of the box, into work."""
    n_vars = spec[0]
    o_point = o_box + 2 * n_vars
    for j in range(n_vars):
        work[o_point + j] = min(max(s[j], work[o_box + j]), work[o_box + n_vars + j])
    _fill_monomials(spec, work[o_point : o_point + n_vars], work)


@njit(cache=CACHE)
def _add_tangent_steps(spec, s, work, o_box):
    """Continue the monomials of :func:`_fill_clipped_monomials` from the
    box's point to ``s`` along their tangent planes."""
    n_vars, n_monomials, width, n_factors = spec[0], spec[1], spec[2], spec[3]
    o_point = o_box + 2 * n_vars
    o_values = n_vars * width
    for k in range(n_monomials):
        row = _HEADER + k * (n_factors + 1)
        count = spec[row]
        for f in range(count):
            j, e = _factor(spec, width, row, f)
            step = s[j] - work[o_point + j]
            if step != 0.0:
                slope = e * work[j * width + e - 1]
                for g in range(count):
                    if g != f:
                        slope *= work[spec[row + 1 + g]]
                work[o_values + k] += slope * step


@njit(cache=CACHE)
def _zero_clipped_slopes(spec, s, work, o_box):
    """Zero the state derivatives of the held monomials along the clipped
    states."""
    n_vars, n_monomials, width, n_diff = spec[0], spec[1], spec[2], spec[4]
    o_point = o_box + 2 * n_vars
    o_out = n_vars * width + n_monomials
    for i in range(n_diff):
        if s[i] != work[o_point + i]:
            for k in range(n_monomials):
                work[o_out + k * n_diff + i] = 0.0


@njit(cache=CACHE)
def _add_tangent_curvature(spec, s, work, o_box):
    """Add to the state derivatives of the continued monomials (computed at
    the box's point) the change of the tangent plane with the unclipped
    states."""
    n_vars, n_monomials, width, n_factors, n_diff = (spec[0], spec[1], spec[2], spec[3],
                                                     spec[4])
    o_point = o_box + 2 * n_vars
    o_out = n_vars * width + n_monomials
    for k in range(n_monomials):
        row = _HEADER + k * (n_factors + 1)
        count = spec[row]
        for f in range(count):
            i, e_i = _factor(spec, width, row, f)
            if i >= n_diff or s[i] != work[o_point + i]:
                continue
            acc = 0.0
            for g in range(count):
                j, e_j = _factor(spec, width, row, g)
                step = s[j] - work[o_point + j]
                if g == f or step == 0.0:
                    continue
                term = e_i * work[i * width + e_i - 1] * e_j * work[j * width + e_j - 1] * step
                for q in range(count):
                    if q != f and q != g:
                        term *= work[spec[row + 1 + q]]
                acc += term
            work[o_out + k * n_diff + i] += acc


@njit(EVALUATE, cache=CACHE)
def _evaluate(theta, spec, s, n, h, work):
    n_zeta, n_eta, o_zeta, o_eta, _, _, o_values, _ = _offsets(spec)
    # Filled at s before the box is looked at, so that the path of the points
    # inside (nearly all of them) is the code without a box; a point outside
    # is filled again at the box's nearest point.
    _fill_monomials(spec, s, work)
    o_box = _work_size(spec)
    outside = not _inside(s, work, o_box)
    work[o_box + 3 * s.shape[0]] = 1.0 if outside else 0.0
    if outside:
        _fill_clipped_monomials(spec, s, work, o_box)
        if not work[o_box + 3 * s.shape[0] + 1]:
            _add_tangent_steps(spec, s, work, o_box)
    o_f = n * n_zeta
    for i in range(n):
        acc = 0.0
        for k in range(n_zeta):
            acc += theta[i * n_zeta + k] * work[o_values + spec[o_zeta + k]]
        h[i] = acc
    for i in range(h.shape[0] - n):
        acc = 0.0
        for k in range(n_eta):
            acc += theta[o_f + i * n_eta + k] * work[o_values + spec[o_eta + k]]
        h[n + i] = acc


@njit(cache=CACHE, inline="always")
def _sparse_rows(theta, o_theta, n_columns, spec, o_positions, o_bounds, n, work, o_slopes,
                 dh_dx, first_row, n_rows):
    """Rows ``first_row:first_row + n_rows`` of dh/dx for the coefficients
    ``theta[o_theta:]`` (``n_columns`` per row) of the monomials listed at
    ``o_positions``, with the table of those containing each state at
    ``o_bounds``."""
    o_indices = o_bounds + n + 1
    for r in range(n_rows):
        o_row = o_theta + r * n_columns
        for j in range(n):
            acc = 0.0
            for q in range(spec[o_bounds + j], spec[o_bounds + j + 1]):
                k = spec[o_indices + q]
                acc += theta[o_row + k] * work[o_slopes + spec[o_positions + k] * n + j]
            dh_dx[first_row + r, j] = acc


@njit(STATE_JACOBIAN, cache=CACHE)
def _state_jacobian(theta, spec, s, n, dh_dx, work):
    n_zeta, n_eta, o_zeta, o_eta, o_zeta_bounds, o_eta_bounds, _, o_slopes = _offsets(spec)
    _fill_derivatives(spec, work)
    o_box = _work_size(spec)
    if work[o_box + 3 * s.shape[0]]:
        if work[o_box + 3 * s.shape[0] + 1]:
            _zero_clipped_slopes(spec, s, work, o_box)
        else:
            _add_tangent_curvature(spec, s, work, o_box)
    _sparse_rows(theta, 0, n_zeta, spec, o_zeta, o_zeta_bounds, n, work, o_slopes, dh_dx, 0, n)
    _sparse_rows(theta, n * n_zeta, n_eta, spec, o_eta, o_eta_bounds, n, work, o_slopes,
                 dh_dx, n, dh_dx.shape[0] - n)


@njit(PARAMETER_JACOBIAN, cache=CACHE)
def _parameter_jacobian(theta, spec, s, n, work, state_out, state_offset, output_out,
                        output_offset):
    n_zeta, n_eta, o_zeta, o_eta, _, _, o_values, _ = _offsets(spec)
    for i in range(n):
        for k in range(n_zeta):
            state_out[i, state_offset + i * n_zeta + k] += work[o_values + spec[o_zeta + k]]
    if output_offset < 0:
        return
    o_f = output_offset + n * n_zeta
    for i in range(output_out.shape[0]):
        for k in range(n_eta):
            output_out[i, o_f + i * n_eta + k] += work[o_values + spec[o_eta + k]]


class PolynomialTerms(RangedTerms):
    """``h_x = E zeta(s)``, ``h_y = F eta(s)`` with monomials zeta and eta.

    Parameters
    ----------
    n_states, n_outputs : int
        Dimensions.
    state_exponents, output_exponents : ndarray of int64
        Exponents of zeta and eta, shapes (n_zeta, n_vars) and (n_eta, n_vars).
    input_range : ndarray of shape (2, n_vars), default=None
        Lower and upper ends of the range of each variable of ``s = [x; u]``
        around which the monomials are themselves (see ``reach``); beyond,
        they go on along their tangent planes at the nearest point of that
        box, or are held there (``held``). ``None``: the monomials everywhere.
    reach : float, default=1.0
        The monomials hold out to ``reach`` times the half-width of
        ``input_range`` about its centre; ``inf``: everywhere (the range is
        then only a record of where the points went).
    held : bool, default=False
        Beyond that box, hold the monomials at their value at its nearest
        point instead of continuing them along their tangent planes.
    """

    evaluate = staticmethod(_evaluate)
    state_jacobian = staticmethod(_state_jacobian)
    parameter_jacobian = staticmethod(_parameter_jacobian)

    def __init__(self, n_states, n_outputs, state_exponents, output_exponents,
                 input_range=None, reach=1.0, held=False):
        self.exponents = (np.ascontiguousarray(state_exponents, dtype=np.int64),
                          np.ascontiguousarray(output_exponents, dtype=np.int64))
        n_zeta, n_eta = (len(e) for e in self.exponents)
        n_vars = self.exponents[0].shape[1]
        self.blocks = [("E", (n_states, n_zeta)), ("F", (n_outputs, n_eta))]
        distinct, positions = np.unique(np.vstack(self.exponents).reshape(-1, n_vars),
                                        axis=0, return_inverse=True)
        monomials = _monomial_spec(distinct, n_states)
        positions = positions.ravel()
        zeta_bounds, zeta_indices = _containing(self.exponents[0], n_states)
        eta_bounds, eta_indices = _containing(self.exponents[1], n_states)
        # Each bounds table is followed by its indices, which _sparse_rows finds there.
        tables = [positions[:n_zeta], positions[n_zeta:], zeta_bounds, zeta_indices,
                  eta_bounds, eta_indices]
        starts = len(monomials) + np.cumsum([0] + [len(t) for t in tables[:-1]])
        self.spec = np.concatenate([monomials, *tables, starts[[0, 1, 2, 4]],
                                    [n_zeta, n_eta]]).astype(np.int64)
        # The box, its nearest point and the clipped and held flags end the
        # work.
        self._range_offset = _work_size(monomials)
        self.work_size = self._range_offset + 3 * n_vars + 2
        self._set_range(input_range, reach, n_vars)
        self.held = bool(held)
        self.n_state_params = n_states * n_zeta
        self.dimensions = (n_states, n_outputs)

    @property
    def work_init(self):
        work = super().work_init
        work[-1] = float(self.held)
        return work

    def with_input_range(self, values, S, reach=1.0, held=False):
        """The same terms with the box that the points ``S = [x; u]`` fill,
        held out to ``reach`` times its half-width (``values``, the parameter
        blocks, are not needed: the box holds the points themselves)."""
        return PolynomialTerms(*self.dimensions, *self.exponents,
                               np.vstack([S.min(axis=0), S.max(axis=0)]), reach, held)
