"""How deploy_array derivatives grow with the horizon, and where they stop describing the
model: forward-mode AD through the adaptive run with its steps replayed, against central
differences over the same steps.

`jaxdeploy.simulate(..., replay_steps=True)` makes the differentiated run step over the
accepted steps of an undifferentiated adaptive run, so AD gives the exact derivative of one
discrete map; a central difference that replays the same steps approximates that derivative
with an O(h²) truncation error and no step-selection noise. Per time window the script
reports the size of the derivative (max |c dy/dc| over the window, i.e. the output change
per 100 % change of c, linearised) and the disagreement ‖FD_h − AD‖/‖AD‖ for relative steps
h = 1e-2 … 1e-8: where it is small the derivative is verified; the largest h at which it stays
below 10 % is the range over which the linearisation holds ("linear range"). A pointwise
derivative whose linear range is below the parameter's uncertainty (or below 1e-6, where
integration error competes) says nothing useful about the model's response.

Usage: `PYTHONPATH=. python experiments/gradient_horizon.py [--t-end 0.7]` (~15 min on 2
shared cores). Writes `docs/figures/gradient_horizon.{json,png}` and the "gradient_horizon"
block of `docs/identification.md`.
"""

from __future__ import annotations

import argparse
import os
import time

import diffrax as dfx
import jax
import jax.numpy as jnp
import matplotlib
import numpy as np

from jaxdeploy import pages

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from jaxdeploy.analysis.deploy_array import crossing_time  # noqa: E402
from jaxdeploy.batch import run_scene, simulate_batch  # noqa: E402
from jaxdeploy.io import atomic_write_json, run_metadata  # noqa: E402
from jaxdeploy.scenes import DeployArray  # noqa: E402
from jaxdeploy.scenes.deploy_array import GEOMETRY, deployment_angle  # noqa: E402

# The solver this experiment's page was generated with (pinned: deploy_array's default is
# now Tsit5, and a rerun must reproduce what the page says).
SOLVER = "generalized_alpha"

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PARAMS = ["panel1_clearance", "restitution"]
CHANNELS = ["alpha", "panel2_tip_ay"]
STEPS = [1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8]
EDGES = [0.0, 0.01, 0.025, 0.05, 0.1, 0.2, 0.3, 0.4, 0.5, 0.55, 0.6, 0.7, 1.0, 1.5, 2.0]


# What moves the numbers: deploy_array's simulation and its derivatives.
MEASURES = [
    "jaxdeploy/analysis/deploy_array.py",
    "jaxdeploy/batch.py",
    "jaxdeploy/contact",
    "jaxdeploy/mechanism",
    "jaxdeploy/scenes/_contact.py",
    "jaxdeploy/scenes/base.py",
    "jaxdeploy/scenes/data",
    "jaxdeploy/scenes/deploy_array.py",
    "jaxdeploy/simulation.py",
    "jaxdeploy/solvers",
    "experiments/gradient_horizon.py",
]


