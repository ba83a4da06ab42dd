"""Sequences of samples: boundaries, transients, held-out tails and periods.

Several experiments (records, realizations) are concatenated rows; the
``starts`` array of length ``n_sequences + 1`` holds their boundaries:
sequence ``k`` occupies rows ``starts[k]:starts[k + 1]``.
"""

import numbers

import numpy as np

#: A sequence repeats with the period when its periods differ from their mean
#: by at most this fraction of its standard deviation (RMS): a random input
#: differs by 70 % or more, a measured periodic one by its noise.
PERIODIC_TOLERANCE = 0.2


def sequence_bounds(sequence_id, n_samples):
    """Return the row boundaries of the sequences.

    Parameters
    ----------
    sequence_id : array-like of shape (n_samples,) or None
        Label of the experiment each row belongs to: an integer (also as a
        whole float) or a string. Each label must occupy one contiguous block
        of rows. ``None`` means a single sequence.
    n_samples : int
        Number of rows of ``X``.

    Returns
    -------
    starts : ndarray of shape (n_sequences + 1,)
        Sequence ``k`` occupies rows ``starts[k]:starts[k + 1]``.
    """
    if sequence_id is None:
        return np.array([0, n_samples], dtype=np.int64)
    ids = np.asarray(sequence_id)
    if ids.ndim != 1 or ids.shape[0] != n_samples:
        raise ValueError(
            f"sequence_id must be a 1-D array with one label per sample: got shape "
            f"{ids.shape} for X with {n_samples} samples."
        )
    if ids.dtype.kind == "O":
        # A column of a DataFrame of object dtype holds Python objects.
        if all(isinstance(label, str) for label in ids):
            ids = ids.astype(str)
        elif all(isinstance(label, numbers.Integral) and not isinstance(label, bool)
                 for label in ids):
            try:
                ids = ids.astype(np.int64)
            except OverflowError:
                # Labels beyond 64 bits stay labels: as their decimal strings.
                ids = ids.astype(str)
    if ids.dtype.kind not in "iubUS":
        # A float that is not a whole number is more likely a time vector
        # passed by mistake than a label.
        if ids.dtype.kind == "f" and np.all(np.isfinite(ids)) and np.all(ids == np.round(ids)):
            ids = ids.astype(np.int64)
        else:
            found = ("values that are not whole numbers" if ids.dtype.kind == "f"
                     else "labels that are neither numbers nor strings")
            raise ValueError(
                "sequence_id must hold integer labels (whole numbers, also as floats) or "
                f"strings; got dtype {ids.dtype} with {found}."
            )
    change = np.flatnonzero(ids[1:] != ids[:-1]) + 1
    starts = np.concatenate(([0], change, [n_samples])).astype(np.int64)
    run_labels = ids[starts[:-1]]
    labels, counts = np.unique(run_labels, return_counts=True)
    if np.any(counts > 1):
        raise ValueError(
            "sequence_id must label each sequence by one contiguous block of rows; "
            f"label(s) {labels[counts > 1].tolist()} occur in separate blocks."
        )
    return starts


def transient_mask(starts, n_transient):
    """Boolean mask of the rows kept once ``n_transient`` samples per sequence
    are dropped (an int, or one per sequence)."""
    mask = np.ones(starts[-1], dtype=bool)
    n_drop = np.broadcast_to(n_transient, (len(starts) - 1,))
    for begin, end, n in zip(starts[:-1], starts[1:], n_drop):
        mask[begin : min(begin + n, end)] = False
    return mask


def holdout_masks(starts, n_transient, validation_fraction):
    """Rows used for the cost and rows held out for selection.

    The last ``validation_fraction`` of every sequence is held out; the first
    ``n_transient`` samples of every sequence are in neither set (each an
    int, or one per sequence). Simulations run over whole sequences, so the
    held-out tail continues from the state the model reached at the end of
    the fitted part.

    Returns
    -------
    fit_mask, validation_mask : ndarray of bool of shape (n_samples,)
    """
    fit_mask = transient_mask(starts, n_transient)
    validation_mask = np.zeros_like(fit_mask)
    n_sequences = len(starts) - 1
    for begin, end, n_drop, fraction in zip(
            starts[:-1], starts[1:], np.broadcast_to(n_transient, (n_sequences,)),
            np.broadcast_to(validation_fraction, (n_sequences,))):
        if fraction:
            split = end - int(round(fraction * (end - begin)))
            validation_mask[max(split, begin + n_drop) : end] = True
            fit_mask[split:end] = False
    if not fit_mask.any():
        raise ValueError(
            f"n_transient={n_transient} and validation_fraction={validation_fraction} "
            "leave no sample to fit."
        )
    return fit_mask, validation_mask


def part_before_holdout(U, Y, starts, fit_mask):
    """Each sequence from its start to its last fitted row, concatenated.

    With masks from :func:`holdout_masks`, these are the sequences cut before
    their held-out tails (their transients kept): the initialisations of the
    nonlinear models see only these rows, so the tails stay unseen until the
    iterate selection.

    Returns
    -------
    U_part, Y_part : ndarray
        The kept rows, C-contiguous.
    starts_part : ndarray of shape (n_kept_sequences + 1,)
        Boundaries of the kept parts; sequences without a fitted row are dropped.
    kept : ndarray of int
        Indices of the kept sequences.
    """
    segments, kept = [], []
    for k, (begin, end) in enumerate(zip(starts[:-1], starts[1:])):
        fitted = np.flatnonzero(fit_mask[begin:end])
        if fitted.size:
            segments.append((begin, begin + fitted[-1] + 1))
            kept.append(k)
    rows = np.concatenate([np.arange(begin, end) for begin, end in segments])
    lengths = [end - begin for begin, end in segments]
    starts_part = np.cumsum([0] + lengths).astype(np.int64)
    return (np.ascontiguousarray(U[rows]), np.ascontiguousarray(Y[rows]), starts_part,
            np.array(kept, dtype=np.int64))


