"""NL-LFR estimator and the bases of its static nonlinearity."""

import warnings

import numpy as np
import pytest
from sklearn.base import clone

from sknlss import (
    BLAEstimator,
    ChebyshevBasis,
    LegendreBasis,
    NLLFRRegressor,
    PolynomialBasis,
)
from sknlss._estimators import _nllfr
from sknlss.exceptions import SimulationDivergedWarning
from sknlss.metrics import rms_error

pytestmark = pytest.mark.filterwarnings("ignore::sklearn.exceptions.ConvergenceWarning")


def _duffing(u):
    x = np.zeros(2)
    y = np.empty(len(u))
    for t, ut in enumerate(u[:, 0]):
        y[t] = x[0]
        x = np.array([1.5 * x[0] - 0.7 * x[1] - 0.05 * x[0] ** 3 + ut, x[0]])
    return y


@pytest.fixture(scope="module")
def records():
    rng = np.random.default_rng(0)
    u, u_test = 0.5 * rng.standard_normal((600, 1)), 0.5 * rng.standard_normal((400, 1))
    return u, _duffing(u), u_test, _duffing(u_test)


def test_recovers_a_cubic_feedback(records):
    u, y, u_test, y_test = records
    # The signals are centred: the cubic expanded around their (small) mean
    # operating point needs the constant as well as its linear terms.
    model = NLLFRRegressor(n_states=2, basis=PolynomialBasis(3, constant=True),
                           max_iter=50).fit(u, y)
    linear = BLAEstimator(n_states=2).fit(u, y)
    assert rms_error(y_test, model.predict(u_test)) < 0.02 * rms_error(
        y_test, linear.predict(u_test))
    # 9 linear, Bw 2, Dw 1, Cz 2, Dz 1, 3 coefficients.
    assert model.n_params_ == 18
    assert model.Bw_.shape == (2, 1) and model.Dw_.shape == (1, 1)
    assert model.Cz_.shape == (1, 2) and model.Dz_.shape == (1, 1)
    assert model.coefficients_.shape == (1, 3)


def test_initialisation_improves_on_the_linear_model(records):
    # The least-squares initialisation along the BLA's trajectory, before any
    # iteration, already fits better than the linear model.
    u, y, u_test, y_test = records
    start = NLLFRRegressor(n_states=2, max_iter=0, n_init=1, validation_fraction=0.0)
    start.fit(u, y)
    linear = BLAEstimator(n_states=2).fit(u, y)
    assert rms_error(y, start.predict(u)) < 0.95 * rms_error(y, linear.predict(u))


@pytest.mark.parametrize("basis", [PolynomialBasis(3, kind="odd"), LegendreBasis(3),
                                   ChebyshevBasis(3)])
def test_bases(basis, records):
    # 0.999 to 0.9998 at random states 0-4 for every basis; the BLA's 0.883.
    u, y, _, _ = records
    models = [NLLFRRegressor(n_states=2, n_branches=2, basis=basis, max_iter=10,
                             random_state=seed).fit(u, y) for seed in range(3)]
    assert models[0].coefficients_.shape == (2, basis.n_functions)
    assert np.median([model.score(u, y) for model in models]) > 0.99
    assert clone(models[0]).basis == basis


