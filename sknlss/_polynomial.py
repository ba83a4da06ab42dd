"""Monomial terms of the polynomial nonlinear state-space model.

The nonlinear terms zeta(x, u) and eta(x, u) of a PNLSS model are monomials in
the stacked vector s = [x; u]. A set of monomials is represented by an integer
exponent array of shape (n_terms, n_states + n_inputs): row k holds the power
of each variable in monomial k.
"""

from itertools import combinations_with_replacement
from numbers import Integral

import numpy as np

_STRUCTURES = ("full", "states_only", "no_cross_products", "inputs_only")


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
    if min(degrees) < 2:
        raise ValueError(
            f"Polynomial degrees must be >= 2 (the linear part is A, B, C, D), "
            f"got {degree!r}."
        )
    return sorted(set(degrees))


def _validate_exponents(exponents, n_vars):
    """Check an explicit exponent array and return it as int64."""
    arr = np.asarray(exponents)
    if arr.ndim != 2 or arr.shape[1] != n_vars:
        raise ValueError(
            f"An explicit exponent array must have shape (n_terms, {n_vars}) "
            f"(n_states + n_inputs columns), got shape {arr.shape}."
        )
    if arr.size and not np.all(np.isfinite(arr.astype(float))):
        raise ValueError("The exponent array must be finite.")
    if arr.size and not np.all(arr == np.round(arr)):
        raise ValueError("The exponent array must hold integers.")
    arr = arr.astype(np.int64)
    if np.any(arr < 0):
        raise ValueError("The exponent array must hold non-negative integers.")
    if np.any(arr.sum(axis=1) < 2):
        raise ValueError(
            "Every monomial must have total degree >= 2 (the linear part is "
            "A, B, C, D)."
        )
    if len(np.unique(arr, axis=0)) != len(arr):
        raise ValueError("The exponent array has duplicate rows.")
    return np.ascontiguousarray(arr)


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
    if structure not in _STRUCTURES:
        raise ValueError(
            f"structure must be one of {_STRUCTURES} or an exponent array, "
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
    S = np.asarray(S, dtype=float)
    exponents = np.asarray(exponents, dtype=np.int64)
    # Integer powers with zero exponent give 1 even at 0, as required.
    return np.prod(S[:, None, :] ** exponents[None, :, :], axis=2)


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
    S = np.asarray(S, dtype=float)
    exponents = np.asarray(exponents, dtype=np.int64)
    n_samples, n_vars = S.shape
    n_terms = exponents.shape[0]
    jac = np.zeros((n_samples, n_terms, n_vars))
    powers = S[:, None, :] ** exponents[None, :, :]
    for j in range(n_vars):
        reduced = exponents.copy()
        active = reduced[:, j] > 0
        reduced[active, j] -= 1
        factor = powers.copy()
        factor[:, :, j] = S[:, None, j] ** reduced[None, :, j]
        jac[:, :, j] = np.where(
            active[None, :], exponents[None, :, j] * np.prod(factor, axis=2), 0.0
        )
    return jac
