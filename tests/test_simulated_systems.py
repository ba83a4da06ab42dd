"""The simulated systems: records, noise level, nonlinearity, validation."""

import inspect

import numpy as np
import pytest
from scipy import signal

from sknlss.datasets import (make_bouc_wen, make_closed_loop_drive, make_duffing,
                             make_wiener_hammerstein)

GENERATORS = [make_wiener_hammerstein, make_duffing, make_bouc_wen, make_closed_loop_drive]
OPEN_LOOP = [make_wiener_hammerstein, make_duffing, make_bouc_wen]
SMALL = {"n_samples": 1024, "n_test_samples": 512}

# The input argument that sets the estimation amplitude.
AMPLITUDE = {make_wiener_hammerstein: "input_rms", make_duffing: "input_rms",
             make_bouc_wen: "input_rms", make_closed_loop_drive: "reference_rms"}


def _ids(functions):
    return [function.__name__ for function in functions]


def _arx_simulation_error(u, y, order=6):
    """RMS error of the free-run simulation of a least-squares ARX(order, order) fit.

    The linear model a best-linear-approximation method would find from these
    data: on a linear system of order up to ``order`` it is exact.
    """
    # Unit scales keep the least-squares problem well conditioned.
    u_scale, y_scale = u.std(), y.std()
    u, y = u / u_scale, y / y_scale
    lagged = [y[order - i:len(y) - i] for i in range(1, order + 1)]
    lagged += [u[order - j:len(u) - j] for j in range(order + 1)]
    theta, *_ = np.linalg.lstsq(np.column_stack(lagged), y[order:], rcond=None)
    # Free run from the first `order` measured samples.
    a, b = np.r_[1.0, -theta[:order]], theta[order:]
    initial = signal.lfiltic(b, a, y[order - 1::-1], u[order - 1::-1])
    simulated = signal.lfilter(b, a, u[order:], zi=initial)[0]
    return y_scale * np.sqrt(np.mean((simulated - y[order:]) ** 2))


@pytest.mark.parametrize("make", GENERATORS, ids=_ids(GENERATORS))
def test_records_and_fields(make):
    data = make(**SMALL, random_state=0)
    assert data.X_est.shape == (1024, 1) and data.y_est.shape == (1024,)
    assert data.X_test.shape == (512, 1) and data.y_test.shape == (512,)
    for key in ("X_est", "y_est", "X_test", "y_test"):
        assert data[key].dtype == np.float64 and np.all(np.isfinite(data[key]))
    assert data.init_window == 50
    assert data.sampling_time > 0 and data.noise_std > 0
    low, high = data.excited_band
    assert 0 <= low < high <= 0.5 / data.sampling_time
    assert len(data.DESCR) > 500 and "noise" in data.DESCR


@pytest.mark.parametrize("make", GENERATORS, ids=_ids(GENERATORS))
def test_the_estimation_input_lies_in_the_excited_band(make):
    data = make(random_state=0)
    u = data.X_est[:, 0] - data.X_est[:, 0].mean()
    frequencies = np.fft.rfftfreq(u.size, data.sampling_time)
    power = np.abs(np.fft.rfft(u)) ** 2
    # The drive's band-limited noise has a short roll-off beyond its edge.
    above = frequencies > 1.05 * data.excited_band[1]
    assert power[above].sum() < 0.01 * power.sum()


@pytest.mark.parametrize("make", GENERATORS, ids=_ids(GENERATORS))
def test_deterministic_per_random_state(make):
    first, again, other = (make(**SMALL, random_state=seed) for seed in (4, 4, 5))
    for key in ("X_est", "y_est", "X_test", "y_test"):
        np.testing.assert_array_equal(first[key], again[key])
        assert not np.allclose(first[key], other[key])


@pytest.mark.parametrize("make", GENERATORS, ids=_ids(GENERATORS))
def test_noise_level_is_the_stated_one(make):
    noisy = make(random_state=1)
    clean = make(random_state=1, noise_std=0.0)
    np.testing.assert_array_equal(noisy.X_est, clean.X_est)
    np.testing.assert_array_equal(noisy.X_test, clean.X_test)
    # The drive's controller feeds the measurement noise back, so the position
    # itself moves with it a little.
    tolerance = 0.1 if make is make_closed_loop_drive else 0.05
    for record in ("est", "test"):
        noise = noisy[f"y_{record}"] - clean[f"y_{record}"]
        assert noise.std() == pytest.approx(noisy.noise_std, rel=tolerance)


@pytest.mark.parametrize("make", GENERATORS, ids=_ids(GENERATORS))
def test_a_linear_model_leaves_more_than_the_noise(make):
    clean = make(random_state=2, noise_std=0.0)
    error = _arx_simulation_error(clean.X_est[:, 0], clean.y_est)
    assert error > 5 * make(random_state=2).noise_std


@pytest.mark.parametrize("make", OPEN_LOOP, ids=_ids(OPEN_LOOP))
def test_nearly_linear_at_small_amplitude(make):
    # The nonlinearity is the system's, not the ARX structure's: with an input
    # a thousand times smaller the relative error of the linear fit collapses.
    name = AMPLITUDE[make]
    nominal = make(random_state=3, noise_std=0.0)
    small = make(random_state=3, noise_std=0.0,
                 **{name: inspect.signature(make).parameters[name].default / 1000})
    relative = [_arx_simulation_error(d.X_est[:, 0], d.y_est) / d.y_est.std()
                for d in (nominal, small)]
    assert relative[1] < relative[0] / 10


