"""Work–precision benchmark: every solver configuration against a reference, in one run.

For each configuration: the error against the reference (relative clearance-joint
eccentricity, over the reference window and over the full horizon; `reference.py`), wall time
(median of up to `repeats` runs after a first, compiling run, fewer once the timed runs
exceed `TIMING_BUDGET_S`; compile time = first run − median),
steps, rejected steps, Newton iterations (generalized-α), and the peak resident memory: of the
configuration's own worker process when each runs in one under a wall-time budget
(`run_benchmark(..., budget_s=...)`, needed where some configurations take hours, e.g. Kvaerno5
on deploy_array), otherwise the process's monotone maximum (it shows which configuration first
needed more memory, not each one's own footprint).
"""

from __future__ import annotations

import resource
import time
from dataclasses import asdict, dataclass

import numpy as np

from ..scenes import get_scene
from ..simulation import simulate
from ..solvers import GeneralizedAlpha, solver_by_name
from .reference import PEER_SCENE_OPTIONS, Reference, eccentricity_error, reference_solution


@dataclass
class Config:
    """One benchmarked configuration."""

    family: str  # plot series, e.g. "gen-α fixed ρ∞=0.8"
    label: str  # e.g. "h=1e-06"
    kind: str  # "jaxdeploy", "scipy-numpy", "scipy-jitted", "exudyn"
    solver: str
    rtol: float | None = None
    atol: float | None = None
    dt: float | None = None
    rho_inf: float = 0.8
    dt_max: float | None = None
    force_function: str = "python"  # Exudyn's clearance force: "python" or "symbolic"


@dataclass
class Row:
    family: str
    label: str
    kind: str
    error_window: float
    error_full: float
    wall_s: float
    compile_s: float
    steps: int
    rejected: int
    newton_iterations: int
    peak_rss_mb: float
    status: str


def exudyn_configurations(scene_name: str, quick: bool) -> list[Config]:
    """Exudyn's generalized-α with fixed steps on slider_crank (`exudyn_peer.py`): none when
    exudyn is not importable or for other scenes. Exudyn's generalized-α has no
    error-controlled step size, so there is no adaptive Exudyn configuration."""
    from .exudyn_peer import exudyn_available

    if scene_name != "slider_crank" or not exudyn_available():
        return []
    sweep = [  # (ρ∞, force function, steps)
        (0.8, "python", (4e-6, 1e-6, 2.5e-7)),
        (0.8, "symbolic", (4e-6, 1e-6, 2.5e-7)),
        (0.5, "python", (1e-6,)),
    ]
    if quick:
        sweep = [(0.8, "python", (1e-6,)), (0.8, "symbolic", (1e-6,))]
    return [
        Config(
            f"Exudyn gen-α fixed ρ∞={rho}" + (", symbolic force" if force == "symbolic" else ""),
            f"h={h:.2g}",
            "exudyn",
            "generalized_alpha",
            dt=h,
            rho_inf=rho,
            force_function=force,
        )
        for rho, force, steps in sweep
        for h in steps
    ]


def configurations(scene_name: str, quick: bool) -> list[Config]:
    """The configurations benchmarked on a scene (`quick`: a handful, for tests), with the
    Exudyn ones appended when exudyn is installed (`exudyn_configurations`)."""
    return _own_and_scipy_configurations(scene_name, quick) + exudyn_configurations(
        scene_name, quick
    )


