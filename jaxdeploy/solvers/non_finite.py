"""Stop a run whose steps produce non-finite values, at the time it reached.

diffrax replaces a NaN error estimate by infinity, so an adaptive controller rejects the step
and shrinks the next one (`diffrax/_integrate.py`). That is right for a step too long for a
stiff contact, which a shorter step repairs, and useless when the vector field itself is NaN
(a NaN parameter, a force law evaluated outside its domain): then every step is rejected, or
steps shrink towards the point where the field turns NaN without ever passing it, until
`max_steps` (2e6 by default; minutes of stepping) ends the run with a message that names the
wrong cause. With constant steps nothing is rejected at all: the NaN state is accepted and
integrated to the end, and the run reports success.

`StopAtNonFinite` wraps the run's step-size controller and ends the run with
`RESULTS.nonfinite` at the step's start, the last finite state:

* fixed steps (`ConstantStepSize`, `ReplaySteps`): as soon as a step's state (q, q̇, q̈, λ) is
  not finite;
* adaptive steps: when the state or the error estimate is not finite although the step is
  already shorter than `1024 ε max(|t₀|, |t₁|, time_scale)` (ε the float64 machine epsilon;
  2e-13 of the run's time span): a step that short changes nothing a shorter one would, so
  the field is non-finite at the step's start itself. Longer non-finite steps are left to
  the wrapped controller (rejected and shortened, as before).

Memory is not checked (a meter may legitimately hold ±inf, e.g. the smallest step so far).
"""

from __future__ import annotations

import diffrax as dfx
import jax
import jax.numpy as jnp

from .term import MechanismState
from .wrapped_controller import WrappedController

# Steps shorter than this many ulps of the time span are "as short as steps get".
_ULPS = 1024.0
# The factor a retried non-finite step is shortened by (diffrax's PIDController's `factormin`).
_SHRINK = 0.2


def _finite_state(y: MechanismState):
    leaves = jax.tree.leaves((y.q, y.v, y.qdd, y.lam))
    return jnp.all(jnp.stack([jnp.all(jnp.isfinite(leaf)) for leaf in leaves]))


def _finite_tree(tree):
    leaves = [leaf for leaf in jax.tree.leaves(tree) if jnp.size(leaf)]
    if not leaves:
        return jnp.array(True)
    return jnp.all(jnp.stack([jnp.all(jnp.isfinite(leaf)) for leaf in leaves]))


def _stopped(give_up, outcome, t0, t1, state):
    """The wrapped controller's `outcome`, overridden where `give_up`: the step is rejected,
    the run stays at `t0` and ends with `RESULTS.nonfinite`."""
    keep, next_t0, next_t1, made_jump, next_state, result = outcome
    return (
        keep & ~give_up,
        jnp.where(give_up, t0, next_t0),
        jnp.where(give_up, t1, next_t1),
        made_jump,
        next_state,
        dfx.RESULTS.where(give_up, dfx.RESULTS.nonfinite, result),
    )


class _StopAdaptive(WrappedController):
    controller: dfx.AbstractAdaptiveStepSizeController
    time_scale: jax.Array

    def init(self, terms, t0, t1, y0, dt0, args, func, error_order):
        return self.controller.init(terms, t0, t1, y0, dt0, args, func, error_order)

    def adapt_step_size(self, t0, t1, y0, y1_candidate, args, y_error, error_order, state):
        outcome = self.controller.adapt_step_size(
            t0, t1, y0, y1_candidate, args, y_error, error_order, state
        )
        keep, next_t0, next_t1, made_jump, next_state, result = outcome
        h = jax.lax.stop_gradient(t1 - t0)
        scale = jnp.maximum(jnp.maximum(jnp.abs(t0), jnp.abs(t1)), self.time_scale)
        shortest = _ULPS * jnp.finfo(jnp.result_type(h)).eps * scale
        finite_state = _finite_state(y1_candidate)
        give_up = (~finite_state | ~_finite_tree(y_error)) & (h <= shortest)
        # A non-finite state whose error estimate is finite (e.g. accelerations evaluated
        # after the step) would be accepted by the wrapped controller: retry it shorter, as
        # the controller does a step with a non-finite error estimate.
        retry = keep & ~finite_state & ~give_up
        outcome = (
            keep & ~retry,
            jnp.where(retry, t0, next_t0),
            jnp.where(retry, t0 + _SHRINK * h, next_t1),
            made_jump,
            jax.tree.map(lambda old, new: jnp.where(retry, old, new), state, next_state),
            result,
        )
        return _stopped(give_up, outcome, t0, t1, state)


class _StopFixed(dfx.AbstractStepSizeController):
    controller: dfx.AbstractStepSizeController

    def wrap(self, direction):
        return _StopFixed(self.controller.wrap(direction))

    def init(self, terms, t0, t1, y0, dt0, args, func, error_order):
        return self.controller.init(terms, t0, t1, y0, dt0, args, func, error_order)

    def adapt_step_size(self, t0, t1, y0, y1_candidate, args, y_error, error_order, state):
        outcome = self.controller.adapt_step_size(
            t0, t1, y0, y1_candidate, args, y_error, error_order, state
        )
        return _stopped(~_finite_state(y1_candidate), outcome, t0, t1, state)


def stop_at_non_finite(controller, time_scale):
    """`controller` wrapped so that a run stops with `RESULTS.nonfinite` at the last finite
    state (module docstring). `time_scale` [s]: the run's time span (sets the shortest step
    an adaptive run tries before giving up). The wrapper passes the wrapped controller's
    state through unchanged."""
    if isinstance(controller, dfx.AbstractAdaptiveStepSizeController):
        return _StopAdaptive(controller, jnp.asarray(time_scale, dtype=float))
    return _StopFixed(controller)
