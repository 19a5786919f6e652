"""Batch throughput: cost per simulation in one vmapped batch of B cases relative to one
simulation, measured side by side in one run (compilation timed separately, ahead of time).

    PYTHONPATH=. python experiments/batch_throughput.py [--scene deploy_array] [--batch 256]
        [--t-end 0.05] [--repeats 1] [--out docs/batch_throughput.json]

The B cases scatter the varied parameters around the scene's defaults (deploy_array: panel1_ra,
panel2_ra, panel1_clearance, panel2_clearance), x_i = x0 e^{s ξ_i}, ξ_i ~ N(0, 1) seeded, s =
`--spread` (default 0.1: the manufacturing-scatter use case of robust design), so the batch is
not one case repeated. A batch advances until its slowest case ends, so a wide spread (cases of
very different stiffness) costs more per case; `--spread 1` shows it. A single run is timed on
the first case. Times are wall-clock medians over `--repeats` interleaved calls of the
compiled programs (single, batch, single, ...); the ratio, not the absolute time, is the
result (the machine is shared).
"""

from __future__ import annotations

import argparse
import json
import sys
import time

import jax
import jax.numpy as jnp
import numpy as np

import jaxdeploy
from jaxdeploy.batch import _stack_cases, batch_function, step_control
from jaxdeploy.io import atomic_write_bytes, atomic_write_json, run_metadata
from jaxdeploy.scenes import get_scene

VARIED = {
    "deploy_array": ("panel1_ra", "panel2_ra", "panel1_clearance", "panel2_clearance"),
    "slider_crank": ("clearance",),
}


def cases(scene, batch, spread, seed):
    rng = np.random.default_rng(seed)
    defaults = scene.default_params()
    return {
        name: defaults[name] * np.exp(spread * rng.standard_normal(batch))
        for name in VARIED[scene.name]
    }


def timed(fn, args, repeats):
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        out = fn(args)
        jax.block_until_ready(out)
        times.append(time.perf_counter() - start)
    return float(np.median(times)), out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scene", default="deploy_array", choices=sorted(VARIED))
    ap.add_argument("--batch", type=int, default=256)
    ap.add_argument("--t-end", type=float, default=0.05)
    ap.add_argument("--n-save", type=int, default=11)
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--spread", type=float, default=0.1, help="log-normal scatter s")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default=None, help="write the result as JSON here")
    ap.add_argument("--doc", default=None, help="write a generated markdown page here")
    ap.add_argument(
        "--from-json", default=None, help="only rewrite --doc from a stored --out result"
    )
    args = ap.parse_args(argv)

    if args.from_json:
        with open(args.from_json) as fh:
            stored = json.load(fh)
        atomic_write_bytes(args.doc, page(stored, stored["argv"]).encode())
        return stored
    scene = get_scene(args.scene)
    table, varied, shared = _stack_cases(
        scene, cases(scene, args.batch, args.spread, args.seed), None
    )
    ts = jnp.linspace(0.0, args.t_end, args.n_save)
    run = batch_function(scene, varied, shared, args.t_end, ts)
    stacked = tuple(jnp.asarray(table[k]) for k in varied)
    one = tuple(v[:1] for v in stacked)  # the same program at batch size 1

    result = {
        "scene": args.scene,
        "batch": args.batch,
        "t_end": args.t_end,
        "spread": args.spread,
        "seed": args.seed,
        "varied": varied,
    }
    compiled = {}
    for label, inputs in (("single", one), ("batch", stacked)):
        start = time.perf_counter()
        compiled[label] = run.lower(inputs).compile()
        result[f"{label}_compile_s"] = time.perf_counter() - start
    # Interleaved (single, batch, single, batch, ...) so that both see the same load.
    walls = {"single": [], "batch": []}
    for _ in range(args.repeats):
        for label, inputs in (("single", one), ("batch", stacked)):
            wall, trajectory = timed(compiled[label], inputs, 1)
            walls[label].append(wall)
            steps = np.asarray(trajectory.stats["num_accepted_steps"])
            result[f"{label}_steps_max"] = int(steps.max())
            result[f"{label}_steps_mean"] = float(steps.mean())
            result[f"{label}_ok"] = int(np.sum(np.asarray(trajectory.result._value) == 0))
            print(f"{label}: {wall:.3f} s for {len(inputs[0])} case(s)", flush=True)
    for label in walls:
        result[f"{label}_wall_s"] = float(np.median(walls[label]))
        result[f"{label}_walls_s"] = walls[label]
    per_case = result["batch_wall_s"] / args.batch
    result["batch_per_case_s"] = per_case
    result["speedup_per_case"] = result["single_wall_s"] / per_case
    result["control"] = step_control(scene)
    result["versions"] = run_metadata()
    result["jaxdeploy_version"] = jaxdeploy.__version__
    result["argv"] = sys.argv[1:] if argv is None else list(argv)
    print(
        f"{args.scene}, t_end {args.t_end} s: one run {result['single_wall_s']:.3f} s; batch of "
        f"{args.batch} {result['batch_wall_s']:.2f} s = {per_case:.4f} s per case: "
        f"{result['speedup_per_case']:.2f}x cheaper per simulation "
        f"(steps: single {result['single_steps_max']}, batch max {result['batch_steps_max']})"
    )
    if args.out:
        atomic_write_json(args.out, result)
    if args.doc:
        atomic_write_bytes(args.doc, page(result, argv).encode())
    return result


