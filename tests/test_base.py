import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from sklearn.metrics import r2_score

from sknlss import BLAEstimator, SimulationDivergedWarning
from sknlss._core._model import StateSpaceModel
from sknlss._core._sequences import (delayed_input, holdout_masks, periodic_sequences,
                                     sequence_bounds, transient_mask, undelayed_input)
from sknlss._estimators._base import _BaseStateSpace


# ------------------------------------------------------------ row helpers
def test_sequence_bounds():
    np.testing.assert_array_equal(sequence_bounds(None, 5), [0, 5])
    np.testing.assert_array_equal(sequence_bounds([3, 3, 1, 1, 1, 7], 6), [0, 2, 5, 6])
    np.testing.assert_array_equal(sequence_bounds(np.array([0.0, 0.0, 1.0]), 3), [0, 2, 3])
    # Experiment names label sequences as integers do.
    np.testing.assert_array_equal(sequence_bounds(["run_b", "run_b", "run_a"], 3), [0, 2, 3])
    names = np.array(["x", "y", "y"], dtype=object)
    np.testing.assert_array_equal(sequence_bounds(names, 3), [0, 1, 3])
    # A DataFrame column of object dtype holding integers.
    numbers = np.array([4, 4, 2], dtype=object)
    np.testing.assert_array_equal(sequence_bounds(numbers, 3), [0, 2, 3])
    beyond_64_bits = np.array([2**64, 2**64, 1], dtype=object)
    np.testing.assert_array_equal(sequence_bounds(beyond_64_bits, 3), [0, 2, 3])


@pytest.mark.parametrize(
    "sequence_id, match",
    [
        ([0, 0, 1], "one label per sample"),
        (np.zeros((4, 1)), "one label per sample"),
        ([0, 0, 1, 0], "contiguous"),
        ([0.0, 0.5, 1.0, 1.0], "integer labels.*not whole numbers"),
        ([None, None, 1, 1], "integer labels.*or strings.*neither numbers nor strings"),
        ([0.0, np.nan, 1.0, 1.0], "integer labels"),
    ],
)
def test_sequence_bounds_errors(sequence_id, match):
    with pytest.raises(ValueError, match=match):
        sequence_bounds(sequence_id, 4)


def test_transient_mask():
    starts = np.array([0, 3, 5, 10])
    np.testing.assert_array_equal(
        transient_mask(starts, [0, 1, 2]),
        [True, True, True, False, True, False, False, True, True, True])
    np.testing.assert_array_equal(
        transient_mask(starts, 2),
        [False, False, True, False, False, False, False, True, True, True],
    )
    assert transient_mask(starts, 0).all()


def test_holdout_masks():
    starts = np.array([0, 10, 20])
    fit, validation = holdout_masks(starts, 2, 0.3)
    expected_fit = np.zeros(20, dtype=bool)
    expected_fit[2:7] = expected_fit[12:17] = True
    expected_validation = np.zeros(20, dtype=bool)
    expected_validation[7:10] = expected_validation[17:20] = True
    np.testing.assert_array_equal(fit, expected_fit)
    np.testing.assert_array_equal(validation, expected_validation)
    fit, validation = holdout_masks(starts, 1, 0.0)
    assert not validation.any() and fit.sum() == 18
    with pytest.raises(ValueError, match="leave no sample"):
        holdout_masks(starts, 10, 0.0)


@settings(max_examples=30, deadline=None)
@given(offset=st.floats(-1e3, 1e3), scale=st.floats(1e-3, 1e3), seed=st.integers(0, 2**16))
def test_periodic_sequences_ignore_offsets_and_scales(offset, scale, seed):
    rng = np.random.default_rng(seed)
    period, starts = 8, np.array([0, 32, 64])
    U = rng.standard_normal((64, 2))
    U[32:] = np.tile(U[32:40], (4, 1))
    expected = periodic_sequences(U, starts, period)
    np.testing.assert_array_equal(expected, [False, True])
    moved = U * [1.0, scale] + [0.0, offset]
    np.testing.assert_array_equal(periodic_sequences(moved, starts, period), expected)


