"""Event location by step relocation: an adaptive step that a memory event (a clearance
joint's contact onset, a peak of its approach speed that raises v⁻, or its separation, where
v⁻ resets) falls inside is redone so that it ends just past the event.

Why. A clearance joint's damping needs v⁻, the approach speed at contact onset, which is memory
taken after each accepted step from δ = |e| − c on the step's cubic Hermite interpolant of the
eccentricity e (`jaxdeploy.mechanism.clearance`). Inside a step that crosses the onset, δ(t) is
not that interpolant's: a Hertz force K δ^1.5 adds a term ∝ (t − t_on)^3.5, so the interpolated
onset speed carries an error ∝ (K/m) v^1.5 (h_c)^2.5, where h_c is the part of the step spent in
contact. No step-size controller sees that error (it is in the memory, not in the state), so a
tighter tolerance stops improving the solution at about that level (measured on slider_crank,
docs/performance.md). Ending the step just past the onset makes h_c a small fraction of the
step and the memory error negligible: the usual remedy for a discontinuity inside a step,
locating it and stepping onto it (Hairer, Nørsett & Wanner, *Solving ODEs I*, §II.6, "dense
output and discontinuities"; Shampine & Thompson, *Appl. Numer. Math.* 36 (2001) 403, event
location in ODE solvers). Unlike a terminal event with a restart, the solver never stops: the
step is rejected and retried with the length that ends at the located event.

Rule, with s the event (onset or peak) as a fraction of the step (`Mechanism.event_fraction`,
located on the step's interpolant):

* `s ≤ lead`: the contact began at the step's start, where the interpolant matches the exact
  δ and δ̇ — keep the step;
* `s ≥ 1 − tail`: the step spent at most a fraction `tail` of itself in contact — keep it;
* otherwise reject it and retry from the same start with length `s (1 + overshoot) h`, which
  ends past the onset by `overshoot` of the located position (far more than the error of the
  located position on any step the controller accepts). The retried step locates the onset
  again on its own interpolant and keeps it (its s is about 1 − overshoot); if it falls short of
  the onset, the next step starts just before it (s ≈ 0) and is kept.

The step-size controller's own history is left as it was before the rejected attempt.
"""

from __future__ import annotations

import diffrax as dfx
import equinox as eqx
import jax
import jax.numpy as jnp

from ..mechanism import Mechanism
from .wrapped_controller import WrappedController


class LocateEvents(WrappedController):
    """Wraps an adaptive step-size controller so that steps end just past the mechanism's
    memory events (module docstring).

    **Arguments:**
    - `controller`: the adaptive controller to wrap (e.g. `diffrax.PIDController`).
    - `mechanism`: the mechanism being integrated; its `event_fraction` must not be `None`.
    - `lead`, `tail`: the fractions of a step (at its start, at its end) where an event is
      accepted as it is.
    - `overshoot`: a retried step ends at `s (1 + overshoot)` of the rejected one.
    - `dt_min`: no retried step shorter than this [s] (the wrapped controller's lower bound).
    """

    controller: dfx.AbstractAdaptiveStepSizeController
    mechanism: Mechanism
    lead: float = eqx.field(static=True, default=1e-3)
    tail: float = eqx.field(static=True, default=1e-2)
    overshoot: float = eqx.field(static=True, default=1e-3)
    dt_min: float | None = None

    def init(self, terms, t0, t1, y0, dt0, args, func, error_order):
        return self.controller.init(terms, t0, t1, y0, dt0, args, func, error_order)

    def adapt_step_size(self, t0, t1, y0, y1_candidate, args, y_error, error_order, state):
        keep, next_t0, next_t1, made_jump, next_state, result = self.controller.adapt_step_size(
            t0, t1, y0, y1_candidate, args, y_error, error_order, state
        )
        # Step decisions carry no derivative (the step sizes are not differentiated).
        s = jax.lax.stop_gradient(self.mechanism.event_fraction(y1_candidate.memory))
        h = jax.lax.stop_gradient(t1 - t0)
        retry_length = s * (1.0 + self.overshoot) * h
        inside = (s > self.lead) & (s < 1.0 - self.tail)
        if self.dt_min is not None:
            inside = inside & (retry_length >= self.dt_min)
        relocate = keep & inside
        next_t0 = jnp.where(relocate, t0, next_t0)
        next_t1 = jnp.where(relocate, t0 + retry_length, next_t1)
        if made_jump is not False:  # a static False (PID's) stays static: a relocated step
            made_jump = jnp.where(relocate, False, made_jump)  # makes no jump either
        next_state = jax.tree.map(lambda new, old: jnp.where(relocate, old, new), next_state, state)
        return keep & ~relocate, next_t0, next_t1, made_jump, next_state, result
