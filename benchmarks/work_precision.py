"""Work–precision of slider_crank: jaxdeploy's solvers and the peers a user would pick instead,
against the independent reference, with one error measure.

Error: `max |x_s − x_ref|` [m] of the slider position over the 4001 saved times 0, 1 µs, …,
4 ms, x_ref from `tests/data/slider_crank_reference.npz` (`tests/independent/
slider_crank_minimal.py`: minimal coordinates, DOP853 at rtol 1e-13 with every onset and
separation located; its check runs agree to 1e-13 m over these 4 ms). Same parameters, the
classical Lankarani–Nikravesh rule everywhere.

Timing, per configuration, in one process pinned to one core (so jaxdeploy's XLA threads and
the single-threaded peers use the same hardware):
* compile [s] — jaxdeploy only: the first call of a solver family (its first configuration)
  minus its warm call. Tolerances and steps are data of the compiled program, so the other
  configurations of a family reuse it; a fresh process pays the compile once per family.
* first call [s] — what a user's first call costs in a fresh process: compile + warm
  (jaxdeploy), or for `NEW_PROCESS_FAMILIES` the first call measured in a new process (below);
  the first run (peers: scipy has nothing to compile; Exudyn: building and assembling the
  model included).
* warm [s] — the fastest of the further calls (`timed_calls`): at least `repeats`, then more
  until they add up to `WARM_BUDGET_S` (at most `MAX_REPEATS`, and none started once they add
  up to `TIMING_BUDGET_S`). A call of 20–90 ms is repeated ~10–50 times: its fastest run is
  the one least disturbed by other processes, where a median of three moved by 2× between two
  quiet runs. The same rule for every side; the median and the fastest CPU time are kept too.
* first call in a new process [s] — jaxdeploy's Tsit5 and Dopri8 (`NEW_PROCESS_FAMILIES`):
  a fresh Python process (`first_call_child`) with the persistent caches set up as the command
  line sets them (JAX's compilation cache and jaxdeploy's program cache in one new folder)
  builds the scene, then times its first `simulate` call and its fastest warm call; run once
  with the folder empty (cold: trace, lower and compile) and once more with the folder the
  first run filled (cached: read the program back, load the compiled executable). A family's
  other configurations reuse the program: their value is the child's first call minus its
  warm call plus their own warm call. Importing jaxdeploy and building the scene are not in
  the first call (the peers' first call has no imports either); they are kept as
  `setup_s`.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import asdict, dataclass

import numpy as np

REFERENCE = "tests/data/slider_crank_reference.npz"
HORIZON_S = 4e-3
# A configuration's warm calls: at least `repeats`, then more until they add up to
# WARM_BUDGET_S, at most MAX_REPEATS; none is started once they add up to TIMING_BUDGET_S.
WARM_BUDGET_S = 1.0
MAX_REPEATS = 100
TIMING_BUDGET_S = 20.0
# Families whose first call is also timed in new processes, empty caches and filled ones.
NEW_PROCESS_FAMILIES = ("tsit5", "dopri8")


@dataclass
class Config:
    family: str  # one series of the plot, e.g. "jaxdeploy Tsit5"
    kind: str  # "jaxdeploy", "scipy", "exudyn"
    solver: str  # jaxdeploy solver name, scipy method, or "generalized_alpha" (Exudyn)
    rtol: float | None = None
    dt: float | None = None  # fixed step [s]
    force_function: str = "python"  # Exudyn only
    outputs: str = "motion"  # jaxdeploy only: what a saved time keeps (`simulate`'s option)

    @property
    def setting(self) -> str:
        return f"rtol={self.rtol:.0e}" if self.rtol is not None else f"h={self.dt:.2g} s"


@dataclass
class Row:
    family: str
    setting: str
    kind: str
    error_m: float
    compile_s: float  # NaN for peers
    first_s: float
    warm_s: float
    steps: int  # accepted steps (jaxdeploy, Exudyn), right-hand-side evaluations (scipy)
    status: str
    warm_median_s: float = math.nan  # the median of the warm calls
    warm_cpu_s: float = math.nan  # the fastest warm call's CPU time (process_time)
    warm_calls: int = 0
    first_new_process_s: float = math.nan  # first call in a new process, empty caches
    first_cached_s: float = math.nan  # first call in a new process, persistent caches filled


def configurations(quick: bool, exudyn: bool) -> list[Config]:
    """Ours at several tolerances or steps, the scipy peers at several tolerances, and Exudyn
    (when importable) at several fixed steps. `quick`: one or two of each, for tests."""
    ours = {
        "tsit5": [1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10],
        "dopri8": [1e-7, 1e-8, 1e-9, 1e-10, 1e-11],
        "generalized_alpha": [1e-5, 1e-6, 1e-7, 1e-8],
        "kvaerno5": [1e-6, 1e-8],
    }
    fixed = [4e-6, 1e-6, 2.5e-7]
    peers = {"LSODA": [1e-4, 1e-6, 1e-8, 1e-10], "Radau": [1e-4, 1e-6, 1e-8, 1e-10]}
    peers["DOP853"] = [1e-4, 1e-6, 1e-8, 1e-10, 1e-12]
    exu = {"python": [1e-6, 5e-7, 2.5e-7], "symbolic": [1e-6, 2.5e-7]}
    if quick:
        ours = {"tsit5": [1e-6, 1e-8], "generalized_alpha": [1e-6]}
        fixed, peers = [1e-6], {"LSODA": [1e-6], "Radau": [1e-6], "DOP853": [1e-6]}
        exu = {"python": [1e-6]}
    out = []
    for solver, tolerances in ours.items():
        name = {"generalized_alpha": "generalized-α adaptive"}.get(solver, solver.capitalize())
        out += [Config(f"jaxdeploy {name}", "jaxdeploy", solver, rtol=t) for t in tolerances]
    out += [
        Config("jaxdeploy generalized-α fixed", "jaxdeploy", "generalized_alpha", dt=h)
        for h in fixed
    ]
    # What saving the whole state at the 4001 times costs (simulate's default: q̈ and λ are an
    # acceleration solve per saved time).
    out += [
        Config("jaxdeploy Tsit5, q̈, λ, memory saved", "jaxdeploy", "tsit5", rtol=t, outputs="all")
        for t in ([1e-6] if quick else [1e-5, 1e-7, 1e-9])
    ]
    for method, tolerances in peers.items():
        out += [Config(f"scipy {method}", "scipy", method, rtol=t) for t in tolerances]
    if exudyn:
        for force, steps in exu.items():
            out += [
                Config(
                    f"Exudyn generalized-α ({force} force)",
                    "exudyn",
                    "generalized_alpha",
                    dt=h,
                    force_function=force,
                )  # fmt: skip
                for h in steps
            ]
    return out


def load_reference(root: str = "."):
    """`(ts, x_ref)` over 0–4 ms from the fixture (frictionless case)."""
    import os

    with np.load(os.path.join(root, REFERENCE)) as data:
        ts, x = np.array(data["fine_ts"]), np.array(data["mu0_fine"][:, 1])
    if not math.isclose(ts[-1], HORIZON_S, rel_tol=1e-12):
        raise ValueError(f"{REFERENCE}: fine_ts ends at {ts[-1]} s, expected {HORIZON_S} s")
    return ts, x


class _Ours:
    """jaxdeploy's slider_crank (the scene's defaults: the Flores case, classical rule)."""

    def __init__(self, ts):
        from jaxdeploy.scenes import SliderCrank

        scene = SliderCrank(impact_velocity_rule="onset")
        params = scene.resolve_params()
        if params["friction_coefficient"] != 0.0:
            raise ValueError("the reference is frictionless; the scene's default is not")
        self.mech = scene.build(params)
        self.s0 = scene.initial_state(params, self.mech)
        self.control = scene.default_control
        self.ts = ts
        self.params = params
        self.q0, self.v0 = np.asarray(self.s0.q), np.asarray(self.s0.v)

    def call(self, cfg: Config):
        from jaxdeploy.simulation import simulate

        control = _control(self.control, cfg)

        def run():
            tr = simulate(self.mech, self.s0, float(self.ts[-1]), ts=self.ts, control=control,
                          outputs=cfg.outputs)  # fmt: skip
            q = np.asarray(tr.q)
            return q[:, 6], int(tr.stats["num_accepted_steps"]), tr.status()

        return run


def _control(control, cfg: Config):
    """The scene's step control with `cfg`'s solver and tolerance or fixed step."""
    if cfg.dt is not None:
        return control.replace(solver=cfg.solver, rtol=None, atol=None, dt=cfg.dt,
                               dt_max=None, max_steps=100_000)  # fmt: skip
    return control.replace(solver=cfg.solver, rtol=cfg.rtol, atol=1e-3 * cfg.rtol,
                           max_steps=1_000_000)  # fmt: skip


def _call(cfg: Config, ours, ts):
    if cfg.kind == "jaxdeploy":
        return ours.call(cfg)
    if cfg.kind == "scipy":
        from .scipy_peer import SliderCrankPeer

        def run():
            x, evaluations = SliderCrankPeer().solve(ts, cfg.solver, cfg.rtol, 1e-3 * cfg.rtol)
            return x, evaluations, "ok"

        return run
    from .exudyn_peer import ExudynSliderCrank

    model = {}

    def run():  # the first call builds and assembles the model (part of a user's first call)
        if not model:
            model["m"] = ExudynSliderCrank(ours.params, ours.q0, ours.v0,
                                           force_function=cfg.force_function)  # fmt: skip
        out = model["m"].solve(cfg.dt, float(ts[-1]), ts)
        return out.q[:, 6], out.steps, "ok" if out.ok else out.message

    return run


def timed_calls(run, failed_output, repeats: int, stats: dict | None = None):
    """`((output, steps, status), first, warm)` of a configuration's callable `run`: the first
    call's wall time, then the fastest of the warm calls (module docstring: at least `repeats`,
    more until `WARM_BUDGET_S`; NaN when the first call did not end "ok"). `stats`, if given,
    receives the warm calls' median wall time, the fastest CPU time and their number. A call
    that raises is a row with `failed_output`, not a lost benchmark."""
    start = time.perf_counter()
    try:
        result = run()
    except Exception as err:
        result = (failed_output, -1, f"failed: {err}")
    first = time.perf_counter() - start
    walls, cpus = [], []
    while result[2] == "ok" and len(walls) < MAX_REPEATS and sum(walls) < TIMING_BUDGET_S:
        if len(walls) >= repeats and sum(walls) >= WARM_BUDGET_S:
            break
        start, cpu = time.perf_counter(), time.process_time()
        run()
        walls.append(time.perf_counter() - start)
        cpus.append(time.process_time() - cpu)
    if stats is not None:
        stats.update(
            warm_median_s=float(np.median(walls)) if walls else math.nan,
            warm_cpu_s=min(cpus) if cpus else math.nan,
            warm_calls=len(walls),
        )
    return result, first, min(walls) if walls else math.nan


def first_call_child(solver: str, rtol: float, root: str = ".") -> dict:
    """In a new process (`python -m benchmarks.work_precision first-call SOLVER RTOL`): the
    persistent caches set up as the command line sets them up (`JAXDEPLOY_CACHE_DIR` names
    their folder), the scene built, then the first `simulate` call and the fastest of the warm
    calls, timed as `timed_calls` times them (module docstring)."""
    start = time.perf_counter()
    # Before equinox is imported (as `jaxdeploy.cli` does): callback-free runtime checks,
    # which the program cache needs.
    from jaxdeploy._compilation_cache import enable_compilation_cache, prefer_cacheable_errors

    prefer_cacheable_errors()
    enable_compilation_cache()
    ts, x_ref = load_reference(root)
    ours = _Ours(ts)
    setup = time.perf_counter() - start
    stats = {}
    cfg = Config("", "jaxdeploy", solver, rtol=rtol)
    phases = _compile_phases()
    (x, steps, status), first, warm = timed_calls(ours.call(cfg), None, 3, stats)
    error = float(np.max(np.abs(x - x_ref))) if status == "ok" else math.nan
    return dict(setup_s=setup, first_s=first, warm_s=warm, steps=steps, status=status,
                error_m=error, compile_phases_s=phases, **stats)  # fmt: skip


# JAX's compile events (`jax/_src/dispatch.py`), each the wall time of one top-level program's
# phase (a nested `jit` traced inside another is part of the outer one's time).
_COMPILE_EVENTS = {
    "/jax/core/compile/jaxpr_trace_duration": "trace",
    "/jax/core/compile/jaxpr_to_mlir_module_duration": "lower",
    "/jax/core/compile/backend_compile_duration": "xla_compile",
}


def _compile_phases() -> dict:
    """A dict that from now on sums the wall time [s] of JAX's tracing, lowering and XLA
    compiling (`_COMPILE_EVENTS`) in this process: where a cold first call's time goes."""
    import jax

    totals = dict.fromkeys(_COMPILE_EVENTS.values(), 0.0)

    def listener(event, duration, **_):
        if event in _COMPILE_EVENTS:
            totals[_COMPILE_EVENTS[event]] += duration

    jax.monitoring.register_event_duration_secs_listener(listener)
    return totals


