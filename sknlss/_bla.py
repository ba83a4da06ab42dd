"""Best Linear Approximation: nonparametric FRF, then a balanced state-space model."""

from numbers import Integral, Real

import numpy as np
from sklearn.utils._param_validation import Interval, StrOptions
from threadpoolctl import threadpool_limits

from ._base import _BaseStateSpace, transient_mask
from ._frf import lpm_frf, robust_frf
from ._linear import (
    balanced_realization,
    estimate_initial_state,
    frf_subspace,
    n_block_rows,
    refine_frf,
    simulate_linear,
    ss_frf,
)

# Variances below this fraction of the mean squared FRF magnitude (a relative
# standard deviation of 1e-6) are treated as this floor, so that noise-free
# lines do not receive unbounded weights.
_RELATIVE_VARIANCE_FLOOR = 1e-12


def _weights(estimate, weighting):
    """Inverse standard deviation of each FRF sample, or ones."""
    if weighting == "noise":
        var = estimate.noise_variance
        var = estimate.total_variance if var is None else var
    elif weighting == "total":
        var = estimate.total_variance
        var = estimate.noise_variance if var is None else var
    else:
        var = None
    if var is None:
        return np.ones(estimate.frf.shape)
    floor = _RELATIVE_VARIANCE_FLOOR * max(np.mean(np.abs(estimate.frf) ** 2),
                                           np.finfo(float).tiny)
    return 1.0 / np.sqrt(np.maximum(var, floor))


