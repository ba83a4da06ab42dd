import dataclasses
import hashlib
import io
import shutil
import zipfile
from pathlib import Path

import numpy as np
import pytest

from sknlss.datasets import (fetch_cascaded_tanks, fetch_silverbox, load_cascaded_tanks,
                             make_bouc_wen, make_cascaded_tanks, make_duffing,
                             make_pnlss_reference)
from sknlss.datasets import _cascaded_tanks, _fetch, _silverbox


@pytest.fixture(autouse=True)
def no_network(monkeypatch):
    """Fail any test that reaches the real downloader."""

    def refuse():
        raise AssertionError("the test tried to download")

    monkeypatch.setattr(_fetch, "_downloader", refuse)


@pytest.fixture
def empty_environment(monkeypatch, tmp_path):
    monkeypatch.delenv("SKNLSS_DATA", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))


def _zip_bytes(members):
    archive = io.BytesIO()
    with zipfile.ZipFile(archive, "w") as zipped:
        for name, content in members.items():
            zipped.writestr(name, content)
    return archive.getvalue()


def _serve(monkeypatch, payload):
    """Make downloads write ``payload``; returns the list of requested addresses."""
    requested = []

    def downloader(url, output_file, pooch):
        requested.append(url)
        Path(output_file).write_bytes(payload)

    monkeypatch.setattr(_fetch, "_downloader", lambda: downloader)
    return requested


def _trust_archive(monkeypatch, module, name, payload):
    """Record the SHA-256 of ``payload`` as the archive's, as for an official one."""
    dataset = getattr(module, name)
    digest = hashlib.sha256(payload).hexdigest()
    monkeypatch.setattr(module, name, dataclasses.replace(dataset, archive_sha256=digest))


def _files(folder):
    return sorted(path.name for path in Path(folder).rglob("*") if path.is_file())


def _shared_file(data, name):
    path = Path(data.filename).with_name(name)
    if not path.is_file():
        pytest.skip(f"needs {name} beside {data.filename}")
    return path


# -------------------------------------------------------- Cascaded Tanks
@pytest.mark.realdata
def test_fetch_cascaded_tanks_records(cascaded_tanks):
    data = cascaded_tanks
    assert data.X_est.shape == (1024, 1) and data.X_test.shape == (1024, 1)
    assert data.y_est.shape == (1024,) and data.y_test.shape == (1024,)
    assert data.sampling_time == 4.0
    assert data.init_window == 50
    assert data.excited_band == (0.0, 0.0144)
    assert data.output_unit == "V"
    # First values as recorded in the data's SOURCE.md.
    np.testing.assert_allclose(data.X_est[:2, 0], [3.25672305, 3.24655232], atol=5e-9)
    np.testing.assert_allclose(data.y_est[:2], [5.20500496, 5.21538109], atol=5e-9)
    np.testing.assert_allclose(data.X_test[:2, 0], [0.97619197, 0.99921371], atol=5e-9)
    np.testing.assert_allclose(data.y_test[:2], [4.97276265, 4.97215229], atol=5e-9)
    assert np.sum(data.y_est == 10.0) == 47 and np.sum(data.y_test == 10.0) == 37
    assert "Cascaded Tanks" in data.DESCR


@pytest.mark.realdata
def test_cascaded_tanks_input_band(cascaded_tanks):
    # The benchmark's input has no power above the stated upper band edge.
    for X in (cascaded_tanks.X_est, cascaded_tanks.X_test):
        spectrum = np.abs(np.fft.rfft(X[:, 0] - X[:, 0].mean())) ** 2
        frequencies = np.fft.rfftfreq(1024, cascaded_tanks.sampling_time)
        above = frequencies > cascaded_tanks.excited_band[1] + 1 / 4096
        assert spectrum[above].sum() < 1e-3 * spectrum.sum()


@pytest.mark.realdata
def test_mat_and_csv_agree(cascaded_tanks, tmp_path, empty_environment):
    folder = tmp_path / "data"
    folder.mkdir()
    shutil.copy(_shared_file(cascaded_tanks, "dataBenchmark_from_mat.csv"), folder)
    from_csv = fetch_cascaded_tanks(folder)
    shutil.copy(_shared_file(cascaded_tanks, "dataBenchmark.mat"), folder)
    from_mat = fetch_cascaded_tanks(folder)
    assert from_mat.filename.endswith(".mat") and from_csv.filename.endswith(".csv")
    for key in ("X_est", "y_est", "X_test", "y_test"):
        np.testing.assert_array_equal(from_mat[key], from_csv[key])


