"""Simulated Wiener-Hammerstein system: filter, saturation, filter."""

import numpy as np
from scipy import signal
from sklearn.utils import Bunch, check_random_state
from sklearn.utils._param_validation import validate_params

from ._synthetic import (INIT_WINDOW, POSITIVE, PRE_ROLL, RECORD_CONSTRAINTS,
                         gaussian_noise, measure, ramp, random_multisine)

# Excited band as fractions of the sampling frequency, like the Wiener-Hammerstein
# benchmark's 10 kHz at 51.2 kHz.
_BAND = (0.0, 0.2)

_DESCR = """\
Simulated Wiener-Hammerstein system
-----------------------------------

Discrete time, like the electronic circuit of the Wiener-Hammerstein benchmark
(Schoukens, Suykens, Ljung, SYSID 2009): a linear filter G1, a static
nonlinearity f, a linear filter G2,

    x = G1(q) u,   w = f(x) = tanh(x),   y = G2(q) w + e.

- G1: third-order Chebyshev type I low-pass, 0.5 dB pass-band ripple, edge at
  0.125 of the sampling frequency (scipy.signal.cheby1(3, 0.5, 0.25)); poles of
  radius 0.59 and 0.80, unit static gain.
- f: a soft saturation at +-1. An amplifier or actuator that saturates between
  two dynamic stages is the commonest nonlinearity of this structure; it is
  odd, so its distortions fall on the odd DFT lines an odd multisine leaves
  unexcited, and bounded, so inputs beyond the estimation amplitude drive it
  deeper into saturation than anything seen during estimation.
- G2: third-order Chebyshev type II (inverse Chebyshev) low-pass, 40 dB
  stop-band attenuation from 0.2 of the sampling frequency
  (scipy.signal.cheby2(3, 40, 0.4)); poles of radius 0.59 and 0.80,
  transmission zeros in the stop band.

Sampling: 51.2 kHz by default (the benchmark's); the system is discrete, so
sampling_time only sets the time and frequency units.
Estimation input: one period of an odd random-phase multisine flat on the odd
DFT lines from 0 to 0.2 of the sampling frequency, RMS input_rms, in periodic
steady state (the period before it is simulated and dropped). With the default
RMS 0.5 the saturation's input x has an RMS of about 0.42 and peaks near 1.5.
Test input: band-limited Gaussian noise in the same band and at the same RMS
whose amplitude ramps up linearly over the last quarter of the record to 1.5
times the estimation level, beyond the estimation amplitude. The record starts
mid-motion (256 samples simulated before it are dropped).
Noise: white Gaussian output noise e of standard deviation noise_std.
The first init_window = 50 test samples may be used to set the initial state.
"""


def _filters():
    return signal.cheby1(3, 0.5, 0.25), signal.cheby2(3, 40, 0.4)


def _simulate(u, n_drop, noise_std, rng):
    """Filter from rest, drop the first ``n_drop`` samples, add the output noise."""
    (b1, a1), (b2, a2) = _filters()
    y = signal.lfilter(b2, a2, np.tanh(signal.lfilter(b1, a1, u)))[n_drop:]
    return u[n_drop:].reshape(-1, 1), measure(y, noise_std, rng)


@validate_params({**RECORD_CONSTRAINTS, "input_rms": [POSITIVE]},
                 prefer_skip_nested_validation=True)
def make_wiener_hammerstein(n_samples=4096, n_test_samples=2048, *, input_rms=0.5,
                            noise_std=2e-3, sampling_time=1.0 / 51200.0,
                            random_state=None):
    """Simulate a Wiener-Hammerstein system: filter, soft saturation, filter.

    ``y = G2(q) tanh(G1(q) u) + e`` in discrete time, with G1 a third-order
    Chebyshev type I low-pass and G2 a third-order inverse Chebyshev low-pass
    (see ``DESCR``), like the electronic Wiener-Hammerstein benchmark circuit.
    The estimation input is one period of an odd random-phase multisine up to
    0.2 of the sampling frequency, in steady state; the test input is
    band-limited Gaussian noise in the same band whose amplitude ramps up to
    1.5 times the estimation level over the last quarter of the record. With
    the defaults a linear model leaves an error of about 8 % of the output RMS,
    ten times the noise.

    Parameters
    ----------
    n_samples : int, default=4096
        Samples of the estimation record (one multisine period), at least 128.
    n_test_samples : int, default=2048
        Samples of the test record, at least 128.
    input_rms : float, default=0.5
        RMS value of the estimation input.
    noise_std : float, default=2e-3
        Standard deviation of the white Gaussian output noise.
    sampling_time : float, default=1 / 51200
        Sampling time in seconds.
    random_state : int, RandomState instance or None, default=None
        Seed of the inputs and of the noise.

    Returns
    -------
    data : :class:`~sklearn.utils.Bunch`
        Dictionary-like object with the attributes:

        X_est : ndarray of shape (n_samples, 1)
            Estimation input.
        y_est : ndarray of shape (n_samples,)
            Estimation output, with noise.
        X_test : ndarray of shape (n_test_samples, 1)
            Test input.
        y_test : ndarray of shape (n_test_samples,)
            Test output, with noise.
        sampling_time : float
            Sampling time in seconds.
        noise_std : float
            Standard deviation of the output noise.
        init_window : int
            Samples at the start of the test record that may be used to set
            the initial state (50).
        excited_band : tuple of float
            Lower and upper edge (Hz) of the inputs' band, ``(0, 0.2 /
            sampling_time)``.
        DESCR : str
            Equations, parameter values, inputs and noise.

    See Also
    --------
    make_duffing : An oscillator with a cubic stiffness.

    Examples
    --------
    >>> from sknlss.datasets import make_wiener_hammerstein
    >>> data = make_wiener_hammerstein(random_state=0)
    >>> data.X_est.shape, data.y_test.shape, data.excited_band
    ((4096, 1), (2048,), (0.0, 10240.0))
    """
    rng = check_random_state(random_state)
    # The first of two periods brings the filters to their periodic steady state.
    u_est = random_multisine(n_samples, _BAND, input_rms, rng, n_periods=2)
    n_total = PRE_ROLL + n_test_samples
    u_test = gaussian_noise(n_total, _BAND, input_rms, rng) * ramp(
        n_total, n_total - n_test_samples // 4, 1.0, 1.5)
    X_est, y_est = _simulate(u_est, n_samples, noise_std, rng)
    X_test, y_test = _simulate(u_test, PRE_ROLL, noise_std, rng)
    return Bunch(
        X_est=X_est, y_est=y_est, X_test=X_test, y_test=y_test,
        sampling_time=float(sampling_time), noise_std=float(noise_std),
        init_window=INIT_WINDOW,
        excited_band=(_BAND[0] / sampling_time, _BAND[1] / sampling_time),
        DESCR=_DESCR,
    )
