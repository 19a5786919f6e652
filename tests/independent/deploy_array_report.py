"""The ideal-joint deploy_array against a model that shares no code with jaxdeploy (issue 24,
item 5); writes the generated block `independent-check` of docs/deploy_array.md, the figure
docs/figures/deploy_array_independent.png and the numbers docs/deploy_array_independent.json.

The reference, `tests/independent/deploy_array_minimal.py`, has one coordinate (the root-hinge
angle α), closed-form loops and Lagrange's equation, integrated by scipy (DOP853 and Radau,
rtol 1e-12/1e-13) with the latch engagement located as an event. jaxdeploy runs
`DeployArray(ideal=True, latch="angle_only")` (the latch the reference models): 21 absolute
coordinates, 20 constraints, at the scene's default step control and at tighter ones; and the
scene's default, preloaded latch at the default control (its preload acts after the lock).
Compared: α at 4001 equally spaced times over the scene's
2 s, the lock time (the first time α reaches 90°, located on a 1 µs output grid around it)
and α̇ there.

How discriminating the check is: the reference is rerun with the spring stiffness changed by
1e-5 and the latch stiffness by 1e-4 (relative), and the same measures reported.

Usage: `cd tests && PYTHONPATH=.. python -m independent.deploy_array_report` (about 10 min on one
loaded core).
"""

from __future__ import annotations

import copy
import json
import math
import os
import time

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from jaxdeploy import pages  # noqa: E402
from jaxdeploy.io import (  # noqa: E402
    atomic_write_bytes,
    run_metadata,
)
from jaxdeploy.scenes import DeployArray  # noqa: E402
from jaxdeploy.scenes.deploy_array import deployment_angle  # noqa: E402
from jaxdeploy.simulation import simulate  # noqa: E402

from . import deploy_array_minimal  # noqa: E402

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..")
DOC = os.path.join(ROOT, "docs", "deploy_array.md")
FIGURE = os.path.join(ROOT, "docs", "figures", "deploy_array_independent.png")
NUMBERS = os.path.join(ROOT, "docs", "deploy_array_independent.json")
T_END = 2.0  # s, the scene's default
N_TIMES = 4001
AGREEMENT = 1e-6  # relative, issue 24 item 5


def package_runs(scene):
    """(label, latch, control) of the jaxdeploy runs. The reference models the angle-only
    latch (a rotational spring–damper on α from the lock on), so the runs use
    `latch="angle_only"`; the last row is the scene's default, preloaded latch, whose
    preload acts on the ideal hinges too (a model difference after the lock, not an
    integration error)."""
    default = dict(scene.default_control)
    return [
        ("Tsit5, scene default control (rtol 1e-6, atol 1e-9)", "angle_only", default),
        ("Tsit5, rtol 1e-10, atol 1e-12", "angle_only", {**default, "rtol": 1e-10, "atol": 1e-12}),
        (
            "generalized-α, rtol 1e-6, atol 1e-9",
            "angle_only",
            {**default, "solver": "generalized_alpha"},
        ),
        (
            "generalized-α, rtol 1e-8, atol 1e-11",
            "angle_only",
            {**default, "solver": "generalized_alpha", "rtol": 1e-8, "atol": 1e-11},
        ),
        (
            "Tsit5, scene default control, preloaded latch (the scene's default)",
            "preloaded",
            default,
        ),
    ]


def crossing(ts, values, level):
    """First time `values` reaches `level`, linear between samples (NaN if never)."""
    above = np.flatnonzero(values >= level)
    if len(above) == 0 or above[0] == 0:
        return math.nan
    i = above[0]
    return float(
        ts[i - 1] + (level - values[i - 1]) / (values[i] - values[i - 1]) * (ts[i] - ts[i - 1])
    )


def rate_before(ts, rate, t_lock):
    """α̇ at `t_lock`, extrapolated by the parabola through the last three samples before it:
    α̈ jumps at the lock (the latch's damping), so an interval across it would not do, and
    α⃛ is large there (I′(α) changes fast near 90°), so a straight line would be off by
    ~½ α⃛ Δt² ≈ 2e-9 rad/s on the 1 µs grid."""
    i = np.searchsorted(ts, t_lock) - 1  # ts[i] < t_lock <= ts[i + 1]
    coeffs = np.polyfit(ts[i - 2 : i + 1] - ts[i], rate[i - 2 : i + 1], 2)
    return float(np.polyval(coeffs, t_lock - ts[i]))


