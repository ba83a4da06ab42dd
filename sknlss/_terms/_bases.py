"""Univariate bases of the static nonlinearities of branch models.

A branch model (the NL-LFR model and the decoupled PNLSS model) applies a
univariate function ``f_l(z) = sum_k c_lk phi_k(z)`` to each of its branch
inputs ``z_l``. A basis is a small object that names its functions for the
compiled code (``code``, ``degrees``) and evaluates them in NumPy through the
same compiled routine. The compiled kernels apply the functions that ``code``
names, whatever the object's own methods would say, so a basis is an instance
of one of the families below (see :func:`check_basis`).

A new family is a subclass here (its ``code``, ``_degree_range``, ``bounded``
and ``homogeneous``) and its case in
:func:`sknlss._terms._branches.basis_functions`, which lives beside the
kernels that inline it: numba's cache of a compiled function is renewed when
the function's own file changes, not when a file it inlines from does.
"""

import numpy as np
from sklearn.utils._param_validation import HasMethods

from ._branches import BASIS_CODES, CHEBYSHEV, LEGENDRE, POWERS, evaluate_basis

_FAMILIES = "PolynomialBasis, LegendreBasis or ChebyshevBasis"


class _Basis:
    """Common behaviour of the bases: parameters, evaluation, comparison."""

    #: The family's case in the compiled code (see :func:`check_basis`). A
    #: family also says whether its functions stay ``bounded`` however far the
    #: input goes, whether they are ``homogeneous`` (scaling the input and
    #: each coefficient by the matching power leaves the combination unchanged,
    #: one more direction per branch that the data cannot fix) and, through
    #: ``shifted``, whether the branch inputs take a fitted bias.
    code = None
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
        return int(self._flag("constant"))

    def _flag(self, name):
        value = getattr(self, name)
        if not isinstance(value, (bool, np.bool_)):
            raise ValueError(f"{type(self).__name__}: {name} must be a bool, got {value!r}.")
        return bool(value)

    @property
    def shifted(self):
        """Whether each branch input has a fitted bias (see ``shift``)."""
        return False

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
        return evaluate_basis(self.code, self.degrees, z)

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

    code = POWERS
    bounded = False
    homogeneous = True
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


class _TanhBasis(_Basis):
    """Polynomials of ``tanh(z + b)``: bounded, with an optional fitted bias."""

    bounded = True
    homogeneous = False
    _param_names = ("degree", "constant", "shift")

    def __init__(self, degree=3, *, constant=False, shift=False):
        self.degree = degree
        self.constant = constant
        self.shift = shift

    @property
    def shifted(self):
        """Whether each branch input has a fitted bias (see ``shift``)."""
        shift = self._flag("shift")
        if shift and self._flag("constant"):
            raise ValueError(
                f"{type(self).__name__}: constant=True with shift=True: a shifted branch "
                "is anchored at zero, so its constant cancels. Leave constant=False (with "
                "estimate_x0=True the model estimates an output offset).")
        return shift


_TANH_PARAMETERS = """
    Parameters
    ----------
    degree : int, default=3
        Highest degree, at least 1.
    constant : bool, default=False
        Include the constant {constant} (see :class:`PolynomialBasis`).
    shift : bool, default=False
        Give each branch a fitted bias :math:`b_l` of its input, anchored
        at zero: :math:`f_l(z) = \\sum_k c_{{lk}} ({name}_k(\\tanh(z + b_l)) -
        {name}_k(\\tanh(b_l)))`. The saturation need not then be centred on
        the mean operating point, which stays the model's rest state (the
        constant cancels: ``constant=True`` is refused with it). With
        ``degree=1``, each branch is one unit :math:`c_l (\\tanh(z + b_l) -
        \\tanh(b_l))`, and ``n_branches`` of them form a one-hidden-layer
        network in feedback (see the user guide).
"""


class LegendreBasis(_TanhBasis):
    __doc__ = """Legendre polynomials of degrees 1 to ``degree`` of ``tanh(z)``.

    The squashing keeps every branch bounded, so the model cannot be driven
    to infinity by its nonlinearity when the input leaves the estimation
    range; within the range, ``tanh`` is a smooth change of variable.
""" + _TANH_PARAMETERS.format(constant="``P_0``", name="P") + """
    Examples
    --------
    >>> from sknlss import LegendreBasis
    >>> LegendreBasis(1, shift=True)
    LegendreBasis(degree=1, constant=False, shift=True)
"""

    code = LEGENDRE


class ChebyshevBasis(_TanhBasis):
    __doc__ = """Chebyshev polynomials of degrees 1 to ``degree`` of ``tanh(z)``.

    Bounded like :class:`LegendreBasis`; the Chebyshev polynomials weight the
    ends of the range more.
""" + _TANH_PARAMETERS.format(constant="``T_0``", name="T")

    code = CHEBYSHEV


def check_basis(basis):
    """Refuse a basis whose functions the compiled kernels would not apply.

    ``basis`` is an instance of a family's class (:class:`BasisConstraint`
    checks that with the other parameters). The kernels evaluate the family
    that ``basis.code`` names: a class that names none, or an instance whose
    functions (``evaluate``, ``degrees``, ``n_functions``) are redefined, in a
    subclass or on the object itself, would be fitted with other functions
    than it describes, so it is refused here rather than fitted silently.
    Parameters out of their family's range (a ValueError) are refused here too,
    with the basis named as the estimator's argument.
    """
    if basis.code not in BASIS_CODES:
        raise TypeError(
            f"basis {basis!r} names no family the compiled kernels know (code "
            f"{basis.code!r}); they apply the functions of {_FAMILIES} only. A new "
            "family is added to sknlss itself (see sknlss._terms._bases).")
    redefined = [name for name in ("evaluate", "degrees", "n_functions")
                 if name in vars(basis) or getattr(type(basis), name) is not getattr(_Basis, name)]
    if redefined:
        raise TypeError(
            f"basis {basis!r} redefines {', '.join(redefined)} of its family: the compiled "
            "kernels would apply the family's functions, not these. Subclass a family "
            f"({_FAMILIES}) only to change its parameters.")
    try:
        basis.degrees, basis.shifted
    except ValueError as error:
        # The family checks its parameters where they are used; the user set
        # them through the estimator's ``basis`` argument.
        raise ValueError(f"basis={basis!r} cannot be used: {error}") from error


class BasisConstraint(HasMethods):
    """The ``basis`` parameter's constraint for scikit-learn's parameter
    validation: an instance of one of the families, named as the user knows
    them (:func:`check_basis` then checks what an instance may not redefine).

    A :class:`~sklearn.utils._param_validation.HasMethods` because scikit-learn
    takes only its own kinds of constraint; the check is the instance's family.
    """

    def __init__(self):
        super().__init__(["evaluate"])

    def is_satisfied_by(self, val):
        return isinstance(val, _Basis)

    def __str__(self):
        return f"a {_FAMILIES}"
