"""The roughness/clearance study of the seed paper's section 4, with our deploy_array model.

Cases (both hinges alike, as in the paper): Ra ∈ {0.8, 1.6, 3.2} µm at c = 0.05 mm, and
c ∈ {0.01, 0.05, 0.1} mm at Ra = 1.6 µm — five distinct parameter sets, run as **one**
vmapped batch (`jaxdeploy.batch.simulate_batch`: one compilation), 2 s each, saved at 10 kHz
for the spectra. The ideal-joint mechanism is the reference for every deviation.

The same batch is run a second time at a tenfold tighter tolerance. Every number of the claim
table comes with its change between the two runs: a claim whose effect is smaller than that
numerical uncertainty is reported as *not resolved*, not as agreement.

Run from the repository root (≈ 10–30 min on a 2-core CPU; the batches are cached in
`results/paper_study/`, so a rerun only redoes the analysis; `--rerun` forces new runs)::

    .venv/bin/python experiments/paper_study.py

Writes `docs/paper_study.md` and `docs/figures/study_*.png`.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

import jaxdeploy  # noqa: F401  (float64)
from jaxdeploy.analysis.deploy_array import PANELS, deploy_array_outputs
from jaxdeploy.analysis.spectra import amplitude_spectrum
from jaxdeploy.batch import simulate_batch
from jaxdeploy.io import atomic_write_bytes, atomic_write_npz, run_metadata
from jaxdeploy.scenes import DeployArray
from jaxdeploy.simulation import Trajectory

ROOT = Path(__file__).resolve().parents[1]
CACHE = ROOT / "results" / "paper_study"
DOC = ROOT / "docs" / "paper_study.md"
FIG = ROOT / "docs" / "figures"

UM, MM = 1e-6, 1e-3
T_END = 2.0
SAVE_RATE_HZ = 10_000
# name, Ra [m], c [m]
CASES = [
    ("Ra 0.8 µm, c 0.05 mm", 0.8 * UM, 0.05 * MM),
    ("Ra 1.6 µm, c 0.05 mm", 1.6 * UM, 0.05 * MM),
    ("Ra 3.2 µm, c 0.05 mm", 3.2 * UM, 0.05 * MM),
    ("Ra 1.6 µm, c 0.01 mm", 1.6 * UM, 0.01 * MM),
    ("Ra 1.6 µm, c 0.1 mm", 1.6 * UM, 0.1 * MM),
]
ROUGHNESS_STUDY = [0, 1, 2]  # Ra 0.8, 1.6, 3.2 at c 0.05 mm
CLEARANCE_STUDY = [3, 1, 4]  # c 0.01, 0.05, 0.1 at Ra 1.6 µm
# The solver docs/paper_study.md was generated with (pinned: deploy_array's default is now
# Tsit5, and a rerun must reproduce what the page says).
SOLVER = {"solver": "generalized_alpha"}
TOLERANCES = {"default": {**SOLVER}, "tight": {**SOLVER, "rtol": 1e-7, "atol": 1e-10}}


# --------------------------------------------------------------------------------------------
# Runs (cached)
# --------------------------------------------------------------------------------------------
def case_table():
    return {
        "panel1_ra": [c[1] for c in CASES],
        "panel2_ra": [c[1] for c in CASES],
        "panel1_clearance": [c[2] for c in CASES],
        "panel2_clearance": [c[2] for c in CASES],
    }


def run_batch(label: str, rerun: bool):
    """The five cases as one vmapped run at tolerance `label`; cached as npz."""
    path = CACHE / f"batch_{label}.npz"
    scene = DeployArray()
    if path.exists() and not rerun:
        data = np.load(path, allow_pickle=False)
        info = json.loads(str(data["info"]))
        return scene, data, info
    n_save = int(T_END * SAVE_RATE_HZ) + 1
    print(f"[{label}] simulating {len(CASES)} cases as one batch ...", flush=True)
    start = time.perf_counter()
    batch = simulate_batch(scene, case_table(), T_END, n_save=n_save, control=TOLERANCES[label])
    batch.trajectory.q.block_until_ready()
    wall = time.perf_counter() - start
    statuses = batch.statuses()
    stats = {k: np.asarray(v).tolist() for k, v in batch.trajectory.stats.items()}
    info = {
        "wall_time_s": wall,
        "statuses": statuses,
        "stats": stats,
        "control": scene.default_control.updated(TOLERANCES[label]).to_json(),
        "versions": run_metadata(),
        "varied": list(batch.varied),
    }
    print(f"[{label}] {wall:.1f} s (compile + run), statuses {statuses}", flush=True)
    memory_leaves = {
        f"memory_{i}_{k}": np.asarray(v)
        for i, m in enumerate(batch.trajectory.memory)
        for k, v in (m.items() if isinstance(m, dict) else [])
    }
    atomic_write_npz(
        str(path),
        ts=batch.trajectory.ts,
        q=batch.trajectory.q,
        v=batch.trajectory.v,
        qdd=batch.trajectory.qdd,
        lam=batch.trajectory.lam,
        result=np.asarray(batch.trajectory.result._value),
        info=json.dumps(info),
        **memory_leaves,
    )
    return scene, np.load(path, allow_pickle=False), info


def case_trajectory(data, mechanism, i) -> Trajectory:
    """Rebuild case `i`'s Trajectory from the cache (memory pytree by element)."""
    memory = []
    for index, element in enumerate(mechanism.elements):
        if element.has_memory:
            keys = sorted(k for k in data.files if k.startswith(f"memory_{index}_"))
            memory.append({k.split("_", 2)[2]: data[k][i] for k in keys})
        else:
            memory.append(None)
    return Trajectory(
        data["ts"][i],
        data["q"][i],
        data["v"][i],
        data["qdd"][i],
        data["lam"][i],
        tuple(memory),
        data["result"][i],
        {},
    )


