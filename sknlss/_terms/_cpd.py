"""Decoupling of multivariate polynomials from first-order information.

A multivariate polynomial map ``f: R^m -> R^p`` is approximated by the
decoupled form ``f(s) = W g(V^T s)`` with ``r`` univariate branches ``g_l``
(Dreesen, Ishteva and Schoukens, "Decoupling multivariate polynomials using
first-order information and tensor decompositions", SIAM J. Matrix Anal. Appl.
36(2), 2015). The Jacobian of the decoupled form is
``J(s) = W diag(g_1'(v_1^T s), ..., g_r'(v_r^T s)) V^T``, so the Jacobians of
``f`` evaluated in ``N_s`` points and stacked into a ``p x m x N_s`` tensor have
a canonical polyadic decomposition (CPD) of rank ``r`` whose factors are ``W``,
``V`` and the branch derivatives in the points.

Here the CPD (tensorly's ALS, several random starts) is followed by a
structured refinement of ``V``, ``W`` and the branch coefficients that fits
the Jacobians with the third factor constrained to be the branch derivatives,
and also the values of ``f`` in the same points (zeroth-order information):
when ``f`` is only approximately decoupled, the values fix each branch's
integration constant, which the derivatives leave open.

Branches have no constant and no linear term (powers 2 to ``degree``): the
maps decoupled here are the nonlinear parts of PNLSS models, whose linear part
is carried by ``A, B, C, D``.
"""

import warnings

import numpy as np
from sklearn.exceptions import ConvergenceWarning
from sklearn.utils import check_random_state
from sklearn.utils._param_validation import validate_params
from tensorly.decomposition import parafac

from .._core._memory import check_memory
from .._core._optimize import levenberg_marquardt
from .._validation import Integers, naming
from ._polynomial import (
    MAX_DEGREE,
    _validate_exponents,
    evaluate_monomials,
    monomial_jacobian,
)

# ALS for the CPD: iterations per restart and the stopping tolerance on the
# change of the relative reconstruction error. ALS only provides starting
# points: a short structured refinement on a few points screens each of them,
# and the best is refined to full precision.
_ALS_MAX_ITER = 50
_ALS_TOL = 1e-10
_SCREEN_POINTS = 50
_SCREEN_MAX_ITER = 10
_REFINE_MAX_ITER = 100
# The final refinement uses the points of a random subset that hold this many
# tensor entries (at least _SCREEN_POINTS points): enough to determine the few
# parameters of V, W and the branches, while the cost of a Gauss-Newton step
# grows with the entries.
_REFINE_MAX_ENTRIES = 4000


def branch_values(Z, coefficients):
    """Evaluate the branches and their derivatives.

    Parameters
    ----------
    Z : ndarray of shape (n_points, r)
        Branch inputs ``V^T s`` per point.
    coefficients : ndarray of shape (r, n_coef)
        ``coefficients[l, k]`` multiplies ``z_l**(k + 2)``.

    Returns
    -------
    g, dg, d2g : ndarray of shape (n_points, r)
        Branch values and their first and second derivatives.
    """
    n_coef = coefficients.shape[1]
    powers = np.arange(2, n_coef + 2)
    # Z**(k) for k = 0 .. n_coef + 1, stacked on the last axis.
    Zp = Z[..., None] ** np.arange(n_coef + 2)
    g = np.einsum("nlk,lk->nl", Zp[..., 2:], coefficients)
    dg = np.einsum("nlk,lk->nl", Zp[..., 1:-1], coefficients * powers)
    d2g = np.einsum("nlk,lk->nl", Zp[..., :-2], coefficients * powers * (powers - 1))
    return g, dg, d2g


def _jacobian_tensor(coefficients, exponents, points):
    """Jacobians of ``coefficients @ monomials(s)`` stacked as (n_out, n_vars, n_points)."""
    return np.einsum("im,kmj->ijk", coefficients, monomial_jacobian(points, exponents))


def _cpd(tensor, rank, seed):
    """One randomly initialised ALS run: factors (W, V, H), or None when ALS broke down."""
    try:
        cp = parafac(tensor, rank, init="random", n_iter_max=_ALS_MAX_ITER, tol=_ALS_TOL,
                     random_state=int(seed))
    except np.linalg.LinAlgError:
        # A singular normal-equation matrix (collinear factors): another
        # restart may do better.
        return None
    W, V, H = cp.factors
    W = W * cp.weights
    if not all(np.all(np.isfinite(f)) for f in (W, V, H)):
        return None
    return W, V, H


