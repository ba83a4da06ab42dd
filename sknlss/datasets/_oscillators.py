"""Simulated nonlinear oscillators: a Duffing oscillator and the Bouc-Wen benchmark.

Both are the single-degree-of-freedom oscillator

    m y'' + d y' + k y + k3 y^3 + z = u,
    z' = alpha y' - beta (gamma |y'| |z|^(nu - 1) z + delta y' |z|^nu),

a Duffing oscillator when ``alpha = 0`` (z stays 0) and the Bouc-Wen
oscillator when ``k3 = 0``. One compiled kernel integrates it.
"""

import numpy as np
from numba import njit
from sklearn.utils import Bunch, check_random_state
from sklearn.utils._param_validation import validate_params

from .._core._kernels import CACHE
from ._synthetic import (AT_LEAST_ONE, INIT_WINDOW, POSITIVE, PRE_ROLL, RECORD_CONSTRAINTS,
                         band_fraction, gaussian_noise, measure, ramp, random_multisine)

# Order of the entries of the parameter vector of the compiled kernel.
_M, _D, _K, _K3, _ALPHA, _BETA, _GAMMA, _DELTA, _NU = range(9)

_GENERATOR_CONSTRAINTS = {
    **RECORD_CONSTRAINTS,
    "input_rms": [POSITIVE],
    "n_substeps": [AT_LEAST_ONE],
}


@njit(cache=CACHE)
def _slopes(y, v, z, u, p):
    abs_z = abs(z)
    accel = (u - p[_D] * v - p[_K] * y - p[_K3] * y**3 - z) / p[_M]
    dz = p[_ALPHA] * v - p[_BETA] * (p[_GAMMA] * abs(v) * abs_z ** (p[_NU] - 1.0) * z
                                     + p[_DELTA] * v * abs_z ** p[_NU])
    return v, accel, dz


@njit(cache=CACHE)
def _simulate_oscillator(u, params, sampling_time, n_substeps):
    """Displacement at the sampling instants, from rest, input held over each sample.

    Fixed-step fourth-order Runge-Kutta with ``n_substeps`` steps per sample.
    """
    n = u.shape[0]
    out = np.empty(n)
    h = sampling_time / n_substeps
    y = v = z = 0.0
    for t in range(n):
        out[t] = y
        for _ in range(n_substeps):
            y1, v1, z1 = _slopes(y, v, z, u[t], params)
            y2, v2, z2 = _slopes(y + 0.5 * h * y1, v + 0.5 * h * v1, z + 0.5 * h * z1,
                                 u[t], params)
            y3, v3, z3 = _slopes(y + 0.5 * h * y2, v + 0.5 * h * v2, z + 0.5 * h * z2,
                                 u[t], params)
            y4, v4, z4 = _slopes(y + h * y3, v + h * v3, z + h * z3, u[t], params)
            y += h / 6.0 * (y1 + 2.0 * y2 + 2.0 * y3 + y4)
            v += h / 6.0 * (v1 + 2.0 * v2 + 2.0 * v3 + v4)
            z += h / 6.0 * (z1 + 2.0 * z2 + 2.0 * z3 + z4)
    return out


def _oscillator_record(params, u, n_drop, sampling_time, n_substeps, noise_std, rng,
                       input_rms):
    """Simulate from rest, drop the first ``n_drop`` samples, add the output noise.

    A ValueError when the integration overflows: a fixed step that suits the
    oscillator at the documented amplitudes is unstable for the stiffness a
    much larger input makes the cubic or hysteretic term reach.
    """
    y = _simulate_oscillator(np.ascontiguousarray(u), params, float(sampling_time),
                             int(n_substeps))
    if not np.all(np.isfinite(y)):
        raise ValueError(
            f"The oscillator's simulation overflows at input_rms={input_rms!r}: its "
            f"fixed-step integration (n_substeps={n_substeps!r} per sample) is unstable at "
            "that amplitude. Lower input_rms or raise n_substeps.")
    return u[n_drop:].reshape(-1, 1), measure(y[n_drop:], noise_std, rng)


# ------------------------------------------------------------------ Duffing
_DUFFING_F0 = 60.0          # Hz, natural frequency of the linear part
_DUFFING_ZETA = 0.05        # damping ratio of the linear part
_DUFFING_K3 = 10.0          # 1/V^2, cubic stiffness relative to the linear one
_DUFFING_BAND = (0.0, 200.0)  # Hz, excited band of both inputs