# --------------------------------------------------------------------------------------------
# Metrics of one case
# --------------------------------------------------------------------------------------------
ENVELOPE_WINDOW_S = 0.02  # moving-RMS window for envelopes (two periods of 100 Hz)
LATE_WINDOW = (1.5, 2.0)  # "after stabilisation"
FLUTTER_WINDOW_S = 0.1  # "at the locking moment": the first 0.1 s after lock


def moving_rms(t, x, width=ENVELOPE_WINDOW_S):
    """RMS of x over a centred window of `width` seconds (uniform sampling)."""
    n = max(1, int(round(width / float(t[1] - t[0]))))
    kernel = np.ones(n) / n
    return np.sqrt(np.convolve(x**2, kernel, mode="same"))


def post_lock_oscillation(t, x, t_lock):
    """Post-lock part of `x` with its resting offset removed (mean over the late window):
    a journal that settles off-centre leaves a constant deviation that is not vibration."""
    post = t > t_lock
    late = (t >= LATE_WINDOW[0]) & (t <= LATE_WINDOW[1])
    return t[post], x[post] - x[late].mean()


def settling_time(t, x, t_lock, fraction=0.1):
    """Time from lock until the moving-RMS envelope of the post-lock oscillation stays below
    `fraction` of its maximum (nan if it never does within the run)."""
    tp, xp = post_lock_oscillation(t, x, t_lock)
    env = moving_rms(tp, xp)
    above = np.flatnonzero(env > fraction * env.max())
    if len(above) == 0 or above[-1] >= len(tp) - 1 - int(ENVELOPE_WINDOW_S / (tp[1] - tp[0])):
        return float("nan")
    return float(tp[above[-1]] - t_lock)


def spectrum_peak(t, x, f_min=5.0, f_max=2000.0):
    f, a = amplitude_spectrum(t, x)
    band = (f >= f_min) & (f <= f_max)
    k = np.argmax(a[band])
    return float(f[band][k]), float(a[band][k])


