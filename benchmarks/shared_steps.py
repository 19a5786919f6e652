"""A batch whose cases share one step sequence, against the plain vmap (issue 32: "try a batch
mode in which all cases share one step size (no masked lanes) and report its cost").

A vmapped adaptive run lets every case choose its own steps: the batched while loop then runs
until its slowest case is done, and at each iteration every lane computes a step whether its
case still needs one or not (its result masked out). Here the cases of a vmap instead take
the same steps: `SharedSteps` wraps the run's step-size controller and, across the vmapped
axis (a named axis: `jax.lax.pmin`), accepts a step only when every case accepts it and
proposes the smallest of the cases' next steps. Every lane then does useful work at every
iteration, but each case takes every other case's small steps too (each case's contact
onsets and its located events become steps of all). Which effect wins is what this measures.

An experiment of the bench, not a mode of the package: it drives `jaxdeploy.simulation`'s
program with its own controller."""

from __future__ import annotations

import diffrax as dfx
import equinox as eqx
import jax
import jax.numpy as jnp

from jaxdeploy.solvers.wrapped_controller import WrappedController

AXIS = "cases"


class SharedSteps(WrappedController):
    """`controller`'s decisions made common to the cases of the vmapped axis `axis_name`:
    a step is kept when every case keeps it (a case that kept it while another did not
    redoes it, its controller state as before the step), and the next step (or the retry)
    is the shortest any case proposes."""

    controller: dfx.AbstractAdaptiveStepSizeController
    axis_name: str = eqx.field(static=True, default=AXIS)

    def init(self, terms, t0, t1, y0, dt0, args, func, error_order):
        tnext, state = self.controller.init(terms, t0, t1, y0, dt0, args, func, error_order)
        return t0 + jax.lax.pmin(tnext - t0, self.axis_name), state

    def adapt_step_size(self, t0, t1, y0, y1_candidate, args, y_error, error_order, state):
        keep, next_t0, next_t1, made_jump, next_state, result = self.controller.adapt_step_size(
            t0, t1, y0, y1_candidate, args, y_error, error_order, state
        )
        every = jax.lax.pmin(jnp.asarray(keep, jnp.int32), self.axis_name) > 0
        length = jax.lax.pmin(next_t1 - next_t0, self.axis_name)
        start = jnp.where(every, t1, t0)
        # A case that kept a step the others did not keeps its controller's state as it was.
        undone = jnp.asarray(keep) & ~every
        next_state = jax.tree.map(lambda new, old: jnp.where(undone, old, new), next_state, state)
        if made_jump is not False:
            made_jump = jax.lax.pmax(jnp.asarray(made_jump, jnp.int32), self.axis_name) > 0
        return every, start, start + length, made_jump, next_state, result


def shared_steps_function(scene, shared: dict, varied: str, t_end: float, ts, outputs="all"):
    """A jitted function of the `(B,)` values of parameter `varied`: the B cases of `scene`
    (the other parameters `shared`, the scene's default step control) run as one vmap whose
    cases share their steps (`SharedSteps`). Returns the batch's accepted and rejected step
    counts and saved positions (what the bench compares with the plain vmap)."""
    from jaxdeploy.simulation import _solve, prepare

    control = scene.default_control

    def one(value):
        params = {**shared, varied: value}
        mechanism = scene.build(params)
        initial = scene.initial_state(params, mechanism)
        run = prepare(mechanism, initial, t_end, ts=ts, control=control)
        sol = _solve(
            mechanism, run.y0, run.t0, run.t_end, run.dt0, run.ts, run.solver,
            SharedSteps(run.controller), run.max_steps, False, run.adjoint, outputs,
        )  # fmt: skip
        return sol.ys.q, sol.stats["num_accepted_steps"], sol.stats["num_rejected_steps"]

    return jax.jit(jax.vmap(one, axis_name=AXIS))