@pytest.mark.realdata
def test_edited_copy_is_rejected(cascaded_tanks, tmp_path, empty_environment):
    folder = tmp_path / "data" / "cascaded_tanks"
    folder.mkdir(parents=True)
    content = _shared_file(cascaded_tanks, "dataBenchmark_from_mat.csv").read_text()
    # One digit changed: still a valid CSV, not the official file.
    edited = folder / "dataBenchmark_from_mat.csv"
    edited.write_text(content.replace("3.2567", "3.2568", 1))
    with pytest.raises(ValueError, match="SHA-256") as info:
        fetch_cascaded_tanks(tmp_path / "data")
    expected = _cascaded_tanks.CASCADED_TANKS.files["dataBenchmark_from_mat.csv"]
    for text in (str(edited), hashlib.sha256(edited.read_bytes()).hexdigest(), expected):
        assert text in str(info.value)


def test_corrupted_file_is_rejected_with_both_hashes(tmp_path, empty_environment):
    corrupted = tmp_path / "dataBenchmark.mat"
    corrupted.write_bytes(b"not a MATLAB file")
    with pytest.raises(ValueError) as info:
        fetch_cascaded_tanks(tmp_path)
    message = str(info.value)
    assert str(corrupted) in message
    assert hashlib.sha256(b"not a MATLAB file").hexdigest() in message
    assert _cascaded_tanks.CASCADED_TANKS.files["dataBenchmark.mat"] in message


def test_missing_data_message_without_download(tmp_path, empty_environment, monkeypatch):
    monkeypatch.setenv("SKNLSS_DATA", str(tmp_path / "env"))
    with pytest.raises(FileNotFoundError) as info:
        fetch_cascaded_tanks(tmp_path / "home", download_if_missing=False)
    message = str(info.value)
    for expected in ("dataBenchmark.mat", "dataBenchmark_from_mat.csv", "SKNLSS_DATA",
                     str(tmp_path / "home" / "cascaded_tanks"), str(tmp_path / "env"),
                     str(tmp_path / "cache" / "sknlss"), "10.4121/12960104"):
        assert expected in message
    assert "could not be downloaded" not in message


def test_failed_download_is_tried_once_and_clear(tmp_path, empty_environment, monkeypatch):
    requested = []

    def offline(url, output_file, pooch):
        requested.append(url)
        raise OSError("Name or service not known")

    monkeypatch.setattr(_fetch, "_downloader", lambda: offline)
    with pytest.raises(FileNotFoundError) as info:
        fetch_cascaded_tanks(tmp_path / "home")
    assert requested == [_cascaded_tanks.CASCADED_TANKS.archive_url]
    message = str(info.value)
    assert "could not be downloaded (Name or service not known)" in message
    assert "dataBenchmark.mat" in message and str(tmp_path / "home") in message
    # Nothing is left behind, not even the folders made for the download.
    assert not (tmp_path / "cache").exists()


def test_download_of_other_bytes_is_rejected_by_the_archive_hash(
        tmp_path, empty_environment, monkeypatch):
    _serve(monkeypatch, _zip_bytes({"CascadedTanksFiles/dataBenchmark.mat": b"x"}))
    with pytest.raises(FileNotFoundError, match="does not match the known hash") as info:
        fetch_cascaded_tanks(tmp_path / "empty")
    assert _cascaded_tanks.CASCADED_TANKS.archive_sha256 in str(info.value)
    assert _files(tmp_path / "cache") == []


def test_download_with_a_corrupted_member_is_rejected(tmp_path, empty_environment,
                                                      monkeypatch):
    payload = _zip_bytes({"CascadedTanksFiles/TanksBenchmark.pdf": b"%PDF",
                          "CascadedTanksFiles/dataBenchmark.mat": b"corrupt"})
    _trust_archive(monkeypatch, _cascaded_tanks, "CASCADED_TANKS", payload)
    _serve(monkeypatch, payload)
    with pytest.raises(FileNotFoundError, match="SHA-256") as info:
        fetch_cascaded_tanks(tmp_path / "empty")
    assert hashlib.sha256(b"corrupt").hexdigest() in str(info.value)
    assert _files(tmp_path / "cache") == []


