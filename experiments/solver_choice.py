"""Which solver deploy_array should default to: adaptive generalized-α (modified and full
Newton) against Tsit5 on the index-1 equations, over the default run (2 s, the scene's step
control), side by side in one process. Writes docs/solver_choice.md.

    PYTHONPATH=. python experiments/solver_choice.py [--repeats 2]

Per solver:

* the plain run (what `jaxdeploy simulate` does): wall time of compiled calls (median over
  `--repeats`, the solvers interleaved so that they share the machine's load), accepted and
  rejected steps, and the run's summary (lock time, deviations, contact force) — the physics
  a user reads, which must not depend on the solver beyond the tolerance;
* the same run metered (`jaxdeploy.mechanism.metered`: identical dynamics, energy meters in
  the memory): the energy residual max|T + V + D − E0 − J| / E_moved, which no integration
  error escapes, and the dissipated energy against the same solver at rtol/10.

The trajectory error against a high-accuracy reference over the first 0.1 s is in
docs/performance.md (block `generalized-alpha-error`, same scene and tolerances); after the
lock the rattle is chaotic and no pointwise error is meaningful, which is why the energy
balance is the check here.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import time

import numpy as np

from jaxdeploy.analysis.deploy_array import deploy_array_summary
from jaxdeploy.benchmarks.report import machine_description
from jaxdeploy.io import atomic_write_bytes, atomic_write_json, run_metadata
from jaxdeploy.mechanism import energy_balance, energy_moved, metered
from jaxdeploy.scenes import DeployArray
from jaxdeploy.simulation import simulate
from jaxdeploy.solvers import GeneralizedAlpha

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DOC = os.path.join(ROOT, "docs", "solver_choice.md")
RESULT = os.path.join(ROOT, "results", "solver_choice.json")
N_SAVE = 4001
SOLVERS = {
    "generalized-α, modified Newton": GeneralizedAlpha(),
    "generalized-α, full Newton": GeneralizedAlpha(newton="full"),
    "Tsit5": "tsit5",
}
SUMMARY_KEYS = (
    ("lock_time", "lock time [s]", "{:.5f}"),
    ("max_angle_deviation_deploy", "max abs(α − α_ideal) before lock [rad]", "{:.3e}"),
    ("panel2_tip_max_dy", "panel 2 tip max abs(Δy) [m]", "{:.3e}"),
    ("max_contact_force", "max contact force [N]", "{:.1f}"),
)


def _control(scene, solver, tighter=1.0):
    control = {k: v for k, v in scene.default_control.settings().items() if k != "solver"}
    control["rtol"] /= tighter
    control["atol"] /= tighter
    return {**control, "solver": solver}


def _timed(fn):
    start = time.perf_counter()
    out = fn()
    out.q.block_until_ready()
    return time.perf_counter() - start, out


def _energy(scene, params, t_end, control):
    mech = metered(scene.build(params))  # its memory holds the meters: its own initial state
    traj = simulate(mech, scene.initial_state(params, mech), t_end, n_save=N_SAVE, **control)
    balance = energy_balance(mech, traj.q, traj.v, traj.memory)
    moved = energy_moved(balance)
    return {
        "status": traj.status(),
        "steps": int(traj.stats["num_accepted_steps"]),
        "residual_rel": float(np.max(np.abs(np.asarray(balance["residual"])))) / moved,
        "dissipated_J": float(balance["dissipated"][-1]),
        "moved_J": moved,
    }


# Both hinges' clearance [µm] for the scan of where the explicit method stops winning: a
# journal pressed into a small gap is a stiff contact, which limits an explicit method's
# step by stability, not accuracy.
SCAN_CLEARANCES_UM = (1.0, 2.0, 3.0, 5.0, 10.0, 50.0)
SCAN_T_END = 0.7  # unfolding, lock (≈ 0.54 s) and the first post-lock rattle
SCAN_SOLVERS = ("generalized-α, modified Newton", "Tsit5")


def clearance_scan() -> list[dict]:
    """Per clearance: accepted steps, status and the compiled run's wall time per solver, over
    SCAN_T_END (one compilation per solver; the parameters are data)."""
    import jax

    from jaxdeploy.batch import run_scene

    scene = DeployArray()
    runs = {
        label: jax.jit(
            lambda p, solver=SOLVERS[label]: run_scene(
                scene, p, SCAN_T_END, n_save=3, control=_control(scene, solver)
            )
        )
        for label in SCAN_SOLVERS
    }
    rows = []
    for c_um in SCAN_CLEARANCES_UM:
        c = c_um * 1e-6
        params = scene.resolve_params({"panel1_clearance": c, "panel2_clearance": c})
        row = {"clearance_um": c_um}
        for label, run in runs.items():
            run(params).q.block_until_ready()  # compiles once per solver
            wall, traj = _timed(lambda run=run, params=params: run(params))
            row[label] = {
                "status": traj.status(),
                "steps": int(traj.stats["num_accepted_steps"]),
                "wall_s": wall,
            }
        print(row, flush=True)
        rows.append(row)
    return rows


def _scan_section(result) -> str:
    rows = result.get("clearance_scan")
    if not rows:
        return ""
    labels = list(SCAN_SOLVERS)
    head = (
        "| clearance c [µm] | "
        + " | ".join(f"{label}: steps, run [s]" for label in labels)
        + " | Tsit5 speed-up |\n|---|"
        + "---|" * (len(labels) + 1)
    )
    lines = []
    for r in rows:
        cells = [f"{r[label]['steps']}, {r[label]['wall_s']:.2f}" for label in labels]
        ok = all(r[label]["status"] == "ok" for label in labels)
        speed = r[labels[0]]["wall_s"] / r["Tsit5"]["wall_s"]
        lines.append(
            f"| {r['clearance_um']:g} | "
            + " | ".join(cells)
            + f" | {speed:.2f}{'' if ok else ' (a run failed)'} |"
        )
    slower = [r["clearance_um"] for r in rows if r["Tsit5"]["wall_s"] > r[labels[0]]["wall_s"]]
    faster = [r["clearance_um"] for r in rows if r["clearance_um"] not in slower]
    if not slower:
        verdict = "Tsit5 is the faster at every clearance scanned"
    elif not faster or min(faster) < max(slower):
        verdict = f"Tsit5 is the slower at c = {', '.join(f'{c:g}' for c in slower)} µm"
    else:
        verdict = (
            f"Tsit5 is the slower at c ≤ {max(slower):g} µm and the faster from "
            f"{min(faster):g} µm on"
        )
    return f"""
