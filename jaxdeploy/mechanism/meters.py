"""Instruments for simulated runs: energy bookkeeping (`EnergyMeter`, `metered`,
`energy_balance`), a step-size log (`StepClock`, `add_clock`), the quantities whose
extremes a run tracks (`extremes_at`, `merge_extremes`) and the clearance joints' contact
quantities at saved states (`contact_history`).

**Energy.**
The balance of a mechanism whose ideal joints are scleronomic (no driving constraints):

    T(t) + V(t) + D(t) = T(0) + V(0) + J(t)

with `T = ½ q̇ᵀ M q̇`, `V = Σ_e V_e(q)` (`AbstractElement.potential_energy`), `D = Σ_e D_e` the
energy dissipated by the non-conservative part of each element's force,

    D_e(t) = −∫ Q_e^nc · dq,    Q_e^nc = Q_e(q, q̇) + ∇_q V_e(q),

and `J` the energy that memory updates put into potentials (a latch engaging at an overshoot
`α − α_L` stores `½ k_L (α − α_L)²` at once). Ideal joints do no work on a scleronomic
mechanism.

`D_e` is metered *inside* the simulation by `EnergyMeter`, a wrapper element whose memory
integrates `Q_e^nc · dq` by the trapezoidal rule over each accepted step (forces at the step's
start and end, displacement `q_{n+1} − q_n`): exact to O(h³) per step, whatever the integrator,
and blind to the solver's own (numerical) dissipation — which therefore shows up, with the
integrator's energy error, as the balance residual `T + V + D − T(0) − V(0) − J`.
The meter does not change the dynamics: memory is updated between steps only.

**Steps.** `add_clock` adds a free body `"clock"` (no forces, unit velocity along x, so its x
coordinate is the time, exactly for any integrator that is exact on constant velocity) and a
`StepClock` element whose memory logs the smallest and largest accepted step and counts them.
It is an instrument: it adds three coordinates whose error estimate is zero, which scales an
RMS error norm by sqrt(n/(n+3)) — say so when reporting steps taken with it.

**Extremes.** The largest contact force of an impact lasts microseconds, far less than the
spacing of any saved grid, so a maximum taken over saved states depends on the grid (on
deploy_array, 501 saved states saw 27 % of the largest contact force, 20001 saw 96 %).
`extremes_at` gives, at one state, the quantities a summary reports as extremes; the solvers
fold them over every accepted step (`jaxdeploy.solvers.TrackExtremes`), so the run's extremes
do not depend on the output times.

Reference: the work–energy theorem for constrained systems, e.g. Géradin & Cardona, *Flexible
Multibody Dynamics* (2001), §6.
"""

from __future__ import annotations

from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .. import _program_cache
from .._tracing import traced_once
from .assembly import ConsistentState
from .bodies import CLOCK, Body, Kinematics
from .clearance import RevoluteClearance
from .element import AbstractElement
from .system import Mechanism


