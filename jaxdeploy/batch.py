"""Scenes as pure functions of their parameters, and batches of them in one compiled run.

`run_scene(scene, params, t_end)` builds the mechanism, assembles the initial state and
integrates, all inside JAX: with some parameters traced it jits, differentiates (`jax.grad`
over a parameter) and vmaps. `simulate_batch(scene, cases)` runs many parameter sets as one
vmapped simulation: one compilation for the whole batch, whatever the number of cases.

Only the parameters that vary across the batch are traced. The others stay Python floats, so
a scene still decides its composition from them at trace time (a friction coefficient that is
exactly 0.0 in every case traces no friction code).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from ._collector import full_collections_deferred
from .mechanism import balance_metered, balance_metered_state, without_balance_meter
from .scenes.base import Scene
from .simulation import Trajectory, simulate
from .solvers import GeneralizedAlpha
from .solvers.step_control import FIELDS as STEP_FIELDS
from .solvers.step_control import StepControl, as_step_control, scene_default_choice


def step_control(scene: Scene, control: StepControl | Mapping | None = None) -> StepControl:
    """The step control of a run of `scene`: `control` if it is a `StepControl`; otherwise the
    scene's default (`scene.default_control`) updated with the mapping `control` (field
    names of `StepControl`, e.g. `{"rtol": 1e-8}`)."""
    return as_step_control(control, scene.default_control)


def _control_and_options(scene, control, simulate_options) -> tuple[StepControl, dict]:
    """The run's `StepControl` and the rest of `simulate_options`: step settings given as
    keywords (e.g. `solver=`) override those of `control`."""
    rest = dict(simulate_options)
    explicit = {k: rest.pop(k) for k in STEP_FIELDS if k in rest}
    return step_control(scene, control).updated(explicit), rest


def vmapped_control(control: StepControl) -> StepControl:
    """The step control a vmapped batch runs with: `control`, except that generalized-α chosen
    by name (the default solver, or an automatic choice that resolves to it at this tolerance,
    e.g. `"auto:generalized_alpha"`) runs Newton's method proper,
    `GeneralizedAlpha(newton="full")`, rather than the modified Newton of a single run. A
    solver object is used as given.

    Why. Modified Newton keeps the factorised iteration matrix across steps and forms it again
    only when a case's iteration slows: a single slider_crank run re-forms it in fewer than one
    step in ten. Vmapped, that refresh is a branch of a batched loop: it runs for every case
    whenever any case needs it, and each step iterates until its slowest case has converged.
    Counted on 32 slider_crank cases over 2 ms: 1.7 matrix refreshes and 5.3 Newton iterations
    per batched step, against 0.09 and 3.7 per step of a single run, so the batch did more work
    per case than the cases one at a time. Newton proper forms the matrix at every iteration and
    converges quadratically (1.8 iterations per accepted step): the same work in every case,
    which is what a vmapped loop runs well (measured in docs/performance.md). Both solve the
    same equations to the same Newton tolerance, so a case differs from its single run by far
    less than the step's error (tests/test_batch.py).
    """
    if control.resolved_solver() == "generalized_alpha":
        return control.replace(solver=GeneralizedAlpha(newton="full"))
    return control


def run_scene(
    scene: Scene,
    params: Mapping,
    t_end: float | None = None,
    *,
    ts=None,
    n_save: int = 1001,
    control: StepControl | Mapping | None = None,
    energy_meter: bool = False,
    **simulate_options,
) -> Trajectory:
    """Simulate `scene` with `params` (a complete mapping, e.g. from `scene.resolve_params`).

    Pure in `params`: values may be JAX tracers (under `jit`, `grad`, `vmap`). `control`: a
    `StepControl`, or a mapping of its fields overriding the scene's default
    (`step_control`); `simulate_options` go to `simulate` (e.g. `adjoint`, `progress`; a
    step setting such as `solver=` among them overrides `control`'s).

    `energy_meter`: run the mechanism with its energy meter where it allows one
    (`mechanism.balance_metered`, which changes no step): the trajectory's memory then ends
    with the meter's, from which `mechanism.metered_balance` gives the run's energy balance
    (`without_balance_meter` takes it out again). A mechanism the meter cannot meter
    (`unmetered_because`) runs as it is.
    """
    t_end = scene.default_t_end if t_end is None else t_end
    control, options = _control_and_options(scene, control, simulate_options)
    mechanism = scene.build(params)
    initial = scene.initial_state(params, mechanism)
    if energy_meter and (metered := balance_metered(mechanism)) is not None:
        mechanism, initial = metered, balance_metered_state(metered, initial)
    with scene_default_choice(control, scene.default_control):
        return simulate(mechanism, initial, t_end, ts=ts, n_save=n_save, control=control, **options)


def reference_run(scene: Scene, params: Mapping, ts, control: StepControl | None = None):
    """The run a scene's analysis compares against (`jaxdeploy.analysis.Analysis`): its ideal
    counterpart (`scene.ideal_counterpart()`) with the parameters it shares with `params`,
    saved at the run's times `ts` (to `ts[-1]`), with its own default step control unless
    `control` is given. **Returns:** a `Trajectory`, or None for a scene without an ideal
    counterpart."""
    ideal = scene.ideal_counterpart()
    if ideal is None:
        return None
    p = ideal.resolve_params({k: float(v) for k, v in params.items() if k in ideal.params})
    mechanism = ideal.build(p)
    ts = np.asarray(ts, dtype=float)
    control = ideal.default_control if control is None else control
    initial = ideal.initial_state(p, mechanism)
    with scene_default_choice(control, ideal.default_control):
        return simulate(mechanism, initial, float(ts[-1]), ts=ts, control=control)


@dataclass(frozen=True)
class Batch:
    """A batch of simulations of one scene.

    `params`: the complete parameters, `{name: array (B,)}`; `varied`: names that differ
    across cases (traced in the run); `trajectory`: a `Trajectory` whose leaves have a
    leading batch axis `B`.
    """

    scene: Scene
    params: dict
    varied: tuple[str, ...]
    trajectory: Trajectory

    @property
    def size(self) -> int:
        return int(np.shape(self.trajectory.ts)[0])

    def case_params(self, i: int) -> dict[str, float]:
        """Parameters of case `i` as Python floats."""
        return {k: float(v[i]) for k, v in self.params.items()}

    def case(self, i: int) -> Trajectory:
        """The trajectory of case `i` (an ordinary, unbatched `Trajectory`)."""
        return jax.tree.map(lambda leaf: leaf[i], self.trajectory)

    def mechanism(self, i: int):
        """The mechanism of case `i`, built with concrete parameters (for analysis)."""
        return self.scene.build(self.case_params(i))

    def statuses(self) -> list[str]:
        return [self.case(i).status() for i in range(self.size)]

    @property
    def ok(self) -> np.ndarray:
        return np.array([self.case(i).ok for i in range(self.size)])


def stack_cases(scene: Scene, cases, fixed: Mapping | None):
    """Validate every case (concretely, before tracing) and split varied from fixed names."""
    if isinstance(cases, Mapping):
        lengths = {k: np.size(v) for k, v in cases.items()}
        if len(set(lengths.values())) > 1:
            raise ValueError(f"cases: every parameter needs the same number of values: {lengths}")
        n = next(iter(lengths.values())) if lengths else 0
        rows = [{k: float(np.ravel(v)[i]) for k, v in cases.items()} for i in range(n)]
    else:
        rows = [dict(row) for row in cases]
    if not rows:
        raise ValueError("cases: the batch is empty; give at least one parameter set")
    resolved = [scene.resolve_params({**(fixed or {}), **row}) for row in rows]
    names = list(resolved[0])
    table = {k: np.array([float(r[k]) for r in resolved]) for k in names}
    varied = tuple(k for k in names if np.any(table[k] != table[k][0]))
    shared = {k: float(table[k][0]) for k in names if k not in varied}
    return table, varied, shared


def batch_function(
    scene: Scene,
    varied: tuple[str, ...],
    shared: Mapping,
    t_end: float,
    ts,
    *,
    control: StepControl | Mapping | None = None,
    evaluate=None,
    group_size: int | None = None,
    sharding=None,
    **simulate_options,
):
    """The jitted, vmapped run of `scene` over the `varied` parameters (the rest `shared`).

    Call it with a tuple of `(B,)` arrays, one per varied name; it returns the batch's
    `Trajectory` (leading axis B), or `(trajectory, evaluate(params, trajectory))` when
    `evaluate` is given (per case, inside the same compiled program). Build it once and call it
    on many chunks: it compiles once per chunk shape and input sharding (inputs placed with a
    `jax.sharding.NamedSharding` run sharded across devices). The end time and the saved
    times are data of the program, not constants: `run(values, t_end=t, ts=times)` runs the
    same compiled program over another horizon (`times` of the same length as `ts`; the
    sweep's probe of its run length, `jaxdeploy.sweep`).

    `energy_meter` (`run_scene`): each case runs with its energy meter where the mechanism
    allows one; `evaluate` sees the trajectory without it.

    `group_size`: vmap over groups of that many cases, run one group after another inside the
    same compiled program (`jax.lax.map(..., batch_size=group_size)`; the last group may be
    smaller). A vmapped group advances until its slowest case finishes and its Newton loop
    runs until its slowest case converges, so smaller groups waste less on stragglers, and
    their arrays stay in cache; `None` (default) vmaps all cases at once.

    Generalized-α runs with Newton's method proper in a batch (`vmapped_control`), and
    unsharded the saved times' q̈ and λ are solved after the loop, vmapped over the saved
    times (`simulate`'s `batch_saved_accelerations`, unless `simulate_options` say
    otherwise): the same values to rounding, 17 % less per simulation in the bench's 256-case
    batch.

    `sharding` (a `NamedSharding` over a 1-D mesh, as `jaxdeploy.sweep` places its inputs):
    each device runs the policy on its own shard of the cases (`jax.shard_map`), with no
    communication (groups or the vmap are per device). Sharded, the saved q̈ and λ are solved
    inside the loop, and `batch_saved_accelerations=True` is refused: so solved after the
    loop, deploy_array's sweep over two host devices hung (jax 0.10.2: a large batched LAPACK
    Cholesky per device, every XLA thread idle; tests/test_sweep.py).
    """
    check_policy(group_size)
    control, simulate_options = _control_and_options(scene, control, simulate_options)
    control = vmapped_control(control)
    simulate_options = {"batch_saved_accelerations": sharding is None, **simulate_options}
    if sharding is not None and simulate_options["batch_saved_accelerations"] is True:
        raise ValueError(
            "batch_saved_accelerations=True cannot be combined with sharding: solved after "
            "the loop on several host devices the saved accelerations can hang the run; "
            "leave it out (sharded batches solve them inside the loop)"
        )

    def params_of(varied_values):
        return {**shared, **dict(zip(varied, varied_values, strict=True))}

    def one(varied_values, horizon, times):
        params = params_of(varied_values)
        trajectory = run_scene(
            scene, params, horizon, ts=times, control=control, **simulate_options
        )
        if evaluate is None:
            return trajectory
        plain = trajectory
        if simulate_options.get("energy_meter") and balance_metered(scene.build(params)):
            plain = without_balance_meter(trajectory)
        return trajectory, evaluate(params, plain)

    def run(values, horizon, times):
        if group_size is None:
            return jax.vmap(one, in_axes=(0, None, None))(values, horizon, times)
        return jax.lax.map(lambda v: one(v, horizon, times), values, batch_size=group_size)

    if sharding is None:
        program = jax.jit(run)
    else:
        cases, whole = jax.sharding.PartitionSpec(*sharding.spec), jax.sharding.PartitionSpec()
        program = jax.jit(
            jax.shard_map(
                run,
                mesh=sharding.mesh,
                in_specs=(cases, whole, whole),
                out_specs=cases,
                check_vma=False,
            )
        )
    t_end, ts = jnp.asarray(t_end, dtype=float), jnp.asarray(ts, dtype=float)

    def call(values, t_end=t_end, ts=ts):
        # A first call traces, lowers and compiles: full garbage collections wait (`_collector`).
        with full_collections_deferred():
            return program(values, jnp.asarray(t_end, dtype=float), jnp.asarray(ts, dtype=float))

    return call


def check_policy(group_size) -> None:
    """Refuse a batch policy that is not one of: all at once (None), `group_size` ≥ 1."""
    if group_size is not None and not (
        isinstance(group_size, int) and not isinstance(group_size, bool) and group_size >= 1
    ):
        raise ValueError(f"group_size = {group_size!r} is invalid: it must be an integer ≥ 1")


def simulate_batch(
    scene: Scene,
    cases,
    t_end: float | None = None,
    *,
    fixed: Mapping | None = None,
    ts=None,
    n_save: int = 1001,
    control: StepControl | Mapping | None = None,
    group_size: int | None = None,
    **simulate_options,
) -> Batch:
    """Simulate many parameter sets of `scene` as one vmapped run (one compilation).

    **Arguments:**
    - `cases`: `{name: sequence of B values}` or a sequence of B `{name: value}` mappings;
      unspecified parameters take `fixed`, then the scene's defaults. Every case is validated
      (names, ranges) before anything is traced.
    - `t_end`, `ts`/`n_save`, `control`, `simulate_options`: as in `run_scene`, shared by
      every case (same saved times).
    - `group_size`: vmap the cases in groups of this many, run one after another in the same
      compiled program (see `batch_function`); `None` vmaps all at once.

    **Returns:** a `Batch`. Cases advance together in one `while` loop: each step costs the
    whole batch, and the batch runs until its slowest case finishes (cases that finished
    early wait, masked). Generalized-α runs with Newton's method proper (`vmapped_control`).
    Measured: docs/performance.md.
    """
    check_policy(group_size)
    table, varied, shared = stack_cases(scene, cases, fixed)
    t_end = scene.default_t_end if t_end is None else t_end
    ts = jnp.linspace(0.0, t_end, n_save) if ts is None else jnp.asarray(ts, dtype=float)
    if varied:
        run = batch_function(
            scene,
            varied,
            shared,
            t_end,
            ts,
            control=control,
            group_size=group_size,
            **simulate_options,
        )
        trajectory = run(tuple(jnp.asarray(table[k]) for k in varied))
    else:  # identical cases: run once, broadcast
        with full_collections_deferred():
            single = jax.jit(
                lambda: run_scene(scene, shared, t_end, ts=ts, control=control, **simulate_options)
            )()
        n = len(table[next(iter(table))])
        trajectory = jax.tree.map(
            lambda leaf: jnp.broadcast_to(leaf, (n, *jnp.shape(leaf))), single
        )
    return Batch(scene, table, varied, trajectory)
