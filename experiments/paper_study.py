"""The roughness/clearance study of the seed paper's section 4 (W24), claim by claim, with our
deploy_array model and its roughness variants.

Cases (both hinges alike, as in the paper): Ra ∈ {0.8, 1.6, 3.2} µm at c = 0.05 mm and
c ∈ {0.01, 0.05, 0.1} mm at Ra = 1.6 µm, each variant one vmapped batch, 1 s (the lock is at
0.54 s), saved at 10 kHz. Variants: the default reconstruction (preloaded latch, onset impact
rule, μ and c_e independent of Ra); `ploughing` (μ(Ra), contact.PloughingFriction); and
`restitution p` (the free coupling c_e(Ra) = c_e^((Ra/1.6 µm)^p); p = 3 on the roughness cases
only, for the region of p where claims hold). The default variant is rerun at a tenfold
tighter tolerance; the change of each number is its numerical uncertainty, which the variants
borrow (CPU budget). Then the sensitivities: forward-mode derivatives (`jax.jacfwd`) of six
headline outputs against central differences.

Run from the repository root (nice'd; runs cached in results/paper_study/)::

    PYTHONPATH=. nice -n 10 .venv/bin/python experiments/paper_study.py [--rerun]

Writes docs/paper_study.md and docs/figures/study_*.png.
"""

from __future__ import annotations

import argparse
import json
import os
import pickle
import time
from pathlib import Path

import diffrax as dfx
import jax
import jax.numpy as jnp
import numpy as np

import jaxdeploy  # noqa: F401  (float64)
from jaxdeploy import objectives as ob
from jaxdeploy.analysis import paper_claims as pc
from jaxdeploy.analysis.deploy_array import deploy_array_outputs
from jaxdeploy.analysis.spectra import welch_psd
from jaxdeploy.batch import reference_run, run_scene, simulate_batch
from jaxdeploy.io import atomic_savefig, atomic_write_bytes, code_revision, machine_description
from jaxdeploy.scenes import DeployArray
from jaxdeploy.scenes.deploy_array import GEOMETRY

ROOT = Path(__file__).resolve().parents[1]
CACHE, DOC, FIG = (
    ROOT / "results" / "paper_study",
    ROOT / "docs" / "paper_study.md",
    ROOT / "docs" / "figures",
)
UM, MM = 1e-6, 1e-3
T_END, SAVE_RATE_HZ = 1.0, 10_000
CASES = [
    (0.8 * UM, 0.05 * MM),
    (1.6 * UM, 0.05 * MM),
    (3.2 * UM, 0.05 * MM),
    (1.6 * UM, 0.01 * MM),
    (1.6 * UM, 0.1 * MM),
]  # (Ra, c)
CASE_NAMES = [f"Ra {ra / UM:g} µm, c {c / MM:g} mm" for ra, c in CASES]
R, C = pc.ROUGHNESS_STUDY, pc.CLEARANCE_STUDY
TIGHT = {"rtol": 1e-7, "atol": 1e-10}
VARIANTS = {  # name: (scene options, fixed parameters, cases run)
    "default": ({}, {}, range(5)),
    "ploughing": ({"friction_roughness": "ploughing"}, {}, range(5)),
    "restitution p=1": ({}, {"restitution_roughness_exponent": 1.0}, range(5)),
    "restitution p=3": ({}, {"restitution_roughness_exponent": 3.0}, R),
}  # fmt: skip
RUNS = [*((v, "default") for v in VARIANTS), ("default", "tight")]


def run(variant, tolerance, rerun=False):
    """The variant's cases as one batch: `(scene, params, trajectories, info)` (cached)."""
    options, fixed, cases = VARIANTS[variant]
    path = CACHE / f"{variant.replace(' ', '_')}_{tolerance}.pkl"
    scene = DeployArray(**options)
    if path.exists() and not rerun:
        return scene, *pickle.loads(path.read_bytes())
    table = {f"{p}_{k}": [CASES[i][j] for i in cases] for p in ("panel1", "panel2")
             for j, k in enumerate(("ra", "clearance"))}  # fmt: skip
    start = time.perf_counter()
    batch = simulate_batch(scene, table, T_END, fixed=fixed, n_save=int(T_END * SAVE_RATE_HZ) + 1,
                           control=TIGHT if tolerance == "tight" else None)  # fmt: skip
    jax.block_until_ready(batch.trajectory)
    info = {"wall_s": time.perf_counter() - start, "statuses": batch.statuses(),
            "steps": np.asarray(batch.trajectory.stats["num_accepted_steps"]).tolist(),
            "control": str(scene.default_control.updated(TIGHT if tolerance == "tight" else {})),
            "revision": code_revision(), "machine": machine_description()}  # fmt: skip
    print(f"[{variant}, {tolerance}] {info['wall_s']:.0f} s, {info['statuses']}", flush=True)
    params = [batch.case_params(i) for i in range(batch.size)]
    trajectories = [jax.tree.map(np.asarray, batch.case(i)) for i in range(batch.size)]
    CACHE.mkdir(parents=True, exist_ok=True)
    path.write_bytes(pickle.dumps((params, trajectories, info)))
    return scene, params, trajectories, info


