"""Work against precision of the explicit Runge–Kutta methods on slider_crank, against the
independent minimal-coordinate reference: where a high-order method (Dopri8) becomes cheaper
than Tsit5 at equal error. Writes the generated block `solver-by-tolerance` of
docs/solver_by_tolerance.md, the measurement behind `jaxdeploy.solvers.AUTO_TIGHT_RTOL`.

For μ = 0 and μ = 0.01 (tanh friction, v_s = 1 mm/s), Tsit5 and Dopri8 (and generalized-α down
to rtol 1e-8) integrate two revolutions at rtol 1e-6 … 1e-12 (atol = 1e-3 rtol); per run: the
accepted steps, the CPU time of the compiled run (`time.process_time`, every thread of the
process; each solver and case is compiled by a first run that is not timed), the right-hand
side evaluations the Runge–Kutta runs make (attempted steps × new stages per step, from
diffrax's tableaux: a count that the machine's load does not change), the largest x_s
error over two revolutions on the reference's 10 µs grid, and the impacts found with their
largest onset error.

Usage: `cd tests && PYTHONPATH=.. python -m independent.solver_crossover [--doc-only]`
(results cached in results/solver_crossover.json).
"""

from __future__ import annotations

import argparse
import json
import os
import time

import numpy as np

from jaxdeploy import pages
from jaxdeploy.io import atomic_write_json, machine_description
from jaxdeploy.solvers.registry import AUTO_TIGHT_RTOL

from . import generate
from .package_runs import TWO_REVOLUTIONS, slider_crank_run

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..")
DOC = os.path.join(ROOT, "docs", "solver_by_tolerance.md")
CACHE = os.path.join(ROOT, "results", "solver_crossover.json")
CASES = {"mu0": 0.0, "mu0.01": 0.01}
RTOLS = (1e-6, 1e-7, 1e-8, 1e-9, 1e-10, 1e-11, 1e-12)
SOLVERS = {
    "tsit5": RTOLS,
    "dopri8": RTOLS,
    # second order: ~50k steps over two revolutions at 1e-8 already
    "generalized_alpha": (1e-6, 1e-7, 1e-8),
}
DT_MAX = 1e-4  # [s], the scene's default bound


def measure(reference):
    rows = []
    for case, mu in CASES.items():
        expected = reference[f"{case}_onsets"]
        for solver, rtols in SOLVERS.items():
            # compile (not timed)
            slider_crank_run(mu, TWO_REVOLUTIONS, solver=solver, rtol=1e-6, atol=1e-9,
                             dt_max=DT_MAX, max_steps=2_000_000)  # fmt: skip
            for rtol in rtols:
                cpu = time.process_time()
                ts, x_s, onsets, run = slider_crank_run(
                    mu, TWO_REVOLUTIONS, solver=solver, rtol=rtol, atol=1e-3 * rtol,
                    dt_max=DT_MAX, max_steps=2_000_000,
                )  # fmt: skip
                cpu = time.process_time() - cpu
                x_err = np.max(
                    np.abs(np.interp(reference["coarse_ts"], ts, x_s) - reference[f"{case}_coarse"])
                )
                row = {
                    "case": case,
                    "solver": solver,
                    "rtol": rtol,
                    "steps": int(run.stats["num_accepted_steps"]),
                    "rejected": int(run.stats["num_rejected_steps"]),
                    "cpu_s": cpu,
                    "x_s_error_m": float(x_err),
                    "impacts": int(onsets.size),
                    "impacts_reference": int(expected.size),
                    "onset_error_s": (
                        float(np.max(np.abs(onsets - expected)))
                        if onsets.size == expected.size
                        else None
                    ),
                    "load": os.getloadavg()[0],
                }
                rows.append(row)
                print(json.dumps(row), flush=True)
    return {
        "rows": rows,
        "machine": machine_description(),
    }


def evaluations_per_step(solver):
    """New right-hand-side evaluations per attempted step of a diffrax Runge–Kutta method:
    its stages, less one when the last stage is the next step's first (FSAL)."""
    import diffrax as dfx

    tableau = {"tsit5": dfx.Tsit5, "dopri8": dfx.Dopri8}[solver].tableau
    return len(tableau.c) + 1 - int(tableau.fsal)


def evaluations(row):
    if row["solver"] not in ("tsit5", "dopri8"):
        return None
    return (row["steps"] + row["rejected"]) * evaluations_per_step(row["solver"])


def cheaper_at_equal_error(rows, case, key):
    """Per Tsit5 run: Dopri8's `key` (steps or CPU) at Tsit5's x_s error, interpolated
    log-log along Dopri8's runs (None outside their range), over Tsit5's."""
    out = {}
    dop = sorted(
        (r for r in rows if r["case"] == case and r["solver"] == "dopri8"),
        key=lambda r: r["x_s_error_m"],
    )
    errs = np.log([r["x_s_error_m"] for r in dop])
    costs = np.log([cost(r, key) for r in dop])
    for r in rows:
        if r["case"] != case or r["solver"] != "tsit5":
            continue
        e = np.log(r["x_s_error_m"])
        if e < errs[0] or e > errs[-1] or not np.all(np.diff(errs) > 0):
            out[r["rtol"]] = None
        else:
            out[r["rtol"]] = float(np.exp(np.interp(e, errs, costs)) / cost(r, key))
    return out