def _own_and_scipy_configurations(scene_name: str, quick: bool) -> list[Config]:
    out = []
    if quick:
        out += [
            Config("gen-α fixed ρ∞=0.8", "h=1e-06", "jaxdeploy", "generalized_alpha", dt=1e-6),
            Config(
                "gen-α adaptive ρ∞=0.8",
                "rtol=1e-06",
                "jaxdeploy",
                "generalized_alpha",
                rtol=1e-6,
                atol=1e-9,
            ),
            Config("diffrax Kvaerno5", "rtol=1e-06", "jaxdeploy", "kvaerno5", 1e-6, 1e-9),
        ]
        if scene_name == "slider_crank":
            out += [
                Config("scipy DOP853 (numpy)", "rtol=1e-06", "scipy-numpy", "DOP853", 1e-6, 1e-9),
                Config("scipy LSODA (jitted)", "rtol=1e-06", "scipy-jitted", "LSODA", 1e-6, 1e-9),
            ]
        return out
    # A sweep sized for a shared 2-core machine (each configuration compiles once).
    if scene_name == "slider_crank":
        steps, sub = [4e-6, 1e-6, 2.5e-7], [1e-6]
    else:
        # Fixed steps of 1e-5 s and longer fail at the lock (Newton diverges in the hinge
        # contacts' stiff phase after the latch engages, t ≈ 0.54 s): one such row shows it.
        steps, sub = [1e-5, 2.5e-6], [2.5e-6]
    for rho in (0.8, 0.5, 0.9):
        for h in steps if rho == 0.8 else sub:
            out.append(
                Config(
                    f"gen-α fixed ρ∞={rho}",
                    f"h={h:.2g}",
                    "jaxdeploy",
                    "generalized_alpha",
                    dt=h,
                    rho_inf=rho,
                )
            )
    for tol in [1e-5, 1e-6, 1e-7]:
        out.append(
            Config(
                "gen-α adaptive ρ∞=0.8",
                f"rtol={tol:.0e}",
                "jaxdeploy",
                "generalized_alpha",
                tol,
                tol * 1e-3,
            )
        )
    diffrax_tolerances = {
        "kvaerno5": [1e-5, 1e-7, 1e-9],
        "kvaerno3": [1e-6],
        "tsit5": [1e-6, 1e-8, 1e-10],
        "dopri8": [1e-8, 1e-9, 1e-10, 1e-11, 1e-12],
    }
    if scene_name == "deploy_array":
        # Each configuration compiles in its own budgeted worker, and the implicit solvers
        # take ~0.24 s per step here (hours per run): one tolerance each shows that.
        diffrax_tolerances = {
            "kvaerno5": [1e-6],
            "kvaerno3": [1e-6],
            "tsit5": [1e-6, 1e-8],
            "dopri8": [1e-8, 1e-10],
        }
    for solver, solver_tols in diffrax_tolerances.items():
        for tol in solver_tols:
            out.append(
                Config(
                    f"diffrax {solver.capitalize()}",
                    f"rtol={tol:.0e}",
                    "jaxdeploy",
                    solver,
                    tol,
                    tol * 1e-3,
                )
            )
    if scene_name == "slider_crank":
        for method in ("Radau", "BDF", "LSODA", "DOP853"):
            for tol in (1e-6, 1e-9) if method != "DOP853" else (1e-6, 1e-9, 1e-12):
                out.append(
                    Config(
                        f"scipy {method} (numpy)",
                        f"rtol={tol:.0e}",
                        "scipy-numpy",
                        method,
                        tol,
                        tol * 1e-3,
                    )
                )
            out.append(
                Config(f"scipy {method} (jitted)", "rtol=1e-06", "scipy-jitted", method, 1e-6, 1e-9)
            )
    return out


def _peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _run_jaxdeploy(cfg: Config, mech, s0, ts, t_end):
    if cfg.solver == "generalized_alpha":
        solver = GeneralizedAlpha(rho_inf=cfg.rho_inf)
    else:
        solver = solver_by_name(cfg.solver, rtol=cfg.rtol, atol=cfg.atol)
    tr = simulate(
        mech,
        s0,
        t_end,
        ts=ts,
        dt=cfg.dt,
        rtol=cfg.rtol,
        atol=cfg.atol,
        dt_max=cfg.dt_max,
        solver=solver,
        max_steps=5_000_000,
    )
    tr.q.block_until_ready()
    stats = tr.stats
    return (
        np.asarray(tr.q),
        int(stats["num_accepted_steps"]),
        int(stats["num_rejected_steps"]),
        int(stats.get("num_newton_iterations", -1)),
        tr.status(),
    )


def _run_scipy(cfg: Config, model, y0, ts, t_end):
    from .peers import solve_with_onset_events

    run = solve_with_onset_events(*model, y0, (0.0, t_end), ts, cfg.solver, cfg.rtol, cfg.atol)
    n = y0.size // 2
    # solve_ivp does not report rejected steps or Newton iterations.
    return run.ys[:, :n], run.n_steps, -1, -1, "ok" if run.ok else run.message


def _run_exudyn(cfg: Config, model, ts, t_end):
    spacing = float(ts[1] - ts[0]) if len(ts) > 1 else t_end
    for length, name in ((t_end, "the horizon"), (spacing, "the output spacing")):
        ratio = length / cfg.dt
        if abs(ratio - round(ratio)) > 1e-6 * ratio:
            nan = np.full((len(ts), 9), np.nan)
            return nan, 0, -1, -1, f"skipped: h={cfg.dt:g} s does not divide {name}"
    run = model.solve(cfg.dt, t_end, ts)
    return run.q, run.steps, run.rejected, run.newton_iterations, run.message