def outputs_and_metrics(scene, params, trajectories, cases):
    """Per case index (0–4): (deploy_array outputs, claim metrics), None for cases not run."""
    out = [None] * len(CASES)
    # The ideal-joint reference, run once per set of parameters the ideal array uses (the
    # cases differ in their hinges' contact only, so they share one).
    ideal = scene.ideal_counterpart()
    unused = ideal.ignored_params()
    references = {}
    for i, p, tr in zip(cases, params, trajectories, strict=True):
        used = tuple(sorted((k, float(v)) for k, v in p.items() if k in ideal.params))
        key = (tuple(k for k in used if k[0] not in unused), np.asarray(tr.ts).tobytes())
        if key not in references:
            references[key] = reference_run(scene, p, tr.ts)
        o = deploy_array_outputs(scene.build(p), tr, references[key])
        out[i] = (o, pc.case_metrics(o))
    return out


FIGURE_OUTPUTS = ("t", "alpha", "alpha_ideal", "panel2_mean_acceleration")


def analysis(runs, rerun=False):
    """`outputs_and_metrics` of every run (cached: the ideal reference and contact histories
    are slow on a loaded machine); outputs kept for the figures only."""
    path = CACHE / "analysis.pkl"
    if path.exists() and not rerun:
        return pickle.loads(path.read_bytes())
    results = {}
    for key, (scene, params, trajectories, _) in runs.items():
        results[key] = outputs_and_metrics(scene, params, trajectories, VARIANTS[key[0]][2])
        for i, r in enumerate(results[key]):
            if r is not None:
                keep = key == ("default", "tight")
                results[key][i] = ({k: r[0][k] for k in FIGURE_OUTPUTS} if keep else None, r[1])
    path.write_bytes(pickle.dumps(results))
    return results


def evidence(results):
    """Evidence per variant: values at the default tolerance (the default variant: tight),
    uncertainties |default − tight| of the default variant."""
    tight, loose = results[("default", "tight")], results[("default", "default")]
    unc = [{k: abs(m[k] - loose[i][1][k]) for k in m} for i, (_, m) in enumerate(tight)]
    ev = {"default": pc.Evidence([m for _, m in tight], unc)}
    for v in VARIANTS:
        if v != "default":
            ev[v] = pc.Evidence([r and r[1] for r in results[(v, "default")]], unc)
    return ev


# --- sensitivities: d(output)/d ln(parameter) by forward mode, checked by differences --------
SENS_CASE = dict(zip(("panel1_ra", "panel2_ra", "panel1_clearance", "panel2_clearance"),
                     (1.6 * UM, 1.6 * UM, 0.05 * MM, 0.05 * MM), strict=True))  # fmt: skip
SENS_PARAMS = {  # name: the scene parameters it scales together
    "spring stiffness": ("spring_stiffness",), "latch stiffness": ("latch_stiffness",),
    "latch preload": ("latch_preload", "panel_latch_preload"),
    "panel masses": ("panel_mass_scale",),
    "clearance": ("panel1_clearance", "panel2_clearance"), "Ra": ("panel1_ra", "panel2_ra"),
}  # fmt: skip
OUTPUTS = ("lock time [s]", "panel 1 RMS deviation unfolding [m]",
           "panel 2 RMS deviation unfolding [m]", "panel 2 post-lock peak acceleration [m/s²]",
           "panel 2 dominant frequency [Hz]", "J1 peak contact force [N]")  # fmt: skip
CD_STEP = 1e-2  # step in ln(parameter) of the central differences
CD_PARAMS = ("spring stiffness", "clearance")