def test_periodic_records_exciting_one_input_at_a_time_repeat():
    # The other input of each realization is measured noise only.
    rng = np.random.default_rng(0)
    period, blocks = 64, []
    for excited in (0, 1):
        one = np.zeros((period, 2))
        one[:, excited] = rng.standard_normal(period)
        blocks.append(np.tile(one, (4, 1)) + 1e-3 * rng.standard_normal((4 * period, 2)))
    starts = np.array([0, 4 * period, 8 * period])
    assert periodic_sequences(np.vstack(blocks), starts, period).all()


@settings(max_examples=50, deadline=None)
@given(n_periods=st.lists(st.integers(2, 5), min_size=1, max_size=4),
       delays=st.lists(st.integers(0, 5), min_size=1, max_size=3),
       period=st.integers(3, 6), seed=st.integers(0, 2**16))
def test_delayed_input(n_periods, delays, period, seed):
    rng = np.random.default_rng(seed)
    starts = np.concatenate([[0], np.cumsum(n_periods) * period])
    # Every other sequence repeats one period; the others are random.
    U = rng.standard_normal((starts[-1], len(delays)))
    for k in range(0, len(n_periods), 2):
        U[starts[k]:starts[k + 1]] = np.tile(U[starts[k]:starts[k] + period], (n_periods[k], 1))
    repeating = periodic_sequences(U, starts, period)
    assert repeating[::2].all()
    for with_period in (period, None):
        delayed = delayed_input(U, starts, np.array(delays), with_period)
        for k, (begin, end) in enumerate(zip(starts[:-1], starts[1:])):
            for j, lag in enumerate(delays):
                for t in range(begin, end):
                    if t - lag >= begin:
                        expected = U[t - lag, j]
                    elif with_period and repeating[k]:
                        # The periodic continuation of the sequence before its start.
                        expected = U[begin + (t - lag - begin) % period, j]
                    else:
                        expected = 0.0
                    assert delayed[t, j] == expected
        # Undone, the delay gives the input back, but for the samples that
        # reach the model only after a sequence that does not repeat.
        undone = undelayed_input(delayed, starts, np.array(delays))
        for k, (begin, end) in enumerate(zip(starts[:-1], starts[1:])):
            for j, lag in enumerate(delays):
                kept = end if with_period and repeating[k] else end - lag
                np.testing.assert_array_equal(undone[begin:kept, j], U[begin:kept, j])
    assert delayed_input(U, starts, np.zeros(len(delays), int)) is U
    assert undelayed_input(U, starts, np.zeros(len(delays), int)) is U


# ------------------------------------------------------- the base contract
class _FirstOrder(_BaseStateSpace):
    """x(t+1) = pole x(t) + sum(u(t)); y_j(t) = x(t) + gain_j sum(u(t)), normalised units."""

    _parameter_constraints = {**_BaseStateSpace._parameter_constraints}

    def __init__(self, pole=0.5, *, feedthrough=0.25, input_delay=0, n_transient=0):
        self.pole = pole
        self.feedthrough = feedthrough
        self.input_delay = input_delay
        self.n_transient = n_transient

    def _fit_normalized(self, U, Y, starts):
        n_inputs, n_outputs = U.shape[1], Y.shape[1]
        self.A_ = np.array([[self.pole]])
        self.B_ = np.ones((1, n_inputs))
        self.C_ = np.ones((n_outputs, 1))
        self.D_ = self.feedthrough * np.arange(1, n_outputs + 1)[:, None] * np.ones(
            (1, n_inputs))
        self.x0_ = np.zeros(1)
        self.n_params_ = 0
        self.fit_starts_ = starts

    def _fitted_model(self):
        model = StateSpaceModel(1, self.B_.shape[1], self.C_.shape[0])
        return model, model.pack({"A": self.A_, "B": self.B_, "C": self.C_, "D": self.D_})


def _reference(model, U, x0=0.0):
    """Normalised output of _FirstOrder for one sequence, written out."""
    x, out = x0, []
    for u in U:
        out.append(x + model.feedthrough * np.arange(1, model.n_outputs_ + 1) * u.sum())
        x = model.pole * x + u.sum()
    return np.array(out)


@pytest.fixture
def data():
    rng = np.random.default_rng(0)
    X = 3.0 + 2.0 * rng.standard_normal((50, 2))
    y = 10.0 + 0.5 * rng.standard_normal(50)
    return X, y