def test_download_without_the_member_is_rejected(tmp_path, empty_environment, monkeypatch):
    payload = _zip_bytes({"README.txt": b"no data here"})
    _trust_archive(monkeypatch, _cascaded_tanks, "CASCADED_TANKS", payload)
    _serve(monkeypatch, payload)
    with pytest.raises(FileNotFoundError, match="no member CascadedTanksFiles/dataBenchmark"):
        fetch_cascaded_tanks(tmp_path / "empty")


def test_download_of_a_broken_archive_is_rejected(tmp_path, empty_environment, monkeypatch):
    payload = b"<html>not a zip</html>"
    _trust_archive(monkeypatch, _cascaded_tanks, "CASCADED_TANKS", payload)
    _serve(monkeypatch, payload)
    with pytest.raises(FileNotFoundError, match="not a zip file"):
        fetch_cascaded_tanks(tmp_path / "empty")


@pytest.mark.realdata
def test_download_extracts_checks_and_caches(cascaded_tanks, tmp_path, empty_environment,
                                            monkeypatch):
    mat = _shared_file(cascaded_tanks, "dataBenchmark.mat").read_bytes()
    payload = _zip_bytes({"CascadedTanksFiles/TanksBenchmark.pdf": b"%PDF",
                          "CascadedTanksFiles/dataBenchmark.mat": mat})
    _trust_archive(monkeypatch, _cascaded_tanks, "CASCADED_TANKS", payload)
    requested = _serve(monkeypatch, payload)
    data = fetch_cascaded_tanks(tmp_path / "empty")
    assert requested == [_cascaded_tanks.CASCADED_TANKS.archive_url]
    cached = tmp_path / "cache" / "sknlss" / "cascaded_tanks" / "dataBenchmark.mat"
    assert data.filename == str(cached)
    # Only the data file stays in the cache, not the archive.
    assert _files(tmp_path / "cache") == ["dataBenchmark.mat"]
    np.testing.assert_array_equal(data.y_test, cascaded_tanks.y_test)
    # The cached copy is found afterwards without any download.
    monkeypatch.setattr(_fetch, "_downloader", None)
    assert fetch_cascaded_tanks(tmp_path / "empty").filename == str(cached)


def test_search_order(tmp_path, monkeypatch):
    monkeypatch.setenv("SKNLSS_DATA", str(tmp_path / "env"))
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    folders = _fetch.data_folders(tmp_path / "home")
    assert folders == [tmp_path / "home", tmp_path / "env", tmp_path / "cache" / "sknlss"]
    candidates = list(_fetch.candidate_paths(_cascaded_tanks.CASCADED_TANKS,
                                             tmp_path / "home"))
    assert candidates == [
        tmp_path / "home" / "cascaded_tanks" / "dataBenchmark.mat",
        tmp_path / "home" / "cascaded_tanks" / "dataBenchmark_from_mat.csv",
        tmp_path / "home" / "dataBenchmark.mat",
        tmp_path / "home" / "dataBenchmark_from_mat.csv",
    ]
    monkeypatch.delenv("XDG_CACHE_HOME")
    assert _fetch.cache_home() == Path("~/.cache/sknlss").expanduser()


@pytest.mark.realdata
def test_first_folder_holding_the_data_wins(cascaded_tanks, tmp_path, monkeypatch):
    for name in ("home", "env"):
        (tmp_path / name / "cascaded_tanks").mkdir(parents=True)
        shutil.copy(_shared_file(cascaded_tanks, "dataBenchmark.mat"),
                    tmp_path / name / "cascaded_tanks")
    monkeypatch.setenv("SKNLSS_DATA", str(tmp_path / "env"))
    assert fetch_cascaded_tanks(tmp_path / "home").filename.startswith(str(tmp_path / "home"))
    assert fetch_cascaded_tanks().filename.startswith(str(tmp_path / "env"))


@pytest.mark.realdata
def test_load_cascaded_tanks_is_an_alias(cascaded_tanks):
    data = load_cascaded_tanks(Path(cascaded_tanks.filename).parent, download=False)
    assert data.keys() == cascaded_tanks.keys()
    for key in ("X_est", "y_est", "X_test", "y_test"):
        np.testing.assert_array_equal(data[key], cascaded_tanks[key])


def test_alias_passes_download_through(tmp_path, empty_environment):
    # With download=False the alias must not reach the (refusing) downloader.
    with pytest.raises(FileNotFoundError, match="were not found"):
        load_cascaded_tanks(tmp_path, download=False)