class EnergyMeter(AbstractElement):
    """`inner` unchanged, plus a memory that meters the energy its non-conservative forces
    dissipate (`dissipated`) and the energy memory updates put into its potential
    (`injected`). Forces are evaluated at t = 0 in the meter (no element force depends on t).

    **Arguments:** `inner`: a force element (no constraints).
    """

    inner: AbstractElement
    has_memory: ClassVar[bool] = True

    def __check_init__(self):
        if self.inner.n_constraints:
            raise ValueError(
                f"EnergyMeter meters force elements; {type(self.inner).__name__} is a constraint"
            )
        if self.inner.has_internal_state:
            # Its continuous states would sit inside the meter's memory, where the solvers
            # neither integrate nor error-control them.
            raise ValueError(
                f"EnergyMeter cannot meter {type(self.inner).__name__}: elements with "
                "continuous internal states (e.g. HingeFriction) are not supported by the meter"
            )

    def bodies(self):
        return self.inner.bodies()

    def coupled_bodies(self):
        return self.inner.coupled_bodies()

    def wrenches(self, kin: Kinematics, t, memory):
        return self.inner.wrenches(kin, t, memory["inner"])

    def potential_energy(self, kin: Kinematics, memory):
        return self.inner.potential_energy(kin, memory["inner"])

    def switched(self, before, after):
        if not self.inner.has_memory:
            return jnp.array(False)
        return self.inner.switched(before["inner"], after["inner"])

    def event_fraction(self, memory):
        # The meter must not change how a run steps: the inner element's events (a clearance
        # joint's onset, v⁻ peak, separation) are still located.
        return self.inner.event_fraction(memory["inner"]) if self.inner.has_memory else None

    def idealized(self):
        # A clearance joint idealizes to a revolute joint, which does no work: no meter.
        ideal = self.inner.idealized()
        return ideal if ideal.n_constraints else EnergyMeter(ideal)

    # --- metering -------------------------------------------------------------------------

    def _inner_memory(self, method, memory, kin, *step):
        return getattr(self.inner, method)(memory, kin, *step) if self.inner.has_memory else memory

    @property
    def _memory_kept_for_step(self) -> bool:
        """Whether the inner element starts each step with the memory the last step left it
        (no memory, or `memory_for_step` not overridden): then nothing can jump there."""
        return not self.inner.has_memory or not _overrides(self.inner, "memory_for_step")

    def _nonconservative_force(self, kin: Kinematics, inner_memory):
        """`Q_e + ∇_q V_e` at `kin`, with the inner element's memory; exactly 0 for an
        element whose class declares its force conservative (`AbstractElement.conservative`),
        which would only meter the round-off of that difference."""
        if self.inner.conservative:
            return jnp.zeros_like(kin.q)
        if _overrides(self.inner, "nonconservative_wrenches"):
            part = _NonConservativePart(self.inner)
            part = Mechanism(kin.mechanism.bodies, [part], kin.mechanism.ground_points)
            return part.generalized_forces(kin.q, kin.v, 0.0, (inner_memory,))
        alone = Mechanism(kin.mechanism.bodies, [self.inner], kin.mechanism.ground_points)
        forces = alone.generalized_forces(kin.q, kin.v, 0.0, (inner_memory,))
        grad_v = jax.grad(lambda q: self.inner.potential_energy(Kinematics(alone, q), inner_memory))
        return forces + grad_v(kin.q)

    def _jump(self, kin, before, after):
        """`V(q; after) − V(q; before)`: what a memory update put into the potential; 0 for
        an element without memory (the same evaluation twice, skipped at trace time)."""
        if not self.inner.has_memory:
            return jnp.zeros((), dtype=kin.q.dtype)
        return self.inner.potential_energy(kin, after) - self.inner.potential_energy(kin, before)

    def init_memory(self, kin: Kinematics):
        inner = self.inner.init_memory(kin) if self.inner.has_memory else None
        zero = jnp.zeros((), dtype=kin.q.dtype)
        # With the memory kept between steps, each step's starting force is computed by the
        # step before (`after_step`), the first one's here.
        start = self._nonconservative_force(kin, inner) if self._memory_kept_for_step else None
        return {
            "inner": inner,
            "q_start": kin.q,
            "force_start": jnp.zeros_like(kin.q) if start is None else start,
            "dissipated": zero,
            "injected": zero,
        }

    def memory_for_step(self, memory, kin: Kinematics):
        inner = self._inner_memory("memory_for_step", memory["inner"], kin)
        return self.for_step(memory, kin, inner)

    def memory_after_step(self, memory, kin: Kinematics, step):
        inner = self._inner_memory("memory_after_step", memory["inner"], kin, step)
        return self.after_step(memory, kin, inner)

    def for_step(self, memory, kin: Kinematics, inner):
        """`memory_for_step` given the inner element's memory for the step, `inner`."""
        if self._memory_kept_for_step:
            # Nothing changes between steps: the step's starting force (at this state, with
            # this memory) was computed at the end of the step before (`after_step`).
            return {**memory, "q_start": kin.q}
        force, jump = self.step_start(kin, memory["inner"], inner)
        return {
            "inner": inner,
            "q_start": kin.q,
            "force_start": force,
            "dissipated": memory["dissipated"],
            "injected": memory["injected"] + jump,
        }

    def after_step(self, memory, kin: Kinematics, inner):
        """`memory_after_step` given the inner element's memory after the step, `inner`.

        With the memory kept between steps (`_memory_kept_for_step`) the next step starts at
        this state with the memory `inner`: its starting force is computed here, with the
        step's ending force in one evaluation vectorised over the two memories (what does not
        depend on the memory — the kinematics, the contact geometry — is then traced and
        compiled once, not twice)."""
        work, force_next, jump = self.step_end(
            kin, memory["q_start"], memory["force_start"], memory["inner"], inner
        )
        return {
            "inner": inner,
            "q_start": memory["q_start"],
            "force_start": force_next,
            "dissipated": memory["dissipated"] - work,
            "injected": memory["injected"] + jump,
        }

    def step_start(self, kin: Kinematics, before, inner):
        """`(force_start, jump)` of a step that starts at `kin` after the inner element's
        memory changed from `before` to `inner` between steps (`_memory_kept_for_step`
        False): the step's starting non-conservative force and `_jump`."""
        return self._nonconservative_force(kin, inner), self._jump(kin, before, inner)

    def step_end(self, kin: Kinematics, q_start, force_start, step_memory, inner):
        """`(work, force_next, jump)` at the end `kin` of a step from `q_start` whose starting
        force was `force_start`, taken with the inner memory `step_memory` and left with
        `inner`: the trapezoidal work `½ (Q_start + Q_end)·(q − q_start)` of the
        non-conservative force, the next step's starting force (when the memory is kept
        between steps; else `force_start` back, `for_step` computes it) and `_jump`."""
        if self._memory_kept_for_step:
            force_end, force_next = self._forces_with(kin, step_memory, inner)
        else:
            force_end = self._nonconservative_force(kin, step_memory)
            force_next = force_start
        work = 0.5 * jnp.dot(force_start + force_end, kin.q - q_start)
        return work, force_next, self._jump(kin, step_memory, inner)

    def _forces_with(self, kin: Kinematics, first, second):
        """`_nonconservative_force` at `kin` with the inner memories `first` and `second`."""
        if first is None or self.inner.conservative:
            force = self._nonconservative_force(kin, first)
            return force, force
        both = jax.tree.map(lambda a, b: jnp.stack([a, b]), first, second)
        forces = jax.vmap(lambda m: self._nonconservative_force(kin, m))(both)
        return forces[0], forces[1]