def test_extrapolation_changes_only_predictions_beyond_the_estimation_range(records):
    u, y, u_test, _ = records
    options = dict(n_states=2, max_iter=10, random_state=0)
    linear = NLLFRRegressor(extrapolation="linear", **options).fit(u, y)
    continued = NLLFRRegressor(extrapolation="continue", **options).fit(u, y)
    np.testing.assert_array_equal(linear.predict(u), continued.predict(u))
    # The range is where the branch inputs went, whatever the continuation.
    np.testing.assert_array_equal(continued.branch_input_range_, linear.branch_input_range_)
    # The range of the branch input z = Cz x + Dz u on the estimation record
    # (normalised signals).
    states = linear.simulate(u, return_states=True)[1]
    z = states @ linear.Cz_.T + (u - linear.u_offset_) / linear.u_scale_ @ linear.Dz_.T
    np.testing.assert_allclose(linear.branch_input_range_, [[z.min()], [z.max()]])
    # A shifting basis's branches take z + bz_ as argument, anchored at bz_.
    shifted = NLLFRRegressor(basis=LegendreBasis(2, shift=True), **options).fit(u, y)
    states = shifted.simulate(u, return_states=True)[1]
    z = (states @ shifted.Cz_.T + (u - shifted.u_offset_) / shifted.u_scale_ @ shifted.Dz_.T
         + shifted.bz_)
    np.testing.assert_allclose(shifted.branch_input_range_,
                               [np.minimum(z.min(axis=0), shifted.bz_),
                                np.maximum(z.max(axis=0), shifted.bz_)])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SimulationDivergedWarning)
        beyond = continued.predict(4.0 * u_test)
    assert np.all(np.isfinite(linear.predict(4.0 * u_test)))
    assert not np.allclose(linear.predict(4.0 * u_test), beyond, equal_nan=True)


def _simulated_from_the_attributes(model, u):
    """The output of a fitted NL-LFR model, written out from its attributes
    (normalised units inside, from the zero state)."""
    u = (u - model.u_offset_) / model.u_scale_
    x = np.zeros(model.n_states)
    y = np.empty(len(u))
    basis = model.basis_
    for t, ut in enumerate(u):
        z = model.Cz_ @ x + model.Dz_ @ ut + model.bz_
        # A shifting basis anchors each branch at zero.
        anchor = basis.evaluate(model.bz_)[0] if basis.shifted else 0.0
        w = np.sum((basis.evaluate(z)[0] - anchor) * model.coefficients_, axis=1)
        y[t] = (model.C_ @ x + model.D_ @ ut + model.Dw_ @ w)[0]
        x = model.A_ @ x + model.B_ @ ut + model.Bw_ @ w
    return model.y_offset_ + model.y_scale_ * y


def test_a_small_network_in_feedback(records):
    # Two tanh units with biases: w_l = tanh(z_l + b_l) - tanh(b_l). Test errors at
    # random states 0-2 measured 0.034 to 0.064, the BLA's 0.34.
    u, y, u_test, y_test = records
    models = [NLLFRRegressor(n_states=2, n_branches=2, basis=LegendreBasis(1, shift=True),
                             max_iter=20, random_state=seed).fit(u, y) for seed in range(3)]
    linear = BLAEstimator(n_states=2).fit(u, y)
    assert np.median([rms_error(y_test, model.predict(u_test)) for model in models]) < (
        0.35 * rms_error(y_test, linear.predict(u_test)))
    model = models[0]
    # 9 linear, Bw 4, Dw 2, Cz 4, Dz 2, 2 biases and 2 coefficients.
    assert model.n_params_ == 25 and model.bz_.shape == (2,)
    # Each branch has its bias and is zero at the zero state and input (on the
    # estimation record the branch inputs stay inside their range).
    np.testing.assert_allclose(model.predict(u), _simulated_from_the_attributes(model, u),
                               rtol=1e-9, atol=1e-12)


def test_without_shift_the_branch_inputs_have_no_bias(records):
    u, y, _, _ = records
    model = NLLFRRegressor(n_states=2, basis=LegendreBasis(1), max_iter=5, n_init=1).fit(u, y)
    assert model.n_params_ == 16 and np.all(model.bz_ == 0)
    np.testing.assert_allclose(model.predict(u), _simulated_from_the_attributes(model, u),
                               rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("basis, continuation", [(PolynomialBasis(3), "continue"),
                                                 (LegendreBasis(3), "linear")])
def test_auto_extrapolation_follows_the_basis(basis, continuation, records):
    # The default: a power series keeps its curvature beyond the estimation
    # range, a bounded basis goes on along its tangent.
    u, y, u_test, _ = records
    options = dict(n_states=2, basis=basis, max_iter=10, random_state=0)
    auto = NLLFRRegressor(**options).fit(u, y)
    explicit = NLLFRRegressor(extrapolation=continuation, **options).fit(u, y)
    assert auto.extrapolation_ == explicit.extrapolation_ == continuation
    np.testing.assert_array_equal(auto.branch_input_range_, explicit.branch_input_range_)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SimulationDivergedWarning)
        np.testing.assert_array_equal(auto.predict(4.0 * u_test),
                                      explicit.predict(4.0 * u_test))


