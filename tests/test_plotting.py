import sys
from types import SimpleNamespace

import numpy as np
import pytest

matplotlib = pytest.importorskip("matplotlib")
matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from sknlss.plotting import plot_error_spectrum, plot_frf, plot_simulation  # noqa: E402

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(autouse=True)
def _close_figures():
    yield
    plt.close("all")


def _fake_bla(n_freq=40, n_y=1, n_u=1, with_model=True):
    """An object with the fitted attributes plot_frf reads, for a first-order system."""
    freq = np.linspace(0.01, 0.2, n_freq)
    z = np.exp(2j * np.pi * freq)
    frf = (0.5 / (1.0 - 0.8 / z))[:, None, None] * np.ones((1, n_y, n_u))
    bla = SimpleNamespace(
        frequencies_=freq,
        frf_=frf,
        noise_variance_=np.full((n_freq, n_y, n_u), 1e-4),
        total_variance_=np.full((n_freq, n_y, n_u), 1e-2),
    )
    if with_model:
        bla.frf_model_ = frf * 1.01
    return bla


def _assert_png(path):
    assert path.stat().st_size > 1000
    assert path.read_bytes()[:8] == PNG_SIGNATURE


def test_plot_frf_lines_labels_and_png(tmp_path):
    ax = plot_frf(_fake_bla(), sampling_time=4.0)
    labels = [line.get_label() for line in ax.get_lines()]
    assert labels == [
        "BLA (nonparametric)",
        "BLA (parametric model)",
        "Total distortion (noise + nonlinear)",
        "Noise level",
    ]
    assert ax.get_xlabel() == "Frequency (Hz)"
    assert ax.get_ylabel() == "Magnitude (dB)"
    assert ax.get_legend() is not None
    # Hz axis: the frequencies in cycles/sample divided by the sampling time.
    np.testing.assert_allclose(ax.get_lines()[0].get_xdata(), np.linspace(0.01, 0.2, 40) / 4.0)
    # Levels are variances shown as standard deviations in dB.
    np.testing.assert_allclose(ax.get_lines()[3].get_ydata(), -40.0)
    np.testing.assert_allclose(ax.get_lines()[2].get_ydata(), -20.0)
    path = tmp_path / "frf.png"
    ax.figure.savefig(path)
    _assert_png(path)


def test_plot_frf_without_model_and_normalised_frequency():
    ax = plot_frf(_fake_bla(with_model=False))
    assert len(ax.get_lines()) == 3
    assert ax.get_xlabel() == "Frequency (cycles/sample)"


def test_plot_frf_mimo_entry_and_existing_axes():
    bla = _fake_bla(n_y=2, n_u=3)
    bla.frf_[:, 1, 2] *= 10.0
    fig, axes = plt.subplots(1, 2)
    ax = plot_frf(bla, output_index=1, input_index=2, ax=axes[1])
    assert ax is axes[1]
    reference = plot_frf(bla, ax=axes[0])
    np.testing.assert_allclose(
        ax.get_lines()[0].get_ydata() - reference.get_lines()[0].get_ydata(), 20.0
    )
    with pytest.raises(ValueError, match="out of range"):
        plot_frf(bla, output_index=2)


def test_plot_frf_rejects_unfitted_object():
    with pytest.raises(ValueError, match="fitted BLAEstimator"):
        plot_frf(object())


def test_plot_simulation_single_model(tmp_path):
    t = np.arange(300)
    y = np.sin(0.05 * t) + 5.0
    ax = plot_simulation(y, y - 0.1, sampling_time=4.0, unit="V", label="BLA")
    lines = ax.get_lines()
    assert [line.get_label() for line in lines] == ["measured", "BLA", "BLA error"]
    np.testing.assert_allclose(lines[2].get_ydata(), 0.1)
    np.testing.assert_allclose(lines[0].get_xdata()[-1], 4.0 * 299)
    assert ax.get_xlabel() == "Time (s)"
    assert ax.get_ylabel() == "Output (V)"
    assert ax.get_legend() is not None
    path = tmp_path / "simulation.png"
    ax.figure.savefig(path)
    _assert_png(path)


def test_plot_simulation_several_models_and_2d_outputs():
    y = np.column_stack([np.zeros(50), np.ones(50)])
    ax = plot_simulation(y, {"A": y * 0.5, "B": y * 2.0}, output_index=1)
    assert len(ax.get_lines()) == 5
    assert ax.get_xlabel() == "Time (samples)"
    np.testing.assert_allclose(ax.get_lines()[4].get_ydata(), -1.0)