def _duffing_parameters():
    omega = 2.0 * np.pi * _DUFFING_F0
    return np.array([1.0 / omega**2, 2.0 * _DUFFING_ZETA / omega, 1.0, _DUFFING_K3,
                     0.0, 0.0, 0.0, 0.0, 1.0])


_DUFFING_DESCR = """\
Simulated Duffing oscillator (Silverbox-like)
---------------------------------------------

m y'' + d y' + k y + k3 y^3 = u, written with unit static gain as an electronic
implementation (u and y in volts, like the Silverbox benchmark): k = 1,
m = 1 / (2 pi 60 Hz)^2 = 7.036e-6 s^2, d = 2 * 0.05 / (2 pi 60 Hz) = 2.653e-4 s
(natural frequency 60 Hz, damping ratio 0.05), k3 = 10 V^-2 (hardening: at
y = 0.1 V the cubic term adds 10 % to the stiffness).

Integration: fixed-step fourth-order Runge-Kutta with n_substeps steps per
sample, input held (zero-order hold) over each sample; y is sampled at the
sampling instants, the default sampling frequency being the Silverbox's
(10^7 / 2^14 = 610.35 Hz).

Estimation input: one period of an odd random-phase multisine (flat on the odd
DFT lines from 0 to 200 Hz), RMS input_rms, in periodic steady state (the
period before it is simulated and dropped).
Test input: band-limited Gaussian noise (flat from 0 to 200 Hz) whose RMS grows
linearly, like the Silverbox "arrow", from 0.25 * input_rms at the start of the
record to 1.5 * input_rms at its end: it passes the estimation amplitude at 60 %
of the record and then extrapolates. The record starts mid-motion (256 samples
simulated before it are dropped).
Noise: white Gaussian output noise of standard deviation noise_std (V).
The first init_window = 50 test samples may be used to set the initial state.
"""


@validate_params(_GENERATOR_CONSTRAINTS, prefer_skip_nested_validation=True)
def make_duffing(n_samples=4096, n_test_samples=2048, *, input_rms=0.02, noise_std=5e-4,
                 sampling_time=2.0**14 / 1e7, n_substeps=20, random_state=None):
    """Simulate a Duffing oscillator like the Silverbox electronic circuit.

    The system ``m y'' + d y' + k y + k3 y^3 = u`` has unit static gain, a
    natural frequency of 60 Hz, a damping ratio of 0.05 and a hardening cubic
    stiffness ``k3 = 10 V^-2`` (see ``DESCR`` for the values of m and d). It is
    integrated by fourth-order Runge-Kutta at ``n_substeps`` steps per sample
    with the input held over each sample. The estimation input is one period
    of an odd random-phase multisine (0 to 200 Hz) in steady state; the test
    input is band-limited Gaussian noise in the same band whose amplitude grows
    linearly from a quarter of the estimation RMS to 1.5 times it, like the
    Silverbox "arrow". With the defaults the BLA (two states) leaves an error
    of about 16 % of the output RMS on the estimation record (14 to 21 % over
    random states 0 to 7), more than ten times the noise.

    Parameters
    ----------
    n_samples : int, default=4096
        Samples of the estimation record (one multisine period), at least 128.
    n_test_samples : int, default=2048
        Samples of the test record, at least 128.
    input_rms : float, default=0.02
        RMS value (V) of the estimation input.
    noise_std : float, default=5e-4
        Standard deviation (V) of the white Gaussian output noise.
    sampling_time : float, default=2**14 / 1e7
        Sampling time in seconds (the Silverbox's, 610.35 Hz); the 200 Hz band
        must lie below 90 % of the Nyquist frequency.
    n_substeps : int, default=20
        Runge-Kutta steps per sampling interval.
    random_state : int, RandomState instance or None, default=None
        Seed of the inputs and of the noise.

    Returns
    -------
    data : :class:`~sklearn.utils.Bunch`
        Dictionary-like object with the attributes:

        X_est : ndarray of shape (n_samples, 1)
            Estimation input (V).
        y_est : ndarray of shape (n_samples,)
            Estimation output (V), with noise.
        X_test : ndarray of shape (n_test_samples, 1)
            Test input (V).
        y_test : ndarray of shape (n_test_samples,)
            Test output (V), with noise.
        sampling_time : float
            Sampling time in seconds.
        noise_std : float
            Standard deviation of the output noise (V).
        init_window : int
            Samples at the start of the test record that may be used to set
            the initial state (50).
        excited_band : tuple of float
            Lower and upper edge (Hz) of the inputs' band, (0, 200).
        DESCR : str
            Equations, parameter values, inputs and noise.

    See Also
    --------
    fetch_silverbox : The measured Silverbox benchmark.
    make_bouc_wen : A hysteretic oscillator.

    Examples
    --------
    >>> from sknlss.datasets import make_duffing
    >>> data = make_duffing(random_state=0)
    >>> data.X_est.shape, data.y_est.shape, data.X_test.shape
    ((4096, 1), (4096,), (2048, 1))
    >>> data.sampling_time, data.init_window
    (0.0016384, 50)
    """
    rng = check_random_state(random_state)
    band = band_fraction(_DUFFING_BAND, sampling_time)
    params = _duffing_parameters()
    # The first of two periods brings the oscillator to its periodic steady state.
    u_est = random_multisine(n_samples, band, input_rms, rng, n_periods=2)
    n_total = PRE_ROLL + n_test_samples
    u_test = gaussian_noise(n_total, band, input_rms, rng) * ramp(
        n_total, PRE_ROLL, 0.25, 1.5)
    X_est, y_est = _oscillator_record(params, u_est, n_samples, sampling_time,
                                      n_substeps, noise_std, rng, input_rms)
    X_test, y_test = _oscillator_record(params, u_test, PRE_ROLL, sampling_time,
                                        n_substeps, noise_std, rng, input_rms)
    return Bunch(
        X_est=X_est, y_est=y_est, X_test=X_test, y_test=y_test,
        sampling_time=float(sampling_time), noise_std=float(noise_std),
        init_window=INIT_WINDOW, excited_band=_DUFFING_BAND, DESCR=_DUFFING_DESCR,
    )


