"""Headline number of a pendulum run: the drift of its constraint."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp

from .. import _program_cache
from .base import Analysis


class PendulumAnalysis(Analysis):
    """`max_constraint_violation` [m]: the largest |Φ(q)| over the saved states."""

    def summary(self) -> dict:
        # Through the program cache when it is on (a warm command does not trace it).
        drift = _program_cache.call(_largest_residual, self.mechanism, self.trajectory.q)
        return {"max_constraint_violation": float(drift)}


# Compiled once per mechanism structure, not per call: a sweep summarizes every case with it.
@eqx.filter_jit
def _largest_residual(mechanism, q):
    """max |Φ(q)| over the saved states `q` (N, n) [m]."""
    return jnp.max(jnp.abs(jax.vmap(lambda qi: mechanism.constraints(qi, 0.0))(q)))
