import sys
from types import SimpleNamespace

import numpy as np
import pytest

matplotlib = pytest.importorskip("matplotlib")
matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

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


def _assert_png(fig, path):
    fig.savefig(path)
    assert path.stat().st_size > 1000
    assert path.read_bytes()[:8] == PNG_SIGNATURE


def _assert_legend_outside(ax):
    """The legend lies entirely to the right of the Axes: it hides no data."""
    ax.figure.canvas.draw()
    legend = ax.get_legend().get_window_extent()
    assert legend.x0 >= ax.get_window_extent().x1


def _legend_texts(ax):
    return [text.get_text() for text in ax.get_legend().get_texts()]


def test_plot_frf_lines_labels_and_png(tmp_path):
    fig = plot_frf(_fake_bla(), sampling_time=4.0)
    assert isinstance(fig, Figure)
    (ax,) = fig.axes
    labels = [line.get_label() for line in ax.get_lines()]
    assert labels == [
        "BLA (nonparametric)",
        "BLA (parametric model)",
        "Total distortion (noise + nonlinear)",
        "Noise level",
    ]
    assert ax.get_xlabel() == "Frequency (Hz)"
    assert ax.get_ylabel() == "Magnitude (dB)"
    _assert_legend_outside(ax)
    # Hz axis: the frequencies in cycles/sample divided by the sampling time.
    np.testing.assert_allclose(ax.get_lines()[0].get_xdata(), np.linspace(0.01, 0.2, 40) / 4.0)
    # Levels are variances shown as standard deviations in dB.
    np.testing.assert_allclose(ax.get_lines()[3].get_ydata(), -40.0)
    np.testing.assert_allclose(ax.get_lines()[2].get_ydata(), -20.0)
    _assert_png(fig, tmp_path / "frf.png")


def test_plot_frf_without_model_and_normalised_frequency():
    ax = plot_frf(_fake_bla(with_model=False)).axes[0]
    assert len(ax.get_lines()) == 3
    assert ax.get_xlabel() == "Frequency (cycles/sample)"


def test_plot_frf_mimo_entry_and_existing_axes():
    bla = _fake_bla(n_y=2, n_u=3)
    bla.frf_[:, 1, 2] *= 10.0
    fig, axes = plt.subplots(1, 2)
    assert plot_frf(bla, output_index=1, input_index=2, ax=axes[1]) is fig
    plot_frf(bla, ax=axes[0])
    np.testing.assert_allclose(
        axes[1].get_lines()[0].get_ydata() - axes[0].get_lines()[0].get_ydata(), 20.0
    )
    with pytest.raises(ValueError, match="out of range"):
        plot_frf(bla, output_index=2)


def test_plot_frf_leaves_the_entries_not_estimated_as_gaps():
    # NaN where an input has no power of its own (several inputs of
    # different bands): the levels are drawn once, with gaps.
    bla = _fake_bla()
    bla.total_variance_ = bla.noise_variance_
    for name in ("frf_", "noise_variance_"):
        getattr(bla, name)[5:9] = np.nan
    lines = plot_frf(bla).axes[0].get_lines()
    assert len(lines) == 3
    assert np.isnan(lines[0].get_ydata()[5:9]).all()
    assert np.isfinite(lines[0].get_ydata()[:5]).all()