def _overrides(element: AbstractElement, method: str) -> bool:
    """Whether `element`'s class overrides `AbstractElement.method`."""
    return getattr(type(element), method) is not getattr(AbstractElement, method)


class _NonConservativePart(AbstractElement):
    """An element's closed-form non-conservative wrenches (`nonconservative_wrenches`) as an
    element's wrenches, for `Mechanism.generalized_forces`."""

    inner: AbstractElement

    def wrenches(self, kin: Kinematics, t, memory):
        return self.inner.nonconservative_wrenches(kin, t, memory)

    def bodies(self):
        return self.inner.bodies()


def metered(mechanism: Mechanism) -> Mechanism:
    """`mechanism` with every force element wrapped in an `EnergyMeter` (same dynamics)."""
    elements = [e if e.n_constraints else EnergyMeter(e) for e in mechanism.elements]
    return Mechanism(mechanism.bodies, elements, mechanism.ground_points)


class BalanceMeter(AbstractElement):
    """The energy meters of a mechanism's force elements, beside them: the elements stay as
    they are (a clearance joint stays a `RevoluteClearance`, its contact episodes and extremes
    logged as before) and this element keeps an `EnergyMeter`'s bookkeeping of each, updated
    from the same states. It adds no force, no constraint, no event and no coupling, so the
    run steps exactly as without it. See `balance_metered`.

    The metered elements' memories are the mechanism's, handed over before and after it
    updated them (`reads_memories`), not updated a second time (a second clearance-joint
    update, a root search on the step's interpolant, had doubled the size of deploy_array's
    compiled run) nor kept a second time: the meter's memory is four arrays over the k
    meters, `q_start` (n,) the step's starting positions, `force_start` (k, n) each meter's
    starting non-conservative force, `dissipated` (k,) and `injected` (k,). (A copy of each
    element's memory and positions per meter, 52 arrays carried through deploy_array's loop,
    were a fifth of its compiled run; `metered_balance` reads the elements' memories from
    the mechanism's.)

    **Arguments:** `meters`: an `EnergyMeter` per metered element; `indices`: each metered
    element's index in the mechanism.
    """

    meters: tuple
    indices: tuple[int, ...] = eqx.field(static=True)
    has_memory: ClassVar[bool] = True
    reads_memories: ClassVar[bool] = True

    def bodies(self):
        return ()

    def coupled_bodies(self):
        return ()

    def init_memory(self, kin: Kinematics):
        starts = [m.init_memory(kin) for m in self.meters]
        return {
            "q_start": kin.q,
            "force_start": _stacked([s["force_start"] for s in starts], kin.q),
            "dissipated": _stacked([s["dissipated"] for s in starts], kin.q[:0]),
            "injected": _stacked([s["injected"] for s in starts], kin.q[:0]),
        }

    def memory_for_step_beside(self, memory, kin: Kinematics, updated, before):
        """`memory_for_step`, the metered elements' memories for the step in `updated` and
        before this call in `before` (the mechanism's, by element index)."""
        forces, jumps = [], []
        for j, (meter, i) in enumerate(zip(self.meters, self.indices, strict=True)):
            if meter._memory_kept_for_step:
                # Nothing changes between steps: the starting force was computed at the end
                # of the step before (`memory_after_step_beside`).
                forces.append(memory["force_start"][j])
                jumps.append(None)
            else:
                force, jump = meter.step_start(kin, before[i], updated[i])
                forces.append(force)
                jumps.append(jump)
        return {
            "q_start": kin.q,
            "force_start": _stacked(forces, kin.q),
            "dissipated": memory["dissipated"],
            "injected": _add_where_given(memory["injected"], jumps),
        }

    def memory_after_step_beside(self, memory, kin: Kinematics, step, updated, before):
        """`memory_after_step`, the metered elements' memories after the step in `updated`
        and during it in `before`."""
        works, forces, jumps = [], [], []
        for j, (meter, i) in enumerate(zip(self.meters, self.indices, strict=True)):
            work, force, jump = meter.step_end(
                kin, memory["q_start"], memory["force_start"][j], before[i], updated[i]
            )
            works.append(work)
            forces.append(force)
            jumps.append(jump)
        return {
            "q_start": memory["q_start"],
            "force_start": _stacked(forces, kin.q),
            "dissipated": memory["dissipated"] - _stacked(works, kin.q[:0]),
            "injected": memory["injected"] + _stacked(jumps, kin.q[:0]),
        }

    def switched(self, before, after):
        # The metered elements' own switches are seen where they are, in the mechanism.
        return jnp.array(False)

    def idealized(self):
        # A metered clearance joint idealizes to a revolute joint, which does no work: no meter.
        kept = [(m.idealized(), i) for m, i in zip(self.meters, self.indices, strict=True)]
        kept = [(m, i) for m, i in kept if isinstance(m, EnergyMeter)]
        return BalanceMeter(tuple(m for m, _ in kept), tuple(i for _, i in kept))

    def meter_memories(self, memory, elements_memory) -> tuple:
        """Each meter's memory as an `EnergyMeter`'s (`inner` from `elements_memory`, the
        mechanism's memory by element index), from this element's `memory`; leading axes
        (saved states) kept."""
        return tuple(
            {
                "inner": elements_memory[i],
                "q_start": memory["q_start"],
                "force_start": memory["force_start"][..., j, :],
                "dissipated": memory["dissipated"][..., j],
                "injected": memory["injected"][..., j],
            }
            for j, i in enumerate(self.indices)
        )


