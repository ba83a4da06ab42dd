"""Univariate bases of the static nonlinearities of branch models.

A branch model (the NL-LFR model and the decoupled PNLSS model) applies a
univariate function ``f_l(z) = sum_k c_lk phi_k(z)`` to each of its branch
inputs ``z_l``. A basis is a small object that names its functions for the
compiled code (``code``, ``degrees``) and evaluates them in NumPy through the
same compiled routine. A new basis is a subclass and one case in
:func:`basis_functions`.
"""

import numpy as np
from numba import njit

_POWERS, _LEGENDRE, _CHEBYSHEV = 0, 1, 2


@njit(cache=True, inline="always")
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
    if code == _POWERS:
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
        elif code == _LEGENDRE:
            p_next = ((2 * d + 1) * t * p_cur - d * p_prev) / (d + 1)
            dp_next = dp_prev + (2 * d + 1) * p_cur
        else:
            p_next = 2.0 * t * p_cur - p_prev
            dp_next = 2.0 * p_cur + 2.0 * t * dp_cur - dp_prev
        p_prev, p_cur, dp_prev, dp_cur = p_cur, p_next, dp_cur, dp_next


@njit(cache=True)
def _evaluate_points(code, degrees, z):
    m = degrees.shape[0]
    out = np.empty((z.shape[0], 2 * m))
    for t in range(z.shape[0]):
        basis_functions(code, degrees, z[t], out[t], 0, m)
    return out[:, :m].copy(), out[:, m:].copy()


class _Basis:
    """Common behaviour of the bases: parameters, evaluation, comparison."""

    code = _POWERS
    #: The constructor's parameters, in its order.
    _param_names = ("degree", "constant")

    def __init__(self, degree=3, *, constant=False):
        self.degree = degree
        self.constant = constant

    @property
    def degrees(self):
        """Degrees of the basis functions, as int64 (0 for the constant)."""
        return np.array([0] * self._n_constant() + list(self._degree_range()), dtype=np.int64)

    def _degree_range(self):
        """The degrees but the constant, as a ``range``: counted without being listed."""
        return range(1, self._checked_degree(1) + 1)

    def _n_constant(self):
        if not isinstance(self.constant, (bool, np.bool_)):
            raise ValueError(
                f"{type(self).__name__}: constant must be a bool, got {self.constant!r}."
            )
        return int(self.constant)

    def _checked_degree(self, lowest):
        degree = self.degree
        if isinstance(degree, bool) or not isinstance(degree, (int, np.integer)) or (
                degree < lowest):
            raise ValueError(
                f"{type(self).__name__}: degree must be an int >= {lowest}, got "
                f"{degree!r}."
            )
        return int(degree)

    @property
    def n_functions(self):
        """Number of basis functions."""
        return len(self._degree_range()) + self._n_constant()

    def evaluate(self, z):
        """Values and derivatives of the basis functions.

        Parameters
        ----------
        z : array-like of shape (n_points,)
            Branch inputs.

        Returns
        -------
        values, slopes : ndarray of shape (n_points, n_functions)
        """
        z = np.ascontiguousarray(z, dtype=np.float64).reshape(-1)
        return _evaluate_points(self.code, self.degrees, z)

    def get_params(self, deep=True):
        """Constructor parameters, for display and comparison.

        Parameters
        ----------
        deep : bool, default=True
            Unused: a basis holds no estimator.

        Returns
        -------
        params : dict
        """
        return {name: getattr(self, name) for name in self._param_names}

    def set_params(self, **params):
        """Set constructor parameters (``basis__degree`` in a grid search).

        Parameters
        ----------
        **params : dict
            Parameter names and values.

        Returns
        -------
        self : object
        """
        for name, value in params.items():
            if name not in self._param_names:
                raise ValueError(
                    f"{type(self).__name__} has no parameter {name!r}; its parameters are "
                    f"{list(self._param_names)}."
                )
            setattr(self, name, value)
        return self

    def __repr__(self):
        params = ", ".join(f"{key}={value!r}" for key, value in self.get_params().items())
        return f"{type(self).__name__}({params})"

    def __eq__(self, other):
        return type(self) is type(other) and self.get_params() == other.get_params()

    def __hash__(self):
        return hash((type(self).__name__, tuple(self.get_params().items())))


class PolynomialBasis(_Basis):
    """Powers of the branch input from degree 2 (the linear part is the model's own).

    Parameters
    ----------
    degree : int, default=3
        Highest power, at least 2.
    kind : {"full", "odd", "even"}, default="full"
        All powers from 2 to ``degree``, the odd ones from 3, or the even ones.
    constant : bool, default=False
        Include a constant. The model works on centred signals and has no
        bias term of its own: a static nonlinearity expanded around the mean
        operating point instead of its own zero needs the constant that the
        shift creates (the linear terms it creates are the model's linear
        part). It helps where the operating point is far from the
        nonlinearity's own zero; without it the fit is faster and, on the
        Silverbox, more accurate.

    Examples
    --------
    >>> from sknlss import PolynomialBasis
    >>> PolynomialBasis(5, kind="odd").degrees
    array([3, 5])
    """

    code = _POWERS
    _param_names = ("degree", "kind", "constant")

    def __init__(self, degree=3, *, kind="full", constant=False):
        self.degree = degree
        self.kind = kind
        self.constant = constant

    def _degree_range(self):
        top = self._checked_degree(2)
        if self.kind not in ("full", "odd", "even"):
            raise ValueError(
                f"PolynomialBasis: kind must be 'full', 'odd' or 'even', got {self.kind!r}."
            )
        first, step = {"full": (2, 1), "odd": (3, 2), "even": (2, 2)}[self.kind]
        degrees = range(first, top + 1, step)
        if not degrees:
            raise ValueError(
                f"PolynomialBasis: kind='odd' needs degree >= 3, got {self.degree!r}."
            )
        return degrees


class LegendreBasis(_Basis):
    """Legendre polynomials of degrees 1 to ``degree`` of ``tanh(z)``.

    The squashing keeps every branch bounded, so the model cannot be driven
    to infinity by its nonlinearity when the input leaves the estimation
    range; within the range, ``tanh`` is a smooth change of variable.

    Parameters
    ----------
    degree : int, default=3
        Highest degree, at least 1.
    constant : bool, default=False
        Include the constant ``P_0`` (see :class:`PolynomialBasis`).
    """

    code = _LEGENDRE


class ChebyshevBasis(_Basis):
    """Chebyshev polynomials of degrees 1 to ``degree`` of ``tanh(z)``.

    Bounded like :class:`LegendreBasis`; the Chebyshev polynomials weight the
    ends of the range more.

    Parameters
    ----------
    degree : int, default=3
        Highest degree, at least 1.
    constant : bool, default=False
        Include the constant ``T_0`` (see :class:`PolynomialBasis`).
    """

    code = _CHEBYSHEV
