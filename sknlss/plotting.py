"""Figures for identified models: the BLA's FRF, simulations and error spectra.

matplotlib is an optional dependency (``pip install "sknlss[plot]"``); it is
imported when a function of this module is called, not when the module is
imported. Every function draws into the Axes it is given, or into a new figure,
and returns that Axes.
"""

import numpy as np

__all__ = ["plot_frf", "plot_simulation", "plot_error_spectrum"]


def _pyplot():
    try:
        import matplotlib.pyplot as plt
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ImportError(
            "sknlss.plotting needs matplotlib; install it with "
            "`pip install \"sknlss[plot]\"` (or `pip install matplotlib`)."
        ) from exc
    return plt


def _new_axes(ax):
    if ax is None:
        _, ax = _pyplot().subplots(figsize=(7.0, 4.0), layout="constrained")
    return ax


def _frequency_axis(frequencies, sampling_time):
    """Frequencies in Hz when the sampling time is known, else in cycles/sample."""
    if sampling_time is None:
        return np.asarray(frequencies, dtype=float), "Frequency (cycles/sample)"
    if not sampling_time > 0:
        raise ValueError(f"sampling_time must be positive, got {sampling_time}.")
    return np.asarray(frequencies, dtype=float) / sampling_time, "Frequency (Hz)"


def _select_channel(values, output_index, name):
    """Column ``output_index`` of a 1-D or 2-D signal, as a 1-D float array."""
    values = np.asarray(values, dtype=float)
    if values.ndim == 1:
        if output_index != 0:
            raise ValueError(
                f"{name} has a single output; output_index must be 0, got {output_index}."
            )
        return values
    if values.ndim != 2:
        raise ValueError(f"{name} must be 1-D or 2-D, got shape {values.shape}.")
    if not 0 <= output_index < values.shape[1]:
        raise ValueError(
            f"output_index={output_index} is out of range for {name} with "
            f"{values.shape[1]} output(s)."
        )
    return values[:, output_index]


def _as_predictions(y_pred, label):
    """Normalise ``y_pred`` (one array, or a mapping label -> array) to a dict."""
    if isinstance(y_pred, dict):
        if not y_pred:
            raise ValueError("y_pred is an empty mapping; give at least one prediction.")
        return dict(y_pred)
    return {label: y_pred}


def _db(values, power=False):
    """Decibels of magnitudes (or of powers when ``power``), with -inf for zeros."""
    with np.errstate(divide="ignore"):
        return (10.0 if power else 20.0) * np.log10(np.abs(values))


def _bla_entry(values, n_freq, output_index, input_index, name):
    """Entry (output, input) of an FRF-like array of shape (n_freq, n_y, n_u) or (n_freq,)."""
    values = np.asarray(values)
    if values.ndim == 1:
        return values
    if values.ndim != 3 or values.shape[0] != n_freq:
        raise ValueError(
            f"{name} must have shape (n_freq, n_outputs, n_inputs) with n_freq={n_freq}, "
            f"got {values.shape}."
        )
    if not (0 <= output_index < values.shape[1] and 0 <= input_index < values.shape[2]):
        raise ValueError(
            f"(output_index, input_index)=({output_index}, {input_index}) is out of range "
            f"for {name} of shape {values.shape}."
        )
    return values[:, output_index, input_index]


