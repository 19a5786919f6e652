"""deploy_array's post-lock spectral peak: which solver is right, and is the estimate well posed?
Writes docs/spectral_peak.md and docs/figures/spectral_peak.png.

    PYTHONPATH=. python experiments/spectral_peak.py [--doc-only]

The default run (2 s, the scene's parameters) with Tsit5 and generalized-α at their defaults
and at tighter settings — Tsit5 at rtol 1e-7 and 1e-8, Dopri8 at rtol 1e-9 and 1e-10,
generalized-α with ρ∞ = 1 (no numerical damping), at rtol 1e-7, and with fixed 5 µs steps and
ρ∞ = 1 — each saved at 20 kHz (40001 states; saving does not change the steps), and the
ideal-joint mechanism. From the saved states, per run and panel, the post-lock peak frequency
of the centre's Y acceleration by

* the estimate `jaxdeploy simulate` reported before (point samples of the saved acceleration,
  one Hann window over the whole post-lock record, largest bin), at the save rates 1 kHz (the
  CLI's default 2001 states over 2 s) and 20 kHz;
* the estimate it reports now (`analysis.spectra.peak_frequency`: Welch spectrum of the
  interval-mean acceleration from the saved velocities, 0.1 s segments), at 0.5, 1 and 20 kHz
  and with segments of 0.1–1.46 s;

how long the runs stay together (first time panel 1's Y velocity leaves the tightest run by
1 % of its range), and the ideal mechanism's peak against its latch mode. Runs are cached in
results/spectral_peak/ (`--doc-only` rewrites the page from them).
"""

from __future__ import annotations

import argparse
import json
import os
import time

import numpy as np

from jaxdeploy import pages
from jaxdeploy.analysis.deploy_array import SPECTRUM_SEGMENT, crossing_time
from jaxdeploy.analysis.spectra import (
    amplitude_spectrum,
    interval_mean_rate,
    peak_frequency,
    welch_psd,
)
from jaxdeploy.io import (
    atomic_write_bytes,
    atomic_write_json,
    atomic_write_npz,
    machine_description,
    run_metadata,
)
from jaxdeploy.scenes import DeployArray
from jaxdeploy.scenes.deploy_array import GEOMETRY, deployment_angle
from jaxdeploy.simulation import simulate
from jaxdeploy.solvers import GeneralizedAlpha

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DOC = os.path.join(ROOT, "docs", "spectral_peak.md")
FIGURE = os.path.join(ROOT, "docs", "figures", "spectral_peak.png")
CACHE = os.path.join(ROOT, "results", "spectral_peak")
N_SAVE = 40001  # 20 kHz over 2 s; every 20th state is the CLI's default 2001-state grid
STRIDES = {"0.5 kHz": 40, "1 kHz": 20, "20 kHz": 1}
SEGMENTS = (0.05, 0.1, 0.2, 0.4, None)  # None: the whole post-lock record (one segment)
PANELS = ("panel1", "panel2")
DEFAULT = {"rtol": 1e-6, "atol": 1e-9, "dt_max": 5e-4}
# (key, label, control). The first two are the scene's defaults with each solver; "dopri8_10"
# is the tightest run, the one the others' divergence is measured against.
RUNS = (
    ("tsit5", "Tsit5, rtol 1e-6 (default)", {**DEFAULT, "solver": "tsit5"}),
    ("ga", "generalized-α ρ∞ 0.8, rtol 1e-6 (default)", {**DEFAULT, "solver": GeneralizedAlpha()}),
    ("tsit5_7", "Tsit5, rtol 1e-7", {**DEFAULT, "rtol": 1e-7, "atol": 1e-10, "solver": "tsit5"}),
    ("tsit5_8", "Tsit5, rtol 1e-8", {**DEFAULT, "rtol": 1e-8, "atol": 1e-11, "solver": "tsit5"}),
    ("dopri8_9", "Dopri8, rtol 1e-9", {**DEFAULT, "rtol": 1e-9, "atol": 1e-12, "solver": "dopri8"}),
    (
        "dopri8_10",
        "Dopri8, rtol 1e-10",
        {**DEFAULT, "rtol": 1e-10, "atol": 1e-13, "solver": "dopri8"},
    ),
    (
        "ga_rho1",
        "generalized-α ρ∞ 1, rtol 1e-6",
        # max_steps: the run is 90k steps with ρ∞ = 0.8; a run stuck at tiny steps fails early
        {**DEFAULT, "solver": GeneralizedAlpha(rho_inf=1.0), "max_steps": 400_000},
    ),
    (
        "ga_7",
        "generalized-α ρ∞ 0.8, rtol 1e-7",
        {**DEFAULT, "rtol": 1e-7, "atol": 1e-10, "solver": GeneralizedAlpha()},
    ),
    (
        "ga_fixed",
        "generalized-α ρ∞ 1, fixed 5 µs steps",
        {"dt": 5e-6, "solver": GeneralizedAlpha(rho_inf=1.0), "max_steps": 400_001},
    ),
)
REFERENCE = "dopri8_10"


