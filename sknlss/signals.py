"""Excitation signals for system identification.

A random-phase multisine is periodic, has a user-chosen amplitude spectrum on
a chosen set of DFT lines and zero amplitude elsewhere. Periodicity lets the
frequency-domain methods separate noise from nonlinear distortion; the lines
that are left out (even lines of an odd multisine, the dropped odd lines of a
random-odd one) reveal even and odd nonlinear distortions.
"""

import numpy as np
from sklearn.utils import check_random_state
from sklearn.utils._param_validation import StrOptions, validate_params

from ._core._memory import check_memory
from ._validation import POSITIVE_FINITE, Integers, binary_magnitude, naming

__all__ = ["multisine"]

_LINE_SETS = ("full", "odd", "special_odd", "random_odd")


def _band_lines(n_samples_per_period, band):
    try:
        f_min, f_max = (float(f) for f in band)
    except (TypeError, ValueError):
        raise ValueError(
            f"band must be a pair (f_min, f_max) of frequencies as fractions of "
            f"the sampling frequency, got {band!r}."
        ) from None
    if not (0.0 <= f_min <= f_max <= 0.5):
        raise ValueError(
            f"band must satisfy 0 <= f_min <= f_max <= 0.5 (fractions of the "
            f"sampling frequency), got {band!r}."
        )
    first = max(1, int(np.ceil(f_min * n_samples_per_period - 1e-9)))
    # The Nyquist line of an even period carries a real-valued component only,
    # so a random phase cannot be applied to it: it is never excited.
    last = min(int(np.floor(f_max * n_samples_per_period + 1e-9)),
               (n_samples_per_period - 1) // 2)
    return np.arange(first, last + 1)


def _select_lines(n_samples_per_period, lines, band, group_size, rng):
    if not isinstance(lines, str):
        selected = np.asarray(lines)
        if selected.ndim != 1 or selected.size == 0 or selected.dtype.kind not in "iu":
            raise ValueError(
                "An explicit set of lines must be a non-empty 1-D integer array, "
                f"got {lines!r}."
            )
        selected = selected.astype(np.int64)
        if np.any(np.diff(selected) <= 0):
            # Amplitudes given as an array follow the lines in their order, so a
            # reordered or repeated line would silently move an amplitude.
            raise ValueError(
                f"An explicit set of lines must be strictly increasing, got {lines!r}."
            )
        if selected[0] < 1 or 2 * selected[-1] >= n_samples_per_period:
            raise ValueError(
                f"Excited lines must lie in [1, {(n_samples_per_period - 1) // 2}] "
                f"for a period of {n_samples_per_period} samples (no DC, no "
                f"Nyquist line), got {selected[0]}..{selected[-1]}."
            )
        return selected
    candidates = _band_lines(n_samples_per_period, band)
    if lines == "full":
        selected = candidates
    elif lines == "special_odd":
        # Lines 8k+1 and 8k+3: odd nonlinearities of degree 3 then also fall
        # on the unexcited odd lines 8k+5 and 8k+7.
        selected = candidates[np.isin(candidates % 8, (1, 3))]
    else:
        selected = candidates[candidates % 2 == 1]
        if lines == "random_odd":
            n_groups = len(selected) // group_size
            drop = group_size * np.arange(n_groups) + rng.randint(
                0, group_size, size=n_groups
            )
            selected = np.delete(selected, drop)
    if selected.size == 0:
        raise ValueError(
            f"No line of a {n_samples_per_period}-sample period is excited with "
            f"lines={lines!r} and band={band!r}: widen the band or lengthen the period."
        )
    return selected


def _line_amplitudes(amplitudes, lines, n_samples_per_period):
    if amplitudes is None:
        return np.ones(len(lines))
    with naming("amplitudes"):
        if callable(amplitudes):
            values = np.asarray(amplitudes(lines / n_samples_per_period), dtype=np.float64)
        else:
            values = np.asarray(amplitudes, dtype=np.float64)
    if values.shape != lines.shape:
        raise ValueError(
            f"amplitudes must give one value per excited line ({len(lines)}), got "
            f"shape {values.shape}."
        )
    if not np.all(np.isfinite(values)) or np.any(values < 0) or not np.any(values > 0):
        raise ValueError(
            "amplitudes must be finite, non-negative and not all zero."
        )
    # Only relative amplitudes matter; an exact power-of-two scaling keeps the
    # signal's squares from overflowing (or underflowing) before its RMS is set.
    return values / binary_magnitude(values)


@validate_params(
    {
        "n_samples_per_period": [Integers(3, None, closed="left")],
        "n_periods": [Integers(1, None, closed="left")],
        "n_realizations": [Integers(1, None, closed="left")],
        "lines": [StrOptions(set(_LINE_SETS)), "array-like"],
        "band": ["array-like"],
        "rms": [POSITIVE_FINITE],
        "amplitudes": ["array-like", callable, None],
        "group_size": [Integers(2, None, closed="left")],
        "random_state": ["random_state"],
    },
    prefer_skip_nested_validation=True,
)
def multisine(n_samples_per_period, *, n_periods=1, n_realizations=1, lines="odd",
              band=(0.0, 0.45), rms=1.0, amplitudes=None, group_size=4,
              random_state=None):
    """Random-phase multisine.

    Each realization is ``sum_k A_k cos(2 pi k t / N + phi_k)`` over the excited
    lines ``k``, with independent phases ``phi_k`` uniform in [0, 2 pi), repeated
    over ``n_periods`` periods of ``N = n_samples_per_period`` samples, and
    scaled to the requested RMS value exactly.

    Parameters
    ----------
    n_samples_per_period : int
        Samples per period N (at least 3).
    n_periods : int, default=1
        Number of consecutive periods of each realization.
    n_realizations : int, default=1
        Number of realizations; they share the excited lines and amplitudes
        and differ by their random phases.
    lines : {"odd", "full", "special_odd", "random_odd"} or array-like of int, \
            default="odd"
        Excited DFT lines (line k is the frequency ``k / N`` times the
        sampling frequency). ``"full"``: every line in ``band``; ``"odd"``: the
        odd lines; ``"special_odd"``: the lines ``8m+1`` and ``8m+3``;
        ``"random_odd"``: the odd lines, less one line chosen at random in each
        consecutive group of ``group_size`` odd lines (the detection lines of
        odd nonlinear distortion; a last, incomplete group keeps all its
        lines). An explicit, strictly increasing integer array is used as is
        and ``band`` is then ignored. DC and the Nyquist line are never
        excited.
    band : tuple of float, default=(0.0, 0.45)
        ``(f_min, f_max)``, the excited frequency band as fractions of the
        sampling frequency (0.45 is 90 % of the Nyquist frequency).
    rms : float, default=1.0
        Root-mean-square value of every realization.
    amplitudes : array-like of shape (n_lines,) or callable, default=None
        Relative amplitude of each excited line, or a function mapping the
        frequencies (fractions of the sampling frequency) of the excited lines
        to their relative amplitudes. ``None`` gives a flat spectrum.
    group_size : int, default=4
        Size of the groups of odd lines for ``lines="random_odd"``.
    random_state : int, RandomState instance or None, default=None
        Seed of the phases and of the random-odd line selection.

    Returns
    -------
    u : ndarray of shape (n_realizations, n_periods * n_samples_per_period)
        The signals, one realization per row. ``u.reshape(-1, 1)`` stacks the
        realizations as the rows of an input matrix ``X`` (use
        ``np.repeat(np.arange(n_realizations), u.shape[1])`` as its
        ``sequence_id``).
    lines : ndarray of shape (n_lines,)
        The DFT lines selected or given, in increasing order (a line given a
        zero amplitude stays in it, without being excited).

    See Also
    --------
    sknlss.datasets.make_pnlss_reference : Data of a known PNLSS system
        excited by an odd multisine.

    Examples
    --------
    >>> import numpy as np
    >>> from sknlss.signals import multisine
    >>> u, lines = multisine(64, n_periods=2, lines="odd", band=(0.0, 0.25),
    ...                      rms=0.5, random_state=0)
    >>> u.shape, lines
    ((1, 128), array([ 1,  3,  5,  7,  9, 11, 13, 15]))
    >>> round(float(np.sqrt(np.mean(u ** 2))), 12)
    0.5
    """
    # The signals, and the spectra and the period they are computed from.
    check_memory(8 * n_realizations * n_samples_per_period * (n_periods + 3),
                 f"A multisine of {n_realizations} realization(s) of {n_periods} period(s) "
                 f"of {n_samples_per_period} samples (n_realizations, n_periods, "
                 "n_samples_per_period)")
    rng = check_random_state(random_state)
    n = int(n_samples_per_period)
    excited = _select_lines(n, lines, band, group_size, rng)
    magnitude = _line_amplitudes(amplitudes, excited, n)

    phases = rng.uniform(0.0, 2.0 * np.pi, size=(n_realizations, len(excited)))
    spectrum = np.zeros((n_realizations, n // 2 + 1), dtype=np.complex128)
    spectrum[:, excited] = magnitude * np.exp(1j * phases)
    period = np.fft.irfft(spectrum, n=n, axis=1)
    period *= rms / np.sqrt(np.mean(period**2, axis=1, keepdims=True))
    return np.tile(period, (1, n_periods)), excited
