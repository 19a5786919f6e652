"""Batches with lane refilling: `L` lanes run the cases, a lane that finishes its case takes the
next pending one, so no lane idles while cases remain.

Why. A vmapped adaptive run is one `while` loop whose every iteration costs every case of the
batch, and it runs until the case with the most steps finishes. On deploy_array the cases'
step counts differ 4× at 10 % parameter scatter, and unpredictably (docs/batch_throughput.md),
so a vmapped group spends 30–80 % of its case-steps on cases that have already finished. Here
the batch holds `L` lanes instead of all cases: every lane integrates one case at a time, and
between segments of at most `segment_steps` steps a lane whose case has finished (or failed)
is given the next case. Only the last cases of the batch (the tail) leave lanes idle, and a
lane waits at most `segment_steps - 1` steps for its segment to end.

How a case is continued across segments, so that its step sequence is the one it takes when
run through `simulate`: each segment is `diffrax.diffeqsolve(..., max_steps=segment_steps,
throw=False)` from the lane's state, given the solver state and `made_jump` of the previous
segment (`SaveAt(solver_state=True, made_jump=True)`); the step-size controller is wrapped
(`_Resume`) so that the resumed solve starts with exactly the step the previous segment had
proposed, with the controller's own state (diffrax's `dt0` would start it at `t + (t_next - t)`,
which differs from `t_next` in the last bit). The proposal is what diffrax computes after a
step: the controller's, clipped to the end time by the rule of diffrax's integration loop
(`_next_step_end`, written out here from diffrax 0.7's `_integrate.py` because diffrax does
not export it; a resumed segment must start exactly where the uninterrupted loop would
continue, and tests/test_lanes.py checks bit for bit that it does with the diffrax installed).
Saved states come from each segment's `SaveAt(ts=...)`, with the times before the segment's
start clipped to it (diffrax wants them inside [t0, t1]); those entries were saved by an
earlier segment and are kept. A new case starts with the same step size, controller state and
solver state `diffeqsolve` gives a fresh run. A lane rebuilds its case's mechanism from the
parameters in every segment rather than carrying it: XLA fuses parts of the mechanism's
construction into the step's arithmetic, so a carried mechanism rounds differently from a
plain run (measured: 3e-21 m/s after two steps, then amplified).

What equals what (tests/test_lanes.py). Pausing and resuming changes nothing: a case paused
every 3 steps equals, bit for bit, the same case integrated in one segment. Against a plain
vmapped batch and against the case alone, a refilled case takes the same steps and agrees to
round-off, not bit for bit: XLA's CPU code for a batched operation can round a case
differently with the batch's size and the case's position in it (a plain vmap of 2 and of 8
cases agree bit for bit; a case alone and in a vmap do not), and the same holds across these
programs. Contact dynamics amplify such last-bit differences to the tolerance's level, as
between any two layouts: on deploy_array (Tsit5, 0-5 ms) 8 cases in 3 lanes matched their
vmapped run bit for bit, with generalized-α 6 of 8, the others within 6e-11 m and a step or
two, against up to 2e-10 m and up to 78 steps (Tsit5) between a case alone and in a vmap.

A case's `max_steps` is checked at the end of each segment: a case that reaches it fails with
diffrax's `max_steps_reached` after up to `segment_steps - 1` steps more than `simulate`
takes. Not differentiable (a forward batch: no `replay_steps`, no progress bar). Fixed-step
runs take the same number of steps in every case, so they gain nothing from refilling: they
run as vmapped groups of `L` (`jax.lax.map(batch_size=L)`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping

import diffrax as dfx
import equinox as eqx
import equinox.internal as eqxi
import jax
import jax.numpy as jnp

from .simulation import Trajectory, integrate, simulate, solver_stats
from .simulation import prepare as prepare_run
from .solvers import MechanismState, MechanismTerm, tracked_extremes
from .solvers.wrapped_controller import WrappedController

# The options of `simulate` a lane-refilled batch accepts (the rest concern differentiation or
# display: `replay_steps`, `adjoint`, `progress`).
LANE_OPTIONS = (
    "control",
    "t0",
    "dt",
    "rtol",
    "atol",
    "dt_min",
    "dt_max",
    "max_steps",
    "solver",
    "step_ts",
    "locate_events",
    "extreme_samples",
)
DEFAULT_SEGMENT_STEPS = 8


def check_lanes(lanes, segment_steps=DEFAULT_SEGMENT_STEPS) -> None:
    """Refuse a lane count or segment length that is not a positive integer, by name."""
    if not (isinstance(lanes, int) and not isinstance(lanes, bool) and lanes >= 1):
        raise ValueError(f"lanes = {lanes!r} is invalid: it must be an integer ≥ 1")
    if not (
        isinstance(segment_steps, int)
        and not isinstance(segment_steps, bool)
        and segment_steps >= 1
    ):
        raise ValueError(f"segment_steps = {segment_steps!r} is invalid: it must be an integer ≥ 1")


def check_lane_options(options: Mapping) -> None:
    """Refuse `simulate` options a lane-refilled batch cannot honour, naming them."""
    unknown = sorted(set(options) - set(LANE_OPTIONS))
    if unknown:
        raise ValueError(
            f"lanes: option(s) {', '.join(unknown)} are not supported with lane refilling "
            f"(supported: {', '.join(LANE_OPTIONS)}); run without lanes (e.g. group_size)"
        )


def _clip_floor(t1):
    """t1 - 100 ULPs, diffrax's threshold for rounding the next step's end to t1."""
    floor = t1
    for _ in range(100):
        floor = eqxi.prevbefore(floor)
    return floor


def _next_step_end(t, proposed, t_end, t_end_floor, keep):
    """The end of the next step after a step that reached `t`, as diffrax's loop sets it: the
    controller's `proposed` end, unless it lies within ~100 ULPs of `t_end` (past
    `t_end_floor`), when it is `t_end` after an accepted step and the midpoint of what is
    left after a rejected one (no sliver of a step for the dense output to divide by)."""
    near_end = proposed > t_end_floor
    clipped = jnp.where(keep, t_end, t + 0.5 * (t_end - t))
    return jnp.where(near_end, clipped, proposed)


class _Resume(WrappedController):
    """Wraps the run's step-size controller so that a solve starts with a given next step end
    `t_next` and controller state (`init`), and records in its state the raw proposal and the
    keep decision of every step (`adapt_step_size`), from which the next segment's `t_next`
    follows. Otherwise it is the wrapped controller."""

    controller: dfx.AbstractAdaptiveStepSizeController
    t_next: jax.Array
    state: object

    def init(self, terms, t0, t1, y0, dt0, args, func, error_order):
        return self.t_next, (self.state, self.t_next, jnp.array(True))

    def adapt_step_size(self, t0, t1, y0, y1_candidate, args, y_error, error_order, state):
        inner, _, _ = state
        keep, next_t0, next_t1, made_jump, inner, result = self.controller.adapt_step_size(
            t0, t1, y0, y1_candidate, args, y_error, error_order, inner
        )
        return keep, next_t0, next_t1, made_jump, (inner, next_t1, jnp.asarray(keep)), result


class _Lane(eqx.Module):
    """One lane: the case it runs (`n_cases`: none) and that case's integration so far."""

    case: jax.Array
    item: object
    y: MechanismState
    t: jax.Array
    t_next: jax.Array
    solver_state: object
    controller_state: object
    made_jump: jax.Array
    steps: jax.Array
    accepted: jax.Array
    rejected: jax.Array
    ts: jax.Array
    ys: MechanismState