# What moves the numbers: deploy_array's runs under both solvers and the spectral estimate.
MEASURES = [
    "experiments/spectral_peak.py",
    "jaxdeploy/analysis/deploy_array.py",
    "jaxdeploy/analysis/spectra.py",
    "jaxdeploy/contact",
    "jaxdeploy/mechanism",
    "jaxdeploy/scenes/_contact.py",
    "jaxdeploy/scenes/base.py",
    "jaxdeploy/scenes/data",
    "jaxdeploy/scenes/deploy_array.py",
    "jaxdeploy/simulation.py",
    "jaxdeploy/solvers",
]


def run_all(commit, rerun=False):
    """Every run of RUNS and the ideal mechanism, cached as npz (panel columns only) with the
    commit that ran it; the commits of runs kept from the cache (`rerun` redoes them)."""
    os.makedirs(CACHE, exist_ok=True)
    kept = set()
    for key, label, control in (*RUNS, ("ideal", "ideal joints, Tsit5", None)):
        path = os.path.join(CACHE, f"{key}.npz")
        if os.path.exists(path) and not rerun:
            with np.load(path) as cached:
                kept.add(str(cached["commit"]) if "commit" in cached.files else "unknown")
            continue
        scene = DeployArray(ideal=key == "ideal")
        params = scene.resolve_params()
        mech = scene.build(params)
        init = scene.initial_state(params, mech)
        control = control or {**scene.default_control}
        start = time.perf_counter()
        tr = simulate(mech, init, scene.default_t_end, n_save=N_SAVE, **control)
        tr.q.block_until_ready()
        wall = time.perf_counter() - start
        columns = [3 * mech.body_index(p) + 1 for p in PANELS]  # centre Y of each panel
        atomic_write_npz(
            path,
            t=np.asarray(tr.ts),
            alpha=np.asarray(deployment_angle(tr.q)),
            v=np.asarray(tr.v)[:, columns],
            qdd=np.asarray(tr.qdd)[:, columns],
            steps=int(tr.stats["num_accepted_steps"]),
            wall=wall,
            status=tr.status(),
            commit=commit,
        )
        print(f"{label}: {tr.status()}, {int(tr.stats['num_accepted_steps'])} steps", flush=True)
    return kept - {commit}


def load(key):
    with np.load(os.path.join(CACHE, f"{key}.npz")) as d:
        return {k: d[k] for k in d.files}


def before_estimate(t, acc, t_lock):
    """What `jaxdeploy simulate` reported before: point samples after the lock, mean
    removed, one Hann window over the whole record, the largest bin ≥ 1 Hz."""
    after = t > t_lock
    f, amp = amplitude_spectrum(t[after], acc[after])
    keep = f >= 1.0
    return float(f[keep][np.argmax(amp[keep])])


def after_estimate(t, vel, t_lock, segment=SPECTRUM_SEGMENT):
    """What it reports now (analysis/deploy_array.py): Welch peak of the interval-mean
    acceleration over the intervals that begin at or after the lock."""
    starts, acc = interval_mean_rate(t, vel)
    after = starts >= t_lock
    seg = segment if segment is not None else starts[after][-1] - starts[after][0] + 1.0
    return peak_frequency(starts[after], acc[after], segment=seg)


