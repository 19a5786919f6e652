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
  (jaxdeploy), the first run (peers: scipy has nothing to compile; Exudyn: building and
  assembling the model included).
* warm [s] — median of `repeats` further calls (fewer once they add up to `TIMING_BUDGET_S`).
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass

import numpy as np

REFERENCE = "tests/data/slider_crank_reference.npz"
HORIZON_S = 4e-3
# A configuration's timed repeats stop once they add up to this many seconds.
TIMING_BUDGET_S = 20.0


@dataclass
class Config:
    family: str  # one series of the plot, e.g. "jaxdeploy Tsit5"
    kind: str  # "jaxdeploy", "scipy", "exudyn"
    solver: str  # jaxdeploy solver name, scipy method, or "generalized_alpha" (Exudyn)
    rtol: float | None = None
    dt: float | None = None  # fixed step [s]
    force_function: str = "python"  # Exudyn only

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


def configurations(quick: bool, exudyn: bool) -> list[Config]:
    """Ours at several tolerances or steps, the scipy peers at several tolerances, and Exudyn
    (when importable) at several fixed steps. `quick`: one or two of each, for tests."""
    ours = {
        "tsit5": [1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10],
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

        if cfg.dt is not None:
            control = self.control.replace(solver=cfg.solver, rtol=None, atol=None, dt=cfg.dt,
                                           dt_max=None, max_steps=100_000)  # fmt: skip
        else:
            control = self.control.replace(solver=cfg.solver, rtol=cfg.rtol,
                                           atol=1e-3 * cfg.rtol, max_steps=1_000_000)  # fmt: skip

        def run():
            tr = simulate(self.mech, self.s0, float(self.ts[-1]), ts=self.ts, control=control)
            q = np.asarray(tr.q)
            return q[:, 6], int(tr.stats["num_accepted_steps"]), tr.status()

        return run


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


def timed_calls(run, failed_output, repeats: int):
    """`((output, steps, status), first, warm)` of a configuration's callable `run`: the first
    call's wall time, then the median of up to `repeats` further calls (fewer once they add up
    to `TIMING_BUDGET_S`; NaN when the first call did not end "ok"). A call that raises is a
    row with `failed_output`, not a lost benchmark."""
    start = time.perf_counter()
    try:
        result = run()
    except Exception as err:
        result = (failed_output, -1, f"failed: {err}")
    first = time.perf_counter() - start
    walls = []
    while result[2] == "ok" and len(walls) < repeats and sum(walls) < TIMING_BUDGET_S:
        start = time.perf_counter()
        run()
        walls.append(time.perf_counter() - start)
    return result, first, float(np.median(walls)) if walls else math.nan


def measure(quick: bool = False, repeats: int = 3, log=print, root: str = ".") -> dict:
    """Every configuration's row (module docstring) and what was measured."""
    from .exudyn_peer import exudyn_available, exudyn_version

    ts, x_ref = load_reference(root)
    ours = _Ours(ts)
    exudyn = exudyn_available()
    rows, compiled = [], {}
    todo = configurations(quick, exudyn)
    for number, cfg in enumerate(todo, 1):
        (x, steps, status), first, warm = timed_calls(
            _call(cfg, ours, ts), np.full(ts.size, np.nan), repeats
        )
        compile_s = math.nan
        if cfg.kind == "jaxdeploy":
            key = (cfg.solver, cfg.dt is None)
            if key not in compiled:
                compiled[key] = max(first - warm, 0.0)
            compile_s = compiled[key]
            first = compile_s + warm
        error = float(np.max(np.abs(x - x_ref))) if status == "ok" else math.nan
        row = Row(cfg.family, cfg.setting, cfg.kind, error, compile_s, first, warm, steps, status)
        rows.append(row)
        log(
            f"  [{number}/{len(todo)}] {cfg.family:38s} {cfg.setting:13s} err {error:9.2e} m "
            f"compile {compile_s:6.2f} s first {first:7.3f} s warm {warm:7.3f} s {status}"
        )
    return {
        "error_measure": "max |x_s - x_ref| [m] over the 4001 saved times 0..4 ms",
        "reference": REFERENCE,
        "horizon_s": float(ts[-1]),
        "repeats": repeats,
        "exudyn": exudyn_version() if exudyn else None,
        "rows": [asdict(r) for r in rows],
    }


def best_at_levels(rows: list[dict], levels, kinds, time_key: str) -> list[float]:
    """For each error level, the smallest `time_key` among `kinds`' rows with error ≤ level
    (NaN when none reaches it; rows read back from JSON have None for NaN)."""
    out = []
    for level in levels:
        times = [
            r[time_key]
            for r in rows
            if r["kind"] in kinds and r["error_m"] is not None and r["error_m"] <= level
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