def every_sequence(states, kept, n_sequences):
    """The initial ``states`` of the ``kept`` sequences (of shape (n_states,)
    for one) set among all ``n_sequences``, zero for the others; for one
    sequence in all, ``states`` as they are."""
    if n_sequences == 1:
        return states
    every = np.zeros((n_sequences, np.shape(states)[-1]))
    every[kept] = np.reshape(states, (len(kept), -1))
    return every


def steady_state_rows(starts, n_prepend):
    """Row indices of the sequences, each preceded by its last ``n_prepend``
    samples (an int, or one per sequence).

    Simulating a periodic signal from this extension starts every sequence in
    (approximately) steady state. Returns the row index into the original
    arrays per extended row, the extended ``starts`` and a mask of the extended
    rows that are original samples.
    """
    index, original, new_starts = [], [], [0]
    n_heads = np.broadcast_to(n_prepend, (len(starts) - 1,))
    for begin, end, n_prepend in zip(starts[:-1], starts[1:], n_heads):
        length = end - begin
        head = begin + (np.arange(length - n_prepend, length) % length)
        index.append(head)
        index.append(np.arange(begin, end))
        original.append(np.zeros(n_prepend, dtype=bool))
        original.append(np.ones(length, dtype=bool))
        new_starts.append(new_starts[-1] + n_prepend + length)
    return (
        np.concatenate(index).astype(np.int64),
        np.asarray(new_starts, dtype=np.int64),
        np.concatenate(original),
    )


def period_blocks(mask, starts, period):
    """(begin, n_periods) of the masked block of each sequence, in whole periods."""
    blocks = []
    for begin, end in zip(starts[:-1], starts[1:]):
        rows = np.flatnonzero(mask[begin:end])
        if rows.size == 0:
            continue
        if rows.size % period or rows[-1] - rows[0] + 1 != rows.size:
            raise ValueError(
                f"cost='frequency' needs the fitted rows of every sequence to be a "
                f"whole number of periods (period={period}); got {rows.size} "
                "rows. Adjust validation_fraction or the record lengths."
            )
        blocks.append((begin + rows[0], rows.size // period))
    return blocks


def periodic_sequences(U, starts, period, tolerance=PERIODIC_TOLERANCE):
    """Which sequences of ``U`` repeat with ``period``.

    A sequence repeats when it is a whole number of periods and its periods
    differ from their mean by an RMS value within ``tolerance`` times its own
    standard deviation, both pooled over the columns, each column about its
    own mean (so that an offset does not decide; a column of noise beside an
    excited one, an input left unexcited, does not either). A single period
    counts as repeating: nothing tells it apart from one that does.

    Returns
    -------
    repeats : ndarray of bool of shape (n_sequences,)
    """
    repeats = np.zeros(len(starts) - 1, dtype=bool)
    for k, (begin, end) in enumerate(zip(starts[:-1], starts[1:])):
        if (end - begin) % period:
            continue
        periods = U[begin:end].reshape(-1, period, U.shape[1])
        spread = np.sqrt(np.mean((periods - periods.mean(axis=0)) ** 2))
        repeats[k] = spread <= tolerance * np.sqrt(np.mean(np.var(U[begin:end], axis=0)))
    return repeats


def delayed_input(U, starts, delay, period=None):
    """``U`` with its column ``j`` delayed by ``delay[j]`` samples in every sequence.

    The samples that the delay brings in before the start of a sequence were
    not measured: a sequence that repeats with ``period`` (see
    :func:`periodic_sequences`) takes them from its own periodic continuation,
    any other takes zero (a centred input's mean).

    Returns
    -------
    delayed : ndarray of shape U.shape
        ``U`` itself when no column is delayed.
    """
    if not np.any(delay):
        return U
    repeating = (np.zeros(len(starts) - 1, dtype=bool) if period is None
                 else periodic_sequences(U, starts, period))
    delayed = np.zeros_like(U)
    for k, (begin, end) in enumerate(zip(starts[:-1], starts[1:])):
        for j, lag in enumerate(delay):
            delayed[begin + lag:end, j] = U[begin:end - lag, j]
            if lag and repeating[k]:
                delayed[begin:begin + lag, j] = U[begin + np.arange(-lag, 0) % period, j]
    return delayed


def undelayed_input(delayed, starts, delay):
    """The input that :func:`delayed_input` delayed into ``delayed``.

    Column ``j`` of every sequence is advanced by ``delay[j]`` samples. Its
    last ``delay[j]`` samples come back from the sequence's start: the
    original ones where the delay filled that start with the periodic
    continuation, zero otherwise; they would enter the model only after the
    end of the sequence.

    Returns
    -------
    U : ndarray of shape delayed.shape
        ``delayed`` itself when no column is delayed.
    """
    if not np.any(delay):
        return delayed
    U = np.empty_like(delayed)
    for begin, end in zip(starts[:-1], starts[1:]):
        for j, lag in enumerate(delay):
            U[begin:end, j] = np.roll(delayed[begin:end, j], -lag)
    return U