def lock_time_traced(ts, alpha, angle):
    """First crossing of `angle` by α, linear between saved states (differentiable in α)."""
    i, ts = jnp.argmax(alpha >= angle), jnp.asarray(ts)
    return ts[i - 1] + (angle - alpha[i - 1]) / (alpha[i] - alpha[i - 1]) * (ts[i] - ts[i - 1])


def sensitivities():
    """`jax.jacfwd` of the headline outputs in ln(parameter) at Ra 1.6 µm, c 0.05 mm, and
    central differences for `CD_PARAMS` (cached)."""
    path = CACHE / "sensitivity.json"
    if path.exists():
        return json.loads(path.read_text())
    scene, ideal = DeployArray(), DeployArray(ideal=True)
    base = scene.resolve_params(SENS_CASE)
    ts = np.linspace(0.0, T_END, int(T_END * SAVE_RATE_HZ) + 1)
    angle = GEOMETRY["latch"]["engage_alpha"]
    shared = {k: v for k, v in base.items() if k in ideal.params}
    alpha_ideal = ideal.channels(ideal.build(shared), run_scene(ideal, shared, T_END, ts=ts))
    t_lock = ob.ideal_lock_time(ts, alpha_ideal["alpha"], angle)  # fixes the windows

    def at(log_factors):
        p = dict(base)
        for k, names in enumerate(SENS_PARAMS.values()):
            for n in names:
                p[n] = base[n] * jnp.exp(log_factors[k])
        options = {"ts": ts, "adjoint": dfx.ForwardMode()}
        tr = run_scene(scene, p, T_END, **options)
        p_ideal = {k: v for k, v in p.items() if k in ideal.params}
        channels = scene.channels(scene.build(p), tr)
        reference = ideal.channels(
            ideal.build(p_ideal), run_scene(ideal, p_ideal, T_END, **options)
        )
        dep = ob.Deployment(ts, t_lock, channels, reference)
        return jnp.stack([
            lock_time_traced(ts, channels["alpha"], angle),
            ob.deployment_deviation(dep, "panel1"), ob.deployment_deviation(dep, "panel2"),
            ob.peak_vibration(dep, "panel2", "acceleration"), ob.dominant_frequency(dep, "panel2"),
            ob.peak_contact_force(dep, "panel1"),
        ])  # fmt: skip

    start = time.perf_counter()
    zero = jnp.zeros(len(SENS_PARAMS))
    value, jac = jax.jit(lambda x: (at(x), jax.jacfwd(at)(x)))(zero)
    wall_ad = time.perf_counter() - start
    steps = np.zeros((2 * len(CD_PARAMS), len(SENS_PARAMS)))
    for j, name in enumerate(CD_PARAMS):
        steps[2 * j : 2 * j + 2, list(SENS_PARAMS).index(name)] = (CD_STEP, -CD_STEP)
    shifted = np.asarray(jax.jit(jax.vmap(at))(jnp.asarray(steps)))
    cd = {n: ((shifted[2 * j] - shifted[2 * j + 1]) / (2 * CD_STEP)).tolist()
          for j, n in enumerate(CD_PARAMS)}  # fmt: skip
    out = {"outputs": list(OUTPUTS), "params": list(SENS_PARAMS),
           "value": np.asarray(value).tolist(),
           "jacobian": np.asarray(jac).tolist(), "central_difference": cd, "cd_step": CD_STEP,
           "wall_s_jacfwd": wall_ad, "wall_s_total": time.perf_counter() - start,
           "revision": code_revision(), "machine": machine_description()}  # fmt: skip
    CACHE.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(out, indent=1))
    return out


# --- figures --------------------------------------------------------------------------------
def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def figure_cases(results):
    """Angle deviation and panel 2's post-lock Welch spectrum, default variant, both studies."""
    plt = _plt()
    fig, axes = plt.subplots(2, 2, figsize=(11, 7))
    for col, (study, cases) in enumerate((("roughness", R), ("clearance", C))):
        for i in cases:
            o, m = results[("default", "tight")][i]
            axes[0, col].plot(o["t"], (o["alpha"] - o["alpha_ideal"]) * 1e6, lw=0.8,
                              label=CASE_NAMES[i])  # fmt: skip
            after = o["t"][:-1] >= m["lock_time"]
            f, psd = welch_psd(o["t"][:-1][after], o["panel2_mean_acceleration"][after, 1], 0.1)
            axes[1, col].semilogy(f, psd, lw=0.8, label=CASE_NAMES[i])
        axes[0, col].set(title=f"{study} study: α − α_ideal", xlabel="t [s]", ylabel="µrad")
        axes[1, col].set(title="panel 2 Y acceleration after lock (Welch, 0.1 s)",
                         xlabel="f [Hz]", ylabel="PSD [(m/s²)²/Hz]", xlim=(0, 1000))  # fmt: skip
        for ax in axes[:, col]:
            ax.legend(fontsize=7)
    fig.tight_layout()
    path = FIG / "study_cases.png"
    atomic_savefig(fig, str(path))
    plt.close(fig)
    return path