# Repeats stop once the timed runs of one configuration add up to this many seconds: a run
# that long is timed to well under the machine's noise by itself, and repeating the slowest
# peers three times would double the benchmark's length for no information.
TIMING_BUDGET_S = 60.0


def benchmark_reference(
    scene_name: str, *, quick: bool = False, t_end: float | None = None, n_save: int | None = None
) -> Reference:
    """The reference a benchmark of `scene_name` measures errors against (`reference.py`):
    Dopri8 at rtol 1e-12 on 1201 output times over the scene's horizon (`quick`: 1e-10, 61
    times over 0.6 ms for slider_crank, 0.1 s otherwise)."""
    if t_end is None and quick:
        t_end = 0.6e-3 if scene_name == "slider_crank" else 0.1
    return reference_solution(
        scene_name,
        t_end=t_end,
        n_save=n_save or (61 if quick else 1201),
        rtol=1e-10 if quick else 1e-12,
    )


def run_benchmark(
    scene_name: str,
    reference: Reference,
    *,
    quick: bool = False,
    repeats: int = 3,
    done: list[Row] = (),
    on_row=None,
    log=print,
    budget_s: float | None = None,
    reference_folder: str | None = None,
) -> list[Row]:
    """Run every configuration of `configurations(scene_name, quick)` that is not in `done`
    (rows of an interrupted run, matched by family, label and kind) against `reference`
    (`benchmark_reference`), calling `on_row(rows)` with all rows so far after each one, so
    that a caller can write them before the next configuration starts.

    With `budget_s`, each configuration runs in a worker process of its own (it loads the
    reference that `Reference.save` wrote into `reference_folder`) and is stopped after
    `budget_s` seconds of wall time, compilation and repeats included: its row then says so
    (status "over budget"), and the benchmark goes on. The peak memory is then the worker's
    own, not the process-wide maximum.

    **Returns:** the rows, in configuration order.
    """
    if budget_s is not None and reference_folder is None:
        raise ValueError("budget_s needs reference_folder (where Reference.save wrote it)")
    context = None if budget_s is not None else _Context(scene_name, reference)
    finished = {(r.family, r.label, r.kind): r for r in done}
    rows = []
    if scene_name == "slider_crank":
        from .exudyn_peer import ExudynUnavailable, exudyn_version

        try:
            log(f"Exudyn {exudyn_version()}: its generalized-α runs as a peer")
        except ExudynUnavailable as err:
            log(f"  {err}")
    todo = configurations(scene_name, quick)
    for number, cfg in enumerate(todo, 1):
        if (cfg.family, cfg.label, cfg.kind) in finished:
            rows.append(finished[(cfg.family, cfg.label, cfg.kind)])
            log(f"  [{number}/{len(todo)}] {cfg.family} {cfg.label}: done in an earlier run")
            continue
        if budget_s is None:
            row = context.measure(cfg, repeats)
        else:
            row = _measure_in_worker(scene_name, reference_folder, cfg, repeats, budget_s)
        log(
            f"  [{number}/{len(todo)}] {cfg.family:34s} {cfg.label:11s} err "
            f"{row.error_window:9.2e} / {row.error_full:9.2e}  wall {row.wall_s:8.3f}s "
            f"compile {row.compile_s:6.1f}s steps {row.steps} rej {row.rejected} {row.status}"
        )
        rows.append(row)
        if on_row is not None:
            on_row(rows)
    return rows