# ----------------------------------------------------------------- Bouc-Wen
# Noel and Schoukens, "Hysteretic benchmark with a dynamic nonlinearity" (2016).
_BOUC_WEN_PARAMETERS = np.array([
    2.0,     # m_L (kg)
    10.0,    # c_L (N s/m)
    5e4,     # k_L (N/m)
    0.0,     # no cubic stiffness
    5e4,     # alpha (N/m)
    1e3,     # beta (1/m)
    0.8,     # gamma
    -1.1,    # delta
    1.0,     # nu
])
_BOUC_WEN_BAND = (5.0, 150.0)  # Hz, the benchmark's multisine band

_BOUC_WEN_DESCR = """\
Simulated Bouc-Wen hysteretic oscillator (Noel and Schoukens benchmark)
-----------------------------------------------------------------------

m_L y'' + c_L y' + k_L y + z(y, y') = u,
z' = alpha y' - beta (gamma |y'| |z|^(nu - 1) z + delta y' |z|^nu),
with the benchmark's values m_L = 2 kg, c_L = 10 N s/m, k_L = 5e4 N/m,
alpha = 5e4 N/m, beta = 1e3 1/m, gamma = 0.8, delta = -1.1, nu = 1. The input u
is a force (N), the output y the displacement (m). J.P. Noel and M. Schoukens,
"Hysteretic benchmark with a dynamic nonlinearity", Workshop on Nonlinear
System Identification Benchmarks, 2016; data: 4TU.ResearchData,
doi:10.4121/12967592.

Integration: fixed-step fourth-order Runge-Kutta with n_substeps steps per
sample (default 20, the benchmark's integration rate of 15 kHz), input held
over each sample; y is sampled at the benchmark's 750 Hz without a decimation
filter.

Estimation input: one period of a random-phase multisine flat on every DFT line
from 5 to 150 Hz (the benchmark's band), RMS input_rms (50 N, the benchmark's
level), in periodic steady state (the period before it is simulated and
dropped).
Test input: a new random-phase multisine realisation in the same band and at the
same RMS whose amplitude ramps up linearly over the last quarter of the record
to 1.5 times the estimation level, beyond the estimation amplitude. The record
starts mid-motion (256 samples simulated before it are dropped).
Noise: white Gaussian output noise of standard deviation noise_std (m), about
1.5 % of the output RMS by default.
The first init_window = 50 test samples may be used to set the initial state.
"""


