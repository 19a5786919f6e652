"""A batch of designs' objective, and a design's pathwise gradient, as programs the program
cache keeps between processes.

`BatchObjective` compiled `jax.vmap(problem.evaluate)` (split over the devices by
`jax.shard_map`) as a closure over its `DesignProblem`: a closure cannot be a key of
`_program_cache` (what it closes over is not written down), so every `jaxdeploy optimize`
traced it again — deploy_array's smoothed-gradient batch for 12 s, then lowered it for 2 s,
of which only XLA's compile came from JAX's persistent cache.

Here the same computation is a module-level function (`evaluate_designs`) of a `DesignSpec`,
whose one static field (`_described.Described`) carries the problem with a description of
everything the trace reads from it (`describe`): the scene's class and options, the objective's
terms, the horizon and the number of saved states (the saved times are
`linspace(0, t_end, n_save)`), every parameter value that is not a design variable (concrete
numbers choose a scene's composition), the ideal lock time (it places the objective's windows,
static index ranges), the step control, the adjoint and the number of devices. The ideal
reference's channels are arguments (data) rather than constants of the program.
`_program_cache.call` then keeps the traced program: a second process with the same
description traces nothing. A problem that cannot be written down (a scene class outside
jaxdeploy, a subclass of `DesignProblem`, another objective type, a value JSON cannot hold)
keeps its identity as its key: it is traced in each process, as before (`BatchObjective`
gives only a `DesignProblem` itself, not a subclass, to this module).

`optimize`'s pathwise gradient of `DesignProblem.evaluate` (`optimize._design_gradient`) was
likewise a closure (`solvers.tolerances_as_data`): its `gradient_spec` adds the box's bounds,
the mode and the step control's structure to the problem's description (the tolerances are
data, as before: one program for every tolerance the search tries).
"""

from __future__ import annotations

import json

import equinox as eqx
import numpy as np

from . import _program_cache
from ._described import Described


class DesignSpec(eqx.Module):
    """What the batch program evaluates (`describe`), as the static part of its arguments."""

    static: Described = eqx.field(static=True)


def describe(problem, devices) -> str | None:
    """The description that keys the program (module docstring), or None when it cannot be
    written down exactly."""
    from .objectives import Objective, Term

    scene = problem.scene
    cls = type(scene)
    if not cls.__module__.startswith("jaxdeploy."):
        return None
    objective = problem.objective
    if type(objective) is not Objective or any(type(t) is not Term for t in objective.terms):
        return None
    try:
        fixed = {k: float(v) for k, v in problem.fixed.items() if np.ndim(v) == 0}
    except TypeError:  # a traced value
        return None
    if len(fixed) != len(problem.fixed):
        return None
    ts = np.linspace(0.0, problem.t_end, len(problem.ts))
    if not np.array_equal(ts, problem.ts):
        return None
    record = {
        "scene": f"{cls.__module__}:{cls.__qualname__}",
        "scene_options": scene.options,
        "objective": [[t.feature, t.panel, t.weight, t.options] for t in objective.terms],
        "t_end": repr(problem.t_end),
        "n_save": len(problem.ts),
        "fixed": {k: repr(v) for k, v in fixed.items()},
        "lock_time": repr(float(problem.lock_time)),
        "control": repr(problem.control),
        "adjoint": repr(problem.adjoint),
        "ideal": problem.ideal is not None,
        "devices": len(devices),
    }
    try:
        return json.dumps(record, sort_keys=True, allow_nan=True)
    except (TypeError, ValueError):
        return None


def gradient_spec(problem, box, mode: str, structure) -> DesignSpec:
    """The `DesignSpec` of `problem`'s pathwise gradient in the box `box` (`optimize.Box`) by
    `mode` ("forward" or "reverse") at the step control `structure` (its tolerances
    placeholders: `solvers.split_tolerances`)."""
    problem_description = describe(problem, ())
    description = None
    if problem_description is not None:
        record = {
            "problem": json.loads(problem_description),
            "bounds": {k: [repr(float(lo)), repr(float(hi))] for k, (lo, hi) in box.bounds.items()},
            "mode": mode,
            "structure": repr(structure),
        }
        description = json.dumps(record, sort_keys=True)
    return DesignSpec(Described((problem, box, mode, structure), description, "DesignGradient"))


def spec(problem, devices) -> DesignSpec:
    """The `DesignSpec` of `problem`'s designs run over `devices`."""
    value = (problem, tuple(devices))
    return DesignSpec(Described(value, describe(problem, devices), "DesignBatch"))


@eqx.filter_jit
def evaluate_designs(design: DesignSpec, designs, ideal):
    """`(J, parts, ok)` of each design in `designs` (`{name: (B,)}`), `ideal` the problem's
    ideal reference channels (or None): one vmap, or one per device (`jax.shard_map`, the
    designs split, the reference on each; B a multiple of the device count)."""
    import jax

    problem, devices = design.static.value

    def run(designs, ideal):
        return jax.vmap(lambda x: problem.evaluate(x, ideal=ideal))(designs)

    if len(devices) > 1:
        mesh = jax.sharding.Mesh(np.array(devices), ("designs",))
        split, whole = jax.sharding.PartitionSpec("designs"), jax.sharding.PartitionSpec()
        run = jax.shard_map(
            run, mesh=mesh, in_specs=(split, whole), out_specs=split, check_vma=False
        )
    return run(designs, ideal)


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


def call(design: DesignSpec, designs):
    """`evaluate_designs` through the program cache (a plain call when it is off or the
    problem has no description), the ideal reference as data."""
    designs = {k: np.asarray(v) for k, v in designs.items()}
    return _program_cache.call(evaluate_designs, design, designs, _ideal(design.static.value[0]))