@pytest.mark.parametrize("loader, kwargs, name", [
    (fetch_cascaded_tanks, {"download_if_missing": "no"}, "download_if_missing"),
    (fetch_silverbox, {"download_if_missing": 1}, "download_if_missing"),
    (fetch_cascaded_tanks, {"data_home": 3}, "data_home"),
    (load_cascaded_tanks, {"download": "no"}, "download"),
])
def test_loader_arguments_are_validated(loader, kwargs, name):
    with pytest.raises((TypeError, ValueError), match=f"'{name}' parameter"):
        loader(**kwargs)


# -------------------------------------------------------------- Silverbox
@pytest.mark.realdata
def test_fetch_silverbox_records(silverbox):
    data = silverbox
    assert data.X_est.shape == (65062, 1) and data.y_est.shape == (65062,)
    assert list(data.tests) == ["multisine", "arrow", "arrow_full"]
    lengths = {"multisine": 21688, "arrow": 32000, "arrow_full": 40475}
    for name, record in data.tests.items():
        assert record.X.shape == (lengths[name], 1) and record.y.shape == (lengths[name],)
    assert data.X_test is data.tests["multisine"].X
    assert data.y_test is data.tests["multisine"].y
    assert data.sampling_time == 2**14 / 1e7
    assert data.init_window == 50 and data.output_unit == "V"
    assert "Silverbox" in data.DESCR and data.filename.endswith("SNLS80mV.mat")
    np.testing.assert_allclose(data.X_est[:2, 0], [-0.0145043307, 0.0206038614], atol=1e-10)
    np.testing.assert_allclose(data.y_est[:2], [0.0364508525, -0.0400935856], atol=1e-10)
    # The arrow without extrapolation is the start of the full arrow (both
    # begin at sample 100), and only the full arrow goes beyond the
    # estimation amplitude.
    full, arrow = data.tests["arrow_full"], data.tests["arrow"]
    np.testing.assert_array_equal(full.X[:32000], arrow.X)
    assert np.abs(arrow.X).max() < np.abs(data.X_est).max() < np.abs(full.X).max()


@pytest.mark.realdata
def test_silverbox_excited_band(silverbox):
    # One 8192-sample multisine period of the estimation record (it starts at
    # sample 344): its power lies on the odd lines 1 to 2683, the stated band.
    period = silverbox.X_est[344:344 + 8192, 0]
    power = np.abs(np.fft.rfft(period)) ** 2
    assert power[1:2684:2].sum() > 0.999 * power[1:].sum()
    assert power[2683] > 100 * np.median(power[2685:])
    resolution = 1 / (8192 * silverbox.sampling_time)
    np.testing.assert_allclose(silverbox.excited_band, (resolution, 2683 * resolution))
    np.testing.assert_allclose(silverbox.excited_band, (0.0745, 199.9), atol=1e-3)


def test_truncated_silverbox_copy_is_rejected(tmp_path, empty_environment):
    folder = tmp_path / "silverbox"
    folder.mkdir()
    truncated = folder / "SNLS80mV.mat"
    truncated.write_bytes(b"MATLAB 5.0 MAT-file" + bytes(1000))
    with pytest.raises(ValueError, match="not the official Silverbox file") as info:
        fetch_silverbox(tmp_path)
    assert str(truncated) in str(info.value)
    assert _silverbox.SILVERBOX.files["SNLS80mV.mat"] in str(info.value)


def test_silverbox_missing_message(tmp_path, empty_environment):
    with pytest.raises(FileNotFoundError) as info:
        fetch_silverbox(tmp_path, download_if_missing=False)
    for expected in ("SNLS80mV.mat", "SilverboxFiles.zip", str(tmp_path / "silverbox")):
        assert expected in str(info.value)


@pytest.mark.realdata
def test_silverbox_download_extracts_and_caches(silverbox, tmp_path, empty_environment,
                                               monkeypatch):
    payload = _zip_bytes({"SilverboxFiles/README.txt": b"readme",
                          "SilverboxFiles/SNLS80mV.mat": Path(silverbox.filename).read_bytes()})
    _trust_archive(monkeypatch, _silverbox, "SILVERBOX", payload)
    requested = _serve(monkeypatch, payload)
    data = fetch_silverbox(tmp_path / "empty")
    assert requested == [_silverbox.SILVERBOX.archive_url]
    assert data.filename == str(tmp_path / "cache" / "sknlss" / "silverbox" / "SNLS80mV.mat")
    np.testing.assert_array_equal(data.y_est, silverbox.y_est)