## Where the explicit method stops winning: small clearances

Both hinges' clearance changed together, {SCAN_T_END:g} s (unfolding, lock, the first rattle),
each solver compiled once and timed on a second call. A journal pressed into a small gap is a
stiff contact; an explicit method's step is then limited by stability, not accuracy, while
generalized-α (implicit, A-stable) keeps steps set by accuracy.

{head}
{chr(10).join(lines)}

{verdict}. The design space of `jaxdeploy optimize` (c 5–150 µm) is above it; for smaller
clearances choose `--solver generalized_alpha`.
"""


def measure(repeats):
    scene = DeployArray()
    params = scene.resolve_params()
    mech = scene.build(params)
    init = scene.initial_state(params, mech)
    t_end = scene.default_t_end

    def runner(control):
        return lambda: simulate(mech, init, t_end, n_save=N_SAVE, **control)

    runs = {label: runner(_control(scene, solver)) for label, solver in SOLVERS.items()}
    out = {label: {"wall_s": []} for label in SOLVERS}
    last = {}
    for label, run in runs.items():  # compile (and a first run)
        out[label]["first_call_s"], last[label] = _timed(run)
        print(f"{label}: first call {out[label]['first_call_s']:.1f} s", flush=True)
    for _ in range(repeats):  # interleaved: every solver sees the same load
        for label, run in runs.items():
            wall, last[label] = _timed(run)
            out[label]["wall_s"].append(wall)
            print(f"{label}: {wall:.2f} s", flush=True)
    for label, solver in SOLVERS.items():
        traj = last[label]  # the runs are deterministic: the last one stands for all
        rec = out[label]
        rec["status"] = traj.status()
        rec["steps"] = int(traj.stats["num_accepted_steps"])
        rec["rejected"] = int(traj.stats["num_rejected_steps"])
        rec["wall_median_s"] = statistics.median(rec["wall_s"])
        rec["summary"] = {
            k: float(v)
            for k, v in deploy_array_summary(scene, params, mech, traj).items()
            if not isinstance(v, str)
        }
        rec["energy"] = _energy(scene, params, t_end, _control(scene, solver))
        rec["energy_tight"] = _energy(scene, params, t_end, _control(scene, solver, tighter=10.0))
        rec["dissipated_vs_tight_rel"] = (
            abs(rec["energy"]["dissipated_J"] - rec["energy_tight"]["dissipated_J"])
            / rec["energy"]["moved_J"]
        )
        print(label, {k: rec[k] for k in ("steps", "wall_median_s")}, flush=True)
    return {
        "solvers": out,
        "t_end": t_end,
        "control": {k: v for k, v in scene.default_control.settings().items() if k != "solver"},
        "default_solver": scene.default_control.solver_name(),
        "repeats": repeats,
        "machine": machine_description(),
        "cores": len(os.sched_getaffinity(0)),
        "versions": run_metadata(),
    }


def write_doc(result):
    rows = result["solvers"]
    base = "generalized-α, modified Newton"
    header = "| | " + " | ".join(rows) + " |\n|---|" + "---|" * len(rows)

    def line(name, values):
        return f"| {name} | " + " | ".join(values) + " |"

    columns = [  # (row name, value of one solver's record as text)
        ("status", lambda r: r["status"]),
        ("run, compiled [s] (median)", lambda r: f"{r['wall_median_s']:.2f}"),
        (
            "speed-up over modified Newton",
            lambda r: f"{rows[base]['wall_median_s'] / r['wall_median_s']:.2f}",
        ),
        ("accepted (rejected) steps", lambda r: f"{r['steps']} ({r['rejected']})"),
        ("first call, compile + run [s]", lambda r: f"{r['first_call_s']:.1f}"),
        *(
            (name, lambda r, key=key, fmt=fmt: fmt.format(r["summary"][key]))
            for key, name, fmt in SUMMARY_KEYS
        ),
        ("energy residual / energy moved", lambda r: f"{r['energy']['residual_rel']:.1e}"),
        ("same at rtol/10", lambda r: f"{r['energy_tight']['residual_rel']:.1e}"),
        ("dissipated energy [J]", lambda r: f"{r['energy']['dissipated_J']:.5f}"),
        (
            "its change at rtol/10 / energy moved",
            lambda r: f"{r['dissipated_vs_tight_rel']:.1e}",
        ),
    ]
    lines = [line(name, [value(r) for r in rows.values()]) for name, value in columns]
    tsit5, gen = rows["Tsit5"], rows[base]
    speed = gen["wall_median_s"] / tsit5["wall_median_s"]
    machine = result["machine"]
    load = machine.get("load_average_1_5_15min", ("?",))[0]
    where = f"{machine.get('Model name', machine['platform'])}, {machine.get('CPU(s)', '?')} CPUs"

    def meter_ratio(r):
        """Residual ratio rtol → rtol/10, measured and as predicted by a second-order
        quadrature error (∝ h², h ∝ 1/steps)."""
        e, t = r["energy"], r["energy_tight"]
        return e["residual_rel"] / t["residual_rel"], (t["steps"] / e["steps"]) ** 2

    (gen_ratio, gen_pred), (ts_ratio, ts_pred) = meter_ratio(gen), meter_ratio(tsit5)
    pending = (
        ""
        if result["default_solver"] == "tsit5"
        else " By these measurements Tsit5 should become deploy_array's default; that switch"
        " waits for the robustness matrix (docs/robustness.md, which checks the default solver)"
        " to be rerun with it."
    )
    control = ", ".join(f"{k} = {v:g}" for k, v in result["control"].items())
    text = f"""# deploy_array: which solver by default (generated)

