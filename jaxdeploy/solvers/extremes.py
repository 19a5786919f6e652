"""`TrackExtremes`: a run's extremes (largest contact force and penetration per clearance joint,
acceleration extremes) folded over every accepted step, whatever the output times.

A maximum over saved states is a maximum over the output grid: an impact's force peak lasts
tens of microseconds and falls between saved times (deploy_array, default run: 501 saved
states saw 27 % of the largest contact force, 20001 saved states 96 %; docs/
output_extremes.md). The wrapper evaluates
`jaxdeploy.mechanism.extremes_at` at the end of every step the solver takes and folds it into
its state; diffrax keeps the previous solver state for a rejected step, so only accepted steps
count, and the result is the same for every choice of output times.

A step end can miss a peak inside the step. For a peak of duration T (F ≈ F_max (1 − c (t −
t_p)²/T²) near it, c ≈ 7 for a Hertz pulse) sampled every h the miss is up to c h²/(4 T²): a
long explicit step in an impact matters. Measured at the default tolerances against 4
interior samples per step (docs/output_extremes.md, `experiments/extremes_sampling.py`): step
ends alone miss up to 1e-4 (slider_crank, generalized-α: its default), 5.5e-3 (deploy_array,
Tsit5: its default; a panel's acceleration) and 2.6e-3 (slider_crank with Tsit5). So each
step's midpoint is sampled too (`samples = 1`; misses 4e-6, 1.4e-3, 2.6e-3), on the step's
dense output: the contact quantities at the interpolated state, and the accelerations as the
time derivative of the interpolated velocity — on slider_crank (Tsit5) the extreme found so
differed by 6e-6 from the one found by solving the equations of motion at the midpoint, which
costs four times as much (XLA's operation count for a deploy_array step: +7 % for the
midpoint sample, +29 % with an acceleration solve).

The clearance joints' largest normal force and penetration are then refined: `simulate` takes
the larger of these samples and the maximum on each contact step's dense output that the
episode log finds (`jaxdeploy.solvers.episodes.step_maxima`), so `Trajectory.extremes` holds
the true maximum within the step for them (sampled alone, a pendulum's impact peak was reported
0.09 % low at a tight tolerance in issue 31; the refined one matches Johnson's closed form to
1e-8, tests/test_episodes.py).

The accelerations at a step's end are the solver's own (`y1.qdd`): for the index-1 path the
equations of motion at that state; for generalized-α its q̈ = β' u, which differs from them
by the step's Newton error times β' ~ 1/h² (1e-5 relative on the pendulum at h = 1 ms).
"""

from __future__ import annotations

from typing import ClassVar, NamedTuple

import diffrax as dfx
import equinox as eqx
import jax
import jax.numpy as jnp

from .._tracing import traced_once
from ..mechanism import extremes_at, merge_extremes
from .episodes import DEFAULT_CAPACITY, init_log, log_step
from .term import MechanismTerm, mechanism_of


class TrackedState(NamedTuple):
    """The wrapped solver's state, the extremes so far (`extremes_at`'s keys) and the
    clearance joints' contact episodes so far (`jaxdeploy.solvers.episodes.EpisodeLog`, None
    without clearance joints)."""

    inner: object
    extremes: dict
    episodes: object = None


class TrackExtremes(dfx.AbstractWrappedSolver):
    """Wraps a mechanism solver (`GeneralizedAlpha`, `MechanismODESolver`) and tracks the
    run's extremes in its state (module docstring); the steps are the wrapped solver's, bit
    for bit. `simulate` wraps every solver in it.

    **Arguments:**
    - `solver`: the solver to wrap.
    - `samples`: equally spaced interior points of each step's dense output evaluated as
      well (static; default 1, the midpoint; 0: step ends only).
    - `episode_capacity`: contact episodes kept per clearance joint
      (`jaxdeploy.solvers.episodes`; static).
    """

    solver: dfx.AbstractSolver
    samples: int = eqx.field(static=True, default=1)
    episode_capacity: int = eqx.field(static=True, default=DEFAULT_CAPACITY)

    term_structure: ClassVar = MechanismTerm

    def __check_init__(self):
        if not (isinstance(self.samples, int) and self.samples >= 0):
            raise ValueError(f"samples = {self.samples!r} is invalid: it must be an integer ≥ 0")

    @property
    def interpolation_cls(self):
        return self.solver.interpolation_cls

    def order(self, terms):
        return self.solver.order(terms)

    def error_order(self, terms):
        return self.solver.error_order(terms)

    def init(self, terms, t0, t1, y0, args):
        mech = mechanism_of(terms)
        extremes = extremes_at(mech, y0.q, y0.v, y0.qdd, y0.memory)
        episodes = init_log(mech, t0, y0, self.episode_capacity)
        return TrackedState(self.solver.init(terms, t0, t1, y0, args), extremes, episodes)

    def func(self, terms, t0, y0, args):
        return self.solver.func(terms, t0, y0, args)

    def step(self, terms, t0, t1, y0, args, solver_state, made_jump):
        y1, y_error, dense_info, inner, result = self.solver.step(
            terms, t0, t1, y0, args, solver_state.inner, made_jump
        )
        mech = mechanism_of(terms)
        extremes = merge_extremes(
            solver_state.extremes, extremes_at(mech, y1.q, y1.v, y1.qdd, y1.memory)
        )
        dense = self.interpolation_cls(t0=t0, t1=t1, **dense_info)
        episodes = log_step(
            solver_state.episodes,
            mech,
            t0,
            t1,
            y0,
            y1,
            lambda t: _motion(dense, t),
            self.episode_capacity,
        )
        if self.samples:

            def velocity(t):
                return _motion(dense, t)[1]

            for k in range(1, self.samples + 1):
                t = t0 + (t1 - t0) * (k / (self.samples + 1))
                q, v, memory = _motion(dense, t)
                qdd = jax.jvp(velocity, (t,), (jnp.ones_like(t),))[1]
                extremes = merge_extremes(extremes, extremes_at(mech, q, v, qdd, memory))
        return y1, y_error, dense_info, TrackedState(inner, extremes, episodes), result


@traced_once
def _motion(dense, t):
    """`(q, q̇, memory)` of a dense output at `t`: its `motion` (no acceleration solve) where
    it has one, else its `evaluate` (whose q̈ is left unused). Traced once per program: a
    step evaluates it at its midpoint and, for each clearance joint in contact, at the
    episode log's samples and parabolic steps (`episodes.step_maxima`), each in each of
    diffrax's three traces of the step; the Runge–Kutta interpolant was a third of tracing
    slider_crank's run."""
    if hasattr(dense, "motion"):
        return dense.motion(t)
    y = dense.evaluate(t)
    return y.q, y.v, y.memory


def tracked_extremes(solver_state) -> dict | None:
    """The extremes in a final solver state (`TrackedState`), or None if it has none."""
    if isinstance(solver_state, TrackedState):
        return solver_state.extremes
    return None


def tracked_episodes(solver_state):
    """The contact-episode log in a final solver state (`TrackedState`), or None."""
    if isinstance(solver_state, TrackedState):
        return solver_state.episodes
    return None


def untracked(solver_state):
    """The wrapped solver's own state."""
    return solver_state.inner if isinstance(solver_state, TrackedState) else solver_state
