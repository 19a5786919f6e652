"""The fit's model as programs the program cache keeps between processes.

`Model` (z → channels, their Jacobian d/dz, status) was a closure over the scene, the fitted
parameters' bounds, the fixed parameter values and the step control, jit-compiled per step
control (`solvers.tolerances_as_data`). A closure cannot be a key of `_program_cache` (what it
closes over is not written down), so every process traced it again: slider_crank's
forward-mode Jacobian over 4 ms (the README's fit) traced for 8–10 s and lowered for 3.3 s in
every `jaxdeploy fit`, of a second run's 24 s (JAX's compilation cache skipped only XLA's
compile).

Here the same computation is a module-level function (`jacobian`, `channels_batch`) of a
`ModelSpec`, whose one static field is everything the trace depends on, written down
(`describe`): the scene's class and options, each fitted parameter's name and scale (its bounds
are data of the program, and the trace does not depend on its guess), the values of the
parameters that are not fitted (concrete numbers choose a scene's composition,
`scenes.base.is_exactly_zero`, so they stay constants of the program, as in the closure), the
channels, the step control with its tolerances replaced by data, and the options passed to
`simulate`. `_program_cache.call` then keeps the traced program and its executable: a second
process with the same description traces nothing. A scene defined outside jaxdeploy (whose code
the cache's key does not cover) or a description that cannot be written down keeps its object's
identity as its key: it is traced in each process, as before. The bounds as data: a fit from
another guess (whose default bounds, guess/10 … 10 × guess, move with it: `make_parameters`) or
with other bounds runs the same program.
"""

from __future__ import annotations

import json

import equinox as eqx
import numpy as np

from .. import _program_cache
from .._described import Described
from ._parameters import physical


class ModelSpec(eqx.Module):
    """What the fit's model program is (`describe`), as the static part of its arguments."""

    static: Described = eqx.field(static=True)


def describe(scene, parameters, base, names, control, simulate_options) -> str | None:
    """The description that keys the program (module docstring), or None when it cannot be
    written down exactly (a scene class outside jaxdeploy, an option JSON cannot hold)."""
    cls = type(scene)
    if not cls.__module__.startswith("jaxdeploy."):
        return None
    fitted = {p.name for p in parameters}
    record = {
        "scene": f"{cls.__module__}:{cls.__qualname__}",
        "scene_options": scene.options,
        # Bounds are data of the program (`call`): only whether each moves on a log scale.
        "parameters": [[p.name, p.log_scale] for p in parameters],
        "fixed": {k: v for k, v in base.items() if k not in fitted},
        "names": list(names),
        "control": repr(control),
        "simulate_options": {k: repr(v) for k, v in simulate_options.items()},
    }
    try:
        return json.dumps(record, sort_keys=True, allow_nan=True)
    except (TypeError, ValueError):
        return None


def tolerances(control):
    """`(structure, rtol, atol)` of `control` (`solvers.split_tolerances`), the tolerances as
    0-d arrays: data of the model's programs."""
    from ..solvers import split_tolerances

    structure, rtol, atol = split_tolerances(control)
    return structure, np.asarray(rtol), np.asarray(atol)


def spec(scene, parameters, base, names, structure, simulate_options) -> ModelSpec:
    """The `ModelSpec` of a fit's model at one step-control structure (`tolerances`)."""
    value = (scene, tuple(parameters), dict(base), tuple(names), structure, dict(simulate_options))
    description = describe(scene, parameters, base, names, structure, simulate_options)
    return ModelSpec(Described(value, description, "FitModel"))


def _evaluate(model: ModelSpec, z, ts, rtol, atol, ends):
    """`(channels, (channels, ok))` of the run at internal coordinates `z` (`FitParameter`;
    `ends` (p, 2): each parameter's `FitParameter.ends`)."""
    import diffrax as dfx

    from ..batch import run_scene
    from ..solvers import with_tolerances

    scene, parameters, base, names, structure, options = model.static.value
    control = with_tolerances(structure, rtol, atol)
    params = dict(base)
    for k, p in enumerate(parameters):
        params[p.name] = physical(z[k], ends[k, 0], ends[k, 1], p.log_scale)
    traj = run_scene(
        scene, params, ts[-1], ts=ts, control=control, adjoint=dfx.ForwardMode(), **options
    )
    channels = scene.select_channels(scene.build(params), traj, names)
    ok = traj.result == dfx.RESULTS.successful
    return channels, (channels, ok)


@eqx.filter_jit
def jacobian(model: ModelSpec, rtol, atol, ends, z, ts):
    """`(d channels/dz, (channels, ok))` at `z`: forward mode, one tangent per parameter."""
    import jax

    return jax.jacfwd(lambda w: _evaluate(model, w, ts, rtol, atol, ends), has_aux=True)(z)


@eqx.filter_jit
def channels_batch(model: ModelSpec, rtol, atol, ends, zs, ts):
    """`(channels, ok)` of many points `zs` (k, p) as one vmapped batch."""
    import jax

    return jax.vmap(lambda z: _evaluate(model, z, ts, rtol, atol, ends)[1])(zs)


def call(function, model: ModelSpec, rtol, atol, z, ts):
    """`function(model, rtol, atol, ends, z, ts)` through the program cache
    (`_program_cache.call`: a plain call when it is off or the model has no description),
    the fitted parameters' ends (`FitParameter.ends`) as data."""
    ends = np.array([p.ends() for p in model.static.value[1]], dtype=float).reshape(-1, 2)
    return _program_cache.call(function, model, rtol, atol, ends, np.asarray(z), np.asarray(ts))
