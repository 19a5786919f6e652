"""Helpers shared by the derivative tests."""

from collections.abc import Mapping

import jax
import numpy as np

from jaxdeploy.batch import step_control
from jaxdeploy.fit import output_function
from jaxdeploy.fit._derivatives import replayed_step_times


def jacobian_and_differences(
    scene, params, wrt, output, t_end, rel_step, *, ts, control=None, mode="forward", **options
):
    """`(jacobian, differences)`, each `{name: array of the output's shape}`: AD through the
    run (`output_function`, `mode` "forward" or "reverse"), and central differences `(f(θ + h e_k) −
    f(θ − h e_k)) / 2h`, `h = rel_step·|θ_k|` (`rel_step` one number or `{name: step}`), whose
    runs are the primal outputs of the same compiled program (`jax.jacfwd` or `jax.jacrev`
    with `has_aux=True`)
    evaluated at θ ± h e_k: one compilation instead of a second one for a batch of plain runs.
    With adaptive steps every evaluation replays the unperturbed run's accepted steps
    (`replay_steps=` its step times), so AD and the differences differentiate one discrete map,
    as `jaxdeploy.fit.central_differences` does with a separate batch. `options` go to the
    runs (`simulate`'s, e.g. `solver=`)."""
    base = scene.resolve_params(params)
    options = {"ts": ts, "control": control, **options}
    if step_control(scene, control).adaptive:
        options["replay_steps"] = replayed_step_times(scene, base, t_end, **options)
    f, x0 = output_function(scene, base, wrt, output, t_end, mode=mode, **options)

    def value_twice(x):
        y = f(x)
        return y, y

    transform = jax.jacfwd if mode == "forward" else jax.jacrev
    program = jax.jit(transform(value_twice, has_aux=True))
    jacobian, _ = program(x0)
    steps = rel_step if isinstance(rel_step, Mapping) else dict.fromkeys(wrt, rel_step)
    differences = {}
    for name in wrt:
        h = steps[name] * abs(x0[name])
        _, plus = program({**x0, name: x0[name] + h})
        _, minus = program({**x0, name: x0[name] - h})
        differences[name] = (np.asarray(plus) - np.asarray(minus)) / (2 * h)
    return {name: np.asarray(v) for name, v in jacobian.items()}, differences