def simulate_in_lanes(
    prepare: Callable,
    items,
    t_end,
    ts,
    *,
    lanes: int,
    segment_steps: int = DEFAULT_SEGMENT_STEPS,
    options: Mapping | None = None,
) -> Trajectory:
    """Integrate every case in `lanes` lanes refilled from the pending cases (module docstring).

    **Arguments:**
    - `prepare(item) -> (mechanism, initial)`: one case's mechanism and consistent initial
      state (traced, vmapped over the cases).
    - `items`: a pytree whose leaves have a leading case axis B (e.g. the varied parameters).
    - `t_end`, `ts`: end time and output times, shared by every case.
    - `lanes`: cases integrated side by side (vmapped); `segment_steps`: steps per segment.
    - `options`: `simulate`'s step control and solver (`LANE_OPTIONS`).

    **Returns:** a `Trajectory` with leading axis B, case `i` as `simulate` returns it.
    """
    options = dict(options or {})
    check_lanes(lanes, segment_steps)
    check_lane_options(options)
    ts = jnp.asarray(ts, dtype=float)
    n_cases = jax.tree.leaves(items)[0].shape[0]
    lanes = min(lanes, n_cases)

    def setup(mechanism, initial):
        return prepare_run(mechanism, initial, t_end, ts=ts, **options)

    def take(tree, index):
        return jax.tree.map(lambda leaf: leaf[index], tree)

    probe = setup(*prepare(take(items, 0)))
    if not isinstance(probe.controller, dfx.AbstractAdaptiveStepSizeController):
        # Fixed steps: every case takes the same steps, nothing idles; vmapped groups of
        # plain `simulate` runs.
        def fixed(item):
            return simulate(*prepare(item), t_end, ts=ts, **options)

        return jax.lax.map(fixed, items, batch_size=lanes)

    t_end, max_steps = probe.t_end, probe.max_steps
    t1_floor = _clip_floor(t_end)
    n_ts = ts.shape[0]

    def fresh(case):
        """Lane state for the start of `case` (as `diffeqsolve` initialises a run)."""
        item = take(items, case)
        mechanism, initial = prepare(item)
        run = setup(mechanism, initial)
        terms = MechanismTerm(mechanism)
        t_next, controller_state = run.controller.init(
            terms,
            run.t0,
            run.t_end,
            run.y0,
            run.dt0,
            None,
            run.solver.func,
            run.solver.error_order(terms),
        )
        t_next = jnp.minimum(t_next, run.t_end)
        solver_state = run.solver.init(terms, run.t0, t_next, run.y0, None)
        zero = jnp.array(0)
        return _Lane(
            case=case,
            item=item,
            y=run.y0,
            t=run.t0,
            t_next=t_next,
            solver_state=solver_state,
            controller_state=controller_state,
            made_jump=jnp.array(False),
            steps=zero,
            accepted=zero,
            rejected=zero,
            ts=jnp.full(n_ts, jnp.inf),
            ys=jax.tree.map(lambda x: jnp.full((n_ts, *jnp.shape(x)), jnp.inf), run.y0),
        )

    def segment(lane):
        """Up to `segment_steps` steps of the lane's case; returns the lane and its result."""
        active = lane.case < n_cases
        # The mechanism is rebuilt from the case's parameters (cheap, once per segment) rather
        # than carried: then the compiler sees the same program as a plain vmapped run (it may
        # fuse parts of the mechanism's construction into the step, changing the last bits).
        mechanism, _ = prepare(lane.item)
        run = setup(mechanism, MechanismState(*lane.y))
        start = jnp.where(active, lane.t, run.t_end)  # an idle lane takes no step
        controller = _Resume(run.controller, lane.t_next, lane.controller_state)
        sol = integrate(
            mechanism,
            lane.y,
            start,
            run.t_end,
            run.dt0,
            run.solver,
            controller,
            segment_steps,
            saveat=dfx.SaveAt(
                subs=[dfx.SubSaveAt(ts=jnp.maximum(run.ts, start)), dfx.SubSaveAt(t1=True)],
                solver_state=True,
                controller_state=True,
                made_jump=True,
            ),
            solver_state=lane.solver_state,
            made_jump=lane.made_jump,
            adjoint=run.adjoint,
        )
        (saved_ts, end_ts), (saved_ys, end_ys) = sol.ts, sol.ys
        t = end_ts[0]
        inner, t_proposed, keep = sol.controller_state
        done_before = jnp.isfinite(lane.ts)  # saved by an earlier segment: keep

        def merge(old, new):
            mask = done_before.reshape((-1,) + (1,) * (old.ndim - 1))
            return jnp.where(mask, old, new)

        stepped = _Lane(
            case=lane.case,
            item=lane.item,
            y=jax.tree.map(lambda leaf: leaf[0], end_ys),
            t=t,
            t_next=_next_step_end(t, t_proposed, run.t_end, t1_floor, keep),
            solver_state=sol.solver_state,
            controller_state=inner,
            made_jump=jnp.asarray(sol.made_jump),
            steps=lane.steps + sol.stats["num_steps"],
            accepted=lane.accepted + sol.stats["num_accepted_steps"],
            rejected=lane.rejected + sol.stats["num_rejected_steps"],
            ts=jnp.where(done_before, lane.ts, saved_ts),
            ys=jax.tree.map(merge, lane.ys, saved_ys),
        )
        lane = jax.tree.map(lambda new, old: jnp.where(active, new, old), stepped, lane)
        over_budget = lane.steps >= run.max_steps
        paused = sol.result == dfx.RESULTS.max_steps_reached
        # Paused by the segment's step limit with budget left: the case continues.
        finished = active & (~paused | over_budget)
        return lane, finished, sol.result

    def outputs_of(lane, result):
        stats = solver_stats(
            {
                "num_steps": lane.steps,
                "num_accepted_steps": lane.accepted,
                "num_rejected_steps": lane.rejected,
                "max_steps": jnp.array(max_steps),
            },
            lane.solver_state,
        )
        return lane.ts, lane.ys, result, stats, lane.t, tracked_extremes(lane.solver_state)

    first = jax.vmap(fresh)(jnp.arange(lanes))
    no_result = jax.vmap(lambda _: dfx.RESULTS.successful)(jnp.zeros(lanes))
    blank = jax.tree.map(
        lambda leaf: jnp.zeros((n_cases, *leaf.shape[1:]), leaf.dtype),
        jax.eval_shape(jax.vmap(outputs_of), first, no_result),
    )

    def cond(carry):
        lanes_state, _, _ = carry
        return jnp.any(lanes_state.case < n_cases)

    def body(carry):
        lanes_state, next_case, out = carry
        lanes_state, finished, result = jax.vmap(segment)(lanes_state)
        # Write finished cases into the outputs (other lanes' rows are dropped).
        rows = jnp.where(finished, lanes_state.case, n_cases)
        out = jax.tree.map(
            lambda all_, new: all_.at[rows].set(new, mode="drop"),
            out,
            jax.vmap(outputs_of)(lanes_state, result),
        )
        # Finished lanes take the next pending cases, in case order.
        new_case = next_case + jnp.cumsum(finished) - 1
        refill = finished & (new_case < n_cases)

        def load(lanes_state):
            loaded = jax.vmap(fresh)(jnp.minimum(new_case, n_cases - 1))
            return jax.tree.map(
                lambda new, old: jnp.where(refill.reshape((-1,) + (1,) * (old.ndim - 1)), new, old),
                loaded,
                lanes_state,
            )

        lanes_state = jax.lax.cond(jnp.any(refill), load, lambda s: s, lanes_state)
        lanes_state = eqx.tree_at(
            lambda s: s.case,
            lanes_state,
            jnp.where(finished & ~refill, n_cases, lanes_state.case),
        )
        return lanes_state, next_case + jnp.sum(refill), out

    _, _, (saved_ts, saved_ys, result, stats, t_reached, extremes) = jax.lax.while_loop(
        cond, body, (first, jnp.array(lanes), blank)
    )
    return Trajectory.from_states(
        saved_ts, saved_ys, result, stats, t_reached=t_reached, extremes=extremes
    )