def test_bounded_bases_stay_bounded():
    z = np.array([-1e6, -3.0, 0.0, 3.0, 1e6])
    for basis in (LegendreBasis(5), ChebyshevBasis(5)):
        values, slopes = basis.evaluate(z)
        assert np.all(np.abs(values) <= 1.0 + 1e-12)
        assert np.all(np.isfinite(slopes))


def test_a_grid_search_sets_the_basis_parameters(records):
    from sklearn.model_selection import GridSearchCV, TimeSeriesSplit

    u, y, _, _ = records
    search = GridSearchCV(NLLFRRegressor(n_states=2, basis=LegendreBasis(2), max_iter=2,
                                         n_init=1),
                          {"basis__degree": [2, 3]}, cv=TimeSeriesSplit(2))
    search.fit(u, y)
    assert search.best_estimator_.basis.degree in (2, 3)
    assert search.estimator.basis.degree == 2
    with pytest.raises(ValueError, match="LegendreBasis has no parameter 'kind'"):
        LegendreBasis().set_params(kind="odd")


@pytest.mark.parametrize("basis, message", [
    (PolynomialBasis(1), "degree must be an int >= 2"),
    (PolynomialBasis(2, kind="odd"), "needs degree >= 3"),
    (PolynomialBasis(3, kind="cubic"), "kind must be"),
    (LegendreBasis(0), "degree must be an int >= 1"),
    (LegendreBasis(2, constant=True, shift=True), "constant=True with shift=True"),
    (ChebyshevBasis(2, shift=1), "shift must be a bool"),
])
def test_bad_basis(basis, message, records):
    u, y, _, _ = records
    with pytest.raises(ValueError, match=message) as caught:
        NLLFRRegressor(n_states=2, basis=basis).fit(u, y)
    # The estimator's argument is named, the basis shown as the user wrote it.
    assert str(caught.value).startswith(f"basis={basis!r} cannot be used: ")


class _OwnFunctions:
    """A basis object of a kind the compiled kernels do not know."""

    def evaluate(self, z):
        z = np.asarray(z)[:, None]
        return np.exp(-z**2), -2 * z * np.exp(-z**2)


class _RedefinedLegendre(LegendreBasis):
    def evaluate(self, z):
        values, slopes = super().evaluate(z)
        return 2 * values, 2 * slopes


class _LegendreOfDegree5(LegendreBasis):
    def __init__(self, degree=5, *, constant=False):
        super().__init__(degree, constant=constant)


def _legendre_with_its_evaluate_replaced():
    basis = LegendreBasis(3)
    basis.evaluate = _OwnFunctions().evaluate
    return basis


class _UnknownFamily(LegendreBasis):
    code = 7


@pytest.mark.parametrize("basis, message", [
    (_OwnFunctions(), "must be a PolynomialBasis, LegendreBasis or ChebyshevBasis or None"),
    (_UnknownFamily(3), "names no family the compiled kernels know"),
    (_RedefinedLegendre(3), "redefines evaluate"),
    (_legendre_with_its_evaluate_replaced(), "redefines evaluate"),
])
def test_a_basis_the_kernels_do_not_apply_is_refused(basis, message, records):
    u, y, _, _ = records
    with pytest.raises(TypeError, match=message):
        NLLFRRegressor(n_states=2, basis=basis, n_init=1, max_iter=2).fit(u, y)


def test_a_family_subclassed_for_its_parameters_is_fitted(records):
    u, y, _, _ = records
    model = NLLFRRegressor(n_states=2, basis=_LegendreOfDegree5(), n_init=1, max_iter=2)
    assert model.fit(u, y).coefficients_.shape == (1, 5)


