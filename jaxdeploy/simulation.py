"""`simulate`: integrate a mechanism from a consistent state and report what happened.

An integration loop for the mechanism's solvers (`jaxdeploy.solvers.loop`, bit for bit
`diffrax.diffeqsolve`'s run from a smaller program) with the generalized-α solver or the index-1
ODE path (`solver="kvaerno5"` etc., see `jaxdeploy.solvers.SOLVER_NAMES`): fixed step (give
`dt`) or adaptive (give `rtol`/`atol`), outputs at chosen times, solver statistics, and a
status that says when and why a run failed (never silent NaN).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, replace
from typing import NamedTuple

import diffrax as dfx
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from . import _program_cache
from ._collector import deferring_full_collections
from ._validation import float_data, is_concrete
from .mechanism import ConsistentState, Mechanism
from .solvers import (
    EpisodeLog,
    GeneralizedAlpha,
    LocateEvents,
    MechanismODESolver,
    MechanismState,
    MechanismTerm,
    StepControl,
    TrackedState,
    TrackExtremes,
    loop,
    state_norm,
    stop_at_non_finite,
    tracked_episodes,
    tracked_extremes,
    untracked,
)
from .solvers.episodes import DEFAULT_CAPACITY as DEFAULT_EPISODE_CAPACITY
from .solvers.episodes import FIELDS as EPISODE_FIELDS
from .solvers.episodes import UNITS as EPISODE_UNITS
from .solvers.step_control import DEFAULT_MAX_STEPS, default_control, warn_solver_choice
from .solvers.term import accelerations_at

__all__ = [
    "ContactEpisodes",
    "PreparedRun",
    "StepControl",
    "Trajectory",
    "integrate",
    "prepare",
    "simulate",
]


def result_code(result) -> np.ndarray:
    """The integer code of a diffrax `RESULTS` item (`successful` is 0), as a NumPy array.

    Comparing two items with `==` is a JAX operation, which a process compiles on its first
    use (a few ms of a cached first call); the code compares in NumPy. A concrete result only
    (under a transformation, compare the items)."""
    return np.asarray(result._value)


class Trajectory(eqx.Module):
    """Saved states and run statistics.

    `ts` (N,), `q`, `v`, `qdd` (N, n), `lam` (N, m), `memory` (pytree, leading axis N);
    `qdd` and `lam` are None for `simulate(..., outputs="state")`, and `memory` too for
    `outputs="motion"`;
    `result` (a diffrax RESULTS code), `stats` (steps, accepted, rejected, Newton iterations);
    `step_times`: with `simulate(..., replay_steps=...)`, the ends of the steps taken (padded
    with +inf; pass them as `replay_steps` to integrate other parameters over the same steps),
    otherwise None. `t_reached` [s]: the time the integration reached (`t_end` when it
    succeeded; where it stopped when it failed, which can lie between two saved times);
    `extremes`: the run's extremes over every accepted step, independent of the output times
    (`jaxdeploy.mechanism.extremes_at`: `acceleration_min`/`_max` (n,), and with clearance
    joints `normal_force_max`/`penetration_max` (k,)). Both None for a trajectory assembled
    without them. `episodes`: the clearance joints' contact episodes as logged during the run
    (`jaxdeploy.solvers.EpisodeLog`, JAX arrays; read them with `contact_episodes()`), None
    without clearance joints. `control`: the `StepControl` that ran (after `simulate`'s
    defaults; None for a trajectory assembled without it).
    """

    ts: jax.Array
    q: jax.Array
    v: jax.Array
    qdd: jax.Array
    lam: jax.Array
    memory: tuple
    result: dfx.RESULTS
    stats: dict
    step_times: jax.Array | None = None
    t_reached: jax.Array | None = None
    extremes: dict | None = None
    episodes: EpisodeLog | None = None
    control: StepControl | None = eqx.field(static=True, default=None)

    @classmethod
    def from_states(
        cls, ts, ys, result, stats, *, step_times=None, t_reached=None, extremes=None,
        episodes=None, control=None,
    ) -> Trajectory:  # fmt: skip
        """The trajectory of saved `MechanismState`s `ys` at times `ts` (what `integrate`
        returns for `SaveAt(ts=...)`)."""
        states = (ys.q, ys.v, ys.qdd, ys.lam, ys.memory)
        return cls(ts, *states, result, stats, step_times, t_reached, extremes, episodes, control)

    def contact_episodes(self) -> list[ContactEpisodes]:
        """The contact episodes of each clearance joint, in the order of
        `mechanism.find(RevoluteClearance)` (empty without clearance joints): a
        `ContactEpisodes` per joint, whose fields (numpy arrays over its episodes) are
        `onset_time` [s], `impact_velocity` v⁻ [m/s], `separation_time` [s] (NaN if the contact
        lasts to the end), `peak_force` [N] and `peak_force_time` [s], `peak_penetration` [m]
        and `impulse` [N s] (`jaxdeploy.solvers.episodes` says how each is located). For a
        differentiable version use the JAX arrays of `episodes`."""
        if self.episodes is None:
            return []
        return ContactEpisodes.from_log(self.episodes)

    @property
    def ok(self) -> bool:
        return bool(result_code(self.result) == result_code(dfx.RESULTS.successful))

    def time_reached(self) -> float:
        """The time [s] the integration reached (`t_reached`; for a trajectory without it,
        the last saved time with a finite state)."""
        if self.t_reached is not None:
            return float(self.t_reached)
        ts = np.asarray(self.ts)
        finite = np.isfinite(ts) & np.all(np.isfinite(np.asarray(self.q)), axis=-1)
        return float(ts[finite].max()) if finite.any() else float("nan")

    def status(self) -> str:
        """`"ok"` or a message with the time reached and the reason."""
        if self.ok:
            return "ok"
        # A result taken out of a batch holds a NumPy scalar, which `RESULTS[...]` would call
        # "unknown": as a 0-d array it gets the solver's message, as a single run does.
        result = jax.tree.map(np.asarray, self.result)
        return f"failed after t = {self.time_reached():.6g} s: {dfx.RESULTS[result]}"


@dataclass(frozen=True)
class ContactEpisodes:
    """The contact episodes of one clearance joint (numpy arrays over its episodes, in the
    order they began; units in `UNITS`). `total`: how many episodes the run had (more than
    the arrays hold when it exceeded `simulate`'s `max_episodes`)."""

    onset_time: np.ndarray
    impact_velocity: np.ndarray
    separation_time: np.ndarray
    peak_force: np.ndarray
    peak_force_time: np.ndarray
    peak_penetration: np.ndarray
    impulse: np.ndarray
    total: int

    UNITS = EPISODE_UNITS

    @classmethod
    def from_log(cls, log: EpisodeLog) -> list[ContactEpisodes]:
        """One per joint of an `EpisodeLog`."""
        counts = np.asarray(log.count)
        out = []
        for row, total in enumerate(counts):
            kept = min(int(total), np.asarray(log.onset_time).shape[1])
            fields = {f: np.asarray(getattr(log, f))[row, :kept] for f in EPISODE_FIELDS}
            out.append(cls(**fields, total=int(total)))
        return out

    def __len__(self) -> int:
        return self.onset_time.shape[0]

    @property
    def complete(self) -> bool:
        """Whether every episode of the run is in the arrays."""
        return len(self) == self.total

    def rows(self) -> list[dict]:
        """One dict per episode, `{field: float}`."""
        return [{f: float(getattr(self, f)[i]) for f in EPISODE_FIELDS} for i in range(len(self))]


class ReplaySteps(dfx.AbstractStepSizeController):
    """Step to prescribed times and accept every step: `times` are the ends of the steps
    (increasing, the last one `t_end`), padded at the back with +inf to a fixed length.

    Used to replay the accepted steps of an adaptive run (`simulate(..., replay_steps=True)`),
    so that a differentiated run makes no step decision of its own (see `simulate`). If that
    run failed, its times stop short of `t_end`: the replay then stops there with `failure`
    (the failed run's result), never bridging the gap with one long step.
    """

    times: jax.Array
    failure: dfx.RESULTS

    def wrap(self, direction):
        return self

    def init(self, terms, t0, t1, y0, dt0, args, func, error_order):
        return self.times[0], jnp.array(1)

    def adapt_step_size(self, t0, t1, y0, y1_candidate, args, y_error, error_order, index):
        # Past the last accepted time the padding (+inf) is clipped to t_end by diffrax.
        next_t1 = self.times[jnp.minimum(index, self.times.shape[0] - 1)]
        result = dfx.RESULTS.where(jnp.isfinite(next_t1), dfx.RESULTS.successful, self.failure)
        return True, t1, next_t1, False, index + 1, result


def _inner_scan_kind_for(adjoint, solver):
    """The stage loop of a Runge–Kutta method inside `MechanismODESolver`, set as diffrax sets
    it for a bare one (`diffrax/_adjoint.py`, "Support forward-mode autodiff"): under
    `ForwardMode` a plain `lax` loop, under `DirectAdjoint` a bounded one. Its default, a
    checkpointed loop, is a `custom_vjp`, which forward-mode differentiation cannot enter;
    diffrax's own switch does not see a solver wrapped in ours."""
    if not isinstance(solver, MechanismODESolver):
        return solver
    inner = solver.solver
    if not isinstance(inner, dfx.AbstractRungeKutta) or inner.scan_kind is not None:
        return solver
    kind = {dfx.ForwardMode: "lax", dfx.DirectAdjoint: "bounded"}.get(type(adjoint))
    if kind is None:
        return solver
    return replace(solver, solver=replace(inner, scan_kind=kind))


def _stopped_at_non_finite(controller, t0, t_end):
    """`controller`, stopping the run at its last finite state once steps keep producing
    non-finite values (`jaxdeploy.solvers.stop_at_non_finite`, relative to the time scale)."""
    time_scale = jnp.maximum(jnp.abs(t0), jnp.abs(t_end))
    return stop_at_non_finite(controller, jax.lax.stop_gradient(time_scale))


def integrate(mechanism, y0, t0, t_end, dt0, solver, controller, max_steps, **options):
    """`diffrax.diffeqsolve` of the mechanism from `y0` over [t0, t_end], never throwing: a
    failure is reported in the solution's `result`, and a run whose steps keep producing
    non-finite values stops with `RESULTS.nonfinite` at its last finite state
    (`jaxdeploy.solvers.stop_at_non_finite`). `options`: `saveat`, `adjoint`, …

    The lower-level half of `simulate`, for callers that drive the integration themselves
    (e.g. pause and resume runs, or any of diffrax's `SaveAt`): give it the pieces `prepare`
    returns. `simulate` itself integrates with `jaxdeploy.solvers.loop`, whose run is bit for
    bit this one (tests/test_loop.py) from a smaller program."""
    return dfx.diffeqsolve(
        MechanismTerm(mechanism),
        solver,
        t0=t0,
        t1=t_end,
        dt0=dt0,
        y0=y0,
        stepsize_controller=_stopped_at_non_finite(controller, t0, t_end),
        max_steps=max_steps,
        throw=False,
        **options,
    )


@eqx.filter_jit
@deferring_full_collections
def _accepted_step_times(mechanism, y0, t0, t_end, dt0, solver, controller, max_steps):
    """The ends of the accepted steps of an adaptive run (padded with +inf to `max_steps`),
    and the run's result."""
    sol = loop.solve(
        MechanismTerm(mechanism),
        solver,
        _stopped_at_non_finite(controller, t0, t_end),
        t0,
        t_end,
        dt0,
        y0,
        max_steps,
        save_steps=True,
    )
    return sol.step_ts, sol.result


def _replay_times(times, t0, t_end):
    """Step end times given to `replay_steps`, checked when concrete (1-D, increasing, in
    (t0, t_end], the last finite one t_end, then only +inf padding) and stripped of the
    padding."""
    times = jnp.asarray(times, dtype=float)
    if is_concrete((times, t0, t_end)):
        values = np.asarray(times)
        finite = values[np.isfinite(values)]
        n = finite.size
        if (
            values.ndim != 1
            or n == 0
            or not np.all(np.isposinf(values[n:]))
            or np.any(np.diff(finite) <= 0)
            or finite[0] <= float(t0)
            or finite[-1] != float(t_end)
        ):
            raise ValueError(
                "replay_steps is invalid: step end times must be a 1-D increasing array in "
                f"(t0, t_end] = ({float(t0):g}, {float(t_end):g}] s ending at t_end, padded "
                "with +inf only (e.g. a run's Trajectory.step_times)"
            )
        times = times[:n]
    return times


def _save_times(t0, t_end, n_save, ts):
    """Output times, checked here (in Python, when concrete) rather than by diffrax's runtime
    checks, which may be compiled out (see jaxdeploy/_compilation_cache.py)."""
    if is_concrete((t0, t_end)) and not float(t_end) > float(t0):
        raise ValueError(f"t_end = {t_end!r} is invalid: it must be > t0 = {t0!r} (s)")
    if ts is not None:
        ts = float_data(ts)
        if is_concrete((ts, t0, t_end)):
            values = np.asarray(ts)
            if values.ndim != 1 or values.size == 0:
                raise ValueError(f"ts has shape {values.shape}: it must be a non-empty 1-D array")
            if np.any(np.diff(values) < 0) or not np.all(np.isfinite(values)):
                raise ValueError("ts is invalid: save times must be finite and non-decreasing")
            if values[0] < float(t0) or values[-1] > float(t_end):
                raise ValueError(
                    f"ts is invalid: save times [{values[0]:g}, {values[-1]:g}] s must lie in "
                    f"[t0, t_end] = [{float(t0):g}, {float(t_end):g}] s"
                )
        return ts
    return jnp.linspace(t0, t_end, n_save)


def _state_only(t, y, args):
    """A saved state without its q̈ and λ (`simulate(..., outputs="state")`): the dense
    output's acceleration solve is then unused and XLA compiles it out."""
    return y._replace(qdd=None, lam=None)


def _motion_only(t, y, args):
    """A saved state's q and q̇ alone (`simulate(..., outputs="motion")`)."""
    return y._replace(qdd=None, lam=None, memory=None)


def _acceleration_inputs(t, y, args):
    """A saved state as `outputs="all"` with `batch_saved_accelerations` keeps it in the loop
    (`_dense_acceleration_inputs`), from the state itself (the state at t₀ when t₀ = t₁)."""
    return y._replace(qdd=None, lam=None), y.memory


def _dense_acceleration_inputs(t, dense):
    """A saved state as `outputs="all"` with `batch_saved_accelerations` keeps it in the
    loop: without its q̈ and λ (the dense output's acceleration solve is not traced), with
    the memory they are solved with (the step's: `acceleration_inputs`).
    `_with_accelerations` solves them after the loop, for every saved time at once."""
    q, v, memory, step_memory = dense.acceleration_inputs(t)
    return MechanismState(q, v, None, None, memory), step_memory


def _with_accelerations(mechanism, saved, ts, y0, linear_solve):
    """The saved states of `_acceleration_inputs` with their q̈ and λ (`accelerations_at`,
    as the dense outputs give them), solved as one batch over the saved times after the loop.

    Why (`simulate`'s `batch_saved_accelerations`): inside the loop each saved time's solve
    runs alone, one small dense system after the other; vmapped over a batch of runs, at every
    step as many times as the run with the most saved times in that step, for every run (the
    bench's batch: 7.8 ms per simulation with them, 4.8 ms without). Batched over the saved
    times, the solves are one vectorised computation.

    A time the run did not reach keeps +inf (`loop.solve`); its solve is made at the initial
    state instead, so that neither its value nor its derivative carries the +inf."""
    state, memory = saved
    reached = jnp.isfinite(ts)

    def where_reached(x, other):  # x at the reached times, `other` (broadcast) elsewhere
        mask = reached.reshape(reached.shape + (1,) * (x.ndim - 1))
        return jnp.where(mask, x, jnp.broadcast_to(other, x.shape))

    q, v = where_reached(state.q, y0.q), where_reached(state.v, y0.v)
    memory = jax.tree.map(where_reached, memory, y0.memory)
    t = jnp.where(reached, ts, jnp.zeros_like(ts))

    def solve(q, v, t, memory):
        return accelerations_at(mechanism, q, v, t, memory, linear_solve)

    qdd, lam = jax.vmap(solve)(q, v, t, memory)
    return state._replace(qdd=where_reached(qdd, jnp.inf), lam=where_reached(lam, jnp.inf))


def _saved_linear_solve(solver) -> str:
    """How the dense output of `solver` (a `TrackExtremes` around a mechanism solver) solves
    a saved time's q̈ and λ: a `MechanismODESolver`'s `linear_solve`, generalized-α's the
    default of `accelerations_at`."""
    inner = solver.solver if isinstance(solver, TrackExtremes) else solver
    return inner.linear_solve if isinstance(inner, MechanismODESolver) else "range_space"


# `simulate`'s `outputs`: what a saved time keeps (None: the whole state, diffrax's default;
# with `batch_saved_accelerations`, "all" is that state with its q̈ and λ solved after the
# loop: `_dense_acceleration_inputs`).
_OUTPUTS = {"all": None, "state": _state_only, "motion": _motion_only}


@eqx.filter_jit
@deferring_full_collections  # its body runs while JAX traces it
def _solve(
    mechanism, y0, t0, t_end, dt0, ts, solver, controller, max_steps, progress, adjoint,
    outputs="all", batch_saved_accelerations=False,
):  # fmt: skip
    """The run (`jaxdeploy.solvers.loop.solve`): states saved at `ts` through `outputs`'s
    selection, the time reached, the result, the step counts and the final solver state (the
    extremes and contact episodes `TrackExtremes` keeps, each peak refined by
    `_with_refined_peaks`: inside the program, where after it the two maxima would be JAX
    operations compiled on a process's first call)."""
    after_loop = outputs == "all" and batch_saved_accelerations
    sol = loop.solve(
        MechanismTerm(mechanism),
        solver,
        _stopped_at_non_finite(controller, t0, t_end),
        t0,
        t_end,
        dt0,
        y0,
        max_steps,
        ts=ts,
        fn=_acceleration_inputs if after_loop else _OUTPUTS[outputs],
        dense_fn=_dense_acceleration_inputs if after_loop else None,
        kind=loop.kind_for(adjoint),
        checkpoints=getattr(adjoint, "checkpoints", None),
        progress_meter=dfx.TqdmProgressMeter() if progress else None,
    )
    if after_loop:
        saved = _with_accelerations(mechanism, sol.ys, sol.ts, y0, _saved_linear_solve(solver))
        sol = sol._replace(ys=saved)
    return _with_refined_solution(sol)


def _with_refined_solution(sol):
    """`sol` (a `loop.Solution`) with its tracked extremes' peaks refined
    (`_with_refined_peaks`); unchanged without tracked extremes."""
    state = sol.solver_state
    if not isinstance(state, TrackedState):
        return sol
    extremes = _with_refined_peaks(state.extremes, state.episodes)
    return sol._replace(solver_state=state._replace(extremes=extremes))


def simulate(
    mechanism: Mechanism,
    initial: ConsistentState,
    t_end: float,
    *,
    control: StepControl | None = None,
    t0: float = 0.0,
    dt: float | None = None,
    rtol: float | None = None,
    atol: float | None = None,
    dt_min: float | None = None,
    dt_max: float | None = None,
    max_steps: int = DEFAULT_MAX_STEPS,
    n_save: int = 1001,
    ts=None,
    solver=None,
    progress: bool = False,
    adjoint=None,
    step_ts=None,
    replay_steps=False,
    locate_events=True,
    extreme_samples: int = 1,
    outputs: str = "all",
    max_episodes: int = DEFAULT_EPISODE_CAPACITY,
    batch_saved_accelerations: bool = False,
) -> Trajectory:
    """Integrate `mechanism` from `initial` (a `consistent_state`) to `t_end`.

    **Arguments:**
    - `control`: a `StepControl` (solver, tolerances, steps, event location), built once and
      shared with `simulate_batch`, `sweep`, `fit` and `optimize`. Or, instead of it, its
      fields as keywords (`solver`, `rtol`, `atol`, `dt`, `dt_min`, `dt_max`, `max_steps`,
      `locate_events`), described below; giving both is refused. With neither (no `control`,
      no `dt`, `rtol` or `atol`) the step control is chosen from the mechanism
      (`jaxdeploy.solvers.default_control`): with clearance joints the Runge–Kutta path with
      event location, `StepControl("auto", rtol=1e-9, atol=1e-12)` — Dopri8 at that rtol —,
      the loosest tolerance at which every verified clearance case stayed within 1e-5 m of its
      independent reference (slider_crank over two revolutions with and without friction,
      docs/solver_by_tolerance.md: at rtol 1e-8 the friction case is off by 6e-5 to 1e-4 m
      and miscounts its impacts; the pendulum on a clearance pivot of docs/tutorial.md,
      tests/test_independent_pendulum.py); without clearance joints `StepControl("auto",
      rtol=1e-8, atol=1e-11)` (Tsit5), which on Andrews' squeezer is 2000× more accurate than
      generalized-α at the same rtol in 1/24 of the steps (docs/performance.md). A `solver`
      given alone runs at those tolerances. `Trajectory.control` records what ran; a choice
      measured to be less accurate for this mechanism (generalized-α with clearance joints at
      rtol > 1e-12 or fixed steps) raises a `jaxdeploy.solvers.SolverChoiceWarning` that says
      why.
    - `dt`: fixed step [s] (alone), or the first step of an adaptive run.
    - `rtol`, `atol`: adaptive step on the solver's error estimate (positions and velocities).
    - `n_save` / `ts`: output times (default: `n_save` equally spaced).
    - `solver`: a solver object, or a name from `jaxdeploy.solvers.SOLVER_NAMES`:
      `"generalized_alpha"` (`GeneralizedAlpha(rho_inf=0.8)`; the default of a `StepControl`
      and of tolerances given without a solver), or a diffrax method
      (`"kvaerno5"`, `"kvaerno3"`, `"tsit5"`, `"dopri8"`, …) on the index-1 ODE with coordinate
      projection (`MechanismODESolver`); implicit ones take their Newton tolerances from
      `rtol`/`atol`.
    - `progress`: show a progress bar.
    - `step_ts`: times every adaptive run must step to exactly (e.g. `ts`, so that saved
      states are step end points rather than interpolated; used by the reference solutions).
    - `adjoint`: a diffrax adjoint (default `RecursiveCheckpointAdjoint`: reverse mode with
      checkpointing; use `diffrax.ForwardMode()` for forward-mode derivatives).
    - `replay_steps`: for derivatives of an adaptive run (needs `rtol`/`atol`). The run is
      made twice: an undifferentiated adaptive run chooses the steps, then the mechanism is
      integrated again over exactly its accepted steps (`ReplaySteps`), and that second run
      is returned and differentiated. The derivative is then that of one discrete map — the
      solver on the accepted step sequence, step sizes held fixed — and the same in forward
      mode, in reverse mode and for every number of checkpoints. Without it an adaptive run
      re-decides its steps in every program that evaluates it (the forward-mode program, each
      checkpointed recomputation of the reverse pass); accept/reject decisions flip on
      round-off, and the derivative belongs to a different step sequence in each (measured:
      docs/identification.md). Costs one extra forward run. An array instead of True: the
      step end times to replay (e.g. another run's `Trajectory.step_times`): every run then
      integrates over the same steps, which is what a finite difference of a replayed run
      must do.

    - `locate_events`: with adaptive steps, a step inside which a clearance joint's v⁻ is set
      (its contact begins, or its approach speed peaks above v⁻) is redone to end just past
      that event (`jaxdeploy.solvers.LocateEvents`), so v⁻ is as accurate as the state;
      without it v⁻'s error is set by the step length, not by the tolerance. Only mechanisms
      with such events trace it.
    - `extreme_samples`: interior points of every step, besides its end, at which the run's
      extremes (`Trajectory.extremes`) are evaluated on the dense output (default 1, the
      midpoint; `jaxdeploy.solvers.TrackExtremes`).
    - `outputs`: what each saved time keeps. `"all"` (default): q, q̇, q̈, λ and the memory;
      the saved q̈ and λ are an acceleration solve at the interpolated state
      (`jaxdeploy.solvers.term.accelerations_at`). `"state"`: q, q̇ and the memory
      (`Trajectory.qdd` and `.lam` are None); `"motion"`: q and q̇ alone (`.memory` None too),
      what `scipy.integrate.solve_ivp` returns at its `t_eval`. Everything that is kept is bit
      for bit the same; saving many times of a short run gets much cheaper: slider_crank's
      4001 saved times over 4 ms were about a third of a Tsit5 run's cost with `"all"`
      (`benchmarks/work_precision.py`).

    - `max_episodes`: contact episodes kept per clearance joint (`Trajectory.
      contact_episodes()`; the count of all of them is kept too).
    - `batch_saved_accelerations`: with `outputs="all"`, solve the saved times' q̈ and λ
      after the loop, as one solve vmapped over the saved times
      (`simulation._with_accelerations`), instead of one per saved time inside the loop.
      For runs under `jax.vmap` (`batch.batch_function` sets it): a vmapped save loop runs, at
      every step, as many solves as its case with the most saved times in that step, for
      every case; the bench's 256-case slider_crank batch took 17 % less per simulation
      (7.71 → 6.40 ms, one core). Off by default because a single run compiles a larger
      program (slider_crank: 7553 → 7833 operations, XLA's compile 2.30 → 2.76 CPU-s) and
      gains ~3 %. q, q̇ and the memory are bit for bit the same; q̈ and λ equal to rounding
      (2.3e-15 of the largest |q̈| on slider_crank, tests/test_loop.py).

    **Returns:** a `Trajectory`; check `.ok` / `.status()`: a failed solve keeps the states it
    finished and says when and why it stopped.
    """
    if not isinstance(outputs, str) or outputs not in _OUTPUTS:
        raise ValueError(
            f"outputs = {outputs!r} is invalid: valid values are {', '.join(map(repr, _OUTPUTS))}"
        )
    if not isinstance(batch_saved_accelerations, bool):
        raise ValueError(
            f"batch_saved_accelerations = {batch_saved_accelerations!r} is invalid: it must "
            "be True or False"
        )
    run = prepare(
        mechanism,
        initial,
        t_end,
        control=control,
        t0=t0,
        dt=dt,
        rtol=rtol,
        atol=atol,
        dt_min=dt_min,
        dt_max=dt_max,
        max_steps=max_steps,
        n_save=n_save,
        ts=ts,
        solver=solver,
        adjoint=adjoint,
        step_ts=step_ts,
        replay_steps=replay_steps,
        locate_events=locate_events,
        extreme_samples=extreme_samples,
        max_episodes=max_episodes,
    )
    # Through the program cache when the command line enabled it (a plain call otherwise): a
    # second process with the same composition and shapes skips tracing and lowering. A
    # progress bar is a host callback, which JAX cannot export.
    solve = _solve if progress else functools.partial(_program_cache.call, _solve)
    sol = solve(
        mechanism,
        run.y0,
        run.t0,
        run.t_end,
        run.dt0,
        run.ts,
        run.solver,
        run.controller,
        run.max_steps,
        progress,
        run.adjoint,
        outputs,
        bool(batch_saved_accelerations),
    )
    return Trajectory.from_states(
        sol.ts,
        sol.ys,
        sol.result,
        solver_stats(sol.stats, sol.solver_state),
        step_times=run.step_times,
        t_reached=sol.t_reached,
        extremes=tracked_extremes(sol.solver_state),
        episodes=tracked_episodes(sol.solver_state),
        control=run.control,
    )


def _with_refined_peaks(extremes, episodes):
    """The tracked extremes with each clearance joint's largest normal force and penetration
    taken as the larger of the sampled one (step ends and `extreme_samples` interior points)
    and the maximum on each contact step's dense output (`jaxdeploy.solvers.step_maxima`,
    logged with the episodes): the true maximum within each step, not a sample."""
    if extremes is None or episodes is None or "normal_force_max" not in extremes:
        return extremes
    return {
        **extremes,
        "normal_force_max": jnp.maximum(extremes["normal_force_max"], episodes.force_max),
        "penetration_max": jnp.maximum(extremes["penetration_max"], episodes.penetration_max),
    }


class PreparedRun(NamedTuple):
    """A run of `simulate` after validation and defaults: what `integrate` gets (`prepare`)."""

    y0: MechanismState
    t0: jax.Array
    t_end: jax.Array
    dt0: jax.Array
    ts: jax.Array
    solver: object
    controller: object
    max_steps: int
    adjoint: object
    step_times: jax.Array | None
    control: StepControl | None = None


def prepare(
    mechanism,
    initial,
    t_end,
    *,
    control=None,
    t0=0.0,
    dt=None,
    rtol=None,
    atol=None,
    dt_min=None,
    dt_max=None,
    max_steps=DEFAULT_MAX_STEPS,
    n_save=1001,
    ts=None,
    solver=None,
    adjoint=None,
    step_ts=None,
    replay_steps=False,
    locate_events=True,
    extreme_samples=1,
    max_episodes=DEFAULT_EPISODE_CAPACITY,
) -> PreparedRun:
    """Validate `simulate`'s arguments (the same keywords) and build its solver, step-size
    controller, initial state and times: `simulate` is `integrate` of these pieces. Public
    for callers that must integrate exactly as `simulate` does while driving the loop
    themselves (`integrate`)."""
    control = _step_control(
        mechanism,
        control,
        solver=solver,
        rtol=rtol,
        atol=atol,
        dt=dt,
        dt_min=dt_min,
        dt_max=dt_max,
        max_steps=max_steps,
        locate_events=locate_events,
    )
    warn_solver_choice(mechanism, control, stacklevel=4)
    solver = control.make_solver()
    dt_min, locate_events = control.dt_min, control.locate_events
    # The step is data, not part of the compiled program: changing it does not recompile.
    dt0 = float_data(control.first_step())
    if not control.adaptive and isinstance(solver, GeneralizedAlpha):
        solver = replace(solver, estimate_error=False)
    adjoint = dfx.RecursiveCheckpointAdjoint() if adjoint is None else adjoint
    loop.kind_for(adjoint)  # refuses an adjoint the loop has no counterpart for, before work
    if not (isinstance(max_episodes, int) and max_episodes > 0):
        raise ValueError(f"max_episodes = {max_episodes!r} is invalid: it must be an integer > 0")
    solver = TrackExtremes(
        _inner_scan_kind_for(adjoint, solver),
        samples=extreme_samples,
        episode_capacity=max_episodes,
    )
    y0 = MechanismState(initial.q, initial.v, initial.qdd, initial.lam, initial.memory)
    ts = _save_times(t0, t_end, n_save, ts)
    # Times are data too: a new t_end or t0 does not recompile.
    t0, t_end = float_data(t0), float_data(t_end)
    # Both paths control the positions and velocities (the integrated variables) alone.
    controller = control.controller(state_norm)
    if step_ts is not None:
        if not control.adaptive:
            raise ValueError("step_ts needs adaptive steps (give rtol/atol)")
        controller = dfx.ClipStepSizeController(controller, step_ts=jnp.asarray(step_ts, float))
    if locate_events and control.adaptive and mechanism.locates_events(y0.memory):
        dt_min_data = None if dt_min is None else float_data(dt_min)
        controller = LocateEvents(controller, mechanism, dt_min=dt_min_data)
    step_times = None
    if replay_steps is True:
        if not control.adaptive:
            raise ValueError("replay_steps needs adaptive steps (give rtol/atol)")
        frozen = jax.tree.map(
            lambda x: jax.lax.stop_gradient(x) if eqx.is_array(x) else x,
            (mechanism, y0, t0, t_end, dt0),
        )
        step_times, result = _accepted_step_times(*frozen, solver, controller, control.max_steps)
        controller = ReplaySteps(step_times, result)
    elif replay_steps is not False and replay_steps is not None:
        step_times = _replay_times(replay_steps, t0, t_end)
        controller = ReplaySteps(step_times, dfx.RESULTS.successful)
    return PreparedRun(
        y0, t0, t_end, dt0, ts, solver, controller, control.max_steps, adjoint, step_times, control
    )


def _step_control(mechanism, control, **keywords) -> StepControl:
    """`simulate`'s step control: `control`, or a `StepControl` of its keyword arguments
    (never both: which would win is a guess), or, when neither gives a step (no `dt`, `rtol`
    or `atol`), the mechanism's `default_control` with the keywords given applied."""
    if control is None:
        given = {k: v for k, v in keywords.items() if v is not None}
        if not {"dt", "rtol", "atol"} & set(given):
            return default_control(mechanism).replace(**given)
        return StepControl(**given)
    given = [k for k, v in keywords.items() if v is not None]
    given = [k for k in given if k != "max_steps" or keywords[k] != DEFAULT_MAX_STEPS]
    given = [k for k in given if k != "locate_events" or keywords[k] is not True]
    if not isinstance(control, StepControl):
        raise TypeError(f"control = {control!r} is invalid: it must be a StepControl")
    if given:
        raise ValueError(
            f"control= and {', '.join(f'{k}=' for k in given)} given together: put every "
            "step setting in the StepControl (e.g. control.replace(rtol=1e-8))"
        )
    return control


def solver_stats(stats, solver_state) -> dict:
    """diffrax's step counts with the solver's own counters (generalized-α's Newton
    iterations and Jacobian evaluations), as `Trajectory.stats`."""
    stats = dict(stats)
    solver_state = untracked(solver_state)
    if solver_state is not None and hasattr(solver_state, "newton_iterations"):
        stats["num_newton_iterations"] = solver_state.newton_iterations
    if solver_state is not None and hasattr(solver_state, "jacobian_evaluations"):
        stats["num_jacobian_evaluations"] = solver_state.jacobian_evaluations
    return stats
