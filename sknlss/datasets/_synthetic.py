"""Pieces shared by the simulated systems: inputs, envelopes, noise, band checks."""

from numbers import Real

import numpy as np
from sklearn.utils._param_validation import Interval

from .._validation import Integers
from ..signals import multisine

#: Samples at the start of every simulated test record that may be used to
#: set the initial state, as in the measured benchmarks.
INIT_WINDOW = 50

#: Samples simulated before each test record and dropped, so that the record
#: starts mid-motion.
PRE_ROLL = 256

#: Parameter constraints common to the generators.
RECORD_CONSTRAINTS = {
    "n_samples": [Integers(128, None, closed="left")],
    "n_test_samples": [Integers(128, None, closed="left")],
    "noise_std": [Interval(Real, 0, np.inf, closed="left")],
    "sampling_time": [Interval(Real, 0, np.inf, closed="neither")],
    "random_state": ["random_state"],
}
POSITIVE = Interval(Real, 0, np.inf, closed="neither")
AT_LEAST_ONE = Integers(1, None, closed="left")


def band_fraction(band_hz, sampling_time):
    """The band ``(f_min, f_max)`` in Hz as fractions of the sampling frequency.

    Raises ValueError, naming ``sampling_time``, when the band does not fit
    below 90 % of the Nyquist frequency (0.45 of the sampling frequency).
    """
    low, high = (f * sampling_time for f in band_hz)
    if high > 0.45:
        raise ValueError(
            f"sampling_time={sampling_time!r} is too long for the input band "
            f"{band_hz[0]:g}-{band_hz[1]:g} Hz: it must be at most "
            f"{0.45 / band_hz[1]:.6g} s so that the band lies below 90 % of the "
            "Nyquist frequency."
        )
    return low, high


def random_multisine(n_samples, band, rms, rng, *, lines="odd", n_periods=1):
    """``n_periods`` periods of a random-phase multisine of period ``n_samples``, 1-D."""
    u, _ = multisine(n_samples, n_periods=n_periods, lines=lines, band=band, rms=rms,
                     random_state=rng)
    return u[0]


def gaussian_noise(n_samples, band, rms, rng):
    """Band-limited Gaussian noise: flat spectrum on ``band``, zero elsewhere.

    A random-phase multisine whose line amplitudes are Rayleigh distributed is
    Gaussian noise; over ``n_samples`` it is not periodic in any shorter span.
    """
    u, _ = multisine(n_samples, lines="full", band=band, rms=rms,
                     amplitudes=lambda f: rng.rayleigh(size=f.shape), random_state=rng)
    return u[0]


def ramp(n_samples, ramp_start, initial_gain, final_gain):
    """Envelope: ``initial_gain`` up to sample ``ramp_start``, then linear to ``final_gain``."""
    gain = np.full(n_samples, float(initial_gain))
    gain[ramp_start:] = np.linspace(initial_gain, final_gain, n_samples - ramp_start)
    return gain


def measure(y, noise_std, rng):
    """``y`` plus white Gaussian noise of standard deviation ``noise_std``.

    The noise is always drawn, so that the same ``random_state`` gives the same
    inputs and the same noise-free outputs whatever ``noise_std`` is.
    """
    return y + noise_std * rng.standard_normal(y.shape)