def _normalise_factors(W, V, H):
    """Fix the scaling and sign ambiguity: unit-norm columns of V and W, the
    largest entry of each positive; H carries the magnitude."""
    v_norm = np.linalg.norm(V, axis=0)
    w_norm = np.linalg.norm(W, axis=0)
    v_norm[v_norm == 0] = 1.0
    w_norm[w_norm == 0] = 1.0
    cols = np.arange(V.shape[1])
    v_sign = np.sign(V[np.abs(V).argmax(axis=0), cols])
    w_sign = np.sign(W[np.abs(W).argmax(axis=0), cols])
    v_sign[v_sign == 0] = 1.0
    w_sign[w_sign == 0] = 1.0
    V = V * (v_sign / v_norm)
    W = W * (w_sign / w_norm)
    H = H * (v_sign * w_sign * v_norm * w_norm)
    return W, V, H


def _fit_branches(Z, H, n_coef):
    """Least-squares fit of each branch derivative by powers 1 .. n_coef of its input,
    integrated into the coefficients of powers 2 .. n_coef + 1."""
    coefficients = np.empty((Z.shape[1], n_coef))
    powers = np.arange(1, n_coef + 1)
    for l in range(Z.shape[1]):
        basis = Z[:, l : l + 1] ** powers
        slope = np.linalg.lstsq(basis, H[:, l], rcond=None)[0]
        coefficients[l] = slope / (powers + 1)
    return coefficients


def _refine(tensor, values, points, W, V, coefficients, max_iter):
    """Gauss-Newton (Levenberg-Marquardt) fit of ``W``, ``V`` and the branch
    coefficients to the Jacobian tensor, with the third CPD factor constrained
    to the branch derivatives ``g_l'(v_l^T s_k)``, and to the function values
    (n_points, n_out) when given. Both parts are relative to their RMS value."""
    n_out, n_vars, _ = tensor.shape
    rank, n_coef = coefficients.shape
    sizes = np.cumsum([n_out * rank, n_vars * rank])
    powers = np.arange(2, n_coef + 2)
    scale = np.linalg.norm(tensor) / np.sqrt(tensor.size)
    if values is not None:
        value_scale = max(np.linalg.norm(values) / np.sqrt(values.size), np.finfo(float).tiny)

    def unpack(theta):
        W_, V_, c_ = np.split(theta, sizes)
        return (W_.reshape(n_out, rank), V_.reshape(n_vars, rank),
                c_.reshape(rank, n_coef))

    def residual(theta, jacobian):
        W_, V_, c_ = unpack(theta)
        Z = points @ V_
        g, dg, d2g = branch_values(Z, c_)
        r = [((np.einsum("il,jl,kl->ijk", W_, V_, dg) - tensor) / scale).ravel()]
        if values is not None:
            r.append(((g @ W_.T - values) / value_scale).ravel())
        r = np.concatenate(r)
        if not jacobian:
            return r, None
        # Derivatives of the tensor residual [i, j, k] with respect to W[a, l],
        # V[b, l] and c[l, q] ...
        eye_out, eye_vars = np.eye(n_out), np.eye(n_vars)
        dW = np.einsum("ia,jl,kl->ijkal", eye_out, V_, dg, optimize=True)
        dV = np.einsum("il,jb,kl->ijkbl", W_, eye_vars, dg, optimize=True) + np.einsum(
            "il,jl,kl,kb->ijkbl", W_, V_, d2g, points, optimize=True)
        Zq = Z[..., None] ** (powers - 1) * powers
        dc = np.einsum("il,jl,klq->ijklq", W_, V_, Zq, optimize=True)
        m = tensor.size
        J = [np.hstack([dW.reshape(m, -1), dV.reshape(m, -1), dc.reshape(m, -1)]) / scale]
        if values is not None:
            # ... and of the value residual [k, i].
            m = values.size
            dW = np.einsum("ia,kl->kial", eye_out, g, optimize=True)
            dV = np.einsum("il,kl,kb->kibl", W_, dg, points, optimize=True)
            dc = np.einsum("il,klq->kilq", W_, Z[..., None] ** powers, optimize=True)
            J.append(np.hstack([dW.reshape(m, -1), dV.reshape(m, -1),
                                dc.reshape(m, -1)]) / value_scale)
        return r, np.vstack(J)

    theta0 = np.concatenate([W.ravel(), V.ravel(), coefficients.ravel()])
    with warnings.catch_warnings():
        # The caller judges the outcome by the returned fit error.
        warnings.simplefilter("ignore", ConvergenceWarning)
        # Each branch keeps two scaling invariances (of v_l and of w_l).
        result = levenberg_marquardt(residual, theta0, max_iter=max_iter, tol=1e-8,
                                     n_drop=2 * rank, label="CPD refinement")
    return unpack(result.theta)


