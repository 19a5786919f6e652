"""Event outputs of a run, read from the memory its elements keep: the located times of a
latch's engagement and of a clearance joint's contact onsets, and the count of onsets.

Every time here is located inside its step on the step's interpolant and carries the
implicit-function derivative of its event function (`AbstractLatch`, `RevoluteClearance`'s
onset clock), so these are pure JAX scalars to put in a loss, `jax.grad` or `jax.vmap`. They
do not depend on the save grid: the memory at the last saved time holds them (save at the run's
end, as `simulate` does by default).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from .clearance import RevoluteClearance
from .forces import AbstractLatch


def final_memory(memory):
    """The memory at the last saved time (every leaf's leading axis is the saved times)."""
    return jax.tree.map(lambda x: x[-1], memory)


def lock_times(mechanism, memory) -> dict[int, jax.Array]:
    """`{element index: t*}` of every latch [s since the run's start]: when its angle reached
    the stop, NaN if it has not engaged by the last saved time. `memory`: a trajectory's
    saved memory."""
    last = final_memory(memory)
    return {
        i: jnp.where(last[i]["engaged"] > 0.5, last[i]["lock_time"], jnp.nan)
        for i in mechanism.find(AbstractLatch)
    }


def _onset_clocks(mechanism, memory):
    last = final_memory(memory)
    return {
        i: last[i]
        for i in mechanism.find(RevoluteClearance)
        if last[i] is not None and "onsets" in last[i]
    }


def first_onset_times(mechanism, memory) -> dict[int, jax.Array]:
    """`{element index: t_on}` of every clearance joint with an onset clock (laws with
    impact-velocity memory): the onset of its first contact [s since the run's start], NaN if
    none began by the last saved time (0 if the run started in contact)."""
    return {
        i: jnp.where(m["onsets"] > 0.5, m["first_onset_time"], jnp.nan)
        for i, m in _onset_clocks(mechanism, memory).items()
    }


def onset_counts(mechanism, memory) -> dict[int, jax.Array]:
    """`{element index: n}`: contacts begun by the last saved time (a count: its derivative is
    0; a change of it between two runs means they differ by an impact)."""
    return {i: m["onsets"] for i, m in _onset_clocks(mechanism, memory).items()}
