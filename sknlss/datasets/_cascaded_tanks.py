"""The Cascaded Tanks benchmark: loader of the measured data and a simulator."""

import os
from numbers import Real

import numpy as np
from numba import njit
from scipy.io import loadmat
from sklearn.utils import Bunch, check_random_state
from sklearn.utils._param_validation import Interval, validate_params

from .._core._kernels import CACHE
from .._validation import Integers, naming
from ..signals import multisine
from ._fetch import RemoteDataset, fetch_file

CASCADED_TANKS = RemoteDataset(
    title="Cascaded Tanks",
    subfolder="cascaded_tanks",
    # The publisher's MATLAB file and its full-precision CSV conversion.
    files={
        "dataBenchmark.mat": (
            "cb2f88d4388be4d3f2a24c6402fba804976aac5f2e1f26cda59ea0a38d016eab"
        ),
        "dataBenchmark_from_mat.csv": (
            "87985f32affd221d31e5efdf3a53a8f8dbbba7f070be7a16c7810b616bca97b1"
        ),
    },
    # CascadedTanksFiles.zip on 4TU.ResearchData, DOI 10.4121/12960104 (v1),
    # 7,520,592 bytes; its SHA-256 as recorded next to the publisher's MD5
    # f832776ed1efdca4572338f467b7baec.
    archive_url=(
        "https://data.4tu.nl/file/d4810b78-6cdd-48fe-8950-9bd601e5f47f/"
        "3b697e42-01a4-4979-a370-813a456c36f5"
    ),
    archive_name="CascadedTanksFiles.zip",
    archive_sha256="eb0fa05851e8a7136846c2e3b61fbef87def78d0852c86ab91b02ac5db541b51",
    member="CascadedTanksFiles/dataBenchmark.mat",
    source="CascadedTanksFiles.zip, 4TU.ResearchData, doi:10.4121/12960104",
)

_SAMPLING_TIME = 4.0
# The input is a multisine from 0 to 0.0144 Hz (benchmark description).
_EXCITED_BAND = (0.0, 0.0144)
# nonlinear_benchmarks 1.0.1: the first 50 test outputs may set the state.
_INIT_WINDOW = 50

_DESCR = """\
Cascaded Tanks benchmark (Schoukens, Mattsson, Wigren, Noel, 2016)
------------------------------------------------------------------

Two water tanks in cascade with free outlets, fed by a pump. The input u is the
pump voltage (V); the output y is the water level of the lower tank read by an
uncalibrated capacitive sensor (V). Nonlinearities: square-root outflows,
overflow (hard saturation) of both tanks, with input-dependent process noise
when the upper tank overflows.

- Sampling time 4 s; two records of 1024 samples: estimation (uEst, yEst) and
  test (uVal, yVal).
- Input: low-frequency multisine, 0 to 0.0144 Hz (excited_band), zero-order
  hold; it has no power above 0.0144 Hz.
- The unknown initial state is the same for both records and is not a steady
  state.
- Benchmark rule: estimate on the estimation record only; report the RMS error
  (V) of the simulated output on the test record (all 1024 samples). The
  nonlinear_benchmarks protocol may use the first init_window = 50 test outputs
  to set the state and computes the RMS error on the rest.

Data: 4TU.ResearchData, doi:10.4121/12960104, licence CC BY-SA 4.0.
"""


_SIMULATION_DESCR = """\
Simulated Cascaded Tanks
------------------------

dx1/dt = -k1 sqrt(x1) + k4 u + w1,  dx2/dt = k2 sqrt(x1) - k3 sqrt(x2) + w2,
y = x2 + e, with (k1, k2, k3, k4) = {k}; the tanks overflow at {overflow}
(hard saturation), a part of the upper tank's overflow (with process noise
drawn uniform on [0, 2 x {fraction}] and capped at 1, else {fraction})
falling into the lower one. Process noise: level change of standard deviation
{process} V per sample; measurement noise e: white Gaussian, standard deviation
{measurement} V. Fourth-order Runge-Kutta, {n_substeps} steps per sample,
sampling time {sampling_time} s, zero-order-held input. Both records start
from the levels {x0}. Input: {input}.
The first init_window = 50 test samples may be used to set the initial state.
"""


