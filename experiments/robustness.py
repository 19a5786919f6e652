"""Extreme-case matrix (issue 8): `jaxdeploy.robustness.check_run` over two families, varied
one parameter at a time around a base case; writes the generated blocks of docs/robustness.md
(the prose around them is hand-written).

* **impact**: a 1 kg journal (R_j = 5 mm) starting centred in a fixed bearing, rough law or
  Hertz (σ = 0), Flores damping, 2 ms; base c = 10 µm, σ = 1 µm, steel, c_e = 0.9, v0 = 1 m/s.
* **deploy**: the `deploy_array` scene over 0.7 s (both clearance joints changed together),
  and the base case over 20 s (**long**).

Results go to `results/robustness/<family>.json`, one record per case as it finishes; a
family stops starting new cases once it has used `--budget-min` minutes of CPU time, or when
it is stopped (kill it, then `docs`): the page lists the cases not run. `docs` rewrites the
page from the results.

    PYTHONPATH=. nice -n 10 python experiments/robustness.py impact|deploy|long|docs|all
"""

from __future__ import annotations

import argparse
import json
import os
import time

import jax.numpy as jnp
import numpy as np

from jaxdeploy import DeployArray, Impact, StepControl, contact, pages
from jaxdeploy.io import atomic_write_json, machine_description, run_metadata
from jaxdeploy.robustness import check_run

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
RESULTS = os.path.join(ROOT, "results", "robustness")
DOC = os.path.join(ROOT, "docs", "robustness.md")
ENERGY_TOL = 2e-3  # stated acceptance: |residual| ≤ 0.2 % of the energy that moved
AGREE_TOL = 1e-2  # outputs at rtol and rtol/10 agree to 1 % of their scale
SOLVERS_TOL = 1e-2  # the other formulation: outputs, or (chaotic rattle) dissipation, to 1 %

IMPACT_CASES = {
    "base": {},
    "c = 1 µm": {"clearance": 1e-6},
    "c = 0.1 µm": {"clearance": 1e-7},
    "c = 0.01 µm": {"clearance": 1e-8},
    "σ = 0 (Hertz)": {"sigma": 0.0},
    "σ = 10 µm": {"sigma": 1e-5},
    "σ = 10 µm, c = 1 µm": {"sigma": 1e-5, "clearance": 1e-6},
    "E = 1 GPa": {"modulus": 1e9},
    "E = 400 GPa": {"modulus": 400e9},
    "c_e = 0.05": {"restitution": 0.05},
    "c_e = 1": {"restitution": 1.0},
    "v0 = 10 m/s": {"speed": 10.0},
    "v0 = 10 m/s, E = 1 GPa, c_e = 0.05": {"speed": 10.0, "modulus": 1e9, "restitution": 0.05},
    "v0 = 10 m/s, E = 400 GPa, c = 1 µm": {"speed": 10.0, "modulus": 400e9, "clearance": 1e-6},
    "v0 = 1 cm/s": {"speed": 0.01},
}
IMPACT_CONTROL = StepControl(rtol=1e-8, atol=1e-13, dt_max=1e-5)  # generalized-α
SIGMA_FROM_RA = 1.2533141373155  # σ = sqrt(π/2) Ra for a Gaussian surface
# Cheapest first, so that a family stopped by its budget has done the most cases: the ones
# that compile a new structure (σ = 0, μ = 0) and c = 1 µm (the most steps) last.
DEPLOY_CASES = {
    "base (c 50 µm, Ra 1.6 µm, μ 0.05)": {},
    "σ = 10 µm": {"panel1_ra": 1e-5 / SIGMA_FROM_RA, "panel2_ra": 1e-5 / SIGMA_FROM_RA},
    "E = 1 GPa": {"youngs_modulus": 1e9},
    "E = 400 GPa": {"youngs_modulus": 400e9},
    "c_e = 0.05": {"restitution": 0.05},
    "c_e = 1": {"restitution": 1.0},
    "μ = 0.8": {"friction_coefficient": 0.8},
    "spring preload ×10": {"spring_stiffness": 10.0},  # × the default (τ = k(α0 − α))
    "σ = 0 (Hertz)": {"panel1_ra": 0.0, "panel2_ra": 0.0},
    "μ = 0": {"friction_coefficient": 0.0},
    "c = 1 µm": {"panel1_clearance": 1e-6, "panel2_clearance": 1e-6},
}
FAMILIES = {  # t_end [s], saved states, derivative
    "impact": (2e-3, 201, True),
    "deploy": (0.7, 201, True),
    "long": (20.0, 2001, False),
}


def impact_case(case):
    p = {**dict(clearance=1e-5, sigma=1e-6, modulus=207e9, restitution=0.9, speed=1.0), **case}
    stiffness = contact.journal_bearing_stiffness(5e-3, p["clearance"], p["modulus"], 0.3,
                                                  p["modulus"], 0.3)  # fmt: skip
    scene = Impact(damping="flores")
    params = scene.resolve_params(
        dict(clearance=p["clearance"], sigma=p["sigma"], stiffness=float(stiffness),
             restitution=p["restitution"], impact_speed=p["speed"])
    )  # fmt: skip
    return scene, params, IMPACT_CONTROL


