"""Reading an objective evaluated on a grid of designs in ln(parameter): its Gaussian
smoothing (the discrete stand-in for the smoothed objective E[J(y + s ξ)] that a sampled-
gradient optimisation minimises, `optimize.Scatter`), the smoothed minimum and the grid points
that cannot be told from it. Used by experiments/design_study.py (docs/design.md)."""

from __future__ import annotations

import numpy as np


def smoothing_weights(grid, s):
    """Gaussian weights in ln x with width `s` between the points of a 1-D `grid`, each row
    normalised over the grid (the smoothing is truncated at the bounds)."""
    y = np.log(np.asarray(grid, dtype=float))
    w = np.exp(-0.5 * ((y[:, None] - y[None, :]) / s) ** 2)
    return w / w.sum(axis=1, keepdims=True)


def smoothed(J, grid, s):
    """A 2-D grid objective `J[i, j]` (both axes on `grid`) smoothed: W J Wᵀ."""
    w = smoothing_weights(grid, s)
    return w @ np.asarray(J) @ w.T


def near_optimal(J, grid, s):
    """Grid points whose smoothed J cannot be told from the smoothed minimum:
    J_s − min J_s ≤ 2 sqrt(sd² + sd_min²), sd the standard error of J_s at a point if J were a
    smooth trend plus independent scatter of the size of its roughness (rms of J − J_s).

    **Returns:** boolean array of J's shape."""
    w = smoothing_weights(grid, s)
    smooth = w @ np.asarray(J) @ w.T
    rough = np.sqrt(np.mean((np.asarray(J) - smooth) ** 2))
    w2 = (w**2).sum(axis=1)
    sd = rough * np.sqrt(w2[:, None] * w2[None, :])
    i, j = np.unravel_index(np.argmin(smooth), smooth.shape)
    return smooth - smooth[i, j] <= 2 * np.sqrt(sd**2 + sd[i, j] ** 2)


def grid_argmin(J):
    """Indices `(i, j)` of J's minimum."""
    i, j = np.unravel_index(np.argmin(J), np.shape(J))
    return int(i), int(j)