def plot_frf(bla, *, sampling_time=None, output_index=0, input_index=0, ax=None):
    """Plot the Best Linear Approximation with its noise and distortion levels.

    The figure of paper Fig. 2: the magnitude of the nonparametric BLA on the
    excited frequencies, the parametric model's frequency response, the noise
    level (the standard deviation of the FRF due to noise) and the total level
    (noise plus nonlinear distortions). Where the total level lies clearly
    above the noise level, the system behaves nonlinearly at that frequency.

    Parameters
    ----------
    bla : BLAEstimator
        A fitted :class:`~sknlss.BLAEstimator`; it provides ``frequencies_``,
        ``frf_``, ``frf_model_``, ``noise_variance_`` and ``total_variance_``.
        Levels that could not be estimated (None) are not drawn, and a noise
        variance equal to the total variance (the Local Polynomial Method
        cannot separate them) is drawn once, as the total level.
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
    ax : matplotlib.axes.Axes
        The Axes with the magnitudes in dB against frequency.

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
    >>> bla = BLAEstimator(n_states=2, period=256).fit(X, y.ravel(), sequence_id=sequence_id)
    >>> ax = plot_frf(bla, sampling_time=0.01)
    >>> ax.get_xlabel()
    'Frequency (Hz)'
    """
    required = ("frequencies_", "frf_", "noise_variance_", "total_variance_")
    missing = [name for name in required if not hasattr(bla, name)]
    if missing:
        raise ValueError(
            "plot_frf needs a fitted BLAEstimator; the object has no attribute(s) "
            f"{', '.join(missing)}."
        )
    freq, xlabel = _frequency_axis(bla.frequencies_, sampling_time)
    n_freq = freq.shape[0]

    def entry(name):
        values = getattr(bla, name, None)
        if values is None:
            return None
        return _bla_entry(values, n_freq, output_index, input_index, name)

    frf, model = entry("frf_"), entry("frf_model_")
    noise, total = entry("noise_variance_"), entry("total_variance_")
    # The LPM cannot separate noise from distortion and reports the same
    # variance twice; drawing it once avoids suggesting a noise floor.
    if noise is not None and total is not None and np.array_equal(noise, total):
        noise = None

    ax = _new_axes(ax)
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
    ax.legend(loc="best")
    return ax


def plot_simulation(y_true, y_pred, *, sampling_time=None, output_index=0, unit=None,
                    label="model", ax=None):
    """Plot a measured output, the simulated output(s) and the model error(s) in time.

    The figure of paper Figs. 7-8: the measured output in black, each model's
    free-run simulation, and each model's error ``y_true - y_pred``.

    Parameters
    ----------
    y_true : array-like of shape (n_samples,) or (n_samples, n_outputs)
        Measured output.
    y_pred : array-like of shape (n_samples,) or (n_samples, n_outputs), or dict
        Simulated output, or a mapping from a model name to its simulated
        output to compare several models.
    sampling_time : float, default=None
        Sampling time in seconds; the time axis is in seconds when given,
        otherwise in samples.
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
    ax : matplotlib.axes.Axes
        The Axes with one line for the measurement and two (output and
        error) per model. When a simulation leaves the range of the
        measurement (and zero) by more than half that range, the vertical
        axis is limited to it, so that a diverging model does not hide the
        others.

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
    >>> ax = plot_simulation(np.sin(0.1 * t), 0.9 * np.sin(0.1 * t), sampling_time=4.0)
    >>> len(ax.get_lines())
    3
    """
    measured = _select_channel(y_true, output_index, "y_true")
    predictions = {
        name: _select_channel(values, output_index, f"y_pred[{name!r}]")
        for name, values in _as_predictions(y_pred, label).items()
    }
    for name, values in predictions.items():
        if values.shape != measured.shape:
            raise ValueError(
                f"y_pred[{name!r}] has {values.shape[0]} samples, y_true has "
                f"{measured.shape[0]}."
            )
    if sampling_time is None:
        time, xlabel = np.arange(measured.shape[0]), "Time (samples)"
    else:
        if not sampling_time > 0:
            raise ValueError(f"sampling_time must be positive, got {sampling_time}.")
        time, xlabel = sampling_time * np.arange(measured.shape[0]), "Time (s)"

    ax = _new_axes(ax)
    ax.plot(time, measured, "k-", linewidth=1.2, label="measured")
    for k, (name, values) in enumerate(predictions.items()):
        ax.plot(time, values, f"C{k}-", linewidth=1.0, label=name)
        ax.plot(time, measured - values, f"C{k}:", linewidth=1.0, label=f"{name} error")
    # A model that drifts far away (or diverges) would flatten the measurement
    # into a line; the view is then limited around the measured range and zero.
    low, high = min(np.nanmin(measured), 0.0), max(np.nanmax(measured), 0.0)
    margin = 0.5 * (high - low) if high > low else 1.0
    with np.errstate(invalid="ignore"):
        drawn = np.concatenate([np.concatenate([v, measured - v]) for v in predictions.values()])
    drawn = drawn[np.isfinite(drawn)]
    if drawn.size and (drawn.min() < low - margin or drawn.max() > high + margin):
        ax.set_ylim(low - margin, high + margin)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(f"Output ({unit})" if unit else "Output")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best")
    return ax


