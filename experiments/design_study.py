"""Design study: per-panel hinge roughness of deploy_array for each roughness variant of the
model, chosen by a brute-force grid and by sampled-gradient optimisation; does the optimal
machining choice change with the variant? Writes docs/design.md and docs/figures/design_*.png.

    PYTHONPATH=. nice -n 10 .venv/bin/python experiments/design_study.py [PHASE ...]

PHASE: grid, optimize, report or all (default). Results are stored in results/design_study/
(a phase skips a variant whose JSON exists), so the study can be stopped and continued.

Objective `paper_reproducible` (objectives.PRESETS: panel 1 follows the ideal deployment
closely, panel 2 is quiet after the lock — built from features whose values do not move with
the integration tolerance). Variants as in docs/paper_study.md: default (Ra in the elastic law
only), `ploughing` (μ(Ra)), `restitution p=1` (the free c_e(Ra) coupling), `lugre` (LuGre hinge
friction).
"""

from __future__ import annotations

import json
import math
import sys
import time
from pathlib import Path

import numpy as np

import jaxdeploy
from jaxdeploy import pages
from jaxdeploy.analysis import design_grid as dg
from jaxdeploy.io import (
    atomic_savefig,
    atomic_write_bytes,
    atomic_write_json,
    code_revision,
    machine_description,
)
from jaxdeploy.objectives import parse_objective
from jaxdeploy.optimize import MACHINABLE, BatchObjective, DesignProblem, Scatter, evaluate_batch
from jaxdeploy.optimize import optimize as run_optimize
from jaxdeploy.scenes import DeployArray

ROOT = Path(__file__).resolve().parents[1]
RESULTS, DOC, FIG = (
    ROOT / "results" / "design_study",
    ROOT / "docs" / "design.md",
    ROOT / "docs" / "figures",
)
# What moves the numbers: the design objective and optimiser, deploy_array's batched runs.
MEASURES = [
    "experiments/design_study.py",
    "jaxdeploy/analysis",
    "jaxdeploy/batch.py",
    "jaxdeploy/contact",
    "jaxdeploy/mechanism",
    "jaxdeploy/objectives.py",
    "jaxdeploy/optimize.py",
    "jaxdeploy/scenes/_contact.py",
    "jaxdeploy/scenes/base.py",
    "jaxdeploy/scenes/data",
    "jaxdeploy/scenes/deploy_array.py",
    "jaxdeploy/simulation.py",
    "jaxdeploy/solvers",
]
T_END, N_SAVE = 0.75, 1501
OBJECTIVE = "paper_reproducible"
NAMES = ("panel1_ra", "panel2_ra")
GRID_RA = np.geomspace(*MACHINABLE["ra"], 4)
PAPER = {"panel1_ra": 1.6e-6, "panel2_ra": 3.2e-6}
SMOOTHING_S = 0.5  # of the gradient run's Stein smoothing, in ln Ra
# The grid is read smoothed at its own step (ln 3.15 = 1.15): on 4 points a narrower kernel
# does not smooth at all, and what a coarse grid can show is the trend at its scale.
READ_S = float(np.log(GRID_RA[1] / GRID_RA[0]))
OPTIMIZED = ("default",)  # the gradient check, for the default variant only (CPU)
STEPS, PAIRS, LEARNING_RATE = 4, 2, 0.3
VARIANTS = {
    "default": ({}, {}),
    "ploughing": ({"friction_roughness": "ploughing"}, {}),
    "restitution p=1": ({}, {"restitution_roughness_exponent": 1.0}),
    "lugre": ({"friction_law": "lugre"}, {}),
}


def problem(variant):
    options, fixed = VARIANTS[variant]
    return DesignProblem(DeployArray(**options), parse_objective(OBJECTIVE), T_END,
                         n_save=N_SAVE, fixed=fixed)  # fmt: skip


def _path(phase, variant):
    return RESULTS / f"{phase}_{variant.replace(' ', '_')}.json"


def phase_grid(variant):
    """J on the grid (one vmapped batch)."""
    if _path("grid", variant).exists():
        return
    ra1, ra2 = np.meshgrid(GRID_RA, GRID_RA, indexing="ij")
    start = time.perf_counter()
    out = evaluate_batch(problem(variant), {"panel1_ra": ra1.ravel(), "panel2_ra": ra2.ravel()})
    n = len(GRID_RA)
    record = {"J": out["objective"].reshape(n, n).tolist(), "status": out["status"],
              "parts": {k: v.reshape(n, n).tolist() for k, v in out["parts"].items()},
              "wall_s": time.perf_counter() - start, "revision": code_revision(),
              "machine": machine_description()}  # fmt: skip
    print(f"[grid {variant}] {record['wall_s']:.0f} s, {set(out['status'])}", flush=True)
    atomic_write_json(str(_path("grid", variant)), record)


