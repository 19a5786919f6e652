"""docs/performance.md from one bench run's measurements (`__main__.py`), with the targets of
issue 21 item 3 as ratios from that run and met / missed by how much."""

from __future__ import annotations

import math

from .provenance import header
from .work_precision import best_at_levels

LEVELS = (1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9)  # m, error levels of the work–precision target
PEERS = ("scipy", "exudyn")


def _batch_bounds(b: dict) -> str:
    """What bounds the batch ratio, from the batch run's own numbers: the vmap advances until
    its slowest case (max / mean accepted steps), and the share of its time in the saved
    times' acceleration solves (default outputs against `outputs="motion"`)."""
    parts = []
    if b.get("steps_mean"):
        most = b["steps_min_max"][1]
        parts.append(
            f"The vmap advances until its slowest case: {most} accepted steps against a mean "
            f"of {b['steps_mean']:.0f} ({most / b['steps_mean']:.2f}×)."
        )
    mo = b.get("motion")
    if mo:
        share = 1.0 - mo["vmap_per_simulation_s"] / b["vmap_per_simulation_s"]
        single = 1.0 - mo["one_at_a_time_per_simulation_s"] / b["one_at_a_time_per_simulation_s"]
        parts.append(
            f'Saving q and q̇ alone (`outputs="motion"`) takes {_f(share, ".0%")} off the vmap '
            f"({mo['vmap_per_simulation_s']:.3g} s per simulation) and "
            f"{_f(single, '.0%')} "
            "off one at a time: the saved times' q̈ and λ, which the batch solves after its "
            "loop, vmapped over the saved times (`simulate`'s `batch_saved_accelerations`, "
            "set by `batch_function`), and a run alone inside its loop."
        )
    sh = b.get("shared_steps")
    if sh:
        lo, hi = sh["vmap_accepted_steps_min_max"]
        parts.append(
            f"With every case on one shared step sequence (`benchmarks/shared_steps.py`: a step "
            f"is kept when every case keeps it, the next is the shortest any case proposes; "
            f"{sh['cases']} cases of the same spread) the vmap has no idle lanes, but each case "
            f"takes every other case's steps: {sh['shared_accepted_steps']} accepted and "
            f"{sh['shared_rejected_steps']} rejected steps against {lo}–{hi} accepted per case "
            f"(mean {sh['vmap_accepted_steps_mean']:.0f}) in the plain vmap, "
            f"{sh['shared_per_simulation_s']:.3g} s per simulation against "
            f"{sh['vmap_per_simulation_s']:.3g} s ({sh['ratio']:.1f}× the plain vmap's cost; "
            "compile "
            f"{sh['shared_compile_s']:.3g} s against {sh['vmap_compile_s']:.3g} s): each "
            "case's contact onsets and located events become steps of all, so sharing steps "
            "does not pay for a mechanism with impacts."
        )
    return " ".join(parts) + (" " if parts else "")


def _f(x, fmt=".3g"):
    return "–" if x is None or (isinstance(x, float) and math.isnan(x)) else format(x, fmt)


# Issue 32's work–precision goals (they replace issue 21's 0.5 warm and 1 first call): warm
# ≤ 0.6× the best peer, a first call from empty caches ≤ 20×, with the caches filled ≤ 2×.
WARM_GOAL, FIRST_GOAL, CACHED_GOAL = 0.6, 20, 2


def _verdict(value, goal, smaller_is_better=True):
    if value is None or math.isnan(value):
        return "not measured"
    met = value <= goal if smaller_is_better else value >= goal
    if met:
        return "met"
    factor = value / goal if smaller_is_better else goal / value
    if f"{factor:.2g}" == "1":  # "1× the goal" would read as met: say by how much
        return f"missed by {100 * (factor - 1):.1g} %"
    return f"missed: {factor:.2g}× " + ("the goal" if smaller_is_better else "short")


def work_precision_targets(rows):
    """Per error level: best warm, first call and first call with the persistent caches filled
    (`first_cached_s`, jaxdeploy only) of ours and of the peers, and their ratios. The peers
    have nothing to cache: their first call stands for both."""
    out = []
    keys = {"warm_s": "warm_s", "first_s": "first_s", "first_cached_s": "first_s"}
    bests = {
        (who, key): best_at_levels(rows, LEVELS, kinds, key if who == "ours" else peer_key)
        for who, kinds in (("ours", ("jaxdeploy",)), ("peer", PEERS))
        for key, peer_key in keys.items()
    }
    for i, level in enumerate(LEVELS):
        entry = {"level_m": level}
        for key in keys:
            ours, peer = bests[("ours", key)][i], bests[("peer", key)][i]
            entry[f"ours_{key}"], entry[f"peer_{key}"] = ours, peer
            entry[f"ratio_{key}"] = ours / peer if peer and not math.isnan(peer) else math.nan
        out.append(entry)
    return out


STEP_COST_SETTINGS = ("h=1e-06 s", "h=2.5e-07 s")  # 4000 and 16000 steps over 4 ms


def step_cost_ratio(rows):
    """Generalized-α fixed steps on slider_crank: our warm wall per step over Exudyn's
    (python and symbolic force), as `{family: (ratio, how)}`, or None when either is missing.

    Per step is the marginal cost, `(warm(h = 0.25 µs) − warm(h = 1 µs)) / (16000 − 4000)`
    steps on each side: the same saved times (q and q̇ at 4001 times on both sides) and each
    side's fixed cost per call (ours: checks, dispatch, results; Exudyn's: resetting and
    initialising its solver, ~40 ms) cancel, which `warm/steps` of one run does not. Without
    both step sizes on a side (a quick run) it falls back to `warm/steps` at h = 1 µs (`how`
    says which)."""

    def runs(family):
        return {r["setting"]: r for r in rows if r["family"] == family and r["status"] == "ok"}

    def per_step(by, how):
        long_, short = by[STEP_COST_SETTINGS[0]], by.get(STEP_COST_SETTINGS[1])
        if how == "total":
            return long_["warm_s"] / long_["steps"]
        return (short["warm_s"] - long_["warm_s"]) / (short["steps"] - long_["steps"])

    ours = runs("jaxdeploy generalized-α fixed")
    if STEP_COST_SETTINGS[0] not in ours:
        return None
    out = {}
    for family in dict.fromkeys(r["family"] for r in rows if r["kind"] == "exudyn"):
        theirs = runs(family)
        if STEP_COST_SETTINGS[0] not in theirs:
            continue
        both = all(STEP_COST_SETTINGS[1] in side for side in (ours, theirs))
        how = "marginal" if both else "total"
        out[family] = (per_step(ours, how) / per_step(theirs, how), how)
    return out or None


