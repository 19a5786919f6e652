"""Where a generalized-α step's time goes, measured side by side in one run; writes the
`step_profile` block of docs/performance.md.

    PYTHONPATH=. python experiments/step_profile.py [--before DIR] [--repeats 3] [--no-doc]

For each case (ideal slider-crank, h = 1e-5, two revolutions; clearance slider-crank,
h = 1e-6, first 1.5 ms; deploy_array, h = 1e-4, first 0.2 s) and each Newton variant
(`GeneralizedAlpha(newton="full")`: iteration matrix formed and factorised at every iteration;
`"modified"`, the default: factorisation reused across iterations and steps):

* the whole fixed-step `simulate` run, per accepted step, with Newton iterations and matrix
  formations per step;
* the parts, each called 2000 times inside one compiled `lax.scan` with the mechanism passed
  as a traced argument (as in a real run: nothing constant-folded): the step residual r(z)
  (forces and contact Q, constraints Φ, Φ_qᵀμ), the forces Q alone, the iteration matrix
  (`StepSystem.iteration_matrix`: compressed forward-mode derivatives), its factorisation
  and one solve with the factors;
* diffrax's loop: the same `simulate` with a solver whose step does no work.

The breakdown per step is `iterations × (residual + solve) + formations × (matrix +
factorisation) + diffrax loop`, and the rest (the Newton `while` loop and its convergence
test, predictor, memory updates, error estimate) is the measured step minus those. Times are
CPU seconds of this process (`time.process_time`), medians over `--repeats`: on a shared
machine they are less disturbed by other jobs than wall time, but still only ratios within
one run are meaningful.

`--before DIR`: also time the whole runs with the jaxdeploy package found in DIR (e.g. an
export of an older commit, `git archive c9518d3 jaxdeploy | tar -x -C DIR`), in a
subprocess, in the same run.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
DOC = os.path.join(HERE, "..", "docs", "performance.md")

CASES = {
    "slider_crank ideal, h = 1e-5, 2 rev.": ("slider_crank", True, 1e-5, None),
    "slider_crank clearance, h = 1e-6, 1.5 ms": ("slider_crank", False, 1e-6, 1.5e-3),
    "deploy_array, h = 1e-4, 0.2 s": ("deploy_array", False, 1e-4, 0.2),
}


def _cpu(fn, repeats):
    out = fn()  # compiles
    times = []
    for _ in range(repeats):
        start = time.process_time()
        out = fn()
        times.append(time.process_time() - start)
    return out, float(np.median(times))


def _setup(scene_name, ideal):
    from jaxdeploy.scenes import DeployArray, SliderCrank

    scene = SliderCrank(ideal=ideal) if scene_name == "slider_crank" else DeployArray()
    params = scene.resolve_params()
    mech = scene.build(params)
    return scene, mech, scene.initial_state(params, mech)


def whole_runs(repeats, modes=("full", "modified")) -> dict:
    """`{case: {mode: {us_per_step, iterations, matrices, steps}}}` for the package on the
    path (also run by `--whole-only` in a subprocess for `--before`)."""
    import jax

    from jaxdeploy.simulation import simulate
    from jaxdeploy.solvers import GeneralizedAlpha

    out = {}
    for label, (scene_name, ideal, dt, t_end) in CASES.items():
        scene, mech, s0 = _setup(scene_name, ideal)
        t_end = scene.default_t_end if t_end is None else t_end
        out[label] = {}
        for mode in modes:
            solver = GeneralizedAlpha() if mode == "default" else GeneralizedAlpha(newton=mode)

            def run(solver=solver, mech=mech, s0=s0, t_end=t_end, dt=dt):
                trajectory = simulate(mech, s0, t_end, dt=dt, n_save=11, solver=solver)
                jax.block_until_ready(trajectory.q)
                return trajectory

            trajectory, cpu = _cpu(run, repeats)
            steps = int(trajectory.stats["num_accepted_steps"])
            out[label][mode] = dict(
                us_per_step=cpu / steps * 1e6,
                steps=steps,
                iterations=int(trajectory.stats["num_newton_iterations"]) / steps,
                matrices=int(trajectory.stats.get("num_jacobian_evaluations", -steps)) / steps,
                ok=trajectory.ok,
            )
            print(label, mode, out[label][mode], flush=True)
    return out


def diffrax_loop(repeats) -> dict:
    """µs per step of `simulate` with a solver whose step returns its input (the cost of
    diffrax's loop, step-size control and saving)."""
    import diffrax as dfx
    import jax
    import jax.numpy as jnp

    from jaxdeploy.simulation import simulate
    from jaxdeploy.solvers import GeneralizedAlpha

    class NoWork(GeneralizedAlpha):
        def step(self, terms, t0, t1, y0, args, solver_state, made_jump):
            zero = jax.tree_util.tree_map(jnp.zeros_like, y0)
            info = dict(y0=y0, y1=y0, k0=zero, k1=zero)
            return y0, zero, info, solver_state, dfx.RESULTS.successful

    out = {}
    for label, (scene_name, ideal, dt, t_end) in CASES.items():
        scene, mech, s0 = _setup(scene_name, ideal)
        t_end = scene.default_t_end if t_end is None else t_end

        def run(mech=mech, s0=s0, t_end=t_end, dt=dt):
            trajectory = simulate(mech, s0, t_end, dt=dt, n_save=11, solver=NoWork())
            jax.block_until_ready(trajectory.q)
            return trajectory

        trajectory, cpu = _cpu(run, repeats)
        out[label] = cpu / int(trajectory.stats["num_accepted_steps"]) * 1e6
    return out


def parts(repeats, calls=2000) -> dict:
    """µs per call of the parts of one Newton iteration, mechanism traced."""
    out = {}
    for label, (scene_name, ideal, dt, _) in CASES.items():
        out[label] = _case_parts(scene_name, ideal, dt, repeats, calls)
        print(label, out[label], flush=True)
    return out


def _case_parts(scene_name, ideal, dt, repeats, calls, batch=None) -> dict:
    """µs of CPU per call of each part, for one case; with `batch`, per case of a vmapped
    group of `batch` identical cases (the batch's cost divided by `batch`)."""
    import jax
    import jax.numpy as jnp

    from jaxdeploy.solvers.generalized_alpha import StepSystem, _apply_factor, _factor

    _, mech, s0 = _setup(scene_name, ideal)
    n = s0.q.shape[0]
    memory = mech.memory_for_step(s0.memory, s0.q, s0.v)
    beta_p = 1.0 / dt**2

    def system(mech):
        return StepSystem(mech, s0.q, s0.v, 1.0 / dt, beta_p, 0.0, memory)

    def residual(mech, x):
        return jnp.concatenate(system(mech).residual((x[:n], x[n:])))

    def matrix(mech, x):
        return system(mech).iteration_matrix(x)

    x0 = jnp.concatenate([jnp.zeros_like(s0.q), s0.lam / beta_p])
    pieces = {
        "residual r(z)": lambda mech, factors, x: residual(mech, x),
        "forces and contact Q": lambda mech, factors, x: mech.generalized_forces(
            s0.q + x[:n], s0.v, 0.0, memory
        ),
        "iteration matrix": lambda mech, factors, x: matrix(mech, x),
        "factorisation": lambda mech, factors, x: _factor(matrix(mech, x))[0],
        "solve with factors": lambda mech, factors, x: _apply_factor(*factors, x),
    }
    size = 1 if batch is None else batch
    z0 = x0 if batch is None else jnp.tile(x0, (batch, 1))
    # The factors are an argument, one set per case in a group, as in a run (where they are
    # carried in each case's solver state). Closed over as constants, XLA compiled the
    # batched solve of a group of 32 into a path ~300x slower per case than a run's.
    factors = _factor(matrix(mech, x0))
    if batch is not None:
        factors = jax.tree.map(lambda f: jnp.tile(f, (batch,) + (1,) * f.ndim), factors)
    out = {}
    for name, fn in pieces.items():
        each = fn if batch is None else jax.vmap(fn, in_axes=(None, 0, 0))

        @jax.jit
        def loop(mech, factors, z, each=each):
            def body(c, _):
                # A nonlinear use of every output entry: with a plain sum XLA folds linear
                # work (e.g. forward derivatives along constant directions) into the sum.
                r = each(mech, factors, c)
                return c + 1e-30 * jnp.sum(r * r), None

            return jax.lax.scan(body, z, None, length=calls)[0]

        _, cpu = _cpu(lambda loop=loop: jax.block_until_ready(loop(mech, factors, z0)), repeats)
        out[name] = cpu / calls / size * 1e6
    # The factorisation row above includes forming the matrix: report it alone.
    out["factorisation"] -= out["iteration matrix"]
    out["size"] = int(x0.shape[0])
    return out


def breakdown(whole, loop, piece) -> dict:
    rows = {}
    for label in CASES:
        rows[label] = {}
        for mode, w in whole[label].items():
            p = piece[label]
            iterate = w["iterations"] * (p["residual r(z)"] + p["solve with factors"])
            form = w["matrices"] * (p["iteration matrix"] + max(p["factorisation"], 0.0))
            rest = w["us_per_step"] - iterate - form - loop[label]
            rows[label][mode] = dict(iterate=iterate, form=form, loop=loop[label], rest=rest)
    return rows


def page(whole, loop, piece, rows, before, load, argv, before_label=None) -> str:
    lines = [
        f"*Generated by `PYTHONPATH=. python experiments/step_profile.py {' '.join(argv)}`"
        f" (load average at start {load:.1f} on 2 CPUs; CPU time of the process, median of"
        " repeats; ratios within this run are what counts).*",
        "",
        "Whole fixed-step runs, µs of CPU per accepted step (Newton iterations and iteration"
        "-matrix formations per step in brackets)"
        + (f"; *before* is {before_label}, run in the same session:" if before else ":"),
        "",
        "| case | " + ("before | " if before else "") + "full Newton | modified Newton "
        "(default) | speed-up |",
        "|---|" + ("---|" if before else "") + "---|---|---|",
    ]
    for label in CASES:
        full, mod = whole[label]["full"], whole[label]["modified"]
        first = (
            [
                f"{before[label]['default']['us_per_step']:.1f} "
                f"({before[label]['default']['iterations']:.2f} it., "
                f"{before[label]['default']['matrices']:.3f} mat.)"
            ]
            if before
            else []
        )
        base = before[label]["default"]["us_per_step"] if before else full["us_per_step"]
        lines.append(
            "| "
            + " | ".join(
                [label, *first]
                + [
                    f"{r['us_per_step']:.1f} ({r['iterations']:.2f} it., {r['matrices']:.3f} mat.)"
                    for r in (full, mod)
                ]
                + [f"{base / mod['us_per_step']:.1f}×"]
            )
            + " |"
        )
    lines += [
        "",
        "Parts, µs of CPU per call (mechanism traced, inside one compiled loop):",
        "",
        "| case | system size | residual r(z) | of which Q (forces, contact) | iteration matrix |"
        " factorisation | solve with factors |",
        "|---|---|---|---|---|---|---|",
    ]
    for label in CASES:
        p = piece[label]
        lines.append(
            f"| {label} | {p['size']} | {p['residual r(z)']:.2f} | "
            f"{p['forces and contact Q']:.2f} | {p['iteration matrix']:.2f} | "
            f"{max(p['factorisation'], 0.0):.2f} | {p['solve with factors']:.2f} |"
        )
    lines += [
        "",
        "Where a step's time goes (µs per step; *iterations* = iterations × (residual + "
        "solve), *matrices* = formations × (matrix + factorisation), *diffrax* = the loop with "
        "a solver that does no work, *rest* = measured − the others: the Newton `while` loop "
        "and convergence test, predictor, memory updates, error estimate):",
        "",
        "| case | Newton | step | iterations | matrices | diffrax | rest |",
        "|---|---|---|---|---|---|---|",
    ]
    for label in CASES:
        for mode in ("full", "modified"):
            r = rows[label][mode]
            lines.append(
                f"| {label} | {mode} | {whole[label][mode]['us_per_step']:.1f} | "
                f"{r['iterate']:.1f} | {r['form']:.1f} | {r['loop']:.1f} | {r['rest']:.1f} |"
            )
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--before", default=None, help="directory holding an older jaxdeploy")
    ap.add_argument(
        "--before-label",
        default="an older package",
        help="what --before is, for the generated text (e.g. 'main at c035706')",
    )
    ap.add_argument("--whole-only", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--no-doc", action="store_true")
    ap.add_argument("--json", default=None, help="also write the numbers as JSON here")
    args = ap.parse_args(argv)
    argv = sys.argv[1:] if argv is None else list(argv)

    if args.whole_only:  # subprocess for --before: the package on PYTHONPATH, default solver
        print("RESULT " + json.dumps(whole_runs(args.repeats, modes=("default",))))
        return None

    import jaxdeploy  # noqa: F401  (float64)

    load = os.getloadavg()[0]
    before = None
    if args.before:
        env = dict(os.environ, PYTHONPATH=os.path.abspath(args.before))
        proc = subprocess.run(
            [
                sys.executable,
                os.path.abspath(__file__),
                "--whole-only",
                "--repeats",
                str(args.repeats),
            ],
            env=env,
            capture_output=True,
            text=True,
            check=True,
            cwd=args.before,
        )
        line = [x for x in proc.stdout.splitlines() if x.startswith("RESULT ")][-1]
        before = json.loads(line[len("RESULT ") :])
    whole = whole_runs(args.repeats)
    loop = diffrax_loop(args.repeats)
    piece = parts(args.repeats)
    rows = breakdown(whole, loop, piece)
    text = page(whole, loop, piece, rows, before, load, argv, args.before_label)
    print(text)
    if args.json:
        from jaxdeploy.io import atomic_write_json

        atomic_write_json(
            args.json, dict(whole=whole, loop=loop, parts=piece, rows=rows, before=before)
        )
    if not args.no_doc:
        sys.path.insert(0, HERE)
        from jaxdeploy.io import replace_block

        replace_block(DOC, "step_profile", text)
    return rows


if __name__ == "__main__":
    main()
