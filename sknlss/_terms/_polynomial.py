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


@njit(cache=True)
def _fill_powers(s, powers):
    # powers[j, p] = s[j] ** p, shared by every monomial and its derivatives.
    for j in range(s.shape[0]):
        powers[j, 0] = 1.0
        for p in range(1, powers.shape[1]):
            powers[j, p] = powers[j, p - 1] * s[j]


@njit(cache=True)
def _monomials(powers, exponents, out):
    for k in range(exponents.shape[0]):
        value = 1.0
        for j in range(exponents.shape[1]):
            e = exponents[k, j]
            if e:
                value *= powers[j, e]
        out[k] = value


@njit(cache=True)
def _derivatives(powers, exponents, n_vars, out):
    # out[k, i] = d monomial_k / d s_i for the first n_vars variables.
    for k in range(exponents.shape[0]):
        for i in range(n_vars):
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


def _max_degree(exponents):
    return max(1, int(exponents.max(initial=0)))


@njit(cache=True)
def _batch_values(S, exponents, max_degree):
    values = np.empty((S.shape[0], exponents.shape[0]))
    powers = np.empty((S.shape[1], max_degree + 1))
    for t in range(S.shape[0]):
        _fill_powers(S[t], powers)
        _monomials(powers, exponents, values[t])
    return values


@njit(cache=True)
def _batch_derivatives(S, exponents, max_degree):
    derivatives = np.empty((S.shape[0], exponents.shape[0], S.shape[1]))
    powers = np.empty((S.shape[1], max_degree + 1))
    for t in range(S.shape[0]):
        _fill_powers(S[t], powers)
        _derivatives(powers, exponents, S.shape[1], derivatives[t])
    return derivatives


def _as_points(S, exponents):
    exponents = np.ascontiguousarray(exponents, dtype=np.int64)
    return np.ascontiguousarray(S, dtype=np.float64), exponents, _max_degree(exponents)


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
    return _batch_values(*_as_points(S, exponents))


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
    return _batch_derivatives(*_as_points(S, exponents))


# ------------------------------------------------------------------ the terms
# spec = [n_vars, n_zeta, n_eta, max_degree, state exponents, output exponents]
# work = [powers (n_vars x (max_degree + 1)), zeta, eta, dzeta (n_zeta x n),
#         deta (n_eta x n)]
# The compiled functions index these flat arrays directly: views made at
# every sample would cost more than the arithmetic.
_HEADER = 4


@njit(cache=True)
def _flat_powers(s, work, width):
    for j in range(s.shape[0]):
        base = j * width
        work[base] = 1.0
        for p in range(1, width):
            work[base + p] = work[base + p - 1] * s[j]


@njit(cache=True)
def _flat_monomials(spec, o_exp, n_terms, n_vars, work, width, o_out):
    for k in range(n_terms):
        value = 1.0
        row = o_exp + k * n_vars
        for j in range(n_vars):
            e = spec[row + j]
            if e:
                value *= work[j * width + e]
        work[o_out + k] = value


@njit(cache=True)
def _flat_derivatives(spec, o_exp, n_terms, n_vars, n, work, width, o_out):
    # work[o_out + k * n + i] = d monomial_k / d x_i
    for k in range(n_terms):
        row = o_exp + k * n_vars
        for i in range(n):
            e = spec[row + i]
            value = 0.0
            if e:
                value = e * work[i * width + e - 1]
                for j in range(n_vars):
                    if j != i:
                        ej = spec[row + j]
                        if ej:
                            value *= work[j * width + ej]
            work[o_out + k * n + i] = value


@njit(cache=True)
def _layout(spec, n):
    n_vars, n_zeta, n_eta = spec[0], spec[1], spec[2]
    width = spec[3] + 1
    o_zeta = n_vars * width
    o_eta = o_zeta + n_zeta
    o_dzeta = o_eta + n_eta
    o_deta = o_dzeta + n_zeta * n
    return n_vars, n_zeta, n_eta, width, o_zeta, o_eta, o_dzeta, o_deta


@njit(EVALUATE, cache=True)
def _evaluate(theta, spec, s, n, h, work):
    n_vars, n_zeta, n_eta, width, o_zeta, o_eta, _, _ = _layout(spec, n)
    _flat_powers(s, work, width)
    _flat_monomials(spec, _HEADER, n_zeta, n_vars, work, width, o_zeta)
    _flat_monomials(spec, _HEADER + n_zeta * n_vars, n_eta, n_vars, work, width, o_eta)
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
    n_vars, n_zeta, n_eta, width, _, _, o_dzeta, o_deta = _layout(spec, n)
    _flat_derivatives(spec, _HEADER, n_zeta, n_vars, n, work, width, o_dzeta)
    _flat_derivatives(spec, _HEADER + n_zeta * n_vars, n_eta, n_vars, n, work, width,
                      o_deta)
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
    _, n_zeta, n_eta, _, o_zeta, o_eta, _, _ = _layout(spec, n)
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
        max_degree = _max_degree(np.vstack(self.exponents))
        self.blocks = [("E", (n_states, n_zeta)), ("F", (n_outputs, n_eta))]
        self.spec = np.concatenate(
            [[n_vars, n_zeta, n_eta, max_degree], *(e.ravel() for e in self.exponents)]
        ).astype(np.int64)
        self.work_size = n_vars * (max_degree + 1) + (n_zeta + n_eta) * (1 + n_states)
        self.n_state_params = n_states * n_zeta