def generalized_alpha_lines(ga, rows) -> list[str]:
    """What bounds the generalized-α step cost (`work_precision.generalized_alpha_operations`),
    or nothing."""
    if not ga or "error" in ga or not ga.get("newton_body"):
        return []
    by = {r["setting"]: r for r in rows if r["family"] == "jaxdeploy generalized-α fixed"
          and r["status"] == "ok"}  # fmt: skip
    if not all(s in by for s in STEP_COST_SETTINGS):
        return []
    long_, short = (by[s] for s in STEP_COST_SETTINGS)
    per_step = (short["warm_s"] - long_["warm_s"]) / (short["steps"] - long_["steps"])
    step, newton, k = ga["step_body"], ga["newton_body"], ga["newton_per_step"]
    operations = step["operations"] + k * newton["operations"]
    return [
        f"Generalized-α step (the step-cost target's fixed steps): the compiled step loop's body "
        f"is {step['operations']} operations ({step['lapack']} LAPACK calls) plus "
        f"{newton['operations']} per Newton iteration, {k:.2f} iterations per step at the "
        f"margin (the rare branches, matrix refreshes and saved times not counted); at "
        f"{per_step * 1e6:.2f} µs per step that is at most {per_step / operations * 1e9:.0f} ns "
        "per operation: XLA's CPU per-operation cost, not the arithmetic of nine coordinates, "
        "bounds the step.",
        "",
    ]


ANDREWS_TARGET = 1e-8  # relative error at t = 0.03 s (issue 21)
ANDREWS_FAMILY = "jaxdeploy generalized-α adaptive ρ∞=1"


def andrews_targets(a) -> list[str]:
    """Target rows for the Andrews squeezer: adaptive generalized-α (ρ∞ = 1) reaching 1e-8
    relative, and its cheapest warm run there against the cheapest peer's."""
    rows = a["rows"]
    ok = [r for r in rows if r["status"] == "ok" and r["error_rel"] is not None]
    ours = [r for r in ok if r["family"] == ANDREWS_FAMILY]
    best = min((r["error_rel"] for r in ours), default=math.nan)
    out = [
        f"| Andrews squeezer: adaptive generalized-α (ρ∞ = 1) relative error at 0.03 s | "
        f"{_f(best, '.2e')} (best of {', '.join(r['setting'] for r in ours) or 'no run'}) | "
        f"≤ {ANDREWS_TARGET:.0e} | {_verdict(best, ANDREWS_TARGET)} |"
    ]
    level = ANDREWS_TARGET
    reach = {
        who: min((r["warm_s"] for r in ok if pick(r) and r["error_rel"] <= level), default=None)
        for who, pick in (
            ("gen-α", lambda r: r["family"] == ANDREWS_FAMILY),
            ("ours", lambda r: r["kind"] == "jaxdeploy"),
            ("peer", lambda r: r["kind"] in PEERS),
        )
    }
    if reach["ours"] and reach["peer"]:
        out.append(
            f"| Andrews squeezer, error ≤ {level:.0e}: best ours / best peer, warm | "
            f"{reach['ours'] / reach['peer']:.2f} ({_f(reach['ours'])} s / "
            f"{_f(reach['peer'])} s; generalized-α {_f(reach['gen-α'])} s) | ≤ 0.5 | "
            f"{_verdict(reach['ours'] / reach['peer'], 0.5)} |"
        )
    return out


