import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sknlss.signals import multisine

line_sets = st.sampled_from(["full", "odd", "special_odd", "random_odd"])


@settings(max_examples=40, deadline=None)
@given(
    n=st.integers(min_value=32, max_value=300),
    n_periods=st.integers(min_value=1, max_value=3),
    n_realizations=st.integers(min_value=1, max_value=3),
    lines=line_sets,
    rms=st.floats(min_value=1e-3, max_value=1e3),
    seed=st.integers(min_value=0, max_value=2**31 - 1),
)
def test_periodic_exact_rms_and_only_excited_lines(n, n_periods, n_realizations, lines,
                                                   rms, seed):
    u, excited = multisine(n, n_periods=n_periods, n_realizations=n_realizations,
                           lines=lines, band=(0.0, 0.5), rms=rms, random_state=seed)
    assert u.shape == (n_realizations, n_periods * n)
    periods = u.reshape(n_realizations, n_periods, n)
    np.testing.assert_allclose(periods, np.broadcast_to(periods[:, :1], periods.shape),
                               rtol=0, atol=1e-12 * rms)
    np.testing.assert_allclose(np.sqrt(np.mean(u**2, axis=1)), rms, rtol=1e-12)
    spectrum = np.abs(np.fft.rfft(periods[:, 0], axis=1))
    off = np.setdiff1d(np.arange(spectrum.shape[1]), excited)
    assert np.all(spectrum[:, off] <= 1e-9 * spectrum.max())
    # Flat amplitude by default: every excited line carries the same power.
    np.testing.assert_allclose(spectrum[:, excited],
                               np.broadcast_to(spectrum[:, excited[:1]],
                                               (n_realizations, len(excited))),
                               rtol=1e-9)


@settings(max_examples=20, deadline=None)
@given(lines=line_sets, seed=st.integers(min_value=0, max_value=2**31 - 1))
def test_reproducible_with_random_state(lines, seed):
    first = multisine(256, n_realizations=2, lines=lines, random_state=seed)
    second = multisine(256, n_realizations=2, lines=lines, random_state=seed)
    np.testing.assert_array_equal(first[0], second[0])
    np.testing.assert_array_equal(first[1], second[1])
    other = multisine(256, n_realizations=2, lines=lines, random_state=seed + 1)
    assert not np.allclose(first[0], other[0])


def test_realizations_share_lines_but_not_phases():
    u, _ = multisine(128, n_realizations=3, random_state=0)
    assert not np.allclose(u[0], u[1])
    assert not np.allclose(u[1], u[2])


def test_line_sets():
    n = 1024
    _, full = multisine(n, lines="full", band=(0.0, 0.45), random_state=0)
    np.testing.assert_array_equal(full, np.arange(1, 461))
    _, odd = multisine(n, lines="odd", band=(0.0, 0.45), random_state=0)
    np.testing.assert_array_equal(odd, np.arange(1, 461, 2))
    _, special = multisine(n, lines="special_odd", band=(0.0, 0.45), random_state=0)
    assert set(np.unique(special % 8)) == {1, 3}
    assert set(special) <= set(odd)
    _, random_odd = multisine(n, lines="random_odd", band=(0.0, 0.45), random_state=0)
    # One odd line in each full group of 4 is left out as a detection line.
    n_groups = len(odd) // 4
    assert len(random_odd) == len(odd) - n_groups
    for g in range(n_groups):
        assert np.isin(odd[4 * g:4 * g + 4], random_odd).sum() == 3
    np.testing.assert_array_equal(random_odd[random_odd > odd[4 * n_groups - 1]],
                                  odd[4 * n_groups:])


def test_band_and_nyquist():
    _, lines = multisine(100, lines="full", band=(0.1, 0.2), random_state=0)
    np.testing.assert_array_equal(lines, np.arange(10, 21))
    # The Nyquist line of an even period is never excited, DC neither.
    _, lines = multisine(16, lines="full", band=(0.0, 0.5), random_state=0)
    np.testing.assert_array_equal(lines, np.arange(1, 8))


def test_explicit_lines_and_amplitudes():
    u, lines = multisine(64, lines=[3, 5, 9], amplitudes=[1.0, 2.0, 0.0], rms=1.0,
                         random_state=1)
    np.testing.assert_array_equal(lines, [3, 5, 9])
    spectrum = np.abs(np.fft.rfft(u[0]))
    assert spectrum[5] == pytest.approx(2 * spectrum[3], rel=1e-10)
    assert spectrum[9] < 1e-9 * spectrum[5]
    u, lines = multisine(64, lines="full", band=(0.0, 0.25),
                         amplitudes=lambda f: np.where(f < 0.1, 1.0, 0.1),
                         random_state=1)
    spectrum = np.abs(np.fft.rfft(u[0]))
    assert spectrum[2] == pytest.approx(10 * spectrum[10], rel=1e-10)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"lines": "even"}, "'lines' parameter"),
        ({"lines": [0, 3]}, "Excited lines must lie"),
        ({"lines": [3, 32]}, "Excited lines must lie"),
        ({"lines": [1.5]}, "integer array"),
        ({"lines": [5, 3]}, "strictly increasing"),
        ({"lines": [3, 3, 5]}, "strictly increasing"),
        ({"band": (0.3, 0.2)}, "band must satisfy"),
        ({"band": 0.2}, "'band' parameter"),
        ({"band": (0.0, 0.001)}, "No line"),
        ({"rms": 0.0}, "'rms' parameter"),
        ({"n_periods": 0}, "n_periods"),
        ({"n_realizations": 1.5}, "n_realizations"),
        ({"amplitudes": [1.0, 2.0]}, "one value per excited line"),
        ({"lines": [1, 2], "amplitudes": [0.0, 0.0]}, "not all zero"),
    ],
)
def test_bad_arguments(kwargs, match):
    with pytest.raises(ValueError, match=match):
        multisine(64, **kwargs)
