"""Nonparametric estimates of the Best Linear Approximation.

Two estimators of the frequency response function (FRF) and its variance:

- the robust method for periodic excitations (Pintelon & Schoukens, *System
  Identification: A Frequency Domain Approach*, 2nd ed., 2012, ch. 3-4): the
  spectra are averaged over the periods of every realization, one FRF is formed
  per realization (per group of ``n_inputs`` realizations for MIMO), and the
  sample variances over periods and over realizations give the noise variance
  and the total (noise plus nonlinear distortion) variance;
- the Local Polynomial Method (LPM, ibid. ch. 7) for a non-periodic record with
  a transient: around every frequency bin, the FRF and the transient term are
  low-degree polynomials of the bin offset, fitted by least squares over the
  neighbouring bins; the residual gives the variance.

Frequencies are in cycles per sample. Spectra use the DFT scaled by
``1 / sqrt(N)``; the FRF does not depend on the scaling.
"""

from dataclasses import dataclass

import numpy as np

# Relative input power (with respect to the strongest bin) below which a bin
# is considered not excited: periodic multisines leave their unexcited lines
# hundreds of dB down, while every excited line of a practical multisine is
# well within this range.
EXCITATION_THRESHOLD = 1e-8
# For a non-periodic record every bin holds some input power (leakage), so the
# LPM keeps the bins whose window holds at least this fraction of the largest
# window input power (-30 dB): the leakage of a band-limited input lies below,
# while the windows of a broadband random input stay within a few dB.
LPM_POWER_THRESHOLD = 1e-3
# Singular values of an LPM regression below this fraction of the largest are
# discarded, so that a window without input power gives a finite, uninformative
# estimate (with a large variance) rather than a division by zero.
_LPM_RCOND = 1e-10
# Bins whose LPM windows are fitted at once (see ``_lpm_record``).
_LPM_BLOCK = 4096
# Condition number of an input block of the robust method above which its
# inputs are taken as collinear (their FRFs cannot be told apart).
_COLLINEAR_CONDITION = 1e12


@dataclass
class FRFEstimate:
    """Nonparametric FRF with its variances.

    Attributes
    ----------
    frequencies : ndarray of shape (n_freq,)
        Frequencies in cycles per sample, increasing.
    frf : ndarray of shape (n_freq, n_outputs, n_inputs), complex
        Estimated FRF.
    noise_variance : ndarray of shape (n_freq, n_outputs, n_inputs) or None
        Variance of ``frf`` due to the measurement noise (None when it cannot
        be estimated).
    total_variance : ndarray of shape (n_freq, n_outputs, n_inputs) or None
        Variance of ``frf`` due to the noise and the nonlinear distortions
        (None when it cannot be estimated).
    estimated : ndarray of bool of shape (n_freq, n_outputs, n_inputs) or None
        Which entries of ``frf`` are estimated: an input without power of its
        own near a frequency has no FRF there, though others do (several
        inputs of different bands); its entries are zero and not estimated.
        None: every entry.
    total_variance_dof : int or None
        Complex degrees of freedom of ``total_variance`` at each entry: the
        robust method's groups of realizations less one (None for the LPM).
    """

    frequencies: np.ndarray
    frf: np.ndarray
    noise_variance: np.ndarray | None
    total_variance: np.ndarray | None
    estimated: np.ndarray | None = None
    total_variance_dof: int | None = None


def _band_mask(bins, n_dft, max_frequency):
    if max_frequency is None:
        return np.ones(bins.shape, dtype=bool)
    return bins / n_dft <= max_frequency


def _sample_variance(values, axis):
    """Variance of the mean of complex samples along ``axis`` (unbiased)."""
    count = values.shape[axis]
    spread = values - values.mean(axis=axis, keepdims=True)
    return np.sum(np.abs(spread) ** 2, axis=axis) / ((count - 1) * count)


def _block_frf(Y, U):
    """FRF ``Y U^-1`` of square input blocks.

    ``U`` has shape (..., n_inputs, n_inputs) and ``Y`` (..., n_outputs,
    n_inputs), the columns being the experiments of one block.
    """
    # G U = Y  <=>  U^T G^T = Y^T
    if U.shape[-1] > 1 and np.any(np.linalg.cond(U) > _COLLINEAR_CONDITION):
        raise ValueError(
            "The inputs of X are collinear over a group of realizations: the robust "
            "method cannot separate them. Each input needs its own excitation, "
            "different in every realization (e.g. random phases drawn per input and "
            "per realization)."
        )
    return np.swapaxes(np.linalg.solve(np.swapaxes(U, -1, -2), np.swapaxes(Y, -1, -2)),
                       -1, -2)


