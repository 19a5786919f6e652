"""Derivatives of simulation outputs with respect to scene parameters.

Discretise-then-differentiate through the integrator (DESIGN §5): the derivative is that of
the computed trajectory, with each Newton solve differentiated by the implicit-function
theorem and the step sizes held fixed (the step-size controller runs under
`stop_gradient`). Reverse mode (`diffrax.RecursiveCheckpointAdjoint`: memory bounded by the
number of checkpoints, not of steps) suits many parameters and a scalar loss; forward mode
(`diffrax.ForwardMode`, one tangent per parameter) suits few parameters and many outputs.

With adaptive steps a finite difference also sees the change of the step sequence, which
AD does not; the two agree to about the integration tolerance divided by the parameter step.
With a fixed step both differentiate the same map.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence

MODES = ("reverse", "forward")


def output_function(
    scene,
    params: Mapping,
    wrt: Sequence[str],
    output: Callable,
    t_end: float,
    *,
    mode: str = "reverse",
    ts=None,
    n_save: int = 1001,
    control: Mapping | None = None,
    **simulate_options,
):
    """`(f, x0)`: `f({name: value}) = output(channels)` for the parameters `wrt` (the others
    fixed at `params`), a pure JAX function to `jit`, `grad`, `jacrev`/`jacfwd` or `vmap`;
    `x0` the values of `wrt` in `params`. `output(channels)` maps the scene's channel dict
    (`Scene.channels`, arrays over the saved times) to an array or scalar."""
    import diffrax as dfx

    from ..batch import run_scene

    if mode not in MODES:
        raise ValueError(f"mode = {mode!r} is invalid; valid: {', '.join(MODES)}")
    base = scene.resolve_params(params)
    for name in wrt:
        if name not in base:
            raise ValueError(f"unknown parameter {name!r} for scene {scene.name!r}")
    adjoint = dfx.RecursiveCheckpointAdjoint() if mode == "reverse" else dfx.ForwardMode()

    def f(x):
        p = {**base, **x}
        traj = run_scene(
            scene, p, t_end, ts=ts, n_save=n_save, control=control, adjoint=adjoint,
            **simulate_options,
        )  # fmt: skip
        return output(scene.channels(scene.build(p), traj))

    return f, {name: float(base[name]) for name in wrt}


def parameter_jacobian(
    scene, params: Mapping, wrt: Sequence[str], output: Callable, t_end: float, *,
    mode: str = "reverse", **options,
) -> dict:  # fmt: skip
    """`{name: d output / d name}` (each of the output's shape) at `params`, by reverse
    (`jax.jacrev`) or forward (`jax.jacfwd`) mode through the solver; `options` as in
    `output_function`."""
    import jax

    f, x0 = output_function(scene, params, wrt, output, t_end, mode=mode, **options)
    transform = jax.jacrev if mode == "reverse" else jax.jacfwd
    return jax.jit(transform(f))(x0)