def _stacked(values, like):
    """`values` (arrays of one shape) stacked on a new first axis; with none, an empty array
    of `like`'s trailing shape."""
    if not values:
        return jnp.zeros((0, *like.shape), dtype=like.dtype)
    return jnp.stack(values)


def _add_where_given(total, jumps):
    """`total` (k,) plus each given jump at its position (None: nothing added there, so the
    entry stays bit for bit what it was)."""
    if all(jump is None for jump in jumps):
        return total
    return jnp.stack([total[j] if d is None else total[j] + d for j, d in enumerate(jumps)])


def balance_metered(mechanism: Mechanism) -> Mechanism | None:
    """`mechanism` with a `BalanceMeter` of its force elements appended (last element), or
    None when its energy balance cannot be computed (`unmetered_because` says why). Its
    energies: `metered_balance`."""
    if unmetered_because(mechanism) is not None:
        return None
    forces = [i for i, e in enumerate(mechanism.elements) if not e.n_constraints]
    meter = BalanceMeter(tuple(EnergyMeter(mechanism.elements[i]) for i in forces), tuple(forces))
    return Mechanism(mechanism.bodies, (*mechanism.elements, meter), mechanism.ground_points)


def unmetered_because(mechanism: Mechanism) -> str | None:
    """Why `mechanism`'s energy balance cannot be computed, or None: a rheonomic constraint
    (a driver does work that no element meters) or a force element with continuous internal
    states (which `EnergyMeter` cannot meter)."""
    for e in mechanism.elements:
        if e.rheonomic:
            return f"a driving constraint ({type(e).__name__}) does work no element meters"
        if not e.n_constraints and e.has_internal_state:
            return f"{type(e).__name__} has internal states the energy meter cannot meter"
    return None


