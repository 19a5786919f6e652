"""Residuals between a model run and measurements, in units of the noise level.

Two kinds, both over chosen time windows (only samples with `t0 <= t <= t1` count):

* `"trajectory"`: every sample, `r = (y_model(t_i) − y_data(t_i)) / σ`.
* `"block"`: the mean over consecutive blocks of duration `block` [s] (a low-pass feature),
  `r_b = (ȳ_model,b − ȳ_data,b) / (σ/√n_b)` for a block of `n_b` samples. With independent
  noise of level σ the block mean has level σ/√n_b, so the residuals stay in noise units
  and the Gauss–Newton curvature keeps its meaning. A block mean is insensitive to the
  phase of contact chatter inside the block, which a pointwise residual is not
  (docs/identification.md).

* `"smooth"`: the channels smoothed by a Gaussian kernel of standard deviation `width`/2
  (weights normalised over the windowed samples), compared at centres `width` apart,
  `r_k = Σ_i w_ki (y_model(t_i) − y_data(t_i)) / (σ √(Σ_i w_ki²))`. Impacts put their
  momentum exchange into spikes much shorter than a sample block; a pointwise or block
  residual sees a shifted spike only once it crosses a sample or block boundary, so the
  loss is flat (no gradient) beyond a small shift and jumps at the boundaries. A Gaussian
  spreads each spike over ~`width`, so the loss changes smoothly with the impact times over
  that scale: a wide, smooth basin. Fitting with decreasing widths is continuation in
  resolution (coarse-to-fine smoothing of a non-convex objective; e.g. A. Blake &
  A. Zisserman, *Visual Reconstruction*, MIT Press 1987, "graduated non-convexity").
  Neighbouring residuals share samples, so their noise is correlated (for centres `width`
  apart, kernel σ = `width`/2: correlation e^(−1/2) ≈ 0.6 between neighbours, less beyond)
  and the χ² of a smooth stage is not that of independent residuals: take the uncertainties
  from a last stage with independent residuals (`"trajectory"` or `"block"`).

Weights: σ per channel from the measurements' noise levels; a channel without one is scaled
by its own standard deviation over the fitted samples, and the covariance is then rescaled by
the reduced χ² at the optimum (the noise level is estimated from the residuals).
"""

from __future__ import annotations

from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from ._data import Measurements

KINDS = ("trajectory", "block", "smooth")


@dataclass(frozen=True)
class ResidualSpec:
    """How model and data are compared: `kind` (`"trajectory"`, `"block"` or `"smooth"`),
    `windows` (tuple of `(t0, t1)` [s]; None: all samples), `block` (block duration [s]) and
    `width` (smoothing width [s] of `"smooth"`)."""

    kind: str = "trajectory"
    windows: tuple[tuple[float, float], ...] | None = None
    block: float | None = None
    width: float | None = None

    def __post_init__(self):
        if self.kind not in KINDS:
            raise ValueError(f"loss kind {self.kind!r} is invalid; valid: {', '.join(KINDS)}")
        if self.kind == "block" and not (self.block is not None and self.block > 0):
            raise ValueError(f"block = {self.block!r} s is invalid: a block loss needs block > 0")
        if self.kind == "smooth" and not (self.width is not None and self.width > 0):
            raise ValueError(f"width = {self.width!r} s is invalid: a smooth loss needs width > 0")
        for w in self.windows or ():
            if len(w) != 2 or not (np.isfinite(w[0]) and np.isfinite(w[1]) and w[0] < w[1]):
                raise ValueError(f"window {w!r} is invalid: give (t0, t1) with t0 < t1 [s]")