VERDICT_CODE = {"disagrees": 0, "not resolved": 1, "partly": 2, "agrees": 3}


def figure_region(table, variants):
    """Verdict of each claim (rows) per variant (columns): the region where a claim holds."""
    plt = _plt()
    ids = [r["id"] for r in table["default"]]
    grid = np.full((len(ids), len(variants)), np.nan)
    for j, v in enumerate(variants):
        for r in table[v]:
            grid[ids.index(r["id"]), j] = VERDICT_CODE[r["verdict"]]
    fig, ax = plt.subplots(figsize=(1.6 * len(variants) + 2, 0.32 * len(ids) + 1.5))
    image = ax.imshow(grid, cmap=plt.get_cmap("RdYlGn", 4), vmin=-0.5, vmax=3.5, aspect="auto")
    ax.set(xticks=range(len(variants)), xticklabels=variants, yticks=range(len(ids)),
           yticklabels=ids, title="verdict per claim and variant (blank: not run)")  # fmt: skip
    bar = fig.colorbar(image, ticks=range(4))
    bar.ax.set_yticklabels(list(VERDICT_CODE))
    fig.tight_layout()
    path = FIG / "study_region.png"
    atomic_savefig(fig, str(path))
    plt.close(fig)
    return path


# --- the page -------------------------------------------------------------------------------
METRIC_ROWS = [
    ("lock time [s]", "lock_time", 1.0),
    ("max |α−α_ideal| unfolding [µrad]", "angle_dev_deploy", 1e6),
    ("max |α−α_ideal| after lock [µrad]", "angle_dev_locked", 1e6),
    ("α deviation 10 % settling [ms]", "angle_settling", 1e3),
    ("panel 1 centre max |ΔX| unfolding [µm]", "panel1_centre_x_deploy", 1e6),
    ("panel 2 centre max |ΔX| unfolding [µm]", "panel2_centre_x_deploy", 1e6),
    ("panel 1 post-lock peak frequency [Hz]", "panel1_freq_locked", 1.0),
    ("panel 2 post-lock peak frequency [Hz]", "panel2_freq_locked", 1.0),
    ("panel 2 post-lock peak level [m/s² RMS]", "panel2_amp_locked", 1.0),
    ("max contact force (saved states) [N]", "max_contact_force", 1.0),
]  # fmt: skip


def sensitivity_lines(sens):
    lines = [SENS_TEXT.format(**sens), "",
             "| output | value | " + " | ".join(f"d/d ln({p})" for p in sens["params"]) + " |",
             "|---|---|" + "---|" * len(sens["params"])]  # fmt: skip
    for k, name in enumerate(sens["outputs"]):
        cells = [f"{sens['jacobian'][k][j]:.3g}" for j in range(len(sens["params"]))]
        lines.append(f"| {name} | {sens['value'][k]:.4g} | " + " | ".join(cells) + " |")
    lines += ["", f"Central differences (step ±{sens['cd_step']:g} in ln):", "",
              "| output | " + " | ".join(f"{p}: jacfwd / difference"
                                         for p in sens["central_difference"]) + " |",
              "|---|" + "---|" * len(sens["central_difference"])]  # fmt: skip
    for k, name in enumerate(sens["outputs"]):
        cells = [f"{sens['jacobian'][k][sens['params'].index(p)]:.4g} / {d[k]:.4g}"
                 for p, d in sens["central_difference"].items()]  # fmt: skip
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return lines + ["", SENS_READING]


def _control(text):
    """'StepControl(solver='tsit5', rtol=1e-06, …)' → 'tsit5 rtol 1e-06 atol 1e-09'."""
    fields = dict(f.split("=", 1) for f in text[text.index("(") + 1 : -1].split(", "))
    return f"{fields['solver'].strip(chr(39))} rtol {fields['rtol']} atol {fields['atol']}"