def plot_error_spectrum(y_true, y_pred, *, noise_level=None, sampling_time=None,
                        output_index=0, unit=None, label="model", ax=None):
    """Plot the DFT of the measured output and of the model error(s).

    Spectra are ``|fft(v)| / sqrt(n_samples)`` in dB on the positive
    frequencies (bins 1 to ``n_samples // 2``; the DC bin reflects only the
    offsets), so that white noise of standard deviation ``sigma`` lies around
    ``20 log10(sigma)`` dB. A model whose error spectrum reaches the noise
    level explains everything but the noise.

    Parameters
    ----------
    y_true : array-like of shape (n_samples,) or (n_samples, n_outputs)
        Measured output.
    y_pred : array-like of shape (n_samples,) or (n_samples, n_outputs), or dict
        Simulated output, or a mapping from a model name to its simulated
        output.
    noise_level : float or array-like of shape (n_samples // 2,), default=None
        Noise level to draw: a float is the standard deviation of white output
        noise (in output units), drawn as a horizontal line; an array gives
        the noise spectrum per frequency bin, on the same scale as the plotted
        spectra. None draws no noise level.
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
    ax : matplotlib.axes.Axes
        The Axes with the spectra in dB against frequency.

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
    >>> ax = plot_error_spectrum(y, y + 0.01 * rng.standard_normal(256), noise_level=0.01)
    >>> [line.get_label() for line in ax.get_lines()]
    ['measured output', 'model error', 'noise level']
    """
    measured = _select_channel(y_true, output_index, "y_true")
    predictions = {
        name: _select_channel(values, output_index, f"y_pred[{name!r}]")
        for name, values in _as_predictions(y_pred, label).items()
    }
    n_samples = measured.shape[0]
    for name, values in predictions.items():
        if values.shape != measured.shape:
            raise ValueError(
                f"y_pred[{name!r}] has {values.shape[0]} samples, y_true has {n_samples}."
            )
        if not np.all(np.isfinite(values)):
            raise ValueError(
                f"y_pred[{name!r}] contains non-finite values (a diverged simulation?)."
            )
    freq, xlabel = _frequency_axis(np.fft.rfftfreq(n_samples)[1:], sampling_time)

    def spectrum(values):
        return _db(np.fft.rfft(values)[1:] / np.sqrt(n_samples))

    ax = _new_axes(ax)
    ax.plot(freq, spectrum(measured), "k.", markersize=3, label="measured output")
    for k, (name, values) in enumerate(predictions.items()):
        ax.plot(freq, spectrum(measured - values), f"C{k}.", markersize=3,
                label=f"{name} error")
    if noise_level is not None:
        level = np.asarray(noise_level, dtype=float)
        if level.ndim == 0:
            if not level > 0:
                raise ValueError(f"noise_level must be positive, got {float(level)}.")
            ax.axhline(_db(level), color="0.4", linestyle="--", label="noise level")
        elif level.shape == freq.shape:
            ax.plot(freq, _db(level), "--", color="0.4", label="noise level")
        else:
            raise ValueError(
                f"noise_level must be a float or have shape {freq.shape}, got {level.shape}."
            )
    ax.set_xlabel(xlabel)
    ax.set_ylabel(f"Amplitude (dB re 1 {unit})" if unit else "Amplitude (dB)")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best")
    return ax
