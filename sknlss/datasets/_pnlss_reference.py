"""Data from the reference PNLSS system of the PNLSS 1.0 toolbox tutorial (VUB ELEC)."""


import numpy as np
from sklearn.utils import Bunch, check_random_state
from sklearn.utils._param_validation import validate_params

from .._core._model import StateSpaceModel
from .._terms._polynomial import PolynomialTerms, monomial_exponents
from .._validation import Integers
from ..signals import multisine

# The true system: 2 states, 1 input, 1 output; E and F weigh the 16 monomials
# of degree 2 and 3 in s = [x1, x2, u] (order of ``monomial_exponents``).
_A = np.array([[0.73915535, -0.62433133],
               [0.6247377, 0.7364469]])
_B = np.array([[0.79287245],
               [-0.34515159]])
_C = np.array([[0.71165154, 0.34917771]])
_D = np.array([[0.04498052]])
_E = np.array([
    [0.188130305, -0.2702919, 0.00912423046, -0.5780885, 0.00954588221,
     0.000508576019, -1.3389085, -2.0217196, -0.405918956, -1.37744223,
     0.121206232, -0.0926349423, -0.538072197, 0.0023413446, 0.049433469,
     -0.0188329572],
    [-0.53519611, -0.366250013, 0.0234622651, 0.143228677, -0.0135959331,
     0.0132052696, 0.798717915, 1.35344901, -0.0529440815, 0.488513652,
     0.781285093, -0.341019453, 0.227692972, 0.0770150211, -0.0125046731,
     -0.0162456154],
])
_F = np.array([[
    -0.00867042, -0.00636662, 0.00197873, -0.00090865, -0.00088879, -0.02759694,
    -0.01817546, -0.10299409, 0.00648549, 0.08990175, 0.21129849, 0.00030216,
    0.03299013, 0.02058325, -0.09202439, -0.0380775,
]])

_RMS = 0.05
_NOISE_LEVEL = 1e-3
# Samples over which the slowest mode of the linear part (|pole| 0.967)
# decays to 1e-12 of its size: the run-in before the kept periods.
_RUN_IN = int(np.ceil(np.log(1e-12) / np.log(np.max(np.abs(np.linalg.eigvals(_A))))))

_DESCR = """\
Reference PNLSS system (PNLSS 1.0 toolbox tutorial, VUB ELEC)
-------------------------------------------------------------

x(t+1) = A x(t) + B u(t) + E zeta(x(t), u(t)),  y(t) = C x(t) + D u(t) + F eta(x(t), u(t)),
with 2 states, 1 input, 1 output; zeta = eta = the 16 monomials of total degree
2 and 3 in s = [x1, x2, u] (rows of ``exponents``).

Excitation: odd random-phase multisine, flat amplitude on the odd lines up to
90 % of the Nyquist frequency, RMS 0.05, one realization per sequence, several
periods each, in steady state (the periods of the first 815 samples, at
least one, simulated first and dropped: the slowest mode decays to 1e-12 in
them).
Noise: n = 1e-3 std(y) e with white Gaussian e, coloured by n[t] + n[t+1]
(t = 1 .. end-2 of each realization), added to y.

Customary use: realizations 0-1 for estimation, 2 (last period) for validation,
3 (last period) for test. A linear model reaches a test RMS error of about 0.033,
a correct PNLSS model about 1e-4 to 3e-4.
"""