@pytest.mark.parametrize("make", OPEN_LOOP, ids=_ids(OPEN_LOOP))
def test_test_input_leaves_the_estimation_amplitude_at_its_end(make):
    # The ramp ends at 1.5 times the estimation level; the RMS of the last tenth
    # of one draw scatters about it (1.11 to 1.56 over random states 0-19; the
    # medians over 0-2 are 1.315, 1.351 and 1.342).
    ratios = []
    for seed in range(3):
        data = make(random_state=seed)
        n_end = data.X_test.shape[0] // 10
        ratios.append(data.X_test[-n_end:].std() / data.X_est.std())
    assert np.median(ratios) > 1.2


def test_drive_test_reference_leaves_the_estimation_range_at_its_end():
    for seed in range(3):
        data = make_closed_loop_drive(random_state=seed)
        reach = data.X_est.max() + 0.25 * np.ptp(data.X_est)
        assert data.X_test[-1, 0] >= reach - 1e-12
        assert data.y_test[-200:].max() > data.X_est.max()


@pytest.mark.parametrize("make", GENERATORS, ids=_ids(GENERATORS))
def test_test_record_starts_mid_motion(make):
    data = make(random_state=0)
    window = data.y_test[:data.init_window]
    assert np.ptp(window) > 20 * data.noise_std
    assert abs(data.y_est[0]) > 0 and abs(data.X_est[0, 0]) > 0


@pytest.mark.parametrize("make, scale", [(make_duffing, 0.1), (make_bouc_wen, 0.1),
                                         (make_closed_loop_drive, 0.1)],
                         ids=["duffing", "bouc_wen", "closed_loop_drive"])
def test_integration_is_accurate(make, scale):
    substeps = inspect.signature(make).parameters["n_substeps"].default
    default, fine = (make(**SMALL, random_state=0, noise_std=0.0, n_substeps=m)
                     for m in (substeps, 4 * substeps))
    difference = np.abs(default.y_est - fine.y_est).max()
    assert difference < scale * make(**SMALL).noise_std


def test_duffing_is_periodic_in_steady_state():
    # The estimation record is one period of the multisine in steady state: a
    # second period of the same input gives the same output.
    data = make_duffing(**SMALL, random_state=0, noise_std=0.0)
    from sknlss.datasets._oscillators import _duffing_parameters, _simulate_oscillator

    u = np.tile(data.X_est[:, 0], 3)
    y = _simulate_oscillator(u, _duffing_parameters(), data.sampling_time, 20)
    np.testing.assert_allclose(y[1024:2048], data.y_est, atol=1e-9)
    np.testing.assert_allclose(y[2048:], data.y_est, atol=1e-9)


def test_bouc_wen_matches_the_benchmark_scale():
    # The benchmark's 50 N RMS multisine gives displacements of about 0.7 mm RMS.
    data = make_bouc_wen(random_state=0)
    assert 5e-4 < data.y_est.std() < 9e-4
    assert data.sampling_time == 1 / 750 and data.excited_band == (5.0, 150.0)


def test_closed_loop_drive_tracks_its_reference():
    data = make_closed_loop_drive(random_state=0)
    assert data.u_plant_est.shape == (6000,) and data.u_plant_test.shape == (3000,)
    for X, y in ((data.X_est, data.y_est), (data.X_test, data.y_test)):
        # The reference reaches half the loop's bandwidth: the position
        # follows it, with a visible tracking error.
        error = X[:, 0] - y
        assert 0.1 * np.std(X) < np.std(error) < 0.7 * np.std(X)
        assert np.corrcoef(X[:, 0], y)[0, 1] > 0.8
    # A force a linear motor can deliver.
    assert 5.0 < np.abs(data.u_plant_est).max() < 200.0


def _bad_arguments():
    cases = []
    for make in GENERATORS:
        cases += [
            (make, {"n_samples": 10}, "'n_samples' parameter"),
            (make, {"n_test_samples": 2.5}, "'n_test_samples' parameter"),
            (make, {"noise_std": -1.0}, "'noise_std' parameter"),
            (make, {"sampling_time": np.inf}, "'sampling_time' parameter"),
            (make, {"sampling_time": 0.0}, "'sampling_time' parameter"),
            (make, {AMPLITUDE[make]: 0.0}, f"'{AMPLITUDE[make]}' parameter"),
            (make, {"random_state": "seed"}, "'random_state' parameter"),
        ]
    cases += [
        (make_duffing, {"sampling_time": 0.01}, "sampling_time=0.01 is too long"),
        (make_bouc_wen, {"sampling_time": 0.01}, "sampling_time=0.01 is too long"),
        (make_duffing, {"n_substeps": 0}, "'n_substeps' parameter"),
        (make_closed_loop_drive, {"sampling_time": 0.02}, "'sampling_time' parameter"),
        (make_closed_loop_drive, {"n_substeps": 5}, "n_substeps >= 20"),
    ]
    return cases


@pytest.mark.parametrize("make, kwargs, match", _bad_arguments(),
                         ids=lambda value: getattr(value, "__name__", None))
def test_bad_arguments(make, kwargs, match):
    with pytest.raises(ValueError, match=match):
        make(**kwargs)