def algorithmic_damping(rho_inf, omega_h):
    """Damping ratio ξ = −ln|λ| / arg λ of generalized-α on ẍ = −ω²x at ωh (Chung & Hulbert
    1993, J. Appl. Mech. 60, 371–375): with the coefficients α_m, α_f, β, γ of ρ∞, one step
    maps (x, v, a) by
    x₁ = x₀ + h v₀ + h² ((½ − β) a₀ + β a₁),  v₁ = v₀ + h ((1 − γ) a₀ + γ a₁),
    (1 − α_m) a₁ + α_m a₀ = −ω² ((1 − α_f) x₁ + α_f x₀);  λ its complex eigenvalue (h = 1)."""
    from jaxdeploy.solvers import chung_hulbert

    cf = chung_hulbert(rho_inf)
    w2 = omega_h**2
    lhs = np.array(
        [[1, 0, -cf.beta], [0, 1, -cf.gamma], [(1 - cf.alpha_f) * w2, 0, 1 - cf.alpha_m]]
    )
    rhs = np.array(
        [[1, 1, 0.5 - cf.beta], [0, 1, 1 - cf.gamma], [-cf.alpha_f * w2, 0, -cf.alpha_m]]
    )
    eig = np.linalg.eigvals(np.linalg.solve(lhs, rhs))
    lam = eig[np.argmax(np.abs(eig.imag))]
    return float(-np.log(abs(lam)) / abs(np.angle(lam)))


def measure():
    out = {"runs": {}, "machine": machine_description(), "versions": run_metadata()}
    ref = load(REFERENCE)
    for key, label, _ in (*RUNS, ("ideal", "ideal joints, Tsit5 (default control)", None)):
        d = load(key)
        t = d["t"]
        # the summary's lock time: from the run's own saved α at the CLI's default grid
        t_lock = crossing_time(t[::20], d["alpha"][::20], GEOMETRY["latch"]["engage_alpha"])
        rec = {
            "label": label,
            "steps": int(d["steps"]),
            "wall_s": float(d["wall"]),
            "status": str(d["status"]),
            "lock_time": t_lock,
        }
        control = {k: c for k, _, c in RUNS}.get(key, {})
        if "max_steps" in control:
            rec["steps_cap"] = control["max_steps"]
        if rec["status"] != "ok":  # a failed run has no post-lock record to estimate from
            out["runs"][key] = rec
            continue
        for i, panel in enumerate(PANELS):
            vel, acc = d["v"][:, i], d["qdd"][:, i]
            rec[panel] = {
                "before": {
                    r: before_estimate(t[::s], acc[::s], t_lock) for r, s in STRIDES.items()
                },
                "after": {r: after_estimate(t[::s], vel[::s], t_lock) for r, s in STRIDES.items()},
                "segments": {
                    str(seg): after_estimate(t[::20], vel[::20], t_lock, seg) for seg in SEGMENTS
                },
            }
        if key != "ideal":
            dv = np.abs(d["v"][:, 0] - ref["v"][:, 0])
            scale = np.ptp(ref["v"][:, 0])
            apart = np.flatnonzero(dv > 0.01 * scale)
            rec["apart_from_reference_s"] = float(t[apart[0]]) if len(apart) else None
        out["runs"][key] = rec
    mean_step = 2.0 / out["runs"]["ga"]["steps"]
    omega = 2 * np.pi * 200.0
    out["algorithmic_damping"] = {
        "mean_step_s": mean_step,
        "mean_step": algorithmic_damping(0.8, omega * mean_step),
        "dt_max": algorithmic_damping(0.8, omega * DEFAULT["dt_max"]),
    }
    sweep = GEOMETRY["reference_sweep"]
    inertia = float(np.interp(np.pi / 2, sweep["alpha"], sweep["generalized_inertia"]))
    stiffness = GEOMETRY["latch"]["k_latch"] + GEOMETRY["coil_spring"]["k"]
    zeta = GEOMETRY["latch"]["c_latch"] / (2 * np.sqrt(stiffness * inertia))
    out["latch_mode"] = {
        "inertia_kg_m2": inertia,
        "zeta": zeta,
        "f_damped_hz": float(np.sqrt(stiffness / inertia) * np.sqrt(1 - zeta**2) / (2 * np.pi)),
        "half_power_bandwidth_hz": float(2 * zeta * np.sqrt(stiffness / inertia) / (2 * np.pi)),
    }
    return out