def case_metrics(o) -> dict:
    """The numbers behind the paper's claims, for one case (see the doc's metric list)."""
    t = o["t"]
    t_lock = o["lock_time"]
    deploy, locked = t <= t_lock, t > t_lock
    flutter = locked & (t <= t_lock + FLUTTER_WINDOW_S)
    late = (t >= LATE_WINDOW[0]) & (t <= LATE_WINDOW[1])
    dev = o["alpha"] - o["alpha_ideal"]
    m = {
        "lock_time": t_lock,
        "angle_dev_deploy": np.abs(dev[deploy]).max(),
        "angle_dev_locked": np.abs(dev[locked]).max(),
        "angle_settling": settling_time(t, dev, t_lock),
    }
    for panel in PANELS:
        for where in ("centre", "tip"):
            d = o[f"{panel}_{where}_deviation"]
            for k, axis in enumerate("xy"):
                key = f"{panel}_{where}_{axis}"
                m[f"{key}_deploy"] = np.abs(d[deploy, k]).max()
                m[f"{key}_flutter"] = np.abs(d[flutter, k]).max()
                m[f"{key}_late_rms"] = float(
                    np.sqrt(np.mean((d[late, k] - d[late, k].mean()) ** 2))
                )
                m[f"{key}_settling"] = settling_time(t, d[:, k], t_lock)
        acc = o[f"{panel}_acceleration"][:, 1]
        m[f"{panel}_freq_locked"], m[f"{panel}_amp_locked"] = spectrum_peak(t[locked], acc[locked])
        m[f"{panel}_freq_deploy"], m[f"{panel}_amp_deploy"] = spectrum_peak(t[deploy], acc[deploy])
        tp, ap = post_lock_oscillation(t, acc, t_lock)
        env = moving_rms(tp, ap)
        m[f"{panel}_acc_settling"] = settling_time(t, acc, t_lock)
        m[f"{panel}_acc_rms_first"] = float(env[: len(env) // 4].mean())
    forces = [np.asarray(h["normal_force"]) for h in o["joints"].values()]
    m["max_contact_force"] = max(float(f.max()) for f in forces)
    return {k: float(v) for k, v in m.items()}


def analyse(runs):
    """Outputs and metrics of every case at both tolerances."""
    results = {}
    for label, (scene, data, _info) in runs.items():
        results[label] = []
        for i, (_name, ra, c) in enumerate(CASES):
            params = scene.resolve_params(
                {
                    "panel1_ra": ra,
                    "panel2_ra": ra,
                    "panel1_clearance": c,
                    "panel2_clearance": c,
                }
            )
            mechanism = scene.build(params)
            trajectory = case_trajectory(data, mechanism, i)
            outputs = deploy_array_outputs(scene, params, mechanism, trajectory)
            results[label].append((outputs, case_metrics(outputs)))
    return results


# --------------------------------------------------------------------------------------------
# Claims of section 4 and their verdicts
# --------------------------------------------------------------------------------------------
class Evidence:
    """Metric values (the tight run) and their numerical uncertainty (|default − tight|)."""

    def __init__(self, results):
        self.results = results

    def value(self, metric, i):
        return self.results["tight"][i][1][metric]

    def uncertainty(self, metric, i):
        a = self.results["default"][i][1][metric]
        b = self.results["tight"][i][1][metric]
        u = abs(a - b)
        if "freq" in metric:  # a spectral peak is known to one frequency bin at best
            t = self.results["tight"][i][0]["t"]
            u = max(u, 1.0 / (t[-1] - self.value("lock_time", i)))
        return u if np.isfinite(u) else np.inf

    def compare(self, metric_a, i, metric_b, j):
        """'<', '>' or '≈' (difference within the summed numerical uncertainty)."""
        a, b = self.value(metric_a, i), self.value(metric_b, j)
        if not (np.isfinite(a) and np.isfinite(b)):
            return "?"
        u = self.uncertainty(metric_a, i) + self.uncertainty(metric_b, j)
        if a - b > u:
            return ">"
        if b - a > u:
            return "<"
        return "≈"

    def trend(self, metric, cases):
        """Comparisons between consecutive cases, e.g. ('<', '>') = rises then falls."""
        return tuple(
            self.compare(metric, a, metric, b) for a, b in zip(cases, cases[1:], strict=False)
        )

    def fmt(self, metric, cases, scale=1.0, unit="", digits=3):
        def one(i):
            value = self.value(metric, i)
            if not np.isfinite(value):
                return "not within the run"
            return f"{value * scale:.{digits}g}±{self.uncertainty(metric, i) * scale:.1g}"

        return ", ".join(one(i) for i in cases) + (f" {unit}" if unit else "")


def verdict_from(checks):
    """Combine per-series verdicts: all agree → agrees; any resolved disagreement and no
    agreement → disagrees; mixed → partly; nothing resolved → not resolved."""
    if all(c == "agrees" for c in checks):
        return "agrees"
    if all(c == "not resolved" for c in checks):
        return "not resolved"
    if "agrees" in checks:
        return "partly"
    return "disagrees"


def trend_verdict(trend, expected):
    if trend == expected:
        return "agrees"
    if "≈" in trend or "?" in trend:
        resolved = [(t, e) for t, e in zip(trend, expected, strict=True) if t not in "≈?"]
        if all(t == e for t, e in resolved) and resolved:
            return "not resolved"
        if not resolved:
            return "not resolved"
    return "disagrees"


def comparison_verdict(comparison, expected):
    """'agrees' if the resolved comparison is the expected one, 'not resolved' if within the
    error bars ('≈') or undefined ('?'), else 'disagrees'."""
    if comparison == expected:
        return "agrees"
    return "not resolved" if comparison in ("≈", "?") else "disagrees"


def spread_verdict(ev, metric, cases, limit):
    """'Similar across cases': max/min ratio of the values below `limit`."""
    vals = np.array([ev.value(metric, i) for i in cases])
    ratio = vals.max() / vals.min()
    return ratio, ("agrees" if ratio < limit else "disagrees")


MU_RAD = 1e6  # rad → µrad
UM_PER_M = 1e6


def claims(ev: Evidence):
    R, C = ROUGHNESS_STUDY, CLEARANCE_STUDY
    rows = []

    def add(cid, fig, text, ours, verdict):
        rows.append({"id": cid, "figure": fig, "claim": text, "ours": ours, "verdict": verdict})

    t = ev.trend("angle_dev_deploy", R)
    add(
        "R1",
        "9a",
        "Deployment-phase angle deviation first increases, then decreases with roughness.",
        f"max |α−α_ideal| = {ev.fmt('angle_dev_deploy', R, MU_RAD, 'µrad')}; trend {''.join(t)}",
        trend_verdict(t, ("<", ">")),
    )
    ratio, v = spread_verdict(ev, "angle_dev_locked", R, 1.5)
    add(
        "R2",
        "9a",
        "Locked-stage angle deviation range: no significant difference between roughnesses.",
        f"max |α−α_ideal| after lock = {ev.fmt('angle_dev_locked', R, MU_RAD, 'µrad')}; "
        f"max/min {ratio:.2f} (similar: < 1.5)",
        v,
    )
    t = ev.trend("angle_settling", R)
    add(
        "R3",
        "9b",
        "After locking, the angle deviation decays faster with increasing roughness.",
        f"10 % settling time = {ev.fmt('angle_settling', R, 1e3, 'ms')}; trend {''.join(t)}",
        trend_verdict(t, (">", ">")),
    )
    checks, texts = [], []
    for panel in PANELS:
        for axis in "xy":
            m = f"{panel}_centre_{axis}_deploy"
            t = ev.trend(m, R)
            checks.append(trend_verdict(t, (">", ">")))
            texts.append(f"{panel} {axis.upper()}: {ev.fmt(m, R, UM_PER_M)} µm ({''.join(t)})")
    add(
        "R4",
        "10–13",
        "Deployment stage: the smaller the roughness, the larger the panels' displacement "
        "deviation.",
        "; ".join(texts),
        verdict_from(checks),
    )
    checks, texts = [], []
    for panel in PANELS:
        for axis in "xy":
            m = f"{panel}_centre_{axis}_flutter"
            t = ev.trend(m, R)
            checks.append(trend_verdict(t, (">", ">")))
            texts.append(f"{panel} {axis.upper()}: {ev.fmt(m, R, UM_PER_M)} µm ({''.join(t)})")
    add(
        "R5",
        "10–13",
        "At the locking moment, the smaller the roughness, the larger the flutter amplitude.",
        "max |deviation| in the first 0.1 s after lock: " + "; ".join(texts),
        verdict_from(checks),
    )
    checks, texts = [], []
    for panel in PANELS:
        for axis in "xy":
            m = f"{panel}_centre_{axis}_late_rms"
            ratio, v = spread_verdict(ev, m, R, 2.0)
            checks.append(v)
            texts.append(f"{panel} {axis.upper()}: {ev.fmt(m, R, UM_PER_M)} µm (×{ratio:.1f})")
    add(
        "R6",
        "10–13",
        "Once stable, the flutter amplitudes of the different roughnesses are basically similar.",
        "RMS of the deviation (offset removed) over 1.5–2 s: "
        + "; ".join(texts)
        + " (similar: max/min < 2)",
        verdict_from(checks),
    )
    ratios = [
        ev.value("panel2_centre_x_deploy", i) / ev.value("panel1_centre_x_deploy", i) for i in R
    ]
    tip_ratios = [
        ev.value("panel2_tip_x_deploy", i) / ev.value("panel1_tip_x_deploy", i) for i in R
    ]
    add(
        "R7",
        "10a, 12a",
        "Deployment stage: panel 2's X displacement deviation is about twice panel 1's.",
        "panel 2 / panel 1 max |ΔX|, centres: "
        + ", ".join(f"{r:.2f}" for r in ratios)
        + "; tips: "
        + ", ".join(f"{r:.2f}" for r in tip_ratios)
        + " (about twice: 1.5–2.5)",
        verdict_from(["agrees" if 1.5 <= r <= 2.5 else "disagrees" for r in ratios]),
    )
    checks = [
        comparison_verdict(c, "<")
        for c in (ev.compare("panel2_centre_y_deploy", i, "panel1_centre_y_deploy", i) for i in R)
    ]
    add(
        "R8",
        "11a, 13a",
        "Deployment stage: panel 2's Y deviation is smaller than panel 1's.",
        f"max |ΔY| panel 1: {ev.fmt('panel1_centre_y_deploy', R, UM_PER_M)} µm; "
        f"panel 2: {ev.fmt('panel2_centre_y_deploy', R, UM_PER_M)} µm",
        verdict_from(checks),
    )
    checks = []
    for i in R:
        for c in (
            ev.compare("panel2_tip_x_settling", i, "panel1_tip_x_settling", i),
            ev.compare("panel2_tip_x_late_rms", i, "panel1_tip_x_late_rms", i),
        ):
            checks.append(comparison_verdict(c, "<"))
    add(
        "R9",
        "10b, 12b",
        "After locking, the X deviation of panel 2's end decays faster, and once stable is "
        "lower than panel 1's.",
        f"X settling of the tips, panel 1: {ev.fmt('panel1_tip_x_settling', R, 1e3)} ms, "
        f"panel 2: {ev.fmt('panel2_tip_x_settling', R, 1e3)} ms; late RMS panel 1: "
        f"{ev.fmt('panel1_tip_x_late_rms', R, UM_PER_M)} µm, panel 2: "
        f"{ev.fmt('panel2_tip_x_late_rms', R, UM_PER_M)} µm",
        verdict_from(checks),
    )
    checks = [
        comparison_verdict(c, ">")
        for c in (ev.compare("panel2_tip_y_late_rms", i, "panel1_tip_y_late_rms", i) for i in R)
    ]
    add(
        "R10",
        "11b, 13b",
        "Once stable, panel 2's Y deviation is larger than panel 1's.",
        f"late RMS of ΔY at the tips, panel 1: {ev.fmt('panel1_tip_y_late_rms', R, UM_PER_M)} µm;"
        f" panel 2: {ev.fmt('panel2_tip_y_late_rms', R, UM_PER_M)} µm",
        verdict_from(checks),
    )
    t = ev.trend("panel1_amp_locked", R)
    add(
        "R11",
        "14",
        "Panel 1's vibration amplitude first increases, then decreases with roughness "
        "(largest at Ra 1.6).",
        f"post-lock spectral peak of panel 1's Y acceleration: "
        f"{ev.fmt('panel1_amp_locked', R, 1, 'm/s²')}; trend {''.join(t)}",
        trend_verdict(t, ("<", ">")),
    )
    c1 = ev.compare("panel1_freq_locked", R[1], "panel1_freq_locked", R[0])
    c2 = ev.compare("panel1_freq_locked", R[1], "panel1_freq_locked", R[2])
    c3 = ev.compare("panel1_freq_locked", R[0], "panel1_freq_locked", R[2])
    checks = [comparison_verdict(c, want) for c, want in ((c1, ">"), (c2, ">"), (c3, "<"))]
    add(
        "R12",
        "14",
        "Panel 1's peak frequency is highest at Ra 1.6 and lowest at Ra 0.8.",
        f"panel 1 post-lock peak frequency: {ev.fmt('panel1_freq_locked', R, 1, 'Hz')}",
        verdict_from(checks),
    )
    freqs = [ev.value("panel2_freq_locked", i) for i in R]
    add(
        "R13",
        "15",
        "Panel 2 vibrates mainly between 90 and 100 Hz.",
        f"panel 2 post-lock peak frequency: {ev.fmt('panel2_freq_locked', R, 1, 'Hz')}",
        verdict_from(["agrees" if 90 <= f <= 100 else "disagrees" for f in freqs]),
    )
    lowest = [ev.compare("panel2_amp_locked", R[2], "panel2_amp_locked", i) for i in R[:2]]
    fastest = [ev.compare("panel2_acc_settling", R[2], "panel2_acc_settling", i) for i in R[:2]]
    checks = [comparison_verdict(c, "<") for c in lowest + fastest]
    add(
        "R14",
        "15",
        "Panel 2: Ra 3.2 gives the lowest vibration peak and the fastest attenuation.",
        f"panel 2 peak: {ev.fmt('panel2_amp_locked', R, 1, 'm/s²')}; 10 % settling of its "
        f"acceleration: {ev.fmt('panel2_acc_settling', R, 1e3, 'ms')}",
        verdict_from(checks),
    )
    t = ev.trend("angle_dev_deploy", C)
    add(
        "C1",
        "16a",
        "Deployment-phase angle deviation range decreases as the clearance increases.",
        f"max |α−α_ideal| (c = 0.01, 0.05, 0.1 mm): "
        f"{ev.fmt('angle_dev_deploy', C, MU_RAD, 'µrad')}; trend {''.join(t)}",
        trend_verdict(t, (">", ">")),
    )
    t = ev.trend("angle_settling", C)
    add(
        "C2",
        "16b",
        "After locking, the angle deviation attenuates faster with larger clearance.",
        f"10 % settling time: {ev.fmt('angle_settling', C, 1e3, 'ms')}; trend {''.join(t)}",
        trend_verdict(t, (">", ">")),
    )
    checks, texts = [], []
    for panel in PANELS:
        for axis in "xy":
            m = f"{panel}_centre_{axis}_deploy"
            t = ev.trend(m, C)
            checks.append(trend_verdict(t, ("<", "<")))
            texts.append(f"{panel} {axis.upper()}: {ev.fmt(m, C, UM_PER_M)} µm ({''.join(t)})")
    add(
        "C3",
        "17–20",
        "Deployment stage: X and Y displacement deviation ranges of both panels increase with "
        "clearance.",
        "; ".join(texts),
        verdict_from(checks),
    )
    checks, texts = [], []
    for panel in PANELS:
        growth = {
            axis: ev.value(f"{panel}_centre_{axis}_deploy", C[2])
            / ev.value(f"{panel}_centre_{axis}_deploy", C[0])
            for axis in "xy"
        }
        checks.append("agrees" if growth["y"] < growth["x"] else "disagrees")
        texts.append(f"{panel}: X ×{growth['x']:.2f}, Y ×{growth['y']:.2f}")
    add(
        "C4",
        "17–20",
        "The clearance influences the Y displacement deviation least.",
        "growth of max deviation from c = 0.01 to 0.1 mm, " + "; ".join(texts),
        verdict_from(checks),
    )
    t = ev.trend("panel1_amp_locked", C)
    add(
        "C5",
        "21",
        "Panel 1's spectral peak decreases as the clearance increases.",
        f"panel 1 post-lock peak: {ev.fmt('panel1_amp_locked', C, 1, 'm/s²')}; trend {''.join(t)}",
        trend_verdict(t, (">", ">")),
    )
    ta, tf = ev.trend("panel2_amp_locked", C), ev.trend("panel2_freq_locked", C)
    add(
        "C6",
        "22",
        "Panel 2's peak amplitude and peak frequency first increase, then decrease with clearance.",
        f"panel 2 peak: {ev.fmt('panel2_amp_locked', C, 1, 'm/s²')} ({''.join(ta)}); "
        f"frequency {ev.fmt('panel2_freq_locked', C, 1, 'Hz')} ({''.join(tf)})",
        verdict_from([trend_verdict(ta, ("<", ">")), trend_verdict(tf, ("<", ">"))]),
    )
    checks = []
    for i in C:
        for c, want in (
            (ev.compare("panel2_amp_locked", i, "panel1_amp_locked", i), ">"),
            (ev.compare("panel2_freq_locked", i, "panel1_freq_locked", i), "<"),
        ):
            checks.append(comparison_verdict(c, want))
    add(
        "C7",
        "21 vs 22",
        "Panel 2 vibrates with a larger amplitude but a lower peak frequency than panel 1.",
        f"peaks panel 1: {ev.fmt('panel1_amp_locked', C, 1, 'm/s²')}, panel 2: "
        f"{ev.fmt('panel2_amp_locked', C, 1, 'm/s²')}; frequencies panel 1: "
        f"{ev.fmt('panel1_freq_locked', C, 1, 'Hz')}, panel 2: "
        f"{ev.fmt('panel2_freq_locked', C, 1, 'Hz')}",
        verdict_from(checks),
    )
    return rows


# --------------------------------------------------------------------------------------------
# Figures
# --------------------------------------------------------------------------------------------
def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


STUDIES = {
    "roughness": (ROUGHNESS_STUDY, ["Ra 0.8 µm", "Ra 1.6 µm", "Ra 3.2 µm"], "c = 0.05 mm"),
    "clearance": (CLEARANCE_STUDY, ["c 0.01 mm", "c 0.05 mm", "c 0.1 mm"], "Ra = 1.6 µm"),
}
COLOURS = ["tab:blue", "tab:orange", "tab:green"]


def figure_angle(results, study):
    """Paper Figs 9 / 16: angle deviation, (a) unfolding, (b) after lock (with envelopes)."""
    plt = _plt()
    cases, labels, fixed = STUDIES[study]
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4))
    for colour, label, i in zip(COLOURS, labels, cases, strict=True):
        o = results["tight"][i][0]
        t, dev = o["t"], (o["alpha"] - o["alpha_ideal"]) * MU_RAD
        lock = o["lock_time"]
        ax1.plot(t[t <= lock], dev[t <= lock], lw=0.7, color=colour, label=label)
        ax2.plot(t[t > lock] - lock, dev[t > lock], lw=0.5, color=colour, label=label)
    ax1.set_title(f"(a) unfolding ({fixed})")
    ax1.set_xlabel("time [s]")
    ax2.set_title("(b) after lock")
    ax2.set_xlabel("time after lock [s]")
    for ax in (ax1, ax2):
        ax.set_ylabel("α − α_ideal [µrad]")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    path = FIG / f"study_{study}_angle_deviation.png"
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def figure_displacement(results, study):
    """Paper Figs 10–13 / 17–20: X and Y deviation of each panel's centre."""
    plt = _plt()
    cases, labels, fixed = STUDIES[study]
    fig, axes = plt.subplots(2, 2, figsize=(11, 6.5), sharex=True)
    for row, panel in enumerate(PANELS):
        for col, axis in enumerate("XY"):
            ax = axes[row, col]
            for colour, label, i in zip(COLOURS, labels, cases, strict=True):
                o = results["tight"][i][0]
                d = o[f"{panel}_centre_deviation"][:, col] * UM_PER_M
                ax.plot(o["t"], d, lw=0.5, color=colour, label=label)
            ax.axvline(results["tight"][cases[0]][0]["lock_time"], color="grey", ls=":", lw=1)
            ax.set_title(f"{panel} centre: {axis} deviation from ideal ({fixed})", fontsize=9)
            ax.set_ylabel("µm")
            ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=8)
    for ax in axes[-1]:
        ax.set_xlabel("time [s] (dotted: lock)")
    fig.tight_layout()
    path = FIG / f"study_{study}_displacement_deviation.png"
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def figure_spectra(results, study):
    """Paper Figs 14–15 / 21–22: amplitude spectra of the panels' Y acceleration."""
    plt = _plt()
    cases, labels, fixed = STUDIES[study]
    fig, axes = plt.subplots(2, 2, figsize=(11, 6.5))
    for row, panel in enumerate(PANELS):
        for col, phase in enumerate(("unfolding", "after lock")):
            ax = axes[row, col]
            for colour, label, i in zip(COLOURS, labels, cases, strict=True):
                o = results["tight"][i][0]
                t, acc = o["t"], o[f"{panel}_acceleration"][:, 1]
                mask = t <= o["lock_time"] if col == 0 else t > o["lock_time"]
                f, a = amplitude_spectrum(t[mask], acc[mask])
                ax.semilogy(f, a + 1e-9, lw=0.6, color=colour, label=label)
            ax.set_xlim(0, 700)
            ax.set_title(f"{panel}: Y acceleration spectrum, {phase} ({fixed})", fontsize=9)
            ax.set_ylabel("amplitude [m/s²]")
            ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=8)
    for ax in axes[-1]:
        ax.set_xlabel("frequency [Hz]")
    fig.tight_layout()
    path = FIG / f"study_{study}_spectra.png"
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def figure_envelopes(results, study):
    """Decay after lock: moving-RMS envelopes of the post-lock oscillations (log scale)."""
    plt = _plt()
    cases, labels, fixed = STUDIES[study]
    signals = [
        ("α − α_ideal [rad]", lambda o: o["alpha"] - o["alpha_ideal"]),
        ("panel 1 tip ΔX [m]", lambda o: o["panel1_tip_deviation"][:, 0]),
        ("panel 2 tip ΔX [m]", lambda o: o["panel2_tip_deviation"][:, 0]),
        ("panel 2 Y acceleration [m/s²]", lambda o: o["panel2_acceleration"][:, 1]),
    ]
    fig, axes = plt.subplots(2, 2, figsize=(11, 6.5), sharex=True)
    for ax, (name, signal) in zip(axes.flat, signals, strict=True):
        for colour, label, i in zip(COLOURS, labels, cases, strict=True):
            o = results["tight"][i][0]
            tp, xp = post_lock_oscillation(o["t"], signal(o), o["lock_time"])
            ax.semilogy(tp - o["lock_time"], moving_rms(tp, xp), lw=0.8, color=colour, label=label)
        ax.set_title(f"post-lock RMS envelope: {name} ({fixed})", fontsize=9)
        ax.grid(alpha=0.3, which="both")
    axes[0, 0].legend(fontsize=8)
    for ax in axes[-1]:
        ax.set_xlabel("time after lock [s]")
    fig.tight_layout()
    path = FIG / f"study_{study}_envelopes.png"
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