def robust_frf(U, Y, starts, period, *, n_transient=0, max_frequency=None):
    """Robust-method FRF of periodic records.

    Parameters
    ----------
    U : ndarray of shape (n_samples, n_inputs)
        Input signal.
    Y : ndarray of shape (n_samples, n_outputs)
        Output signal.
    starts : ndarray of shape (n_sequences + 1,)
        Sequence boundaries; every sequence is one realization holding the same
        whole number of periods.
    period : int
        Samples per period.
    n_transient : int, default=0
        The first ``ceil(n_transient / period)`` periods of every sequence are
        dropped (they hold the transient).
    max_frequency : float, default=None
        Highest frequency used, in cycles per sample.

    Returns
    -------
    estimate : FRFEstimate
        On the excited lines. The noise variance needs at least two periods,
        the total variance at least two groups of ``n_inputs`` realizations.
    """
    n_u, n_y = U.shape[1], Y.shape[1]
    lengths = np.diff(starts)
    if np.any(lengths % period):
        bad = int(lengths[np.flatnonzero(lengths % period)[0]])
        raise ValueError(
            f"period={period} does not divide the sequence length {bad}: with "
            "`period` set, every sequence must hold a whole number of periods."
        )
    if np.any(lengths != lengths[0]):
        raise ValueError(
            "With `period` set, all sequences (realizations, see sequence_id) must hold "
            f"the same number of periods; got sequence lengths "
            f"{sorted(set(lengths.tolist()))}."
        )
    n_periods = int(lengths[0] // period)
    n_drop = -(-n_transient // period)
    if n_periods - n_drop < 1:
        raise ValueError(
            f"n_transient={n_transient} drops {n_drop} of the {n_periods} period(s) "
            "of each sequence: no period is left to estimate the FRF."
        )
    n_real = len(starts) - 1
    if n_real < n_u:
        raise ValueError(
            f"The robust method needs at least n_inputs={n_u} realizations "
            f"(sequences, see sequence_id) to separate the inputs; got {n_real}."
        )
    if period < 3:
        raise ValueError(f"period must be at least 3 samples, got {period}.")
    # (realization, period, time, channel), the transient periods dropped
    shape = (n_real, n_periods, period)
    Ur = U.reshape(shape + (n_u,))[:, n_drop:]
    Yr = Y.reshape(shape + (n_y,))[:, n_drop:]
    Uf = np.fft.rfft(Ur, axis=2) / np.sqrt(period)
    Yf = np.fft.rfft(Yr, axis=2) / np.sqrt(period)
    bins = np.arange(Uf.shape[2])
    power = np.sum(np.abs(Uf.mean(axis=1)) ** 2, axis=(0, 2))
    keep = (bins > 0) & _band_mask(bins, period, max_frequency)
    keep &= power > EXCITATION_THRESHOLD * power[keep].max(initial=0.0)
    if not keep.any():
        raise ValueError("The input X has no power on any usable frequency line.")
    Uf, Yf = Uf[:, :, keep], Yf[:, :, keep]
    # Every realization's FRF divides by its own input (a noise-only record
    # beside the excited ones would make it singular).
    own = np.sum(np.abs(Uf.mean(axis=1)) ** 2, axis=(1, 2))
    silent = np.flatnonzero(~(own > EXCITATION_THRESHOLD * own.max()))
    if silent.size:
        raise ValueError(
            f"The input of sequence(s) {silent.tolist()} (in the order of the rows) has no "
            "power at the excited lines: the robust method divides by each realization's "
            "input. Leave such a record out, or fit without `period` (the Local Polynomial "
            "Method).")

    n_blocks = n_real // n_u
    used = n_blocks * n_u
    # (block, period, freq, channel, experiment in block)
    Ub = Uf[:used].reshape(n_blocks, n_u, *Uf.shape[1:]).transpose(0, 2, 3, 4, 1)
    Yb = Yf[:used].reshape(n_blocks, n_u, *Yf.shape[1:]).transpose(0, 2, 3, 4, 1)
    G_blocks = _block_frf(Yb.mean(axis=1), Ub.mean(axis=1))
    G = G_blocks.mean(axis=0)
    total = _sample_variance(G_blocks, axis=0) if n_blocks >= 2 else None
    noise = None
    if Ub.shape[1] >= 2:
        # Nonlinear distortions repeat in every period, so the period-to-period
        # spread of the FRF is due to the noise only.
        noise = _sample_variance(_block_frf(Yb, Ub), axis=1).mean(axis=0) / n_blocks
    return FRFEstimate(bins[keep] / period, G, noise, total,
                       total_variance_dof=None if total is None else n_blocks - 1)


def _lpm_unknowns(n_inputs, degree):
    """Unknowns of an LPM window per output: a polynomial of ``degree`` for
    the FRF of every input and one for the transient."""
    return (degree + 1) * (n_inputs + 1)


def lpm_window(n_inputs, order, n_bins, bandwidth=None):
    """Width and polynomial degree of the LPM window.

    With ``p = (order + 1) (n_inputs + 1)`` unknowns per output, the default
    half-width ``ceil(p / 2) + 1`` leaves three or four degrees of freedom for
    the noise variance (Pintelon & Schoukens, 2012, §7.2). When the record has
    too few bins for that window, the window shrinks to one degree of freedom
    and then the degree is lowered; a record too short even for degree 0 is
    treated as one window over all its bins (a minimum-norm fit without a
    variance estimate), which is only good for very short records.

    Parameters
    ----------
    n_inputs : int
        Number of inputs.
    order : int
        Requested polynomial degree.
    n_bins : int
        Number of usable bins of the record.
    bandwidth : int, default=None
        Requested half-width; the degree is lowered if the window cannot hold
        the polynomials.

    Returns
    -------
    width, order : int
        Number of bins of a window, and the degree used.
    """
    for degree in range(order, -1, -1):
        n_unknown = _lpm_unknowns(n_inputs, degree)
        smallest = -(-n_unknown // 2)
        if bandwidth is not None:
            candidates = [bandwidth] if bandwidth >= smallest else []
        else:
            candidates = [smallest + 1, smallest]
        for half in candidates:
            if 2 * half + 1 <= n_bins:
                return 2 * half + 1, degree
    if bandwidth is not None or n_bins < 1:
        raise ValueError(
            f"The record (X, y) is too short for the Local Polynomial Method: {n_bins} "
            f"frequency bin(s) cannot hold a window (lpm_bandwidth={bandwidth}) for "
            f"{n_inputs} input(s)."
        )
    return n_bins, 0


def _lpm_windows(Uf, Yf, centres, width, order, bins):
    """LPM fits of the windows centred on the bins ``centres`` (0-based in
    ``Uf`` and ``Yf``, whose DFT bin numbers are ``bins``): FRF, noise
    variance of the outputs, the variance gain of each FRF unknown, degrees
    of freedom, whether the regressors are rank deficient, and the power of
    each input in each window."""
    n_bins, n_u = Uf.shape
    half = width // 2
    # window of bin k: the `width` bins closest to it that lie in 1..n_bins
    first = np.clip(centres - half, 0, n_bins - width)
    index = first[:, None] + np.arange(width)
    # The polynomials are in frequency, whatever the spacing of the bins (the
    # spacing is 1 for consecutive bins).
    spacing = (bins[-1] - bins[0]) / (bins.size - 1) if bins.size > 1 else 1.0
    offset = (bins[index] - bins[centres][:, None]) / (max(half, 1) * spacing)
    powers = offset[..., None] ** np.arange(order + 1)  # (bin, width, order+1)
    Uw = Uf[index]  # (bin, width, n_u)
    # regressors: [r^s u_i] for every s and i, then [r^s] for the transient
    K = np.concatenate(
        [(powers[..., :, None] * Uw[..., None, :]).reshape(centres.size, width, -1),
         powers.astype(complex)],
        axis=2,
    )
    Uk, s, Vh = np.linalg.svd(K, full_matrices=False)
    inv_s = np.where(s > _LPM_RCOND * s[:, :1], 1.0 / np.where(s > 0, s, 1.0), 0.0)
    rank = np.sum(inv_s > 0, axis=1)
    # theta = pinv(K) Y_window ; the first n_u unknowns are the FRF at the bin
    Yw = Yf[index]  # (bin, width, n_y)
    coef = np.conj(Vh).transpose(0, 2, 1) @ (
        inv_s[..., None] * (np.conj(Uk).transpose(0, 2, 1) @ Yw)
    )
    residual = Yw - K @ coef
    dof = width - rank
    noise_var = np.sum(np.abs(residual) ** 2, axis=1) / np.maximum(dof, 1)[:, None]
    # diag of (K^H K)^+ for the FRF unknowns
    gain = np.sum(np.abs(np.conj(Vh[:, :, :n_u])) ** 2 * inv_s[..., None] ** 2, axis=1)
    G = coef[:, :n_u, :].transpose(0, 2, 1)  # (bin, n_y, n_u)
    window_power = np.sum(np.abs(Uw) ** 2, axis=1)
    # An input without power in a window (inputs in different bands) leaves
    # its columns empty: the others' FRFs are still separable there.
    present = window_power > EXCITATION_THRESHOLD * window_power.max(axis=1, keepdims=True)
    full_rank = np.minimum(width, (order + 1) * (np.sum(present, axis=1) + 1))
    return G, noise_var, gain, dof, rank < full_rank, window_power


def _lpm_record(U, Y, order, bandwidth, max_frequency):
    """LPM on one record, on its bins below ``max_frequency``: (frequencies,
    FRF, variance or None, power of each input in each bin's window), and
    whether its inputs are collinear in every window (which then has no
    power)."""
    n, n_u = U.shape
    n_bins = (n - 1) // 2  # positive bins below Nyquist
    Uf = np.fft.fft(U, axis=0)[1 : n_bins + 1] / np.sqrt(n)
    Yf = np.fft.fft(Y, axis=0)[1 : n_bins + 1] / np.sqrt(n)
    bins = np.arange(1, n_bins + 1)
    in_band = _band_mask(bins, n, max_frequency)
    bin_power = np.sum(np.abs(Uf) ** 2, axis=1)
    excited = bin_power > EXCITATION_THRESHOLD * bin_power.max(initial=0.0)
    width, degree = lpm_window(n_u, order, n_bins, bandwidth)
    record = _lpm_bins(Uf, Yf, bins, n, in_band, excited, width, degree)
    if n_u > 1 and width <= np.count_nonzero(excited) < n_bins:
        # Independent periodic inputs over several periods excite every k-th
        # bin only, or a multisine some lines only: a window of neighbouring
        # bins may hold too few excited ones to tell the inputs apart, where a
        # window of neighbouring excited bins does (the FRFs are as smooth
        # across the excited lines as across the bins). The windows that
        # separate more of the inputs' entries are kept.
        on_lines = _lpm_bins(Uf[excited], Yf[excited], bins[excited], n, in_band[excited],
                             excited[excited], width, degree)
        if np.count_nonzero(on_lines[3]) > np.count_nonzero(record[3]):
            record = on_lines
    return record, n_u > 1 and not np.any(record[3])


def _lpm_bins(Uf, Yf, bins, n, in_band, excited, width, order):
    """The LPM record of :func:`_lpm_record` from the DFT bins ``Uf``, ``Yf``
    (DFT bin numbers ``bins`` of a record of ``n`` samples), with windows of
    ``width`` neighbouring bins centred on those ``in_band``; the bins not
    ``excited`` get no window power, hence no estimate."""
    n_u = Uf.shape[1]
    centres = np.flatnonzero(in_band)
    if centres.size == 0:
        # A window with more bins than unknowns has a variance estimate, as
        # the bins out of the band would have had.
        empty = np.empty((0, Yf.shape[1], n_u), dtype=complex)
        variance = np.empty(empty.shape) if width > _lpm_unknowns(n_u, order) else None
        return np.empty(0), empty, variance, np.empty((0, n_u))
    # The windows' regressors, factors and residuals take about 2 kB per
    # bin; fitted a block of bins at a time, the memory stays that of the
    # record's DFT however long the record.
    fits = [_lpm_windows(Uf, Yf, block, width, order, bins)
            for block in np.array_split(centres, -(-centres.size // _LPM_BLOCK))]
    G, noise_var, gain, dof, deficient, window_power = map(np.concatenate, zip(*fits))
    var = noise_var[:, :, None] * gain[:, None, :] if np.all(dof > 0) else None
    # A bin without input power of its own (an unexcited line of a periodic
    # input, whose window still holds excited ones) has no FRF to estimate:
    # its estimate would be extrapolated from the neighbours, with a variance
    # that does not show it. It counts as not excited.
    window_power[~excited[centres]] = 0.0
    if n_u > 1:
        # Where the inputs are collinear over a window, the FRFs of the
        # inputs cannot be told apart: the bin counts as not excited. (A
        # window narrower than its unknowns, on a very short record, is
        # underdetermined whatever the inputs.)
        window_power[deficient] = 0.0
    return bins[centres] / n, G, var, window_power


def lpm_records(U, Y, starts, *, order=2, bandwidth=None, n_transient=0, max_frequency=None):
    """The LPM of every sequence on its own, before any bin is left out for
    its window's input power (see :func:`lpm_estimate`).

    Parameters are those of :func:`lpm_frf`.

    Returns
    -------
    records : list of tuple
        Per sequence: frequencies, FRF, variance (or None) and the power of
        each input in each bin's window.
    """
    records, collinear = zip(*(
        _lpm_record(U[begin + n_transient : end], Y[begin + n_transient : end], order,
                    bandwidth, max_frequency)
        for begin, end in zip(starts[:-1], starts[1:])
    ))
    # A record whose inputs are collinear has no bin to give; the others may.
    if all(collinear):
        raise ValueError(
            "The inputs of X are collinear in every window of the Local Polynomial "
            "Method: it cannot separate them. Each input needs its own, independent "
            "excitation."
        )
    return list(records)


def lpm_estimate(records, power_threshold=LPM_POWER_THRESHOLD):
    """The FRF estimate of :func:`lpm_records` on the bins whose window holds
    at least ``power_threshold`` times the largest window power of their
    record; estimates at equal frequencies combined (see :func:`lpm_frf`).

    With several inputs, the entries of an input whose own window power there
    is below ``power_threshold`` times its largest are not estimated: where an
    input has no power of its own, the regression's pseudo-inverse sets its
    FRF to zero, with a variance that does not show it."""
    parts = []
    for freqs, G, var, power in records:
        total = np.sum(power, axis=1)
        keep = total > power_threshold * total.max(initial=0.0)
        own = power[keep] > power_threshold * power.max(axis=0, initial=0.0)
        parts.append((freqs[keep], G[keep], None if var is None else var[keep],
                      np.broadcast_to(own[:, None, :], G[keep].shape)))
    freqs = np.concatenate([p[0] for p in parts])
    if freqs.size == 0:
        raise ValueError("The input X has no power on any usable frequency bin.")
    G = np.concatenate([p[1] for p in parts])
    estimated = np.concatenate([p[3] for p in parts])
    if any(p[2] is None for p in parts):
        var = None
        weight = np.ones(G.shape)
    else:
        var = np.concatenate([p[2] for p in parts])
        weight = 1.0 / np.maximum(var, np.finfo(float).tiny)
    # Sorted by frequency, as np.unique sorts them (records of different
    # lengths interleave their bins).
    order = np.argsort(freqs, kind="stable")
    freqs, G, estimated, weight = freqs[order], G[order], estimated[order], weight[order]
    var = None if var is None else var[order]
    unique, group = np.unique(freqs, return_inverse=True)
    if unique.size < freqs.size:
        weight = weight * estimated
        wsum = np.zeros((unique.size,) + G.shape[1:])
        np.add.at(wsum, group, weight)
        Gsum = np.zeros((unique.size,) + G.shape[1:], dtype=complex)
        np.add.at(Gsum, group, weight * G)
        estimated = wsum > 0
        with np.errstate(divide="ignore", invalid="ignore"):
            G = Gsum / wsum
            var = None if var is None else 1.0 / wsum
    if estimated.all():
        return FRFEstimate(unique, G, var, var)
    return FRFEstimate(unique, np.where(estimated, G, 0.0), var, var, estimated.copy())


def lpm_frf(U, Y, starts, *, order=2, bandwidth=None, n_transient=0, max_frequency=None,
            power_threshold=LPM_POWER_THRESHOLD):
    """Local Polynomial Method FRF of non-periodic records.

    Parameters
    ----------
    U : ndarray of shape (n_samples, n_inputs)
        Input signal.
    Y : ndarray of shape (n_samples, n_outputs)
        Output signal.
    starts : ndarray of shape (n_sequences + 1,)
        Sequence boundaries; each sequence is one record, processed alone.
    order : int, default=2
        Degree of the local polynomials of the FRF and the transient; lowered
        automatically on records too short for it.
    bandwidth : int, default=None
        Half-width n of the window of ``2 n + 1`` bins; ``None`` chooses the
        window leaving three or four degrees of freedom (see :func:`lpm_window`).
    n_transient : int, default=0
        Samples dropped at the start of every record.
    max_frequency : float, default=None
        Highest frequency used, in cycles per sample.
    power_threshold : float, default=LPM_POWER_THRESHOLD
        Input power of a bin's window, relative to the largest window's, below
        which the bin is left out.

    Returns
    -------
    estimate : FRFEstimate
        On the bins below ``max_frequency`` that hold input power of their
        own (more than ``EXCITATION_THRESHOLD`` times the strongest bin's: the
        unexcited lines of a periodic input are left out) and whose window
        holds input power (at least ``power_threshold`` times the largest
        window power).
        The LPM cannot separate noise from nonlinear distortion on a
        non-periodic record: both variances are the same total variance.
        Records of different lengths contribute their own bins; estimates at
        equal frequencies are combined by inverse-variance weighting.
    """
    records = lpm_records(U, Y, starts, order=order, bandwidth=bandwidth,
                          n_transient=n_transient, max_frequency=max_frequency)
    return lpm_estimate(records, power_threshold)