@validate_params(
    {
        "n_realizations": [Integers(1, None, closed="left")],
        "n_periods": [Integers(1, None, closed="left")],
        "n_samples_per_period": [Integers(8, None, closed="left")],
        "noise": ["boolean"],
        "random_state": ["random_state"],
    },
    prefer_skip_nested_validation=True,
)
def make_pnlss_reference(*, n_realizations=4, n_periods=3, n_samples_per_period=1024,
                         noise=True, random_state=0):
    """Steady-state multisine data of the reference PNLSS system.

    The known 2-state SISO system of the PNLSS 1.0 toolbox tutorial is excited
    by odd random-phase multisines (RMS 0.05, flat on the odd lines up to 90 %
    of the Nyquist frequency), one realization per sequence.

    Parameters
    ----------
    n_realizations : int, default=4
        Number of realizations (independent phases), one sequence each.
    n_periods : int, default=3
        Periods kept per realization, after the dropped periods that bring
        the system to its periodic steady state (one when a period has 815
        samples or more).
    n_samples_per_period : int, default=1024
        Samples per period.
    noise : bool, default=True
        Add the coloured output noise of the tutorial:
        ``n = 1e-3 * std(y) * e`` with white Gaussian ``e``, then
        ``n[t] + n[t + 1]`` for t in 1 .. end-2 of each realization.
    random_state : int, RandomState instance or None, default=0
        Seed of the phases and of the noise.

    Returns
    -------
    data : :class:`~sklearn.utils.Bunch`
        Dictionary-like object with the attributes:

        X : ndarray of shape (n_realizations * n_periods * n_samples_per_period, 1)
            Input, realizations stacked, periods consecutive.
        y : ndarray of shape (n_realizations * n_periods * n_samples_per_period,)
            Output, with noise when ``noise`` is True.
        y_noiseless : ndarray of the same shape as ``y``
            Output without noise.
        sequence_id : ndarray of shape (n_realizations * n_periods * n_samples_per_period,)
            Realization index of each row.
        period : int
            Samples per period.
        lines : ndarray of shape (n_lines,)
            Excited DFT lines of a period.
        A, B, C, D, E, F : ndarray
            True matrices, of shapes (2, 2), (2, 1), (1, 2), (1, 1), (2, 16)
            and (1, 16).
        exponents : ndarray of shape (16, 3)
            Exponents of the monomials in ``[x1, x2, u]`` weighed by the columns
            of E and F.
        DESCR : str
            Description of the system and the experiment.

    See Also
    --------
    sknlss.signals.multisine : The excitation.

    Examples
    --------
    >>> from sknlss.datasets import make_pnlss_reference
    >>> data = make_pnlss_reference(n_realizations=2, n_periods=2)
    >>> data.X.shape, data.y.shape, data.exponents.shape
    ((4096, 1), (4096,), (16, 3))
    """
    rng = check_random_state(random_state)
    exponents = monomial_exponents(2, 1, (2, 3))
    n = int(n_samples_per_period)
    n_dropped = -(-_RUN_IN // n)
    u, lines = multisine(n, n_periods=n_periods + n_dropped, n_realizations=n_realizations,
                         lines="odd", band=(0.0, 0.45), rms=_RMS, random_state=rng)
    starts = np.arange(n_realizations + 1, dtype=np.int64) * u.shape[1]
    model = StateSpaceModel(2, 1, 1, PolynomialTerms(2, 1, exponents, exponents))
    theta = model.pack({"A": _A, "B": _B, "C": _C, "D": _D, "E": _E, "F": _F})
    y_all = model.simulate(theta, u.reshape(-1, 1), starts)[0]
    # The first periods of every realization hold the transient from rest.
    y_clean = y_all[:, 0].reshape(n_realizations, -1)[:, n_dropped * n:]
    u = u[:, n_dropped * n:]
    y = y_clean.copy()
    if noise:
        white = _NOISE_LEVEL * y_clean.std() * rng.standard_normal(y_clean.shape)
        coloured = white.copy()
        coloured[:, 1:-2] += white[:, 2:-1]
        y += coloured
    length = u.shape[1]
    return Bunch(
        X=u.reshape(-1, 1),
        y=y.ravel(),
        y_noiseless=y_clean.ravel(),
        sequence_id=np.repeat(np.arange(n_realizations), length),
        period=n,
        lines=lines,
        A=_A.copy(), B=_B.copy(), C=_C.copy(), D=_D.copy(), E=_E.copy(), F=_F.copy(),
        exponents=exponents,
        DESCR=_DESCR,
    )
