"""Simulated positioning drive with friction, measured in closed loop."""

from numbers import Real

import numpy as np
from numba import njit
from sklearn.utils import Bunch, check_random_state
from sklearn.utils._param_validation import Interval, validate_params

from .._core._kernels import CACHE
from ._synthetic import (AT_LEAST_ONE, INIT_WINDOW, POSITIVE, RECORD_CONSTRAINTS,
                         band_fraction, gaussian_noise, ramp)

# Plant: moving mass (kg), viscous friction (N s/m), Coulomb and static
# friction (N), Stribeck velocity (m/s) and the velocity (m/s) below which the
# friction's sign is smoothed.
_PLANT = np.array([5.0, 20.0, 8.0, 12.0, 0.01, 1e-4])
_MASS, _VISCOUS = _PLANT[0], _PLANT[1]

# PID tuned on the friction-free plant for a closed-loop natural frequency of
# 10 Hz and damping ratio 0.7; integral corner at a fifth of it; derivative on
# the measurement through a first-order filter with a 100 Hz corner.
_OMEGA = 2.0 * np.pi * 10.0
_GAINS = np.array([
    _MASS * _OMEGA**2,                      # K_p (N/m)
    _MASS * _OMEGA**3 / 5.0,                # K_i (N/(m s))
    2.0 * 0.7 * _OMEGA * _MASS - _VISCOUS,  # K_d (N s/m)
    1.0 / (2.0 * np.pi * 100.0),            # derivative filter time constant (s)
])

# Hz, band of the reference's random motion: up to half the loop's 10 Hz
# bandwidth, as drives are excited to identify their dynamics (a slower
# reference is tracked almost exactly and shows little of them).
_MOTION_BAND = (0.0, 5.0)
_DRIFT_PERIOD = 20.0        # s, period of the reference's slow drift
_PRE_ROLL = 1000            # samples simulated before each record and dropped

# Longest sampling time (s): the controller is tuned for a 10 Hz closed loop,
# which the sampled PID keeps stable with a wide margin up to 5 ms (the loop's
# spectral radius is 0.91 there; it reaches 1 near 12 ms).
_MAX_SAMPLING_TIME = 5e-3
# Longest Runge-Kutta step (s): the smoothed friction's slope at zero velocity,
# F_s / (v_e m) = 24000 1/s, must stay well inside the method's stability region.
_MAX_STEP = 5e-5

_DESCR = """\
Simulated positioning drive with friction, measured in closed loop
------------------------------------------------------------------

Plant (a carriage on a guide driven by a linear motor): m p'' = F - F_f(p'),
with the friction F_f(v) = (F_c + (F_s - F_c) exp(-(v / v_s)^2)) tanh(v / v_e)
+ b v (Coulomb, static with Stribeck decay, and viscous friction):
m = 5 kg, b = 20 N s/m, F_c = 8 N, F_s = 12 N, v_s = 0.01 m/s; the sign of the
velocity is smoothed below v_e = 1e-4 m/s. The position p integrates the
velocity: the plant holds an integrator.

Controller (sampled, output held over each sample): PID on the error
r - y, with the derivative acting on the measurement y through a first-order
filter,
    F[t] = K_p (r[t] - y[t]) + K_i T_s sum_{j<=t} (r[j] - y[j]) + D[t],
    D[t] = a D[t-1] - (1 - a) K_d (y[t] - y[t-1]) / T_s,  a = T_f / (T_f + T_s),
with K_p = m w^2 = 19739 N/m, K_i = m w^3 / 5 = 248050 N/(m s),
K_d = 2 * 0.7 * w m - b = 419.8 N s/m (w = 2 pi 10 Hz: a closed-loop natural
frequency of 10 Hz with damping ratio 0.7 for the friction-free plant) and
T_f = 1 / (2 pi 100 Hz). The closed loop is stable.

Integration: fixed-step fourth-order Runge-Kutta with n_substeps steps per
sample; sampling time 1 ms by default.

Data, as a drive is logged in closed loop: X = the position reference r (m),
y = the measured position p + e (m); u_plant_est and u_plant_test hold the
controller's force F (N). The measurement noise e (white Gaussian, standard
deviation noise_std, encoder-like) is fed back through the controller, as in a
real drive.
Reference: band-limited Gaussian random motion from 0 to 5 Hz of RMS
reference_rms (2 mm by default) plus a slow drift (a sine of period 20 s,
amplitude 2 reference_rms, random phase). Each record starts mid-motion: the
loop is simulated for 1000 samples before it and they are dropped.
Test reference: over the last quarter of the record the random motion's
amplitude ramps up linearly to 1.5 times the estimation level, and a smooth
move (half a cosine) carries the reference to a quarter of the estimation
range beyond the largest estimation position: the test leaves the estimation
amplitude at its end.
The first init_window = 50 test samples may be used to set the initial state.
"""


