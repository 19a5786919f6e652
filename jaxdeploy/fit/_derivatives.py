"""Derivatives of simulation outputs with respect to scene parameters.

Discretise-then-differentiate through the integrator (Kidger, *On Neural Differential
Equations*, PhD thesis, Oxford 2021; docs/identification.md): the derivative is that of
the computed trajectory, with each Newton solve differentiated by the implicit-function
theorem and the step sizes held fixed (the step-size controller runs under
`stop_gradient`). Reverse mode (`diffrax.RecursiveCheckpointAdjoint`: memory bounded by the
number of checkpoints, not of steps) suits many parameters and a scalar loss; forward mode
(`diffrax.ForwardMode`, one tangent per parameter) suits few parameters and many outputs.

Adaptive runs are differentiated with `replay_steps=True` (the default here): an
undifferentiated adaptive run chooses the steps, and the run over exactly those steps is the
one differentiated. Without it each program that evaluates the run (the forward-mode program,
each checkpointed recomputation of the reverse pass) re-decides its steps, decisions flip on
round-off, and forward mode, reverse mode and reverse mode with another number of checkpoints
differentiate different step sequences (docs/identification.md). The matching finite
difference replays the unperturbed run's steps too (`central_differences`); a difference of
re-adapted runs also contains the change of the step sequence, a term of the order of the
integration error that AD does not (and should not) see.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence

from .._collector import deferring_full_collections, full_collections_deferred

MODES = ("reverse", "forward")
GRADIENT_MODES = ("auto", *MODES)
# The largest parameter count for which `mode="auto"` takes forward mode (`gradient_mode`).
# Measured (benchmarks/targets.py, deploy_array loss over 0.2 s, pinned to one core, load
# 1.4-1.8): with 4 parameters forward mode took 0.80x the warm time of reverse mode (0.59 s vs
# 0.74 s) and compiled in 0.42x the time (34 s vs 80 s). Each further tangent adds about one
# primal right-hand-side evaluation per stage (vmapped tangents: 1 cost 2.6x a primal
# evaluation, 4 cost 5.4x), about 0.1 s here, so the warm costs cross near 5-6 parameters;
# the smaller compile tips the choice to forward mode at 6.
FORWARD_MODE_MAX_PARAMETERS = 6


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
    adjoint=None,
    **simulate_options,
):
    """`(f, x0)`: `f({name: value}) = output(channels)` for the parameters `wrt` (the others
    fixed at `params`), a pure JAX function to `jit`, `grad`, `jacrev`/`jacfwd` or `vmap`;
    `x0` the values of `wrt` in `params`. `output(outputs)` maps the scene's outputs
    (`Scene.outputs`: its channels, arrays over the saved times, and its events, scalars such
    as deploy_array's `lock_time` or slider_crank's `first_onset_time`, differentiable event
    times) to an array or scalar. With adaptive
    steps the run replays its own accepted steps (`replay_steps=True`, see the module
    docstring); pass `replay_steps=False` to differentiate the raw adaptive loop. `adjoint`:
    a diffrax adjoint instead of the mode's default (e.g. `RecursiveCheckpointAdjoint` with
    a chosen number of checkpoints)."""
    import diffrax as dfx

    from ..batch import run_scene, step_control

    if mode not in MODES:
        raise ValueError(f"mode = {mode!r} is invalid; valid: {', '.join(MODES)}")
    base = scene.resolve_params(params)
    for name in wrt:
        if name not in base:
            raise ValueError(f"unknown parameter {name!r} for scene {scene.name!r}")
    if adjoint is None:
        adjoint = dfx.RecursiveCheckpointAdjoint() if mode == "reverse" else dfx.ForwardMode()
    if _adaptive(step_control(scene, control)):
        simulate_options.setdefault("replay_steps", True)

    def f(x):
        p = {**base, **x}
        traj = run_scene(
            scene, p, t_end, ts=ts, n_save=n_save, control=control, adjoint=adjoint,
            **simulate_options,
        )  # fmt: skip
        return output(scene.outputs(scene.build(p), traj))

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
    with full_collections_deferred():
        return jax.jit(transform(f))(x0)


def gradient_mode(n_parameters: int) -> str:
    """The mode `mode="auto"` of `gradient_function` picks for a scalar loss of
    `n_parameters` parameters: `"forward"` up to `FORWARD_MODE_MAX_PARAMETERS`, `"reverse"`
    above.

    The rule is the measured crossover of the two costs. Forward mode carries one tangent per
    parameter through the same pass (`jax.jacfwd`: the tangents vmapped, every linear solve's
    factorisation shared with them), so its cost grows with the parameter count; reverse mode
    costs a fixed multiple of a forward run whatever the count, plus the stored steps. For a
    few parameters forward mode is also the smaller program to compile (docs/performance.md,
    "Gradient")."""
    n = int(n_parameters)
    if n < 1:
        raise ValueError(f"n_parameters = {n_parameters!r} is invalid: it must be >= 1")
    return "forward" if n <= FORWARD_MODE_MAX_PARAMETERS else "reverse"


def gradient_function(
    scene, params: Mapping, wrt: Sequence[str], loss: Callable, t_end: float, *,
    mode: str = "auto", **options,
):  # fmt: skip
    """`(g, x0)`: `g({name: value}) = (loss, {name: d loss / d name})` for a scalar
    `loss(channels)` (as `output` in `output_function`) of the parameters `wrt`, a pure JAX
    function to `jit` (compile once, call for many parameter values); `x0` the values of
    `wrt` in `params`. `mode`: `"auto"` (default; `gradient_mode` of the number of
    parameters), `"forward"` (`jax.jacfwd` with `diffrax.ForwardMode`: the loss and every
    tangent from one pass) or `"reverse"` (`jax.value_and_grad` with
    `diffrax.RecursiveCheckpointAdjoint`). Both modes differentiate the same discrete map
    (adaptive steps are replayed, see the module docstring) and agree to round-off;
    `options` as in `output_function`."""
    import jax
    import jax.numpy as jnp

    if mode not in GRADIENT_MODES:
        raise ValueError(f"mode = {mode!r} is invalid; valid: {', '.join(GRADIENT_MODES)}")
    chosen = gradient_mode(len(wrt)) if mode == "auto" else mode
    f, x0 = output_function(scene, params, wrt, loss, t_end, mode=chosen, **options)

    def scalar(x):
        value = f(x)
        if jnp.shape(value) != ():
            raise ValueError(
                f"loss returns shape {jnp.shape(value)}: it must be a scalar (for an array "
                "output use parameter_jacobian)"
            )
        return value

    if chosen == "reverse":
        # Called while the caller's `jit` traces it: the transformation's whole trace
        # (linearisation and transposition) with full garbage collections deferred.
        return deferring_full_collections(jax.value_and_grad(scalar)), x0

    def value_twice(x):
        value = scalar(x)
        return value, value

    jacobian = jax.jacfwd(value_twice, has_aux=True)

    @deferring_full_collections
    def g(x):
        grad, value = jacobian(x)
        return value, grad

    return g, x0


def parameter_gradient(
    scene, params: Mapping, wrt: Sequence[str], loss: Callable, t_end: float, *,
    mode: str = "auto", **options,
) -> tuple:  # fmt: skip
    """`(loss, {name: d loss / d name})` at `params` for a scalar `loss(channels)`, compiled
    and evaluated once (`gradient_function`, whose result to `jit` yourself when evaluating
    at many parameter values)."""
    import jax

    g, x0 = gradient_function(scene, params, wrt, loss, t_end, mode=mode, **options)
    with full_collections_deferred():  # its lowering and compile too
        return jax.jit(g)(x0)


def gradient_at_tolerances(
    scene, params: Mapping, wrt: Sequence[str], loss: Callable, t_end: float, *,
    mode: str = "auto", **options,
) -> Callable:  # fmt: skip
    """`evaluate(control) -> (loss, {name: d loss / d name})` at `params` (as
    `parameter_gradient`) for any `StepControl` `control`, its rtol and atol data of the
    compiled program (`solvers.tolerances_as_data`): controls that differ only in their
    tolerances share one program, where `parameter_gradient` compiles one per tolerance. A
    search over tolerances (`derivative_tolerance`) then compiles once (slider_crank's first
    onset over 2 ms, Tsit5, forward mode, load ~12: 42.6 CPU-s, then 0.1 CPU-s at each of
    rtol 1e-7 and 1e-8). `options` as in `gradient_function` (not `control`); `evaluate.programs`
    holds the compiled programs."""
    from ..batch import step_control
    from ..solvers import tolerances_as_data

    if "control" in options:
        raise ValueError("gradient_at_tolerances: the control is evaluate's argument")
    x0 = {name: float(scene.resolve_params(params)[name]) for name in wrt}

    def gradient(control, x):
        g, _ = gradient_function(scene, params, wrt, loss, t_end, mode=mode, control=control,
                                 **options)  # fmt: skip
        return g(x)

    program = tolerances_as_data(gradient)

    def evaluate(control):
        return program(step_control(scene, control), x0)

    evaluate.programs = program.programs
    return evaluate


def _adaptive(control) -> bool:
    """Whether a run with this `StepControl` chooses its own steps."""
    return control.adaptive


def central_differences(
    scene,
    params: Mapping,
    wrt: Sequence[str],
    output: Callable,
    t_end: float,
    rel_step,
    *,
    ts=None,
    n_save: int = 1001,
    control: Mapping | None = None,
    replay: bool = True,
    abs_step=None,
    failed: dict | None = None,
    **simulate_options,
) -> dict:
    """`{name: (f(θ + h e_k) − f(θ − h e_k)) / 2h}`, `h = rel_step·|θ_k|` (`rel_step` one
    number or `{name: step}`), all runs as one vmapped batch; `output` as in
    `output_function`.

    A parameter whose value is 0 (slider_crank's default σ and μ) has no relative step: it
    takes the absolute step `abs_step` (one number or `{name: step}`, in the parameter's
    unit; default `rel_step` times the width of its valid range, `ParamSpec.low`…`high`, and
    a `ValueError` naming it when that range is unbounded). Where `θ − h` leaves the valid
    range (a parameter at its lower bound, σ = 0) the difference is one-sided, of the same
    order: `(−3 f(θ) + 4 f(θ + h) − f(θ + 2h)) / 2h` (Fornberg, *Math. Comp.* 51 (1988) 699).

    With adaptive steps and `replay=True` (default) every perturbed run integrates over the
    accepted steps of the unperturbed run (`simulate(..., replay_steps=times)`): the
    difference then approximates the derivative of the same discrete map as
    `parameter_jacobian`, with a truncation error O(h²) instead of the O(tol/h) noise of
    re-adapted steps. `replay=False` differences re-adapted runs (what a user perturbing
    the model sees).

    A perturbed run that fails (e.g. a large step that makes an explicit method unstable
    over the replayed steps) raises a `RuntimeError` naming it; with a dict `failed` it is
    recorded there instead, `{name: status of its first failed run}`, and that parameter's
    difference is NaN (the others are unaffected: one batch, judged per case)."""
    import numpy as np

    from ..batch import simulate_batch, step_control

    base = scene.resolve_params(params)
    if replay and _adaptive(step_control(scene, control)):
        times = replayed_step_times(
            scene, base, t_end, ts=ts, n_save=n_save, control=control, **simulate_options
        )
        simulate_options = {**simulate_options, "replay_steps": times}
    widths = difference_steps(scene, base, wrt, rel_step, abs_step)
    stencils = {name: _stencil(scene, name, base[name], widths[name]) for name in wrt}
    cases = [
        {**base, name: base[name] + o * widths[name]} for name in wrt for o, _ in stencils[name]
    ]
    batch = simulate_batch(
        scene, cases, t_end, ts=ts, n_save=n_save, control=control, **simulate_options
    )
    ok = batch.ok
    if failed is None and not all(ok):
        statuses = [s for s in batch.statuses() if s != "ok"]
        raise RuntimeError(f"a perturbed run failed: {statuses[0]}")
    values = [
        np.asarray(output(scene.outputs(batch.mechanism(i), batch.case(i))))
        for i in range(batch.size)
    ]
    out, i = {}, 0
    for name in wrt:
        weights = [w for _, w in stencils[name]]
        cases = range(i, i + len(weights))
        out[name] = sum(w * values[c] for w, c in zip(weights, cases, strict=True))
        out[name] = out[name] / widths[name]
        if not all(ok[c] for c in cases):
            failed[name] = next(batch.case(c).status() for c in cases if not ok[c])
            out[name] = np.full_like(np.asarray(out[name], dtype=float), np.nan)
        i += len(weights)
    return out


def replayed_step_times(scene, params: Mapping, t_end: float, **options):
    """The accepted step times of the unperturbed adaptive run (`simulate(...,
    replay_steps=True)`): pass them as `replay_steps=` to runs that must step over them."""
    import jax
    import numpy as np

    from ..batch import run_scene

    reference = jax.jit(lambda: run_scene(scene, params, t_end, replay_steps=True, **options))()
    if not reference.ok:
        raise RuntimeError(f"the unperturbed run failed: {reference.status()}")
    return np.asarray(reference.step_times)


def difference_steps(scene, params: Mapping, wrt: Sequence[str], rel_step, abs_step=None) -> dict:
    """`{name: h}`, the finite-difference step of each parameter in its unit: `rel_step·|θ|`,
    or for θ = 0 the absolute step (`central_differences`)."""
    import math

    rel = rel_step if isinstance(rel_step, Mapping) else dict.fromkeys(wrt, rel_step)
    out = {}
    for name in wrt:
        value = float(params[name])
        if value != 0.0:
            out[name] = float(rel[name]) * abs(value)
            continue
        given = abs_step.get(name) if isinstance(abs_step, Mapping) else abs_step
        if given is None:
            spec = scene.params[name]
            width = spec.high - spec.low
            if not math.isfinite(width):
                raise ValueError(
                    f"{name} = 0 has no relative step and its range is unbounded: give "
                    f"abs_step for it (in {spec.unit or 'its unit'})"
                )
            given = float(rel[name]) * width
        if not (math.isfinite(given) and given > 0):
            raise ValueError(f"abs_step for {name} = {given!r} is invalid: it must be > 0")
        out[name] = float(given)
    return out


def _stencil(scene, name: str, value: float, h: float) -> list[tuple[int, float]]:
    """`[(offset in steps, weight)]` of the second-order difference of `name` at `value`:
    central, or one-sided where `value ∓ h` leaves the parameter's range."""
    spec = scene.params[name]
    if value - h < spec.low or (value - h == spec.low and not spec.low_inclusive):
        return [(0, -1.5), (1, 2.0), (2, -0.5)]
    if value + h > spec.high or (value + h == spec.high and not spec.high_inclusive):
        return [(0, 1.5), (-1, -2.0), (-2, 0.5)]
    return [(1, 0.5), (-1, -0.5)]
