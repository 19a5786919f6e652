"""A batch of designs' objective, and a design's pathwise gradient, as programs the program
cache keeps between processes.

`BatchObjective` compiled `jax.vmap(problem.evaluate)` (split over the devices by
`jax.shard_map`) as a closure over its `DesignProblem`: a closure cannot be a key of
`_program_cache` (what it closes over is not written down), so every `jaxdeploy optimize`
traced it again — deploy_array's smoothed-gradient batch for 12 s, then lowered it for 2 s,
of which only XLA's compile came from JAX's persistent cache.

Here the same computation is two module-level functions of `DesignSpec`s, whose one static
field (`_described.Described`) carries what the trace reads with a description of it:

* `run_designs`: the designs' runs (`optimize.DesignRuns`), vmapped, returning the channels
  and event outputs the objective reads (`objective_reads`) and each run's success. Its
  description (`describe_runs`): the scene's class and options, the horizon and the number
  of saved states (the saved times are `linspace(0, t_end, n_save)`), every parameter value
  that is not a design variable (concrete numbers choose a scene's composition), the step
  control, the adjoint, the number of devices and the outputs returned.
* `objective_of`: the objective of those outputs, vmapped. Its description: the objective's
  terms, the saved times and the ideal lock time (it places the objective's windows, static
  index ranges); the ideal reference's channels are arguments (data).

Split in two, the runs' program (nearly all of the trace and the compile) needs no ideal
reference, so `jaxdeploy optimize` makes it in a second thread while the reference runs
(`optimize.prepare_batch`); the objective's is small (0.15 s of XLA's compile for the README's
optimize). The split changes no bit (the README's optimize, one device and two).
`_program_cache.call` keeps both: a second process with the same descriptions traces nothing.
What cannot be written down (a scene class outside jaxdeploy, a subclass of `DesignProblem`,
another objective type, a value JSON cannot hold) keeps its identity as its key: it is traced
in each process, as before (`BatchObjective` gives only a `DesignProblem` itself, not a
subclass, to this module).

`optimize`'s pathwise gradient of `DesignProblem.evaluate` (`optimize._design_gradient`) was
likewise a closure (`solvers.tolerances_as_data`): its `gradient_spec` adds the box's bounds,
the mode and the step control's structure to the problem's description (the
tolerances are data, as before: one program for every tolerance the search tries).
"""

from __future__ import annotations

import equinox as eqx
import numpy as np

from . import _program_cache
from ._described import Described, dumps, scene_record


class DesignSpec(eqx.Module):
    """What a program evaluates (its description: `runs_spec`, `objective_spec`,
    `gradient_spec`), as the static part of its arguments."""

    static: Described = eqx.field(static=True)


def _runs_record(runs) -> dict | None:
    """What the runs' program reads of `runs` (`optimize.DesignRuns`: module docstring), or
    None when it cannot be written down exactly."""
    record = scene_record(runs.scene, runs.fixed)
    ts = np.linspace(0.0, runs.t_end, len(runs.ts))
    if record is None or not np.array_equal(ts, runs.ts):
        return None
    return {
        **record,
        "t_end": repr(runs.t_end),
        "n_save": len(runs.ts),
        "control": repr(runs.control),
        "adjoint": repr(runs.adjoint),
    }


def _objective_record(problem) -> dict | None:
    from .objectives import Objective, Term

    objective = problem.objective
    if type(objective) is not Objective or any(type(t) is not Term for t in objective.terms):
        return None
    return {
        "objective": [[t.feature, t.panel, t.weight, t.options] for t in objective.terms],
        "t_end": repr(problem.t_end),
        "n_save": len(problem.ts),
        "lock_time": repr(float(problem.lock_time)),
        "ideal": problem.ideal is not None,
    }


def gradient_spec(problem, box, mode: str, structure) -> DesignSpec:
    """The `DesignSpec` of `problem`'s pathwise gradient in the box `box` (`optimize.Box`) by
    `mode` ("forward" or "reverse") at the step control `structure` (its tolerances
    placeholders: `solvers.split_tolerances`): described by what its runs' and its
    objective's programs read, the box's bounds, the mode and the structure."""
    runs, objective = _runs_record(problem.runs), _objective_record(problem)
    description = None
    if runs is not None and objective is not None:
        description = dumps({
            "problem": {**runs, **objective},
            "bounds": {k: [repr(float(lo)), repr(float(hi))] for k, (lo, hi) in box.bounds.items()},
            "mode": mode,
            "structure": repr(structure),
        })  # fmt: skip
    return DesignSpec(Described((problem, box, mode, structure), description, "DesignGradient"))


def runs_spec(runs, objective, devices) -> DesignSpec:
    """The `DesignSpec` of the designs' runs (`optimize.DesignRuns`) over `devices`, returning
    the outputs `objective` reads (`objective_reads`; all of them when that is unknown)."""
    reads = objective_reads(objective, runs.ts)
    record = _runs_record(runs)
    description = None
    if record is not None:
        record["devices"] = len(devices)
        record["reads"] = None if reads is None else [sorted(r) for r in reads]
        description = dumps(record)
    return DesignSpec(Described((runs, tuple(devices), reads), description, "DesignRuns"))


class _ReadsWhole(Exception):
    """The objective looked at a run's outputs as a whole (`_Reading`)."""