def _read_records(path):
    """Return uEst, yEst, uVal, yVal as 1-D float64 arrays."""
    if path.suffix == ".mat":
        content = loadmat(path)
        return tuple(
            np.asarray(content[key], dtype=np.float64).ravel()
            for key in ("uEst", "yEst", "uVal", "yVal")
        )
    with open(path, encoding="ascii") as handle:
        header = handle.readline().strip().split(",")
    table = np.loadtxt(path, delimiter=",", skiprows=1, dtype=np.float64)
    return tuple(table[:, header.index(key)] for key in ("uEst", "yEst", "uVal", "yVal"))


@validate_params(
    {"data_home": [str, os.PathLike, None], "download_if_missing": ["boolean"]},
    prefer_skip_nested_validation=True,
)
def fetch_cascaded_tanks(data_home=None, *, download_if_missing=True):
    """Load the measured Cascaded Tanks benchmark records.

    The file ``dataBenchmark.mat`` (the publisher's file) or
    ``dataBenchmark_from_mat.csv`` (its full-precision CSV conversion) is looked
    for in the sub-folder ``cascaded_tanks/`` of, or directly in, each of these
    folders in turn: ``data_home``, the folder named by the environment
    variable ``SKNLSS_DATA``, and the user cache folder
    (``$XDG_CACHE_HOME/sknlss``, by default ``~/.cache/sknlss``). The SHA-256 of
    the file read is checked. When no folder holds the data and
    ``download_if_missing`` is True, the official archive
    ``CascadedTanksFiles.zip`` is downloaded from 4TU.ResearchData
    (doi:10.4121/12960104) into the cache folder, its SHA-256 checked and
    ``dataBenchmark.mat`` extracted from it.

    Parameters
    ----------
    data_home : str or path-like, default=None
        First folder to search.
    download_if_missing : bool, default=True
        Whether to download the official archive when the data are absent.

    Returns
    -------
    data : :class:`~sklearn.utils.Bunch`
        Dictionary-like object with the attributes:

        X_est : ndarray of shape (1024, 1)
            Estimation input (pump voltage, V).
        y_est : ndarray of shape (1024,)
            Estimation output (lower tank level, V).
        X_test : ndarray of shape (1024, 1)
            Test input.
        y_test : ndarray of shape (1024,)
            Test output.
        sampling_time : float
            4.0 seconds.
        init_window : int
            Samples at the start of the test record that may be used to set
            the initial state under the nonlinear_benchmarks protocol (50).
        excited_band : tuple of float
            Lower and upper edge of the input's band, (0.0, 0.0144) Hz.
        output_unit : str
            Unit of the output, ``"V"``.
        filename : str
            The file read.
        DESCR : str
            Description of the benchmark.

    Raises
    ------
    FileNotFoundError
        When the data are absent and cannot be downloaded; the message names
        the accepted files, the folders searched and why the download failed.
    ValueError
        When the file found does not have the official SHA-256.

    See Also
    --------
    load_cascaded_tanks : The same loader under its earlier name.
    make_cascaded_tanks : Simulated data of the same system.

    Examples
    --------
    >>> from sknlss.datasets import fetch_cascaded_tanks
    >>> data = fetch_cascaded_tanks()  # doctest: +SKIP
    >>> data.X_est.shape, data.y_test.shape, data.sampling_time  # doctest: +SKIP
    ((1024, 1), (1024,), 4.0)
    """
    path = fetch_file(CASCADED_TANKS, data_home, download_if_missing)
    u_est, y_est, u_test, y_test = _read_records(path)
    return Bunch(
        X_est=u_est.reshape(-1, 1),
        y_est=y_est,
        X_test=u_test.reshape(-1, 1),
        y_test=y_test,
        sampling_time=_SAMPLING_TIME,
        init_window=_INIT_WINDOW,
        excited_band=_EXCITED_BAND,
        output_unit="V",
        filename=str(path),
        DESCR=_DESCR,
    )