def row(label, cases, wall, steps, compile_s) -> str:
    return f"| {label} | {cases} | {wall:.3f} | {wall / cases:.4f} | {steps} | {compile_s:.1f} |"


def page(r, argv) -> str:
    verdict = _verdict(r)
    argv = sys.argv[1:] if argv is None else argv
    command = "PYTHONPATH=. python experiments/batch_throughput.py " + " ".join(argv)
    v = r["versions"]
    return f"""# Batch throughput (generated)

*Written by `{command.strip()}`; rerun it to regenerate. Machine: {v["platform"]},
{len(v["devices"])} device(s), jax {v["jax"]}; shared by several users, so only the ratio of
the two timings, taken side by side in one run, is meaningful.*

Scene `{r["scene"]}` to t = {r["t_end"]} s; the batch varies {", ".join(r["varied"])} by a
log-normal spread s = {r["spread"]} around the defaults (seed {r["seed"]}). Both programs are
compiled ahead of time (`jit(...).lower(...).compile()`), and the timings exclude compilation.

| | cases | wall time [s] | per case [s] | accepted steps (max) | compile [s] |
|---|---|---|---|---|---|
{row("one simulation", 1, r["single_wall_s"], r["single_steps_max"], r["single_compile_s"])}
{row("vmapped batch", r["batch"], r["batch_wall_s"], r["batch_steps_max"], r["batch_compile_s"])}

**Speed-up per simulation: {r["speedup_per_case"]:.2f}** (single-run time over the batch's
time per case; target ≥ 2). {r["batch_ok"]} of {r["batch"]} cases succeeded. {verdict}

A batch advances as one `while` loop until its slowest case finishes, every case taking every
step of the batch (finished or easy cases are masked), so it pays the step count of its slowest
case ({r["batch_steps_max"]} against {r["single_steps_max"]} here). Inside a step, the Newton
`while` loop runs until the last case has converged, and modified Newton forms a new iteration
matrix whenever *any* case asks for one (a batched `while` rather than a `cond`, so no case pays
for it when none asks; `jaxdeploy.solvers.generalized_alpha._run_if`). A gain would have to come
from amortising XLA's per-operation overhead on CPU over the batch; but since the solver
reuses its factorised matrix, a single run's step is mostly the residual (forces, rough
contact law, constraints), which is arithmetic rather than overhead: measured in one compiled
loop (`experiments/step_profile.py` style, deploy_array), the residual costs about as much per
case in a vmapped batch of 64 as alone, so batching has little to amortise.
"""


def _verdict(r) -> str:
    if r["speedup_per_case"] >= 2:
        return "The target is met."
    return (
        "**The target is not met**: on this CPU the vmapped batch costs "
        f"{1 / r['speedup_per_case']:.1f}× more per simulation than single runs, so for "
        "throughput here run cases one by one (or in small batches) in parallel processes; "
        "batching still gives one compilation for all cases and the sharding across devices."
    )


if __name__ == "__main__":
    main()