class _Reading(dict):
    """A mapping that holds every key, each a placeholder array of `shape`, and records the
    keys read (`objective_reads`). Looking at it as a whole (its keys, values, items, size)
    raises `_ReadsWhole`: which names such an objective reads cannot be known."""

    def __init__(self, shape):
        super().__init__()
        self.shape, self.read = shape, set()

    def __contains__(self, name):
        return True

    def __getitem__(self, name):
        import jax.numpy as jnp

        self.read.add(name)
        return jnp.zeros(self.shape)

    def get(self, name, default=None):
        return self[name]

    def _whole(self, *args, **kwargs):
        raise _ReadsWhole

    __iter__ = __len__ = keys = values = items = copy = _whole


def objective_reads(objective, ts):
    """`(channels, events)`: the names of the run outputs `objective` reads, found by
    evaluating it abstractly (`jax.eval_shape`) on placeholders at the saved times `ts` with
    the phase boundary at the start (which names a feature reads does not depend on it); None
    (then the runs return every output) for an objective other than an `objectives.Objective`
    of `Term`s (jaxdeploy's features, which read outputs by name), when it looks at the
    outputs as a whole, or when that evaluation fails (the objective's own trace then
    reports the problem).

    Why the runs return only these: an output nobody reads is left out of the compiled
    program (XLA removes the computation, and the loop's state that only it needs), which a
    program that returns it cannot do: deploy_array's batch returning every channel and event
    took 1.75x the time of one returning what the paper's objective reads."""
    import jax

    from .objectives import Deployment, Objective, Term

    if type(objective) is not Objective or any(type(t) is not Term for t in objective.terms):
        return None
    ts = np.asarray(ts)
    channels, ideal, events = _Reading(ts.shape), _Reading(ts.shape), _Reading(())

    def read_objective():
        deployment = Deployment(ts, float(ts[0]), channels, ideal, events)
        return objective(deployment), objective.parts(deployment)

    try:
        jax.eval_shape(read_objective)
    except Exception:  # noqa: BLE001 - the objective's own trace raises it again, with the data
        return None
    return frozenset(channels.read | ideal.read), frozenset(events.read)


def objective_spec(problem) -> DesignSpec:
    """The `DesignSpec` of `problem`'s objective of its runs' outputs."""
    record = _objective_record(problem)
    description = None if record is None else dumps(record)
    return DesignSpec(Described(problem, description, "DesignObjective"))


@eqx.filter_jit
def run_designs(design: DesignSpec, designs):
    """`(channels, events, ok)` of each design in `designs` (`{name: (B,)}`): one vmap, or one
    per device (`jax.shard_map`, the designs split; B a multiple of the device count)."""
    import diffrax as dfx
    import jax

    runs, devices, reads = design.static.value

    def run(designs):
        def one(x):
            channels, events, trajectory = runs.outputs(x)
            if reads is not None:  # what the objective reads alone (`objective_reads`: why)
                channels = {k: v for k, v in channels.items() if k in reads[0]}
                events = {k: v for k, v in events.items() if k in reads[1]}
            return channels, events, trajectory.result == dfx.RESULTS.successful

        return jax.vmap(one)(designs)

    if len(devices) > 1:
        mesh = jax.sharding.Mesh(np.array(devices), ("designs",))
        split = jax.sharding.PartitionSpec("designs")
        run = jax.shard_map(run, mesh=mesh, in_specs=split, out_specs=split, check_vma=False)
    return run(designs)


@eqx.filter_jit
def objective_of(design: DesignSpec, channels, events, ideal):
    """`(J, parts)` of each design's outputs (`run_designs`' channels and events, leading axis
    the designs) against the ideal reference's channels `ideal` (or None): one vmap."""
    import jax

    problem = design.static.value

    def one(channels, events):
        deployment = problem.deployment_of(channels, events, ideal)
        return problem.objective(deployment), problem.objective.parts(deployment)

    return jax.vmap(one)(channels, events)


def _ideal(problem):
    """The problem's ideal reference channels as arrays (data of its programs), or None."""
    if problem.ideal is None:
        return None
    return {k: np.asarray(v) for k, v in problem.ideal.items()}


def call_gradient(function, design: DesignSpec, rtol, atol, u):
    """`function(design, rtol, atol, u, ideal)` (`optimize`'s pathwise gradient program)
    through the program cache, the ideal reference as data."""
    ideal = _ideal(design.static.value[0])
    arrays = (np.asarray(rtol), np.asarray(atol), np.asarray(u))
    return _program_cache.call(function, design, *arrays, ideal)


def run(runs: DesignSpec, designs):
    """`run_designs` through the program cache (a plain call when it is off or the runs have
    no description), its outputs as NumPy arrays."""
    import jax

    designs = {k: np.asarray(v) for k, v in designs.items()}
    outputs = _program_cache.call(run_designs, runs, designs)
    return jax.tree.map(np.asarray, outputs)


def call(runs: DesignSpec, objective: DesignSpec, designs):
    """`(J, parts, ok)` of `designs`: their runs (`run`), then the objective of the runs'
    outputs (`objective_of`, through the program cache, the ideal reference as data)."""
    channels, events, ok = run(runs, designs)
    problem = objective.static.value
    values, parts = _program_cache.call(objective_of, objective, channels, events, _ideal(problem))
    return values, parts, ok
