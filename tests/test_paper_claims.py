"""The claim checks of the paper study: comparisons honour the error bars, verdicts combine as
documented, the spectral peak finds a known tone and its RMS."""

import math

import numpy as np
import pytest

from jaxdeploy.analysis import paper_claims as pc


def _evidence(values, uncertainty):
    return pc.Evidence([{"m": v} for v in values], [{"m": u} for u in uncertainty])


def test_comparisons_within_the_error_bars_are_unresolved():
    ev = _evidence([1.0, 1.5, 1.2], [0.1, 0.1, 0.2])
    assert ev.trend("m", [0, 1, 2]) == ("<", "≈")  # 0.5 > 0.2; 0.3 ≤ 0.3
    assert pc.trend_verdict(("<", ">"), ("<", ">")) == "agrees"
    assert pc.trend_verdict(("<", "≈"), ("<", ">")) == "not resolved"
    assert pc.trend_verdict((">", "≈"), ("<", ">")) == "disagrees"
    assert pc.verdict_from(["agrees", "disagrees"]) == "partly"
    assert pc.verdict_from(["not resolved", "not resolved"]) == "not resolved"
    assert _evidence([float("nan"), 1.0], [0, 0]).compare("m", 0, "m", 1) == "?"
    # "Similar": a ratio of values within their error bars compares noise.
    assert pc.spread_verdict(_evidence([1.0, 1.5], [0.1, 0.1]), "m", [0, 1], 2.0)[1] == "agrees"
    assert pc.spread_verdict(_evidence([1.0, 3.0], [0.1, 0.1]), "m", [0, 1], 2.0)[1] == "disagrees"
    noise = _evidence([1e-16, 3e-16], [1e-15, 1e-15])
    assert pc.spread_verdict(noise, "m", [0, 1], 2.0)[1] == "not resolved"


def test_spectral_peak_of_a_tone():
    t = np.arange(0.0, 0.5, 1e-4)
    f, level = pc.spectral_peak(t, 3.0 * np.sin(2 * math.pi * 93.0 * t))
    assert f == pytest.approx(93.0, abs=1.0)
    # A tone of amplitude A between bins spreads over the Hann main lobe: the peak bin holds
    # a fraction of its RMS A/√2, between half and all of it.
    assert 0.5 * 3.0 / math.sqrt(2) < level <= 3.0 / math.sqrt(2) * 1.01
