"""The measurements behind issue 21's targets that are not work–precision rows: batch
throughput with the XLA small-solve ceiling, gradient against forward cost, and the cold and
warm `jaxdeploy simulate` of deploy_array. Each function returns a JSON-able dict with its
setting; the ratios are formed in `page.py`.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time

import numpy as np


def _timed(fn, *args):
    start = time.perf_counter()
    out = fn(*args)
    import jax

    jax.block_until_ready(out)
    return time.perf_counter() - start, out


def batch(cases: int = 256, singles: int = 8, t_end: float = 4e-3, shared_cases: int = 64) -> dict:
    """Per-simulation cost of slider_crank (the scene's default step control) as one vmap of
    `cases` cases against one at a time (`singles` of them, the mean), restitution spread over
    0.8–0.99. Run in a process pinned to one core, so both use the same hardware.

    Twice: with the default outputs (q, q̇, q̈, λ and memory at each of 401 saved times), and
    with `outputs="motion"` (q and q̇ alone). The difference is the saved times' q̈ and λ:
    the batch solves them after its loop, vmapped over the saved times (`batch_function`
    sets `simulate`'s `batch_saved_accelerations`), a run alone inside its loop.

    Then `shared_steps` at `shared_cases` cases of the same spread."""
    import jax
    import jax.numpy as jnp

    from jaxdeploy.batch import batch_function, run_scene, vmapped_control
    from jaxdeploy.scenes import SliderCrank

    scene = SliderCrank()
    shared = dict(scene.resolve_params())
    restitution = np.linspace(0.8, 0.99, cases)
    shared.pop("restitution")
    ts = jnp.linspace(0.0, t_end, 401)
    picks = restitution[np.linspace(0, cases - 1, singles).astype(int)]

    def measure(**options):
        # The batch runs as `simulate_batch` does (`vmapped_control`, which changes only
        # generalized-α, to Newton's method proper); slider_crank's default is Tsit5 on the
        # index-1 form, so both sides run the same solver.
        vmapped = batch_function(scene, ("restitution",), shared, t_end, ts, **options)
        compile_vmap, _ = _timed(vmapped, (jnp.asarray(restitution),))
        warm_vmap, trajectory = _timed(vmapped, (jnp.asarray(restitution),))
        one = jax.jit(
            lambda e: run_scene(scene, {**shared, "restitution": e}, t_end, ts=ts, **options)
        )
        compile_one, _ = _timed(one, picks[0])
        walls = [_timed(one, e)[0] for e in picks]
        per_single = float(np.mean(walls))
        return {
            "vmap_warm_s": warm_vmap,
            "vmap_per_simulation_s": warm_vmap / cases,
            "vmap_compile_s": compile_vmap - warm_vmap,
            "one_at_a_time_per_simulation_s": per_single,
            "one_at_a_time_compile_s": compile_one - walls[0],
            "speedup_per_simulation": per_single / (warm_vmap / cases),
        }, np.asarray(trajectory.stats["num_accepted_steps"])

    default, steps = measure()
    motion, _ = measure(outputs="motion")
    return {
        "scene": "slider_crank",
        "t_end_s": t_end,
        "cases": cases,
        "singles_timed": singles,
        **default,
        "motion": motion,
        "shared_steps": shared_steps(scene, shared, restitution, ts, t_end, shared_cases),
        "steps_min_max": [int(steps.min()), int(steps.max())],
        "steps_mean": float(steps.mean()),
        "vmap_solver": vmapped_control(scene.default_control).solver_name(),
        "one_at_a_time_solver": scene.default_control.solver_name(),
    }


def shared_steps(scene, shared, restitution, ts, t_end, cases: int) -> dict:
    """The batch with every case on one shared step sequence (`benchmarks.shared_steps`)
    against the plain vmap, both over `cases` cases spread as `restitution` is, warm, per
    simulation; with the accepted and rejected steps each runs (the plain vmap's per case)."""
    import jax.numpy as jnp

    from jaxdeploy.batch import batch_function

    from .shared_steps import shared_steps_function

    values = jnp.asarray(restitution[np.linspace(0, len(restitution) - 1, cases).astype(int)])
    together = shared_steps_function(scene, shared, "restitution", t_end, ts)
    compile_shared, _ = _timed(together, values)
    warm_shared, (_, accepted, rejected) = _timed(together, values)
    plain = batch_function(scene, ("restitution",), shared, t_end, ts)
    compile_plain, _ = _timed(plain, (values,))
    warm_plain, trajectory = _timed(plain, (values,))
    each = np.asarray(trajectory.stats["num_accepted_steps"])
    return {
        "cases": cases,
        "shared_per_simulation_s": warm_shared / cases,
        "shared_compile_s": compile_shared - warm_shared,
        "shared_accepted_steps": int(np.asarray(accepted)[0]),
        "shared_rejected_steps": int(np.asarray(rejected)[0]),
        "vmap_per_simulation_s": warm_plain / cases,
        "vmap_compile_s": compile_plain - warm_plain,
        "vmap_accepted_steps_min_max": [int(each.min()), int(each.max())],
        "vmap_accepted_steps_mean": float(each.mean()),
        "ratio": (warm_shared / cases) / (warm_plain / cases),
    }


def solve_ceiling(cases: int = 256, size: int = 16, iterations: int = 2000) -> dict:
    """XLA's own gain from vmapping small dense solves: `iterations` chained `size`×`size`
    solves (slider_crank's 9 coordinates + 7 constraints), one system against `cases` of them
    vmapped, on the same core. Speed-up = cases × t_one / t_vmapped."""
    import jax
    import jax.numpy as jnp

    rng = np.random.default_rng(0)
    a = rng.standard_normal((cases, size, size)) + size * np.eye(size)
    b = rng.standard_normal((cases, size))

    def chain(a, b):
        def body(_, x):
            return jnp.linalg.solve(a, b + 1e-3 * x)

        return jax.lax.fori_loop(0, iterations, body, b)

    single, many = jax.jit(chain), jax.jit(jax.vmap(chain))
    _timed(single, a[0], b[0])
    _timed(many, a, b)
    t_one = min(_timed(single, a[0], b[0])[0] for _ in range(3))
    t_many = min(_timed(many, a, b)[0] for _ in range(3))
    return {
        "size": size,
        "cases": cases,
        "iterations": iterations,
        "one_s": t_one,
        "vmapped_s": t_many,
        "speedup_per_solve": cases * t_one / t_many,
        "step": step_solves_ceiling(cases=cases, iterations=iterations),
    }


def step_solves_ceiling(cases: int = 256, iterations: int = 2000) -> dict:
    """vmap's gain on the linear algebra of one slider_crank Tsit5 step alone, the ceiling
    for the batched simulation: `iterations` chained evaluations of (a) the index-1
    accelerations (`Mechanism.accelerations`: forces, Φ_q, γ and the range-space solve, as at
    every Runge–Kutta stage, the step's end and each saved time) and (b) the projection onto
    the constraints (`project_onto_constraints`: two Gauss–Newton position corrections and a
    velocity correction, each a Schur-complement solve), each case with its own restitution;
    one case against `cases` vmapped, same core. Measured with the Schur complement factorised
    as the package does (`saddle_point.unrolled_cholesky`, m = 7) and with LAPACK's
    `potrf`/`trsm` (`UNROLLED_MAX_SIZE = 0`, the factor before it), in the same run."""
    import jax
    import jax.numpy as jnp

    from jaxdeploy.mechanism import saddle_point
    from jaxdeploy.scenes import SliderCrank
    from jaxdeploy.solvers.index1 import project_onto_constraints

    scene = SliderCrank()
    base = dict(scene.resolve_params())

    def chain(restitution):
        params = {**base, "restitution": restitution}
        mechanism = scene.build(params)
        state = scene.initial_state(params, mechanism)
        q, t = state.q, 0.0

        def body(_, v):
            qdd, _ = mechanism.accelerations(q, v, t, state.memory)
            q1, v1 = project_onto_constraints(mechanism, q + 1e-9 * v, v + 1e-9 * qdd, t)
            return v1 + 1e-12 * (qdd + q1)

        return jax.lax.fori_loop(0, iterations, body, state.v)

    restitution = jnp.linspace(0.8, 0.99, cases)
    out = {"scene": "slider_crank", "cases": cases, "iterations": iterations}
    default_size = saddle_point.UNROLLED_MAX_SIZE
    for factor, size in (("lapack", 0), ("unrolled", default_size)):
        # Traced programs are cached with the factor they were traced with (jit, and the
        # mechanism's `traced_once` functions): clear them on each change.
        saddle_point.UNROLLED_MAX_SIZE = size
        jax.clear_caches()
        try:
            single, many = jax.jit(chain), jax.jit(jax.vmap(chain))
            _timed(single, restitution[0])
            _timed(many, restitution)
            t_one = min(_timed(single, restitution[0])[0] for _ in range(3))
            t_many = min(_timed(many, restitution)[0] for _ in range(3))
        finally:
            saddle_point.UNROLLED_MAX_SIZE = default_size
            jax.clear_caches()
        out[factor] = {
            "one_s": t_one,
            "vmapped_s": t_many,
            "speedup_per_case": cases * t_one / t_many,
        }
    # The package's factor is the ceiling the simulation runs against.
    return {**out, **out["unrolled"]}


GRADIENT_WRT = ("restitution", "friction_coefficient", "panel1_clearance", "panel2_clearance")
# slider_crank's gradient programs (`slider_crank_gradient_programs`): compile, not the loss.
SLIDER_CRANK_WRT = ("restitution", "clearance")
GRADIENT_FD_STEPS = (1e-3, 1e-5, 1e-7)  # relative steps of the central differences
# Memory flags whose flip between two runs over the same steps switches the discrete map:
# a clearance joint's contact state, a latch's engagement.
SWITCH_FLAGS = ("in_contact", "engaged")


def gradient(t_end: float = 0.2, repeats: int = 2, fd_steps=GRADIENT_FD_STEPS) -> dict:
    """A deploy_array loss (mean square of panel 2's tip acceleration over `t_end`, 201
    samples; the scene's default step control) and its gradient with respect to
    `GRADIENT_WRT` in both modes of `jaxdeploy.fit.gradient_function` (steps replayed, as
    `jaxdeploy.fit` does), against one forward run and against the forward run with its
    steps replayed (what every gradient pays before differentiating); warm walls, best of
    `repeats` rounds taken in turn. Then `gradient_check`: the gradient against central
    differences at the relative steps `fd_steps`."""
    import diffrax as dfx
    import jax
    import jax.numpy as jnp

    from jaxdeploy.batch import run_scene
    from jaxdeploy.fit import gradient_function, gradient_mode
    from jaxdeploy.scenes import DeployArray

    from .programs import compile_stats

    scene = DeployArray()
    base = scene.resolve_params()
    x0 = {k: jnp.asarray(base[k]) for k in GRADIENT_WRT}

    def loss(channels):
        return jnp.mean(channels["panel2_tip_ay"] ** 2)

    def run(x, replay):
        params = {**base, **x}
        traj = run_scene(scene, params, t_end, n_save=201, replay_steps=replay)
        return loss(scene.channels(scene.build(params), traj)), traj.stats

    functions = {
        "forward": jax.jit(lambda x: run(x, False)),
        "replay": jax.jit(lambda x: run(x, True)[0]),
    }
    for mode in ("forward", "reverse"):
        g, _ = gradient_function(scene, base, GRADIENT_WRT, loss, t_end, mode=mode, n_save=201)
        functions[f"gradient_{mode}"] = jax.jit(g)
    out = {"scene": "deploy_array", "t_end_s": t_end, "wrt": list(GRADIENT_WRT)}
    first, values, programs = {}, {}, {}
    for name, fn in functions.items():
        # The first call, compile included, as phases: trace and lower, XLA's compile (CPU
        # seconds of this process and the program's size: `programs.compile_stats`), run.
        functions[name], programs[name] = compile_stats(fn, x0)
        first[name], values[name] = _timed(functions[name], x0)
        first[name] += programs[name]["compile_wall_s"]
    warm = {name: [] for name in functions}
    for _ in range(repeats):
        for name, fn in functions.items():
            warm[name].append(_timed(fn, x0)[0])
    for name in functions:
        best = min(warm[name])
        out[name] = {"compile_s": first[name] - best, "warm_s": best, "program": programs[name]}
    stats = values["forward"][1]
    max_steps = int(stats["max_steps"])
    out["steps"] = {"accepted": int(stats["num_accepted_steps"]),
                    "rejected": int(stats["num_rejected_steps"]), "max_steps": max_steps,
                    "checkpoints": dfx.RecursiveCheckpointAdjoint().checkpoints
                    or _default_checkpoints(max_steps)}  # fmt: skip
    out["loss"] = float(values["forward"][0])
    grads = {m: {k: float(v) for k, v in values[f"gradient_{m}"][1].items()}
             for m in ("forward", "reverse")}  # fmt: skip
    out["gradient_values"] = grads
    out["modes_max_relative_difference"] = max(
        abs(grads["forward"][k] - grads["reverse"][k]) / abs(grads["reverse"][k])
        for k in GRADIENT_WRT
    )
    out["auto_mode"] = gradient_mode(len(GRADIENT_WRT))
    for mode in ("forward", "reverse"):
        out[f"ratio_{mode}"] = out[f"gradient_{mode}"]["warm_s"] / out["forward"]["warm_s"]
    out["ratio"] = out[f"ratio_{out['auto_mode']}"]
    out["replay_ratio"] = out["replay"]["warm_s"] / out["forward"]["warm_s"]
    out["rhs"] = rhs_cost(scene, base)
    out["slider_crank_programs"] = slider_crank_gradient_programs()
    out["central_differences"] = gradient_check(
        scene, base, loss, t_end, grads[out["auto_mode"]], fd_steps
    )
    return out


def slider_crank_gradient_programs(t_end: float = 4e-3) -> dict:
    """The compile of `jaxdeploy.fit.gradient_function`'s programs for slider_crank (both
    modes; `programs.compile_stats`): a loss of the slider's acceleration over `t_end` (201
    samples, the scene's default step control) with respect to `SLIDER_CRANK_WRT`, and one
    warm call each."""
    import jax
    import jax.numpy as jnp

    from jaxdeploy.fit import gradient_function
    from jaxdeploy.scenes import SliderCrank

    from .programs import compile_stats

    scene = SliderCrank()
    base = scene.resolve_params()

    def loss(channels):
        return jnp.mean(channels["slider_ax"] ** 2)

    out = {"scene": "slider_crank", "t_end_s": t_end, "wrt": list(SLIDER_CRANK_WRT)}
    for mode in ("forward", "reverse"):
        g, x0 = gradient_function(scene, base, SLIDER_CRANK_WRT, loss, t_end, mode=mode,
                                  n_save=201)  # fmt: skip
        compiled, stats = compile_stats(jax.jit(g), x0)
        _timed(compiled, x0)
        out[mode] = {**stats, "warm_s": _timed(compiled, x0)[0]}
    return out


def rhs_cost(scene, base, calls: int = 2000) -> dict:
    """What one evaluation of the accelerations (`Mechanism.accelerations`, the right-hand
    side every stage of every step evaluates) costs, and its JVP with 1 and with 4 tangents
    (vmapped, as `jax.jacfwd` carries them) and its VJP, in µs per call: `calls` chained
    calls in one compiled loop, so dispatch is not counted."""
    import jax
    import jax.numpy as jnp

    mechanism = scene.build(base)
    state = scene.initial_state(base, mechanism)
    memory = state.memory
    q0, v0 = jnp.asarray(state.q), jnp.asarray(state.v)
    tangents = 1e-6 * jax.random.normal(jax.random.PRNGKey(0), (4, q0.size))

    def f(q, v):
        return mechanism.accelerations(q, v, 0.0, memory)[0]

    def primal(q, d):
        return q + 1e-12 * f(q, v0), d

    def jvp1(q, d):
        a, da = jax.jvp(f, (q, v0), (d[0], d[0]))
        return q + 1e-12 * a, d.at[0].add(1e-12 * da)

    def jvp4(q, d):
        a, da = jax.vmap(lambda t: jax.jvp(f, (q, v0), (t, t)), out_axes=(None, 0))(d)
        return q + 1e-12 * a, d + 1e-12 * da

    def vjp(q, d):
        a, pull = jax.vjp(f, q, v0)
        gq, _ = pull(d[0])
        return q + 1e-12 * a, d.at[0].add(1e-12 * gq)

    out = {"coordinates": int(q0.size), "constraints": int(mechanism.n_constraints)}
    for name, body in (("primal", primal), ("jvp1", jvp1), ("jvp4", jvp4), ("vjp", vjp)):
        loop = jax.jit(lambda q, d, body=body: jax.lax.fori_loop(
            0, calls, lambda i, c: body(*c), (q, d)))  # fmt: skip
        _timed(loop, q0, tangents)
        out[f"{name}_us"] = 1e6 * min(_timed(loop, q0, tangents)[0] for _ in range(3)) / calls
    return out


def _default_checkpoints(max_steps: int) -> int:
    """diffrax's default checkpoint count for `max_steps` (equinox's
    `checkpointed_while_loop`: ⌊−1.5 + √(2 max_steps + ¼)⌋ + 1, at most `max_steps`)."""
    import math

    return min(max_steps, math.floor(-1.5 + math.sqrt(2 * max_steps + 0.25)) + 1)


def gradient_check(scene, base, loss, t_end, grad, fd_steps, n_save: int = 201) -> dict:
    """The gradient `grad` ({name: value}) against central differences of the same loss,
    `(L(θ + h e_k) − L(θ − h e_k)) / 2h`, h = rel·|θ_k| for each relative step in
    `fd_steps`, every perturbed run over the unperturbed run's accepted steps (so both
    differentiate one discrete map). All runs are one vmapped batch that also saves the
    state at every step end: where a difference disagrees, the switch flags (`SWITCH_FLAGS`)
    of the two runs tell whether a contact onset or separation (or a latch) moved across a
    step end between them — a jump of the discrete map inside [θ − h, θ + h], which a
    difference sees and a derivative does not."""
    import jax
    import jax.numpy as jnp

    from jaxdeploy.batch import run_scene, simulate_batch

    names = list(grad)
    samples = np.linspace(0.0, t_end, n_save)
    reference = jax.jit(lambda: run_scene(scene, base, t_end, ts=samples, replay_steps=True))()
    times = np.asarray(reference.step_times)
    ends = times[np.isfinite(times)]
    ts = np.concatenate([samples, ends])
    order = np.argsort(ts, kind="stable")
    where = np.empty_like(order)
    where[order] = np.arange(order.size)
    at_samples, at_ends = where[:n_save], where[n_save:]
    cases = [dict(base)]
    for name in names:
        for rel in fd_steps:
            h = rel * abs(base[name])
            cases += [{**base, name: base[name] + h}, {**base, name: base[name] - h}]
    batch = simulate_batch(scene, cases, t_end, ts=ts[order], replay_steps=times)
    if not all(batch.ok):
        raise RuntimeError(f"a perturbed run failed: {[s for s in batch.statuses() if s != 'ok']}")
    losses, flags = [], []
    for i in range(batch.size):
        case = batch.case(i)
        channels = scene.channels(batch.mechanism(i), case)
        sampled = {k: np.asarray(v)[at_samples] for k, v in channels.items()}
        losses.append(float(loss({k: jnp.asarray(v) for k, v in sampled.items()})))
        flags.append(_switch_flags(case.memory, at_ends))
    rows = []
    for k, name in enumerate(names):
        for j, rel in enumerate(fd_steps):
            plus, minus = 1 + 2 * (k * len(fd_steps) + j), 2 + 2 * (k * len(fd_steps) + j)
            h = rel * abs(base[name])
            fd = (losses[plus] - losses[minus]) / (2 * h)
            differ = flags[plus] != flags[minus]
            steps = np.nonzero(differ.any(axis=0))[0]
            rows.append({
                "parameter": name, "relative_step": rel, "central_difference": fd,
                "gradient": grad[name],
                "relative_error": abs(fd - grad[name]) / abs(grad[name]),
                "switched_steps": int(steps.size),
                "first_switch_s": float(ends[steps[0]]) if steps.size else None,
            })  # fmt: skip
    smooth = [r["relative_error"] for r in rows if r["switched_steps"] == 0]
    return {
        "relative_steps": list(fd_steps),
        "step_ends": int(ends.size),
        "rows": rows,
        "max_relative_error_smooth": max(smooth) if smooth else None,
        "loss_replayed": losses[0],
    }


def _switch_flags(memory, at) -> np.ndarray:
    """The `SWITCH_FLAGS` of every element's memory at the saved positions `at`, as a
    boolean array (flags, len(at))."""
    rows = []
    for element in memory or ():
        if isinstance(element, dict):
            for key in SWITCH_FLAGS:
                if key in element and np.ndim(element[key]) == 1:
                    rows.append(np.asarray(element[key])[at] > 0.5)
    return np.array(rows, dtype=bool).reshape(len(rows), len(at))


def simulate_cold_warm(scene: str = "deploy_array") -> dict:
    """Wall time of `jaxdeploy simulate SCENE` (the scene's defaults, the whole command:
    import, scene build, compile, run, ideal reference, files) twice in fresh processes with
    a new, empty persistent compilation cache: cold (nothing cached), then warm. Beside each
    wall: the CPU time of the process (user + system, every thread) and the phases its
    `summary.json` recorded (`start_up_s`: the wall before the phases began: interpreter,
    imports, arguments)."""
    import json
    import resource

    out = {"scene": scene}
    with tempfile.TemporaryDirectory() as tmp:
        env = {**os.environ, "JAXDEPLOY_CACHE_DIR": os.path.join(tmp, "cache")}
        for run in ("cold", "warm"):
            command = [sys.executable, "-c", "import sys; from jaxdeploy.cli import main; "
                       "sys.exit(main())", "simulate", scene, "--out",
                       os.path.join(tmp, run), "--quiet"]  # fmt: skip
            before = resource.getrusage(resource.RUSAGE_CHILDREN)
            start = time.perf_counter()
            done = subprocess.run(command, env=env, capture_output=True, text=True)
            wall = time.perf_counter() - start
            after = resource.getrusage(resource.RUSAGE_CHILDREN)
            if done.returncode != 0:
                raise RuntimeError(f"jaxdeploy simulate failed ({run}): {done.stderr[-2000:]}")
            with open(os.path.join(tmp, run, "summary.json")) as f:
                summary = json.load(f)
            out[f"{run}_s"] = wall
            out[f"{run}_cpu_s"] = (after.ru_utime - before.ru_utime) + (
                after.ru_stime - before.ru_stime
            )
            out[f"{run}_phases"] = {
                "start_up_s": wall - summary["wall_time_s"],
                **summary["phases"],
            }
            out[f"{run}_steps"] = {k: summary.get(k) for k in ("n_steps", "n_rejected")}
    return out