@pytest.mark.parametrize(
    "X_shape, match",
    [((50,), r"X must be 2-D.*u\.reshape\(-1, 1\)"), ((50, 2, 1), "dim 3")],
)
def test_x_must_be_2d(data, X_shape, match):
    X, y = data
    with pytest.raises(ValueError, match=match):
        _FirstOrder().fit(np.ones(X_shape), y)


@pytest.mark.parametrize("X_shape, y_shape, argument", [
    ((8, 32), (8, 32), "X has 8 sample"), ((1, 50), (50,), "X has 1 sample"),
    ((50, 1), (1, 50), "y has 1 sample"),
])
def test_signals_stored_as_rows_are_refused(X_shape, y_shape, argument):
    # Realizations as rows (the layout of multisine, or of MATLAB signals)
    # would be fitted as dozens of inputs and outputs.
    with pytest.raises(ValueError, match=argument + r".*rows are time samples.*reshape"):
        _FirstOrder().fit(np.ones(X_shape), np.ones(y_shape))


def test_short_windows_of_several_outputs_are_not_training_records():
    # Two samples of three outputs: a window to set a state, or to score.
    rng = np.random.default_rng(0)
    u = rng.standard_normal((400, 1))
    y = np.column_stack([np.convolve(u[:, 0], [0.0, 1.0, 0.5])[:400] + k for k in range(3)])
    model = BLAEstimator(n_states=1).fit(u, y)
    assert np.all(np.isfinite(model.estimate_initial_state(u[:2], y[:2])))
    assert np.isfinite(model.score(u[:2], y[:2]))


@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_non_finite_rejected(data, bad):
    X, y = data
    X_bad = X.copy()
    X_bad[3, 1] = bad
    # The advice is that of records (no gaps), not scikit-learn's for
    # independent samples (drop them, or impute).
    gap = r"contains NaN or infinity in 1 row\(s\), the first at row 3.*sequence_id"
    with pytest.raises(ValueError, match="X " + gap):
        _FirstOrder().fit(X_bad, y)
    y_bad = y.copy()
    y_bad[3] = bad
    with pytest.raises(ValueError, match="y " + gap):
        _FirstOrder().fit(X, y_bad)
    model = _FirstOrder().fit(X, y)
    with pytest.raises(ValueError, match="X " + gap):
        model.predict(X_bad)
    with pytest.raises(ValueError, match="y " + gap):
        model.score(X, y_bad)
    y_bad = y.copy()
    y_bad[7] = bad
    with pytest.raises(ValueError, match="NaN|infinity"):
        _FirstOrder().fit(X, y_bad)
    model = _FirstOrder().fit(X, y)
    with pytest.raises(ValueError, match="NaN|infinity"):
        model.predict(X_bad)


def test_length_mismatch_and_sequence_id(data):
    X, y = data
    with pytest.raises(ValueError, match="inconsistent numbers of samples"):
        _FirstOrder().fit(X, y[:-1])
    with pytest.raises(ValueError, match="sequence_id"):
        _FirstOrder().fit(X, y, sequence_id=np.zeros(49))
    model = _FirstOrder().fit(X, y)
    with pytest.raises(ValueError, match="sequence_id"):
        model.predict(X, sequence_id=np.zeros(10))
    with pytest.raises(ValueError, match="different numbers of samples"):
        model.score(X, y[:-1])
    with pytest.raises(ValueError, match="features"):
        model.predict(X[:, :1])


def test_one_sample_rejected():
    with pytest.raises(ValueError, match="1 sample"):
        _FirstOrder().fit(np.ones((1, 1)), np.ones(1))


def test_sequences_passed_to_fit(data):
    X, y = data
    model = _FirstOrder().fit(X, y, sequence_id=np.repeat([4, 2], 25))
    np.testing.assert_array_equal(model.fit_starts_, [0, 25, 50])


def test_offsets_removed_and_restored(data):
    X, y = data
    model = _FirstOrder().fit(X, y)
    np.testing.assert_allclose(model.u_offset_, X.mean(axis=0))
    np.testing.assert_allclose(model.u_scale_, X.std(axis=0))
    assert model.y_offset_ == pytest.approx([y.mean()])
    assert model.y_scale_ == pytest.approx([y.std()])
    U = (X - X.mean(axis=0)) / X.std(axis=0)
    expected = y.mean() + y.std() * _reference(model, U)[:, 0]
    y_pred = model.predict(X)
    assert y_pred.shape == (50,)
    np.testing.assert_allclose(y_pred, expected, rtol=1e-12)