*Written by `PYTHONPATH=. python experiments/solver_choice.py --repeats {result["repeats"]}`;
rerun it to regenerate. {where}, load {load:.1f}, the process allowed on
{result.get("cores", "?")} core(s) (e.g. `taskset -c 0`); a shared machine, so only the ratios
of timings taken side by side (interleaved, one process) are meaningful.*

The default run (deploy_array, {result["t_end"]:g} s, {control}, {N_SAVE} saved states) with
each solver. The physics rows come from the run's summary (`jaxdeploy simulate`'s numbers);
the energy rows from the same run metered (identical dynamics): the residual
max|T + V + D − E0 − J| is what the integration error does to the energy balance, and the
dissipated energy is a sturdy "same answer" where the post-lock rattle is chaotic.

{header}
{chr(10).join(lines)}

The physics a user reads (lock time, deviations, contact force) agrees between the solvers to
the digits shown. The trajectory error over the first 0.1 s against a Dopri8 reference at rtol
1e-12, same tolerances, is in [performance.md](performance.md) (block
`generalized-alpha-error`): at rtol 1e-6 Tsit5 is there more than an order of magnitude closer
than generalized-α. Over the whole run Tsit5 is **{speed:.2f}×** faster than generalized-α with
modified Newton, with {gen["steps"] / tsit5["steps"]:.1f}× fewer steps.

