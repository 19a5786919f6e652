"""Locating level crossings in a simulation's saved states (test-side measurement, not a
reference: it reads the package's output the same way for every check)."""

from __future__ import annotations

import numpy as np
from scipy.optimize import brentq


def level_crossings(ts, x, v, level):
    """Times where `x` crosses `level` between samples, located on the cubic Hermite
    interpolant of (x, v) (used on a simulation's saved states; accurate to O(Δt⁴))."""
    out = []
    for k in np.nonzero(np.diff(np.sign(x - level)) != 0)[0]:
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