def _load(machine):
    return " ".join(f"{x:.0f}" for x in machine["load_average_1_5_15min"])


def _rev(revision):
    return revision["commit"][:7] + (" (uncommitted changes)" if revision.get("dirty") else "")


def _cell(text):
    return str(text).replace("|", "\\|")


def write_page(runs, results, sens):
    ev = evidence(results)
    table = {v: pc.claims(e, clearance=v != "restitution p=3") for v, e in ev.items()}
    main_variants = [v for v in VARIANTS if v != "restitution p=3"]
    figures = [figure_cases(results), figure_region(table, list(VARIANTS))]
    info = {k: r[3] for k, r in runs.items()}
    lines = [
        "# The seed study's section 4, claim by claim, with our model and its roughness variants",
        "", "<!-- generated by experiments/paper_study.py; do not edit by hand -->", "",
        f"Page generated at commit `{code_revision()['commit'][:7]}`, runs at "
        f"`{_rev(info[('default', 'default')]['revision'])}`, by "
        "`PYTHONPATH=. nice -n 10 .venv/bin/python experiments/paper_study.py` (runs cached in "
        "`results/paper_study/`, `--rerun` to redo them).", "",
        INTRO, "", "## Runs", "",
        "| variant | control | cases | accepted steps per case | wall [s] | load avg. | statuses |",
        "|---|---|---|---|---|---|---|",
    ]  # fmt: skip
    for (v, _), i in info.items():
        lines.append(
            f"| {v} | {_control(i['control'])} | {len(i['steps'])} | {i['steps']} | "
            f"{i['wall_s']:.0f} | {_load(i['machine'])} | {sorted(set(i['statuses']))} |"
        )
    lines += ["", RUNS_TEXT, "", "## Our numbers (default variant)", "",
              "| quantity | " + " | ".join(CASE_NAMES) + " |", "|---|" + "---|" * 5]  # fmt: skip
    for name, metric, scale in METRIC_ROWS:
        cells = [f"{ev['default'].value(metric, i) * scale:.4g} ± "
                 f"{ev['default'].uncertainty(metric, i) * scale:.1g}"
                 for i in range(5)]  # fmt: skip
        lines.append(f"| {_cell(name)} | " + " | ".join(cells) + " |")
    lines += ["", "## Claim by claim", "", CLAIMS_TEXT, ""]
    for v in main_variants:
        counts = {}
        for r in table[v]:
            counts[r["verdict"]] = counts.get(r["verdict"], 0) + 1
        lines.append(f"* {v}: " + ", ".join(f"{n} {k}" for k, n in sorted(counts.items())))
    signature = ",".join(
        f"{r['id']}:" + "/".join(table[v][k]["verdict"] for v in main_variants)
        for k, r in enumerate(table["default"])
    )
    if signature != CAUSES_WRITTEN_FOR:
        print("WARNING: verdicts changed since the causes were written")
        lines += ["", "> **Stale:** the causes below were written for other verdicts; revise them."]
    lines += ["", "| # | paper fig. | claim (W24 §4) | " + " | ".join(main_variants) + " | cause |",
              "|---|---|---|" + "---|" * (len(main_variants) + 1)]  # fmt: skip
    for k, r in enumerate(table["default"]):
        verdicts = [table[v][k]["verdict"] for v in main_variants]
        lines.append(f"| {r['id']} | {r['figure']} | {_cell(r['claim'])} | "
                     + " | ".join(f"**{x}**" for x in verdicts)
                     + f" | {_cell(CAUSES.get(r['id'], 'no cause written'))} |")  # fmt: skip
    lines += ["", "Our numbers behind each verdict, per variant:", ""]
    for v in main_variants:
        lines += [f"<details><summary>{v}</summary>", "", "| # | ours | verdict |", "|---|---|---|"]
        lines += [f"| {r['id']} | {_cell(r['ours'])} | {r['verdict']} |" for r in table[v]]
        lines += ["", "</details>", ""]
    lines += ["## Where the roughness claims hold: the free restitution exponent p", "",
              REGION_TEXT, "", "| claim | " + " | ".join(VARIANTS) + " |",
              "|---|" + "---|" * len(VARIANTS)]  # fmt: skip
    for k, r in enumerate(table["restitution p=3"]):
        lines.append(
            f"| {r['id']} | " + " | ".join(table[v][k]["verdict"] for v in VARIANTS) + " |"
        )
    lines += [
        "",
        f"![verdicts per variant]({os.path.relpath(figures[1], DOC.parent)})",
        "",
        "## Sensitivity of the headline outputs to the reconstruction's parameters",
        "",
    ]
    lines += sensitivity_lines(sens) if sens else [SENS_MISSING]
    lines += ["", "## Figures", "", f"![cases]({os.path.relpath(figures[0], DOC.parent)})", "",
              DISCUSSION]  # fmt: skip
    atomic_write_bytes(str(DOC), ("\n".join(lines).rstrip() + "\n").encode())
    print(f"wrote {DOC}")