class BLAEstimator(_BaseStateSpace):
    """Best Linear Approximation as a balanced linear state-space model.

    The fit has two steps (paper §3.3). First, the nonparametric BLA: the
    frequency response function (FRF) with its variance, by the robust method
    when the data are periodic (``period`` given: every sequence is one
    realization of whole periods) or else by the Local Polynomial Method (LPM),
    which also removes the transient of a record that does not start at rest.
    Second, the parametric BLA: a frequency-domain subspace estimate of
    (A, B, C, D) refined by weighted nonlinear least squares of the model FRF
    on the nonparametric FRF (paper eq. 9, in a state-space parametrisation),
    weighted by the inverse variance, and converted to a balanced realization.
    All fitting happens on signals normalised to zero mean and unit standard
    deviation; the FRF attributes are in the user's units.

    Parameters
    ----------
    n_states : int, default=2
        Model order n.
    period : int, default=None
        Samples per period of a periodic excitation. Every sequence must then
        hold the same whole number of periods. ``None`` for non-periodic data.
    method : {"auto", "robust", "lpm"}, default="auto"
        Nonparametric method: ``"auto"`` is ``"robust"`` when ``period`` is
        given and ``"lpm"`` otherwise. ``"lpm"`` with ``period`` given ignores
        the periodicity.
    lpm_order : int, default=2
        Degree of the local polynomials of the LPM (FRF and transient). It is
        lowered on records too short for it.
    lpm_bandwidth : int, default=None
        Half-width n of the LPM window of ``2 n + 1`` bins. ``None`` takes the
        smallest window leaving three or four degrees of freedom for the noise
        variance (nine bins for one input and ``lpm_order=2``). Records too
        short for the window shrink it, then lower the degree; a record too
        short even for that gives an FRF without variance.
    max_frequency : float, default=None
        Highest frequency used, in cycles per sample (0.5 is Nyquist). Within
        it, only the bins where the input has power are used: the excited lines
        of a periodic excitation, or the LPM bins whose window holds input
        power (at least 1e-3 of the largest window's, so that the leakage of a
        band-limited input is left out). DC is never used (the offsets are
        removed separately).
    weighting : {"total", "noise"} or None, default="total"
        Variance weighting the parametric fit: ``"total"`` (noise plus
        nonlinear distortions) or ``"noise"``; each falls back on the other
        when it cannot be estimated, and ``None`` (or no variance at all, e.g.
        one realization of one period) gives a uniform weighting.
    max_iter : int, default=100
        Levenberg-Marquardt iterations refining the subspace estimate (0 keeps
        the subspace estimate).
    tol : float, default=1e-10
        Relative cost decrease below which the refinement stops.
    estimate_x0 : bool, default=False
        Estimate the initial state (one state shared by all sequences) and a
        correction of the output offset by linear least squares on the
        estimation data; else ``x0_`` is zero.
    n_transient : int, default=0
        Samples at the start of each sequence left out: of the least-squares
        initial state and the score, and of the FRF (with ``period``, the first
        ``ceil(n_transient / period)`` periods of every sequence are dropped;
        for the LPM, the first ``n_transient`` samples).
    verbose : int, default=0
        Print the refinement's progress when positive.

    Attributes
    ----------
    A_ : ndarray of shape (n_states, n_states)
        State matrix (balanced realization, normalised signal units).
    B_ : ndarray of shape (n_states, n_inputs)
        Input matrix.
    C_ : ndarray of shape (n_outputs, n_states)
        Output matrix.
    D_ : ndarray of shape (n_outputs, n_inputs)
        Feed-through matrix.
    x0_ : ndarray of shape (n_states,)
        Initial state, zero unless ``estimate_x0``.
    output_offset_ : ndarray of shape (n_outputs,)
        Correction of the output offset estimated with ``x0_`` (normalised
        units, zero unless ``estimate_x0``): the mean of a record that does not
        start in steady state contains the mean of its transient. ``fit`` adds
        it to ``y_offset_``.
    poles_ : ndarray of shape (n_states,)
        Eigenvalues of ``A_`` (discrete-time poles), sorted by decreasing
        magnitude.
    hankel_singular_values_ : ndarray of shape (n_states,) or None
        Hankel singular values of the balanced model (None when the model
        could not be balanced).
    frequencies_ : ndarray of shape (n_freq,)
        Frequencies of the nonparametric FRF, in cycles per sample.
    frf_ : ndarray of shape (n_freq, n_outputs, n_inputs), complex
        Nonparametric BLA in the user's units.
    noise_variance_ : ndarray of shape (n_freq, n_outputs, n_inputs) or None
        Variance of ``frf_`` due to the noise (robust method with at least two
        periods). For the LPM, the noise and the nonlinear distortions cannot
        be told apart: it equals ``total_variance_``.
    total_variance_ : ndarray of shape (n_freq, n_outputs, n_inputs) or None
        Variance of ``frf_`` due to the noise and the nonlinear distortions
        (robust method with at least two groups of ``n_inputs`` realizations,
        or the LPM).
    frf_model_ : ndarray of shape (n_freq, n_outputs, n_inputs), complex
        FRF of the parametric model at ``frequencies_``, in the user's units.
    n_params_ : int
        Number of parameters as counted in the paper,
        ``n^2 + n n_u + n_y n + n_y n_u`` (plus ``n`` with ``estimate_x0``).
    n_iter_ : int
        Levenberg-Marquardt iterations performed.
    loss_history_ : ndarray of shape (n_iter_ + 1,)
        Weighted FRF cost per iteration (mean squared weighted residual).
    n_features_in_ : int
        Number of inputs.
    u_offset_, u_scale_, y_offset_, y_scale_ : ndarray
        Offsets and scales of the normalisation.

    See Also
    --------
    PNLSSRegressor : Polynomial nonlinear state space initialised from the BLA.
    NLSS2Regressor : Neural-network nonlinear state space initialised from it.

    Notes
    -----
    The robust method needs at least ``n_inputs`` realizations; with more,
    they are grouped ``n_inputs`` at a time (the realizations left over are
    not used), and the spread over groups gives the total variance. The LPM
    treats each sequence as one record; estimates of several records at the
    same frequencies are averaged with inverse-variance weights.

    The parametric step minimises the weighted FRF error of paper eq. 9 over
    the state-space matrices rather than over the coefficients of a rational
    transfer function: the subspace estimate gives a good start for any order
    and for MIMO data, and the state-space parametrisation stays well
    conditioned where polynomial coefficients do not. Steps that would make
    the model unstable are rejected, so the BLA can always be simulated.
    Moreover, every pole's damping is kept large enough for its half-power
    band to reach a measured frequency: the data do not determine the damping
    of a pole farther from them, and an unconstrained fit lets such a pole
    (typically one the order does not need) drift to the unit circle, where
    it amplifies the little input content outside the measured band. Near
    DC this bounds the slowest time constant by ``1 / (2 pi f_min)`` samples,
    ``f_min`` being the lowest frequency of ``frequencies_``; outside the
    measured band the bound tightens with the distance to it, so to identify
    poles there, excite and measure up to them.

    References
    ----------
    R. Pintelon and J. Schoukens, *System Identification: A Frequency Domain
    Approach*, 2nd ed., Wiley-IEEE Press, 2012 (ch. 3-4 and 7).

    T. McKelvey, H. Akçay and L. Ljung, "Subspace-based multivariable system
    identification from frequency response data", IEEE TAC 41(7), 1996.

    Examples
    --------
    >>> import numpy as np
    >>> from scipy.signal import lfilter
    >>> from sknlss import BLAEstimator
    >>> from sknlss.signals import multisine
    >>> u, lines = multisine(256, n_periods=2, n_realizations=2, random_state=0)
    >>> y = lfilter([0.0, 0.5], [1.0, -1.2, 0.5], u, axis=1)
    >>> X, sequence_id = u.reshape(-1, 1), np.repeat([0, 1], u.shape[1])
    >>> bla = BLAEstimator(n_states=2, period=256, n_transient=256)
    >>> bla = bla.fit(X, y.ravel(), sequence_id=sequence_id)
    >>> bla.n_params_
    9
    >>> np.round(np.sort_complex(bla.poles_), 6)
    array([0.6-0.374166j, 0.6+0.374166j])
    """

    _parameter_constraints: dict = {
        **_BaseStateSpace._parameter_constraints,
        "n_states": [Interval(Integral, 1, None, closed="left")],
        "period": [Interval(Integral, 3, None, closed="left"), None],
        "method": [StrOptions({"auto", "robust", "lpm"})],
        "lpm_order": [Interval(Integral, 0, None, closed="left")],
        "lpm_bandwidth": [Interval(Integral, 1, None, closed="left"), None],
        "max_frequency": [Interval(Real, 0, 0.5, closed="right"), None],
        "weighting": [StrOptions({"total", "noise"}), None],
        "max_iter": [Interval(Integral, 0, None, closed="left")],
        "tol": [Interval(Real, 0, None, closed="left")],
        "estimate_x0": ["boolean"],
        "verbose": ["verbose"],
    }

    def __init__(
        self,
        n_states=2,
        *,
        period=None,
        method="auto",
        lpm_order=2,
        lpm_bandwidth=None,
        max_frequency=None,
        weighting="total",
        max_iter=100,
        tol=1e-10,
        estimate_x0=False,
        n_transient=0,
        verbose=0,
    ):
        self.n_states = n_states
        self.period = period
        self.method = method
        self.lpm_order = lpm_order
        self.lpm_bandwidth = lpm_bandwidth
        self.max_frequency = max_frequency
        self.weighting = weighting
        self.max_iter = max_iter
        self.tol = tol
        self.estimate_x0 = estimate_x0
        self.n_transient = n_transient
        self.verbose = verbose

    def fit(self, X, y, *, sequence_id=None):
        """Fit the BLA to input/output records.

        Parameters
        ----------
        X : array-like of shape (n_samples, n_inputs)
            Input signal u; rows are time samples.
        y : array-like of shape (n_samples,) or (n_samples, n_outputs)
            Measured output signal.
        sequence_id : array-like of shape (n_samples,), default=None
            Integer label of the record (realization) each row belongs to;
            each label occupies one contiguous block of rows.

        Returns
        -------
        self : object
            The fitted estimator.
        """
        super().fit(X, y, sequence_id=sequence_id)
        self.y_offset_ = self.y_offset_ + self.y_scale_ * self.output_offset_
        # the nonparametric and model FRFs in the user's units
        scale = self.y_scale_[:, None] / self.u_scale_[None, :]
        self.frf_ = self.frf_ * scale
        self.frf_model_ = self.frf_model_ * scale
        noise, total = self.noise_variance_, self.total_variance_
        if noise is not None:
            self.noise_variance_ = noise * scale**2
        if total is not None:
            self.total_variance_ = (
                self.noise_variance_ if total is noise else total * scale**2
            )
        return self

    def _nonparametric(self, U, Y, starts):
        method = self.method
        if method == "auto":
            method = "lpm" if self.period is None else "robust"
        if method == "robust":
            if self.period is None:
                raise ValueError('method="robust" needs the `period` of the excitation.')
            return robust_frf(U, Y, starts, self.period, n_transient=self.n_transient,
                              max_frequency=self.max_frequency)
        shortest = int(np.diff(starts).min()) - self.n_transient
        if shortest < 2:
            raise ValueError(
                f"A record of {shortest} sample(s) after n_transient={self.n_transient} "
                "is too short for the Local Polynomial Method."
            )
        return lpm_frf(U, Y, starts, order=self.lpm_order, bandwidth=self.lpm_bandwidth,
                       n_transient=self.n_transient, max_frequency=self.max_frequency)

    def _fit_normalized(self, U, Y, starts):
        # The factorisations here are small: multithreaded BLAS only adds
        # synchronisation cost (tenfold on two cores, see DESIGN.md §2).
        with threadpool_limits(limits=1, user_api="blas"):
            return self._fit_linear(U, Y, starts)

    def _fit_linear(self, U, Y, starts):
        n, n_u, n_y = self.n_states, U.shape[1], Y.shape[1]
        estimate = self._nonparametric(U, Y, starts)
        n_freq = estimate.frequencies.size
        n_free = n * (n_u + n_y) + n_y * n_u
        if 2 * n_freq * n_y * n_u < n_free:
            raise ValueError(
                f"n_states={n} is too large for the {n_freq} frequency line(s) of the "
                f"FRF: {2 * n_freq * n_y * n_u} real FRF values cannot determine "
                f"{n_free} identifiable parameters. Use a longer record or fewer states."
            )
        n_block_rows(n, n_freq, n_u)
        weight = _weights(estimate, self.weighting)
        G, freqs = estimate.frf, estimate.frequencies
        A, B, C, D = frf_subspace(freqs, G, weight, n)
        self.n_iter_, self.loss_history_ = 0, None
        if self.max_iter > 0:
            A, B, C, D, result = refine_frf(A, B, C, D, freqs, G, weight,
                                            max_iter=self.max_iter, tol=self.tol,
                                            verbose=self.verbose)
            self.n_iter_, self.loss_history_ = result.n_iter, result.loss_history
        A, B, C, D, hsv = balanced_realization(A, B, C, D)
        self.A_, self.B_, self.C_, self.D_ = A, B, C, D
        self.hankel_singular_values_ = hsv
        self.frequencies_ = freqs
        self.frf_ = G
        self.noise_variance_ = estimate.noise_variance
        self.total_variance_ = estimate.total_variance
        self.frf_model_ = ss_frf(A, B, C, D, freqs)
        self.n_params_ = n * n + n_free
        self.x0_, self.output_offset_ = np.zeros(n), np.zeros(n_y)
        if self.estimate_x0:
            mask = transient_mask(starts, self.n_transient)
            self.x0_, self.output_offset_ = estimate_initial_state(A, B, C, D, U, Y,
                                                                   starts, mask)
            self.n_params_ += n
        return self

    def _simulate_normalized(self, U, starts, x0):
        return simulate_linear(self.A_, self.B_, self.C_, self.D_, U, starts, x0)

    @property
    def poles_(self):
        """Discrete-time poles (eigenvalues of ``A_``), by decreasing magnitude."""
        poles = np.linalg.eigvals(self.A_)
        return poles[np.argsort(-np.abs(poles), kind="stable")]