# --------------------------------------------------------------------------------------------
# The document
# --------------------------------------------------------------------------------------------
METRIC_ROWS = [
    ("lock time [s]", "lock_time", 1.0),
    ("max |α−α_ideal| unfolding [µrad]", "angle_dev_deploy", MU_RAD),
    ("max |α−α_ideal| after lock [µrad]", "angle_dev_locked", MU_RAD),
    ("α deviation 10 % settling [ms]", "angle_settling", 1e3),
    ("panel 1 centre max |ΔX| unfolding [µm]", "panel1_centre_x_deploy", UM_PER_M),
    ("panel 1 centre max |ΔY| unfolding [µm]", "panel1_centre_y_deploy", UM_PER_M),
    ("panel 2 centre max |ΔX| unfolding [µm]", "panel2_centre_x_deploy", UM_PER_M),
    ("panel 2 centre max |ΔY| unfolding [µm]", "panel2_centre_y_deploy", UM_PER_M),
    ("panel 1 post-lock peak frequency [Hz]", "panel1_freq_locked", 1.0),
    ("panel 2 post-lock peak frequency [Hz]", "panel2_freq_locked", 1.0),
    ("panel 1 post-lock spectral peak [m/s²]", "panel1_amp_locked", 1.0),
    ("panel 2 post-lock spectral peak [m/s²]", "panel2_amp_locked", 1.0),
    ("max contact force [N]", "max_contact_force", 1.0),
]


