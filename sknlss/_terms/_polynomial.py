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

from .._core._kernels import EVALUATE, PARAMETER_JACOBIAN, STATE_JACOBIAN
from .._core._model import Terms

#: Monomial selections understood by :func:`monomial_exponents`.
STRUCTURES = ("full", "states_only", "no_cross_products", "inputs_only")
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
    k = {"full": n_vars, "states_only": int(n_states), "inputs_only": int(n_inputs)}[structure]
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
    structure : {"full", "states_only", "no_cross_products", "inputs_only"} \
            or array-like of shape (n_terms, n_states + n_inputs)
        Which monomials to keep: all of them, those in x only, the pure powers
        of single variables only, or those in u only. An explicit exponent
        array is validated and returned as is (``degree`` is then ignored).

    Returns
    -------
    exponents : ndarray of shape (n_terms, n_states + n_inputs), dtype int64
        Ordered by degree, then in the order of
        :func:`itertools.combinations_with_replacement` over the variable
        indices.

    Examples
    --------
    >>> from sknlss._polynomial import monomial_exponents
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
# spec = [n_vars, n_monomials, width, n_factors, n_diff,
#         factors (n_monomials x n_factors),
#         derivative rows (n_monomials x n_diff x (n_factors + 1))]
# work = [powers (n_vars x width), monomials (n_monomials),
#         derivatives (n_monomials x n_diff)]
#
# with ``work[j * width + p] = s_j ** p``. Row k of ``factors`` holds the
# positions in work of the powers whose product is monomial k, in the order of
# the variables, padded with position 0 (``s_0 ** 0 = 1``). The derivative row
# of monomial k and variable i holds the exponent e of s_i, the position of
# ``s_i ** (e - 1)`` and those of the other factors (all padding when e = 0).
# Every monomial is then a fixed number of products without branches, and the
# compiled functions index the flat arrays directly: views made at every
# sample would cost more than the arithmetic.
_HEADER = 5


def _monomial_spec(exponents, n_diff):
    """The integer tables of the monomials ``exponents`` (see above), with
    derivatives with respect to the first ``n_diff`` variables."""
    exponents = np.asarray(exponents, dtype=np.int64)
    n_monomials, n_vars = exponents.shape
    width = _max_degree(exponents) + 1
    n_factors = max(1, int(np.count_nonzero(exponents, axis=1).max(initial=0)))
    factors = np.zeros((n_monomials, n_factors), dtype=np.int64)
    derivatives = np.zeros((n_monomials, n_diff, n_factors + 1), dtype=np.int64)
    for k, row in enumerate(exponents):
        present = [(j, int(e)) for j, e in enumerate(row) if e]
        factors[k, : len(present)] = [j * width + e for j, e in present]
        for i in range(n_diff):
            if row[i]:
                others = [j * width + e for j, e in present if j != i]
                derivatives[k, i, : 2 + len(others)] = [row[i], i * width + row[i] - 1,
                                                        *others]
    header = [n_vars, n_monomials, width, n_factors, n_diff]
    return np.concatenate([header, factors.ravel(), derivatives.ravel()]).astype(np.int64)


def _work_size(spec):
    n_vars, n_monomials, width, _, n_diff = spec[:_HEADER]
    return int(n_vars * width + n_monomials * (1 + n_diff))


@njit(cache=True)
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
        row = _HEADER + k * n_factors
        for f in range(n_factors):
            value *= work[spec[row + f]]
        work[o_values + k] = value


@njit(cache=True)
def _fill_derivatives(spec, work):
    """Derivatives of the monomials, into work (after :func:`_fill_monomials`)."""
    n_vars, n_monomials, width, n_factors, n_diff = (spec[0], spec[1], spec[2], spec[3],
                                                     spec[4])
    o_rows = _HEADER + n_monomials * n_factors
    o_out = n_vars * width + n_monomials
    for k in range(n_monomials):
        for i in range(n_diff):
            row = o_rows + (k * n_diff + i) * (n_factors + 1)
            value = spec[row] * work[spec[row + 1]]
            for f in range(n_factors - 1):
                value *= work[spec[row + 2 + f]]
            work[o_out + k * n_diff + i] = value


def _max_degree(exponents):
    return max(1, int(exponents.max(initial=0)))


@njit(cache=True)
def _batch_values(S, spec, work):
    n_vars, n_monomials, width = spec[0], spec[1], spec[2]
    o_values = n_vars * width
    values = np.empty((S.shape[0], n_monomials))
    for t in range(S.shape[0]):
        _fill_monomials(spec, S[t], work)
        for k in range(n_monomials):
            values[t, k] = work[o_values + k]
    return values