@njit(cache=CACHE)
def _acceleration(v, force, plant):
    mass, viscous, coulomb, static, stribeck, smoothing = (
        plant[0], plant[1], plant[2], plant[3], plant[4], plant[5])
    friction = ((coulomb + (static - coulomb) * np.exp(-(v / stribeck) ** 2))
                * np.tanh(v / smoothing) + viscous * v)
    return (force - friction) / mass


@njit(cache=CACHE)
def _simulate_loop(reference, noise, plant, gains, sampling_time, n_substeps):
    """Measured positions and controller forces of the closed loop.

    The carriage starts at rest at the first reference value.
    """
    kp, ki, kd, tf = gains[0], gains[1], gains[2], gains[3]
    n = reference.shape[0]
    measured = np.empty(n)
    forces = np.empty(n)
    position = reference[0]
    velocity = 0.0
    integral = 0.0
    derivative = 0.0
    previous = reference[0]
    a = tf / (tf + sampling_time)
    h = sampling_time / n_substeps
    for t in range(n):
        y = position + noise[t]
        error = reference[t] - y
        integral += sampling_time * error
        derivative = a * derivative - (1.0 - a) * kd * (y - previous) / sampling_time
        previous = y
        force = kp * error + ki * integral + derivative
        measured[t] = y
        forces[t] = force
        for _ in range(n_substeps):
            a1 = _acceleration(velocity, force, plant)
            a2 = _acceleration(velocity + 0.5 * h * a1, force, plant)
            a3 = _acceleration(velocity + 0.5 * h * a2, force, plant)
            a4 = _acceleration(velocity + h * a3, force, plant)
            # The position's slopes are the velocities at the four stages.
            position += h / 6.0 * (6.0 * velocity + h * (a1 + a2 + a3))
            velocity += h / 6.0 * (a1 + 2.0 * a2 + 2.0 * a3 + a4)
    return measured, forces


def _reference(n_samples, sampling_time, motion_gain, reference_rms, rng):
    band = band_fraction(_MOTION_BAND, sampling_time)
    time = np.arange(n_samples) * sampling_time
    drift = 2.0 * reference_rms * np.sin(2.0 * np.pi * time / _DRIFT_PERIOD
                                         + rng.uniform(0.0, 2.0 * np.pi))
    return gaussian_noise(n_samples, band, reference_rms, rng) * motion_gain + drift


def _record(reference, noise_std, sampling_time, n_substeps, rng):
    noise = noise_std * rng.standard_normal(reference.shape)
    y, force = _simulate_loop(reference, noise, _PLANT, _GAINS, float(sampling_time),
                              int(n_substeps))
    return reference[_PRE_ROLL:].reshape(-1, 1), y[_PRE_ROLL:], force[_PRE_ROLL:]