def _cell(text: str) -> str:
    """A markdown table cell: literal pipes escaped."""
    return text.replace("|", "\\|")


def write_report(runs) -> int:
    results = analyse(runs)
    ev = Evidence(results)
    rows = claims(ev)
    figures = []
    for study in STUDIES:
        figures += [
            figure_angle(results, study),
            figure_displacement(results, study),
            figure_spectra(results, study),
            figure_envelopes(results, study),
        ]
    infos = {label: info for label, (_s, _d, info) in runs.items()}
    lines = [
        "# The seed study's section 4, reproduced with our model",
        "",
        "<!-- generated by experiments/paper_study.py; do not edit by hand -->",
        "",
        "The paper (W24, section 4) simulates its deployable array for 2 s with roughness",
        "Ra ∈ {0.8, 1.6, 3.2} µm at clearance c = 0.05 mm, and c ∈ {0.01, 0.05, 0.1} mm at",
        "Ra = 1.6 µm, and draws conclusions from deviations against the ideal-joint mechanism,",
        "from displacement deviations of the panels and from acceleration spectra. We ran the",
        "same five cases on our reconstruction `deploy_array` (geometry and its reasons:",
        "[deploy_array_geometry.md](deploy_array_geometry.md); contact model:",
        "[contact.md](contact.md)) — both hinges J1 (panel 1) and J7 (panel 2) with the same",
        "Ra and c, rough Lankarani–Nikravesh law (c_e = 0.9), smooth Coulomb friction μ = 0.05.",
        "",
        "Regenerate with `.venv/bin/python experiments/paper_study.py` (add `--rerun` to",
        "re-simulate instead of using the cached batches in `results/paper_study/`).",
        "",
        "## How the runs were made",
        "",
        "* The five cases are **one** vmapped batch (`jaxdeploy.batch.simulate_batch`): one",
        "  compilation, the four varied parameters traced, everything else fixed at trace time.",
        "* Adaptive generalized-α (ρ∞ = 0.8); states saved at 10 kHz for the spectra (the paper's",
        "  0.01 s step could not resolve the 90–100 Hz it reports, nor a sub-millisecond impact).",
    ]
    for label, info in infos.items():
        ctl = info["control"]
        steps = info["stats"].get("num_accepted_steps")
        rejected = info["stats"].get("num_rejected_steps")
        lines.append(
            f"* `{label}` batch: rtol {ctl.get('rtol')}, atol {ctl.get('atol')}, "
            f"dt_max {ctl.get('dt_max')}: accepted steps per case {steps}, rejected {rejected}; "
            f"{info['wall_time_s']:.0f} s wall time for the whole batch (compile + run), "
            f"statuses {sorted(set(info['statuses']))}."
        )
    lines += [
        "* **Numerical uncertainty.** Every number below is from the tight batch, followed by",
        "  ± its change from the default-tolerance batch. Impacting trajectories amplify small",
        "  differences, so this change is the honest error bar. A comparison between two cases",
        "  counts only when the difference exceeds the sum of their error bars (≈ otherwise).",
        "* Spectra: Hann-windowed amplitude spectra of each panel centre's Y acceleration,",
        "  separately over the unfolding phase (0 → lock) and after lock (lock → 2 s).",
        "  Settling time: time after lock until the 20 ms moving RMS of the oscillation (its",
        "  resting offset over 1.5–2 s removed) stays below 10 % of its maximum.",
        "",
        "## Our numbers",
        "",
        "| quantity | " + " | ".join(c[0] for c in CASES) + " |",
        "|---|" + "---|" * len(CASES),
    ]
    for name, metric, scale in METRIC_ROWS:
        cells = [
            f"{ev.value(metric, i) * scale:.4g} ± {ev.uncertainty(metric, i) * scale:.1g}"
            for i in range(len(CASES))
        ]
        lines.append(f"| {_cell(name)} | " + " | ".join(cells) + " |")
    counts = {}
    for r in rows:
        counts[r["verdict"]] = counts.get(r["verdict"], 0) + 1
    lines += [
        "",
        "## Claim by claim",
        "",
        "Verdicts: **agrees**, **disagrees**, **partly** (some of the series the claim covers",
        "agree, others do not), **not resolved** (the effect is within our numerical error bar).",
        "Summary: " + ", ".join(f"{v} {k}" for k, v in sorted(counts.items())) + ".",
        "",
        "| # | paper fig. | claim (W24 §4) | ours | verdict |",
        "|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['id']} | {r['figure']} | {_cell(r['claim'])} | {_cell(r['ours'])} "
            f"| **{r['verdict']}** |"
        )
    lines += ["", "## Figures", ""]
    for path in figures:
        rel = os.path.relpath(path, DOC.parent)
        lines.append(f"![{path.stem}]({rel})")
        lines.append("")
    lines += discussion(ev, rows)
    atomic_write_bytes(str(DOC), ("\n".join(lines).rstrip() + "\n").encode())
    print(f"wrote {DOC} and {len(figures)} figures")
    return 0