def deploy_case(case):
    scene = DeployArray()
    case = dict(case)
    if "spring_stiffness" in case:
        case["spring_stiffness"] *= scene.default_params()["spring_stiffness"]
    return scene, scene.resolve_params(case), scene.default_control


def impact_outputs(traj):
    """Final journal position and velocity along x."""
    return jnp.stack([traj.q[-1, 0], traj.v[-1, 0]])


def impact_scale(traj):
    """max |x| and max |v_x| over the run (a captured journal ends at rest: no scale)."""
    return jnp.stack([jnp.max(jnp.abs(traj.q[:, 0])), jnp.max(jnp.abs(traj.v[:, 0]))])


def deploy_outputs(traj):
    """Deployment angle at the saved times (panel 1 is the first body)."""
    return 0.5 * jnp.pi - traj.q[:, 2]


def deploy_scale(traj):
    return jnp.max(jnp.abs(deploy_outputs(traj)))


def _load(family):
    path = os.path.join(RESULTS, f"{family}.json")
    return json.load(open(path)) if os.path.exists(path) else {}


# What moves the numbers: the robustness checks, the two scenes' simulations.
MEASURES = [
    "experiments/robustness.py",
    "jaxdeploy/contact",
    "jaxdeploy/mechanism",
    "jaxdeploy/robustness.py",
    "jaxdeploy/scenes/_contact.py",
    "jaxdeploy/scenes/base.py",
    "jaxdeploy/scenes/data",
    "jaxdeploy/scenes/deploy_array.py",
    "jaxdeploy/scenes/impact.py",
    "jaxdeploy/simulation.py",
    "jaxdeploy/solvers",
]


def run_family(family, budget_min):
    t_end, n_save, derivative = FAMILIES[family]
    cases = (
        {"base, 20 s": {}}
        if family == "long"
        else IMPACT_CASES
        if family == "impact"
        else DEPLOY_CASES
    )
    make, outputs, scale = ((impact_case, impact_outputs, impact_scale) if family == "impact"
                            else (deploy_case, deploy_outputs, deploy_scale))  # fmt: skip
    records = _load(family)
    records.setdefault("_meta", {"versions": run_metadata(), "machine": machine_description()})
    record = pages.start(MEASURES, f"python experiments/robustness.py {family}")
    earlier = records["_meta"].get("provenance")
    if any(name in records for name in cases):  # cases kept from earlier runs
        # (results stored before the script recorded provenance: an unknown commit)
        kept = {earlier["commit"], *earlier.get("runs_at", [])} if earlier else {"unknown"}
        record["runs_at"] = sorted(kept - {record["commit"]})
    start = time.process_time()
    for name, case in cases.items():
        if name in records:
            continue
        if time.process_time() - start > 60 * budget_min:
            print(f"[{family}] CPU budget of {budget_min} min used: {name} not run", flush=True)
            break
        print(f"[{family}] {name} ...", flush=True)
        scene, params, control = make(case)
        try:
            rec = check_run(scene, params, t_end, control, outputs, scale, n_save=n_save,
                            derivative=derivative)  # fmt: skip
        except Exception as err:  # reported in the table, never hidden
            rec = {"status": f"exception: {type(err).__name__}: {err}", "finite": False}
        records[name] = rec
        records["_meta"]["cpu_min"] = (time.process_time() - start) / 60
        records["_meta"]["provenance"] = pages.finish(record)
        atomic_write_json(os.path.join(RESULTS, f"{family}.json"), records)
        print(json.dumps(rec, default=str)[:300], flush=True)


# --- the page ----------------------------------------------------------------------------------


def _f(x, spec=".1e"):
    return (
        "—" if x is None else ("yes" if x else "**NO**") if isinstance(x, bool) else format(x, spec)
    )


def _derivative(r):
    if "gradient_finite" not in r:
        return "—"
    if r["gradient_finite"]:
        return f"yes ({r['gradient_max_abs']:.0e})"
    if "gradient_nonfinite_from_s" not in r:
        return "**NO**"
    before = r["gradient_max_abs_before"]
    return f"**NO** from {r['gradient_nonfinite_from_s']:.3f} s ({before:.0e} before)"


def _other(r):
    d = r.get("other_solver", {})
    if "difference_rel" not in d:
        return d.get("status", "—")
    text = f"{d['solver']}: {d['status']}, Δ {d['difference_rel']:.1e}"
    if "dissipated_difference_rel" in d:
        text += f", ΔD {d['dissipated_difference_rel']:.1e}"
    window = f"{1e3 * d['t_end']:g} ms, " if d["t_end"] < r["t_end"] else ""
    return text + f" ({window}{d['steps']} steps, {d['wall_s']:.0f} s)"


def _solvers_agree(d):
    close = min(d.get("difference_rel", np.inf), d.get("dissipated_difference_rel", np.inf))
    return d.get("status") == "ok" and close <= SOLVERS_TOL