INTRO = """\
The paper (W24, section 4) simulates a two-panel deployable array with roughness
Ra ∈ {0.8, 1.6, 3.2} µm at clearance c = 0.05 mm and c ∈ {0.01, 0.05, 0.1} mm at Ra = 1.6 µm,
and draws conclusions from deviations against the ideal-joint mechanism and from acceleration
spectra. We run the same five cases on our reconstruction `deploy_array`
([deploy_array_geometry.md](deploy_array_geometry.md), [deploy_array.md](deploy_array.md)):
both hinges J1 and J7 with the same Ra and c, rough Lankarani–Nikravesh law (c_e = 0.9),
onset impact rule, smooth Coulomb friction, and the **preloaded latch** (100 N on each
hinge after the lock). Three variants say how roughness acts ([contact.md](contact.md),
"Roughness"):

* **default**: Ra enters only the elastic law (GW-averaged Hertz); μ = 0.05, c_e = 0.9.
* **ploughing**: μ(Ra) = μ_a + (2/π) Δa(Ra) (Bowden–Tabor ploughing by the asperities of a
  turned surface, `friction_roughness="ploughing"`, μ_a = 0.01, tool nose radius 0.8 mm):
  μ = 0.038, 0.050, 0.066 at Ra 0.8, 1.6, 3.2 µm. Grounded in published relations; μ_a free.
* **restitution p**: c_e(Ra) = 0.9^((Ra/1.6 µm)^p), the free coupling (no published relation:
  its exponent p is unknown). p = 1: c_e = 0.949, 0.9, 0.81; p = 3: 0.987, 0.9, 0.43."""

RUNS_TEXT = """\
* 1 s per case, not the paper's 2 s: CPU budget (2 cores shared by ~7 engineers; one case of
  2 s cost 74 s wall warm at load ~7). The lock is at 0.54 s, so 0.46 s after it; "once
  stable" is the last 0.2 s.
* Tsit5 with the scene's default control (rtol 1e-6, atol 1e-9, dt_max 0.5 ms); the default
  variant again at rtol 1e-7, atol 1e-10. **Uncertainty**: every default-variant number is the
  tight run's, ± its change from the default tolerance; a comparison counts only when the
  difference exceeds the summed error bars (≈ otherwise). The variants were run once (default
  tolerance) and carry the default variant's error bars: a cut for CPU, which assumes the
  variants are as reproducible as the default.
* Spectra: Welch (0.1 s Hann segments, half overlapping) of the interval-mean Y acceleration
  of each panel's centre after lock (docs/spectral_peak.md); peak frequency refined by a
  parabola; "peak level" = sqrt(P_max Δf), the RMS in the 10 Hz peak bin. Settling: time after
  lock until the 20 ms moving RMS (resting offset over the last 0.2 s removed) stays below 10 %
  of its maximum."""

CLAIMS_TEXT = """\
Verdicts: **agrees**, **disagrees**, **partly** (some of the series the claim covers agree,
others do not), **not resolved** (the effect is within the numerical error bar). The cause
column says why, for the pattern of verdicts across the variants."""

REGION_TEXT = """\
The restitution–roughness exponent p is the unknown that could make roughness act in the
normal direction (no published relation fixes it, docs/contact.md). The roughness claims for
p = 0 (the default), 1 and 3, with ploughing for comparison. A claim that changes verdict
along the row holds only in that part of p: R6 (stable amplitudes similar) needs p ≳ 3, R14
(panel 2 quietest at 3.2 µm) needs p ≥ 1 for its amplitude half; R9 is lost at p = 3; R3
leaves "disagrees" for "not resolved" once p ≥ 1 (the decay times fall with Ra at p = 3, by
less than their error bars). The rest do not move with p (the figure: columns are variants)."""