def separate_accelerations_child(mode: str, rtol: float = 1e-5, root: str = ".") -> dict:
    """In a new process (`python -m benchmarks.work_precision separate-accelerations MODE`),
    no persistent cache: `breakdown`'s Tsit5 run (4001 saved times, q and q̇), its first call
    (trace, lower, compile, run) and its fastest of 5 warm calls, CPU seconds. `mode`
    "noinline": each evaluation of the accelerations in the step (`index1.
    stabilised_accelerations`: the stages and the step's end) made a separately compiled
    computation by `equinox.internal.noinline`, the mechanism that issue reports on JAX ODE
    solvers' compile time point to (equinox lowers it to a host callback into a separately
    jitted function); "inline": the program as it is."""
    import jax

    if mode == "noinline":
        import equinox.internal as eqxi

        from jaxdeploy.solvers import index1

        def accelerations(mechanism, q, v, t, memory, baumgarte, linear_solve):
            return mechanism.accelerations(q, v, t, memory, baumgarte, linear_solve)

        separate = eqxi.noinline(accelerations)
        index1.stabilised_accelerations = lambda *args: separate(*args)
    elif mode != "inline":
        raise ValueError(f"mode = {mode!r}: 'inline' or 'noinline'")
    ts, x_ref = load_reference(root)
    ours = _Ours(ts)
    run = ours.call(Config("", "jaxdeploy", "tsit5", rtol=rtol, outputs="motion"))
    cpu = time.process_time()
    x, _, status = run()
    first = time.process_time() - cpu
    warm = []
    for _ in range(5):
        cpu = time.process_time()
        jax.block_until_ready(run()[0])
        warm.append(time.process_time() - cpu)
    return {"mode": mode, "first_cpu_s": first, "warm_cpu_s": min(warm), "status": status,
            "error_m": float(np.max(np.abs(x - x_ref)))}  # fmt: skip