class _Context:
    """The scene's mechanism, initial state and reference, and the peers' models built so far
    (shared by the configurations measured in one process)."""

    def __init__(self, scene_name: str, reference: Reference):
        scene = get_scene(scene_name, **PEER_SCENE_OPTIONS.get(scene_name, {}))
        self.params = reference.params
        self.mech = scene.build(self.params)
        self.s0 = scene.initial_state(self.params, self.mech)
        # The numpy peer models the same rule as the scene (only slider_crank has the peer).
        self.impact_velocity_rule = getattr(scene, "impact_velocity_rule", "onset")
        self.reference = reference
        self.ts = reference.ts
        self.t_end = float(self.ts[-1])
        self.models = {}

    def _call(self, cfg: Config):
        """A function running `cfg` once: `(q, steps, rejected, newton, status)`."""
        if cfg.kind == "jaxdeploy":
            return lambda: _run_jaxdeploy(cfg, self.mech, self.s0, self.ts, self.t_end)
        if cfg.kind == "exudyn":
            key = ("exudyn", cfg.rho_inf, cfg.force_function)
            if key not in self.models:
                from .exudyn_peer import ExudynSliderCrank

                self.models[key] = ExudynSliderCrank(
                    self.params,
                    np.asarray(self.s0.q),
                    np.asarray(self.s0.v),
                    rho_inf=cfg.rho_inf,
                    force_function=cfg.force_function,
                )
            model = self.models[key]
            return lambda: _run_exudyn(cfg, model, self.ts, self.t_end)
        if cfg.kind not in self.models:
            from .peers import SliderCrankNumpy, jitted_rhs

            if cfg.kind == "scipy-numpy":
                m = SliderCrankNumpy(self.params, self.impact_velocity_rule)
                self.models[cfg.kind] = (
                    m.rhs,
                    m.penetration,
                    m.penetration_rate,
                    m.penetration_acceleration,
                )
            else:
                self.models[cfg.kind] = jitted_rhs(self.mech)
        model = self.models[cfg.kind]
        y0 = np.concatenate([np.asarray(self.s0.q), np.asarray(self.s0.v)])
        return lambda: _run_scipy(cfg, model, y0, self.ts, self.t_end)

    def measure(self, cfg: Config, repeats: int) -> Row:
        """Run `cfg` once (compiling), then time up to `repeats` runs; its row."""
        call = self._call(cfg)
        compiled = cfg.kind not in ("scipy-numpy", "exudyn")
        start = time.perf_counter()
        q, steps, rejected, newton, status = call()
        first = time.perf_counter() - start
        # A path without compilation whose first run alone used the budget is timed by it.
        walls = [first] if not compiled and first >= TIMING_BUDGET_S else []
        while len(walls) < repeats and sum(walls) < TIMING_BUDGET_S:
            start = time.perf_counter()
            call()
            walls.append(time.perf_counter() - start)
        wall = float(np.median(walls))
        # Compile time is meaningful for the jitted paths only (scipy-jitted: the RHS).
        compile_s = max(first - wall, 0.0) if compiled else 0.0
        ref = self.reference
        window, full = eccentricity_error(self.mech, q, ref.q, self.ts, ref.window_end)
        return Row(
            cfg.family,
            cfg.label,
            cfg.kind,
            window,
            full,
            wall,
            compile_s,
            steps,
            rejected,
            newton,
            _peak_rss_mb(),
            status,
        )


def _worker(scene_name, reference_folder, cfg, repeats, connection, cache_dir):
    """Body of a budgeted worker process: measure `cfg` and send its row (or the error).
    `cache_dir`: the parent's persistent compilation cache, so that configurations of one
    compiled program (e.g. generalized-α at several h: the step is data) compile once, as
    they do in one process."""
    try:
        if cache_dir:
            import jax

            jax.config.update("jax_compilation_cache_dir", cache_dir)
        context = _Context(scene_name, Reference.load(reference_folder))
        connection.send(context.measure(cfg, repeats))
    except Exception as err:  # reported in the row, never lost with the worker
        connection.send(f"{type(err).__name__}: {err}")
    finally:
        connection.close()


def _measure_in_worker(scene_name, reference_folder, cfg, repeats, budget_s) -> Row:
    """`_Context.measure` of `cfg` in a fresh process, stopped after `budget_s` seconds."""
    import multiprocessing

    import jax

    # spawn: a fork of a process that has started JAX's threads can deadlock.
    mp = multiprocessing.get_context("spawn")
    receiver, sender = mp.Pipe(duplex=False)
    cache_dir = jax.config.jax_compilation_cache_dir
    worker = mp.Process(
        target=_worker,
        args=(scene_name, reference_folder, cfg, repeats, sender, cache_dir),
        daemon=True,
    )
    start = time.perf_counter()
    worker.start()
    sender.close()
    result = receiver.recv() if receiver.poll(budget_s) else None
    elapsed = time.perf_counter() - start
    if worker.is_alive():
        worker.kill()
    worker.join()
    if isinstance(result, Row):
        return result
    status = (
        f"over budget: not finished after {elapsed:.0f} s (compilation included)"
        if result is None
        else f"failed: {result}"
    )
    nan = float("nan")
    return Row(cfg.family, cfg.label, cfg.kind, nan, nan, nan, nan, -1, -1, -1, nan, status)


def rows_as_dicts(rows: list[Row]) -> list[dict]:
    return [asdict(r) for r in rows]