def test_plot_frf_rejects_unfitted_or_invalid_input():
    with pytest.raises(ValueError, match="fitted BLAEstimator"):
        plot_frf(object())
    # A nonlinear model is not a BLA, but it holds one.
    with pytest.raises(ValueError, match=r"plot_frf\(model\.bla_\)"):
        plot_frf(SimpleNamespace(bla_=_fake_bla()))
    bla = _fake_bla()
    bla.frf_[3] = np.inf
    with pytest.raises(ValueError, match=r"bla\.frf_ has infinite"):
        plot_frf(bla)
    bla = _fake_bla()
    bla.noise_variance_ = bla.noise_variance_[:5]
    with pytest.raises(ValueError, match=r"bla\.noise_variance_ must have shape"):
        plot_frf(bla)
    bla = _fake_bla()
    bla.frequencies_ = np.array([])
    with pytest.raises(ValueError, match=r"bla\.frequencies_ must be a non-empty"):
        plot_frf(bla)
    with pytest.raises(ValueError, match="'sampling_time' parameter"):
        plot_frf(_fake_bla(), sampling_time=-1.0)
    with pytest.raises(ValueError, match="'input_index' parameter"):
        plot_frf(_fake_bla(), input_index=0.5)
    with pytest.raises(ValueError, match="ax must be a matplotlib Axes"):
        plot_frf(_fake_bla(), ax="left")


def test_plot_frf_draws_levels_once_or_not_at_all():
    bla = _fake_bla()
    bla.noise_variance_ = bla.total_variance_.copy()  # the LPM reports one level
    labels = [line.get_label() for line in plot_frf(bla).axes[0].get_lines()]
    assert labels == ["BLA (nonparametric)", "BLA (parametric model)",
                      "Total distortion (noise + nonlinear)"]
    bla.noise_variance_ = bla.total_variance_ = None
    assert len(plot_frf(bla).axes[0].get_lines()) == 2


def test_plot_frf_of_a_fitted_bla(tmp_path):
    from scipy.signal import lfilter

    from sknlss import BLAEstimator
    from sknlss.signals import multisine

    u, _ = multisine(256, n_periods=2, n_realizations=4, random_state=0)
    y = lfilter([0.0, 0.5], [1.0, -1.2, 0.5], u, axis=1)
    y += 0.5 * y**3 + 1e-3 * np.random.default_rng(1).standard_normal(y.shape)
    X, sequence_id = u.reshape(-1, 1), np.repeat(np.arange(4), u.shape[1])
    bla = BLAEstimator(n_states=2, period=256).fit(X, y.ravel(), sequence_id=sequence_id)
    fig = plot_frf(bla, sampling_time=0.5)
    lines = fig.axes[0].get_lines()
    assert len(lines) == 4
    assert len(lines[0].get_xdata()) == len(bla.frequencies_)
    # With nonlinear distortion the total level lies above the noise level.
    assert np.median(lines[2].get_ydata()) > np.median(lines[3].get_ydata()) + 6.0
    _assert_png(fig, tmp_path / "bla.png")


def test_plot_simulation_single_model(tmp_path):
    t = np.arange(300)
    y = np.sin(0.05 * t) + 5.0
    fig = plot_simulation(y, y - 0.1, sampling_time=4.0, unit="V", label="BLA")
    output_ax, error_ax = fig.axes
    assert [line.get_label() for line in output_ax.get_lines()] == ["measured",
                                                                    "BLA (simulated)"]
    np.testing.assert_allclose(error_ax.get_lines()[-1].get_ydata(), 0.1)
    np.testing.assert_allclose(output_ax.get_lines()[0].get_xdata()[-1], 4.0 * 299)
    assert _legend_texts(error_ax) == ["RMS error 0.1 V"]
    assert output_ax.get_ylabel() == "Output (V)"
    assert error_ax.get_ylabel() == "Error (V)"
    # One time axis: labelled on the bottom panel only.
    assert output_ax.get_xlabel() == ""
    assert error_ax.get_xlabel() == "Time (s)"
    for ax in fig.axes:
        _assert_legend_outside(ax)
    _assert_png(fig, tmp_path / "simulation.png")