def separate_accelerations(root: str = ".") -> dict:
    """`separate_accelerations_child` in both modes, one new process each."""
    out = {}
    for mode in ("inline", "noinline"):
        paths = [os.path.abspath(root), os.environ.get("PYTHONPATH")]
        env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in paths if p)}
        command = [sys.executable, "-m", "benchmarks.work_precision", "separate-accelerations",
                   mode, "--root", root]  # fmt: skip
        done = subprocess.run(command, env=env, capture_output=True, text=True, cwd=root)
        if done.returncode != 0:
            return {"error": f"{mode}: {done.stderr[-2000:]}"}
        out[mode] = json.loads(done.stdout.strip().splitlines()[-1])
    return out


def new_process_first_calls(solver: str, rtol: float, root: str = ".") -> dict:
    """`first_call_child` twice with one new cache folder: empty (`cold`), then filled by the
    first run (`cached`)."""
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        paths = [os.path.abspath(root), os.environ.get("PYTHONPATH")]
        env = {**os.environ, "JAXDEPLOY_CACHE_DIR": os.path.join(tmp, "cache"),
               "PYTHONPATH": os.pathsep.join(p for p in paths if p)}  # fmt: skip
        env.pop("EQX_ON_ERROR", None)
        for run in ("cold", "cached"):
            command = [sys.executable, "-m", "benchmarks.work_precision", "first-call", solver,
                       repr(rtol), "--root", root]  # fmt: skip
            done = subprocess.run(command, env=env, capture_output=True, text=True, cwd=root)
            if done.returncode != 0:
                raise RuntimeError(f"first call of {solver} ({run}) failed: {done.stderr[-2000:]}")
            out[run] = json.loads(done.stdout.strip().splitlines()[-1])
    return out