def phase_optimize(variant):
    """Adam on the Gaussian smoothing of J (Stein gradients, antithetic pairs) from the
    paper's design."""
    if _path("optimize", variant).exists() or variant not in OPTIMIZED:
        return
    scatter = Scatter(relative={n: SMOOTHING_S for n in NAMES}, pairs=PAIRS, seed=9)
    start = time.perf_counter()

    def progress(i, r):
        print(f"[optimize {variant}] {i}: J {r.objective[-1]:.4f}", flush=True)

    result = run_optimize(BatchObjective(problem(variant)), PAPER,
                          {n: MACHINABLE["ra"] for n in NAMES}, steps=STEPS,
                          learning_rate=LEARNING_RATE, smoothing=scatter,
                          callback=progress)  # fmt: skip
    record = {**result.to_json(), "wall_s": time.perf_counter() - start,
              "revision": code_revision(), "machine": machine_description()}  # fmt: skip
    atomic_write_json(str(_path("optimize", variant)), record)


def _um(x):
    return f"Ra₁ {x['panel1_ra'] * 1e6:.2f} µm, Ra₂ {x['panel2_ra'] * 1e6:.2f} µm"


def _grid_point(i, j):
    return {"panel1_ra": float(GRID_RA[i]), "panel2_ra": float(GRID_RA[j])}


def _steps_apart(x, y):
    step = math.log(GRID_RA[1] / GRID_RA[0])
    return max(abs(math.log(x[n] / y[n])) for n in NAMES) / step


def figure(grids, opts):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(grids), figsize=(4.6 * len(grids), 4.2), squeeze=False)
    y = np.log10(GRID_RA * 1e6)
    for ax, (variant, J) in zip(axes[0], grids.items(), strict=True):
        image = ax.pcolormesh(y, y, dg.smoothed(J, GRID_RA, READ_S).T, shading="nearest")
        fig.colorbar(image, ax=ax, label="smoothed J")
        path = opts.get(variant)
        if path:
            xs = np.log10(
                np.array([[x[n] * 1e6 for n in NAMES] for x in [h["x"] for h in path["history"]]])
            )
            ax.plot(xs[:, 0], xs[:, 1], "w.-", label="Adam (sampled gradients)")
        ax.plot(*np.log10([PAPER[n] * 1e6 for n in NAMES]), "r*", ms=12, label="paper's advice")
        ax.set(title=variant, xlabel="log10 Ra₁ [µm]", ylabel="log10 Ra₂ [µm]")
        ax.legend(fontsize=7)
    fig.tight_layout()
    path = FIG / "design_variants.png"
    atomic_savefig(fig, str(path))
    plt.close(fig)
    return path


