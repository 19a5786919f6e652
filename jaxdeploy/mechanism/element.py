"""The interface every joint and force element implements.

An element may contribute constraint equations `Φ_e(q, t) = 0` (ideal joints), generalized
forces (force elements, clearance joints) and a memory state that changes only between time
steps (the impact velocity of a clearance joint, the latch's engaged flag). The mechanism sums
what its elements provide; an element that provides nothing of a kind adds nothing to the trace.
"""

from __future__ import annotations

from typing import ClassVar, NamedTuple

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array

from .bodies import Kinematics


class Wrench(NamedTuple):
    """A force `force` acting at global point `point` of `body`, plus a pure `torque`."""

    body: str
    force: Array | None = None
    point: Array | None = None
    torque: Array | None = None


class AbstractElement(eqx.Module):
    """Base of all joints and force elements (abstract; subclasses are final).

    Subclasses override what they provide:
    - `n_constraints` and `constraint(kin, t)` for ideal joints;
    - `wrenches(kin, t, memory)` for forces;
    - `has_memory`, `init_memory`, `memory_for_step`, `memory_after_step` for state that
      changes between steps only (it is held fixed while Newton solves a step, which keeps the
      step's residual smooth), and `switch_flags`: the memory keys whose flip switches the
      model discontinuously at a step boundary (an O(h) effect that adaptive solvers localise,
      see `switched`);
    - `potential_energy(kin, memory)` for the conservative part of their forces (energy
      balances, `mechanism/energy.py`);
    - `internal_rates(kin, t, memory)` for *continuous* internal states (a friction law's
      bristle deflection): arrays kept in the memory under the key `"internal"` (a dict
      `{name: array}` that `init_memory` creates and `memory_after_step` passes on). Unlike
      the rest of the memory they are integrated with the mechanism's ODE, `ż = rates`, by
      the index-1 solvers (`jaxdeploy.solvers.MechanismODESolver`), error-controlled with
      `q` and `q̇`; `has_internal_state` says an element has them.
    """

    n_constraints: ClassVar[int] = 0
    # Whether the element's constraints depend on time explicitly (a driver): it then does
    # work on the mechanism, and `T + V + D` is not conserved (`meters.balance_metered`).
    rheonomic: ClassVar[bool] = False
    has_memory: ClassVar[bool] = False
    has_internal_state: ClassVar[bool] = False
    switch_flags: ClassVar[tuple[str, ...]] = ()
    # An instrument that follows other elements' memories (`meters.BalanceMeter`): the
    # mechanism updates its memory after theirs and hands it their updated memories
    # (`memory_for_step_beside`, `memory_after_step_beside`), so it does not repeat their
    # updates (a clearance joint's is a root search on the step's interpolant).
    reads_memories: ClassVar[bool] = False
    # Whether the element's force is exactly `−∇_q V` of its `potential_energy` for every
    # parameter value (no damping, friction or memory): it dissipates nothing, so an energy
    # meter books nothing for it instead of evaluating `Q + ∇V` (round-off) twice per step.
    # tests/test_energy.py checks each such class's force against its potential's gradient.
    conservative: ClassVar[bool] = False

    def constraint(self, kin: Kinematics, t) -> Array:
        return jnp.zeros((0,), dtype=kin.q.dtype)

    def wrenches(self, kin: Kinematics, t, memory) -> list[Wrench]:
        return []

    def potential_energy(self, kin: Kinematics, memory) -> Array:
        """Energy `V` (J) whose gradient gives the element's conservative force, `Q = −∇_q V`;
        0 for elements that store none (ideal joints, pure dampers)."""
        return jnp.zeros((), dtype=kin.q.dtype)

    def nonconservative_wrenches(self, kin: Kinematics, t, memory) -> list[Wrench] | None:
        """The wrenches of the element's force less its conservative part `−∇_q V`, in
        closed form, or None (the default): an energy meter then computes `Q + ∇_q V`
        generically (`meters.EnergyMeter`), a second evaluation of the force and a gradient
        of the potential per state, traced and compiled into every metered run."""
        return None

    def bodies(self) -> tuple[str, ...]:
        """Names of the bodies this element touches (for validation)."""
        return ()

    def coupled_bodies(self) -> tuple[str, ...] | None:
        """The bodies whose coordinates and velocities this element's constraints and forces
        depend on; the state-dependent forces act on these bodies only. The implicit solvers'
        iteration matrix is sparse accordingly (`Mechanism.jacobian_patterns`). `None`: not
        declared, every body is assumed. Default: `bodies()`, or `None` if that is empty."""
        return self.bodies() or None

    @property
    def has_forces(self) -> bool:
        """Whether this element's class provides forces (overrides `wrenches`)."""
        return type(self).wrenches is not AbstractElement.wrenches

    def init_memory(self, kin: Kinematics):
        return None

    def memory_for_step(self, memory, kin: Kinematics):
        """Memory used throughout the step that starts at state `kin`."""
        return memory

    def memory_after_step(self, memory, kin: Kinematics, step):
        """Memory after an accepted step of length `step` (s) that ended at state `kin`."""
        return memory

    def internal_rates(self, kin: Kinematics, t, memory) -> dict:
        """`{name: ż}` of the continuous internal states `memory["internal"]` (same shapes),
        at state `kin` and time t; only for elements with `has_internal_state`."""
        return {}

    def event_fraction(self, memory) -> Array | None:
        """Where inside the last accepted step an event of this element's memory happened
        (a clearance joint's onset, v⁻-raising peak or separation), as the fraction s ∈ [0, 1)
        of the step; ≥ 1 when none did. `None` (the default) for elements without locatable events.
        Adaptive runs use it to end a step just past the event
        (`jaxdeploy.solvers.LocateEvents`)."""
        return None

    def switched(self, before, after) -> Array:
        """Whether a step flipped one of the `switch_flags` of this element's memory."""
        flips = [jnp.any(before[key] != after[key]) for key in self.switch_flags]
        return jnp.any(jnp.stack(flips)) if flips else jnp.array(False)

    def idealized(self) -> AbstractElement:
        """This element with clearances removed (the ideal-joint reference)."""
        return self