def test_constant_signals_refused():
    # A constant signal carries no information about the dynamics; its zero
    # variance used to reach the BLA's weights as a LinAlgError.
    X = np.column_stack([np.full(20, 3.0), np.arange(20.0)])
    with pytest.raises(ValueError, match=r"X is constant in input column\(s\) \[0\]"):
        _FirstOrder().fit(X, np.arange(20.0) ** 2)
    with pytest.raises(ValueError, match=r"y is constant in output\(s\) \[1\]"):
        _FirstOrder().fit(X[:, 1:], np.column_stack([np.arange(20.0), np.zeros(20)]))


def test_extreme_magnitudes_scaled_exactly():
    # The statistics are taken after an exact power-of-two scaling: huge and
    # tiny signals normalise like ordinary ones.
    rng = np.random.default_rng(0)
    X, y = rng.standard_normal((50, 1)), rng.standard_normal(50)
    reference = _FirstOrder().fit(X, y)
    for factor in (2.0**600, 2.0**-600, 2.0**1000):
        model = _FirstOrder().fit(X * factor, y * factor)
        assert model.u_scale_[0] == reference.u_scale_[0] * factor
        assert model.y_offset_[0] == reference.y_offset_[0] * factor
        np.testing.assert_array_equal(model.predict(X * factor), reference.predict(X) * factor)
        assert model.score(X * factor, y * factor) == pytest.approx(reference.score(X, y))


def test_multi_output(data):
    X, y = data
    Y = np.column_stack([y, -2.0 * y + 1.0, np.arange(50.0)])
    model = _FirstOrder().fit(X, Y)
    assert model.n_outputs_ == 3
    Y_pred, states = model.simulate(X, return_states=True)
    assert Y_pred.shape == (50, 3) and states.shape == (50, 1)
    U = (X - X.mean(axis=0)) / X.std(axis=0)
    np.testing.assert_allclose(Y_pred, Y.mean(axis=0) + Y.std(axis=0) * _reference(model, U))
    # A one-column 2-D target keeps its 2-D shape.
    assert _FirstOrder().fit(X, y[:, None]).predict(X).shape == (50, 1)


def test_sequences_restart_the_state(data):
    X, y = data
    model = _FirstOrder().fit(X, y)
    single = model.predict(X[:20])
    stacked = model.predict(np.vstack([X[:20], X[:20]]), sequence_id=np.repeat([0, 1], 20))
    np.testing.assert_allclose(stacked, np.concatenate([single, single]))
    # Without sequence_id the second half continues the state instead.
    continued = model.predict(np.vstack([X[:20], X[:20]]))
    assert not np.allclose(continued[20:], single)


def test_initial_state(data):
    X, y = data
    model = _FirstOrder().fit(X, y)
    U = (X - X.mean(axis=0)) / X.std(axis=0)
    from_x0 = model.predict(X, x0=[2.0])
    np.testing.assert_allclose(from_x0, y.mean() + y.std() * _reference(model, U, 2.0)[:, 0])
    both = model.predict(X, sequence_id=np.repeat([0, 1], 25), x0=[[2.0], [-1.0]])
    np.testing.assert_allclose(both[:25], from_x0[:25])
    np.testing.assert_allclose(
        both[25:], y.mean() + y.std() * _reference(model, U[25:], -1.0)[:, 0])
    for bad in ([1.0, 2.0], [[1.0], [2.0]], [[np.nan]], 1.0):
        with pytest.raises(ValueError, match="x0 must be"):
            model.predict(X, x0=bad)