SENS_TEXT = """\
At Ra 1.6 µm, c 0.05 mm (default variant, 1 s, default tolerance): derivatives of each output
with respect to the natural logarithm of each parameter (a 1 % increase changes the output by
≈ 1/100 of the entry), by `jax.jacfwd` through the simulation (diffrax forward mode; the
ideal-joint reference differentiated too, the phase windows fixed at its lock time),
{wall_s_jacfwd:.0f} s wall for value and Jacobian (load average {machine[load_average_1_5_15min]}).
"Latch preload" scales both latches' preload, "panel masses" both panels' mass and inertia,
"clearance" and "Ra" both hinges'."""

SENS_MISSING = """\
Not computed for this page: the forward-mode Jacobian (six tangents through two 1 s
simulations) did not finish within the session's CPU budget on the loaded machine. The code
is `sensitivities()` in the script (`--sensitivity-only` computes and caches it)."""
SENS_READING = """\
How to read the check: the lock time is a smooth function of the parameters, and its
forward-mode derivative in the spring stiffness matches the difference. Everything that
passes through hinge impacts does not: the unfolding deviations match in the spring stiffness
to 20–30 % but not in the clearance, and the post-lock outputs' pathwise derivatives are
orders of magnitude above their differences. They are derivatives of one trajectory whose
impact times move with every parameter (the optimize module's docstring measures such
derivatives up to 1e15 with adaptive steps); the differences over a 1 % step are the trend a
designer can use, and the Jacobian columns other than the lock time's are not."""

# Written for the verdicts at the commit on top of the page; a changed verdict makes the
# script say so here instead of keeping a cause it no longer shows.
CAUSES_WRITTEN_FOR = (  # default/ploughing/restitution p=1 verdicts per claim
    "R1:disagrees/disagrees/disagrees,"
    "R2:agrees/agrees/agrees,"
    "R3:disagrees/not resolved/not resolved,"
    "R4:partly/disagrees/partly,"
    "R5:partly/disagrees/partly,"
    "R6:partly/partly/partly,"
    "R7:disagrees/disagrees/disagrees,"
    "R8:agrees/agrees/agrees,"
    "R9:partly/partly/partly,"
    "R10:agrees/agrees/agrees,"
    "R11:disagrees/disagrees/disagrees,"
    "R12:partly/disagrees/partly,"
    "R13:disagrees/disagrees/disagrees,"
    "R14:disagrees/disagrees/partly,"
    "C1:disagrees/disagrees/disagrees,"
    "C2:agrees/agrees/agrees,"
    "C3:agrees/agrees/agrees,"
    "C4:partly/partly/partly,"
    "C5:agrees/agrees/agrees,"
    "C6:partly/partly/partly,"
    "C7:disagrees/disagrees/disagrees"
)
CAUSES = {
    "R1": "No variant has the paper's maximum at 1.6 µm: Ra as contact softening (default, "
    "p) moves the unfolding lag by ≤ 3 %, non-monotone; ploughing friction raises it "
    "monotonically (+47 % from 0.8 to 3.2 µm).",
    "R2": "The preloaded latch seats both hinges after the lock: the angle deviation is the "
    "latch-up transient, within 13 % across Ra in every variant.",
    "R3": "The post-lock decay is the latch mode's damping; Ra changes it by less than the "
    "tolerance error (ploughing, p) or the other way (default, 118 → 127 ms).",
    "R4": "Default and p: the softer rough contact lowers some unfolding deviations only; "
    "ploughing: friction grows with Ra and so do the deviations, the opposite direction.",
    "R5": "The first 0.1 s after the lock is the latch-up impact (lock speed, preload): Ra "
    "moves it by a few per cent with mixed signs, ploughing friction raises it.",
    "R6": "The stable Y deviation is the same static seat for every Ra; the X residuals "
    "(picometres) grow with Ra beyond ×2 unless rough hinges dissipate much more (p = 3).",
    "R7": "Geometry of our reconstruction (W24's Fig. 8 and Table 2 are missing): panel 2's "
    "X deviation is ~4× panel 1's in every variant; not a roughness effect.",
    "R8": "A geometric ratio of the reconstruction, insensitive to the contact law.",
    "R9": "Both tips settle in ~100 ms (the latch mode), panel 2's late X residual is larger, "
    "not lower; only the settling half agrees, for some Ra.",
    "R10": "The seated hinges leave panel 2's tip a larger static Y offset, in every variant.",
    "R11": "Panel 1's latch-mode level is monotone in Ra in every variant (rising by 13 % "
    "in the default, falling with p = 3): no maximum at 1.6 µm.",
    "R12": "The latch mode (k_L calibrated to the ideal array's 95 Hz) moves by ~1 Hz with "
    "Ra: default lowest at 0.8 but highest at 3.2 µm, p = 1 falling with Ra; flat with ploughing.",
    "R13": "With the preloaded latch panel 2's acceleration peaks at 160–180 Hz (its seated "
    "hinge J7), not 90–100 Hz, in every variant: a latch-model effect, not a roughness one.",
    "R14": "Panel 2's level is lowest at 3.2 µm only if rough hinges dissipate much more "
    "(p = 3: −24 % from 1.6 µm; p = 1: below 1.6 µm only); fastest attenuation never resolved.",
    "C1": "The unfolding lag grows with clearance (harder impacts, more play) in every "
    "variant: the paper's 'small clearance enhances collisions' is not what ours do.",
    "C2": "Larger clearance, lower contact stiffness (K ∝ c^(−1/2)) and more impact "
    "dissipation per cycle: faster post-lock decay, in every variant.",
    "C3": "More play, larger excursions from the ideal path, in every variant.",
    "C4": "Panel 1's Y grows least (×1.5) but panel 2's Y most (×4.5): geometry of the "
    "reconstruction.",
    "C5": "The latch-mode level of panel 1 falls with clearance (softer, more dissipative "
    "contact), in every variant.",
    "C6": "Amplitude rises then falls (agrees); panel 2's peak frequency at c = 0.1 mm is "
    "not resolved (±200 Hz between tolerances).",
    "C7": "Panel 2's peak (its hinge mode, 160–280 Hz) lies above panel 1's 82–93 Hz latch "
    "mode, except at c = 0.1 mm where it is not resolved (see R13).",
}