def test_plot_simulation_one_panel_pair_per_model():
    y = np.column_stack([np.zeros(50), 1.0 + np.sin(0.3 * np.arange(50))])
    models = {"A": y * 0.5, "B": y * 2.0, "C": y + 0.2}
    fig = plot_simulation(y, models, output_index=1)
    axes = fig.axes
    assert len(axes) == 6
    output_axes, error_axes = axes[0::2], axes[1::2]
    for (name, values), output_ax, error_ax in zip(models.items(), output_axes, error_axes,
                                                   strict=True):
        measured, simulated = output_ax.get_lines()
        assert simulated.get_label() == f"{name} (simulated)"
        np.testing.assert_allclose(simulated.get_ydata(), values[:, 1])
        np.testing.assert_allclose(error_ax.get_lines()[-1].get_ydata(),
                                   y[:, 1] - values[:, 1])
        # Panel k and its error share the colour of model k.
        assert simulated.get_color() == error_ax.get_lines()[-1].get_color()
    # One time axis for all panels, one vertical scale per kind of panel.
    assert all(axes[0].get_shared_x_axes().joined(axes[0], ax) for ax in axes)
    assert len({ax.get_ylim() for ax in output_axes}) == 1
    assert len({ax.get_ylim() for ax in error_axes}) == 1
    assert [ax.get_xlabel() for ax in axes] == [""] * 5 + ["Time (samples)"]
    # Panels are stacked top to bottom in the mapping's order.
    tops = [ax.get_position().y1 for ax in axes]
    assert tops == sorted(tops, reverse=True)


def test_plot_simulation_divides_a_given_axes():
    fig, (left, right) = plt.subplots(1, 2, figsize=(10, 6))
    y = np.sin(0.1 * np.arange(100))
    cell = right.get_position()
    assert plot_simulation(y, {"A": 0.9 * y, "B": 1.1 * y}, ax=right) is fig
    right.set_title("Test record")
    panels = fig.axes[1:]
    assert panels[0] is right and len(panels) == 4
    assert left.get_lines() == []
    for ax in panels:
        box = ax.get_position()
        assert cell.x0 - 1e-9 <= box.x0 and box.x1 <= cell.x1 + 1e-9
        assert cell.y0 - 1e-9 <= box.y0 and box.y1 <= cell.y1 + 1e-9
    # The title set on the given Axes heads the column.
    assert right.get_title() == "Test record"
    assert right.get_position().y1 == max(ax.get_position().y1 for ax in panels)


def test_plot_simulation_uses_a_sequence_of_axes_as_given():
    fig, axes = plt.subplots(2, 2)
    y = np.sin(0.1 * np.arange(100))
    assert plot_simulation(y, {"A": 0.9 * y, "B": 1.1 * y}, ax=axes.T) is fig
    # Column-major order of axes.T: A's output, A's error, B's output, B's error.
    assert axes[0, 0].get_lines()[1].get_label() == "A (simulated)"
    assert axes[1, 0].get_legend() is not None and axes[1, 0].get_xlabel() == "Time (samples)"
    assert axes[0, 1].get_lines()[1].get_label() == "B (simulated)"
    with pytest.raises(ValueError, match=r"needs 2 \* 2 = 4"):
        plot_simulation(y, {"A": y, "B": y}, ax=axes[0])
    with pytest.raises(ValueError, match="each element of ax"):
        plot_simulation(y, y, ax=[axes[0, 0], "error"])


def test_plot_simulation_needs_an_axes_of_a_grid():
    fig = plt.figure()
    free = fig.add_axes((0.1, 0.1, 0.8, 0.8))
    with pytest.raises(ValueError, match="grid of subplots"):
        plot_simulation(np.zeros(10), np.zeros(10), ax=free)


@pytest.mark.parametrize(
    "y_true, y_pred, message",
    [
        (np.zeros(10), np.zeros(9), r"y_pred has 9 samples, y_true has 10"),
        (np.zeros(10), {"B": np.zeros(11)}, r"y_pred\['B'\] has 11 samples"),
        (np.array([]), np.array([]), "y_true is empty"),
        (np.zeros(10), {}, "empty mapping"),
        (np.zeros((10, 2, 2)), np.zeros(10), "y_true must be 1-D or 2-D"),
        (np.zeros(10), {"B": np.r_[np.zeros(9), np.nan]}, r"y_pred\['B'\] has 1 non-finite"),
        (np.r_[np.zeros(9), np.inf], np.zeros(10), "y_true has 1 non-finite"),
        (np.zeros(10), ["a"] * 10, "y_pred must be an array of numbers"),
    ],
)
def test_plot_simulation_rejects_invalid_signals(y_true, y_pred, message):
    with pytest.raises(ValueError, match=message):
        plot_simulation(y_true, y_pred)


