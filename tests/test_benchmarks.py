"""The benchmark reproductions and the command line over them."""

import io
import math
import warnings

import numpy as np
import pytest
from sklearn.base import clone
from sklearn.exceptions import ConvergenceWarning

from sknlss import BLAEstimator, PNLSSRegressor, benchmarks
from sknlss.__main__ import main
from sknlss.benchmarks import BENCHMARKS, Benchmark, evaluate, format_table, reproduce
from sknlss.datasets import make_cascaded_tanks
from sknlss.metrics import rms_error


def _tiny_benchmark():
    data = make_cascaded_tanks(n_samples=256, random_state=0)
    return Benchmark(
        "Tiny tanks", lambda home, download_if_missing: data, lambda: data,
        lambda: [("BLA", lambda seed: BLAEstimator(n_states=2, estimate_x0=True)),
                 ("BLA 1", lambda seed: BLAEstimator(n_states=1))],
        lambda d: {"test": (d.X_test, d.y_test, 0)},
    )


def test_evaluate_summarises_over_random_states():
    data = make_cascaded_tanks(n_samples=256, random_state=0)
    records = {"test": (data.X_test, data.y_test, 0), "tail": (data.X_test, data.y_test, 50)}
    rows, fitted = evaluate(data, [("BLA", lambda seed: BLAEstimator(n_states=2))], records,
                            random_states=(0, 1), scale=1e3)
    row = rows[0]
    assert row["model"] == "BLA" and row["n_params"] == 9
    assert row["test min"] <= row["test"] <= row["test max"]
    assert math.isfinite(row["tail"])
    assert isinstance(fitted["BLA"], BLAEstimator)
    text = format_table(rows, records, "mV")
    assert "test (mV)" in text and "BLA" in text
    # The first 50 samples of "tail" set the state of its simulation.
    model = fitted["BLA"]
    x0 = model.estimate_initial_state(data.X_test[:50], data.y_test[:50])
    tail = rms_error(data.y_test[50:], model.predict(data.X_test, x0=x0)[50:])
    assert rows[0]["tail"] == pytest.approx(1e3 * tail, rel=1e-9)


def test_reproduce_writes_tables_and_figures(monkeypatch, tmp_path):
    monkeypatch.setitem(BENCHMARKS, "tiny", _tiny_benchmark())
    out = io.StringIO()
    tables = reproduce(["tiny"], output=tmp_path, random_states=(0,), out=out)
    assert [row["model"] for row in tables["tiny"]] == ["BLA", "BLA 1"]
    assert (tmp_path / "tiny.csv").is_file()
    assert any(path.suffix == ".png" for path in tmp_path.iterdir())
    assert "Tiny tanks" in out.getvalue()


def test_a_diverging_model_is_listed_not_drawn_and_does_not_warn(monkeypatch, tmp_path):
    from sknlss.exceptions import SimulationDivergedWarning

    simulate = benchmarks._simulate_record

    def diverging_one_state(model, X, y, n_skip):
        if model.n_states == 1:
            warnings.warn("diverged", SimulationDivergedWarning)
            return np.full(len(y), np.nan)
        return simulate(model, X, y, n_skip)

    monkeypatch.setattr(benchmarks, "_simulate_record", diverging_one_state)
    monkeypatch.setitem(BENCHMARKS, "tiny", _tiny_benchmark())
    out = io.StringIO()
    with warnings.catch_warnings():
        warnings.simplefilter("error", SimulationDivergedWarning)
        reproduce(["tiny"], output=tmp_path, random_states=(0,), out=out)
    assert "Not drawn (diverged): BLA 1" in out.getvalue()


def test_missing_data_fall_back_to_simulated(monkeypatch, tmp_path):
    def missing(home, download_if_missing):
        raise FileNotFoundError("no data here")

    benchmark = _tiny_benchmark()
    benchmark.fetch = missing
    monkeypatch.setitem(BENCHMARKS, "tiny", benchmark)
    out = io.StringIO()
    data, source = benchmarks.load_benchmark("tiny", out=out)
    assert source == "simulated"
    assert "FALLING BACK TO SIMULATED DATA" in out.getvalue()
    assert data.X_est.shape[1] == 1
    # Its files say so too, and cannot pass for the benchmark's results.
    reproduce(["tiny"], output=tmp_path, random_states=(0,), out=io.StringIO())
    assert {path.name for path in tmp_path.iterdir()} >= {"tiny_simulated.csv"}
    assert all(path.name.startswith("tiny_simulated") for path in tmp_path.iterdir())


def test_measured_source_names_the_file_only(monkeypatch):
    data = make_cascaded_tanks(n_samples=256, random_state=0)
    data.filename = "/some/folder/cascaded_tanks/dataBenchmark.mat"
    benchmark = _tiny_benchmark()
    benchmark.fetch = lambda home, download_if_missing: data
    monkeypatch.setitem(BENCHMARKS, "tiny", benchmark)
    assert benchmarks.load_benchmark("tiny")[1] == "measured (dataBenchmark.mat)"


def test_reproduce_refuses_an_output_path_before_any_fit(monkeypatch, tmp_path):
    monkeypatch.setitem(BENCHMARKS, "tiny", _tiny_benchmark())
    a_file = tmp_path / "a_file"
    a_file.write_text("")
    out = io.StringIO()
    with pytest.raises(OSError):
        reproduce(["tiny"], output=a_file, random_states=(0,), out=out)
    # A folder where no file can be written (a directory of /proc, which even
    # the superuser cannot write to).
    with pytest.raises(OSError):
        reproduce(["tiny"], output="/proc/self", random_states=(0,), out=out)
    assert out.getvalue() == ""


