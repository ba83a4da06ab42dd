"""The Silverbox benchmark: loader of the measured data."""

import os

import numpy as np
from scipy.io import loadmat
from sklearn.utils import Bunch
from sklearn.utils._param_validation import validate_params

from ._fetch import RemoteDataset, fetch_file

SILVERBOX = RemoteDataset(
    title="Silverbox",
    subfolder="silverbox",
    files={
        "SNLS80mV.mat": "5c7413a52255af0cb4e2f93fb6903beb92b08965ba1e6ad0a6ffedfed8477ed4",
    },
    # SilverboxFiles.zip as linked from the benchmark's page on
    # nonlinearbenchmark.org (a Google Drive file, 5,793,999 bytes); its
    # SHA-256 as recorded with the SHA-256 of its member SNLS80mV.mat above.
    archive_url=(
        "https://drive.google.com/uc?export=download&id=17iS-6oBUUgrmiAcrZoG9S5sOaljZnDSy"
    ),
    archive_name="SilverboxFiles.zip",
    archive_sha256="2398dda503ac4c30f46c7a1ba09d8a8864d001cc71bbeb59f207a054cc592d8c",
    member="SilverboxFiles/SNLS80mV.mat",
    source="SilverboxFiles.zip, nonlinearbenchmark.org, Silverbox page",
)

# The acquisition runs at 10 MHz / 2^14 = 610.35 Hz.
_SAMPLING_TIME = 2.0**14 / 1e7

# The multisines have a period of 8192 samples: the DFT of each of the ten
# periods in the file (the last 8192 samples of each 8692-sample block) shows
# the 1342 odd lines 1, 3, ..., 2683 excited 30 to 40 dB above all other lines,
# i.e. 0.0745 Hz to 199.9 Hz; the arrow's spectrum is flat up to 190 Hz and
# 11 dB down at 200 Hz.
_PERIOD = 8192
_EXCITED_BAND = (1 / (_PERIOD * _SAMPLING_TIME), 2683 / (_PERIOD * _SAMPLING_TIME))

# nonlinear_benchmarks 1.0.1: the first 50 outputs of each test record may set
# the state; the RMS error is computed on the rest.
_INIT_WINDOW = 50

# Half-open sample ranges of the nonlinear_benchmarks 1.0.1 split.
_ESTIMATION = (40650, 105712)
_TESTS = {
    "multisine": (105712, 127400),
    "arrow": (100, 32100),
    "arrow_full": (100, 40575),
}

_DESCR = """\
Silverbox benchmark (Wigren and Schoukens, 2013)
------------------------------------------------

An electronic circuit implementing a Duffing-like oscillator: a second-order
linear system with a cubic (static) nonlinearity in feedback, like a mass on a
spring with hardening stiffness. The input V1 and the output V2 are voltages
(V), sampled at 10^7 / 2^14 = 610.35 Hz (sampling_time 1.6384 ms). The input
has a DC offset of about 6 mV.

The file SNLS80mV.mat (131,072 samples) holds first the "arrow" (Gaussian noise
low-pass filtered at about 200 Hz whose amplitude grows linearly, to beyond the
amplitude of the estimation data), then ten realisations of an odd
random-phase multisine (period 8192 samples; the odd lines from 0.0745 Hz to
199.9 Hz, excited_band), each preceded by a short gap and transient.

Split (nonlinear_benchmarks 1.0.1; half-open, 0-based sample ranges):

- estimation (X_est, y_est): multisine [40650, 105712), 65,062 samples;
- test "multisine" (X_test, y_test): [105712, 127400), 21,688 samples;
- test "arrow" (no extrapolation): [100, 32100), 32,000 samples;
- test "arrow_full": [100, 40575), 40,475 samples; its end exceeds the
  estimation amplitude (extrapolation).

Protocol: simulate each test record from its start; the first init_window = 50
samples may be used to set the state; report the RMS error over y[50:] in mV
(the values here are in V). Published PNLSS and neural state-space models reach
a few tenths of a mV on the multisine and arrow tests, the best linear
approximation about 7 mV.

Citation: T. Wigren and J. Schoukens, "Three free data sets for development and
benchmarking in nonlinear system identification", European Control Conference,
Zurich, 2013, pp. 2933-2938. Data: SilverboxFiles.zip, nonlinearbenchmark.org.
"""