def phase_report():
    record = pages.start(MEASURES, "python experiments/design_study.py all")
    grids = {
        v: json.loads(_path("grid", v).read_text()) for v in VARIANTS if _path("grid", v).exists()
    }
    opts = {v: json.loads(_path("optimize", v).read_text()) for v in VARIANTS
            if _path("optimize", v).exists()}  # fmt: skip
    J = {v: np.asarray(g["J"]) for v, g in grids.items()}
    fig = figure(J, opts)
    first = next(iter(grids.values()))
    runs_at = first["revision"]["commit"][:7]
    # The stored runs' commits (the freshness test checks them too); a run of uncommitted
    # code makes the page dirty.
    stored = [r["revision"] for r in (*grids.values(), *opts.values()) if r.get("revision")]
    record["runs_at"] = sorted({r["commit"] for r in stored} - {record["commit"]})
    record["dirty"] = record["dirty"] or any(r["dirty"] for r in stored)
    load = " ".join(f"{x:.0f}" for x in first["machine"]["load_average_1_5_15min"])
    lines = [HEADER.format(runs_at=runs_at,
                           version=jaxdeploy.__version__, t_end=T_END,
                           grid=", ".join(f"{r * 1e6:.2f}" for r in GRID_RA), n=len(GRID_RA),
                           s=SMOOTHING_S, read_s=READ_S, steps=STEPS, pairs=PAIRS, lr=LEARNING_RATE,
                           load=load),
             "| variant | grid wall [s] | raw grid minimum | smoothed grid minimum | "
             "points within 2 s.e. | gradient run's end | steps from the smoothed minimum |",
             "|---|---|---|---|---|---|---|"]  # fmt: skip
    best = {}
    for v, grid in grids.items():
        raw = _grid_point(*dg.grid_argmin(J[v]))
        smooth = dg.smoothed(J[v], GRID_RA, READ_S)
        best[v] = _grid_point(*dg.grid_argmin(smooth))
        near = dg.near_optimal(J[v], GRID_RA, READ_S)
        o = opts.get(v)
        # A stochastic run ends at its last iterate (its J values are noisy estimates).
        end = f"{_um(o['last'])} ({o['wall_s']:.0f} s)" if o and o.get("last") else "not run"
        apart = f"{_steps_apart(o['last'], best[v]):.2f}" if o and o.get("last") else "—"
        lines.append(f"| {v} | {grid['wall_s']:.0f} | {_um(raw)} | **{_um(best[v])}** | "
                     f"{int(near.sum())} of {near.size} | {end} | {apart} |")  # fmt: skip
    lines += ["", f"![smoothed J per variant]({Path(fig).relative_to(DOC.parent)})", "",
              "J on the grid (rows Ra₁, columns Ra₂ [µm]):", ""]  # fmt: skip
    for v in grids:
        header = " | ".join(f"{r * 1e6:.2f}" for r in GRID_RA)
        lines += [f"**{v}**", "", f"| Ra₁ \\\\ Ra₂ | {header} |",
                  "|---|" + "---|" * len(GRID_RA)]  # fmt: skip
        lines += [f"| {GRID_RA[i] * 1e6:.2f} | " + " | ".join(f"{x:.3f}" for x in row) + " |"
                  for i, row in enumerate(J[v])]  # fmt: skip
        lines.append("")
    lines += ["What moves J: each term at the smoothest and the roughest corner of the grid, "
              "and J's roughness against its trend:", "",
              "| variant | term | Ra 0.2/0.2 µm | Ra 6.3/6.3 µm | ratio |",
              "|---|---|---|---|---|"]  # fmt: skip
    for v, grid in grids.items():
        for label, part in grid["parts"].items():
            lo, hi = part[0][0], part[-1][-1]
            lines.append(f"| {v} | `{label}` | {lo:.4g} | {hi:.4g} | {hi / lo:.2f} |")
    lines.append("")
    for v in grids:
        smooth = dg.smoothed(J[v], GRID_RA, READ_S)
        rough = float(np.sqrt(np.mean((J[v] - smooth) ** 2)))
        lines.append(f"* {v}: rms(J − J_s) = {rough:.3f}, range of J_s = "
                     f"{float(np.ptp(smooth)):.3f}.")  # fmt: skip
    lines.append("")
    # A variant prefers a design only if most of the grid can be told from its minimum.
    resolved = {v: int(dg.near_optimal(J[v], GRID_RA, READ_S).sum()) for v in grids}
    lines += ["## Does the machining choice change with the variant?", ""]
    for v, b in best.items():
        n = resolved[v]
        lines.append(f"* {v}: smoothed minimum {_um(b)}; " + (
            f"**resolved** ({n} of {J[v].size} grid points within two standard errors)"
            if n <= J[v].size // 2 else
            f"**no resolved preference** ({n} of {J[v].size} grid points within two "
            "standard errors of the minimum)"))  # fmt: skip
    lines += [
              "", VERDICT_TEXT]  # fmt: skip
    text = pages.whole_page("\n".join(lines).rstrip() + "\n", record)
    atomic_write_bytes(str(DOC), text.encode())
    print(f"wrote {DOC}")