def cost(row, key):
    return evaluations(row) if key == "evaluations" else row[key]


def block(result):
    rows = result["rows"]
    machine = result["machine"]
    loads = [r["load"] for r in rows]
    lines = [
        "Machine: "
        f"{machine.get('Model name', machine['platform'])}, {machine.get('CPU(s)', '?')} CPUs; "
        f"1-min load average {min(loads):.1f}–{max(loads):.1f} during the runs (CPU time is "
        "process time, less sensitive to the load than wall time, not free of it).",
        "",
        "Two revolutions of slider_crank (onset rule, dt_max 0.1 ms, atol = 1e-3 rtol) against "
        "the minimal-coordinate reference (tests/independent; converged to ~2e-9 m in x_s and "
        "~1e-8 s in the onsets, so smaller errors are not resolved).",
    ]
    for case, mu in CASES.items():
        lines += [
            "",
            f"**μ = {mu}** ({rows_of(rows, case)[0]['impacts_reference']} impacts in the "
            "reference)",
            "",
            "| solver | rtol | accepted (rejected) steps | RHS evaluations | CPU [s] "
            "| x_s error [m] | impacts | largest onset error [s] |",
            "|---|---|---|---|---|---|---|---|",
        ]
        for r in rows_of(rows, case):
            onset = "—" if r["onset_error_s"] is None else f"{r['onset_error_s']:.1e}"
            n_eval = evaluations(r)
            lines.append(
                f"| {r['solver']} | {r['rtol']:g} | {r['steps']} ({r['rejected']}) "
                f"| {'—' if n_eval is None else n_eval} | {r['cpu_s']:.2f} "
                f"| {r['x_s_error_m']:.1e} | {r['impacts']}/{r['impacts_reference']} | {onset} |"
            )
        steps = cheaper_at_equal_error(rows, case, "evaluations")
        cpu = cheaper_at_equal_error(rows, case, "cpu_s")
        lines += [
            "",
            "Dopri8's cost at Tsit5's x_s error, over Tsit5's (interpolated log-log between "
            "Dopri8's runs; < 1: Dopri8 is cheaper; — where Tsit5's error is outside Dopri8's "
            "range; RHS evaluations per attempted step: Tsit5 "
            f"{evaluations_per_step('tsit5')}, Dopri8 {evaluations_per_step('dopri8')}; "
            "generalized-α's cost is Newton iterations, not stages, and is not in the ratios):",
            "",
            "| Tsit5 rtol | RHS evaluations ratio | CPU ratio |",
            "|---|---|---|",
        ]
        for rtol in RTOLS:
            s, c = steps.get(rtol), cpu.get(rtol)
            lines.append(
                f"| {rtol:g} | {'—' if s is None else f'{s:.2f}'} "
                f"| {'—' if c is None else f'{c:.2f}'} |"
            )
        fewer = [rtol for rtol in RTOLS if steps.get(rtol) is not None and steps[rtol] < 1.0]
        lines += [
            "",
            f"μ = {mu}: Dopri8 needs fewer evaluations than Tsit5 at equal error from Tsit5's "
            + (f"rtol {max(fewer):g} down." if fewer else "— (nowhere in this range)."),
        ]
    lines += [
        "",
        f'`jaxdeploy.solvers.AUTO_TIGHT_RTOL` = {AUTO_TIGHT_RTOL:g}: `solver="auto"` runs '
        "Tsit5 at rtol ≥ it and Dopri8 below.",
    ]
    return "\n".join(lines)


def rows_of(rows, case):
    return [r for r in rows if r["case"] == case]


# What moves the numbers: slider_crank's runs under each method and tolerance, the reference.
MEASURES = [
    "jaxdeploy/contact",
    "jaxdeploy/mechanism",
    "jaxdeploy/scenes/_contact.py",
    "jaxdeploy/scenes/base.py",
    "jaxdeploy/scenes/slider_crank.py",
    "jaxdeploy/simulation.py",
    "jaxdeploy/solvers",
    "tests/data/slider_crank_reference.npz",
    "tests/independent/crossings.py",
    "tests/independent/package_runs.py",
    "tests/independent/solver_crossover.py",
]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--doc-only", action="store_true", help="rewrite the block from the cache")
    args = ap.parse_args(argv)
    if args.doc_only:
        with open(CACHE) as fh:
            result = json.load(fh)
        pages.stored(result, CACHE)  # refuses a result without provenance
    else:
        record = pages.start(MEASURES, "cd tests && python -m independent.solver_crossover")
        with np.load(generate.PATH) as data:
            reference = {k: np.array(data[k]) for k in data.files}
        result = measure(reference)
        result["provenance"] = pages.finish(record)
        os.makedirs(os.path.dirname(CACHE), exist_ok=True)
        atomic_write_json(CACHE, result)
    text = block(result)
    pages.write_block(DOC, "solver-by-tolerance", text, result["provenance"])
    print(text)


if __name__ == "__main__":
    main()
