"""Selection among fits that hold out different ends of the records.

On a short record the iterate (and the start) that a single held-out end
selects depends strongly on where that end begins: a few dozen samples more or
less can move an overflow episode or a large excursion between the fitted and
the held-out part. :class:`HoldoutSearch` fits one model per held-out share
(and per parameter setting) and keeps the one with the smallest simulation
error on the end of the records that all of them held out.
"""

import warnings

import numpy as np
from sklearn.base import BaseEstimator, MetaEstimatorMixin, RegressorMixin, clone
from sklearn.exceptions import FitFailedWarning
from sklearn.model_selection import ParameterGrid
from sklearn.utils import get_tags
from sklearn.utils._param_validation import HasMethods
from sklearn.utils.validation import check_is_fitted

from ._core._multistart import recorded_warnings, run_starts
from ._core._sequences import holdout_masks, sequence_bounds
from ._estimators._base import _unfitted_on_error
from ._validation import ANY_INTEGER, binary_magnitude, naming
from .exceptions import SimulationDivergedWarning, warn_at_caller

__all__ = ["HoldoutSearch"]


def _fit_candidate(estimator, params, X, y, sequence_id):
    """A fitted candidate and the warnings of its fit, as ``(message,
    category)`` pairs: those of a joblib worker would not reach the caller."""
    with recorded_warnings() as caught:
        model = clone(estimator).set_params(**params).fit(X, y, sequence_id=sequence_id)
    return model, caught


def _fitted_states(model):
    """The initial states ``model`` fitted to each of its training sequences,
    to simulate them again; None (its own default) when it has one state for
    all, or when it starts periodic sequences in steady state (which a given
    state would override)."""
    states = getattr(model, "x0_", None)
    periodic = (getattr(model, "period", None) is not None
                and getattr(model, "n_transient", 0) > 0)
    return states if np.ndim(states) == 2 and not periodic else None


def _holdout_errors(model, X, Y, sequence_id, rows):
    """Coefficient of determination and RMS error of the free-run simulation on
    ``rows`` (uniform average over the outputs); ``-inf`` and ``inf`` when the
    simulation diverges."""
    with warnings.catch_warnings():
        # A candidate that diverges is ranked last; that is its whole outcome.
        warnings.simplefilter("ignore", SimulationDivergedWarning)
        states = _fitted_states(model)
        given = {} if states is None else {"x0": states}
        simulated = np.asarray(model.predict(X, sequence_id=sequence_id, **given)).reshape(
            Y.shape)
    if not np.all(np.isfinite(simulated[rows])):
        return -np.inf, np.inf
    # In units of a power of two near each output's largest value, measured or
    # simulated (an exact scaling), the squares cannot overflow; the RMS error
    # is scaled back.
    unit = np.maximum(binary_magnitude(Y[rows]), binary_magnitude(simulated[rows]))
    measured = Y[rows] / unit
    mse = np.mean((simulated[rows] / unit - measured) ** 2, axis=0)
    variance = np.var(measured, axis=0)
    r2 = 1.0 - mse / np.where(variance > 0, variance, 1.0)
    top = unit.max()
    return float(np.mean(r2)), float(top * np.sqrt(np.mean(mse * (unit / top) ** 2)))


