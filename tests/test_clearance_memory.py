"""The clearance joint's v⁻ memory: the step interpolant of δ that locates onsets and peaks
(step independence through an impact is checked in tests/test_diffrax_path.py)."""

import jax
import numpy as np
import pytest

from jaxdeploy.mechanism.clearance import _StepPenetration


def _cubic(t):
    """A cubic δ(t) (m) with a rate peak inside [0, h]: exactly representable by the Hermite
    interpolant of its end values."""
    return -1e-6 + 4.0 * t + 2e6 * t**2 - 1e12 * t**3


_RATE = jax.grad(_cubic)


@pytest.mark.parametrize("t0", [0.0, 2e-7])
def test_step_interpolant_finds_onset_and_interior_peak_of_a_cubic_exactly(t0):
    h = 1.6e-6
    path = _StepPenetration(_cubic(t0), _RATE(t0), _cubic(t0 + h), _RATE(t0 + h), h)
    # Onset: δ = 0 at the root of the cubic (numpy's polynomial root, independent).
    roots = np.roots([-1e12, 2e6, 4.0, -1e-6])
    t_on = float(roots[np.isreal(roots) & (roots.real > t0) & (roots.real < t0 + h)][0].real)
    s_on = float(path.crossing(0.0))
    np.testing.assert_allclose(t0 + s_on * h, t_on, rtol=1e-10)
    # Peak of δ̇: where δ̈ = 4e6 − 6e12 t = 0.
    t_peak = 4e6 / 6e12
    assert t0 < t_peak < t0 + h
    np.testing.assert_allclose(float(path.max_rate(s_on)), float(_RATE(t_peak)), rtol=1e-12)
    # From after the peak, the maximum is at the interval's start.
    s_late = (t_peak - t0) / h + 0.1
    np.testing.assert_allclose(
        float(path.max_rate(s_late)), float(_RATE(t0 + s_late * h)), rtol=1e-12
    )


def test_a_step_too_short_to_resolve_delta_adds_no_interior_peak():
    """A 4e-19 s step that landed on a requested output time (Dopri8 with `step_ts` on
    slider_crank): δ₁ − δ₀ = 2.8e-17 m is round-off of world positions ~0.1 m, and
    (δ₁ − δ₀)/h = 64 m/s once made v⁻ = 95 m/s in a 1.09 m/s contact. The interpolant must
    then not invent a rate beyond its end values."""
    d0, r0 = 1.1362057218265828e-05, 1.091997004573437
    d1, r1 = 1.1362057218293584e-05, 1.0919970045734377
    roundoff = 16 * np.finfo(float).eps * 0.2
    path = _StepPenetration(d0, r0, d1, r1, 4.336808689942018e-19, roundoff)
    assert float(path.max_rate(0.0)) == pytest.approx(max(r0, r1), rel=1e-15)
    # A step long enough to resolve δ keeps the cubic (and its interior peak): the exact
    # cubic of the test above, with the same round-off level.
    h = 1.6e-6
    exact = _StepPenetration(_cubic(0.0), _RATE(0.0), _cubic(h), _RATE(h), h, roundoff)
    np.testing.assert_allclose(float(exact.max_rate(0.0)), float(_RATE(4e6 / 6e12)), rtol=1e-12)