def test_default_bases_take_the_starts_in_turn(records):
    # Each default basis gets the first starts (seeds and held-out shares) it
    # would get alone, and the fit keeps the best of all of them. One share
    # for all starts: the linear start is fitted before the largest held-out
    # end, which otherwise depends on the number of starts.
    u, y, _, _ = records
    options = dict(n_states=2, max_iter=5, random_state=0, validation_fraction=0.3)
    both = NLLFRRegressor(n_init=5, **options).fit(u, y)
    powers = NLLFRRegressor(basis=PolynomialBasis(3), n_init=3, **options).fit(u, y)
    legendre = NLLFRRegressor(basis=LegendreBasis(3), n_init=2, **options).fit(u, y)
    np.testing.assert_allclose(both.start_losses_[0::2], powers.start_losses_, rtol=1e-12)
    np.testing.assert_allclose(both.start_losses_[1::2], legendre.start_losses_, rtol=1e-12)
    best = int(np.argmin(both.start_losses_))
    kept = (powers, legendre)[best % 2]
    assert both.basis_ == kept.basis_
    assert both.n_params_ == kept.n_params_
    assert both.coefficients_.shape == (1, both.basis_.n_functions)
    np.testing.assert_allclose(both.predict(u), kept.predict(u), rtol=1e-10, atol=1e-12)


def test_a_single_start_uses_the_powers(records):
    u, y, _, _ = records
    model = NLLFRRegressor(n_states=2, n_init=1, max_iter=3).fit(u, y)
    assert model.basis_ == PolynomialBasis(3)
    assert len(model.start_losses_) == 1


def test_random_starts_keep_the_best_of_their_screened_directions(records, monkeypatch):
    # Before any iteration, a random start's error is at most that of its
    # first draw alone (the screen keeps the best least-squares start of its
    # draws); the start along the outputs is not screened.
    u, y, _, _ = records
    options = dict(n_states=2, basis=LegendreBasis(3), max_iter=0, n_init=3,
                   validation_fraction=0.0)

    def start_losses():
        return [NLLFRRegressor(random_state=random_state, **options).fit(u, y).start_losses_
                for random_state in range(3)]

    screened = start_losses()
    monkeypatch.setattr(_nllfr, "_SCREENED_DIRECTIONS", 1)
    single = start_losses()
    for kept, first in zip(screened, single):
        assert kept[0] == first[0]
        assert np.all(kept[1:] <= first[1:])
    assert any(np.any(kept[1:] < first[1:]) for kept, first in zip(screened, single))


@pytest.mark.parametrize("basis", [PolynomialBasis(3), LegendreBasis(3)])
def test_inference_start_fits_better_than_the_trajectory_start(basis, records):
    # Before any iteration: the starts of inference and learning leave about
    # a tenth (powers, whose linear term is moved into A, B, C, D) to a
    # quarter (Legendre) of the trajectory starts' error on this record;
    # medians over three starts of random output directions.
    u, y, _, _ = records
    options = dict(n_states=2, basis=basis, max_iter=0, n_init=3, validation_fraction=0.0)
    for random_state in range(3):
        trajectory = NLLFRRegressor(random_state=random_state, **options).fit(u, y)
        inference = NLLFRRegressor(init="inference", random_state=random_state,
                                   **options).fit(u, y)
        assert np.median(inference.start_losses_) < 0.5 * np.median(
            trajectory.start_losses_)


def test_inference_start_with_several_inputs_outputs_and_branches():
    rng = np.random.default_rng(1)
    u = 0.5 * rng.standard_normal((800, 2))
    y = np.column_stack([_duffing(u[:, :1] + 0.5 * u[:, 1:]),
                         np.convolve(u[:, 1], [0.5, 0.3, 0.1])[:800]])
    linear = rms_error(y, BLAEstimator(n_states=3).fit(u, y).predict(u))
    errors = [rms_error(y, NLLFRRegressor(
        n_states=3, n_branches=2, basis=LegendreBasis(3), init="inference", max_iter=20,
        n_init=1, random_state=random_state).fit(u, y).predict(u))
        for random_state in range(3)]
    # The search works with several inputs, outputs and branches. Measured:
    # 0.08-0.11 of the linear model's error (0.05 from the trajectory start).
    assert np.median(errors) < 0.2 * linear