def measure(quick: bool = False, repeats: int = 3, log=print, root: str = ".") -> dict:
    """Every configuration's row (module docstring) and what was measured."""
    from .exudyn_peer import exudyn_available, exudyn_version

    ts, x_ref = load_reference(root)
    ours = _Ours(ts)
    exudyn = exudyn_available()
    rows, compiled = [], {}
    todo = configurations(quick, exudyn)
    # The new processes first, while this one has compiled nothing to contend with them.
    families = [f for f in NEW_PROCESS_FAMILIES if any(c.solver == f for c in todo)]
    new_process = {}
    for solver in families[:1] if quick else families:
        first_cfg = next(c for c in todo if c.solver == solver and c.outputs == "motion")
        new_process[solver] = new_process_first_calls(solver, first_cfg.rtol, root)
        log(f"  new process, {solver} {first_cfg.setting}: " + ", ".join(
            f"{k} first {v['first_s']:.2f} s (setup {v['setup_s']:.2f} s)"
            for k, v in new_process[solver].items()))  # fmt: skip
    for number, cfg in enumerate(todo, 1):
        stats = {}
        (x, steps, status), first, warm = timed_calls(
            _call(cfg, ours, ts), np.full(ts.size, np.nan), repeats, stats
        )
        compile_s = math.nan
        if cfg.kind == "jaxdeploy":
            key = (cfg.solver, cfg.dt is None, cfg.outputs)
            if key not in compiled:
                compiled[key] = max(first - warm, 0.0)
            compile_s = compiled[key]
            first = compile_s + warm
        error = float(np.max(np.abs(x - x_ref))) if status == "ok" else math.nan
        row = Row(cfg.family, cfg.setting, cfg.kind, error, compile_s, first, warm, steps, status,
                  **stats)  # fmt: skip
        child = new_process.get(cfg.solver) if cfg.kind == "jaxdeploy" else None
        if child and cfg.rtol is not None and cfg.outputs == "motion" and status == "ok":
            # The family's program: the child's first call beyond its warm one, then this
            # configuration's own warm call.
            row.first_new_process_s = child["cold"]["first_s"] - child["cold"]["warm_s"] + warm
            row.first_cached_s = child["cached"]["first_s"] - child["cached"]["warm_s"] + warm
            row.first_s = row.first_new_process_s  # the cold first call a user meets
        rows.append(row)
        log(
            f"  [{number}/{len(todo)}] {cfg.family:38s} {cfg.setting:13s} err {error:9.2e} m "
            f"compile {compile_s:6.2f} s first {row.first_s:7.3f} s warm {warm:7.4f} s "
            f"({stats.get('warm_calls', 0)} calls) {status}"
        )
    return {
        "error_measure": "max |x_s - x_ref| [m] over the 4001 saved times 0..4 ms",
        "reference": REFERENCE,
        "horizon_s": float(ts[-1]),
        "repeats": repeats,
        "warm_statistic": f"fastest of at least {repeats} warm calls, more until they add up to "
        f"{WARM_BUDGET_S:g} s (at most {MAX_REPEATS})",
        "exudyn": exudyn_version() if exudyn else None,
        "new_process": new_process,
        "breakdown": breakdown(ours, ts, repeats=5 if quick else 20),
        "program_parts": program_parts(ours, ts),
        "separate_accelerations": separate_accelerations(root),
        "generalized_alpha_step": None if quick else generalized_alpha_operations(ours, ts),
        "rows": [asdict(r) for r in rows],
    }