@validate_params(_GENERATOR_CONSTRAINTS, prefer_skip_nested_validation=True)
def make_bouc_wen(n_samples=4096, n_test_samples=2048, *, input_rms=50.0, noise_std=1e-5,
                  sampling_time=1.0 / 750.0, n_substeps=20, random_state=None):
    """Simulate the Bouc-Wen hysteretic oscillator of the Noël-Schoukens benchmark.

    ``m_L y'' + c_L y' + k_L y + z = u`` with the hysteretic force
    ``z' = alpha y' - beta (gamma |y'| |z|^(nu-1) z + delta y' |z|^nu)`` and the
    benchmark's values (m_L = 2 kg, c_L = 10 N s/m, k_L = alpha = 5e4 N/m,
    beta = 1e3 1/m, gamma = 0.8, delta = -1.1, nu = 1), sampled at 750 Hz. The
    estimation input is one period of a random-phase multisine from 5 to
    150 Hz at 50 N RMS, in steady state; the test input is a new realisation
    whose amplitude ramps up to 1.5 times the estimation level over the last
    quarter of the record.

    Parameters
    ----------
    n_samples : int, default=4096
        Samples of the estimation record (one multisine period), at least 128.
    n_test_samples : int, default=2048
        Samples of the test record, at least 128.
    input_rms : float, default=50.0
        RMS value (N) of the estimation input.
    noise_std : float, default=1e-5
        Standard deviation (m) of the white Gaussian output noise.
    sampling_time : float, default=1 / 750
        Sampling time in seconds; the 150 Hz band must lie below 90 % of the
        Nyquist frequency.
    n_substeps : int, default=20
        Runge-Kutta steps per sampling interval.
    random_state : int, RandomState instance or None, default=None
        Seed of the inputs and of the noise.

    Returns
    -------
    data : :class:`~sklearn.utils.Bunch`
        Dictionary-like object with the attributes:

        X_est : ndarray of shape (n_samples, 1)
            Estimation input (force, N).
        y_est : ndarray of shape (n_samples,)
            Estimation output (displacement, m), with noise.
        X_test : ndarray of shape (n_test_samples, 1)
            Test input (N).
        y_test : ndarray of shape (n_test_samples,)
            Test output (m), with noise.
        sampling_time : float
            Sampling time in seconds.
        noise_std : float
            Standard deviation of the output noise (m).
        init_window : int
            Samples at the start of the test record that may be used to set
            the initial state (50).
        excited_band : tuple of float
            Lower and upper edge (Hz) of the inputs' band, (5, 150).
        DESCR : str
            Equations, parameter values, inputs and noise.

    See Also
    --------
    make_duffing : An oscillator with a static (cubic) nonlinearity.

    Examples
    --------
    >>> from sknlss.datasets import make_bouc_wen
    >>> data = make_bouc_wen(random_state=0)
    >>> data.X_est.shape, data.y_test.shape, data.excited_band
    ((4096, 1), (2048,), (5.0, 150.0))
    """
    rng = check_random_state(random_state)
    band = band_fraction(_BOUC_WEN_BAND, sampling_time)
    # The first of two periods brings the oscillator to its periodic steady state.
    u_est = random_multisine(n_samples, band, input_rms, rng, lines="full", n_periods=2)
    n_total = PRE_ROLL + n_test_samples
    u_test = random_multisine(n_total, band, input_rms, rng, lines="full") * ramp(
        n_total, n_total - n_test_samples // 4, 1.0, 1.5)
    X_est, y_est = _oscillator_record(_BOUC_WEN_PARAMETERS, u_est, n_samples,
                                      sampling_time, n_substeps, noise_std, rng, input_rms)
    X_test, y_test = _oscillator_record(_BOUC_WEN_PARAMETERS, u_test, PRE_ROLL,
                                        sampling_time, n_substeps, noise_std, rng, input_rms)
    return Bunch(
        X_est=X_est, y_est=y_est, X_test=X_test, y_test=y_test,
        sampling_time=float(sampling_time), noise_std=float(noise_std),
        init_window=INIT_WINDOW, excited_band=_BOUC_WEN_BAND, DESCR=_BOUC_WEN_DESCR,
    )
