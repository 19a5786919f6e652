"""Cost of one gradient of a 2 s deploy_array loss against one forward simulation, and the
memory of the reverse pass, measured side by side in one process.

Loss: the mean square of panel 2's tip acceleration over the 2 s run (2001 saved samples), a
scalar of the whole trajectory; gradient with respect to six contact parameters (Ra and c of
both clearance hinges, c_e, μ) by reverse mode through the generalized-α solver
(`diffrax.RecursiveCheckpointAdjoint`: treeverse/binomial checkpointing, Griewank & Walther
2000), the adaptive steps replayed (`replay_steps=True`, as `jaxdeploy.fit` differentiates).
Timings exclude compilation (reported separately): each is the best of `--repeats` runs.
Memory: XLA's static buffer plan of each compiled program (`memory_analysis()`: the
checkpointed reverse pass allocates its checkpoints up front, so this is the peak of the
pass, fixed before any step is taken and independent of the number of steps), and the
process's peak resident set size after the forward runs and after the gradient runs.

Usage: `PYTHONPATH=. python experiments/gradient_cost.py [--t-end 2] [--repeats 2]`
(about 10 minutes on 2 shared cores). Writes `docs/figures/gradient_cost.json` and the
"gradient_cost" block of `docs/identification.md`.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import time

import diffrax as dfx
import jax
import jax.numpy as jnp
import numpy as np

from jaxdeploy.batch import run_scene
from jaxdeploy.io import atomic_write_json, replace_block, run_metadata
from jaxdeploy.scenes import DeployArray

# The solver this experiment's page was generated with (pinned: deploy_array's default is
# now Tsit5, and a rerun must reproduce what the page says).
SOLVER = "generalized_alpha"

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
WRT = ["panel1_ra", "panel1_clearance", "panel2_ra", "panel2_clearance", "restitution",
       "friction_coefficient"]  # fmt: skip


def peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # Linux: kB


def best_time(fn, x, repeats):
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        jax.block_until_ready(fn(x))
        times.append(time.perf_counter() - start)
    return min(times)


def compiled(fn, x):
    start = time.perf_counter()
    exe = jax.jit(fn).lower(x).compile()
    seconds = time.perf_counter() - start
    mem = exe.memory_analysis()
    temp = getattr(mem, "temp_size_in_bytes", None) if mem is not None else None
    return exe, seconds, temp


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--t-end", type=float, default=2.0)
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--checkpoints", type=int, nargs="*", default=[0, 2000],
                        help="checkpoint counts to compare (0: diffrax default)")  # fmt: skip
    args = parser.parse_args()

    scene = DeployArray()
    base = scene.resolve_params()
    x0 = {k: jnp.asarray(base[k]) for k in WRT}

    def make_loss(adjoint, replay=False):
        def loss(x):
            params = {**base, **x}
            traj = run_scene(
                scene,
                params,
                args.t_end,
                n_save=2001,
                adjoint=adjoint,
                replay_steps=replay,
                solver=SOLVER,
            )
            ch = scene.channels(scene.build(params), traj)
            return jnp.mean(ch["panel2_tip_ay"] ** 2), traj.stats["num_accepted_steps"]

        return loss

    results = {"t_end": args.t_end, "parameters": WRT, "machine": platform.platform(),
               "cpu_count": os.cpu_count(), "versions": run_metadata()}  # fmt: skip
    forward = make_loss(dfx.RecursiveCheckpointAdjoint())
    exe, compile_s, temp = compiled(forward, x0)
    value, steps = exe(x0)
    results["forward"] = {
        "compile_s": compile_s,
        "run_s": best_time(exe, x0, args.repeats),
        "temp_bytes": temp,
        "loss": float(value),
        "accepted_steps": int(steps),
        "peak_rss_mb_after": peak_rss_mb(),
    }
    print(json.dumps(results["forward"]), flush=True)
    state = jax.eval_shape(lambda: run_scene(scene, base, 1e-3, n_save=2))
    n_state = sum(int(np.prod(leaf.shape[1:])) for leaf in jax.tree.leaves((state.q, state.v,
                  state.qdd, state.lam)))  # fmt: skip
    results["state_floats"] = n_state
    results["store_every_step_bytes"] = int(steps) * n_state * 8 * 2  # y and solver state

    results["gradient"] = []
    for k in args.checkpoints:
        adjoint = dfx.RecursiveCheckpointAdjoint(checkpoints=k or None)
        # Adaptive steps replayed (what jaxdeploy.fit does): the adaptive run without
        # derivatives, then the replayed run forward (checkpointed) and backward.
        grad_fn = jax.grad(lambda x, adj=adjoint: make_loss(adj, True)(x)[0])
        exe, compile_s, temp = compiled(grad_fn, x0)
        g = exe(x0)
        run_s = best_time(exe, x0, args.repeats)
        entry = {
            "checkpoints": k or "default (log max_steps)",
            "compile_s": compile_s,
            "run_s": run_s,
            "ratio_to_forward": run_s / results["forward"]["run_s"],
            "temp_bytes": temp,
            "peak_rss_mb_after": peak_rss_mb(),
            "gradient": {n: float(v) for n, v in g.items()},
        }
        results["gradient"].append(entry)
        print(json.dumps(entry), flush=True)

    grads = [np.array([e["gradient"][n] for n in WRT]) for e in results["gradient"]]
    spread = max(
        float(np.max(np.abs(g - grads[0]) / np.maximum(np.abs(grads[0]), 1e-300))) for g in grads
    )
    results["gradient_spread_between_checkpoint_counts"] = spread
    atomic_write_json(os.path.join(ROOT, "docs/figures/gradient_cost.json"), results)
    f = results["forward"]
    lines = [
        f"Measured by `experiments/gradient_cost.py` in one process ({results['cpu_count']} "
        f"CPU cores shared with other users; {results['machine']}). Loss: mean square of "
        f"`panel2_tip_ay` over a {args.t_end:g} s deploy_array run "
        f"({f['accepted_steps']} accepted adaptive steps); gradient w.r.t. {len(WRT)} "
        "parameters (" + ", ".join(f"`{w}`" for w in WRT) + "). Times exclude "
        "compilation; best of "
        f"{args.repeats}.",
        "",
        "| run | checkpoints | time [s] | ratio to forward | compile [s] | XLA temp buffers "
        "[MB] | peak RSS after [MB] |",
        "|---|---|---|---|---|---|---|",
        f"| forward | – | {f['run_s']:.2f} | 1 | {f['compile_s']:.0f} | "
        f"{(f['temp_bytes'] or 0) / 1e6:.2f} | {f['peak_rss_mb_after']:.0f} |",
    ]
    for e in results["gradient"]:
        lines.append(
            f"| gradient (reverse) | {e['checkpoints']} | {e['run_s']:.2f} | "
            f"{e['ratio_to_forward']:.2f} | {e['compile_s']:.0f} | "
            f"{(e['temp_bytes'] or 0) / 1e6:.2f} | {e['peak_rss_mb_after']:.0f} |"
        )
    lines += [
        "",
        f"Storing every step for a plain reverse pass would take about "
        f"{results['store_every_step_bytes'] / 1e6:.1f} MB ({f['accepted_steps']} steps × "
        f"{n_state} floats × 2); the checkpointed pass's buffers are fixed at compile time by "
        "the number of checkpoints (and `max_steps`), not by the steps a run takes. The "
        "gradient includes the undifferentiated adaptive run that chooses the steps "
        "(`replay_steps=True`). Largest relative difference of any gradient component "
        f"between the checkpoint settings: {spread:.1e}.",
    ]
    replace_block(os.path.join(ROOT, "docs/identification.md"), "gradient_cost", "\n".join(lines))


if __name__ == "__main__":
    main()