class Comparison:
    """Residual layout for one `ResidualSpec` on one set of `Measurements` (numpy, static).

    `t_end`: the last time the model must reach; `ts`: the save times (data samples up to
    `t_end`); `residuals(model_channels)` → the flat residual vector (JAX); `labels`: the
    channel of each residual.
    """

    def __init__(self, data: Measurements, spec: ResidualSpec):
        self.spec = spec
        t = np.asarray(data.t)
        mask = np.zeros(t.shape, bool)
        for t0, t1 in spec.windows or [(t[0], t[-1])]:
            mask |= (t >= t0) & (t <= t1)
        if not mask.any():
            raise ValueError(
                f"no data sample lies in the windows {spec.windows}; the data cover "
                f"[{t[0]:g}, {t[-1]:g}] s"
            )
        used = np.nonzero(mask)[0]
        self.n_save = int(used[-1]) + 1
        self.ts = t[: self.n_save]
        self.t_end = float(self.ts[-1])
        self.used = used
        self.weights = None
        if spec.kind == "trajectory":
            segment = np.arange(used.size)
        elif spec.kind == "smooth":
            tu = t[used]
            centres = np.arange(tu[0], tu[-1] + 1e-12 * max(1.0, abs(tu[-1])), spec.width)
            # keep centres inside the windows (not in gaps between them)
            near = np.abs(tu[None, :] - centres[:, None]).min(axis=1) <= 0.5 * spec.width
            centres = centres[near]
            kernel = np.exp(-0.5 * ((tu[None, :] - centres[:, None]) / (0.5 * spec.width)) ** 2)
            kernel[kernel < 1e-8] = 0.0
            self.weights = kernel / kernel.sum(axis=1, keepdims=True)
            segment = np.arange(centres.size)  # one residual per centre
        else:
            # A new block starts at every gap between windows and every `block` seconds.
            segment = np.zeros(used.size, int)
            start = t[used[0]]
            for k in range(1, used.size):
                gap = used[k] != used[k - 1] + 1
                if gap or t[used[k]] >= start + spec.block - 1e-12 * max(1.0, abs(start)):
                    segment[k] = segment[k - 1] + 1
                    start = t[used[k]]
                else:
                    segment[k] = segment[k - 1]
        self.segment = segment
        self.n_segments = int(segment[-1]) + 1
        if self.weights is None:
            self.counts = np.bincount(segment, minlength=self.n_segments).astype(float)
        else:  # the effective number of samples averaged: 1/Σ w² (σ/√n for a mean of n)
            self.counts = 1.0 / np.sum(self.weights**2, axis=1)
        self.names = data.names
        self.noise_known = all(n in data.noise for n in data.names)
        self.sigma = {}
        for n in data.names:
            if n in data.noise:
                self.sigma[n] = float(data.noise[n])
            else:
                spread = float(np.std(data.channels[n][used]))
                self.sigma[n] = (
                    spread if spread > 0 else max(abs(data.channels[n][used]).max(), 1.0)
                )
        self.data_features = {n: self.features_np(data.channels[n]) for n in data.names}
        self.scale = {n: self.sigma[n] / np.sqrt(self.counts) for n in data.names}
        self.labels = np.concatenate(
            [np.full(self.n_segments, n, dtype=object) for n in self.names]
        )
        if self.weights is None:
            self.times = np.bincount(segment, weights=t[used], minlength=self.n_segments)
            self.times = self.times / self.counts
        else:
            self.times = centres

    def features_np(self, y):
        y = np.asarray(y)[self.used]
        if self.weights is not None:
            return self.weights @ y
        return np.bincount(self.segment, weights=y, minlength=self.n_segments) / self.counts

    def features(self, y):
        """Block means (samples, for `"trajectory"`; kernel averages, for `"smooth"`) of a
        model channel sampled at `ts`."""
        y = jnp.asarray(y)[self.used]
        if self.weights is not None:
            return jnp.asarray(self.weights) @ y
        sums = jax.ops.segment_sum(y, jnp.asarray(self.segment), num_segments=self.n_segments)
        return sums / self.counts

    def residuals(self, model_channels):
        parts = [
            (self.features(model_channels[n]) - self.data_features[n]) / self.scale[n]
            for n in self.names
        ]
        return jnp.concatenate(parts)

    def residuals_np(self, model_channels) -> np.ndarray:
        """`residuals` in numpy (the model channels as numpy arrays)."""
        return np.concatenate(
            [
                (self.features_np(np.asarray(model_channels[n])[: self.n_save])
                 - self.data_features[n]) / self.scale[n]
                for n in self.names
            ]
        )  # fmt: skip

    def residual_jacobian(self, channel_jacobians) -> np.ndarray:
        """d residuals/dz from `{name: d channel/dz (n_save, p)}`: the residuals are linear
        in the channel samples, so the same map applies to every column."""
        blocks = []
        for n in self.names:
            jac = np.asarray(channel_jacobians[n])[: self.n_save]
            cols = [self.features_np(jac[:, k]) for k in range(jac.shape[1])]
            blocks.append(np.stack(cols, axis=1) / self.scale[n][:, None])
        return np.concatenate(blocks, axis=0)

    @property
    def size(self) -> int:
        return self.n_segments * len(self.names)