@validate_params(
    {"data_home": [str, os.PathLike, None], "download_if_missing": ["boolean"]},
    prefer_skip_nested_validation=True,
)
def fetch_silverbox(data_home=None, *, download_if_missing=True):
    """Load the measured Silverbox benchmark records.

    The file ``SNLS80mV.mat`` (from the official ``SilverboxFiles.zip``) is
    looked for in the sub-folder ``silverbox/`` of, or directly in, each of
    these folders in turn: ``data_home``, the folder named by the environment
    variable ``SKNLSS_DATA``, and the user cache folder
    (``$XDG_CACHE_HOME/sknlss``, by default ``~/.cache/sknlss``). Its SHA-256 is
    checked. When no folder holds it and ``download_if_missing`` is True, the
    archive linked from the benchmark's page on nonlinearbenchmark.org is
    downloaded into the cache folder, its SHA-256 checked and ``SNLS80mV.mat``
    extracted from it.

    The records follow the usual split: an estimation record of 65,062
    multisine samples and three test records, ``multisine``, ``arrow`` (no
    extrapolation) and ``arrow_full`` (whose end exceeds the estimation
    amplitude).

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

        X_est : ndarray of shape (65062, 1)
            Estimation input (V).
        y_est : ndarray of shape (65062,)
            Estimation output (V).
        X_test : ndarray of shape (21688, 1)
            Input of the multisine test record (V).
        y_test : ndarray of shape (21688,)
            Output of the multisine test record (V).
        tests : dict of str to Bunch
            The three test records ``"multisine"``, ``"arrow"`` and
            ``"arrow_full"``, in that order, each a Bunch with ``X`` of shape
            (n, 1) and ``y`` of shape (n,) (n = 21688, 32000, 40475).
        sampling_time : float
            2**14 / 1e7 seconds (610.35 Hz).
        init_window : int
            Samples at the start of each test record that may be used to set
            the initial state (50); the RMS error is reported over the rest.
        excited_band : tuple of float
            Lower and upper edge of the multisine's band (Hz): the odd lines 1
            to 2683 of its 8192-sample period, 0.0745 to 199.9 Hz.
        output_unit : str
            Unit of the output, ``"V"`` (the benchmark reports errors in mV).
        filename : str
            The file read.
        DESCR : str
            Description of the benchmark.

    Raises
    ------
    FileNotFoundError
        When the data are absent and cannot be downloaded; the message names
        the file, the folders searched and why the download failed.
    ValueError
        When the file found does not have the official SHA-256.

    See Also
    --------
    make_duffing : Simulated data of a similar oscillator.

    Examples
    --------
    >>> from sknlss.datasets import fetch_silverbox
    >>> data = fetch_silverbox()  # doctest: +SKIP
    >>> data.X_est.shape, list(data.tests)  # doctest: +SKIP
    ((65062, 1), ['multisine', 'arrow', 'arrow_full'])
    """
    path = fetch_file(SILVERBOX, data_home, download_if_missing)
    content = loadmat(path)
    u = np.asarray(content["V1"], dtype=np.float64).ravel()
    y = np.asarray(content["V2"], dtype=np.float64).ravel()
    tests = {name: Bunch(X=u[start:stop].reshape(-1, 1), y=y[start:stop])
             for name, (start, stop) in _TESTS.items()}
    start, stop = _ESTIMATION
    return Bunch(
        X_est=u[start:stop].reshape(-1, 1),
        y_est=y[start:stop],
        X_test=tests["multisine"].X,
        y_test=tests["multisine"].y,
        tests=tests,
        sampling_time=_SAMPLING_TIME,
        init_window=_INIT_WINDOW,
        excited_band=_EXCITED_BAND,
        output_unit="V",
        filename=str(path),
        DESCR=_DESCR,
    )
