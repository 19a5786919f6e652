"""Work–precision on Andrews' squeezing mechanism (Hairer & Wanner, *Solving Ordinary
Differential Equations II*, 2nd ed. 1996, §VII.7; the Test Set for IVP Solvers of Mazzia &
Magherini, problem "andrews": seven bodies, an index-3 DAE of dimension 27, t ∈ [0, 0.03] s).

Error: the Test Set's own measure, the largest relative error of the seven angles
(β, Θ, γ, Φ, δ, Ω, ε) at t = 0.03 s against its published reference solution (PSIDE at
rtol = atol = 1e-14); `tests/independent/andrews_squeezer.py` carries it.

Sides:
* jaxdeploy: the squeezer built with the public mechanism API (`tests/andrews_mechanism.py`:
  absolute coordinates, ten revolutes, a spring and a torque), adaptive generalized-α with
  ρ∞ = 1 (no numerical damping) on the index-3 form, Tsit5 and Dopri8 on the index-1 ODE with
  coordinate projection; atol = rtol (the Test Set's convention).
* scipy: what a user would write — the benchmark's relative-angle equations with the index-1
  form solved at each right-hand-side evaluation (`tests/independent/andrews_squeezer.py`,
  numpy only), `solve_ivp` with DOP853, Radau and LSODA at atol = rtol.

Timing as in `benchmarks.work_precision` (one process pinned to one core; compile = a family's
first call minus its warm call; first call = compile + warm; warm = the fastest warm call,
`work_precision.timed_calls`).
"""

from __future__ import annotations

import math
import os
import sys
from dataclasses import asdict

import numpy as np

from .work_precision import Config, Row, timed_calls

HORIZON_S = 0.03


def _tests_on_path(root: str) -> None:
    """The model builders live with the tests (`tests/andrews_mechanism.py` and the independent
    reference beside it); a source checkout is required, as for the other bench parts."""
    folder = os.path.abspath(os.path.join(root, "tests"))
    if folder not in sys.path:
        sys.path.insert(0, folder)


def configurations(quick: bool) -> list[Config]:
    ours = {
        "generalized_alpha": [1e-6, 1e-8, 1e-10, 1e-12],
        "tsit5": [1e-6, 1e-8, 1e-10],
        "dopri8": [1e-6, 1e-8, 1e-10, 1e-12],
    }
    peers = {"DOP853": [1e-6, 1e-8, 1e-10, 1e-12], "Radau": [1e-6, 1e-8], "LSODA": [1e-6, 1e-8]}
    if quick:
        ours = {"generalized_alpha": [1e-6], "dopri8": [1e-8]}
        peers = {"DOP853": [1e-8], "Radau": [1e-6]}
    out = []
    for solver, tolerances in ours.items():
        name = {"generalized_alpha": "generalized-α adaptive ρ∞=1"}.get(solver, solver.capitalize())
        out += [Config(f"jaxdeploy {name}", "jaxdeploy", solver, rtol=t) for t in tolerances]
    for method, tolerances in peers.items():
        out += [Config(f"scipy {method}", "scipy", method, rtol=t) for t in tolerances]
    return out


def _runner(cfg: Config):
    """A callable returning `(angles at t_end, steps, status)`."""
    if cfg.kind == "scipy":
        from independent.andrews_squeezer import AndrewsSqueezer

        model = AndrewsSqueezer()

        def run():
            sol = model.solve(HORIZON_S, rtol=cfg.rtol, atol=cfg.rtol, method=cfg.solver)
            return sol.y[:7, -1], int(sol.nfev), "ok" if sol.success else sol.message

        return run
    import andrews_mechanism

    from jaxdeploy.simulation import simulate
    from jaxdeploy.solvers import GeneralizedAlpha

    mech = andrews_mechanism.build()
    s0 = andrews_mechanism.initial_state(mech)
    solver = GeneralizedAlpha(rho_inf=1.0) if cfg.solver == "generalized_alpha" else cfg.solver

    def run():
        tr = simulate(mech, s0, HORIZON_S, n_save=2, solver=solver, rtol=cfg.rtol, atol=cfg.rtol,
                      max_steps=400_000)  # fmt: skip
        angles = andrews_mechanism.benchmark_angles(np.asarray(tr.q[-1]))
        return angles, int(tr.stats["num_accepted_steps"]), tr.status()

    return run


def measure(quick: bool = False, repeats: int = 3, log=print, root: str = ".") -> dict:
    """Every configuration's row (module docstring)."""
    _tests_on_path(root)
    from independent.andrews_squeezer import TEST_SET_SOLUTION

    reference = np.asarray(TEST_SET_SOLUTION["q"])
    rows, compiled = [], {}
    for number, cfg in enumerate(configurations(quick), 1):
        (angles, steps, status), first, warm = timed_calls(
            _runner(cfg), np.full(7, np.nan), repeats
        )
        compile_s = math.nan
        if cfg.kind == "jaxdeploy":
            # Tolerances are data of the compiled program: a family compiles once.
            if cfg.solver not in compiled:
                compiled[cfg.solver] = max(first - warm, 0.0)
            compile_s = compiled[cfg.solver]
            first = compile_s + warm
        error = float(np.max(np.abs(np.asarray(angles) - reference) / np.abs(reference)))
        row = asdict(Row(cfg.family, cfg.setting, cfg.kind, math.nan, compile_s, first, warm,
                         steps, status))  # fmt: skip
        del row["error_m"]  # this error is relative (dimensionless), not metres
        rows.append({"error_rel": error if status == "ok" else math.nan, **row})
        log(f"[andrews {number}] {cfg.family} {cfg.setting}: error {error:.2e}, warm "
            f"{warm:.3g} s, steps {steps}, {status}")  # fmt: skip
    return {
        "rows": rows,
        "error": "max over the 7 angles of |q − q_ref| / |q_ref| at t = 0.03 s, q_ref the Test "
        "Set's published solution",
        "horizon_s": HORIZON_S,
    }