class HoldoutSearch(MetaEstimatorMixin, RegressorMixin, BaseEstimator):
    """Best of several fits with different held-out ends, judged on their common end.

    Each candidate is a clone of ``estimator`` fitted with one of the
    ``validation_fractions`` (and one setting of ``param_grid``): it fits the
    first part of every sequence and selects its iterate (and start) on the
    rest. All candidates are then simulated over the whole records and ranked
    by the coefficient of determination on the last ``min(validation_fractions)``
    of every sequence, which none of them was fitted on. The best one is kept
    and used by ``predict``.

    On short records this is steadier than a single split: the model a single
    held-out end selects can change a lot when the boundary moves by a few
    samples (see ``benchmarks/bench_cascaded_tanks_splits.py``).

    Parameters
    ----------
    estimator : estimator
        A sknlss estimator with a ``validation_fraction`` parameter.
    validation_fractions : array-like of float, default=(0.25, 0.275, 0.3, 0.325, 0.35)
        Held-out shares of the end of every sequence, one candidate fit each.
    param_grid : dict or list of dict, default=None
        Further settings to combine with every fraction, as in
        :class:`~sklearn.model_selection.GridSearchCV`; ``None`` varies the
        fraction only.
    n_jobs : int, default=None
        Number of candidates fitted in parallel (joblib).

    Attributes
    ----------
    best_estimator_ : estimator
        The selected fitted candidate.
    best_params_ : dict
        Its settings, ``validation_fraction`` included.
    best_score_ : float
        Its coefficient of determination on the common held-out end.
    best_index_ : int
        Its position in the lists of ``results_``.
    results_ : dict of lists
        Per candidate: ``params``, ``holdout_score`` (coefficient of
        determination, ``-inf`` for a diverging simulation or a failed fit),
        ``holdout_rms`` (RMS error in output units, averaged over the outputs
        as mean squares; ``inf`` likewise) and ``error`` (the message of the
        error that stopped the candidate's fit, None when it fitted).
    holdout_fraction_ : float
        Share of the end of every sequence on which the candidates are ranked.
    n_features_in_ : int
        Number of inputs.
    feature_names_in_ : ndarray of shape (n_features_in_,)
        Names of the inputs, when ``X`` has column names of strings.
    n_params_ : int
        Number of free parameters of the selected model.

    See Also
    --------
    sklearn.model_selection.GridSearchCV : Cross-validated search, for
        settings that a split of independent records can judge.

    Examples
    --------
    >>> import numpy as np
    >>> from sknlss import PNLSSRegressor
    >>> from sknlss.model_selection import HoldoutSearch
    >>> rng = np.random.default_rng(0)
    >>> u = 0.3 * rng.normal(size=(400, 1))
    >>> y = np.zeros(400)
    >>> x = 0.0
    >>> for t in range(400):
    ...     y[t] = x
    ...     x = 0.5 * x + u[t, 0] + 0.1 * x**2
    >>> search = HoldoutSearch(PNLSSRegressor(n_states=1, degree=2, max_iter=10),
    ...                        validation_fractions=[0.2, 0.25]).fit(u, y)
    >>> sorted(search.best_params_)
    ['validation_fraction']
    >>> bool(search.score(u, y) > 0.99)
    True
    """

    _parameter_constraints: dict = {
        "estimator": [HasMethods(["fit", "predict", "get_params"])],
        "validation_fractions": ["array-like"],
        "param_grid": [dict, list, None],
        "n_jobs": [ANY_INTEGER, None],
    }

    def __init__(self, estimator, *, validation_fractions=(0.25, 0.275, 0.3, 0.325, 0.35),
                 param_grid=None, n_jobs=None):
        self.estimator = estimator
        self.validation_fractions = validation_fractions
        self.param_grid = param_grid
        self.n_jobs = n_jobs

    def _candidates(self):
        with naming("validation_fractions"):
            fractions = np.asarray(self.validation_fractions, dtype=np.float64).ravel()
        if fractions.size == 0 or not np.all((fractions > 0) & (fractions < 1)):
            raise ValueError(
                "validation_fractions must hold at least one share strictly between "
                f"0 and 1; got {self.validation_fractions!r}."
            )
        if "validation_fraction" not in self.estimator.get_params():
            raise ValueError(
                f"estimator={type(self.estimator).__name__}() has no validation_fraction "
                "parameter: it cannot hold out the end of the records."
            )
        with naming("param_grid"):
            grid = ParameterGrid({} if self.param_grid is None else self.param_grid)
        for params in grid:
            if "validation_fraction" in params:
                raise ValueError(
                    "param_grid must not set validation_fraction; use "
                    "validation_fractions."
                )
        candidates = [{**params, "validation_fraction": float(fraction)}
                      for params in grid for fraction in fractions]
        if not candidates:
            raise ValueError(
                f"param_grid={self.param_grid!r} holds no setting to try; use None to "
                "vary the held-out share only."
            )
        return candidates, float(fractions.min())

    @_unfitted_on_error
    def fit(self, X, y, *, sequence_id=None):
        """Fit every candidate and keep the best on the common held-out end.

        A candidate whose fit raises an error is ranked last (with a
        :class:`~sklearn.exceptions.FitFailedWarning`); the error of the first
        candidate is raised when none fits. A
        :class:`~sknlss.SimulationDivergedWarning` says when the simulations of
        all fitted candidates diverge on the held-out end.

        Parameters
        ----------
        X : array-like of shape (n_samples, n_inputs)
            Input signal.
        y : array-like of shape (n_samples,) or (n_samples, n_outputs)
            Measured output signal.
        sequence_id : array-like of shape (n_samples,), default=None
            Sequence labels (see the estimator's ``fit``).

        Returns
        -------
        self : object
            The fitted search.
        """
        self._validate_params()
        candidates, holdout_fraction = self._candidates()
        # A candidate whose numerics fail leaves the others standing.
        outcomes = run_starts(_fit_candidate, [(self.estimator, params, X, y, sequence_id)
                                               for params in candidates], n_jobs=self.n_jobs)
        models = []
        for outcome in outcomes:
            if isinstance(outcome, Exception):
                models.append(outcome)
                continue
            model, caught = outcome
            for message, category in caught:
                warn_at_caller(message, category)
            models.append(model)
        fitted = [i for i, model in enumerate(models) if not isinstance(model, Exception)]
        if not fitted:
            raise models[0]
        if len(fitted) < len(models):
            failed = next(model for model in models if isinstance(model, Exception))
            warn_at_caller(
                f"{len(models) - len(fitted)} of {len(models)} candidates failed to fit "
                f"and are ranked last (see results_['error']); the first error: {failed}",
                FitFailedWarning)
        # The candidates validated the data; the ranking only needs the
        # output as an array (they predict the input as given).
        Y = np.asarray(y, dtype=np.float64)
        Y = Y.reshape(len(Y), -1)
        starts = sequence_bounds(sequence_id, len(Y))
        params = self.estimator.get_params()
        # With a period, the transient is simulated before each sequence, not
        # taken from it.
        n_transient = 0 if params.get("period") is not None else params.get("n_transient", 0)
        rows = holdout_masks(starts, n_transient, holdout_fraction)[1]
        if not rows.any():
            raise ValueError(
                f"validation_fractions: the smallest share, {holdout_fraction}, holds out "
                "no sample of these records (it is rounded to whole samples per "
                "sequence); use a larger share.")
        errors = [(-np.inf, np.inf) if isinstance(model, Exception)
                  else _holdout_errors(model, X, Y, sequence_id, rows)
                  for model in models]
        scores = [score for score, _ in errors]
        # The first of the best fitted candidates (the first fitted one when
        # all diverge).
        best = max(fitted, key=lambda i: scores[i])
        if scores[best] == -np.inf:
            warn_at_caller(
                "The simulation of every fitted candidate diverges on the held-out end: "
                f"the first one ({candidates[best]}) is kept, but no candidate simulates "
                "these data.", SimulationDivergedWarning)
        self.holdout_fraction_ = holdout_fraction
        self.results_ = {
            "params": candidates,
            "holdout_score": scores,
            "holdout_rms": [rms for _, rms in errors],
            "error": [str(model) if isinstance(model, Exception) else None
                      for model in models],
        }
        self.best_index_ = best
        self.best_estimator_ = models[best]
        self.best_params_ = candidates[best]
        self.best_score_ = scores[best]
        self.n_features_in_ = self.best_estimator_.n_features_in_
        if hasattr(self.best_estimator_, "feature_names_in_"):
            self.feature_names_in_ = self.best_estimator_.feature_names_in_
        return self

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        # What the search can fit and how well is what its estimator can.
        inner = get_tags(self.estimator)
        tags.target_tags.multi_output = inner.target_tags.multi_output
        tags.regressor_tags.poor_score = inner.regressor_tags.poor_score
        return tags

    def predict(self, X, *, sequence_id=None, x0=None):
        """Free-run simulation of the selected model (see its ``predict``).

        Parameters
        ----------
        X : array-like of shape (n_samples, n_inputs)
            Input signal.
        sequence_id : array-like of shape (n_samples,), default=None
            Sequence labels.
        x0 : array-like, default=None
            Initial state; ``None`` starts as the selected model's ``predict``
            does (from its fitted ``x0_``).

        Returns
        -------
        y : ndarray of shape (n_samples,) or (n_samples, n_outputs)
            Simulated output.
        """
        check_is_fitted(self)
        return self.best_estimator_.predict(X, sequence_id=sequence_id, x0=x0)

    def score(self, X, y, sample_weight=None, *, sequence_id=None):
        """R² of the selected model's simulated output (see its ``score``).

        Parameters
        ----------
        X : array-like of shape (n_samples, n_inputs)
            Input signal.
        y : array-like of shape (n_samples,) or (n_samples, n_outputs)
            Measured output.
        sample_weight : array-like of shape (n_samples,), default=None
            Weight of each sample in the R².
        sequence_id : array-like of shape (n_samples,), default=None
            Sequence labels.

        Returns
        -------
        score : float
        """
        check_is_fitted(self)
        return self.best_estimator_.score(X, y, sample_weight, sequence_id=sequence_id)

    def estimate_initial_state(self, X, y, *, sequence_id=None, x0=None, max_iter=100):
        """Initial state of the selected model that fits a record's first
        samples (see its ``estimate_initial_state``).

        Parameters
        ----------
        X : array-like of shape (n_samples, n_inputs)
            Input signal.
        y : array-like of shape (n_samples,) or (n_samples, n_outputs)
            Measured output.
        sequence_id : array-like of shape (n_samples,), default=None
            Sequence labels of several records, each given its own state.
        x0 : array-like of shape (n_states,) or (n_sequences, n_states), default=None
            Where the search starts; ``None`` starts as the selected model's
            ``estimate_initial_state`` does.
        max_iter : int, default=100
            Maximum number of Levenberg-Marquardt iterations.

        Returns
        -------
        x0 : ndarray of shape (n_states,) or (n_sequences, n_states)
            Initial state, one row per sequence with ``sequence_id``, as
            ``predict`` takes it.
        """
        check_is_fitted(self)
        return self.best_estimator_.estimate_initial_state(
            X, y, sequence_id=sequence_id, x0=x0, max_iter=max_iter)

    @property
    def n_params_(self):
        """Number of free parameters of the selected model."""
        check_is_fitted(self)
        return self.best_estimator_.n_params_