@validate_params(
    {"data_home": [str, os.PathLike, None], "download": ["boolean"]},
    prefer_skip_nested_validation=True,
)
def load_cascaded_tanks(data_home=None, *, download=True):
    """Load the measured Cascaded Tanks benchmark records (alias).

    The same as :func:`fetch_cascaded_tanks`, whose ``download_if_missing``
    is called ``download`` here; kept for code written before the loaders
    took scikit-learn's names.

    Parameters
    ----------
    data_home : str or path-like, default=None
        First folder to search.
    download : bool, default=True
        Whether to download the official archive when the data are absent.

    Returns
    -------
    data : :class:`~sklearn.utils.Bunch`
        The records and benchmark facts; see :func:`fetch_cascaded_tanks`.

    See Also
    --------
    fetch_cascaded_tanks : The loader.

    Examples
    --------
    >>> from sknlss.datasets import load_cascaded_tanks
    >>> data = load_cascaded_tanks()  # doctest: +SKIP
    >>> data.X_est.shape  # doctest: +SKIP
    (1024, 1)
    """
    return fetch_cascaded_tanks(data_home, download_if_missing=download)


@njit(cache=CACHE)
def _tank_slopes(x1, x2, inflow, disturbance, k1, k2, k3):
    q1 = np.sqrt(max(x1, 0.0))
    q2 = np.sqrt(max(x2, 0.0))
    return inflow - k1 * q1, k2 * q1 - k3 * q2 + disturbance


@njit(cache=CACHE)
def _simulate_tanks(u, x0, k, sampling_time, n_substeps, overflow, process, split):
    """Integrate the tanks over zero-order-held inputs with RK4 sub-steps.

    ``process`` (n, 2) is the process noise (level rate, held over a sample);
    ``split[t]`` is the fraction of the upper tank's overflow reaching the
    lower tank during sample t. Returns the levels at the sampling instants.
    """
    n = u.shape[0]
    states = np.empty((n, 2))
    x1 = x0[0]
    x2 = x0[1]
    k1, k2, k3, k4 = k[0], k[1], k[2], k[3]
    h = sampling_time / n_substeps
    for t in range(n):
        states[t, 0] = x1
        states[t, 1] = x2
        inflow = k4 * u[t] + process[t, 0]
        w2 = process[t, 1]
        for _ in range(n_substeps):
            a1, a2 = _tank_slopes(x1, x2, inflow, w2, k1, k2, k3)
            b1, b2 = _tank_slopes(x1 + 0.5 * h * a1, x2 + 0.5 * h * a2, inflow, w2,
                                  k1, k2, k3)
            c1, c2 = _tank_slopes(x1 + 0.5 * h * b1, x2 + 0.5 * h * b2, inflow, w2,
                                  k1, k2, k3)
            d1, d2 = _tank_slopes(x1 + h * c1, x2 + h * c2, inflow, w2, k1, k2, k3)
            x1 += h / 6.0 * (a1 + 2.0 * b1 + 2.0 * c1 + d1)
            x2 += h / 6.0 * (a2 + 2.0 * b2 + 2.0 * c2 + d2)
            if x1 > overflow[0]:
                x2 += split[t] * (x1 - overflow[0])
                x1 = overflow[0]
            x2 = min(x2, overflow[1])
            # A tank cannot hold a negative amount of water.
            x1 = max(x1, 0.0)
            x2 = max(x2, 0.0)
    return states


#: Upper edge of the band of the benchmark's input, in Hz.
_INPUT_BAND = 0.0144


def _benchmark_like_input(n_samples, sampling_time, rng):
    """Low-pass multisine like the benchmark's: 0 to 0.0144 Hz, 2.8 V mean, 1 V RMS.

    As in the measured input, the lowest third of the band has ten times the
    amplitude of the rest. A pump voltage cannot be negative.
    """
    f_max = _INPUT_BAND * sampling_time
    u, _ = multisine(
        n_samples, lines="full", band=(0.0, min(f_max, 0.5)),
        amplitudes=lambda f: np.where(f <= f_max / 3, 1.0, 0.1),
        rms=1.0, random_state=rng,
    )
    return np.maximum(2.8 + u[0], 0.0)