def compare(ts, alpha, alpha_ref, t_lock, t_lock_ref, rate_lock, rate_lock_ref, lock_angle):
    """The measures of the page, for one run against the reference."""
    diff = np.abs(alpha - alpha_ref)
    after = ts > t_lock_ref
    # The latch oscillation: α − 90° after the lock (about 6e-3 rad at first).
    swing = np.abs(alpha_ref[after] - lock_angle).max()
    return {
        "max_abs_alpha_difference_rad": float(diff.max()),
        "max_rel_alpha_difference": float((diff / np.abs(alpha_ref)).max()),
        "max_abs_alpha_difference_before_lock_rad": float(diff[~after].max()),
        "max_abs_alpha_difference_after_lock_rad": float(diff[after].max()),
        "max_alpha_difference_after_lock_over_latch_swing": float(diff[after].max() / swing),
        "lock_time_s": t_lock,
        "lock_time_rel_difference": abs(t_lock - t_lock_ref) / t_lock_ref,
        "lock_rate_rad_s": rate_lock,
        "lock_rate_rel_difference": abs(rate_lock - rate_lock_ref) / abs(rate_lock_ref),
    }


# What moves the numbers: deploy_array's ideal-joint simulation and the reference.
MEASURES = [
    "jaxdeploy/mechanism",
    "jaxdeploy/scenes/_contact.py",
    "jaxdeploy/scenes/base.py",
    "jaxdeploy/scenes/data",
    "jaxdeploy/scenes/deploy_array.py",
    "jaxdeploy/simulation.py",
    "jaxdeploy/solvers",
    "tests/independent/deploy_array_minimal.py",
    "tests/independent/deploy_array_report.py",
]