def balance_metered_state(mechanism: Mechanism, state: ConsistentState) -> ConsistentState:
    """`state` (of the mechanism without the meter) for `mechanism` from `balance_metered`:
    the same q, q̇, q̈, λ, its memory initialised with the meter's."""
    return ConsistentState(
        state.q, state.v, state.qdd, state.lam, mechanism.init_memory(state.q, state.v)
    )


def without_balance_meter(trajectory):
    """A run of a `balance_metered` mechanism as the run of the mechanism without it: the
    meter's memory (the last entry) taken out of the saved memory."""
    return eqx.tree_at(lambda t: t.memory, trajectory, tuple(trajectory.memory[:-1]))


def metered_balance(mechanism: Mechanism, q, v, memory) -> dict:
    """`energy_balance` of a run of a `balance_metered` mechanism, from its saved `q`, `v`
    and `memory` (the `BalanceMeter`'s memory is the last entry)."""
    meter = mechanism.elements[-1]
    alone = Mechanism(mechanism.bodies, meter.meters, mechanism.ground_points)
    # Through the program cache when it is on: a warm `jaxdeploy simulate` reads the
    # program back instead of tracing it.
    return _program_cache.call(_metered_energy_balance, alone, meter, q, v, memory)


@eqx.filter_jit
def _metered_energy_balance(alone: Mechanism, meter: BalanceMeter, q, v, memory) -> dict:
    """`energy_balance` of the meters `alone`, their memories from the `BalanceMeter`'s and
    the mechanism's saved `memory` (`BalanceMeter.meter_memories`)."""
    return energy_balance(alone, q, v, meter.meter_memories(memory[-1], memory))