@njit(cache=True)
def _batch_derivatives(S, spec, work):
    n_vars, n_monomials, width = spec[0], spec[1], spec[2]
    o_out = n_vars * width + n_monomials
    derivatives = np.empty((S.shape[0], n_monomials, n_vars))
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
# The terms' spec is the monomials' spec of [state exponents; output
# exponents] (zeta first, then eta) followed by n_zeta; derivatives are taken
# with respect to the states.


@njit(cache=True)
def _offsets(spec):
    """n_zeta and the offsets of the monomials and their derivatives in work."""
    n_vars, n_monomials, width = spec[0], spec[1], spec[2]
    o_values = n_vars * width
    return spec[spec.shape[0] - 1], o_values, o_values + n_monomials


@njit(EVALUATE, cache=True)
def _evaluate(theta, spec, s, n, h, work):
    n_zeta, o_zeta, _ = _offsets(spec)
    n_eta = spec[1] - n_zeta
    o_eta = o_zeta + n_zeta
    _fill_monomials(spec, s, work)
    o_f = n * n_zeta
    for i in range(n):
        acc = 0.0
        for k in range(n_zeta):
            acc += theta[i * n_zeta + k] * work[o_zeta + k]
        h[i] = acc
    for i in range(h.shape[0] - n):
        acc = 0.0
        for k in range(n_eta):
            acc += theta[o_f + i * n_eta + k] * work[o_eta + k]
        h[n + i] = acc


@njit(STATE_JACOBIAN, cache=True)
def _state_jacobian(theta, spec, s, n, dh_dx, work):
    n_zeta, _, o_dzeta = _offsets(spec)
    n_eta = spec[1] - n_zeta
    o_deta = o_dzeta + n_zeta * n
    _fill_derivatives(spec, work)
    o_f = n * n_zeta
    for i in range(n):
        for j in range(n):
            acc = 0.0
            for k in range(n_zeta):
                acc += theta[i * n_zeta + k] * work[o_dzeta + k * n + j]
            dh_dx[i, j] = acc
    for i in range(dh_dx.shape[0] - n):
        for j in range(n):
            acc = 0.0
            for k in range(n_eta):
                acc += theta[o_f + i * n_eta + k] * work[o_deta + k * n + j]
            dh_dx[n + i, j] = acc


@njit(PARAMETER_JACOBIAN, cache=True)
def _parameter_jacobian(theta, spec, s, n, work, state_out, state_offset, output_out,
                        output_offset):
    n_zeta, o_zeta, _ = _offsets(spec)
    n_eta = spec[1] - n_zeta
    o_eta = o_zeta + n_zeta
    for i in range(n):
        for k in range(n_zeta):
            state_out[i, state_offset + i * n_zeta + k] += work[o_zeta + k]
    if output_offset < 0:
        return
    o_f = output_offset + n * n_zeta
    for i in range(output_out.shape[0]):
        for k in range(n_eta):
            output_out[i, o_f + i * n_eta + k] += work[o_eta + k]


class PolynomialTerms(Terms):
    """``h_x = E zeta(s)``, ``h_y = F eta(s)`` with monomials zeta and eta.

    Parameters
    ----------
    n_states, n_outputs : int
        Dimensions.
    state_exponents, output_exponents : ndarray of int64
        Exponents of zeta and eta, shapes (n_zeta, n_vars) and (n_eta, n_vars).
    """

    evaluate = staticmethod(_evaluate)
    state_jacobian = staticmethod(_state_jacobian)
    parameter_jacobian = staticmethod(_parameter_jacobian)

    def __init__(self, n_states, n_outputs, state_exponents, output_exponents):
        self.exponents = (np.ascontiguousarray(state_exponents, dtype=np.int64),
                          np.ascontiguousarray(output_exponents, dtype=np.int64))
        n_zeta, n_eta = (len(e) for e in self.exponents)
        n_vars = self.exponents[0].shape[1]
        self.blocks = [("E", (n_states, n_zeta)), ("F", (n_outputs, n_eta))]
        monomials = _monomial_spec(np.vstack(self.exponents).reshape(-1, n_vars), n_states)
        self.spec = np.append(monomials, n_zeta)
        self.work_size = _work_size(monomials)
        self.n_state_params = n_states * n_zeta