def main():
    record = pages.start(MEASURES, "cd tests && python -m independent.deploy_array_report")
    started = time.perf_counter()
    ref_module = deploy_array_minimal
    model = ref_module.DeployArrayMinimal()
    lock_angle = model.alpha_lock
    uniform = np.linspace(0.0, T_END, N_TIMES)

    timings = {}
    t0 = time.perf_counter()
    ref = model.simulate(T_END, "DOP853", rtol=1e-12, atol=1e-12)
    timings["reference DOP853 1e-12"] = time.perf_counter() - t0
    ts = np.union1d(uniform, ref.lock_time + np.linspace(-5e-5, 5e-5, 101))
    alpha_ref = ref.alpha(ts)

    # The reference's own error: a tighter DOP853 and an implicit method of another family.
    checks = {}
    for label, method, rtol, atol in (
        ("DOP853, rtol 1e-13, atol 1e-14", "DOP853", 1e-13, 1e-14),
        ("Radau, rtol 1e-12, atol 1e-12", "Radau", 1e-12, 1e-12),
    ):
        t0 = time.perf_counter()
        other = model.simulate(T_END, method, rtol=rtol, atol=atol)
        timings[f"reference {label}"] = time.perf_counter() - t0
        checks[label] = {
            "max_abs_alpha_difference_rad": float(np.abs(other.alpha(ts) - alpha_ref).max()),
            "lock_time_rel_difference": abs(other.lock_time - ref.lock_time) / ref.lock_time,
        }
    # Energy: before the lock the spring's work is all kinetic (closed form for α̇ at 90°).
    k, a0 = model.k, model.alpha0
    work = 0.5 * k * ((a0 - model.alpha_start) ** 2 - (a0 - lock_angle) ** 2)
    inertia_lock, _ = model.generalized_inertia(lock_angle)
    rate_energy = math.sqrt(2.0 * work / inertia_lock)

    # How discriminating 1e-6 is: the reference with slightly different constants.
    power = {}
    for label, section, key, rel in (
        ("spring stiffness k × (1 + 1e-5)", "coil_spring", "k", 1e-5),
        ("latch stiffness k_L × (1 + 1e-4)", "latch", "k_latch", 1e-4),
    ):
        data = copy.deepcopy(json.loads(ref_module.DATA_FILE.read_text()))
        data[section][key] *= 1.0 + rel
        other = ref_module.DeployArrayMinimal(data).simulate(T_END, "DOP853", 1e-12, 1e-12)
        alpha_other = other.alpha(ts)
        power[label] = {
            "max_rel_alpha_difference": float(
                (np.abs(alpha_other - alpha_ref) / np.abs(alpha_ref)).max()
            ),
            "lock_time_rel_difference": abs(other.lock_time - ref.lock_time) / ref.lock_time,
        }

    results, histories = {}, {}
    for label, latch, control in package_runs(DeployArray(ideal=True)):
        scene = DeployArray(ideal=True, latch=latch)
        params = scene.resolve_params()
        mech = scene.build(params)
        initial = scene.initial_state(params, mech)
        t0 = time.perf_counter()
        tr = simulate(mech, initial, T_END, ts=ts, **control)
        timings[f"jaxdeploy {label}"] = time.perf_counter() - t0
        if not tr.ok:
            raise RuntimeError(f"{label}: {tr.status()}")
        alpha = np.asarray(deployment_angle(tr.q))
        rate = -np.asarray(tr.v)[:, 2]  # α̇ = −θ̇ of panel 1
        t_lock = crossing(ts, alpha, lock_angle)
        rate_lock = rate_before(ts, rate, t_lock)
        results[label] = compare(
            ts, alpha, alpha_ref, t_lock, ref.lock_time, rate_lock, ref.lock_rate, lock_angle
        )
        results[label]["agrees"] = bool(
            results[label]["max_rel_alpha_difference"] < AGREEMENT
            and results[label]["lock_time_rel_difference"] < AGREEMENT
        )
        results[label]["control"] = control
        results[label]["accepted_steps"] = int(tr.stats["num_accepted_steps"])
        histories[label] = alpha

    numbers = {
        "what": "ideal-joint deploy_array vs an independent one-coordinate model (issue 24 item 5)",
        "command": "cd tests && python -m independent.deploy_array_report",
        "t_end_s": T_END,
        "n_compared_times": int(ts.size),
        "agreement_required_rel": AGREEMENT,
        "reference": {
            "module": "tests/independent/deploy_array_minimal.py",
            "method": "DOP853, rtol 1e-12, atol 1e-12, latch engagement as a terminal event",
            "lock_time_s": ref.lock_time,
            "lock_rate_rad_s": ref.lock_rate,
            "lock_rate_energy_closed_form_rad_s": rate_energy,
            "lock_rate_energy_rel_difference": abs(ref.lock_rate - rate_energy) / rate_energy,
            "generalized_inertia_at_lock_kg_m2": inertia_lock,
            "against_other_integrations": checks,
        },
        "jaxdeploy": results,
        "sensitivity_of_the_reference": power,
        "wall_time_s": {**timings, "total": time.perf_counter() - started},
        "versions": run_metadata(),
    }
    atomic_write_bytes(NUMBERS, (json.dumps(numbers, indent=2, allow_nan=False) + "\n").encode())
    plot(ts, alpha_ref, histories, ref.lock_time, lock_angle)
    pages.write_block(DOC, "independent-check", page_block(numbers), record)
    print(page_block(numbers))