class StepClock(AbstractElement):
    """Logs accepted steps through the `"clock"` body's x coordinate (= t); see `add_clock`.

    Memory: `t_start`, `min_step`, `max_step`, `steps` (accepted steps).
    """

    has_memory: ClassVar[bool] = True

    def bodies(self):
        return (CLOCK,)

    def _time(self, kin):
        return kin.origin(CLOCK)[0]

    def init_memory(self, kin: Kinematics):
        t = self._time(kin)
        return {"t_start": t, "min_step": jnp.inf + 0 * t, "max_step": 0 * t, "steps": 0 * t}

    def memory_for_step(self, memory, kin: Kinematics):
        return {**memory, "t_start": self._time(kin)}

    def memory_after_step(self, memory, kin: Kinematics, step):
        h = self._time(kin) - memory["t_start"]
        return {
            "t_start": memory["t_start"],
            "min_step": jnp.minimum(memory["min_step"], h),
            "max_step": jnp.maximum(memory["max_step"], h),
            "steps": memory["steps"] + 1.0,
        }


def add_clock(mechanism: Mechanism, state: ConsistentState, t0=0.0):
    """`(mechanism + clock, state + clock)`: the clock body starts at x = t0 with unit speed.

    **Returns:** the extended mechanism and its consistent state (memory re-initialised).
    """
    clock = Body(CLOCK, 1.0, 1.0)
    extended = Mechanism(
        (*mechanism.bodies, clock), (*mechanism.elements, StepClock()), mechanism.ground_points
    )
    dtype = state.q.dtype
    q = jnp.concatenate([state.q, jnp.array([t0, 0.0, 0.0], dtype=dtype)])
    v = jnp.concatenate([state.v, jnp.array([1.0, 0.0, 0.0], dtype=dtype)])
    qdd = jnp.concatenate([state.qdd, jnp.zeros(3, dtype=dtype)])
    return extended, ConsistentState(q, v, qdd, state.lam, extended.init_memory(q, v))


def step_log(mechanism: Mechanism, memory) -> dict:
    """`{min_step, max_step, steps}` at the last saved state of a clocked run (floats)."""
    (index,) = [i for i, e in enumerate(mechanism.elements) if isinstance(e, StepClock)]
    log = memory[index]
    return {k: float(log[k][-1]) for k in ("min_step", "max_step", "steps")}


@eqx.filter_jit
def energy_balance(mechanism: Mechanism, q, v, memory) -> dict:
    """Energy terms along saved states of a `metered` mechanism.

    **Arguments:** `mechanism` (from `metered`), saved `q`, `v` (N, n) and `memory` (leading
    axis N), e.g. a `Trajectory`'s fields.

    **Returns:** arrays over the N saved states: `kinetic` T, `potential` V, `dissipated` D,
    `injected` J, `residual` `T + V + D − T(0) − V(0) − J`, and per element index
    `dissipated_by` / `potential_of` / `injected_by` (dicts over element index). A clock
    body's kinetic energy is left out.

    Compiled (`equinox.filter_jit`: once per mechanism composition and array shapes): run
    eagerly, the vmapped energies dispatch hundreds of small operations, each compiled on
    first use (~6 s for an impact scene on a 2-core CPU, against < 1 s compiled).
    """
    meters = [i for i, e in enumerate(mechanism.elements) if isinstance(e, EnergyMeter)]

    def at(q, v, memory):
        kin = mechanism.kinematics(q, v)
        potentials = {i: mechanism.elements[i].potential_energy(kin, memory[i]) for i in meters}
        moving = jnp.asarray([b.name != CLOCK for b in mechanism.bodies for _ in range(3)])
        return {
            "kinetic": mechanism.kinetic_energy(jnp.where(moving, v, 0.0)),
            "potential_of": potentials,
            "dissipated_by": {i: memory[i]["dissipated"] for i in meters},
            "injected_by": {i: memory[i]["injected"] for i in meters},
        }

    out = jax.vmap(at)(q, v, memory)
    potential = sum(out["potential_of"].values(), jnp.zeros_like(out["kinetic"]))
    dissipated = sum(out["dissipated_by"].values(), jnp.zeros_like(out["kinetic"]))
    injected = sum(out["injected_by"].values(), jnp.zeros_like(out["kinetic"]))
    total = out["kinetic"] + potential + dissipated
    out.update(
        potential=potential,
        dissipated=dissipated,
        injected=injected,
        residual=total - total[0] - (injected - injected[0]),
    )
    return out