def test_score_skips_transient(data):
    X, y = data
    model = _FirstOrder(n_transient=5).fit(X, y)
    y_pred = model.predict(X)
    y_true = y_pred + 0.1 * np.sin(np.arange(50))
    y_true[:5] += 100.0
    assert model.score(X, y_true) == pytest.approx(r2_score(y_true[5:], y_pred[5:]))
    sequence_id = np.repeat([0, 1], 25)
    y_seq = model.predict(X, sequence_id=sequence_id)
    keep = np.ones(50, dtype=bool)
    keep[:5] = keep[25:30] = False
    y_true = y_seq + 0.1 * np.cos(np.arange(50))
    y_true[~keep] -= 50.0
    assert model.score(X, y_true, sequence_id=sequence_id) == pytest.approx(
        r2_score(y_true[keep], y_seq[keep]))
    with pytest.raises(ValueError, match="leaves 0 sample"):
        _FirstOrder(n_transient=50).fit(X, y).score(X, y)
    # R² of one sample is undefined.
    with pytest.raises(ValueError, match="leaves 1 sample.*two or more"):
        _FirstOrder(n_transient=49).fit(X, y).score(X, y)


def test_score_weights_the_samples(data):
    X, y = data
    model = _FirstOrder(n_transient=5).fit(X, y)
    y_pred = model.predict(X)
    y_true = y_pred + 0.1 * np.sin(np.arange(50))
    weight = np.linspace(0.0, 2.0, 50)
    assert model.score(X, y_true, weight) == pytest.approx(
        r2_score(y_true[5:], y_pred[5:], sample_weight=weight[5:]))
    assert model.score(X, y_true, np.ones(50)) == pytest.approx(model.score(X, y_true))
    with pytest.raises(ValueError, match="sample_weight"):
        model.score(X, y_true, np.ones(49))


def test_input_delay_shifts_the_input_in_every_sequence(data):
    X, y = data
    model = _FirstOrder(input_delay=[2, 0]).fit(X, y)
    np.testing.assert_array_equal(model.input_delay_, [2, 0])
    U = (X - X.mean(axis=0)) / X.std(axis=0)
    ids = np.repeat([0, 1], 25)
    U_delayed = U.copy()
    for begin in (0, 25):
        U_delayed[begin + 2:begin + 25, 0] = U[begin:begin + 23, 0]
        # Before the start the input was not measured: its mean.
        U_delayed[begin:begin + 2, 0] = 0.0
    predicted = model.predict(X, sequence_id=ids)
    for begin in (0, 25):
        np.testing.assert_allclose(
            predicted[begin:begin + 25],
            y.mean() + y.std() * _reference(model, U_delayed[begin:begin + 25])[:, 0])
    # The delay is that of the fit: set_params on the fitted model changes nothing.
    np.testing.assert_array_equal(model.set_params(input_delay=0).predict(X, sequence_id=ids),
                                  predicted)


@pytest.mark.parametrize("input_delay, match", [
    (-1, "input_delay"), ([1, 2, 3], r"one per input column \(2\)"), (1.5, "input_delay"),
    ([1.5, 0], "non-negative integer"), (25, "not shorter than a sequence of 25"),
])
def test_input_delay_validated(data, input_delay, match):
    X, y = data
    with pytest.raises(ValueError, match=match):
        _FirstOrder(input_delay=input_delay).fit(X, y, sequence_id=np.repeat([0, 1], 25))


def test_input_delay_longer_than_a_predicted_record(data):
    X, y = data
    model = _FirstOrder(input_delay=3).fit(X, y)
    with pytest.raises(ValueError, match="not shorter than a sequence of 3"):
        model.predict(X[:3])
    with pytest.raises(ValueError, match="not shorter than a sequence of 2"):
        model.estimate_initial_state(X[:2], y[:2])


def test_n_transient_validated(data):
    X, y = data
    with pytest.raises(ValueError, match="n_transient"):
        _FirstOrder(n_transient=-1).fit(X, y)


def test_divergence_warns_and_gives_nan(data):
    X, y = data
    model = _FirstOrder(pole=3.0).fit(X, y)
    with pytest.warns(SimulationDivergedWarning):
        y_pred = model.predict(X)
    first_nan = np.flatnonzero(np.isnan(y_pred))[0]
    assert 5 < first_nan < 50
    assert np.all(np.isnan(y_pred[first_nan:]))
    assert np.all(np.isfinite(y_pred[:first_nan]))
    with pytest.warns(SimulationDivergedWarning):
        assert model.score(X, y) == -np.inf
    stable = _FirstOrder(pole=0.5).fit(X, y)
    with warnings.catch_warnings():
        warnings.simplefilter("error", SimulationDivergedWarning)
        stable.predict(X)
