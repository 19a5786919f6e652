"""How well adaptive generalized-α's error estimate controls the error: error against the
tolerance, next to the explicit diffrax path, on both benchmark scenes; writes the generated
block `generalized-alpha-error` of docs/generalized_alpha_error.md (its own page: `make bench`
rewrites docs/performance.md whole).

* slider_crank over the benchmark's reference window (1.5 ms, six impacts), against the
  event-exact numpy model under scipy DOP853 at rtol 1e-13 (`peers.py`);
* deploy_array over its first 0.1 s (the hinge journals cross their clearances and settle
  into contact), against Dopri8 at rtol 1e-12; Tsit5 at rtol 1e-12 is the check, and their
  difference bounds what this reference can tell apart.

The error is the benchmark's, `max |e − e_ref| / c` over both clearance joints; atol is
1e-3 rtol, as in the benchmark. Wall times are of a second, compiled run (the tolerance is
data of the compiled program).

Usage: `python experiments/generalized_alpha_error_control.py`.
"""

from __future__ import annotations

import os
import time

import numpy as np

from benchmarks.peers import SliderCrankNumpy
from benchmarks.reference import WINDOW, eccentricity_error
from jaxdeploy import pages
from jaxdeploy.io import machine_description
from jaxdeploy.scenes import DeployArray, SliderCrank
from jaxdeploy.simulation import simulate

DOC = os.path.join(os.path.dirname(__file__), "..", "docs", "generalized_alpha_error.md")
DEPLOY_WINDOW = 0.1
CONFIGS = {  # scene → (solver, rtol) rows
    "slider_crank": [("generalized_alpha", tol) for tol in (1e-5, 1e-6, 1e-7, 1e-8)]
    + [("tsit5", 1e-8), ("dopri8", 1e-10)],
    "deploy_array": [("generalized_alpha", tol) for tol in (1e-4, 1e-5, 1e-6, 1e-7)]
    + [("tsit5", 1e-6), ("tsit5", 1e-8), ("dopri8", 1e-9)],
}


def _setup(scene):
    p = scene.resolve_params()
    mech = scene.build(p)
    return p, mech, scene.initial_state(p, mech)


def _run(mech, s0, t_end, ts, solver, rtol):
    def once():
        tr = simulate(mech, s0, t_end, ts=ts, solver=solver, rtol=rtol, atol=rtol * 1e-3)
        tr.q.block_until_ready()
        return tr

    once()
    start = time.perf_counter()
    tr = once()
    return tr, time.perf_counter() - start


def _rows(mech, s0, t_end, ts, q_ref, configs):
    rows = []
    for solver, rtol in configs:
        tr, wall = _run(mech, s0, t_end, ts, solver, rtol)
        error, _ = eccentricity_error(mech, np.asarray(tr.q), q_ref, ts, t_end)
        steps = int(tr.stats["num_accepted_steps"])
        rows.append((solver, rtol, error, steps, wall, tr.status()))
        print(rows[-1], flush=True)
    return rows


# What moves the numbers: the solvers, the simulation loop, the two scenes and what they build.
MEASURES = [
    "experiments/generalized_alpha_error_control.py",
    "jaxdeploy/contact",
    "jaxdeploy/mechanism",
    "jaxdeploy/scenes",
    "jaxdeploy/simulation.py",
    "jaxdeploy/solvers",
    "benchmarks/peers.py",
    "benchmarks/reference.py",
]


def main():
    record = pages.start(MEASURES, "python experiments/generalized_alpha_error_control.py")
    blocks = []
    # slider_crank against the event-exact numpy model.
    t_end = WINDOW["slider_crank"]
    ts = np.linspace(0.0, t_end, 76)
    p, mech, s0 = _setup(SliderCrank())
    n = np.asarray(s0.q).shape[0]
    peer = SliderCrankNumpy(p).solve(s0, t_end, ts, "DOP853", 1e-13, 1e-15)
    if not peer.ok:
        raise RuntimeError(peer.message)
    rows = _rows(mech, s0, t_end, ts, peer.ys[:, :n], CONFIGS["slider_crank"])
    blocks.append(
        (
            f"slider_crank, t ≤ {t_end * 1e3:g} ms, against the event-exact numpy model "
            "(DOP853, rtol 1e-13)",
            rows,
        )
    )
    # deploy_array against Dopri8 at 1e-12, checked by Tsit5 at 1e-12.
    ts = np.linspace(0.0, DEPLOY_WINDOW, 401)
    _, mech, s0 = _setup(DeployArray())
    ref, _ = _run(mech, s0, DEPLOY_WINDOW, ts, "dopri8", 1e-12)
    check, _ = _run(mech, s0, DEPLOY_WINDOW, ts, "tsit5", 1e-12)
    q_ref = np.asarray(ref.q)
    bound, _ = eccentricity_error(mech, np.asarray(check.q), q_ref, ts, DEPLOY_WINDOW)
    rows = _rows(mech, s0, DEPLOY_WINDOW, ts, q_ref, CONFIGS["deploy_array"])
    blocks.append(
        (
            f"deploy_array, t ≤ {DEPLOY_WINDOW:g} s, against Dopri8 at rtol 1e-12 (Tsit5 at "
            f"1e-12 differs from it by {bound:.1e}: errors below that are not resolved)",
            rows,
        )
    )
    load = machine_description()["load_average_1_5_15min"][0]
    lines = [
        f"Error `max |e − e_ref| / c`, atol = 1e-3 rtol, wall of a compiled run; load {load:.1f}.",
    ]
    for title, rows in blocks:
        lines += [
            "",
            f"{title}:",
            "",
            "| solver | rtol | error | accepted steps | wall [s] |",
            "|---|---|---|---|---|",
        ]
        for solver, rtol, error, steps, wall, status in rows:
            name = "generalized-α adaptive" if solver == "generalized_alpha" else solver
            note = "" if status == "ok" else f" ({status})"
            lines.append(f"| {name} | {rtol:g} | {error:.2e}{note} | {steps} | {wall:.2f} |")
    pages.write_block(DOC, "generalized-alpha-error", "\n".join(lines), record)
    print("wrote the generalized-alpha-error block of", DOC)


if __name__ == "__main__":
    main()