@validate_params(
    {**RECORD_CONSTRAINTS, "reference_rms": [POSITIVE], "n_substeps": [AT_LEAST_ONE],
     "sampling_time": [Interval(Real, 0, _MAX_SAMPLING_TIME, closed="right")]},
    prefer_skip_nested_validation=True,
)
def make_closed_loop_drive(n_samples=6000, n_test_samples=3000, *, reference_rms=0.002,
                           noise_std=1e-6, sampling_time=1e-3, n_substeps=40,
                           random_state=None):
    """Simulate a positioning drive with friction under PID control, in closed loop.

    A 5 kg carriage with Coulomb, Stribeck and viscous friction (an integrating
    plant) is positioned by a sampled PID controller; as positioning drives are
    logged, the input ``X`` is the position reference and the output ``y`` the
    measured position. The reference is band-limited random motion (0 to
    5 Hz, half the loop's bandwidth) on a slow drift; each record starts
    mid-motion. Over the last
    quarter of the test record the motion ramps up to 1.5 times the
    estimation amplitude and a final move carries the reference beyond the
    estimation positions. The friction makes the closed loop nonlinear
    (stick-slip at velocity reversals); the equations and values are in
    ``DESCR``.

    Parameters
    ----------
    n_samples : int, default=6000
        Samples of the estimation record, at least 128.
    n_test_samples : int, default=3000
        Samples of the test record, at least 128.
    reference_rms : float, default=0.002
        RMS value (m) of the reference's random motion in the estimation
        record; the drift's amplitude is twice it.
    noise_std : float, default=1e-6
        Standard deviation (m) of the white Gaussian position measurement
        noise, which the controller feeds back.
    sampling_time : float, default=1e-3
        Sampling time of the controller and of the data, in seconds, at most
        5 ms (the controller is tuned for a 10 Hz closed loop).
    n_substeps : int, default=40
        Runge-Kutta steps per sampling interval; the steps may not be longer
        than 5e-5 s, so ``n_substeps >= sampling_time / 5e-5``.
    random_state : int, RandomState instance or None, default=None
        Seed of the references and of the noise.

    Returns
    -------
    data : :class:`~sklearn.utils.Bunch`
        Dictionary-like object with the attributes:

        X_est : ndarray of shape (n_samples, 1)
            Estimation position reference (m).
        y_est : ndarray of shape (n_samples,)
            Estimation measured position (m).
        X_test : ndarray of shape (n_test_samples, 1)
            Test position reference (m).
        y_test : ndarray of shape (n_test_samples,)
            Test measured position (m).
        u_plant_est : ndarray of shape (n_samples,)
            Controller force (N) during the estimation record.
        u_plant_test : ndarray of shape (n_test_samples,)
            Controller force (N) during the test record.
        sampling_time : float
            Sampling time in seconds.
        noise_std : float
            Standard deviation of the position measurement noise (m).
        init_window : int
            Samples at the start of the test record that may be used to set
            the initial state (50).
        excited_band : tuple of float
            Lower and upper edge (Hz) of the reference's random motion, (0, 5);
            the drift lies below it.
        DESCR : str
            Equations, parameter values, references and noise.

    See Also
    --------
    make_bouc_wen : An open-loop mechanical system with hysteresis.

    Examples
    --------
    >>> from sknlss.datasets import make_closed_loop_drive
    >>> data = make_closed_loop_drive(random_state=0)
    >>> data.X_est.shape, data.y_est.shape, data.u_plant_test.shape
    ((6000, 1), (6000,), (3000,))
    """
    if sampling_time / n_substeps > _MAX_STEP * (1.0 + 1e-9):
        raise ValueError(
            f"n_substeps={n_substeps} is too few for sampling_time={sampling_time!r}: "
            f"the friction's steep slope at zero velocity needs Runge-Kutta steps of at "
            f"most {_MAX_STEP:g} s, so n_substeps >= "
            f"{int(np.ceil(sampling_time / _MAX_STEP - 1e-9))}."
        )
    rng = check_random_state(random_state)
    n_est_total = _PRE_ROLL + n_samples
    n_test_total = _PRE_ROLL + n_test_samples
    n_end = n_test_samples // 4
    r_est = _reference(n_est_total, sampling_time, 1.0, reference_rms, rng)
    r_test = _reference(n_test_total, sampling_time,
                        ramp(n_test_total, n_test_total - n_end, 1.0, 1.5),
                        reference_rms, rng)
    # A final smooth move carries the test reference to a quarter of the
    # estimation range beyond the estimation record's largest position.
    positions = r_est[_PRE_ROLL:]
    travel = max(positions.max() + 0.25 * np.ptp(positions) - r_test[-1], 0.0)
    r_test[-n_end:] += travel * 0.5 * (1.0 - np.cos(np.linspace(0.0, np.pi, n_end)))
    X_est, y_est, force_est = _record(r_est, noise_std, sampling_time, n_substeps, rng)
    X_test, y_test, force_test = _record(r_test, noise_std, sampling_time, n_substeps,
                                         rng)
    return Bunch(
        X_est=X_est, y_est=y_est, X_test=X_test, y_test=y_test,
        u_plant_est=force_est, u_plant_test=force_test,
        sampling_time=float(sampling_time), noise_std=float(noise_std),
        init_window=INIT_WINDOW, excited_band=_MOTION_BAND, DESCR=_DESCR,
    )
