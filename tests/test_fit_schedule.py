"""Defaults a fit takes from the data: the continuation's horizons from the impact onsets."""

import numpy as np

from jaxdeploy.fit import impact_horizons


def test_horizons_through_4_8_16_impacts_end_in_flight():
    onsets = np.arange(1, 40) * 1e-3  # one impact per ms
    horizons = impact_horizons(onsets, 35e-3)
    np.testing.assert_allclose(horizons, [4.5e-3, 8.5e-3, 16.5e-3, 32.5e-3, 35e-3])


def test_beyond_the_impacts_of_the_start_run_the_horizon_at_most_doubles():
    """The start run shows 10 impacts in the first 5 ms of a 12 ms record: after the 8th the
    elapsed time doubles (the measurements may hold more impacts than the start run) instead
    of jumping to the whole record."""
    onsets = np.arange(1, 11) * 0.5e-3
    horizons = impact_horizons(onsets, 12e-3, t_start=0.0)
    np.testing.assert_allclose(horizons, [2.25e-3, 4.25e-3, 8.5e-3, 12e-3])
    assert all(b <= 2 * a or b == 12e-3 for a, b in zip(horizons, horizons[1:], strict=False))


def test_a_doubled_horizon_ends_between_two_onsets_when_the_start_run_has_them():
    """14 impacts (no 16th): after the 8th, twice the elapsed time is 17 ms, between the
    onsets at 14.5 and 18 ms; the stage ends midway, in flight."""
    onsets = np.array([1, 2, 3, 4, 5, 6, 7, 8, 9, 9.5, 10.5, 12, 14.5, 18]) * 1e-3
    horizons = impact_horizons(onsets, 30e-3)
    np.testing.assert_allclose(horizons, [4.5e-3, 8.5e-3, 16.25e-3, 30e-3])


def test_without_enough_impacts_one_stage():
    assert impact_horizons([1e-3, 2e-3], 10e-3) == []