def main(argv=None):
    record = pages.start(MEASURES, "python experiments/gradient_horizon.py")
    parser = argparse.ArgumentParser()
    parser.add_argument("--t-end", type=float, default=0.7)
    parser.add_argument("--n-save", type=int, default=281)
    args = parser.parse_args(argv)
    scene = DeployArray()
    base = scene.resolve_params()
    t_end = args.t_end
    ts = jnp.linspace(0.0, t_end, args.n_save)
    x0 = {k: float(base[k]) for k in PARAMS}

    def f(x):
        p = {**base, **x}
        traj = run_scene(scene, p, t_end, ts=ts, adjoint=dfx.ForwardMode(), replay_steps=True,
                         solver=SOLVER)  # fmt: skip
        ch = scene.channels(scene.build(p), traj)
        return jnp.stack([ch[n] for n in CHANNELS]), traj

    start = time.perf_counter()
    ad, traj = jax.jit(jax.jacfwd(f, has_aux=True))(x0)
    ad = {k: np.asarray(v) for k, v in ad.items()}
    times = np.asarray(traj.step_times)
    n_steps = int(np.isfinite(times).sum())
    print(f"AD: {time.perf_counter() - start:.0f} s, {n_steps} steps, {traj.status()}")
    alpha = np.asarray(deployment_angle(traj.q))
    lock = float(crossing_time(np.asarray(traj.ts), alpha, GEOMETRY["latch"]["engage_alpha"]))
    lock = lock if np.isfinite(lock) else None

    cases = []
    for name in PARAMS:
        for h in STEPS:
            for sign in (1.0, -1.0):
                cases.append({**base, name: x0[name] * (1.0 + sign * h)})
    start = time.perf_counter()
    batch = simulate_batch(scene, cases, t_end, ts=ts, replay_steps=times[:n_steps], solver=SOLVER)
    print(f"FD batch ({len(cases)} runs): {time.perf_counter() - start:.0f} s")
    t = np.asarray(ts)
    rows = []
    k = 0
    fd = {}
    failures = {}
    for name in PARAMS:
        for h in STEPS:
            plus, minus = batch.case(k), batch.case(k + 1)
            # A replayed run whose Newton iteration fails at some step stops there; the
            # difference is used up to the earlier of the two stops.
            yp = scene.channels(batch.mechanism(k), plus)
            ym = scene.channels(batch.mechanism(k + 1), minus)
            d = np.stack(
                [(np.asarray(yp[n]) - np.asarray(ym[n])) / (2 * h * x0[name]) for n in CHANNELS]
            )
            d[:, ~np.all(np.isfinite(d), axis=0)] = np.nan
            fd[name, h] = d
            if not (plus.ok and minus.ok):
                failures[f"{name} h={h:g}"] = [plus.status(), minus.status()]
                print(f"{name} h={h:g}: {plus.status()} / {minus.status()}")
            k += 2
    edges = [e for e in EDGES if e < t_end] + [t_end]
    for t0, t1 in zip(edges[:-1], edges[1:], strict=True):
        mask = (t > t0) & (t <= t1)
        row = {"window": [t0, t1]}
        for name in PARAMS:
            for c, ch in enumerate(CHANNELS):
                a = ad[name][c, mask]
                entry = {"max_abs_scaled": float(np.max(np.abs(a)) * x0[name]), "fd_error": {}}
                linear = 0.0
                for h in STEPS:
                    d = fd[name, h]
                    if not np.all(np.isfinite(d[c, mask])):
                        entry["fd_error"][f"{h:g}"] = None
                        continue
                    err = float(np.linalg.norm(d[c, mask] - a) / max(np.linalg.norm(a), 1e-300))
                    entry["fd_error"][f"{h:g}"] = err
                    if err < 0.1 and linear == 0.0:
                        linear = h
                entry["linear_range"] = linear
                row[f"{name}/{ch}"] = entry
        rows.append(row)
    atomic_write_json(
        os.path.join(ROOT, "docs/figures/gradient_horizon.json"),
        {"params": PARAMS, "channels": CHANNELS, "steps": STEPS, "t_end": t_end,
         "accepted_steps": n_steps, "lock_time_s": lock, "rows": rows,
         "fd_failures": failures,
         "versions": run_metadata()},
    )  # fmt: skip

    fig, axes = plt.subplots(len(CHANNELS), 1, figsize=(8, 6), sharex=True)
    for c, ch in enumerate(CHANNELS):
        ax = axes[c]
        for name in PARAMS:
            ax.semilogy(
                t, np.abs(ad[name][c]) * x0[name], lw=0.8, label=f"|p d{ch}/dp|, p = {name}"
            )
        if lock:
            ax.axvline(lock, color="k", lw=0.6, ls=":")
        ax.set_ylabel(f"|p d{ch}/dp|")
    axes[0].legend(fontsize=7)
    axes[-1].set_xlabel("t [s]")
    fig.tight_layout()
    fig.savefig(os.path.join(ROOT, "docs/figures/gradient_horizon.png"), dpi=110)

    def fmt(x):
        return "stop" if x is None else f"{x:.1g}"

    lines = [
        "default deploy_array run "
        f"to {t_end:g} s "
        f"({n_steps} accepted adaptive steps, replayed; latch locks at "
        f"{lock if lock is None else f'{lock:.3f}'} s). For each window: the largest "
        "|p dy/dp| (forward-mode AD), ‖FD_h − AD‖/‖AD‖ for central differences over the same "
        'steps with relative step h ("stop": a perturbed replay\'s Newton iteration '
        "failed before the window ended), and the linear range (largest h with agreement "
        "< 10 %; 0: none).",
        "",
        "| window [s] | derivative | max \\|p dy/dp\\| | "
        + " | ".join(f"h={h:g}" for h in STEPS)
        + " | linear range |",
        "|---|---|---|" + "---|" * len(STEPS) + "---|",
    ]
    for row in rows:
        for name in PARAMS:
            for ch in CHANNELS:
                e = row[f"{name}/{ch}"]
                lines.append(
                    f"| {row['window'][0]:g}–{row['window'][1]:g} | d`{ch}`/d`{name}` | "
                    f"{e['max_abs_scaled']:.2g} | "
                    + " | ".join(fmt(e["fd_error"][f"{h:g}"]) for h in STEPS)
                    + f" | {e['linear_range']:g} |"
                )
    lines += ["", "![derivative size over the horizon](figures/gradient_horizon.png)"]
    doc = os.path.join(ROOT, "docs/identification.md")
    pages.write_block(doc, "gradient_horizon", "\n".join(lines), record)


if __name__ == "__main__":
    main()