def _decoupling_error(tensor, points, W, V, coefficients):
    """Relative Frobenius error of the decoupled form's Jacobian tensor."""
    dg = branch_values(points @ V, coefficients)[1]
    return np.linalg.norm(np.einsum("il,jl,kl->ijk", W, V, dg) - tensor) / np.linalg.norm(tensor)


def _refinement_cost(tensor, values, points, W, V, coefficients):
    """Squared relative errors of the Jacobians plus (when given) the values."""
    cost = _decoupling_error(tensor, points, W, V, coefficients) ** 2
    if values is not None:
        g = branch_values(points @ V, coefficients)[0]
        cost += np.sum((g @ W.T - values) ** 2) / max(np.sum(values**2), np.finfo(float).tiny)
    return cost


@validate_params(
    {
        "coefficients": ["array-like"],
        "exponents": ["array-like"],
        "rank": [Integers(1, None, closed="left")],
        "degree": [Integers(2, MAX_DEGREE, closed="both"), None],
        "n_samples": [Integers(1, None, closed="left")],
        "sampling_points": ["array-like", None],
        "n_restarts": [Integers(1, None, closed="left")],
        "refine": ["boolean"],
        "zeroth_order": ["boolean"],
        "random_state": ["random_state"],
    },
    prefer_skip_nested_validation=True,
)
def decouple_polynomial(
    coefficients,
    exponents,
    rank,
    *,
    degree=None,
    n_samples=500,
    sampling_points=None,
    n_restarts=10,
    refine=True,
    zeroth_order=True,
    random_state=None,
):
    """Decouple a multivariate polynomial map into univariate branches.

    The coupled map is ``f(s) = coefficients @ m(s)`` where ``m(s)`` are the
    monomials of ``s`` with the given exponents. It is approximated by
    ``W g(V^T s)`` where ``g_l(z) = sum_k branch_coefficients[l, k] z**(k + 2)``.

    Parameters
    ----------
    coefficients : array-like of shape (n_out, n_terms)
        Coefficients of the monomials in each output of ``f``; for a PNLSS
        model, ``[E; F]`` over the union of the state and output monomials.
    exponents : array-like of shape (n_terms, n_vars)
        Exponents of the monomials (total degree >= 2).
    rank : int
        Number of branches ``r``.
    degree : int, default=None
        Degree of the branches (>= 2). ``None`` uses the largest total
        degree of the monomials.
    n_samples : int, default=500
        Number of normally distributed sampling points, used when
        ``sampling_points`` is None.
    sampling_points : array-like of shape (n_points, n_vars), default=None
        Points in which the Jacobians are evaluated, e.g. the model's own
        trajectory of ``[x; u]``. ``None`` draws ``n_samples`` points from the
        standard normal distribution.
    n_restarts : int, default=10
        Number of randomly initialised CPD computations; the best fit is kept.
    refine : bool, default=True
        Refine the CPD with its third factor constrained to the branch
        derivatives (Levenberg-Marquardt on V, W and the branch coefficients,
        on a random subset of the points: as many as hold 4000 tensor entries,
        and at least 50), which makes the decoupling exact to machine
        precision when ``f`` has an exact
        decoupled form. ``False`` keeps the plain CPD followed by the
        least-squares fit of the branch derivatives.
    zeroth_order : bool, default=True
        Let the refinement also fit the values of ``f`` in the sampling
        points. When ``f`` is only approximately decoupled, the derivative
        alone leaves each branch's integration constant to the error of
        ``g_l'`` between 0 and the sampled region (far from 0 for PNLSS states
        with large offsets), which the values fix. Without effect when
        ``refine`` is False.
    random_state : int, RandomState instance or None, default=None
        Seeds the sampling points and the CPD initialisations.

    Returns
    -------
    V : ndarray of shape (n_vars, rank)
        Input transformation; unit-norm columns.
    W : ndarray of shape (n_out, rank)
        Output transformation.
    branch_coefficients : ndarray of shape (rank, degree - 1)
        ``branch_coefficients[l, k]`` multiplies ``(v_l^T s)**(k + 2)``.
    error : float
        Relative Frobenius error of the decoupled form's Jacobian tensor in
        the sampling points.

    See Also
    --------
    DecoupledPNLSS : Decoupled polynomial state-space model.

    Examples
    --------
    >>> import numpy as np
    >>> from sknlss import decouple_polynomial
    >>> # f(s) = (s1 + s2)**2 = s1**2 + 2 s1 s2 + s2**2 has one branch.
    >>> V, W, c, error = decouple_polynomial(
    ...     [[1.0, 2.0, 1.0]], [[2, 0], [1, 1], [0, 2]], rank=1, random_state=0)
    >>> bool(error < 1e-10)
    True
    >>> s = np.array([1.0, 2.0])
    >>> print(f"{(W[0, 0] * c[0, 0] * (s @ V[:, 0]) ** 2):.6f}")
    9.000000
    """
    with naming("coefficients"):
        coefficients = np.atleast_2d(np.asarray(coefficients, dtype=np.float64))
    with naming("exponents"):
        exponents = np.atleast_2d(np.asarray(exponents, dtype=np.float64))
        exponents = _validate_exponents(exponents, exponents.shape[-1])
    if coefficients.ndim != 2:
        raise ValueError(
            f"coefficients must be a 2-D array (n_out, n_terms), got shape "
            f"{coefficients.shape}."
        )
    n_out, n_terms = coefficients.shape
    if exponents.shape[0] != n_terms:
        raise ValueError(
            f"coefficients has {n_terms} columns but exponents has "
            f"{exponents.shape[0]} rows (one per monomial)."
        )
    if not np.all(np.isfinite(coefficients)):
        raise ValueError("coefficients must be finite.")
    n_vars = exponents.shape[1]
    if degree is None:
        degree = int(exponents.sum(axis=1).max()) if n_terms else 2
    rng = check_random_state(random_state)
    if sampling_points is None:
        n_points = n_samples
    else:
        with naming("sampling_points"):
            points = np.asarray(sampling_points, dtype=np.float64)
        if points.ndim != 2 or points.shape[1] != n_vars or not np.all(np.isfinite(points)):
            raise ValueError(
                f"sampling_points must be a finite array of shape (n_points, {n_vars}); "
                f"got shape {points.shape}."
            )
        n_points = points.shape[0]
    if n_points < degree:
        raise ValueError(
            f"{n_points} sampling points (n_samples or sampling_points) cannot "
            f"determine branches of degree {degree}; use at least {degree}."
        )
    # The monomials' Jacobians and the tensor stacked from them.
    check_memory(8 * n_points * n_vars * (n_terms + 2 * n_out),
                 f"The Jacobian tensor of {n_terms} monomials in {n_points} sampling points "
                 "(n_samples or sampling_points)")
    if sampling_points is None:
        points = rng.standard_normal((n_points, n_vars))
    n_coef = degree - 1
    tensor = _jacobian_tensor(coefficients, exponents, points)
    if not np.all(np.isfinite(tensor)):
        raise ValueError(
            "The Jacobians of the polynomial overflow at the sampling points; "
            "scale the points or the coefficients."
        )
    if not np.any(tensor):
        # Nothing to decouple: zero branches in arbitrary unit directions.
        V = rng.standard_normal((n_vars, rank))
        V /= np.linalg.norm(V, axis=0)
        return V, np.zeros((n_out, rank)), np.zeros((rank, n_coef)), 0.0

    values = None
    if zeroth_order:
        values = evaluate_monomials(points, exponents) @ coefficients.T
    order = rng.permutation(points.shape[0])
    subset = order[:_SCREEN_POINTS]
    refine_set = order[: max(_SCREEN_POINTS, _REFINE_MAX_ENTRIES // (n_out * n_vars))]

    def restrict(rows):
        return tensor[:, :, rows], None if values is None else values[rows], points[rows]

    # Every restart is screened after a short structured refinement on a
    # subset of the points: ALS alone often stalls in a swamp far from the
    # decoupled solution, which the refinement escapes cheaply.
    best, best_cost = None, np.inf
    for seed in rng.randint(np.iinfo(np.int32).max, size=n_restarts):
        factors = _cpd(tensor, rank, seed)
        if factors is None:
            continue
        W, V, H = _normalise_factors(*factors)
        candidate = (W, V, _fit_branches(points @ V, H, n_coef))
        if refine:
            candidate = _refine(*restrict(subset), *candidate, max_iter=_SCREEN_MAX_ITER)
        cost = _refinement_cost(tensor, values if refine else None, points, *candidate)
        if cost < best_cost:
            best, best_cost = candidate, cost
    if best is None:
        raise ValueError(
            "The CPD of the Jacobian tensor failed in every restart (singular "
            "updates); try more restarts, a lower rank or other sampling points."
        )
    W, V, branch_coefficients = best
    if refine:
        W, V, branch_coefficients = _refine(*restrict(refine_set), W, V, branch_coefficients,
                                            max_iter=_REFINE_MAX_ITER)
    # Unit-norm columns of V: the scale moves into the branch coefficients.
    norm = np.linalg.norm(V, axis=0)
    norm[norm == 0] = 1.0
    V = V / norm
    branch_coefficients = branch_coefficients * norm[:, None] ** np.arange(2, degree + 1)
    error = _decoupling_error(tensor, points, W, V, branch_coefficients)
    return V, W, branch_coefficients, float(error)