# ------------------------------------------------------- simulated tanks
def test_make_cascaded_tanks_shapes_and_ranges():
    data = make_cascaded_tanks(random_state=0)
    assert data.X_est.shape == data.X_test.shape == (1024, 1)
    assert data.y_est.shape == data.y_test.shape == (1024,)
    assert data.states_est.shape == (1024, 2)
    assert data.sampling_time == 4.0
    assert data.noise_std == 0.02 and data.init_window == 50
    assert "k1 sqrt(x1)" in data.DESCR
    for X, y, states in ((data.X_est, data.y_est, data.states_est),
                         (data.X_test, data.y_test, data.states_test)):
        assert np.all(X >= 0)
        assert 1.5 < X.mean() < 4.0
        assert np.all(states >= 0) and np.all(states <= 10.0)
        assert 2.0 < y.mean() < 9.0
    # Both records start from the same initial state.
    np.testing.assert_array_equal(data.states_est[0], data.states_test[0])


def test_make_cascaded_tanks_reproducible_and_noise():
    first = make_cascaded_tanks(random_state=3)
    second = make_cascaded_tanks(random_state=3)
    for key in ("X_est", "y_est", "X_test", "y_test"):
        np.testing.assert_array_equal(first[key], second[key])
    clean = make_cascaded_tanks(random_state=3, process_noise=0.0, measurement_noise=0.0)
    np.testing.assert_array_equal(clean.y_est, clean.states_est[:, 1])
    noisy = make_cascaded_tanks(random_state=3, process_noise=0.0, measurement_noise=0.05)
    np.testing.assert_array_equal(noisy.states_est, clean.states_est)
    assert np.std(noisy.y_est - clean.y_est) == pytest.approx(0.05, rel=0.15)


def test_make_cascaded_tanks_steady_state_and_overflow():
    n = 400
    u = np.full(n, 2.0)
    k = (0.05, 0.05, 0.05, 0.042)
    data = make_cascaded_tanks(n, input=(u, u), process_noise=0.0, measurement_noise=0.0,
                               x0=(0.0, 0.0), k=k)
    # Equilibrium of eq. 1: sqrt(x1) = k4 u / k1, sqrt(x2) = k2 sqrt(x1) / k3.
    level = (k[3] * 2.0 / k[0]) ** 2
    np.testing.assert_allclose(data.states_est[-1], [level, level], rtol=1e-3)
    # A large input fills the upper tank to its overflow level and the lower
    # one to its own.
    big = np.full(n, 8.0)
    full = make_cascaded_tanks(n, input=(big, big), process_noise=0.0,
                               measurement_noise=0.0, overflow=(6.0, 9.0))
    np.testing.assert_allclose(full.states_est[-1], [6.0, 9.0])


def test_make_cascaded_tanks_rk4_converges():
    u = make_cascaded_tanks(random_state=0).X_est[:, 0]
    coarse, fine = (make_cascaded_tanks(input=(u, u), process_noise=0.0,
                                        measurement_noise=0.0, overflow=(50.0, 50.0),
                                        n_substeps=m).states_est for m in (4, 32))
    np.testing.assert_allclose(coarse, fine, atol=1e-4)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"n_samples": 2}, "n_samples"),
        ({"n_samples": 100.0}, "n_samples"),
        ({"sampling_time": np.inf}, "sampling_time"),
        ({"sampling_time": 0.0}, "sampling_time"),
        ({"n_substeps": 0}, "n_substeps"),
        ({"input": (np.ones(10), np.ones(10))}, "input must be a pair"),
        ({"input": (np.ones(1024), np.full(1024, np.nan))}, "finite"),
        ({"measurement_noise": -1.0}, "measurement_noise"),
        ({"process_noise": np.nan}, "process_noise"),
        ({"overflow": (10.0,)}, "overflow"),
        ({"k": (0.05, 0.05, 0.05)}, "k must be"),
        ({"x0": (1.0, -1.0)}, "x0"),
        ({"overflow_fraction": 2.0}, "overflow_fraction"),
        ({"random_state": "seed"}, "random_state"),
    ],
)
def test_make_cascaded_tanks_bad_arguments(kwargs, match):
    with pytest.raises(ValueError, match=match):
        make_cascaded_tanks(**kwargs)


