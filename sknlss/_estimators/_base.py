"""Shared behaviour of the state-space estimators.

Every estimator identifies a discrete-time model

    x(t+1) = f(x(t), u(t)),    y(t) = g(x(t), u(t))

on normalised signals ``u_n = (u - u_offset_) / u_scale_`` and
``y_n = (y - y_offset_) / y_scale_``. The base class owns what is common to all
of them: input validation, splitting the rows into sequences, the offsets and
scales, the initial state, free-run simulation and scoring. Subclasses implement
``_fit_normalized`` and ``_fitted_model`` (the model structure and parameter
vector the shared kernels simulate).
"""

import functools
from abc import ABCMeta, abstractmethod

import numpy as np
from sklearn.base import BaseEstimator, RegressorMixin
from sklearn.metrics import r2_score
from sklearn.utils._param_validation import validate_params
from sklearn.utils.validation import (
    _check_sample_weight,
    check_array,
    check_consistent_length,
    check_is_fitted,
    validate_data,
)

from .._core._kernels import DIVERGENCE_BOUND
from .._core._multistart import fit_initial_state
from .._core._sequences import delayed_input, sequence_bounds, transient_mask
from .._validation import Integers, binary_magnitude, naming
from ..exceptions import SimulationDivergedWarning, warn_at_caller

#: The fitted attributes that describe the normalisation of the signals (and
#: the delay of the inputs, which the model sees delayed).
_NORMALISATION = ("n_features_in_", "n_outputs_", "_y_was_1d", "u_offset_", "u_scale_",
                  "y_offset_", "y_scale_", "input_delay_")


def normalisation_of(estimator):
    """The normalisation attributes of a fitted (or fitting) estimator, as a dict."""
    return {name: getattr(estimator, name) for name in _NORMALISATION}

#: A column whose standard deviation is below this fraction of its largest
#: magnitude is constant to working precision: it carries no signal.
_CONSTANT = 1e-12


def _record_input(estimator, X, *, reset, ensure_min_samples=1):
    """``X`` validated as scikit-learn validates features, with the advice
    for records: scikit-learn's own (reshape to one sample, drop the samples
    with missing values) would change the experiment."""
    with naming("X"):
        try:
            X = validate_data(estimator, X, reset=reset, dtype=np.float64,
                              ensure_min_samples=ensure_min_samples, ensure_all_finite=False)
        except ValueError as error:
            # scikit-learn's message for a 1-D array, whose advice to reshape
            # it into one sample would turn a record into a single sample.
            if "got 1D array" not in str(error):
                if reset:
                    # A signal stored as one row fails the minimum number of
                    # samples: the advice is to transpose it.
                    _refuse_rows_as_signals(getattr(X, "shape", ()), "X")
                raise
            raise ValueError(
                "X must be 2-D, of shape (n_samples, n_inputs); got a 1-D array. Reshape "
                "your data: a single input signal u is passed as u.reshape(-1, 1).") from None
    if reset:
        _refuse_rows_as_signals(X.shape, "X")
    _refuse_gaps(X, "X")
    return X


def _record_output(y):
    """``y`` validated as scikit-learn validates targets, with the advice for
    records (see :func:`_record_input`)."""
    with naming("y"):
        y = check_array(y, ensure_2d=False, dtype=np.float64, input_name="y",
                        ensure_all_finite=False)
    _refuse_gaps(y, "y")
    return y


def _refuse_rows_as_signals(shape, argument):
    """Refuse a training record of ``shape`` with fewer samples than
    signals: it is nearly always a record transposed, whose columns would be
    fitted as hundreds of inputs or outputs (and the memory run out)."""
    if len(shape) == 2 and 0 < shape[0] < shape[1]:
        raise ValueError(
            f"{argument} has {shape[0]} sample(s) (rows) and {shape[1]} columns: rows are "
            "time samples, columns are signals. A record stored as a row (as multisine "
            "returns its realizations, or as MATLAB holds signals) is passed transposed: "
            "one signal u as u.reshape(-1, 1), the realizations of one input as "
            "u.reshape(-1, 1) with sequence_id=np.repeat(np.arange(n_realizations), "
            "n_samples).")