def energy_moved(balance: dict) -> float:
    """The scale an energy residual is judged against: max_t (T + D) + max_t |J| over the run,
    from an `energy_balance` — the most energy that was ever in motion, dissipated or put in
    (a residual relative to E0 alone would be meaningless for a mechanism released from rest)."""
    kinetic, dissipated = np.asarray(balance["kinetic"]), np.asarray(balance["dissipated"])
    return float(np.max(kinetic + dissipated) + np.max(np.abs(np.asarray(balance["injected"]))))


def contact_history(mechanism: Mechanism, q, v, memory) -> dict[int, dict]:
    """For every clearance joint (by element index): eccentricity (N, 2), penetration,
    penetration rate, sliding velocity, normal force and friction force (N,) at the saved
    states `q`, `v` (N, n) with their saved `memory` (impact velocities). The forces are net
    of the bore's near and far side (`RevoluteClearance.contact_forces`; the far side is zero
    unless the clearance is below ~3σ)."""
    return {
        index: _program_cache.call(_joint_history, mechanism, index, q, v, memory)
        for index in mechanism.find(RevoluteClearance)
    }


# Compiled once per mechanism structure and joint, not per call: a sweep evaluates it for
# every case (the parameters are leaves of `mechanism`, so new values reuse the program).
@eqx.filter_jit
def _joint_history(mechanism, index, q, v, memory):
    joint = mechanism.elements[index]

    def at(q, v, memory):
        kin = mechanism.kinematics(q, v)
        fn, ft, g = joint.contact_forces(kin, memory[index])
        return {
            "eccentricity": g.eccentricity,
            "penetration": g.penetration,
            "penetration_rate": g.penetration_rate,
            "sliding_velocity": g.sliding_velocity,
            "normal_force": fn,
            "friction_force": jnp.asarray(ft) + 0.0 * fn,
        }

    return jax.vmap(at)(q, v, memory)


@traced_once
def extremes_at(mechanism: Mechanism, q, v, qdd, memory) -> dict:
    """The quantities whose extremes a run tracks, at one state `(q, q̇, q̈, memory)`:

    - `acceleration_min`, `acceleration_max`: q̈ (n,) [m/s², rad/s²] (absent if `qdd` is None);
    - for the clearance joints, in the order of `mechanism.find(RevoluteClearance)` (the keys
      are absent, and nothing of this is traced, without any): `normal_force_max` (k,) [N],
      the net normal force on the journal `F_N(δ) − F_N(δ')` (`RevoluteClearance.
      contact_forces`, with the joint's memory for a step from this state), and
      `penetration_max` (k,) [m], δ = |e| − c.

    `merge_extremes` folds two of these (minimum of `*_min`, maximum of `*_max`).
    """
    out = {} if qdd is None else {"acceleration_min": qdd, "acceleration_max": qdd}
    joints = mechanism.find(RevoluteClearance)
    if not joints:
        return out
    kin = mechanism.kinematics(q, v)
    forces, penetrations = [], []
    for index in joints:
        joint = mechanism.elements[index]
        joint_memory = memory[index]
        if joint.has_memory:
            joint_memory = joint.memory_for_step(joint_memory, kin)
        fn, _, geometry = joint.contact_forces(kin, joint_memory)
        forces.append(fn)
        penetrations.append(geometry.penetration)
    out["normal_force_max"] = jnp.stack(forces)
    out["penetration_max"] = jnp.stack(penetrations)
    return out


def merge_extremes(a: dict, b: dict) -> dict:
    """Elementwise the smaller of `*_min` and the larger of `*_max` entries (NaN wins: a run
    that met a NaN shows it)."""
    merged = {
        k: jnp.minimum(a[k], b[k]) if k.endswith("_min") else jnp.maximum(a[k], b[k]) for k in b
    }
    return {**a, **merged}
