"""The loss of the worked identification along each parameter axis, for several residual
definitions: why pointwise and block losses fail from guesses 50 % off and smoothed ones
do not.

Runs deploy_array (root hinge J1 with clearance, fixed step 1e-5 s, 0–30 ms, the set-up of
`experiments/identification.py`) with one parameter at a time scaled by each factor, all as
one vmapped batch, and evaluates ½χ² against the measurements of that script
(`docs/figures/identification/data.npz`; run it first) for:

* the earlier set-up: every 25th sample (0.5 ms apart), 2 ms block means over 0–10 ms;
* every sample (20 µs apart), pointwise, over 0–30 ms;
* every sample, 1 ms block means;
* every sample, smoothed over 4 ms and over 1 ms (`ResidualSpec("smooth")`).

Writes `docs/figures/identification/landscape.json` and the "identification_landscape"
block of `docs/identification.md`. Usage: `PYTHONPATH=. python
experiments/identification_landscape.py`.
"""

from __future__ import annotations

import json
import os
import time

import numpy as np

from jaxdeploy import pages
from jaxdeploy.batch import simulate_batch
from jaxdeploy.fit import Comparison, Measurements, ResidualSpec, load_measurements
from jaxdeploy.io import atomic_write_json, run_metadata
from jaxdeploy.scenes import DeployArray

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
OUT = os.path.join(ROOT, "docs", "figures", "identification")
NAMES = ["panel1_clearance", "panel1_ra", "restitution", "friction_coefficient"]
FACTORS = [0.5, 0.7, 0.9, 0.95, 0.98, 0.99, 1.0, 1.01, 1.02, 1.05, 1.1, 1.3, 1.5]


# What moves the numbers: the residuals and deploy_array's batched fixed-step simulation (the
# measurements, docs/figures/identification/data.npz, are identification.py's: run it first).
MEASURES = [
    "experiments/identification_landscape.py",
    "jaxdeploy/batch.py",
    "jaxdeploy/contact",
    "jaxdeploy/mechanism",
    "jaxdeploy/scenes/_contact.py",
    "jaxdeploy/scenes/base.py",
    "jaxdeploy/scenes/data",
    "jaxdeploy/scenes/deploy_array.py",
    "jaxdeploy/simulation.py",
    "jaxdeploy/solvers",
    "jaxdeploy/fit",
]


def main():
    record = pages.start(MEASURES, "python experiments/identification_landscape.py")
    # The measurements are identification.py's: the commit (and tree) that made them counts.
    with open(os.path.join(OUT, "summary.json"), encoding="utf-8") as fh:
        made = json.load(fh)["versions"]["git"] or {"commit": "unknown", "dirty": True}
    record["runs_at"] = sorted({made["commit"]} - {record["commit"]})
    record["dirty"] = record["dirty"] or made["dirty"]
    data = load_measurements(os.path.join(OUT, "data.npz"))
    scene = DeployArray(clearance_joints={"J1": "panel1"})
    truth = scene.resolve_params()
    control = {"rtol": None, "atol": None, "dt_max": None, "dt": 1e-5}
    cases, keys = [], []
    for n in NAMES:
        for f in FACTORS:
            value = truth[n] * f
            if (
                scene.params[n].low
                <= value
                < min(scene.params[n].high, 0.995 if n == "restitution" else np.inf)
            ):
                cases.append({**truth, n: value})
                keys.append((n, f))
    start = time.perf_counter()
    batch = simulate_batch(scene, cases, float(data.t[-1]), ts=data.t, control=control)
    wall = time.perf_counter() - start
    if not all(batch.ok):
        raise SystemExit(f"a run failed: {[s for s in batch.statuses() if s != 'ok'][0]}")
    names = list(data.names)
    runs = [
        scene.select_channels(batch.mechanism(i), batch.case(i), names) for i in range(batch.size)
    ]
    sparse = Measurements(data.t[::25], {n: v[::25] for n, v in data.channels.items()}, data.noise)
    losses = {
        "0.5 ms samples, 2 ms blocks, 0–10 ms (earlier set-up)": (
            sparse, ResidualSpec("block", ((0.0, 0.01),), block=0.002), slice(None, None, 25)),
        "20 µs samples, pointwise, 0–30 ms": (data, ResidualSpec("trajectory"), slice(None)),
        "20 µs samples, 1 ms blocks": (data, ResidualSpec("block", block=0.001), slice(None)),
        "20 µs samples, smoothed, 4 ms": (data, ResidualSpec("smooth", width=4e-3), slice(None)),
        "20 µs samples, smoothed, 1 ms": (data, ResidualSpec("smooth", width=1e-3), slice(None)),
    }  # fmt: skip
    table = {}
    for label, (d, spec, take) in losses.items():
        cmp_ = Comparison(d, spec)
        table[label] = {
            f"{n}×{f:g}": 0.5 * float(np.sum(cmp_.residuals_np(
                {c: np.asarray(runs[i][c])[take] for c in names}) ** 2))
            for i, (n, f) in enumerate(keys)
        }  # fmt: skip
        table[label]["n_residuals"] = cmp_.size
    atomic_write_json(
        os.path.join(OUT, "landscape.json"),
        {"factors": FACTORS, "parameters": NAMES, "truth": {n: truth[n] for n in NAMES},
         "half_chi2": table, "batch_wall_s": wall, "cases": len(cases),
         "versions": run_metadata()},
    )  # fmt: skip
    lines = [
        "½χ² against the measurements "
        f"of the worked identification with one parameter scaled by the factor in the header "
        f"(the others at the truth; {len(cases)} runs as one batch, {wall:.0f} s). At the "
        "truth ½χ² ≈ half the number of residuals is the noise; c_e is capped below 0.995.",
        "",
    ]
    for label in losses:
        lines += [
            f"*{label}* ({table[label]['n_residuals']} residuals):",
            "",
            "| parameter | " + " | ".join(f"×{f:g}" for f in FACTORS) + " |",
            "|---|" + "---|" * len(FACTORS),
        ]
        for n in NAMES:
            cells = [table[label].get(f"{n}×{f:g}") for f in FACTORS]
            lines.append(
                f"| `{n}` | " + " | ".join("–" if c is None else f"{c:.2g}" for c in cells) + " |"
            )
        lines.append("")
    doc = os.path.join(ROOT, "docs/identification.md")
    pages.write_block(doc, "identification_landscape", "\n".join(lines), record)


if __name__ == "__main__":
    main()