HEADER = """\
# Choosing hinge roughness per panel (design study)

*jaxdeploy {version}, runs at {runs_at}; every number below comes from the stored results of
`python experiments/design_study.py all` (in `results/design_study/`: delete them to rerun).*

The seed study (W24 §4.1) ends with machining advice: panel 1 ("a faster system response
speed") Ra 1.6 µm, panel 2 ("reduce the vibration phenomenon") Ra 3.2 µm, from three roughness
values compared by eye. Here the same question is an optimisation, asked of each roughness
variant of our model (docs/paper_study.md): the **default** (Ra acts only in the GW-averaged
elastic law), **ploughing** (μ(Ra) = 0.01 + (2/π) Δa(Ra), a turned surface of tool nose
radius 0.8 mm, contact.PloughingFriction), **restitution p=1** (c_e(Ra) = 0.9^(Ra/1.6 µm),
the free coupling) and **lugre** (LuGre hinge friction that sticks, contact.LuGreContactFriction,
μ independent of Ra). From the command line: `jaxdeploy optimize --objective
paper_reproducible --param panel1_ra --param panel2_ra --set restitution_roughness_exponent=1`
(restitution p=1), with `--scene-option friction_roughness=ploughing` (ploughing) or
`--scene-option friction_law=lugre` (lugre).

## Set-up

* deploy_array (preloaded latch, onset impact rule, clearance 50 µm at both hinges), {t_end} s
  (lock at 0.54 s), outputs every 0.5 ms, Tsit5 at the scene's default control; deviations
  from the ideal-joint run.
* Objective `paper_reproducible`: J = ln dev(panel 1) + ln peak(panel 2) + ln peak_acc(panel 2)
  (objectives.PRESETS): panel 1 follows the ideal deployment before the lock (the "fast
  response"), panel 2's post-lock peak tip displacement and acceleration deviations are small.
* Brute force: Ra of each hinge on {n} values {grid} µm (the machinable range; ploughing's
  range of validity ends at 6.4 µm), one vmapped batch per variant. J is rough below the grid's
  scale (contact events shift with the design), so what a designer should read is the grid
  smoothed with Gaussian weights of width {read_s:.2f} in ln Ra (one grid step,
  `analysis.design_grid`), and the points whose smoothed J is within two standard errors of
  its minimum.
* Gradient check (default variant only): Adam (learning rate {lr}) on J smoothed at s = {s},
  Stein gradients from {pairs} antithetic pairs per step (one batch), {steps} steps from the
  paper's design.
* Cut for CPU (2 cores shared by ~5 engineers, load average {load} at the first grid): a
  {n}×{n} grid (was 9×9: five times the cases, about an hour for the four variants at the
  grid walls below, past the session's deadline), {steps} steps of {pairs} pairs (was 12 of
  4), the objective
  `paper` (built on tolerance-sensitive decay and frequency terms), its robust design and the
  well-posedness check of the features were not rerun.

## Results
"""

VERDICT_TEXT = """\
**Reading.** With roughness acting only through the elastic law (default) or through the free
restitution coupling (p = 1), J's trend over the whole machinable range is of the order of its
roughness between neighbouring designs (the lines above the verdicts): the smoothed minimum
sits at the roughest corner, but most of the grid cannot be told from it, and the corner owes
its value mostly to the post-lock peak acceleration, a term that scatters from design to
design. With the
ploughing friction the picture is clear and opposite: the friction coefficient grows with
√Ra (0.024 at 0.2 µm to 0.089 at 6.3 µm), hinge friction delays the unfolding, and panel 1's
deployment deviation grows with both hinges' roughness by far more than J's roughness — the
smoothest surfaces win. The answer a designer should act on is therefore set by the friction
law, i.e. by measurements of μ against the surface finish of the actual hinge pair, not by
the contact-stiffness effect of roughness: if friction follows the asperity slope as the
ploughing relation says, machine both hinges as smooth as affordable; the paper's advice
(Ra₁ 1.6, Ra₂ 3.2 µm) is not the optimum of any variant. LuGre hinge friction (hinges that
stick; μ independent of Ra) makes J about half as rough between neighbouring designs as the
default (rms 0.05 against 0.10), so its trend of similar size resolves a preference for the
roughest corner — each term falls by 5–11 % from the smoothest to the roughest corner, the
contact-stiffness effect of Ra — but that trend is a quarter of ploughing's and of the
opposite sign: where friction depends on the finish, friction decides. The gradient run
(default variant) ended about a grid step from the smoothed minimum, inside the region that
cannot be told from it: on a grid this coarse and an objective this flat, that agreement is a
weak check.

Caveats: the mechanism is a reconstruction (the paper's Fig. 8 and Table 2 are missing;
docs/deploy_array_geometry.md); μ_a = 0.01 and the tool nose radius are our choices; the
restitution coupling's exponent is unknown (docs/contact.md)."""


def main(argv) -> int:
    phases = argv or ["all"]
    RESULTS.mkdir(parents=True, exist_ok=True)
    for variant in VARIANTS:
        if {"grid", "all"} & set(phases):
            phase_grid(variant)
    for variant in VARIANTS:
        if {"optimize", "all"} & set(phases):
            phase_optimize(variant)
    if {"report", "all"} & set(phases):
        phase_report()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