@pytest.mark.parametrize("arguments, message", [
    (dict(random_states=(0, -1)), "random_states must hold non-negative integers, got -1"),
    (dict(random_states=("a",)), "random_states must hold non-negative integers, got 'a'"),
    (dict(random_states=(True,)), "random_states must hold non-negative integers, got True"),
    (dict(n_jobs=0), "The 'n_jobs' parameter of reproduce"),
])
def test_reproduce_refuses_its_arguments_before_loading_any_data(monkeypatch, arguments,
                                                                  message):
    benchmark = _tiny_benchmark()
    benchmark.fetch = lambda home, download_if_missing: pytest.fail("data loaded")
    monkeypatch.setitem(BENCHMARKS, "tiny", benchmark)
    with pytest.raises(ValueError, match=message):
        reproduce(["tiny"], out=io.StringIO(), **arguments)


def test_command_line(monkeypatch, tmp_path, capsys):
    monkeypatch.chdir(tmp_path)
    calls = []
    monkeypatch.setattr("sknlss.__main__.reproduce",
                        lambda names, **kwargs: calls.append((names, kwargs)))
    assert main(["reproduce", "--benchmark", "silverbox", "--random-states", "3", "4",
                 "--no-download", "--output", "somewhere"]) == 0
    names, kwargs = calls[0]
    assert names == ["silverbox"]
    assert kwargs["random_states"] == (3, 4) and not kwargs["download_if_missing"]
    main(["reproduce"])
    assert calls[1][0] == sorted(BENCHMARKS)
    with pytest.raises(SystemExit):
        main(["reproduce", "--benchmark", "nowhere"])
    # Usage errors, before any fit.
    (tmp_path / "a_file").write_text("")
    for arguments, message in [(["--output", "a_file"], "--output a_file"),
                               (["--output", "/proc/self"], "--output /proc/self"),
                               (["--random-states", "-1"], "non-negative"),
                               (["--random-states", "abc"], "non-negative integer, got 'abc'"),
                               (["--n-jobs", "0"], "0 fits at once"),
                               (["--n-jobs", "x"], "is an integer, got 'x'")]:
        capsys.readouterr()
        with pytest.raises(SystemExit):
            main(["reproduce", *arguments])
        assert message in capsys.readouterr().err
    assert len(calls) == 2


@pytest.mark.parametrize("name", sorted(BENCHMARKS))
def test_benchmarks_define_their_models(name):
    models = BENCHMARKS[name].models()
    assert models[0][0] == "BLA"
    for label, factory in models:
        estimator = factory(0)
        assert hasattr(estimator, "fit") and np.isscalar(estimator.get_params()["n_states"])


def test_evaluate_counts_fits_stopped_while_improving():
    data = make_cascaded_tanks(n_samples=256, random_state=0)
    records = {"test": (data.X_test, data.y_test, 0)}
    factory = lambda seed: PNLSSRegressor(n_states=2, degree=2, max_iter=1, n_init=1,  # noqa: E731
                                          validation_fraction=0.0, random_state=seed)
    with warnings.catch_warnings():
        # The table says it; nothing is printed.
        warnings.simplefilter("error", ConvergenceWarning)
        rows, _ = evaluate(data, [("PNLSS", factory)], records, random_states=(0, 1))
    assert rows[0]["still_improving"] == 2
    assert "at max_iter" in format_table(rows, records, "V")


@pytest.mark.parametrize("data, records, random_states, message", [
    ({"X_est": np.zeros((8, 1))}, {}, (0,), "lacks y_est"),
    (None, {}, (), "at least one random state"),
    (None, {"test": (None, np.zeros(20), -5)}, (0,), r"records\['test'\]: n_skip must be "
                                                    r"an integer from 0 to 19"),
    (None, {"test": (None, np.zeros(20), 2.5)}, (0,), "n_skip must be an integer"),
    (None, {"test": (None, np.zeros(20), 20)}, (0,), "n_skip must be an integer"),
    (None, {"test": (None, np.zeros(20))}, (0,), r"must be a tuple \(X, y, n_skip\)"),
    (None, {}, (0, -2), "random_states must hold non-negative integers"),
])
def test_evaluate_names_the_argument_it_cannot_use(data, records, random_states, message):
    data = make_cascaded_tanks(n_samples=64, random_state=0) if data is None else data
    with pytest.raises(ValueError, match=message):
        evaluate(data, [("BLA", lambda seed: BLAEstimator(n_states=1))], records,
                 random_states=random_states)


def test_evaluate_names_models_that_are_not_pairs():
    data = make_cascaded_tanks(n_samples=64, random_state=0)
    with pytest.raises(ValueError, match=r"models must hold \(label, factory\) pairs.*'BLA'"):
        evaluate(data, ["BLA"], {}, random_states=(0,))


def test_evaluate_takes_a_plain_dict_and_a_holdout_search():
    from sknlss.model_selection import HoldoutSearch

    data = make_cascaded_tanks(n_samples=256, random_state=0)
    records = {"tail": (data.X_test, data.y_test, 50)}
    search = HoldoutSearch(PNLSSRegressor(n_states=1, degree=2, max_iter=2, n_init=1),
                           validation_fractions=(0.3,))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        rows, fitted = evaluate({"X_est": data.X_est, "y_est": data.y_est},
                                [("search", lambda seed: clone(search))], records,
                                random_states=(0,))
    model = fitted["search"]
    x0 = model.estimate_initial_state(data.X_test[:50], data.y_test[:50])
    np.testing.assert_array_equal(
        x0, model.best_estimator_.estimate_initial_state(data.X_test[:50], data.y_test[:50]))
    assert rows[0]["tail"] == pytest.approx(
        rms_error(data.y_test[50:], model.predict(data.X_test, x0=x0)[50:]), rel=1e-9)