**The energy residual here is mostly the meter's.** `EnergyMeter` integrates the
non-conservative work by the trapezoid rule in q over each step, a second-order quadrature, so
its error scales with h² whatever the solver's order. From rtol to rtol/10 the residual falls
by {ts_ratio:.2f}× for Tsit5 and {gen_ratio:.2f}× for generalized-α; a quadrature error ∝ h²
predicts ({ts_pred:.2f}×, {gen_pred:.2f}×) from the step counts (the square of their ratio),
where an error proportional to the tolerance would fall 10×. Tsit5's residual is larger because its
steps are {gen["steps"] / tsit5["steps"]:.1f}× longer, and it still balances
{1 - tsit5["energy"]["residual_rel"]:.2%} of the energy moved.

**Why an explicit method wins on this scene.** Generalized-α is second order and was chosen for
stiffness, but the contact stiffness never limits an explicit step here: the steps are limited
by accuracy through the impacts anyway, and between impacts the mechanism is smooth and slow,
where a fifth-order method takes long steps. Per step Tsit5 costs seven evaluations of the
index-1 accelerations (six stages, and one at the projected step end that is also the next
step's first stage) and a projection, generalized-α a Newton solve (a factorisation whenever
the iteration matrix is refreshed); Tsit5 takes far fewer steps, and that decides.

The scene's default solver is `{result["default_solver"]}` (`DeployArray.default_control`).{pending}
Any run can choose: `jaxdeploy simulate|optimize|sweep --solver NAME`, `simulate(...,
solver=NAME)`, or `control={{"solver": NAME}}` in the batch, sweep and design functions.
{_scan_section(result)}"""
    atomic_write_bytes(DOC, text.encode())
    print(f"wrote {DOC}")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument(
        "--doc-only", action="store_true", help=f"rewrite the page from {RESULT} (no runs)"
    )
    ap.add_argument(
        "--scan-only",
        action="store_true",
        help=f"run only the clearance scan, added to {RESULT}",
    )
    args = ap.parse_args(argv)
    if args.doc_only or args.scan_only:
        with open(RESULT) as fh:
            result = json.load(fh)
    else:
        result = measure(args.repeats)
    if not args.doc_only:
        result["clearance_scan"] = clearance_scan()
        os.makedirs(os.path.dirname(RESULT), exist_ok=True)
        atomic_write_json(RESULT, result)
    write_doc(result)


if __name__ == "__main__":
    main()