def figure(result):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from jaxdeploy.io import atomic_savefig

    fig, axes = plt.subplots(4, 1, figsize=(8, 12))
    for key, _, _ in RUNS:
        if result["runs"][key]["status"] != "ok":
            continue
        d = load(key)
        t, t_lock = d["t"][::20], result["runs"][key]["lock_time"]
        for i, ax in enumerate(axes[:2]):
            starts, acc = interval_mean_rate(t, d["v"][::20, i])
            after = starts >= t_lock
            f, psd = welch_psd(starts[after], acc[after], SPECTRUM_SEGMENT)
            ax.semilogy(f, psd, lw=0.7, label=result["runs"][key]["label"])
        if key in ("tsit5", "ga", REFERENCE):
            after = t > t_lock
            f, amp = amplitude_spectrum(t[after], d["qdd"][::20, 0][after])
            axes[2].semilogy(f, amp, lw=0.6, label=result["runs"][key]["label"])
            starts, acc = interval_mean_rate(d["t"], d["v"][:, 0])
            axes[3].plot(starts, acc, lw=0.5, label=result["runs"][key]["label"])
    for i, ax in enumerate(axes[:2]):
        ax.set_title(
            f"panel {i + 1}: Welch spectrum ({SPECTRUM_SEGMENT:g} s segments) of the "
            "interval-mean Y acceleration, 1 kHz saves (now)",
            fontsize=9,
        )
        ax.set_ylabel("(m/s²)²/Hz")
    axes[0].legend(fontsize=6)
    axes[2].set_title(
        "panel 1: before — Hann amplitude spectrum of the point-sampled acceleration, 1 kHz",
        fontsize=9,
    )
    axes[2].set_ylabel("m/s²")
    axes[2].legend(fontsize=7)
    for ax in axes[:3]:
        ax.set_xlim(0, 500)
        ax.grid(alpha=0.3)
    axes[2].set_xlabel("frequency [Hz]")
    axes[3].set_xlim(0.53, 0.75)
    axes[3].set_title("panel 1: interval-mean Y acceleration, 20 kHz saves", fontsize=9)
    axes[3].set_ylabel("m/s²")
    axes[3].set_xlabel("time [s]")
    axes[3].legend(fontsize=7)
    axes[3].grid(alpha=0.3)
    fig.tight_layout()
    atomic_savefig(fig, FIGURE, dpi=110)
    plt.close(fig)


def _spread(values):
    return max(values) - min(values)