def andrews_section(a) -> list[str]:
    lines = [
        "## Andrews' squeezing mechanism",
        "",
        "Seven bodies, index-3 (Hairer & Wanner 1996, §VII.7; the Test Set for IVP Solvers, "
        f"problem “andrews”), 0–{a['horizon_s']:g} s. Error: {a['error']}. jaxdeploy: the "
        "squeezer built with the public mechanism API (`tests/andrews_mechanism.py`, absolute "
        "coordinates), atol = rtol; generalized-α on the index-3 form, Tsit5/Dopri8 on the "
        "index-1 ODE with projection. scipy: the benchmark's relative-angle equations, index-1 "
        "form solved per right-hand-side evaluation (`tests/independent/andrews_squeezer.py`), "
        "`solve_ivp` at atol = rtol. Steps: accepted steps (jaxdeploy), right-hand-side "
        "evaluations (scipy). `benchmarks/andrews.py`.",
        "",
        "| configuration | setting | relative error | compile [s] | first call [s] | warm [s] "
        "| steps | status |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in a["rows"]:
        lines.append(
            f"| {r['family']} | {r['setting']} | {_f(r['error_rel'], '.2e')} | "
            f"{_f(r['compile_s'], '.2f')} | {_f(r['first_s'], '.3g')} | {_f(r['warm_s'], '.3g')} "
            f"| {r['steps']} | {r['status']} |"
        )
    return lines + [""]


def breakdown_lines(bd) -> list[str]:
    """Where a warm Tsit5 call's CPU time goes (`work_precision.breakdown`)."""
    if not bd:
        return []
    cpu, steps = bd["cpu_s"], bd["steps"]
    saves = cpu["saved_4001"] - cpu["saved_2"]
    stepping = cpu["saved_2"] - cpu["horizon_2us"]
    return [
        f"Where a warm Tsit5 call's time goes (rtol {bd['rtol']:.0e}, fastest CPU time of "
        f"alternated calls, `work_precision.breakdown`): {cpu['saved_4001'] * 1e3:.1f} ms in "
        f"all; {stepping * 1e3:.1f} ms for its {steps['saved_2'] - steps['horizon_2us']} "
        f"steps (accepted and rejected: {bd['per_step_s'] * 1e6:.0f} µs each), "
        f"{saves * 1e3:.1f} ms for interpolating the 4001 saved states "
        f"({bd['per_saved_time_s'] * 1e6:.2f} µs each), {cpu['horizon_2us'] * 1e3:.1f} ms per "
        "call besides (argument checks, dispatch, results; a 2 µs run). A step is six Tsit5 "
        "stages (each an index-1 acceleration solve: contact forces, then a 7×7 Cholesky "
        "factorisation and two triangular solves, LAPACK's or written as array operations as "
        "`saddle_point.UNROLLED_MAX_SIZE` chooses), the projection, the "
        "step-end accelerations, event location and the extremes, executed by XLA's CPU "
        "runtime as a loop of small operations" + _operations_text(bd) + ".",
        "",
    ]


def separate_accelerations_lines(sa) -> list[str]:
    """The Tsit5 program with each evaluation of the accelerations compiled apart
    (`work_precision.separate_accelerations`), or nothing for a record without it."""
    if not sa or "error" in sa:
        return []
    a, b = sa["inline"], sa["noinline"]
    saved = a["first_cpu_s"] - b["first_cpu_s"]
    first = f"saves {saved:.2f} s of the first call" if saved > 0 else "saves no compile time"
    return [
        "The accelerations compiled apart (`work_precision.separate_accelerations`, a new "
        "process each, no cache, CPU seconds): with each evaluation of the step's "
        "accelerations a separate computation by `equinox.internal.noinline`, the first "
        f"call (trace, compile and run) takes {b['first_cpu_s']:.2f} s against "
        f"{a['first_cpu_s']:.2f} s inlined, and a warm call {b['warm_cpu_s']:.3g} s against "
        f"{a['warm_cpu_s']:.3g} s ({b['warm_cpu_s'] / a['warm_cpu_s']:.0f}×; the same slider "
        f"error, {b['error_m']:.2e} m against {a['error_m']:.2e} m). equinox runs the separate "
        "computation through a host callback, so each evaluation in a step leaves "
        f"the compiled loop for Python: it {first} and costs every later call. Not used (a "
        "nested `jax.jit` is no alternative: it lowers to a call that XLA's CPU compiler "
        "inlines).",
        "",
    ]


def program_parts_lines(pp) -> list[str]:
    """What XLA compiles in the Tsit5 program and what each part costs it
    (`work_precision.program_parts`), or nothing for a record without it."""
    if not pp or "error" in pp or "full" not in pp:
        return []
    full = pp["full"]
    parts = full["operations_by_part"]
    lines = [
        f"What XLA compiles (the Tsit5 program above, rtol {pp['rtol']:.0e}, q and q̇ saved; "
        "`work_precision.program_parts`, CPU seconds of the bench's process): tracing and "
        f"lowering {full['trace_lower_cpu_s']:.2f} s, XLA's compile "
        f"{full['xla_compile_cpu_s']:.2f} s for {full['operations']} operations (every "
        "instruction of the optimised program, fusions' insides included). Operations by the "
        "part that produced them (the name of the function traced once per program on each): "
        + ", ".join(f"{k} {v}" for k, v in parts.items())
        + " (end-time threshold: diffrax's t1 − 100 ULP, computed once per solve by 100 "
        "chained `nextafter`, outside the loop; loop: diffrax's integration loop, the stage "
        "arithmetic, the step-size controller, event location, the dense output and the save "
        "loop). Each part's compile time is measured by compiling the program without it:",
        "",
        "| program | operations | XLA compile [CPU s] | the part's share [CPU s] |",
        "|---|---|---|---|",
        f"| full | {full['operations']} | {full['xla_compile_cpu_s']:.2f} | |",
    ]
    for name, st in pp.items():
        if name == "full" or not isinstance(st, dict) or "operations" not in st:
            continue
        lines.append(
            f"| {name} | {st['operations']} | {st['xla_compile_cpu_s']:.2f} | "
            f"{full['xla_compile_cpu_s'] - st['xla_compile_cpu_s']:.2f} |"
        )
    return lines + [""]


def _compile_phases_text(new_process) -> str:
    """Where the cold new-process first calls went (`work_precision._compile_phases`), or
    nothing for a record without it."""
    parts = []
    for solver, runs in sorted(new_process.items()):
        phases = runs.get("cold", {}).get("compile_phases_s")
        if phases:
            parts.append(
                f"{solver} {phases['trace']:.2f} s tracing, {phases['lower']:.2f} s lowering, "
                f"{phases['xla_compile']:.2f} s XLA compiling"
            )
    if not parts:
        return ""
    return (
        "Of a cold first call (JAX's compile events, wall time of the top-level programs): "
        + "; ".join(parts)
        + ". "
    )


def _operations_text(bd) -> str:
    """The compiled loops' operation counts (`work_precision.loop_operations`), or nothing."""
    ops = bd.get("operations")
    if not ops or "error" in ops or not ops.get("stage_body") or not ops.get("save_body"):
        return ""
    step, stage, save = ops["step_body"], ops["stage_body"], ops["save_body"]
    per_op = bd["per_saved_time_s"] / save["operations"]
    per_step_op = bd["per_step_s"] / (step["operations"] + 6 * stage["operations"])
    return (
        f": the compiled step loop's body is {step['operations']} operations one after another "
        f"({step['lapack']} of them LAPACK calls), plus {stage['operations']} "
        f"({stage['lapack']} LAPACK) for each stage in the loop over a step's stages; a saved "
        f"time is {save['operations']} operations, {per_op * 1e9:.0f} ns each, and a step "
        f"{step['operations']} + 6 × {stage['operations']}, {per_step_op * 1e9:.0f} ns each. "
        "About the same cost per operation in both loops, whatever the operation does: that "
        "cost, not the arithmetic of nine coordinates, sets the step's time, and fewer, larger "
        "operations per step are what would cut it"
    )


def render(record, wp, targets, *, command, cut) -> str:
    rows = wp["rows"]
    levels = work_precision_targets(rows)
    lines = ["# Performance (generated: do not edit; `make bench` rewrites this page)", ""]
    lines += [header(record, command), ""]
    lines += [
        "How to rerun: `make bench` in a source checkout (a clean tree; it installs the `bench` "
        "extra: scipy, exudyn), or `python -m benchmarks all` in an environment that has them; "
        "`python -m benchmarks all --quick` tries the whole chain in a few minutes and writes "
        "to results/bench_quick instead. The benchmarks live in `benchmarks/` at the top of "
        "the checkout, not in the installed package. `tests/test_page_freshness.py` fails once "
        "a commit after the one above changes a measured path: rerun `make bench` then. "
        f"This run took {record['wall_s'] / 60:.1f} min.",
        "",
    ]
    lines += ["## What this run leaves out to fit its budget", ""]
    lines += [f"* {c}" for c in cut] + [""]

    lines += ["## Targets (issues 21 and 32): ratios from this run", ""]
    lines += ["| target | measured | goal | verdict |", "|---|---|---|---|"]
    for e in levels:
        lv = f"{e['level_m']:.0e} m"
        lines.append(
            f"| work–precision warm, error ≤ {lv}: best ours / best peer | "
            f"{_f(e['ratio_warm_s'], '.2f')} ({_f(e['ours_warm_s'])} s / "
            f"{_f(e['peer_warm_s'])} s) | ≤ {WARM_GOAL} | "
            f"{_verdict(e['ratio_warm_s'], WARM_GOAL)} |"
        )
    for e in levels:
        lv = f"{e['level_m']:.0e} m"
        lines.append(
            f"| work–precision first call (compile included), error ≤ {lv} | "
            f"{_f(e['ratio_first_s'], '.2f')} ({_f(e['ours_first_s'])} s / "
            f"{_f(e['peer_first_s'])} s) | ≤ {FIRST_GOAL} | "
            f"{_verdict(e['ratio_first_s'], FIRST_GOAL)} |"
        )
    for e in levels:
        if math.isnan(e["ratio_first_cached_s"]):
            continue
        lv = f"{e['level_m']:.0e} m"
        lines.append(
            f"| work–precision first call, new process with the persistent caches filled, "
            f"error ≤ {lv} | {_f(e['ratio_first_cached_s'], '.2f')} "
            f"({_f(e['ours_first_cached_s'])} s / "
            f"{_f(e['peer_first_cached_s'])} s) | ≤ {CACHED_GOAL} | "
            f"{_verdict(e['ratio_first_cached_s'], CACHED_GOAL)} |"
        )
    b, c = targets.get("batch"), targets.get("ceiling")
    if b:
        lines.append(
            f"| batch: one at a time / {b['cases']}-case vmap, per simulation | "
            f"{b['speedup_per_simulation']:.2f}× ({b['one_at_a_time_per_simulation_s']:.3g} s / "
            f"{b['vmap_per_simulation_s']:.3g} s) | ≥ 3× | "
            f"{_verdict(b['speedup_per_simulation'], 3.0, smaller_is_better=False)} |"
        )
        mo = b.get("motion")
        if mo:
            lines.append(
                f'| batch saving q, q̇ only (`outputs="motion"`), one at a time / vmap, per '
                f"simulation | {mo['speedup_per_simulation']:.2f}× "
                f"({mo['one_at_a_time_per_simulation_s']:.3g} s / "
                f"{mo['vmap_per_simulation_s']:.3g} s) | ≥ 3× | "
                f"{_verdict(mo['speedup_per_simulation'], 3.0, smaller_is_better=False)} |"
            )
    if c:
        share = b["speedup_per_simulation"] / c["speedup_per_solve"] if b else math.nan
        lines.append(
            f"| XLA ceiling: {c['size']}×{c['size']} solves, one / {c['cases']} vmapped, per "
            f"solve | {c['speedup_per_solve']:.2f}× (the simulation reaches "
            f"{_f(share, '.0%')} of it) | (reference) | – |"
        )
        st = c.get("step")
        if st:
            share = b["speedup_per_simulation"] / st["speedup_per_case"] if b else math.nan
            before = st.get("lapack")
            lines.append(
                f"| ceiling of the step's own linear algebra ({st['scene']} Tsit5: index-1 "
                f"accelerations + projection), one / {st['cases']} vmapped, per case | "
                f"{st['speedup_per_case']:.2f}× (the simulation reaches {_f(share, '.0%')} of "
                "it)"
                + (
                    f"; {before['speedup_per_case']:.2f}× with LAPACK's Cholesky of the Schur "
                    "complement"
                    if before
                    else ""
                )
                + " | (reference) | – |"
            )
    g = targets.get("gradient")
    if g:
        mode = g["auto_mode"]
        lines.append(
            f"| gradient / forward, deploy_array loss over {g['t_end_s']:g} s ({mode} mode, "
            f"the choice of `gradient_mode` for {len(g['wrt'])} parameters) | "
            f"{g['ratio']:.2f}× ({g[f'gradient_{mode}']['warm_s']:.3g} s / "
            f"{g['forward']['warm_s']:.3g} s) | ≤ 3× | {_verdict(g['ratio'], 3.0)} |"
        )
    s = targets.get("simulate")
    if s:
        lines.append(
            f"| `jaxdeploy simulate {s['scene']}` cold | {s['cold_s']:.1f} s | ≤ 10 s | "
            f"{_verdict(s['cold_s'], 10.0)} |"
        )
        lines.append(
            f"| `jaxdeploy simulate {s['scene']}` warm (compilation cache filled) | "
            f"{s['warm_s']:.1f} s | ≤ 3 s | {_verdict(s['warm_s'], 3.0)} |"
        )
    w = targets.get("whole-process")
    lines += whole_process_targets(w) if w else []
    a = targets.get("andrews")
    for line in andrews_targets(a) if a else []:
        lines.append(line)
    steps = step_cost_ratio(rows)
    for family, (ratio, how) in (steps or {}).items():
        which = {
            "marginal": "marginal cost per step from h = 1 µs to 0.25 µs",
            "total": "warm call / steps at h = 1 µs",
        }[how]
        lines.append(
            f"| generalized-α step / {family} step (slider_crank, {which}) | {ratio:.2f} | "
            f"≤ 0.3 | {_verdict(ratio, 0.3)} |"
        )
    lines += [
        "",
        "A work–precision level compares the fastest configuration of each side whose error "
        "is at or below it; “–”: no configuration of that side reached the level. The first-"
        "call target is judged on the cold first call (empty caches); the rows “persistent "
        "caches filled” are the first call of a new process after an earlier one filled "
        "jaxdeploy's persistent caches (the program cache and JAX's compilation cache, as "
        "`jaxdeploy` commands set them up), against the same peer first call. Peers: "
        + ", ".join(sorted({r["family"] for r in rows if r["kind"] in PEERS}))
        + ". Timed in one process pinned to one core for both sides (work–precision, batch, "
        "ceiling, gradient); `jaxdeploy simulate` uses every core of the machine.",
        "",
    ]

    lines += ["## Work–precision: slider_crank, 0–4 ms", ""]
    lines += [
        f"Error: {wp['error_measure']} against `{wp['reference']}` (the independent "
        "minimal-coordinate model, `tests/independent/slider_crank_minimal.py`). Every "
        "configuration uses the classical Lankarani–Nikravesh rule (v⁻ held from the onset). "
        "jaxdeploy: adaptive runs at atol = 1e-3 rtol with the scene's dt_max = 0.1 ms, saving "
        'q and q̇ at the 4001 times, as solve_ivp does (`simulate(..., outputs="motion")`; '
        "the family “q̈, λ, memory saved” is simulate's default, an acceleration solve per "
        "saved time more); "
        "compile is the family's (in the bench's process: its first configuration's first call "
        "minus warm; tolerances and steps are data, the other configurations reuse the "
        "program). First call: "
        + (
            "for " + ", ".join(sorted(wp["new_process"])) + " a new process with empty caches "
            "times its first call (import and scene build excluded: "
            + ", ".join(
                f"{k} {v['cold']['setup_s']:.1f} s" for k, v in sorted(wp["new_process"].items())
            )  # fmt: skip
            + "), the family's other configurations add their own warm call to its first call "
            "minus its warm one; for the other families compile + warm. "
            if wp.get("new_process")
            else "compile + warm. "
        )
        + "Caches filled: the same in a second new process reading the caches the first one "
        "filled. "
        + _compile_phases_text(wp.get("new_process") or {})
        + "scipy peers (`benchmarks/scipy_peer.py`): minimal coordinates, numpy, `solve_ivp` with "
        "onset and separation events, atol = 1e-3 rtol. Exudyn "
        f"({wp['exudyn'] or 'not installed'}; `benchmarks/exudyn_peer.py`): its generalized-α, "
        "fixed steps, v⁻ from the onset on each step's Hermite interpolant; first call includes "
        "building the model. Warm: the "
        + wp.get("warm_statistic", f"median of up to {wp['repeats']} calls")
        + ", the same rule for every side (CPU time and median in `bench/work_precision.json`). "
        "Steps: accepted steps (jaxdeploy, Exudyn), right-hand-side evaluations (scipy).",
        "",
        "![work–precision](bench/work_precision.png)",
        "",
        "| configuration | setting | error [m] | compile [s] | first call [s] | first call, "
        "caches filled [s] | warm [s] | steps | status |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['family']} | {r['setting']} | {_f(r['error_m'], '.2e')} | "
            f"{_f(r['compile_s'], '.2f')} | {_f(r['first_s'], '.3g')} | "
            f"{_f(r.get('first_cached_s'), '.3g')} | {_f(r['warm_s'], '.3g')} "
            f"| {r['steps']} | {r['status']} |"
        )
    lines.append("")
    lines += breakdown_lines(wp.get("breakdown"))
    lines += program_parts_lines(wp.get("program_parts"))
    lines += separate_accelerations_lines(wp.get("separate_accelerations"))
    lines += generalized_alpha_lines(wp.get("generalized_alpha_step"), rows)
    if b:
        lines += [
            "## Batch",
            "",
            f"slider_crank over {b['t_end_s'] * 1e3:g} ms with the scene's default step control, "
            f"restitution spread over 0.8–0.99: one vmap of {b['cases']} cases "
            f"({b['vmap_warm_s']:.3g} s warm, compile {b['vmap_compile_s']:.3g} s; accepted steps "
            f"{b['steps_min_max'][0]}–{b['steps_min_max'][1]} per case) against one at a time "
            f"(mean of {b['singles_timed']} cases spread over the range, compile "
            f"{b['one_at_a_time_compile_s']:.3g} s). Solver: one at a time "
            f"`{b.get('one_at_a_time_solver', '?')}`, the vmap `{b.get('vmap_solver', '?')}` "
            "(`jaxdeploy.batch.vmapped_control` changes only generalized-α, to Newton's method "
            "proper). " + _batch_bounds(b) + f"The ceilings: {c['iterations']} chained "
            f"{c['size']}×{c['size']} `jnp.linalg.solve` ({c['one_s']:.3g} s for one system, "
            f"{c['vmapped_s']:.3g} s for {c['cases']} vmapped)"
            + (
                f"; {c['step']['iterations']} chained evaluations of the step's linear algebra "
                f"({c['step']['one_s']:.3g} s for one case, {c['step']['vmapped_s']:.3g} s for "
                f"{c['step']['cases']} vmapped"
                + (
                    f"; with LAPACK's factor {c['step']['lapack']['one_s']:.3g} s and "
                    f"{c['step']['lapack']['vmapped_s']:.3g} s"
                    if c["step"].get("lapack")
                    else ""
                )
                + ")."
                if c.get("step")
                else "."
            ),
            "",
        ]
    if g:
        lines += gradient_section(g)
    if a:
        lines += andrews_section(a)
    if s:
        lines += [
            "## `jaxdeploy simulate`",
            "",
            f"The whole command (`jaxdeploy simulate {s['scene']} --quiet`, scene defaults: "
            "import, scene build, compile, run, ideal-joint reference, files) in a fresh "
            "process with an empty persistent compilation cache (cold), then again (warm).",
            "",
            *simulate_phases(s),
        ]
    if w:
        lines += whole_process_section(w)
    return "\n".join(lines)


def whole_process_targets(w: dict) -> list[str]:
    """Issue 32's whole-process rows: `jaxdeploy simulate slider_crank` against the scipy
    user's script, first and second run, and a Python script's second process."""
    lines = []
    sc = w.get("slider_crank")
    if sc:
        peer = f"scipy LSODA script (rtol {sc['script']['rtol']:g})"
        for run, goal, what in (("first", 5.0, "first run, empty caches"),
                                ("second", 2.0, "second run, caches filled")):  # fmt: skip
            ours, theirs = sc["ours"][run], sc["script"][run]
            lines.append(
                f"| `{sc['command']}` / {peer}, whole processes, {what} | "
                f"{sc[f'{run}_ratio']:.1f}× ({ours['wall_s']:.2f} s / {theirs['wall_s']:.2f} s; "
                f"CPU {sc[f'{run}_cpu_ratio']:.1f}×) | ≤ {goal:g}× | "
                f"{_verdict(sc[f'{run}_ratio'], goal)} |"
            )
    sw = w.get("sweep")
    if sw:
        default = sw["default"]
        how = f"{default['first']['policy']}, {default['first']['devices']} device(s)"
        for name, flags in (
            ("each case alone", "--policy each"),
            ("vmap, one device", "--policy all --devices 1"),
        ):
            for run, what in (("first", "empty caches"), ("second", "caches filled")):
                other = sw[name][run]
                lines.append(
                    f"| `jaxdeploy sweep` (16 deploy_array cases, 0.6 s), {what}: `{flags}` / "
                    f"default ({how}), whole process | {sw[f'{name}/{run}_ratio']:.2f}× "
                    f"({other['wall_s']:.1f} s / {default[run]['wall_s']:.1f} s) | "
                    "(reference: the default) | – |"
                )
    py = w.get("python_script")
    if py:
        second = py["second"]
        lines.append(
            "| Python script (README's example, `jd.enable_caches`), second process: end of "
            f"`import jaxdeploy` to the first `simulate` result | {second['first_result_s']:.2f} s "
            f"(CPU {second['first_result_cpu_s']:.2f} s) | ≤ 1 s | "
            f"{_verdict(second['first_result_s'], 1.0)} |"
        )
    return lines


def start_up_lines(imports: dict | None) -> list[str]:
    """What the second run's start-up spends on imports, by package (`whole_process.
    start_up_imports`), the solvers' stack named apart."""
    if not imports:
        return []
    from .whole_process import SOLVER_STACK

    packages = imports["packages"]
    stack = sum(packages.get(name, 0.0) for name in SOLVER_STACK)
    named = ("jax", "jaxlib", "numpy", "equinox", "jaxdeploy")
    other = imports["total_s"] - stack - sum(packages.get(name, 0.0) for name in named)
    parts = ", ".join(f"{name} {packages.get(name, 0.0):.2f}" for name in named)
    return [
        f"The start-up's imports alone (`{imports['statement']}` in a new process, "
        "`python -X importtime`, its own bookkeeping included; the fastest of three): "
        f"{imports['total_s']:.2f} s, of which {parts}, the solvers' stack "
        f"({', '.join(SOLVER_STACK)}) {stack:.2f} and the rest {other:.2f} s. A run read back "
        "from the program cache calls a kept executable whose inputs and outputs are flat "
        "arrays, but its arguments are still built, and its key computed, from objects "
        "whose classes subclass diffrax's, so the solvers' stack is imported on the warm "
        "path too.",
        "",
    ]


def fit_lines(fit: dict) -> list[str]:
    """The README's fit in two new processes sharing one cache folder
    (`whole_process.fit_second_process`)."""
    same = "the same estimates bit for bit" if fit["identical"] else "**different estimates**"
    return [
        f"`{fit['command']}` (the README's fit) in two new processes sharing one cache "
        "folder: the first makes the fit's model (the channels' forward-mode Jacobian) in a "
        "second thread while it chooses the tolerance (`jaxdeploy/commands/fit.py`); the "
        "second reads it from the program cache (`jaxdeploy/fit/_model_program.py`) instead "
        f"of tracing and compiling it; {same}.",
        "",
        *_twice_table(fit, "the fit itself (`fit.json` `wall_time_s`)"),
    ]


def optimize_lines(optimize: dict) -> list[str]:
    """The README's optimize in two new processes sharing one cache folder
    (`whole_process.optimize_second_process`)."""
    same = (
        "the same objective history bit for bit"
        if optimize["identical"]
        else "**a different objective history**"
    )
    return [
        f"`{optimize['command']}` (the README's optimize) in two new processes sharing one "
        "cache folder: the first makes the design batch's runs program in a second thread "
        "while it runs the ideal reference (`jaxdeploy/commands/optimize.py`), then the "
        "objective of their outputs; the second reads both programs "
        "(`jaxdeploy/_design_program.py`) from the program cache instead of tracing them; "
        f"{same}.",
        "",
        *_twice_table(optimize, "the optimisation itself (`result.json` `wall_time_s`)"),
    ]


def _twice_table(twice: dict, own: str) -> list[str]:
    first, second = twice["first"], twice["second"]
    return [
        f"| process | wall [s] | CPU [s] | {own} [s] |",
        "|---|---|---|---|",
        f"| first (empty caches) | {first['wall_s']:.1f} | {first['cpu_s']:.1f} | "
        f"{first['own_wall_s']:.1f} |",
        f"| second | {second['wall_s']:.1f} | {second['cpu_s']:.1f} | {second['own_wall_s']:.1f} |",
        "",
    ]


def whole_process_section(w: dict) -> list[str]:
    """Where the whole-process rows come from, each run's wall and CPU time."""
    lines = ["## Whole processes", ""]
    sc = w.get("slider_crank")
    if sc:
        script = sc["script"]
        lines += [
            f"`{sc['command']}` (two crank revolutions, 2001 saved times, trajectory.npz, "
            "summary.json and two plots) against `benchmarks/slider_crank_script.py`, what a "
            "scipy user would run instead: the minimal-coordinate model of "
            "`benchmarks/scipy_peer.py` with `solve_ivp` (LSODA, onset and separation events) "
            "over the same span and saved times, writing them to a file, no plots. The "
            f"script's tolerance (rtol {script['rtol']:g}, atol {script['atol']:g}) is the "
            "loosest of LSODA's whose slider error over the first 4 ms (against "
            "`tests/data/slider_crank_reference.npz`) is at or below ours: "
            f"{sc['ours']['error_4ms_m']:.2e} m ours, {script['first']['error_4ms_m']:.2e} m "
            "the script's. Each side twice in new processes (jaxdeploy's and the "
            "benchmarks' modules compiled to bytecode beforehand, as an install leaves "
            "them), the first with a new, empty "
            "`JAXDEPLOY_CACHE_DIR`, the second with the caches the first filled"
            + (
                "; the two runs' trajectories are bit-identical."
                if sc["identical_runs"]
                else "; the two runs' trajectories DIFFER."
            ),  # fmt: skip
            "",
            "| run | jaxdeploy wall [s] | jaxdeploy CPU [s] | script wall [s] | "
            "script CPU [s] | wall ratio |",
            "|---|---|---|---|---|---|",
        ]
        for run in ("first", "second"):
            ours, theirs = sc["ours"][run], script[run]
            lines.append(
                f"| {run} | {ours['wall_s']:.2f} | {ours['cpu_s']:.2f} | {theirs['wall_s']:.2f} "
                f"| {theirs['cpu_s']:.2f} | {sc[f'{run}_ratio']:.1f}× |"
            )
        phases = sorted({k for run in ("first", "second") for k in sc["ours"][run]["phases"]},
                        key=lambda k: (k not in SIMULATE_PHASES, list(SIMULATE_PHASES).index(k)
                                       if k in SIMULATE_PHASES else 0, k))  # fmt: skip
        lines += [
            "",
            "jaxdeploy's phases (wall [s], from its `summary.json`): "
            + "; ".join(
                f"{k.removesuffix('_s')} "
                + " / ".join(
                    f"{sc['ours'][run]['phases'][k]:.2f}"
                    if k in sc["ours"][run]["phases"]
                    else "–"  # fmt: skip
                    for run in ("first", "second")
                )
                for k in phases
            )
            + " (first / second run).",
            "",
        ]
        lines += start_up_lines(w.get("start_up_imports"))
    py = w.get("python_script")
    if py:
        lines += [
            "The README's Python example as a script (`jd.enable_caches(DIR)` first, then the "
            "slider-crank with clearance 1e-4 m, Tsit5 at rtol 1e-8, 0.024 s) in two new "
            "processes sharing DIR, run from its file as a user runs a script: the second "
            "reads the programs the first traced and compiled, in a background thread from "
            "`enable_caches` on (`jaxdeploy/_read_ahead.py`).",
            "",
            "| process | `import jaxdeploy` [s] | import → first result, wall [s] | its CPU [s] | "
            "whole process wall [s] | whole process CPU [s] |",
            "|---|---|---|---|---|---|",
        ]
        for run in ("first", "second"):
            r = py[run]
            lines.append(
                f"| {run} | {r['import_s']:.2f} | {r['first_result_s']:.2f} | "
                f"{r['first_result_cpu_s']:.2f} | {r['wall_s']:.2f} | {r['cpu_s']:.2f} |"
            )
        lines.append("")
    fit = w.get("fit")
    if fit:
        lines += fit_lines(fit)
    optimize = w.get("optimize")
    if optimize:
        lines += optimize_lines(optimize)
    sw = w.get("sweep")
    if sw:
        lines += [
            f"`{sw['command']}`: by default (`--policy auto`) a sweep of more than two cases "
            f"per usable core ({sw['cores']} here) runs its chunk as one vmap sharded over one "
            "device per core, as `--policy all` does, and a smaller one each case alone, as "
            "`jaxdeploy simulate` runs it (a thread per core, its programs kept in the program "
            "cache): here the default against `--policy each` and against `--policy all "
            "--devices 1`, the vmap on one device (`--devices N` chooses the count). Each "
            "twice in new processes (empty caches, then the caches the first filled). The "
            "chunk's wall time is from the sweep's manifest; the rest of the process is "
            "start-up, the run-length probe (which makes the chunk's programs, kept in the "
            "program cache: `jaxdeploy/sweep.py`'s `_chunk_program`, so that a second process "
            "traces none of them) and the files.",
            "",
            "| configuration | policy | devices | run | whole process wall [s] | CPU [s] "
            "| the chunk [s] |",
            "|---|---|---|---|---|---|---|",
        ]
        for name in ("default", "each case alone", "vmap, one device"):
            for run in ("first", "second"):
                r = sw[name][run]
                lines.append(
                    f"| {name} | {r['policy']} | {r['devices']} | {run} | {r['wall_s']:.1f} | "
                    f"{r['cpu_s']:.1f} | {r['chunk_wall_s']:.1f} |"
                )
        lines.append("")
    return lines


# What each phase of `jaxdeploy simulate`'s summary.json measures (docs/results.md).
SIMULATE_PHASES = {
    "start_up_s": "interpreter, imports, arguments (the wall before the phases began)",
    "build_s": "scene build and initial state (its assembly programs compiled or loaded; warm: "
    "read back from the scene cache)",
    "compile_s": "tracing, lowering and compiling the run's program, or loading it (warm); cold: "
    "what the run still waits for of its program compiled ahead",
    "compile_ahead_s": "the run's program traced and compiled in a second thread while the "
    "initial state is assembled (cold: overlaps build)",
    "integrate_s": "the run, and beside it the contact-history programs",
    "reference_compile_s": "the reference run's compile, in a second thread beside the run",
    "reference_s": "the reference run, in that thread (cold; warm: read from its cache)",
    "reference_wait_s": "waiting for the reference after the run",
    "outputs_s": "summary quantities, trajectory.npz",
    "plots_s": "waiting for the figures (drawn in a second process beside the outputs; "
    "matplotlib's import there overlaps the run)",
}


def simulate_phases(s: dict) -> list[str]:
    """The phases of the cold and the warm `jaxdeploy simulate`, where their time went."""
    cold, warm = s.get("cold_phases"), s.get("warm_phases")
    if not cold or not warm:
        return []
    lines = [
        f"Wall time of each phase [s] (CPU time of the whole process: cold "
        f"{s['cold_cpu_s']:.1f} s, warm {s['warm_cpu_s']:.1f} s). The reference's phases run "
        "in a second thread, overlapping the run's: they do not add to the wall.",
        "",
        "| phase | what | cold | warm |",
        "|---|---|---|---|",
    ]
    names = list(SIMULATE_PHASES) + [k for k in {**cold, **warm} if k not in SIMULATE_PHASES]
    for name in names:
        if name in cold or name in warm:
            values = [f"{p[name]:.2f}" if name in p else "–" for p in (cold, warm)]
            what = SIMULATE_PHASES.get(name, "")
            lines.append(f"| {name.removesuffix('_s')} | {what} | {values[0]} | {values[1]} |")
    lines.append(f"| total | the whole command | {s['cold_s']:.2f} | {s['warm_s']:.2f} |")
    lines.append("")
    lines += warm_run_bound(s)
    return lines


SIMULATE_WARM_GOAL_S = 3.0  # issue 32: `jaxdeploy simulate deploy_array` warm


def warm_run_bound(s: dict) -> list[str]:
    """What bounds the warm command: its integration's steps and their cost, against what the
    goal leaves the integration once the other phases are paid."""
    steps, warm = s.get("warm_steps") or {}, s["warm_phases"]
    accepted, rejected = steps.get("n_steps"), steps.get("n_rejected")
    if not accepted or rejected is None:
        return []
    taken = accepted + rejected
    integrate = warm["integrate_s"]
    rest = s["warm_s"] - integrate
    left = SIMULATE_WARM_GOAL_S - rest
    if left > 0:
        need = (
            f"the {SIMULATE_WARM_GOAL_S:g} s goal leaves the integration {left:.2f} s, "
            f"{1e6 * left / taken:.0f} µs a step ({integrate / left:.1f}× faster than this)"
        )
    else:
        need = f"the other phases alone take the {SIMULATE_WARM_GOAL_S:g} s goal"
    return [
        f"**What bounds the warm command.** Its integration: {accepted} accepted and "
        f"{rejected} rejected steps in {integrate:.2f} s, {1e6 * integrate / taken:.0f} µs a "
        f"step (with the contact-history programs beside it); the other phases take "
        f"{rest:.2f} s. With them as they are, {need}.",
        "",
    ]


def _program(run) -> str:
    """`XLA compile [CPU s] | operations` of a gradient-part run (`programs.compile_stats`)."""
    p = run.get("program")
    if not p:
        return "– | –"
    return f"{p['xla_compile_cpu_s']:.3g} | {p['operations']}"


def _slider_crank_programs(sc) -> list[str]:
    """slider_crank's gradient programs' compile (`targets.slider_crank_gradient_programs`)."""
    if not sc:
        return []
    cells = "; ".join(
        f"{mode} mode {sc[mode]['xla_compile_cpu_s']:.3g} CPU s of XLA compile for "
        f"{sc[mode]['operations']} operations (tracing and lowering "
        f"{sc[mode]['trace_lower_cpu_s']:.3g} s; warm {sc[mode]['warm_s']:.3g} s)"
        for mode in ("forward", "reverse")
    )
    return [
        f"slider_crank's gradient programs (a loss of the slider's acceleration over "
        f"{sc['t_end_s'] * 1e3:g} ms, with respect to "
        + ", ".join(f"`{w}`" for w in sc["wrt"])
        + f"): {cells}.",
        "",
    ]


def gradient_section(g) -> list[str]:
    """The gradient's costs in both modes and its check against central differences."""
    fwd, rev, rep, base = (g["gradient_forward"], g["gradient_reverse"], g["replay"],
                           g["forward"])  # fmt: skip
    st = g["steps"]
    lines = [
        "## Gradient",
        "",
        f"Loss: mean square of panel 2's tip acceleration over {g['t_end_s']:g} s of "
        "deploy_array (201 samples, the scene's default step control); its gradient with "
        "respect to " + ", ".join(f"`{w}`" for w in g["wrt"]) + " by "
        "`jaxdeploy.fit.gradient_function` in both modes, steps replayed "
        "(`replay_steps=True`, as `jaxdeploy.fit`): an undifferentiated adaptive run chooses "
        'the steps, the run over exactly those steps is differentiated. `mode="auto"` '
        f"takes {g['auto_mode']} mode here (`gradient_mode`: forward up to "
        "`FORWARD_MODE_MAX_PARAMETERS` parameters). Warm: best of the rounds, taken in turn.",
        "",
        "| run | compile [s] | XLA compile [CPU s] | operations | warm [s] | warm / forward run |",
        "|---|---|---|---|---|---|",
        f"| forward run (the loss) | {base['compile_s']:.3g} | {_program(base)} | "
        f"{base['warm_s']:.3g} | 1 |",
        f"| forward run, steps replayed (the loss; what every gradient pays first) | "
        f"{rep['compile_s']:.3g} | {_program(rep)} | {rep['warm_s']:.3g} | "
        f"{g['replay_ratio']:.2f} |",
        f"| gradient, forward mode (`jax.jacfwd`, `diffrax.ForwardMode`) | "
        f"{fwd['compile_s']:.3g} | {_program(fwd)} | {fwd['warm_s']:.3g} | "
        f"{g['ratio_forward']:.2f} |",
        f"| gradient, reverse mode (`jax.value_and_grad`, `RecursiveCheckpointAdjoint`) | "
        f"{rev['compile_s']:.3g} | {_program(rev)} | {rev['warm_s']:.3g} | "
        f"{g['ratio_reverse']:.2f} |",
        "",
        "compile: the first call's wall time less the warm one; XLA compile: CPU seconds of "
        "the bench's process in XLA's compile alone, and the compiled program's operations "
        "(`benchmarks/programs.py`).",
        "",
        *_slider_crank_programs(g.get("slider_crank_programs")),
        f"The two modes' gradients differ by {g['modes_max_relative_difference']:.1e} "
        f"(largest relative difference over the parameters). The run takes {st['accepted']} "
        f"accepted and {st['rejected']} rejected steps; reverse mode's default "
        f"{st['checkpoints']} checkpoints (diffrax's for max_steps = {st['max_steps']}) "
        "exceed them, so its backward pass recomputes nothing.",
        "",
    ]
    r = g.get("rhs")
    if r:
        p = r["primal_us"]
        lines += [
            "**What bounds it.** Every gradient first pays the run that chooses the steps (the "
            f"replayed forward run costs {g['replay_ratio']:.2f}× a forward run: the adaptive "
            "run, then the run over its steps), then a pass over the same steps in which every "
            "evaluation of the right-hand side carries the derivatives. One evaluation of the "
            f"accelerations (`Mechanism.accelerations`, {r['coordinates']} coordinates, "
            f"{r['constraints']} constraints; chained calls in one compiled loop) costs "
            f"{p:.3g} µs; its JVP with 1 tangent {r['jvp1_us']:.3g} µs "
            f"({r['jvp1_us'] / p:.1f}×), with 4 tangents (vmapped, as "
            f"`jax.jacfwd`) {r['jvp4_us']:.3g} µs ({r['jvp4_us'] / p:.1f}×), its VJP "
            f"{r['vjp_us']:.3g} µs ({r['vjp_us'] / p:.1f}×). Small dense linear algebra costs "
            "per operation, not per flop, so each tangent costs about one more primal "
            "evaluation: a gradient within 3× a forward run would need the differentiated pass "
            "within about 2× the primal pass, which these ratios exclude at this size.",
            "",
        ]
    cd = g.get("central_differences")
    if not cd:
        return lines
    smooth = cd["max_relative_error_smooth"]
    lines += [
        "**Against central differences** of the same loss, (L(θ + h) − L(θ − h)) / 2h with h "
        "a relative step of each parameter, every perturbed run over the unperturbed run's "
        f"{cd['step_ends']} steps (so both sides differentiate one discrete map). Switched "
        "steps: step ends at which a clearance joint's contact flag (or a latch's) differs "
        "between the runs at θ + h and θ − h — a contact onset or separation that moved across "
        "a step end, where the discrete map jumps: the difference then measures the jump, "
        "not the derivative. Largest disagreement where no step switched: "
        + (f"{smooth:.1e}." if smooth is not None else "none (every difference switched)."),
        "",
        "| parameter | h (relative) | central difference | gradient | relative error | "
        "switched steps (first at) |",
        "|---|---|---|---|---|---|",
    ]
    for r in cd["rows"]:
        first = f" ({r['first_switch_s']:.4g} s)" if r["first_switch_s"] is not None else ""
        lines.append(
            f"| `{r['parameter']}` | {r['relative_step']:g} | {r['central_difference']:.6g} | "
            f"{r['gradient']:.6g} | {r['relative_error']:.1e} | {r['switched_steps']}{first} |"
        )
    lines.append("")
    return lines