def _refuse_gaps(values, argument):
    """Refuse non-finite values: a record has no gaps."""
    missing = ~np.isfinite(values.reshape(len(values), -1)).all(axis=1)
    if missing.any():
        rows = np.flatnonzero(missing)
        raise ValueError(
            f"{argument} contains NaN or infinity in {rows.size} row(s), the first at row "
            f"{rows[0]}. A record has no gaps: interpolate the missing samples, or split "
            "the record at the gap into sequences (sequence_id).")


def _input_delays(input_delay, n_inputs, starts):
    """``input_delay`` as one non-negative integer per input column, checked
    against the sequences of the training data."""
    delay = np.asarray(input_delay)
    if delay.ndim == 0:
        delay = np.full(n_inputs, delay)
    if (delay.shape != (n_inputs,) or not np.issubdtype(delay.dtype, np.number)
            or np.any(delay < 0) or np.any(delay != np.round(delay))):
        raise ValueError(
            "input_delay must be a non-negative integer, or one per input column "
            f"({n_inputs}); got {input_delay!r}.")
    delay = delay.astype(np.int64)
    check_delay_fits(delay, starts)
    return delay


def check_delay_fits(delay, starts):
    """Refuse sequences whose every sample would see an unmeasured input."""
    shortest = int(np.min(np.diff(starts)))
    if np.max(delay, initial=0) >= shortest:
        raise ValueError(
            f"input_delay={delay.tolist()} is not shorter than a sequence of {shortest} "
            "sample(s): its output would depend on no measured input.")


def _offset_and_scale(values, argument, what):
    """Mean and standard deviation of every column of ``values``.

    The statistics are computed on the values divided by their
    :func:`binary_magnitude`, so that the squares of values beyond 1e154 cannot
    overflow. A constant column is a ValueError naming ``argument`` (``what``
    names its columns). Each column is summed as one contiguous run, whatever
    the memory layout of ``values``: a C-ordered array of several columns
    would otherwise be summed row by row, and its statistics would differ in
    the last bit from those of the same values in Fortran order (a DataFrame's
    array), which some fits amplify.
    """
    magnitude = binary_magnitude(values)
    scaled = np.asfortranarray(values / magnitude)
    scale = scaled.std(axis=0)
    constant = np.flatnonzero(~(scale > _CONSTANT * np.abs(scaled).max(axis=0)))
    if constant.size:
        raise ValueError(
            f"{argument} is constant in {what} {constant.tolist()}: a constant signal "
            "carries no information about the dynamics."
        )
    return scaled.mean(axis=0) * magnitude, scale * magnitude


def _normalised(values, offset, scale):
    """``(values - offset) / scale``, evaluated on halves (halving is exact) so
    that the difference cannot overflow. Values far beyond the training range
    may still give infinity; the simulation reports them as a divergence."""
    with np.errstate(over="ignore"):
        return np.ascontiguousarray((values / 2 - offset / 2) / (scale / 2))


#: Fitted attributes without the trailing underscore of the public ones.
_PRIVATE_FITTED = ("_y_was_1d", "_model")


def _clear_fitted(estimator):
    """Remove the fitted attributes of ``estimator``."""
    for name in [name for name in vars(estimator)
                 if (name.endswith("_") and not name.startswith("__"))
                 or name in _PRIVATE_FITTED]:
        delattr(estimator, name)


def _unfitted_on_error(fit):
    """Decorate ``fit`` so that it starts from an unfitted estimator (no
    attribute of an earlier fit survives one that does not set it again), and
    so that a fit that does not complete, whatever stops it (an error,
    ``KeyboardInterrupt``), leaves the estimator unfitted rather than with some
    of its fitted attributes set."""

    @functools.wraps(fit)
    def guarded_fit(self, *args, **kwargs):
        _clear_fitted(self)
        try:
            return fit(self, *args, **kwargs)
        except BaseException:
            _clear_fitted(self)
            raise

    return guarded_fit