def write_doc(result):
    runs = result["runs"]
    keys = [k for k, _, _ in RUNS if runs[k]["status"] == "ok"]
    failed = [k for k, _, _ in RUNS if runs[k]["status"] != "ok"]
    n_ok = len(keys)
    failed_text = "".join(
        f"\n* **{runs[k]['label']} failed**: {runs[k]['status']} ({runs[k]['steps']} steps"
        + (
            f"; the cap max_steps = {runs[k]['steps_cap']} is "
            f"{runs[k]['steps_cap'] / runs['ga']['steps']:.1f}× the steps of the whole "
            "ρ∞ = 0.8 run"
            if "max_steps" in runs[k]["status"] and "steps_cap" in runs[k]
            else ""
        )
        + ")."
        for k in failed
    )
    if {"ga_rho1", "ga_fixed"} <= set(failed):
        failed_text += (
            "\n  Without numerical damping (ρ∞ = 1) generalized-α does not get past the first "
            "impacts after the lock, adaptive or with fixed steps; it is meant to be used with "
            "ρ∞ < 1, which damps the high-frequency response (Arnold & Brüls 2007). So the "
            "ρ∞ → 1 limit is not a reference here; the tighter-tolerance generalized-α run is."
        )
    machine = result["machine"]
    where = f"{machine.get('Model name', machine['platform'])}, {machine.get('CPU(s)', '?')} CPUs"
    res_hz = 1.0 / SPECTRUM_SEGMENT

    def table(panel):
        head = (
            "| run | steps | before, 1 kHz | before, 20 kHz | now, 0.5 kHz | now, 1 kHz "
            "| now, 20 kHz |\n|---|---|---|---|---|---|---|"
        )
        lines = []
        for k in keys:
            r, p = runs[k], runs[k][panel]
            lines.append(
                f"| {r['label']} | {r['steps']} | {p['before']['1 kHz']:.1f} "
                f"| {p['before']['20 kHz']:.1f} | {p['after']['0.5 kHz']:.1f} "
                f"| {p['after']['1 kHz']:.1f} | {p['after']['20 kHz']:.1f} |"
            )
        spreads = [
            _spread([runs[k][panel][kind][rate] for k in keys])
            for kind, rate in (
                ("before", "1 kHz"),
                ("before", "20 kHz"),
                ("after", "0.5 kHz"),
                ("after", "1 kHz"),
                ("after", "20 kHz"),
            )
        ]
        for k in failed:
            lines.append(f"| {runs[k]['label']} | {runs[k]['steps']} | failed | | | | |")
        lines.append(
            "| **spread (max − min)** | | " + " | ".join(f"**{s:.1f}**" for s in spreads) + " |"
        )
        return head + "\n" + "\n".join(lines), spreads

    t1, s1 = table("panel1")
    t2, s2 = table("panel2")
    seg_head = (
        "| segment [s] | resolution [Hz] | panel 1: range over the runs [Hz] "
        "| panel 2: range [Hz] |\n|---|---|---|---|"
    )
    seg_lines = []
    for seg in SEGMENTS:
        cells = []
        for panel in PANELS:
            vals = [runs[k][panel]["segments"][str(seg)] for k in keys]
            cells.append(f"{min(vals):.1f}–{max(vals):.1f} (spread {_spread(vals):.1f})")
        post = runs["tsit5"]["lock_time"]
        length = seg if seg is not None else 2.0 - post
        name = f"{seg:g}" if seg is not None else f"whole record ({length:.2f})"
        seg_lines.append(f"| {name} | {1 / length:.1f} | " + " | ".join(cells) + " |")
    apart = [
        runs[k]["apart_from_reference_s"]
        for k in keys
        if k != REFERENCE and runs[k]["apart_from_reference_s"] is not None
    ]
    apart_text = (
        f"between {min(apart):.3f} and {max(apart):.3f} s (Dopri8 at rtol 1e-9: "
        f"{runs['dopri8_9']['apart_from_reference_s']:.3f} s; the lock is at "
        f"{runs[REFERENCE]['lock_time']:.3f} s)"
    )
    damping = result["algorithmic_damping"]

    def old(run_keys):
        return ", ".join(
            f"{runs[k]['panel1']['before']['1 kHz']:.0f}" if k in keys else "failed"
            for k in run_keys
        )

    old_tsit5, old_dopri = old(("tsit5", "tsit5_7", "tsit5_8")), old(("dopri8_9", "dopri8_10"))
    lm = result["latch_mode"]
    ideal = runs["ideal"]
    gen, ts5 = runs["ga"]["panel1"], runs["tsit5"]["panel1"]
    gen_2, ts5_2 = runs["ga"]["panel2"], runs["tsit5"]["panel2"]
    # the old estimate on 20 kHz point samples, without the runs where it is far off
    # (more than 100 Hz from the median over the runs)
    at_20 = {k: runs[k]["panel1"]["before"]["20 kHz"] for k in keys}
    median_20 = float(np.median(list(at_20.values())))
    outliers_20 = {k: v for k, v in at_20.items() if abs(v - median_20) > 100.0}
    spread_20 = _spread([v for k, v in at_20.items() if k not in outliers_20])
    if spread_20 < 0.5 * s1[0]:
        samples_text = (
            "the old estimate on point samples at 20 kHz already scatters less (spread "
            f"{spread_20:.0f} Hz for panel 1 against {s1[0]:.0f} Hz at 1 kHz"
            + (
                ", leaving out "
                + ", ".join(f"{runs[k]['label']} at {v:.0f} Hz" for k, v in outliers_20.items())
                if outliers_20
                else ""
            )
            + "; the rest being cause 2): what moved it was the sampling rate, not the "
            "interpolant between steps."
        )
    else:
        samples_text = (
            f"the old estimate on point samples at 20 kHz scatters by {spread_20:.0f} Hz for "
            f"panel 1 (at 1 kHz: {s1[0]:.0f} Hz)."
        )
    if outliers_20:
        samples_text += (
            " At 20 kHz the point-sampled acceleration of "
            + ", ".join(f"{runs[k]['label']} peaks at {v:.0f} Hz" for k, v in outliers_20.items())
            + ", far from every other run (its velocities give the same peak as the others; "
            "not investigated further)."
        )
    now = {p: [runs[k][p]["after"]["1 kHz"] for k in keys] for p in PANELS}
    rate_spread = max(
        _spread([runs[k][p]["after"][r] for r in STRIDES]) for k in keys for p in PANELS
    )
    text = f"""# deploy_array: one scene, two solvers, one spectral peak (generated)

*Runs cached in results/spectral_peak/ (`--rerun` redoes them). {where}. Issue 19 item 7.*

`jaxdeploy simulate deploy_array` reports `panel{{1,2}}_peak_freq_hz`, the post-lock spectral
peak of each panel centre's Y acceleration. With the scene's default step control the
estimate it reported before read **{ts5["before"]["1 kHz"]:.1f} Hz with Tsit5 and
{gen["before"]["1 kHz"]:.1f} Hz with generalized-α** for panel 1, and
**{ts5_2["before"]["1 kHz"]:.1f} and {gen_2["before"]["1 kHz"]:.1f} Hz** for panel 2; over
the runs below it scatters by {s1[0]:.0f} Hz (panel 1) and {s2[0]:.0f} Hz (panel 2). Neither
solver was wrong: the estimate was not well posed.

## Which is right

Every run below is the default scene over 2 s, saved at 20 kHz (saving does not change the
steps; every 20th state is the CLI's default grid of 2001). "Before" is the estimate reported
until now (point samples of the saved acceleration, one Hann window over the whole post-lock
record, largest bin); "now" is the one reported from this commit on (below). Peaks in Hz.

**Panel 1**

{t1}

**Panel 2**

{t2}

* **The old estimate scatters over the reference runs themselves**: panel 1 reads
  {old_tsit5} Hz with Tsit5 at rtol 1e-6, 1e-7, 1e-8, {old_dopri} Hz with Dopri8 at
  rtol 1e-9, 1e-10, and its spread over these runs is {s1[0]:.0f} Hz (panel 1) and
  {s2[0]:.0f} Hz (panel 2). No tolerance and no solver setting makes it converge.{failed_text}
* **Not generalized-α's numerical damping**: at rtol 1e-7 (more than twice the steps, so less
  numerical damping) it lands in the same scatter as at its default. Its algorithmic damping
  ratio at 200 Hz
  (Chung & Hulbert 1993 recurrences for ẍ = −ω²x, ρ∞ = 0.8) is {damping["mean_step"]:.1e} at
  the default run's mean step ({damping["mean_step_s"] * 1e6:.0f} µs) and
  {damping["dt_max"]:.1e} even at the largest step allowed (dt_max = 0.5 ms), against the
  latch's physical ζ = {lm["zeta"]:.3f}.
* **Not the interpolated saved accelerations**: the estimate below reads no saved
  acceleration at all (only velocities) and agrees across all runs; {samples_text}
* **The causes** are the estimate's: (1) **aliasing** — after the lock the panel acceleration
  is a train of impacts lasting microseconds, flat in frequency far above 10 kHz; point
  samples at 1 kHz fold all of it onto 0–500 Hz (the third plot below is flat to the Nyquist
  frequency; the fourth shows the impacts), and whether a sample falls inside an impact
  decides the spectrum; (2) **a
  resolution finer than the signal supports** — one window over the 1.46 s record resolves
  ~1 Hz, but the ringing lasts ~0.1 s and its resonance is {lm["half_power_bandwidth_hz"]:.1f}
  Hz wide (latch damping ratio ζ = {lm["zeta"]:.3f}), so the largest bin is one of many ripples
  made by the interference of individual rattle impacts; (3) those impacts are **chaotic**:
  the runs leave the tightest one (by 1 % of panel 1's velocity range) {apart_text}. Any
  quantity that depends on the individual impacts after ~0.6 s has no
  converged reference at any tolerance.
* **The right answer** is the resonance every run shows once the estimate is well posed:
  panel 1 **{min(now["panel1"]):.1f}–{max(now["panel1"]):.1f} Hz**
  over all {n_ok} successful runs, the latch mode (ideal joints: {lm["f_damped_hz"]:.1f} Hz from
  f_d = √((k_L + k)/I(90°)) √(1 − ζ²)/2π with I(90°) = {lm["inertia_kg_m2"]:.3f} kg m² from
  the design study; the ideal run's estimate {ideal["panel1"]["after"]["1 kHz"]:.1f} Hz)
  lowered a little by the hinges' clearance; panel 2
  **{min(now["panel2"]):.1f}–{max(now["panel2"]):.1f} Hz**.
  Both solvers at their defaults were equally right about the physics; the disagreement was
  the estimate's. (The issue's 85 Hz vs ≈ 200 Hz was measured on an earlier model: with the
  running-max impact rule and before the preloaded latch.)

## The estimate now (`jaxdeploy/analysis/spectra.py`)

1. **The interval-mean acceleration** (v(t_(k+1)) − v(t_k))/Δt from the saved velocities
   instead of point samples of the acceleration: the mean over each save interval, what an
   integrating sensor reports. Every impulse between samples is counted once, exactly, and the
   averaging is a low-pass filter (gain |sinc(f/f_s)|) applied before sampling. Its spread over
   the save rates 0.5, 1 and 20 kHz is at most
   {rate_spread:.1f} Hz per run.
2. **Welch's averaged periodogram** (Welch 1967) with {SPECTRUM_SEGMENT:g} s Hann segments, half
   overlapping, mean removed per segment: resolution {res_hz:g} Hz — about the latch mode's
   {lm["half_power_bandwidth_hz"]:.1f} Hz bandwidth, so the resonance is one peak, and much
   coarser than the chaotic ripple, which the average over the segments smooths out.
   The segment's effect (1 kHz saves, all {n_ok} successful runs):

{seg_head}
{chr(10).join(seg_lines)}

   The longer the segment, the more the estimate follows the chaotic details and the wider
   it scatters; panel 2's spectrum also has a second peak near twice the frequency (the
   figure's middle plot), and with long segments the largest peak can switch between runs.
   With {SPECTRUM_SEGMENT:g} s the scatter is a small fraction of the resolution. The first
   segment's taper de-weights the first tens of ms after the lock, where the panel's arrest
   (from ~1 m/s to rest) dominates the acceleration rather than the ringing.
3. The maximum bin refined by a parabola through the log power at it and its neighbours.

Over the {n_ok} successful runs the spread is now {s1[3]:.1f} Hz (panel 1) and {s2[3]:.1f} Hz
(panel 2) at the default save rate, within the {res_hz:g} Hz resolution, where it was
{s1[0]:.0f} and {s2[0]:.0f} Hz. Tests: `tests/test_spectra.py` (a tone between bins, Parseval, and a
resonance under impacts that point samples alias), `tests/test_deploy_array.py`
(the ideal mechanism's peak is its latch mode; slow: Tsit5 and generalized-α at the defaults
agree within the resolution).

![spectra](figures/spectral_peak.png)
"""
    atomic_write_bytes(DOC, pages.whole_page(text, result["provenance"]).encode())
    print(f"wrote {DOC}")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--doc-only", action="store_true", help="rewrite the page from the cache")
    ap.add_argument("--rerun", action="store_true", help="redo the runs kept in the cache")
    args = ap.parse_args(argv)
    result_path = os.path.join(CACHE, "result.json")
    if args.doc_only:
        with open(result_path) as fh:
            result = json.load(fh)
        pages.stored(result, result_path)  # refuses a result without provenance
    else:
        record = pages.start(MEASURES, "python experiments/spectral_peak.py --rerun")
        kept = run_all(record["commit"], rerun=args.rerun)
        if kept:  # runs of other commits: the freshness test checks them too
            record["runs_at"] = sorted(kept)
        result = measure()
        result["provenance"] = pages.finish(record)
        atomic_write_json(result_path, result)
    figure(result)
    write_doc(result)


if __name__ == "__main__":
    main()