def plot(ts, alpha_ref, histories, t_lock, lock_angle):
    fig, axes = plt.subplots(3, 1, figsize=(8, 9), constrained_layout=True)
    ax = axes[0]
    ax.plot(ts, np.degrees(alpha_ref), "k-", lw=1.5, label="independent (1 coordinate, scipy)")
    first = next(iter(histories))
    every = max(1, ts.size // 80)
    ax.plot(ts[::every], np.degrees(histories[first][::every]), "o", ms=3, mfc="none",
            color="C0", label=f"jaxdeploy: {first}")  # fmt: skip
    ax.set_ylabel("α [deg]")
    ax.set_title("Deployment angle, ideal joints")
    ax.legend(loc="lower right")
    ax = axes[1]
    window = (ts > t_lock - 0.002) & (ts < t_lock + 0.12)
    ax.plot(ts[window], np.degrees(alpha_ref[window] - lock_angle), "k-", lw=1.5,
            label="independent")  # fmt: skip
    ax.plot(ts[window], np.degrees(histories[first][window] - lock_angle), "--", color="C0",
            label="jaxdeploy (scene default control)")  # fmt: skip
    ax.axvline(t_lock, color="0.6", lw=0.8)
    ax.set_ylabel("α − 90° [deg]")
    ax.set_title("After the lock: the latch oscillation (95 Hz, ζ = 0.05)")
    ax.legend(loc="upper right")
    ax = axes[2]
    for i, (label, alpha) in enumerate(histories.items()):
        diff = np.abs(alpha - alpha_ref)
        ax.semilogy(ts, np.maximum(diff, 1e-17), lw=0.8, color=f"C{i}", label=label)
    ax.axhline(AGREEMENT * math.pi / 2, color="r", lw=0.8, ls=":", label="1e-6 × 90°")
    ax.axvline(t_lock, color="0.6", lw=0.8)
    ax.set_xlabel("t [s]")
    ax.set_ylabel("|α_jaxdeploy − α_independent| [rad]")
    ax.set_ylim(1e-18, 1e-1)
    ax.set_title("Difference")
    ax.legend(loc="upper right", fontsize=7)
    fig.savefig(FIGURE, dpi=110)
    plt.close(fig)


def page_block(n):
    ref = n["reference"]
    lines = [
        f"Reference: {ref['method']}. Lock time **{ref['lock_time_s']:.12f} s**, α̇ at lock "
        f"{ref['lock_rate_rad_s']:.12f} rad/s; energy closed form ½ I(90°) α̇² = spring work "
        f"gives {ref['lock_rate_energy_closed_form_rad_s']:.12f} rad/s (relative difference "
        f"{ref['lock_rate_energy_rel_difference']:.1e}).",
        "",
        "The reference's own error (same measures against the run above):",
        "",
        "| reference integration | max abs Δα [rad] | lock time, rel. difference |",
        "|---|---|---|",
    ]
    for label, c in ref["against_other_integrations"].items():
        lines.append(
            f"| {label} | {c['max_abs_alpha_difference_rad']:.1e} | "
            f"{c['lock_time_rel_difference']:.1e} |"
        )
    lines += [
        "",
        f"jaxdeploy `DeployArray(ideal=True)` against it, at {n['n_compared_times']} times over "
        f"0–{n['t_end_s']:g} s (required: relative differences below "
        f"{n['agreement_required_rel']:.0e}):",
        "",
        "| jaxdeploy run | steps | max rel Δα | max abs Δα before / after lock [rad] | "
        "after lock / latch swing | lock time [s] | rel Δ lock time | rel Δ α̇ at lock | "
        "within 1e-6 |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for label, r in n["jaxdeploy"].items():
        lines.append(
            f"| {label} | {r['accepted_steps']} | {r['max_rel_alpha_difference']:.1e} | "
            f"{r['max_abs_alpha_difference_before_lock_rad']:.1e} / "
            f"{r['max_abs_alpha_difference_after_lock_rad']:.1e} | "
            f"{r['max_alpha_difference_after_lock_over_latch_swing']:.1e} | "
            f"{r['lock_time_s']:.12f} | {r['lock_time_rel_difference']:.1e} | "
            f"{r['lock_rate_rel_difference']:.1e} | {'yes' if r['agrees'] else '**no**'} |"
        )
    lines += [
        "",
        "How far a small change of the model moves the reference (the same measures):",
        "",
        "| reference with | max rel Δα | rel Δ lock time |",
        "|---|---|---|",
    ]
    for label, p in n["sensitivity_of_the_reference"].items():
        lines.append(
            f"| {label} | {p['max_rel_alpha_difference']:.1e} | "
            f"{p['lock_time_rel_difference']:.1e} |"
        )
    lines += ["", "![independent check](figures/deploy_array_independent.png)"]
    return "\n".join(lines)


if __name__ == "__main__":
    main()
