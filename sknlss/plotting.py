"""Figures for identified models: the BLA's FRF, simulations and error spectra.

matplotlib is an optional dependency (``pip install "sknlss[plot]"``); it is
imported when a function of this module is called, not when the module is
imported. Every function draws into the Axes it is given (``ax``), or into a
new figure, and returns the figure it drew into. Legends are placed outside
the data, to the right of the Axes.
"""

from numbers import Real

import numpy as np
from sklearn.utils._param_validation import validate_params

from ._validation import POSITIVE_FINITE, Integers
from .metrics import rms_error

__all__ = ["plot_frf", "plot_simulation", "plot_error_spectrum"]

# Outside the Axes, top-aligned with its right edge: a legend never hides data.
_LEGEND_OUTSIDE = {"loc": "upper left", "bbox_to_anchor": (1.01, 1.0), "borderaxespad": 0.0}


def _pyplot():
    try:
        import matplotlib.pyplot as plt
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ImportError(
            "sknlss.plotting needs matplotlib; install it with "
            "`pip install \"sknlss[plot]\"` (or `pip install matplotlib`)."
        ) from exc
    return plt


def _check_axes(ax, name="ax"):
    """``ax`` itself when it is a matplotlib Axes, else a ValueError naming it."""
    from matplotlib.axes import Axes

    if not isinstance(ax, Axes):
        raise ValueError(f"{name} must be a matplotlib Axes, got {type(ax).__name__}.")
    return ax


def _single_axes(ax):
    """The given Axes, or the Axes of a new figure sized for an outside legend."""
    if ax is None:
        return _pyplot().subplots(figsize=(9.0, 4.0), layout="constrained")[1]
    return _check_axes(ax)


def _frequency_axis(frequencies, sampling_time):
    """Frequencies in Hz when the sampling time is known, else in cycles/sample."""
    if sampling_time is None:
        return frequencies, "Frequency (cycles/sample)"
    return frequencies / sampling_time, "Frequency (Hz)"


def _time_axis(n_samples, sampling_time):
    """Time in seconds when the sampling time is known, else in samples."""
    if sampling_time is None:
        return np.arange(n_samples), "Time (samples)"
    return sampling_time * np.arange(n_samples), "Time (s)"