def _table(records, names):
    rows = ["| case | status | finite | steps (rejected) | min / max step [s] | energy residual / "
            "moved (tighter) | Δ outputs vs tighter | ΔD vs tighter | d/ds finite | other "
            "solver | wall [s] |", "|---|---|---|---|---|---|---|---|---|---|---|"]  # fmt: skip
    for name in names:
        r = records.get(name, {"status": "not run (time)"})
        energy = _f(r.get("energy_residual_rel"))
        if "ref_energy_residual_rel" in r:
            energy += f" ({r['ref_energy_residual_rel']:.1e})"
        rows.append(
            f"| {name} | {r.get('status')} | {_f(r.get('finite'))} | {_f(r.get('steps'), '.0f')} "
            f"({_f(r.get('rejected'), '.0f')}) | {_f(r.get('min_step'))} / {_f(r.get('max_step'))} "
            f"| {energy} | {_f(r.get('ref_difference_rel'))} | "
            f"{_f(r.get('ref_dissipated_difference_rel'))} | {_derivative(r)} | {_other(r)} | "
            f"{_f(r.get('wall_s'), '.0f')} |"
        )
    return "\n".join(rows)


def _verdict(records, names):
    cases = {k: r for k, r in records.items() if k in names}
    missing = [n for n in names if n not in cases]

    def where(test):
        return "; ".join(k for k, r in cases.items() if test(r))

    failed = where(lambda r: r.get("status") != "ok")
    energy = where(lambda r: r.get("energy_residual_rel", 1.0) > ENERGY_TOL)
    ref = where(lambda r: r.get("ref_difference_rel", 0.0) > AGREE_TOL)
    ref_d = where(lambda r: r.get("ref_dissipated_difference_rel", 0.0) > AGREE_TOL)
    solvers = where(lambda r: not _solvers_agree(r.get("other_solver", {})))
    grad = where(lambda r: r.get("gradient_finite") is False)
    worst = max((r.get("energy_residual_rel", 0.0) for r in cases.values()), default=np.nan)
    computed = any("gradient_finite" in r for r in cases.values())
    smallest = min((r.get("min_step", np.inf) for r in cases.values()), default=np.inf)
    lines = [
        f"{len(cases)} of {len(names)} cases run"
        + (f" (not run in the time available: {'; '.join(missing)})" if missing else ""),
        "completed: " + (f"all but {failed}" if failed else "all"),
        f"largest energy residual {worst:.1e} of the energy moved (tolerance {ENERGY_TOL:g})"
        + (f"; above it: {energy}" if energy else ""),
        f"outputs vs the 10× tighter run within {AGREE_TOL:g}: "
        + (f"not in {ref}" if ref else "every case"),
        f"dissipated energy vs that run within {AGREE_TOL:g} of the energy moved: "
        + (f"not in {ref_d}" if ref_d else "every case"),
        f"other solver, outputs or dissipated energy within {SOLVERS_TOL:g}: "
        + (f"not in {solvers}" if solvers else "every case"),
        "directional derivatives: "
        + (f"NaN/inf in {grad}" if grad else "finite in every case run" if computed else "—"),
        f"smallest accepted step {smallest:.1e} s",
    ]
    return "\n".join(f"* {line}" for line in lines)


def _stamp(records, family):
    meta = records.get("_meta", {})
    load = meta.get("machine", {}).get("load_average_1_5_15min", [np.nan] * 3)
    cpu = meta.get("machine", {}).get("Model name", "?")
    return (
        f"*{meta.get('cpu_min', np.nan):.0f} min of CPU on "
        f"{cpu} ({os.cpu_count()} cores shared, load average {load[0]:.0f} at the start: wall "
        "times are noisy).*"
    )


def write_docs(record):
    """The three blocks, each with the provenance of the run that made its table (`record`,
    this call's, for a family without results)."""
    deploy_control = DeployArray.default_control.settings()
    for family, names, what in (
        ("impact", list(IMPACT_CASES), f"Step control: {IMPACT_CONTROL.settings()}."),
        ("deploy", list(DEPLOY_CASES), f"Step control: the scene's, {deploy_control}."),
        ("long", ["base, 20 s"], "No derivative over 20 s."),
    ):
        records = _load(family)
        # Results stored before the script recorded provenance were made at an unknown commit.
        made = records.get("_meta", {}).get("provenance", {**record, "runs_at": ["unknown"]})
        if not any(name in records for name in names):
            made = record
            text = (
                f"*No results: `python experiments/robustness.py {family}` has not been run "
                "since the model's defaults changed (onset impact rule, deploy_array's "
                "preloaded latch); the earlier tables were deleted.*"
            )
        else:
            text = f"{_stamp(records, family)} {what}\n\n{_verdict(records, names)}\n\n"
            text += _table(records, names)
        pages.write_block(DOC, f"robustness-{family}", text, made)
    print(f"wrote {DOC}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("what", choices=(*FAMILIES, "docs", "all"))
    ap.add_argument("--budget-min", type=float, default=20.0, help="CPU minutes per family")
    args = ap.parse_args()
    record = pages.start(MEASURES, "python experiments/robustness.py docs")
    for family in FAMILIES:
        if args.what in (family, "all"):
            run_family(family, args.budget_min)
    write_docs(record)


if __name__ == "__main__":
    main()
