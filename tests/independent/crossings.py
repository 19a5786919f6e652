"""Locating level crossings in a simulation's saved states (test-side measurement, not a
reference: it reads every run's output the same way)."""

from __future__ import annotations

import numpy as np
from scipy.optimize import brentq


def level_crossings(ts, x, v, level, direction=0):
    """Times where `x` crosses `level` between samples (`direction` > 0: rising only, < 0:
    falling only, 0: both), located on the cubic Hermite interpolant of (x, v) = (x, ẋ) on
    each sample interval; its error is O(Δt⁴) where x is smooth."""
    sign = np.sign(x - level)
    jumps = np.diff(sign)
    if direction > 0:
        jumps = np.where(jumps > 0, jumps, 0)
    elif direction < 0:
        jumps = np.where(jumps < 0, jumps, 0)
    out = []
    for k in np.nonzero(jumps)[0]:
        h = ts[k + 1] - ts[k]

        def hermite(s, k=k, h=h):
            return (
                (2 * s**3 - 3 * s**2 + 1) * x[k]
                + (s**3 - 2 * s**2 + s) * h * v[k]
                + (-2 * s**3 + 3 * s**2) * x[k + 1]
                + (s**3 - s**2) * h * v[k + 1]
                - level
            )

        out.append(ts[k] + h * brentq(hermite, 0.0, 1.0, xtol=1e-15))
    return np.array(out)