# The verdicts the discussion below was written for. If a rerun (new model, new defaults)
# changes any of them, the document says so at the top of the discussion instead of
# silently keeping an explanation of results it no longer shows.
DISCUSSED_VERDICTS = {
    "R1": "disagrees", "R2": "agrees", "R3": "disagrees", "R4": "partly",
    "R5": "partly", "R6": "agrees", "R7": "disagrees", "R8": "agrees", "R9": "disagrees",
    "R10": "agrees", "R11": "disagrees", "R12": "not resolved", "R13": "disagrees",
    "R14": "disagrees", "C1": "disagrees", "C2": "agrees", "C3": "agrees", "C4": "partly",
    "C5": "agrees", "C6": "partly", "C7": "partly",
}  # fmt: skip

DISCUSSION = """\
## Why we agree or disagree

**Roughness is a weak lever in our model (R1, R3–R6, R11, R14).** Roughness enters our contact
law only through the GW-averaged elastic force (docs/contact.md): σ = 1.25 Ra is 1–4 µm,
against 50 µm of clearance, and it changes the force only within a few σ of nominal contact.
Impacts in the hinges penetrate about as deep, so the rough law softens each impact's onset
without changing much of what the impact does to the panels. The two tolerances now agree
closely enough during unfolding and at the lock to resolve the effects, and they are small:
over a fourfold range of Ra the unfolding deviations change by a few per cent up to about a
fifth, some series falling with roughness as the paper says (R4 partly), others not monotone;
the deviation just after the lock falls with roughness by about a per cent (R5 partly, the
paper's direction); the stable flutter does not differ beyond its scatter (R6). What the paper
reports as "first increases, then decreases" (R1, R11) does not appear: our three values are
monotone, or the other way round. The paper explains its roughness trends by friction growing
with roughness ("the increase in the initial friction force caused by the increase in
roughness") and by asperities "absorbing the collision energy". Those are couplings μ(Ra) and
c_e(Ra) that the paper does not state. Our model has them (`RoughnessCoupling`,
`RestitutionRoughnessCoupling` in jaxdeploy.contact), but the study keeps μ = 0.05 and c_e =
0.9 fixed, as the paper's text implies. Until measured couplings exist, our model predicts that
roughness alone is a weak design lever next to clearance. Where the paper reports a trend as
"first increases, then decreases", three cases cannot separate a real extremum from noise; our
error bars say when they cannot.

**Clearance matters, and mostly as the paper says (C2, C3, C5).** More play lets the panels
move further from the ideal path during unfolding (C3: every deviation grows with c). After
locking, the angle deviation dies out faster with larger clearance (C2), and panel 1's
post-lock spectral peak falls as c grows (C5). C1 disagrees: our unfolding angle deviation
*grows* with clearance. Most of it is a lag that builds up before lock (first figure), from
energy lost to hinge friction and impacts, and larger clearance means harder impacts. The
paper's explanation ("too small a clearance enhances the collision phenomenon") would need
smaller clearances to produce more impacts. Ours produce fewer and gentler ones (the maximum
contact force grows with c in the table).

**Geometry-dependent ratios (R7, C4, R8, R10) belong to our reconstruction.** The paper's
mechanism figure and parameter table are missing. Our rods and pivots are designed in
docs/deploy_array_geometry.md, so how a hinge's play maps to X and Y motion of each panel is
ours, not the paper's. Panel 2's X deviation is about four times panel 1's, not twice. The
qualitative Y statements (panel 2 smaller while unfolding, larger once locked) agree.

**After lock our hinges keep rattling (R9, R13, R14, C6, C7).** The latch holds the deployment
*angle*. Nothing holds the journals: in weightlessness, with c_e = 0.9 and no preload across
the hinge, the pins fly from wall to wall of their bearings. The panels' X and Y deviations
become a slow triangular wave whose amplitude is the clearance itself, and whose period grows
as each impact removes 1 − c_e² of the rattling energy. These deviations do not settle within
the 2 s (R9 has no settling time). The repeated impacts also make the post-lock acceleration
spectra broadband. Panel 1 still shows its latch mode near 85–95 Hz, whatever the roughness
(R12 not resolved): k_L was *chosen* so that the locked ideal-joint array vibrates at 95 Hz,
so this frequency is calibrated, not predicted. Panel 2 has no clean peak, so its
"90–100 Hz" (R13) and the peak trends built on it (R14, C7; C6 only in its amplitude) are not
reproduced. A real array would hold its pins with hinge preload, gravity in ground
tests, or friction-dominated, lower-restitution contact. Each of these is a scene option away
(a preload spring across a hinge, a lower c_e, μ(Ra) coupling), and each would be a different
prediction. We report the model as specified rather than tuning it until the spectra match.

**What the comparison says about the paper's numbers.** The paper integrates with a fixed
0.01 s step (its §4). That step cannot resolve a 90–100 Hz vibration (Nyquist 50 Hz) or a
hinge impact lasting less than a millisecond. Its spectra and impact-driven trends are
therefore unlikely to be converged. Ours carry error bars from two tolerances, and every
verdict above is conditional on them.
"""


def discussion(ev, rows):
    """Why we agree or disagree (text kept next to the numbers it interprets)."""
    changed = [
        f"{r['id']} (now {r['verdict']}, written for {DISCUSSED_VERDICTS.get(r['id'])})"
        for r in rows
        if DISCUSSED_VERDICTS.get(r["id"]) != r["verdict"]
    ]
    lines = DISCUSSION.splitlines()
    if changed:
        print("WARNING: verdicts changed since the discussion was written:", changed)
        lines[1:1] = [
            "",
            "> **Stale:** the discussion below was written for other verdicts of "
            + ", ".join(changed)
            + "; revise it.",
        ]
    return lines


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rerun", action="store_true", help="ignore cached batches")
    parser.add_argument("--runs-only", action="store_true", help="simulate, no analysis")
    args = parser.parse_args(argv)
    os.makedirs(CACHE, exist_ok=True)
    runs = {label: run_batch(label, args.rerun) for label in TOLERANCES}
    if args.runs_only:
        return 0
    return write_report(runs)


if __name__ == "__main__":
    sys.exit(main())