# ----------------------------------------------------------- PNLSS reference
def test_pnlss_reference_shapes_and_model():
    data = make_pnlss_reference()
    n_rows = 4 * 3 * 1024
    assert data.X.shape == (n_rows, 1) and data.y.shape == (n_rows,)
    np.testing.assert_array_equal(data.sequence_id, np.repeat(np.arange(4), 3 * 1024))
    assert data.period == 1024
    np.testing.assert_array_equal(data.lines, np.arange(1, 461, 2))
    assert data.A.shape == (2, 2) and data.B.shape == (2, 1)
    assert data.C.shape == (1, 2) and data.D.shape == (1, 1)
    assert data.E.shape == (2, 16) and data.F.shape == (1, 16)
    assert data.exponents.shape == (16, 3)
    # Documented order: x1^2, x1 x2, x1 u, x2^2, ..., then degree 3 ending in u^3.
    np.testing.assert_array_equal(data.exponents[:4], [[2, 0, 0], [1, 1, 0], [1, 0, 1],
                                                       [0, 2, 0]])
    np.testing.assert_array_equal(data.exponents[-1], [0, 0, 3])
    assert np.all(np.abs(np.linalg.eigvals(data.A)) < 1)
    np.testing.assert_allclose(np.sqrt(np.mean(data.X**2)), 0.05, rtol=1e-12)


def test_pnlss_reference_is_the_shared_true_model(pnlss_tutorial_model):
    data = make_pnlss_reference(noise=False)
    for name in "ABCDEF":
        np.testing.assert_array_equal(getattr(data, name), pnlss_tutorial_model[name])
    # The defaults are the tutorial's experiment.
    experiment = pnlss_tutorial_model["experiment"]
    assert data.period == experiment["samples_per_period"]
    assert np.unique(data.sequence_id).size == experiment["realizations"]
    assert data.X.shape[0] == data.period * experiment["periods"] * experiment["realizations"]


def test_pnlss_reference_steady_state_and_reproducible():
    data = make_pnlss_reference(noise=False)
    periods = data.y.reshape(4, 3, 1024)
    np.testing.assert_allclose(periods[:, 0], periods[:, 2], atol=1e-12)
    again = make_pnlss_reference(noise=False)
    np.testing.assert_array_equal(data.y, again.y)
    other = make_pnlss_reference(noise=False, random_state=1)
    assert not np.allclose(data.y, other.y)


def test_pnlss_reference_matches_a_direct_simulation():
    data = make_pnlss_reference(n_realizations=1, n_periods=1, n_samples_per_period=64,
                                noise=False)
    u = data.X[:, 0]
    # Steady state: starting from the state reached after the dropped periods
    # (the same input; 13 of 64 samples cover the 815 of the run-in), a plain
    # simulation reproduces the data.
    x = np.zeros(2)
    for _ in range(14):
        y = np.empty(64)
        for t in range(64):
            s = np.array([x[0], x[1], u[t]])
            z = np.prod(s ** data.exponents, axis=1)
            y[t] = (data.C @ x + data.D[:, 0] * u[t] + data.F @ z)[0]
            x = data.A @ x + data.B[:, 0] * u[t] + data.E @ z
    np.testing.assert_allclose(data.y, y, rtol=1e-12, atol=1e-15)


def test_pnlss_reference_noise_level():
    data = make_pnlss_reference()
    noise = data.y - data.y_noiseless
    # White noise of std 1e-3 std(y) summed with its successor: std sqrt(2) times.
    expected = np.sqrt(2) * 1e-3 * data.y_noiseless.std()
    assert noise.std() == pytest.approx(expected, rel=0.05)
    lag1 = np.corrcoef(noise[1:-2], noise[2:-1])[0, 1]
    assert lag1 == pytest.approx(0.5, abs=0.05)


@pytest.mark.parametrize("kwargs, name", [
    ({"n_periods": 0}, "n_periods"),
    ({"n_realizations": 1.5}, "n_realizations"),
    ({"n_samples_per_period": 4}, "n_samples_per_period"),
    ({"noise": "yes"}, "noise"),
])
def test_pnlss_reference_bad_arguments(kwargs, name):
    with pytest.raises(ValueError, match=f"'{name}' parameter"):
        make_pnlss_reference(**kwargs)


@pytest.mark.parametrize("make, input_rms", [(make_duffing, 1e4), (make_bouc_wen, 3e5)])
def test_an_oscillator_that_overflows_is_refused(make, input_rms):
    # Far beyond the documented amplitudes the fixed-step integration is
    # unstable: an error naming the amplitude, not records of NaN.
    with pytest.raises(ValueError, match=r"overflows at input_rms=.*Lower input_rms or raise "
                                         r"n_substeps"):
        make(256, 256, input_rms=input_rms, random_state=0)