DISCUSSION = """\
## Reading

**What changed since the previous study.** The preloaded latch (default since issue 24) seats
both hinges after the lock, so the post-lock dynamics are the locked array's modes, not
rattling: panel 1's spectrum peaks at the 88–93 Hz latch mode in every case, and the stable
deviations are static offsets. Panel 2's peak sits at 160–180 Hz, the mode of its seated
hinge, so the paper's 90–100 Hz (R13) and the comparisons built on panel 2's frequency (C7)
disagree for a reason that lies in the latch model, not in roughness. The 1 s horizon (CPU)
and the Welch estimate replace the previous page's 2 s and point-sampled spectra.

**Roughness stays a weak lever unless it changes friction.** Through the elastic law alone
(default), roughness moves the unfolding deviations by a few per cent and the post-lock
numbers by less than their trends need: of the 14 roughness claims, the ones that agree (R2,
R8, R10) are the ones that say roughness does *not* matter or that are geometric ratios. The
free restitution coupling changes little at p = 1 (c_e 0.95 → 0.81) and reproduces more of
the paper only at p = 3 (c_e 0.99 → 0.43, an extreme loss for Ra 3.2 µm steel): R6 (stable
amplitudes similar) and the amplitude half of R14 (panel 2's peak lowest at Ra 3.2). No value of p
we ran gives the paper's "first increases, then decreases" (R1, R11): those need a mechanism
with an extremum in Ra, which none of the published relations we found provides. The
grounded ploughing friction makes roughness matter — μ rises from 0.038 to 0.066 — but in the
direction opposite to the paper's displacement claims (R4, R5): more friction, more lag
during unfolding. The paper explains its trends by friction growing with roughness; in our
model that mechanism produces the opposite deviations.

**Clearance claims do not depend on how roughness acts** (C1–C7 have the same verdict in
every variant): C2, C3 and C5 agree as before; C1 still disagrees (our unfolding lag grows
with clearance).
"""


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rerun", action="store_true", help="ignore the cached runs")
    parser.add_argument("--runs-only", action="store_true", help="run (cache) and stop")
    parser.add_argument("--sensitivity-only", action="store_true", help="the derivatives only")
    parser.add_argument("--skip-sensitivity", action="store_true", help="page without them")
    args = parser.parse_args(argv)
    if args.sensitivity_only:
        print(json.dumps(sensitivities(), indent=1))
        return 0
    runs = {key: run(*key, rerun=args.rerun) for key in RUNS}
    if args.runs_only:
        return 0
    results = analysis(runs, rerun=args.rerun)
    write_page(runs, results, None if args.skip_sensitivity else sensitivities())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
