"""How much a run's extremes miss when taken at step ends only, with the step midpoints too
(the default, `simulate(..., extreme_samples=1)`), and with 4 interior samples per step; and
what a maximum over saved states gives instead. Writes docs/output_extremes.md.

    PYTHONPATH=. python experiments/extremes_sampling.py

Per scene and solver, at the scene's default tolerances: the largest contact force, the
largest penetration and the acceleration extremes of one coordinate (slider x; panel 1 y) as
`Trajectory.extremes` tracks them (every accepted step; the step sequence does not depend on
the samples or on the output times, so the runs differ only in where they look), and the
same maxima over 501 and 20001 saved states. The miss is measured against the 4-sample
value (the largest found).
"""

from __future__ import annotations

import os

import numpy as np

from jaxdeploy import pages
from jaxdeploy.analysis import clearance_joint_history
from jaxdeploy.io import atomic_write_bytes
from jaxdeploy.scenes import DeployArray, SliderCrank
from jaxdeploy.simulation import simulate

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DOC = os.path.join(ROOT, "docs", "output_extremes.md")
CASES = [
    # (scene, solver override, body, coordinate)
    (SliderCrank(), None, "slider", 0),
    (SliderCrank(), "tsit5", "slider", 0),
    (DeployArray(), None, "panel1", 1),
]
SAMPLES = (0, 1, 4)


def _case(scene, solver, body, coordinate):
    params = scene.resolve_params()
    mech = scene.build(params)
    initial = scene.initial_state(params, mech)
    control = dict(scene.default_control)
    if solver is not None:
        control["solver"] = solver
    k = 3 * mech.body_index(body) + coordinate
    rows = {}
    for samples in SAMPLES:
        tr = simulate(
            mech, initial, scene.default_t_end, n_save=501, extreme_samples=samples, **control
        )
        assert tr.ok, tr.status()
        ex = {key: np.asarray(value) for key, value in tr.extremes.items()}
        rows[f"tracked, {samples} interior"] = {
            "force": float(ex["normal_force_max"].max()),
            "penetration": float(ex["penetration_max"].max()),
            "acc_min": float(ex["acceleration_min"][k]),
            "acc_max": float(ex["acceleration_max"][k]),
            "steps": int(tr.stats["num_accepted_steps"]),
        }
    for n_save in (501, 20001):
        tr = simulate(mech, initial, scene.default_t_end, n_save=n_save, **control)
        history = list(clearance_joint_history(mech, tr).values())
        qdd = np.asarray(tr.qdd[:, k])
        rows[f"saved states, {n_save}"] = {
            "force": float(max(np.max(h["normal_force"]) for h in history)),
            "penetration": float(max(np.max(h["penetration"]) for h in history)),
            "acc_min": float(qdd.min()),
            "acc_max": float(qdd.max()),
            "steps": int(tr.stats["num_accepted_steps"]),
        }
    return control.get("solver", "generalized_alpha"), f"{body} q̈[{'xyθ'[coordinate]}]", rows


def _table(scene, solver, label, rows) -> str:
    best = rows[f"tracked, {SAMPLES[-1]} interior"]
    lines = [
        f"### {scene.name}, {solver} ({best['steps']} accepted steps)",
        "",
        f"| extremes from | max contact force [N] | max penetration [m] | min {label} | "
        f"max {label} | largest miss |",
        "|---|---|---|---|---|---|",
    ]
    for name, row in rows.items():
        misses = [
            abs(row[key] - best[key]) / abs(best[key])
            for key in ("force", "penetration", "acc_min", "acc_max")
        ]
        lines.append(
            f"| {name} | {row['force']:.6g} | {row['penetration']:.6g} | {row['acc_min']:.6g} "
            f"| {row['acc_max']:.6g} | {max(misses):.1e} |"
        )
    return "\n".join(lines) + "\n"


# What moves the numbers: the two scenes' default runs and the extremes folded over the steps.
MEASURES = [
    "experiments/extremes_sampling.py",
    "jaxdeploy/analysis/contact_forces.py",
    "jaxdeploy/contact",
    "jaxdeploy/mechanism",
    "jaxdeploy/scenes/_contact.py",
    "jaxdeploy/scenes/base.py",
    "jaxdeploy/scenes/data",
    "jaxdeploy/scenes/deploy_array.py",
    "jaxdeploy/scenes/slider_crank.py",
    "jaxdeploy/simulation.py",
    "jaxdeploy/solvers",
]


def main():
    record = pages.start(MEASURES, "python experiments/extremes_sampling.py")
    sections = []
    for scene, solver, body, coordinate in CASES:
        name, label, rows = _case(scene, solver, body, coordinate)
        sections.append(_table(scene, name, label, rows))
        print(sections[-1], flush=True)
    text = (
        "# Extremes of a run: tracked over the steps, not read off the saved states\n\n"
        "`Trajectory.extremes` (`jaxdeploy.solvers.TrackExtremes`) folds the largest contact "
        "force and penetration of every clearance joint and the acceleration extremes over "
        "every accepted step: at its end and at `extreme_samples` interior points of its dense "
        "output (default 1, the midpoint). The summaries (`jaxdeploy simulate`'s "
        "summary.json) report these, so they do not change with `--n-save`. Below, each scene "
        "at its default tolerances; the miss is relative to the 4-sample value. The saved "
        "states' maxima show what a summary over the output grid reported before.\n\n"
        + "\n".join(sections)
    )
    atomic_write_bytes(DOC, pages.whole_page(text, record).encode())
    print(f"wrote {DOC}")


if __name__ == "__main__":
    main()