@validate_params(
    {
        "n_samples": [Integers(3, None, closed="left")],
        "input": ["array-like", None],
        "sampling_time": [Interval(Real, 0, np.inf, closed="neither")],
        "process_noise": [Interval(Real, 0, np.inf, closed="left")],
        "measurement_noise": [Interval(Real, 0, np.inf, closed="left")],
        "overflow": ["array-like"],
        "overflow_fraction": [Interval(Real, 0, 1, closed="both")],
        "k": ["array-like"],
        "x0": ["array-like", None],
        "n_substeps": [Integers(1, None, closed="left")],
        "random_state": ["random_state"],
    },
    prefer_skip_nested_validation=True,
)
def make_cascaded_tanks(n_samples=1024, *, input=None, sampling_time=4.0,
                        process_noise=0.01, measurement_noise=0.02,
                        overflow=(10.0, 10.0), overflow_fraction=0.5,
                        k=(0.05, 0.05, 0.05, 0.042), x0=None, n_substeps=4,
                        random_state=None):
    """Simulate the two-tank system of the Cascaded Tanks benchmark.

    The levels follow (paper eq. 1)

        dx1/dt = -k1 sqrt(x1) + k4 u + w1,
        dx2/dt =  k2 sqrt(x1) - k3 sqrt(x2) + w2,
        y = x2 + e,

    with a zero-order-held input, integrated by fixed-step fourth-order
    Runge-Kutta with ``n_substeps`` steps per sample. Both tanks overflow: a
    level above its ``overflow`` value is cut to it; a random part of the
    upper tank's overflow (uniform between 0 and ``2 * overflow_fraction``,
    capped at 1, drawn for each sample, an input-dependent process noise) falls
    into the lower tank, the rest is lost. Without process noise the part is
    exactly ``overflow_fraction``. The defaults give records that resemble the
    measured benchmark (output mostly between about 2.5 and 10 V, with dips
    to about 1 V, and some overflow).

    An estimation and a test record are simulated from the same initial
    state, as in the real benchmark.

    Parameters
    ----------
    n_samples : int, default=1024
        Samples per record.
    input : tuple of two array-like of shape (n_samples,), default=None
        Input of the estimation and of the test record (pump voltage, V).
        ``None`` draws two realizations of a benchmark-like low-pass multisine
        (0 to 0.0144 Hz, mean 2.8 V, RMS 1 V about the mean, negative values
        clipped to 0).
    sampling_time : float, default=4.0
        Sampling time in seconds.
    process_noise : float, default=0.01
        Standard deviation of the level change (V) that the white process
        noise w1, w2 causes over one sample; it also makes the overflow split
        random.
    measurement_noise : float, default=0.02
        Standard deviation of the white measurement noise e (V).
    overflow : tuple of two float, default=(10.0, 10.0)
        Overflow levels of the upper and lower tank (hard saturation).
    overflow_fraction : float, default=0.5
        Fraction of the upper tank's overflow that reaches the lower tank:
        with process noise, the centre of its uniform draw on
        ``[0, 2 * overflow_fraction]`` capped at 1 (its mean for values up to
        0.5).
    k : tuple of four float, default=(0.05, 0.05, 0.05, 0.042)
        The constants k1, k2, k3, k4.
    x0 : array-like of shape (2,), default=None
        Initial levels of both records; ``None`` gives (5, 5), not a steady
        state.
    n_substeps : int, default=4
        Runge-Kutta steps per sampling interval.
    random_state : int, RandomState instance or None, default=None
        Seed of the input and of the noise.

    Returns
    -------
    data : :class:`~sklearn.utils.Bunch`
        Dictionary-like object with the attributes:

        X_est, X_test : ndarray of shape (n_samples, 1)
            Inputs of the estimation and test records.
        y_est, y_test : ndarray of shape (n_samples,)
            Measured (noisy) outputs.
        states_est, states_test : ndarray of shape (n_samples, 2)
            True levels (x1, x2) at the sampling instants.
        sampling_time : float
            Sampling time in seconds.
        noise_std : float
            Standard deviation of the measurement noise, ``measurement_noise``.
        init_window : int
            Samples at the start of the test record that may be used to set
            the initial state, as in the benchmark (50).
        DESCR : str
            Equations and the parameter values used.

    See Also
    --------
    fetch_cascaded_tanks : The measured benchmark data.

    Examples
    --------
    >>> from sknlss.datasets import make_cascaded_tanks
    >>> data = make_cascaded_tanks(random_state=0)
    >>> data.X_est.shape, data.y_test.shape, data.states_est.shape
    ((1024, 1), (1024,), (1024, 2))
    >>> bool(data.y_est.max() <= 10.1)
    True
    """
    with naming("overflow"):
        overflow = np.asarray(overflow, dtype=np.float64)
    with naming("k"):
        constants = np.asarray(k, dtype=np.float64)
    if overflow.shape != (2,) or np.any(overflow <= 0) or np.any(np.isnan(overflow)):
        raise ValueError(f"overflow must be two positive levels, got {overflow!r}.")
    if constants.shape != (4,) or not np.all(np.isfinite(constants)) or np.any(constants <= 0):
        raise ValueError(f"k must be four positive finite constants, got {k!r}.")
    with naming("x0"):
        x0 = np.array([5.0, 5.0]) if x0 is None else np.asarray(x0, dtype=np.float64)
    if x0.shape != (2,) or not np.all(np.isfinite(x0)) or np.any(x0 < 0):
        raise ValueError(f"x0 must hold two non-negative finite levels, got {x0!r}.")

    rng = check_random_state(random_state)
    if input is None:
        # The lowest frequency of the record, 1 / (n_samples * sampling_time),
        # must lie in the input band.
        if min(_INPUT_BAND * sampling_time, 0.5) * n_samples < 1:
            raise ValueError(
                f"n_samples={n_samples} samples at sampling_time={sampling_time} s are too "
                f"short a record for the benchmark's input band (0 to {_INPUT_BAND} Hz): "
                f"it needs at least {1 / _INPUT_BAND:.0f} s, or an explicit input."
            )
        inputs = [_benchmark_like_input(n_samples, sampling_time, rng) for _ in range(2)]
    else:
        with naming("input"):
            inputs = [np.asarray(u, dtype=np.float64) for u in input]
        if len(inputs) != 2 or any(u.shape != (n_samples,) for u in inputs):
            raise ValueError(
                f"input must be a pair (u_est, u_test) of 1-D arrays of length "
                f"n_samples={n_samples}."
            )
        if not all(np.all(np.isfinite(u)) for u in inputs):
            raise ValueError("input must be finite.")

    records = []
    for u in inputs:
        process = process_noise / sampling_time * rng.standard_normal((n_samples, 2))
        if process_noise > 0:
            split = np.minimum(rng.uniform(0.0, 2.0 * overflow_fraction, n_samples), 1.0)
        else:
            split = np.full(n_samples, float(overflow_fraction))
        states = _simulate_tanks(np.ascontiguousarray(u), x0, constants,
                                 float(sampling_time), int(n_substeps), overflow,
                                 process, split)
        y = states[:, 1] + measurement_noise * rng.standard_normal(n_samples)
        records.append((u.reshape(-1, 1), y, states))
    (X_est, y_est, states_est), (X_test, y_test, states_test) = records
    descr = _SIMULATION_DESCR.format(
        k=constants, overflow=overflow, fraction=overflow_fraction,
        process=process_noise, measurement=measurement_noise, x0=x0,
        sampling_time=sampling_time, n_substeps=n_substeps,
        input="the given arrays" if input is not None else (
            "two realisations of a low-pass multisine like the benchmark's (0 to "
            "0.0144 Hz, mean 2.8 V, RMS 1 V about the mean, the lowest third of the "
            "band ten times stronger, negative values clipped to 0)"),
    )
    return Bunch(
        X_est=X_est, y_est=y_est, X_test=X_test, y_test=y_test,
        states_est=states_est, states_test=states_test,
        sampling_time=float(sampling_time), noise_std=float(measurement_noise),
        init_window=_INIT_WINDOW, DESCR=descr,
    )
