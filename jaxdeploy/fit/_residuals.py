"""Residuals between a model run and measurements, in units of the noise level.

Two kinds, both over chosen time windows (only samples with `t0 <= t <= t1` count):

* `"trajectory"`: every sample, `r = (y_model(t_i) − y_data(t_i)) / σ`.
* `"block"`: the mean over consecutive blocks of duration `block` [s] (a low-pass feature),
  `r_b = (ȳ_model,b − ȳ_data,b) / (σ/√n_b)` for a block of `n_b` samples. With independent
  noise of level σ the block mean has level σ/√n_b, so the residuals stay in noise units
  and the Gauss–Newton curvature keeps its meaning. A block mean is insensitive to the
  phase of contact chatter inside the block, which a pointwise residual is not
  (docs/identification.md).

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

KINDS = ("trajectory", "block")


@dataclass(frozen=True)
class ResidualSpec:
    """How model and data are compared: `kind` (`"trajectory"` or `"block"`), `windows`
    (tuple of `(t0, t1)` [s]; None: all samples) and `block` (block duration [s])."""

    kind: str = "trajectory"
    windows: tuple[tuple[float, float], ...] | None = None
    block: float | None = None

    def __post_init__(self):
        if self.kind not in KINDS:
            raise ValueError(f"loss kind {self.kind!r} is invalid; valid: {', '.join(KINDS)}")
        if self.kind == "block" and not (self.block is not None and self.block > 0):
            raise ValueError(f"block = {self.block!r} s is invalid: a block loss needs block > 0")
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
        if spec.kind == "trajectory":
            segment = np.arange(used.size)
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
        self.counts = np.bincount(segment, minlength=self.n_segments).astype(float)
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
        self.data_features = {n: self._features_np(data.channels[n]) for n in data.names}
        self.scale = {n: self.sigma[n] / np.sqrt(self.counts) for n in data.names}
        self.labels = np.concatenate(
            [np.full(self.n_segments, n, dtype=object) for n in self.names]
        )
        self.times = np.bincount(segment, weights=t[used], minlength=self.n_segments) / self.counts

    def _features_np(self, y):
        y = np.asarray(y)[self.used]
        return np.bincount(self.segment, weights=y, minlength=self.n_segments) / self.counts

    def features(self, y):
        """Block means (samples, for `"trajectory"`) of a model channel sampled at `ts`."""
        y = jnp.asarray(y)[self.used]
        sums = jax.ops.segment_sum(y, jnp.asarray(self.segment), num_segments=self.n_segments)
        return sums / self.counts

    def residuals(self, model_channels):
        parts = [
            (self.features(model_channels[n]) - self.data_features[n]) / self.scale[n]
            for n in self.names
        ]
        return jnp.concatenate(parts)

    @property
    def size(self) -> int:
        return self.n_segments * len(self.names)