def _signal(values, output_index, name, non_finite_hint=""):
    """Column ``output_index`` of a non-empty, finite 1-D or 2-D signal, as 1-D floats."""
    try:
        values = np.asarray(values, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be an array of numbers.") from exc
    if values.ndim not in (1, 2):
        raise ValueError(f"{name} must be 1-D or 2-D, got shape {values.shape}.")
    if values.size == 0:
        raise ValueError(f"{name} is empty (shape {values.shape}); it needs samples to draw.")
    if values.ndim == 1:
        if output_index != 0:
            raise ValueError(
                f"{name} has a single output; output_index must be 0, got {output_index}."
            )
        column = values
    elif not 0 <= output_index < values.shape[1]:
        raise ValueError(
            f"output_index={output_index} is out of range for {name} with "
            f"{values.shape[1]} output(s)."
        )
    else:
        column = values[:, output_index]
    n_bad = np.count_nonzero(~np.isfinite(column))
    if n_bad:
        raise ValueError(
            f"{name} has {n_bad} non-finite value(s) (NaN or infinity) among its "
            f"{column.shape[0]} samples{non_finite_hint}."
        )
    return column


def _measured_and_predictions(y_true, y_pred, output_index, label):
    """Validated measured output and a dict name -> simulated output of the same length."""
    measured = _signal(y_true, output_index, "y_true")
    if isinstance(y_pred, dict):
        if not y_pred:
            raise ValueError("y_pred is an empty mapping; give at least one prediction.")
        named = y_pred
    else:
        named = {label: y_pred}
    predictions = {}
    for name, values in named.items():
        argument = f"y_pred[{name!r}]" if isinstance(y_pred, dict) else "y_pred"
        values = _signal(values, output_index, argument,
                         "; a diverged simulation cannot be drawn, leave that model out")
        if values.shape != measured.shape:
            raise ValueError(
                f"{argument} has {values.shape[0]} samples, y_true has "
                f"{measured.shape[0]}; they must be the same record."
            )
        predictions[str(name)] = values
    return measured, predictions


def _db(values, power=False):
    """Decibels of magnitudes (or of powers when ``power``), with -inf for zeros."""
    with np.errstate(divide="ignore"):
        return (10.0 if power else 20.0) * np.log10(np.abs(values))


def _bla_entry(bla, name, n_freq, output_index, input_index):
    """Entry (output, input) of the attribute ``name`` of shape (n_freq, n_y, n_u).

    None when the attribute is absent or None (a level that was not estimated).
    NaN marks a frequency where the entry was not estimated (an input without
    power of its own there, see :class:`~sknlss.BLAEstimator`); infinity is
    refused.
    """
    values = getattr(bla, name, None)
    if values is None:
        return None
    values = np.asarray(values)
    if values.ndim == 3 and values.shape[0] == n_freq:
        if not (0 <= output_index < values.shape[1] and 0 <= input_index < values.shape[2]):
            raise ValueError(
                f"(output_index, input_index)=({output_index}, {input_index}) is out of "
                f"range for bla.{name} of shape {values.shape}."
            )
        values = values[:, output_index, input_index]
    elif values.shape != (n_freq,):
        raise ValueError(
            f"bla.{name} must have shape (n_freq, n_outputs, n_inputs) or (n_freq,) "
            f"with n_freq={n_freq}, got {values.shape}."
        )
    if np.any(np.isinf(values)):
        raise ValueError(f"bla.{name} has infinite values.")
    return values


_COMMON_CONSTRAINTS = {
    "sampling_time": [POSITIVE_FINITE, None],
    "output_index": [Integers(0, None, closed="left")],
    "ax": "no_validation",  # one Axes or a sequence of them, checked where drawn
}
_SIGNAL_CONSTRAINTS = {
    **_COMMON_CONSTRAINTS,
    "y_true": ["array-like"],
    "y_pred": ["array-like", dict],
    "unit": [str, None],
    "label": [str],
}


@validate_params(
    {**_COMMON_CONSTRAINTS, "bla": "no_validation",  # its fitted attributes are checked
     "input_index": [Integers(0, None, closed="left")]},
    prefer_skip_nested_validation=True,
)
def plot_frf(bla, *, sampling_time=None, output_index=0, input_index=0, ax=None):
    """Plot the Best Linear Approximation with its noise and distortion levels.

    The figure of paper Fig. 2: the magnitude of the nonparametric BLA on the
    excited frequencies, the parametric model's frequency response, the noise
    level (the standard deviation of the FRF due to noise) and the total level
    (noise plus nonlinear distortions). Where the total level lies clearly
    above the noise level, the system behaves nonlinearly at that frequency.
    The legend is drawn to the right of the Axes.

    Parameters
    ----------
    bla : BLAEstimator
        A fitted :class:`~sknlss.BLAEstimator`; it provides ``frequencies_``,
        ``frf_``, ``frf_model_``, ``noise_variance_`` and ``total_variance_``.
        Levels that could not be estimated (None) are not drawn, and a noise
        variance equal to the total variance (the Local Polynomial Method
        cannot separate them) is drawn once, as the total level. Frequencies
        where the entry was not estimated (NaN: an input without power of its
        own there, while others have) are left as gaps.
    sampling_time : float, default=None
        Sampling time in seconds. When given, frequencies are shown in Hz,
        otherwise in cycles per sample.
    output_index : int, default=0
        Output channel of a MIMO model.
    input_index : int, default=0
        Input channel of a MIMO model.
    ax : matplotlib.axes.Axes, default=None
        Axes to draw into; a new figure is created when None.

    Returns
    -------
    fig : matplotlib.figure.Figure
        The figure drawn into (the one holding ``ax`` when given). Its Axes
        show the magnitudes in dB against frequency.

    Raises
    ------
    ValueError
        If ``bla`` is not fitted, its attributes have inconsistent shapes or
        infinite values, an index is out of range, or ``sampling_time`` is
        not positive.

    See Also
    --------
    sknlss.BLAEstimator : The estimator whose attributes are drawn.

    Examples
    --------
    >>> import matplotlib
    >>> matplotlib.use("Agg")
    >>> import numpy as np
    >>> from scipy.signal import lfilter
    >>> from sknlss import BLAEstimator
    >>> from sknlss.plotting import plot_frf
    >>> from sknlss.signals import multisine
    >>> u, lines = multisine(256, n_periods=2, n_realizations=2, random_state=0)
    >>> y = lfilter([0.0, 0.5], [1.0, -1.2, 0.5], u, axis=1)
    >>> y += 0.01 * np.random.default_rng(0).standard_normal(y.shape)
    >>> X, sequence_id = u.reshape(-1, 1), np.repeat([0, 1], u.shape[1])
    >>> bla = BLAEstimator(n_states=2, period=256)
    >>> bla = bla.fit(X, y.ravel(), sequence_id=sequence_id)
    >>> fig = plot_frf(bla, sampling_time=0.01)
    >>> fig.axes[0].get_xlabel()
    'Frequency (Hz)'
    """
    required = ("frequencies_", "frf_", "noise_variance_", "total_variance_")
    missing = [name for name in required if not hasattr(bla, name)]
    if missing:
        hint = (" A nonlinear model's linear start is its bla_: plot_frf(model.bla_)."
                if hasattr(bla, "bla_") else "")
        raise ValueError(
            "plot_frf needs a fitted BLAEstimator as bla; the object passed "
            f"({type(bla).__name__}) has no attribute(s) {', '.join(missing)}.{hint}"
        )
    frequencies = np.asarray(bla.frequencies_, dtype=float)
    if frequencies.ndim != 1 or frequencies.size == 0 or not np.all(np.isfinite(frequencies)):
        raise ValueError(
            "bla.frequencies_ must be a non-empty 1-D array of finite frequencies, got "
            f"shape {frequencies.shape}."
        )
    freq, xlabel = _frequency_axis(frequencies, sampling_time)
    frf, model, noise, total = (
        _bla_entry(bla, name, freq.shape[0], output_index, input_index)
        for name in ("frf_", "frf_model_", "noise_variance_", "total_variance_")
    )
    if frf is None:
        raise ValueError("plot_frf needs a fitted BLAEstimator; bla.frf_ is None.")
    # The LPM cannot separate noise from distortion and reports the same
    # variance twice; drawing it once avoids suggesting a noise floor.
    if noise is not None and total is not None and np.array_equal(noise, total,
                                                                    equal_nan=True):
        noise = None

    ax = _single_axes(ax)
    ax.plot(freq, _db(frf), "k.", markersize=4, label="BLA (nonparametric)")
    if model is not None:
        ax.plot(freq, _db(model), "C0-", label="BLA (parametric model)")
    if total is not None:
        ax.plot(freq, _db(total, power=True), "C1.", markersize=4,
                label="Total distortion (noise + nonlinear)")
    if noise is not None:
        ax.plot(freq, _db(noise, power=True), "C2.", markersize=4, label="Noise level")
    ax.set_xlabel(xlabel)
    ax.set_ylabel("Magnitude (dB)")
    ax.set_title("Best Linear Approximation")
    ax.grid(True, alpha=0.3)
    ax.legend(**_LEGEND_OUTSIDE)
    return ax.figure


def _simulation_panels(ax, n_models):
    """Pairs (output Axes, error Axes) for each model, and whether they are stacked here.

    ``ax`` None or one Axes: its grid cell (a new figure's for None) is divided
    into a column of 2 * n_models rows sharing the time axis, the given Axes
    becoming the first output panel. A sequence of Axes is used as given.
    """
    if ax is None:
        _, ax = _pyplot().subplots(figsize=(9.0, 1.0 + 2.2 * n_models),
                                   layout="constrained")
    if isinstance(ax, (list, tuple, np.ndarray)):
        axes = [_check_axes(item, "each element of ax") for item in np.ravel(ax)]
        if len(axes) != 2 * n_models:
            raise ValueError(
                f"ax holds {len(axes)} Axes; with {n_models} model(s) it needs "
                f"2 * {n_models} = {2 * n_models} (the output, then the error, of each "
                "model), or a single Axes to divide."
            )
        return list(zip(axes[0::2], axes[1::2], strict=True)), False
    ax = _check_axes(ax)
    spec = ax.get_subplotspec()
    if spec is None:
        raise ValueError(
            "ax must belong to a grid of subplots (plt.subplots, Figure.add_subplot) "
            "so that its place can be divided into panels, or be a sequence of "
            "2 * n_models Axes; got an Axes placed by coordinates."
        )
    grid = spec.subgridspec(2 * n_models, 1, height_ratios=(2, 1) * n_models)
    # The caller's Axes stays in the figure as the first panel, so that what the
    # caller does to it afterwards (a title, a log scale) still shows.
    ax.set_subplotspec(grid[0])
    axes = [ax] + [ax.figure.add_subplot(grid[row], sharex=ax)
                   for row in range(1, 2 * n_models)]
    return list(zip(axes[0::2], axes[1::2], strict=True)), True


def _view_limits(values, keep, margin_fraction):
    """Limits showing ``values``, cut at ``keep`` widened by ``margin_fraction`` of its span.

    A simulation that drifts far away would flatten every other curve; the view
    is then limited around the range that matters (the measurement).
    """
    low, high = min(np.min(v) for v in values), max(np.max(v) for v in values)
    span = keep[1] - keep[0]
    margin = margin_fraction * span if span > 0 else 1.0
    low, high = max(low, keep[0] - margin), min(high, keep[1] + margin)
    pad = 0.05 * (high - low) if high > low else 0.5
    return low - pad, high + pad


@validate_params(_SIGNAL_CONSTRAINTS, prefer_skip_nested_validation=True)
def plot_simulation(y_true, y_pred, *, sampling_time=None, output_index=0, unit=None,
                    label="model", ax=None):
    """Plot a measured output with each model's simulated output and error, one panel each.

    The figure of paper Figs. 7-8, one model at a time: for every model, a
    panel with the measured output (black) and the model's free-run
    simulation, and below it a narrower panel with the model's error
    ``y_true - y_pred`` and its RMS value in the legend. All panels share the
    time axis; the output panels share one vertical scale and the error
    panels another, so that the models compare at a glance.

    Parameters
    ----------
    y_true : array-like of shape (n_samples,) or (n_samples, n_outputs)
        Measured output.
    y_pred : array-like of shape (n_samples,) or (n_samples, n_outputs), or dict
        Simulated output, or a mapping from a model name to its simulated
        output to compare several models (one pair of panels each, in the
        mapping's order). Non-finite values (a diverged simulation) are
        rejected: leave such a model out.
    sampling_time : float, default=None
        Sampling time in seconds; the time axis is in seconds when given,
        otherwise in samples.
    output_index : int, default=0
        Output channel to show when the outputs are 2-D.
    unit : str, default=None
        Unit of the output for the axis labels and the RMS errors, e.g.
        ``"V"``.
    label : str, default="model"
        Name of the model in the legend when ``y_pred`` is a single array.
    ax : matplotlib.axes.Axes or sequence of Axes, default=None
        Where to draw:

        - None: a new figure, 2.2 inches high per model;
        - one Axes (of a grid of subplots): its place is divided into a
          column of ``2 * n_models`` panels (output, then error, for each
          model). The given Axes becomes the first output panel, so a title
          set on it afterwards heads the column; size the figure for the
          number of models (about 2 inches per model);
        - a sequence of ``2 * n_models`` Axes: the output, then the error,
          of each model in turn, used as they are (their layout and sharing
          are the caller's).

    Returns
    -------
    fig : matplotlib.figure.Figure
        The figure drawn into (the one holding ``ax`` when given); its Axes
        include the ``2 * n_models`` panels. When a simulation leaves the
        measured range by more than half that range, the output panels are
        limited to it (and the error panels to the measured span), so that a
        drifting model does not flatten the others.

    Raises
    ------
    ValueError
        If a signal is empty, not 1-D or 2-D, has non-finite values, or
        differs in length from ``y_true``; if ``y_pred`` is an empty mapping;
        if ``output_index`` is out of range or ``sampling_time`` not positive;
        or if ``ax`` is not an Axes of a grid or does not hold
        ``2 * n_models`` Axes.

    See Also
    --------
    plot_error_spectrum : The same errors in the frequency domain.

    Examples
    --------
    >>> import matplotlib
    >>> matplotlib.use("Agg")
    >>> import numpy as np
    >>> from sknlss.plotting import plot_simulation
    >>> t = np.arange(200)
    >>> y = np.sin(0.1 * t)
    >>> fig = plot_simulation(y, {"A": 0.9 * y, "B": 1.2 * y}, sampling_time=4.0)
    >>> len(fig.axes)
    4
    >>> fig.axes[1].get_legend().get_texts()[0].get_text()
    'RMS error 0.0699'
    """
    measured, predictions = _measured_and_predictions(y_true, y_pred, output_index, label)
    time, xlabel = _time_axis(measured.shape[0], sampling_time)
    panels, stacked = _simulation_panels(ax, len(predictions))
    errors = {name: measured - values for name, values in predictions.items()}
    in_unit = f" ({unit})" if unit else ""

    output_limits = _view_limits([measured, *predictions.values()],
                                 (measured.min(), measured.max()), 0.5)
    largest_error = max(np.max(np.abs(error)) for error in errors.values())
    span = np.ptp(measured)
    error_limits = _view_limits([np.array([-largest_error, largest_error])],
                                (-span, span), 0.0)
    for k, ((output_ax, error_ax), name) in enumerate(zip(panels, predictions, strict=True)):
        colour = f"C{k}"
        output_ax.plot(time, measured, color="k", linewidth=1.0, label="measured")
        output_ax.plot(time, predictions[name], color=colour, linewidth=1.0,
                       label=f"{name} (simulated)")
        output_ax.set_ylim(output_limits)
        output_ax.set_ylabel(f"Output{in_unit}")
        rms = rms_error(measured, predictions[name])
        error_ax.axhline(0.0, color="0.6", linewidth=0.8)
        error_ax.plot(time, errors[name], color=colour, linewidth=1.0,
                      label=f"RMS error {rms:.3g} {unit or ''}".rstrip())
        error_ax.set_ylim(error_limits)
        error_ax.set_ylabel(f"Error{in_unit}")
        for panel in (output_ax, error_ax):
            panel.grid(True, alpha=0.3)
            panel.legend(**_LEGEND_OUTSIDE)
    all_panels = [panel for pair in panels for panel in pair]
    if stacked:
        # One time axis for the column: tick labels and label on the bottom panel only.
        for panel in all_panels[:-1]:
            panel.tick_params(labelbottom=False)
        all_panels[-1].set_xlabel(xlabel)
    else:
        for _, error_ax in panels:
            error_ax.set_xlabel(xlabel)
    return panels[0][0].figure


@validate_params(
    {**_SIGNAL_CONSTRAINTS,
     "noise_level": [Real, "array-like", None]},
    prefer_skip_nested_validation=True,
)
def plot_error_spectrum(y_true, y_pred, *, noise_level=None, sampling_time=None,
                        output_index=0, unit=None, label="model", ax=None):
    """Plot the DFT of the measured output and of the model error(s).

    Spectra are ``|fft(v)| / sqrt(n_samples)`` in dB on the positive
    frequencies (bins 1 to ``n_samples // 2``; the DC bin reflects only the
    offsets), so that white noise of standard deviation ``sigma`` lies around
    ``20 log10(sigma)`` dB. A model whose error spectrum reaches the noise
    level explains everything but the noise. The legend is drawn to the right
    of the Axes.

    Parameters
    ----------
    y_true : array-like of shape (n_samples,) or (n_samples, n_outputs)
        Measured output, at least 2 samples.
    y_pred : array-like of shape (n_samples,) or (n_samples, n_outputs), or dict
        Simulated output, or a mapping from a model name to its simulated
        output. Non-finite values (a diverged simulation) are rejected.
    noise_level : float or array-like of shape (n_samples // 2,), default=None
        Noise level to draw: a float is the standard deviation of white output
        noise (in output units), drawn as a horizontal line; an array gives
        the noise spectrum per frequency bin as magnitudes
        ``|DFT| / sqrt(n_samples)`` in output units (not in dB: the plot
        converts it like the spectra). None draws no noise level.
    sampling_time : float, default=None
        Sampling time in seconds; frequencies are in Hz when given, otherwise
        in cycles per sample.
    output_index : int, default=0
        Output channel to show when the outputs are 2-D.
    unit : str, default=None
        Unit of the output for the axis label, e.g. ``"V"``.
    label : str, default="model"
        Name of the model in the legend when ``y_pred`` is a single array.
    ax : matplotlib.axes.Axes, default=None
        Axes to draw into; a new figure is created when None.

    Returns
    -------
    fig : matplotlib.figure.Figure
        The figure drawn into (the one holding ``ax`` when given). Its Axes
        show the spectra in dB against frequency.

    Raises
    ------
    ValueError
        If a signal has fewer than 2 samples, non-finite values or a length
        different from ``y_true``; if ``noise_level`` is not positive and
        finite or has the wrong shape; if ``output_index`` is out of range or
        ``sampling_time`` not positive.

    See Also
    --------
    plot_simulation : The same errors in the time domain.

    Examples
    --------
    >>> import matplotlib
    >>> matplotlib.use("Agg")
    >>> import numpy as np
    >>> from sknlss.plotting import plot_error_spectrum
    >>> rng = np.random.default_rng(0)
    >>> y = np.sin(0.3 * np.arange(256))
    >>> fig = plot_error_spectrum(y, y + 0.01 * rng.standard_normal(256), noise_level=0.01)
    >>> [line.get_label() for line in fig.axes[0].get_lines()]
    ['measured output', 'model error', 'noise level']
    """
    measured, predictions = _measured_and_predictions(y_true, y_pred, output_index, label)
    n_samples = measured.shape[0]
    if n_samples < 2:
        raise ValueError(f"y_true needs at least 2 samples for a spectrum, got {n_samples}.")
    freq, xlabel = _frequency_axis(np.fft.rfftfreq(n_samples)[1:], sampling_time)
    level = None
    if noise_level is not None:
        if np.asarray(noise_level).dtype == bool:
            raise ValueError(f"noise_level must be a float or an array of floats, got "
                             f"{noise_level!r}.")
        level = np.asarray(noise_level, dtype=float)
        if level.shape not in ((), freq.shape):
            raise ValueError(
                f"noise_level must be a float or have shape {freq.shape}, got {level.shape}."
            )
        if not (np.all(np.isfinite(level)) and np.all(level > 0)):
            raise ValueError("noise_level must be positive and finite.")

    def spectrum(values):
        return _db(np.fft.rfft(values)[1:] / np.sqrt(n_samples))

    ax = _single_axes(ax)
    ax.plot(freq, spectrum(measured), "k.", markersize=3, label="measured output")
    for k, (name, values) in enumerate(predictions.items()):
        ax.plot(freq, spectrum(measured - values), f"C{k}.", markersize=3,
                label=f"{name} error")
    if level is not None and level.ndim == 0:
        ax.axhline(_db(level), color="0.4", linestyle="--", label="noise level")
    elif level is not None:
        ax.plot(freq, _db(level), "--", color="0.4", label="noise level")
    ax.set_xlabel(xlabel)
    ax.set_ylabel(f"Amplitude (dB re 1 {unit})" if unit else "Amplitude (dB)")
    ax.grid(True, alpha=0.3)
    ax.legend(**_LEGEND_OUTSIDE)
    return ax.figure