def test_plot_simulation_rejects_invalid_options():
    y = np.zeros((10, 2))
    with pytest.raises(ValueError, match="sampling_time"):
        plot_simulation(y[:, 0], y[:, 0], sampling_time=0.0)
    with pytest.raises(ValueError, match="out of range for y_true"):
        plot_simulation(y, y, output_index=2)
    with pytest.raises(ValueError, match="output_index must be 0"):
        plot_simulation(y[:, 0], y[:, 0], output_index=1)


def test_plot_simulation_keeps_the_measurement_visible_when_a_model_drifts():
    y = 5.0 + np.sin(0.1 * np.arange(100))
    drifting = y.copy()
    drifting[60:] = np.logspace(2, 9, 40)
    fig = plot_simulation(y, {"stable": y + 0.1, "drifting": drifting})
    output_ax, error_ax = fig.axes[:2]
    # The view is cut at the top of the measured range (4 to 6 V) widened by
    # half of it, plus a 5% pad; nothing is cut below.
    pad = 0.05 * (7.0 - y.min())
    np.testing.assert_allclose(output_ax.get_ylim(), (y.min() - pad, 7.0 + pad), atol=1e-3)
    # Errors are shown up to plus or minus the measured span, plus the pad.
    span = np.ptp(y)
    np.testing.assert_allclose(error_ax.get_ylim(), (-1.1 * span, 1.1 * span))
    fig = plot_simulation(y, y + 0.1)
    assert fig.axes[0].get_ylim()[1] < 6.5


def test_plot_error_spectrum_levels(tmp_path):
    rng = np.random.default_rng(0)
    n = 4096
    y = 3.0 + np.sin(2 * np.pi * 64 / n * np.arange(n))
    error = 0.01 * rng.standard_normal(n)
    fig = plot_error_spectrum(y, y - error, noise_level=0.01, sampling_time=4.0, unit="V")
    (ax,) = fig.axes
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
    _assert_legend_outside(ax)
    _assert_png(fig, tmp_path / "spectrum.png")


def test_plot_error_spectrum_array_level_and_errors():
    y = np.sin(0.2 * np.arange(64))
    fig = plot_error_spectrum(y, {"A": y * 0.9, "B": y * 0.8}, noise_level=np.full(32, 1e-3))
    assert len(fig.axes[0].get_lines()) == 4
    with pytest.raises(ValueError, match="noise_level must be a float or have shape"):
        plot_error_spectrum(y, y, noise_level=np.ones(5))
    with pytest.raises(ValueError, match="noise_level must be positive"):
        plot_error_spectrum(y, y, noise_level=0.0)
    with pytest.raises(ValueError, match="noise_level must be a float or an array of floats"):
        plot_error_spectrum(y, y, noise_level=True)
    with pytest.raises(ValueError, match=r"y_pred has 64 non-finite"):
        plot_error_spectrum(y, np.full(64, np.nan))
    with pytest.raises(ValueError, match="at least 2 samples"):
        plot_error_spectrum(y[:1], y[:1])


def test_missing_matplotlib_names_the_plot_extra(monkeypatch):
    # A None entry in sys.modules makes the import fail as if not installed.
    monkeypatch.setitem(sys.modules, "matplotlib.pyplot", None)
    with pytest.raises(ImportError, match=r"sknlss\[plot\]"):
        plot_simulation(np.zeros(10), np.zeros(10))