class _BaseStateSpace(RegressorMixin, BaseEstimator, metaclass=ABCMeta):
    """Base class of the sknlss state-space estimators.

    Subclasses implement ``_fit_normalized``, which sets at least ``A_``,
    ``B_``, ``C_``, ``D_``, ``x0_`` and ``n_params_``, and ``_fitted_model``.
    """

    _parameter_constraints: dict = {
        "input_delay": [Integers(0, None, closed="left"), "array-like"],
        "n_transient": [Integers(0, None, closed="left")],
    }

    def set_params(self, **params):
        """Set the parameters of this estimator (see scikit-learn's ``set_params``).

        A nested parameter (``bla__n_transient``, ``pnlss__degree``,
        ``basis__degree``) needs its parent to be an object: left at None, the
        parent stands for the defaults and has no parameters to set.

        Parameters
        ----------
        **params : dict
            Estimator parameters.

        Returns
        -------
        self : estimator instance
        """
        for key in params:
            parent, nested, _ = key.partition("__")
            if nested and params.get(parent, getattr(self, parent, "")) is None:
                raise ValueError(
                    f"{type(self).__name__}: {key} sets a parameter of {parent}, which is "
                    f"None (its defaults). Pass an instance as {parent} (the parameter's "
                    "docstring says which kind) to set or search its parameters.")
        return super().set_params(**params)

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        tags.target_tags.multi_output = True
        # Dynamical models identified on i.i.d. tabular data need not beat R2=0.5.
        tags.regressor_tags.poor_score = True
        return tags

    # ------------------------------------------------------------------ fit
    def _validate_training_data(self, X, y, sequence_id):
        """Validate and normalise the training data.

        Returns the normalised inputs ``U`` (n_samples, n_inputs), outputs
        ``Y`` (n_samples, n_outputs) and the sequence boundaries.
        """
        # X and y are checked one after the other, so that an error names the
        # argument at fault.
        X = _record_input(self, X, reset=True, ensure_min_samples=2)
        if y is None:
            raise ValueError(
                f"This {type(self).__name__} estimator requires y to be passed, but the "
                "target y is None."
            )
        y = _record_output(y)
        _refuse_rows_as_signals(y.shape, "y")
        with naming("y"):
            check_consistent_length(X, y)
        self._y_was_1d = y.ndim == 1
        Y = y.reshape(len(y), -1) if y.ndim == 1 else y
        starts = sequence_bounds(sequence_id, X.shape[0])
        self.input_delay_ = _input_delays(self.input_delay, X.shape[1], starts)
        self.n_outputs_ = Y.shape[1]
        self.u_offset_, self.u_scale_ = _offset_and_scale(X, "X", "input column(s)")
        self.y_offset_, self.y_scale_ = _offset_and_scale(Y, "y", "output(s)")
        self._choose_offsets()
        U = _normalised(X, self.u_offset_, self.u_scale_)
        Yn = _normalised(Y, self.y_offset_, self.y_scale_)
        return U, Yn, starts

    def _choose_offsets(self):
        """Set ``u_offset_`` and ``y_offset_``, the points the signals are
        normalised about: the means they hold when called, unless a subclass
        expands its model around another point."""

    @_unfitted_on_error
    def fit(self, X, y, *, sequence_id=None):
        """Fit the model to input/output records.

        Parameters
        ----------
        X : array-like of shape (n_samples, n_inputs)
            Input signal u; rows are time samples.
        y : array-like of shape (n_samples,) or (n_samples, n_outputs)
            Measured output signal.
        sequence_id : array-like of shape (n_samples,), default=None
            Label (an integer or a string) of the experiment (record,
            realization) each row belongs to; each label occupies one
            contiguous block of rows. ``None`` means that all rows form one
            sequence.

        Returns
        -------
        self : object
            The fitted estimator.
        """
        return self._fit(X, y, sequence_id)

    def _fit(self, X, y, sequence_id):
        """The work of ``fit``, for subclasses whose ``fit`` sets attributes first."""
        self._validate_params()
        U, Y, starts = self._validate_training_data(X, y, sequence_id)
        # Delayed once the offsets are final (a subclass may leave the signals
        # uncentred), as predict delays them.
        self._fit_normalized(self._delayed(U, starts), Y, starts)
        return self

    @abstractmethod
    def _fit_normalized(self, U, Y, starts):
        """Fit on normalised signals split into sequences by ``starts``."""

    @abstractmethod
    def _fitted_model(self):
        """The fitted model: a :class:`~sknlss._core._model.StateSpaceModel`
        and its parameter vector."""

    def _model_input(self, X, starts):
        """The input the model sees: ``X`` normalised, then delayed (sequences
        not longer than the delay refused)."""
        check_delay_fits(self.input_delay_, starts)
        return self._delayed(_normalised(X, self.u_offset_, self.u_scale_), starts)

    def _delayed(self, U, starts):
        """Normalised inputs ``U`` delayed by ``input_delay_``, a sequence that
        repeats with the estimator's ``period`` continued periodically before
        its start."""
        return delayed_input(U, starts, self.input_delay_, getattr(self, "period", None))

    def _scored_rows(self, starts, X):
        """The rows ``score`` compares for the input ``X``: all but the first
        ``n_transient`` of every sequence."""
        return transient_mask(starts, self.n_transient)

    def _simulate_normalized(self, U, starts, x0, steady_state=False):
        """Simulate from initial states ``x0`` of shape (n_sequences, n_states).

        ``steady_state`` lets a model fitted on periodic data start each
        sequence whose input repeats with the period in its periodic steady
        state instead (the initial states then only start the prepended
        samples).

        Returns the normalised outputs (n_samples, n_outputs), the states
        (n_samples, n_states) and a flag telling whether a trajectory diverged.
        """
        model, theta = self._fitted_model()
        return model.simulate(theta, U, starts, x0)

    def _set_search_result(self, result):
        """Store the history of the Levenberg-Marquardt search that was kept."""
        self.n_iter_ = result.n_iter
        self.loss_history_ = result.loss_history
        self.validation_loss_history_ = result.validation_history
        self.best_iteration_ = result.best_iter

    # ----------------------------------------------------------- simulation
    def _initial_states(self, x0, n_sequences):
        n_states = self.A_.shape[0]
        if x0 is None:
            # The states of several fitted sequences belong to those records;
            # another record (as cross-validation scores) starts from their
            # mean, the state a record of these experiments starts from on
            # average.
            x0 = self.x0_ if self.x0_.ndim == 1 else self.x0_.mean(axis=0)
        if np.iscomplexobj(x0):
            # NumPy would drop the imaginary part with a warning only.
            raise ValueError("x0: Complex data not supported; the states are real.")
        with naming("x0"):
            x0 = np.asarray(x0, dtype=np.float64)
        if x0.shape not in ((n_states,), (n_sequences, n_states)):
            raise ValueError(
                f"x0 must be of shape ({n_states},) or ({n_sequences}, {n_states}) for "
                f"{n_sequences} sequence(s); got shape {x0.shape}."
            )
        if not np.all(np.isfinite(x0)):
            raise ValueError("x0 must be finite; it holds NaN or infinity.")
        return np.ascontiguousarray(np.broadcast_to(x0, (n_sequences, n_states)))

    def simulate(self, X, *, sequence_id=None, x0=None, return_states=False):
        """Simulate the fitted model in free run.

        Parameters
        ----------
        X : array-like of shape (n_samples, n_inputs)
            Input signal.
        sequence_id : array-like of shape (n_samples,), default=None
            Sequence labels; each sequence starts from its own initial state.
        x0 : array-like of shape (n_states,) or (n_sequences, n_states), default=None
            Initial state in the model's (normalised) state coordinates; with
            one row per sequence, row ``k`` starts the ``k``-th sequence in the
            order of the rows of ``X`` (not in the sorted order of the labels).
            ``None`` uses the fitted ``x0_`` (zero unless it was estimated;
            the mean of its rows when it holds one state per fitted sequence:
            pass ``x0=model.x0_`` to simulate those sequences from their own);
            a nonlinear model fitted with ``period`` and ``n_transient`` then
            starts every sequence whose input repeats with the period in its
            periodic steady state (a sequence of a single period counts as
            repeating: nothing in it says otherwise; pass ``x0`` to start it
            from a state).
        return_states : bool, default=False
            Also return the simulated states.

        Returns
        -------
        y : ndarray of shape (n_samples,) or (n_samples, n_outputs)
            Simulated output in the units of the training output.
        states : ndarray of shape (n_samples, n_states)
            State x(t) at each sample, returned when ``return_states`` is True.
        """
        check_is_fitted(self)
        X = _record_input(self, X, reset=False)
        starts = sequence_bounds(sequence_id, X.shape[0])
        # A state the user passes starts the simulation, periodic data or not.
        steady_state = x0 is None
        x0 = self._initial_states(x0, len(starts) - 1)
        U = self._model_input(X, starts)
        Yn, states, diverged = self._simulate_normalized(U, starts, x0, steady_state)
        with np.errstate(over="ignore", invalid="ignore"):
            Y = self.y_offset_ + self.y_scale_ * Yn
        # Outputs beyond the floating-point range in the user's units (from
        # outputs near 1e302 and above) are a divergence too.
        overflow = np.isinf(Y)
        Y[overflow] = np.nan
        if diverged or overflow.any():
            warn_at_caller(
                "The simulation left the bounded region (a state or output beyond "
                f"{DIVERGENCE_BOUND:g} in normalised units, or an output beyond the "
                "floating-point range): the model is unstable for this input; the "
                "outputs from the divergence on are NaN.",
                SimulationDivergedWarning)
        if self._y_was_1d:
            Y = Y[:, 0]
        return (Y, states) if return_states else Y

    def predict(self, X, *, sequence_id=None, x0=None):
        """Free-run simulation of the output (not one-step-ahead prediction).

        Parameters
        ----------
        X : array-like of shape (n_samples, n_inputs)
            Input signal.
        sequence_id : array-like of shape (n_samples,), default=None
            Sequence labels; ``None`` simulates all rows as one sequence.
        x0 : array-like of shape (n_states,) or (n_sequences, n_states), default=None
            Initial state; ``None`` uses the fitted ``x0_`` (see
            :meth:`simulate`).

        Returns
        -------
        y : ndarray of shape (n_samples,) or (n_samples, n_outputs)
            Simulated output.
        """
        return self.simulate(X, sequence_id=sequence_id, x0=x0)

    @validate_params({"max_iter": [Integers(0, None, closed="left")]},
                     prefer_skip_nested_validation=True)
    def estimate_initial_state(self, X, y, *, sequence_id=None, x0=None, max_iter=100):
        """The initial state from which the simulation fits a measured record best.

        A record that starts mid-motion starts from an unknown state. This
        minimises the simulation error of ``(X, y)``, each sequence simulated
        from its first sample, over its initial state alone (the model's
        parameters fixed) by Levenberg-Marquardt. Pass the first samples of a
        record (e.g. the ``init_window`` of a benchmark's test record) and
        simulate the whole record from the result with ``predict(X, x0=...)``.

        Parameters
        ----------
        X : array-like of shape (n_samples, n_inputs)
            Input signal.
        y : array-like of shape (n_samples,) or (n_samples, n_outputs)
            Measured output.
        sequence_id : array-like of shape (n_samples,), default=None
            Sequence labels of several records (experiments): each gets its own
            state, as the System Identification Toolbox's ``findstates`` gives
            one per experiment.
        x0 : array-like of shape (n_states,) or (n_sequences, n_states), default=None
            Where the search starts; ``None`` uses the fitted ``x0_`` (as
            ``simulate`` does).
        max_iter : int, default=100
            Maximum number of Levenberg-Marquardt iterations.

        Returns
        -------
        x0 : ndarray of shape (n_states,) or (n_sequences, n_states)
            Initial state in the model's (normalised) state coordinates, as
            ``predict`` and ``simulate`` take it; with ``sequence_id``, one row
            per sequence in the order of the rows of ``X``.

        Examples
        --------
        >>> from sknlss import BLAEstimator
        >>> from sknlss.datasets import make_duffing
        >>> data = make_duffing(random_state=0)
        >>> model = BLAEstimator(n_states=2).fit(data.X_est, data.y_est)
        >>> w = data.init_window
        >>> x0 = model.estimate_initial_state(data.X_test[:w], data.y_test[:w])
        >>> y_sim = model.predict(data.X_test, x0=x0)
        """
        check_is_fitted(self)
        X = _record_input(self, X, reset=False)
        y = _record_output(y)
        Y = y.reshape(len(y), -1)
        if Y.shape != (X.shape[0], self.C_.shape[0]):
            raise ValueError(
                f"y must have {X.shape[0]} rows (as X) and {self.C_.shape[0]} output(s); "
                f"got shape {y.shape}."
            )
        starts = sequence_bounds(sequence_id, X.shape[0])
        initial = self._initial_states(x0, len(starts) - 1)
        U = self._model_input(X, starts)
        Y = _normalised(Y, self.y_offset_, self.y_scale_)
        model, theta = self._fitted_model()
        states = []
        for k, (begin, end) in enumerate(zip(starts[:-1], starts[1:])):
            if (end - begin) * Y.shape[1] < initial.shape[1]:
                which = "" if sequence_id is None else f" (sequence {k} in the order of the rows)"
                warn_at_caller(
                    f"estimate_initial_state: {(end - begin) * Y.shape[1]} output value(s)"
                    f"{which} cannot determine the {initial.shape[1]} states; the state "
                    "returned is one of many that fit them. Pass more samples.", UserWarning)
            states.append(fit_initial_state(model, theta, U[begin:end], Y[begin:end],
                                            initial[k], max_iter=max_iter))
        return states[0] if sequence_id is None else np.array(states)

    def score(self, X, y, sample_weight=None, *, sequence_id=None):
        """R² of the simulated output, skipping ``n_transient`` samples per
        sequence (none of a sequence simulated in periodic steady state).

        Parameters
        ----------
        X : array-like of shape (n_samples, n_inputs)
            Input signal.
        y : array-like of shape (n_samples,) or (n_samples, n_outputs)
            Measured output.
        sample_weight : array-like of shape (n_samples,), default=None
            Weight of each sample in the R² (the simulation runs over all
            samples whatever their weight).
        sequence_id : array-like of shape (n_samples,), default=None
            Sequence labels.

        Returns
        -------
        score : float
            Coefficient of determination averaged uniformly over the outputs.
        """
        y_pred = self.predict(X, sequence_id=sequence_id)
        X = _record_input(self, X, reset=False)
        y = _record_output(y)
        if y.shape[0] != y_pred.shape[0]:
            raise ValueError(
                f"X and y have different numbers of samples: {y_pred.shape[0]} and "
                f"{y.shape[0]}."
            )
        y, y_pred = y.reshape(len(y), -1), y_pred.reshape(len(y_pred), -1)
        if y.shape[1] != y_pred.shape[1]:
            raise ValueError(
                f"y has {y.shape[1]} output(s), the model was fitted on {y_pred.shape[1]}."
            )
        starts = sequence_bounds(sequence_id, len(y_pred))
        keep = self._scored_rows(starts, self._model_input(X, starts))
        if keep.sum() < 2:
            # R² compares the samples with their mean: one is not enough.
            raise ValueError(
                f"n_transient={self.n_transient} leaves {keep.sum()} sample(s) to score; "
                "R² needs two or more."
            )
        if sample_weight is not None:
            with naming("sample_weight"):
                sample_weight = _check_sample_weight(sample_weight, y)[keep]
        y_pred = y_pred[keep]
        if not np.all(np.isfinite(y_pred)):
            return -np.inf
        # R² does not change under a scaling of each output; in normalised
        # units its sums of squares cannot overflow.
        return r2_score(_normalised(y[keep], self.y_offset_, self.y_scale_),
                        _normalised(y_pred, self.y_offset_, self.y_scale_),
                        sample_weight=sample_weight)