def test_plot_simulation_rejects_mismatched_lengths():
    with pytest.raises(ValueError, match="samples"):
        plot_simulation(np.zeros(10), np.zeros(9))
    with pytest.raises(ValueError, match="sampling_time"):
        plot_simulation(np.zeros(10), np.zeros(10), sampling_time=0.0)


def test_plot_error_spectrum_levels(tmp_path):
    rng = np.random.default_rng(0)
    n = 4096
    y = 3.0 + np.sin(2 * np.pi * 64 / n * np.arange(n))
    error = 0.01 * rng.standard_normal(n)
    ax = plot_error_spectrum(y, y - error, noise_level=0.01, sampling_time=4.0, unit="V")
    lines = ax.get_lines()
    assert [line.get_label() for line in lines] == ["measured output", "model error",
                                                    "noise level"]
    assert len(lines[1].get_xdata()) == n // 2
    assert lines[1].get_xdata()[0] == pytest.approx(1.0 / (n * 4.0))
    # White noise of std 0.01 lies around -40 dB on this scale.
    assert abs(np.median(lines[1].get_ydata()) - (-40.0)) < 3.0
    np.testing.assert_allclose(lines[2].get_ydata(), -40.0)
    assert ax.get_xlabel() == "Frequency (Hz)"
    assert ax.get_ylabel() == "Amplitude (dB re 1 V)"
    path = tmp_path / "spectrum.png"
    ax.figure.savefig(path)
    _assert_png(path)


def test_plot_error_spectrum_array_level_and_errors():
    y = np.sin(0.2 * np.arange(64))
    ax = plot_error_spectrum(y, {"A": y * 0.9, "B": y * 0.8}, noise_level=np.full(32, 1e-3))
    assert len(ax.get_lines()) == 4
    with pytest.raises(ValueError, match="noise_level"):
        plot_error_spectrum(y, y, noise_level=np.ones(5))
    with pytest.raises(ValueError, match="non-finite"):
        plot_error_spectrum(y, np.full(64, np.nan))


def test_plot_frf_draws_levels_once_or_not_at_all():
    bla = _fake_bla()
    bla.noise_variance_ = bla.total_variance_.copy()  # the LPM reports one level
    labels = [line.get_label() for line in plot_frf(bla).get_lines()]
    assert labels == ["BLA (nonparametric)", "BLA (parametric model)",
                      "Total distortion (noise + nonlinear)"]
    bla.noise_variance_ = bla.total_variance_ = None
    assert len(plot_frf(bla).get_lines()) == 2


def test_plot_frf_of_a_fitted_bla(tmp_path):
    from scipy.signal import lfilter

    from sknlss import BLAEstimator
    from sknlss.signals import multisine

    u, _ = multisine(256, n_periods=2, n_realizations=4, random_state=0)
    y = lfilter([0.0, 0.5], [1.0, -1.2, 0.5], u, axis=1)
    y += 0.5 * y**3 + 1e-3 * np.random.default_rng(1).standard_normal(y.shape)
    X, sequence_id = u.reshape(-1, 1), np.repeat(np.arange(4), u.shape[1])
    bla = BLAEstimator(n_states=2, period=256).fit(X, y.ravel(), sequence_id=sequence_id)
    ax = plot_frf(bla, sampling_time=0.5)
    lines = ax.get_lines()
    assert len(lines) == 4
    assert len(lines[0].get_xdata()) == len(bla.frequencies_)
    # With nonlinear distortion the total level lies above the noise level.
    assert np.median(lines[2].get_ydata()) > np.median(lines[3].get_ydata()) + 6.0
    path = tmp_path / "bla.png"
    ax.figure.savefig(path)
    _assert_png(path)


def test_plot_simulation_keeps_the_measurement_visible_when_a_model_diverges():
    y = 5.0 + np.sin(0.1 * np.arange(100))
    diverged = y.copy()
    diverged[60:70] = np.logspace(2, 9, 10)
    diverged[70:] = np.nan
    ax = plot_simulation(y, {"stable": y + 0.1, "unstable": diverged})
    low, high = ax.get_ylim()
    assert low == pytest.approx(-3.0, abs=0.01)
    assert high == pytest.approx(9.0, abs=0.01)
    ax = plot_simulation(y, y + 0.1)
    assert ax.get_ylim()[1] < 7.0


def test_missing_matplotlib_names_the_plot_extra(monkeypatch):
    # A None entry in sys.modules makes the import fail as if not installed.
    monkeypatch.setitem(sys.modules, "matplotlib.pyplot", None)
    with pytest.raises(ImportError, match=r"sknlss\[plot\]"):
        plot_simulation(np.zeros(10), np.zeros(10))