def best_at_levels(rows: list[dict], levels, kinds, time_key: str) -> list[float]:
    """For each error level, the smallest `time_key` among `kinds`' rows with error ≤ level
    (NaN when none reaches it; rows read back from JSON have None for NaN, and a row without
    `time_key` or with no value there is left out)."""
    out = []
    for level in levels:
        times = [
            r[time_key]
            for r in rows
            if r["kind"] in kinds
            and r["error_m"] is not None
            and r["error_m"] <= level
            and r.get(time_key) is not None
            and not math.isnan(r[time_key])
        ]
        out.append(min(times) if times else math.nan)
    return out


def plot(result: dict, path: str) -> None:
    """Error against warm and against first-call wall time, one series per family."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(12, 5), sharey=True)
    families = dict.fromkeys(r["family"] for r in result["rows"])
    for key, ax in zip(("warm_s", "first_s"), axes, strict=True):
        for family in families:
            pts = sorted(
                (r[key], r["error_m"])
                for r in result["rows"]
                if r["family"] == family and (r["error_m"] or 0.0) > 0 and r[key] is not None
            )
            if pts:
                style = "-o" if family.startswith("jaxdeploy") else "--s"
                ax.loglog(*zip(*pts, strict=True), style, label=family, ms=4)
        ax.set_xlabel({"warm_s": "warm call [s]", "first_s": "first call [s]"}[key])
        ax.grid(True, which="both", alpha=0.3)
    axes[0].set_ylabel("max |x_s − x_ref| over 0–4 ms [m]")
    axes[1].legend(fontsize=7)
    fig.suptitle("slider_crank work–precision (one core)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def breakdown(ours, ts, rtol: float = 1e-5, repeats: int = 20) -> dict:
    """Where a warm Tsit5 call's time goes (rtol `rtol`, fastest CPU time of `repeats` calls
    each, alternated): the run as the table times it (`ts`: 4001 saved times), the same with
    the first and last time saved only (the save loop's share), and a run over the first
    2 µs (its ends saved: what a call costs besides its steps: checks, program dispatch,
    results; the same program as the second). Per step: the 2-saved-times run less the 2 µs
    run, over its steps (accepted and rejected)."""
    from jaxdeploy.simulation import simulate

    control = _control(ours.control, Config("", "jaxdeploy", "tsit5", rtol=rtol))
    cases = {"saved_4001": (float(ts[-1]), ts), "saved_2": (float(ts[-1]), ts[[0, -1]]),
             "horizon_2us": (float(ts[2]), ts[[0, 2]])}  # fmt: skip

    def call(case):
        t_end, saved = cases[case]
        tr = simulate(ours.mech, ours.s0, t_end, ts=saved, control=control, outputs="motion")
        np.asarray(tr.q)
        return tr

    steps = {c: int(call(c).stats["num_steps"]) for c in cases}
    cpu = {c: [] for c in cases}
    for _ in range(repeats):
        for c in cases:
            start = time.process_time()
            call(c)
            cpu[c].append(time.process_time() - start)
    best = {c: min(v) for c, v in cpu.items()}
    per_step = (best["saved_2"] - best["horizon_2us"]) / (steps["saved_2"] - steps["horizon_2us"])
    try:
        operations = loop_operations(ours, ts, control)
    except Exception as err:  # the count reads XLA's text, which may change: not a lost part
        operations = {"error": f"{type(err).__name__}: {err}"}
    return {
        "rtol": rtol,
        "cpu_s": best,
        "steps": steps,
        "per_step_s": per_step,
        "per_saved_time_s": (best["saved_4001"] - best["saved_2"]) / (ts.size - 2),
        "per_call_s": best["horizon_2us"],
        "operations": operations,
    }


_TRIVIAL = ("get-tuple-element", "bitcast", "parameter", "tuple", "constant")


def loop_operations(ours, ts, control) -> dict:
    """The operations XLA's CPU runtime executes one after another in the compiled program of
    `breakdown`'s run (`ts`: 4001 saved times): in the body of the step loop (the while loop of
    the entry computation, its nested loops not counted), in the body of the loop inside it
    over a step's Runge–Kutta stages, and in the body of the loop over the saved times within
    a step (the nested loop that carries the (4001, …) output buffers). An operation: every
    instruction of a loop body but tuple plumbing, bitcasts and constants (a fusion is one);
    `lapack`: LAPACK calls (factorisations and triangular solves) among them."""
    import re

    from jaxdeploy.simulation import _solve, prepare

    run = prepare(ours.mech, ours.s0, float(ts[-1]), ts=ts, control=control)
    args = (ours.mech, run.y0, run.t0, run.t_end, run.dt0, run.ts, run.solver, run.controller,
            run.max_steps, False, run.adjoint, "motion")  # fmt: skip
    text = re.sub(r"/\*.*?\*/", "", _solve.lower(*args).lowered.compile().as_text())
    bodies = {
        m.group(2): m.group(3)
        for m in re.finditer(r"^(ENTRY )?(%[\w.\-]+) [^\n]*\{\n(.*?)\n\}", text, re.M | re.S)
    }
    entry = re.search(r"^ENTRY (%[\w.\-]+)", text, re.M).group(1)

    def instructions(name):
        for line in bodies[name].split("\n"):
            line = re.sub(r", metadata=.*", "", line)
            m = re.match(r"\s*(ROOT )?%[\w.\-]+ = (.*)", line)
            op = m and re.search(r"(?:\)|\]|\}|\w) ([a-z][\w-]*)\(", m.group(2))
            if op and op.group(1) not in _TRIVIAL:
                yield op.group(1), line

    def count(name):
        ops = list(instructions(name))
        lapack = sum("lapack_" in line for _, line in ops)
        return {"operations": len(ops), "lapack": lapack}

    def loops(name):
        return [(re.search(r"body=(%[\w.\-]+)", line).group(1), line)
                for op, line in instructions(name) if op == "while"]  # fmt: skip

    # The step loop is the entry's largest loop (jaxdeploy's loop also has a small one of 100
    # `nextafter` for its end-time threshold).
    step = max((body for body, _ in loops(entry)), key=lambda body: len(bodies[body]))
    inner = loops(step)
    saves = [body for body, line in inner if f"[{ts.size}" in line]
    stages = [body for body, line in inner if f"[{ts.size}" not in line]
    return {
        "step_body": count(step),
        "stage_body": count(stages[0]) if len(stages) == 1 else None,
        "save_body": count(saves[0]) if len(saves) == 1 else None,
    }


def program_parts(ours, ts, rtol: float = 1e-5) -> dict:
    """What XLA compiles in `breakdown`'s Tsit5 program (`ts`: 4001 saved times, q and q̇
    saved) and what each part costs it: the whole program (`programs.compile_stats`: CPU
    seconds of tracing and lowering and of XLA's compile, operations, operations by part),
    then the same program with one part left out — the projection onto the constraints,
    the extremes' interior samples, event location — so that the difference in XLA's CPU
    seconds is that part's compile time (a measurement: operations alone do not say what
    XLA spends on them). The accelerations cannot be left out; their share is in the counts."""
    from dataclasses import replace

    from jaxdeploy.simulation import _solve, prepare

    from .programs import compile_stats

    control = _control(ours.control, Config("", "jaxdeploy", "tsit5", rtol=rtol))

    def without_projection(solver):  # TrackExtremes(MechanismODESolver(Tsit5))
        return replace(solver, solver=replace(solver.solver, project=False))

    variants = {
        "full": (control, {}, None),
        "without projection": (control, {}, without_projection),
        "without extremes' interior samples": (control, {"extreme_samples": 0}, None),
        "without event location": (control.replace(locate_events=False), {}, None),
    }
    out = {"solver": "tsit5", "rtol": rtol, "outputs": "motion"}
    try:
        for name, (chosen, options, change) in variants.items():
            run = prepare(ours.mech, ours.s0, float(ts[-1]), ts=ts, control=chosen, **options)
            solver = change(run.solver) if change else run.solver
            args = (ours.mech, run.y0, run.t0, run.t_end, run.dt0, run.ts, solver,
                    run.controller, run.max_steps, False, run.adjoint, "motion")  # fmt: skip
            out[name] = compile_stats(_solve, *args)[1]
    except Exception as err:  # reads XLA's text, which may change: not a lost part
        out["error"] = f"{type(err).__name__}: {err}"
    return out


if __name__ == "__main__":
    import argparse

    parser = argparse.ArgumentParser(prog="python -m benchmarks.work_precision")
    parser.add_argument("command", choices=["first-call", "separate-accelerations"])
    parser.add_argument("solver", help="first-call: the solver; separate-accelerations: the mode")
    parser.add_argument("rtol", type=float, nargs="?", default=1e-5)
    parser.add_argument("--root", default=".")
    args = parser.parse_args()
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
    if args.command == "first-call":
        print(json.dumps(first_call_child(args.solver, args.rtol, args.root)))
    else:
        print(json.dumps(separate_accelerations_child(args.solver, args.rtol, args.root)))


def generalized_alpha_operations(ours, ts) -> dict:
    """What a fixed generalized-α step executes (the step-cost target's runs, `ts`: the 4001
    saved times): the operations of the compiled step loop's body and of the Newton loop's
    body inside it (`loop_operations`), and the Newton iterations per step at the margin
    between h = 1 µs and 0.25 µs (the runs the step-cost ratio differences)."""
    from jaxdeploy.simulation import simulate

    try:
        counts = {}
        for h in (1e-6, 2.5e-7):
            control = _control(ours.control, Config("", "jaxdeploy", "generalized_alpha", dt=h))
            tr = simulate(ours.mech, ours.s0, float(ts[-1]), ts=ts, control=control,
                          outputs="motion")  # fmt: skip
            counts[h] = (int(tr.stats["num_steps"]), int(tr.stats["num_newton_iterations"]))
        ops = loop_operations(ours, ts, control)
        (steps1, its1), (steps2, its2) = counts[1e-6], counts[2.5e-7]
        return {
            "step_body": ops["step_body"],
            "newton_body": ops["stage_body"],
            "newton_per_step": (its2 - its1) / (steps2 - steps1),
        }
    except Exception as err:  # the count reads XLA's text, which may change: not a lost part
        return {"error": f"{type(err).__name__}: {err}"}
