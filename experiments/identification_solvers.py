"""Which Levenberg–Marquardt fits our problems (issue 20 item 4): the package's
`jaxdeploy.fit.levenberg_marquardt` (Marquardt's diagonal scaling, Nielsen's damping update)
against optimistix's `LevenbergMarquardt` (identity damping in the internal coordinates, a
classical trust region), stepped trial by trial as the package did from 93ac379 to this
script's commit (`optimistix_lm` below: the same stopping rules, the same model, the same
reporting). Both are handed to `jaxdeploy.fit.fit(..., optimiser=...)` on the same stages.

Problems, each from several starts 10–20 % off the truth, with the command's defaults (model
tolerance chosen from the noise at the start, horizons from the start run's impacts):

* `impact`: synthetic journal position and acceleration through one damped impact (1 % noise;
  the model made the data), restitution and contact stiffness;
* `readme`: the README's slider-crank record (0–4 ms, independent reference, σ = 1 µm),
  clearance and restitution;
* `mu0_12ms`, `friction_12ms`: the 12 ms records without and with friction (μ fitted too).

A start "reached the truth" when the fit converged and every truth lies within 3 reported
standard errors of its estimate. Each fit's record (estimates, trial steps, model
evaluations, wall and CPU time, load average) is kept in
`docs/figures/identification_solvers/results.json` with the commit it ran at; a rerun keeps
the recorded fits and runs only what is missing (`--rerun` runs everything again; `--only`
and `--no-fits` restrict what runs), and the block names the commits. Writes the
"identification_solvers" block of docs/identification.md.

Usage: `PYTHONPATH=. nice -n 10 python experiments/identification_solvers.py [--only NAME]`.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import time

os.environ.setdefault("EQX_ON_ERROR", "nan")  # cacheable programs (persistent cache below)

import jax  # noqa: E402
import numpy as np  # noqa: E402

from jaxdeploy import pages  # noqa: E402
from jaxdeploy.fit import (  # noqa: E402
    Comparison,
    ResidualSpec,
    choose_tolerance,
    fit,
    impact_horizons,
    levenberg_marquardt,
    load_measurements,
    onset_times,
    synthesize,
)
from jaxdeploy.scenes import get_scene  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
OUT = os.path.join(ROOT, "docs", "figures", "identification_solvers")
CPU = os.cpu_count()

SC = {"clearance": 0.5e-3, "restitution": 0.9, "friction_coefficient": 0.01}
PROBLEMS = {
    "impact": dict(
        scene=("impact", {"damping": "lankarani_nikravesh"}),
        data="synthetic",
        truth={"restitution": 0.7, "stiffness": 1e10},
        bounds={"restitution": (0.05, 0.99), "stiffness": (1e8, 1e12)},
        starts=[(0.805, 1.2e10), (0.595, 0.8e10), (0.805, 0.8e10), (0.595, 1.2e10)],
    ),
    "readme": dict(
        scene=("slider_crank", {}),
        data="examples/slider_crank_slider_x.csv",
        truth={k: SC[k] for k in ("clearance", "restitution")},
        starts=[(6e-4, 0.72), (4.5e-4, 0.8), (5.5e-4, 0.765)],
    ),
    "mu0_12ms": dict(
        scene=("slider_crank", {}),
        data="examples/slider_crank_slider_x_12ms.csv",
        truth={k: SC[k] for k in ("clearance", "restitution")},
        starts=[(6e-4, 0.72), (4.5e-4, 0.8)],
    ),
    "friction_12ms": dict(
        scene=("slider_crank", {"friction_shape": "tanh"}),
        data="examples/slider_crank_friction_slider_x_12ms.csv",
        truth=SC,
        starts=[(6e-4, 0.72, 0.012), (4.5e-4, 0.8, 0.009)],
    ),
}


def _linearisation(z, args):
    """The model as optimistix sees it: its linearisation r₀ + J₀ (z − z₀) at the point z₀
    where the solver evaluates next."""
    r0, jac0, z0 = args
    return r0 + jac0 @ (z - z0), None


_STEP = None


def _step(solver, y, args, state):
    global _STEP
    if _STEP is None:
        import equinox as eqx

        _STEP = eqx.filter_jit(
            lambda solver, y, args, state: solver.step(
                _linearisation, y, args, {}, state, frozenset()
            )
        )
    return _STEP(solver, y, args, state)


def optimistix_lm(model, z0, *, max_iterations=30, ftol=1e-8, ctol=0.0, xtol=1e-8,
                  zmax=math.inf, callback=None):  # fmt: skip
    """optimistix's `LevenbergMarquardt` (lineax QR on [J; √λ I] h = −[r; 0], classical
    trust-region update of λ; Conn, Gould & Toint, *Trust-Region Methods*, 2000, Alg. 6.1.1),
    stepped one trial point at a time: each `step` is handed the model's linearisation at its
    trial point `state.y_eval`. A failed simulation enters as r = +inf (rejected). Same
    signature, stopping rules and return value as `jaxdeploy.fit.levenberg_marquardt`."""
    import jax.numpy as jnp
    import lineax as lx
    import optimistix as optx

    z = np.clip(np.asarray(z0, dtype=float), -zmax, zmax)
    r, jac, aux, ok = model(z)
    if not ok:
        raise RuntimeError("the model cannot be evaluated at the initial guess")
    aux0 = aux
    solver = optx.LevenbergMarquardt(rtol=xtol, atol=xtol, linear_solver=lx.QR())
    args = (jnp.asarray(r), jnp.asarray(jac), jnp.asarray(z))
    y = jnp.asarray(z)
    state = solver.init(_linearisation, y, args, {}, jax.ShapeDtypeStruct(r.shape, r.dtype),
                        None, frozenset())  # fmt: skip
    y, state, _ = _step(solver, y, args, state)  # the first step accepts the start
    cost = 0.5 * float(r @ r)
    history = [dict(iteration=0, cost=cost, accepted=True, step=0.0, z=z.tolist())]
    if callback:
        callback(history[-1])
    evaluations, converged, message, iteration = 1, False, "maximum number of iterations", 0
    jac_seen = jac
    for iteration in range(1, max_iterations + 1):
        trial = np.asarray(state.y_eval)
        h = trial - np.asarray(y)
        predicted = 0.5 * float(r @ r) - 0.5 * float(np.sum((r + jac_seen @ h) ** 2))
        if np.linalg.norm(h) <= xtol * (np.linalg.norm(trial) + xtol):
            iteration -= 1
            converged, message = True, "step below tolerance"
            break
        if predicted < ctol:
            iteration -= 1
            converged, message = True, "predicted decrease below ctol"
            break
        clipped = np.abs(trial) > zmax
        z_trial = np.clip(trial, -zmax, zmax)
        r_new, jac_new, aux_new, ok = model(z_trial)
        evaluations += 1
        if ok:
            args = (jnp.asarray(r_new), jnp.asarray(np.where(clipped, 0.0, jac_new)), trial)
        else:
            args = (jnp.full_like(r, jnp.inf), jnp.zeros_like(jac), trial)
        y_before = np.asarray(y)
        y, state, _ = _step(solver, y, args, state)
        accepted = ok and bool(np.array_equal(np.asarray(y), trial))
        cost_new = 0.5 * float(r_new @ r_new) if ok else math.inf
        history.append(dict(iteration=iteration, cost=cost_new, accepted=accepted,
                            step=float(np.linalg.norm(trial - y_before)), z=z_trial.tolist(),
                            simulation_ok=ok))  # fmt: skip
        if callback:
            callback(history[-1])
        if accepted:
            decrease = cost - cost_new
            z, r, jac, aux, cost = z_trial, r_new, jac_new, aux_new, cost_new
            jac_seen = np.asarray(args[1])
        done, result = solver.terminate(_linearisation, y, args, {}, state, frozenset())
        if result != optx.RESULTS.successful:
            message = f"optimistix: {optx.RESULTS[result]}"
            break
        if bool(done):
            converged, message = True, "step and residual change below tolerance"
            break
        if accepted and (decrease < ftol * (cost + decrease) or decrease < ctol):
            converged, message = True, "cost decrease below tolerance"
            break
    info = dict(iterations=iteration, evaluations=evaluations, converged=converged,
                message=message, history=history, aux_initial=aux0)  # fmt: skip
    return z, r, jac, aux, info


OPTIMISERS = {"marquardt": levenberg_marquardt, "optimistix": optimistix_lm}


def data_of(problem):
    name, options = problem["scene"]
    scene = get_scene(name, **options)
    if problem["data"] == "synthetic":
        data = synthesize(scene, problem["truth"], np.linspace(0.0, 6e-4, 121),
                          ["journal_x", "journal_ax"], seed=3)  # fmt: skip
    else:
        data = load_measurements(os.path.join(ROOT, problem["data"]))
    return scene, data


def run_one(problem, start, optimiser):
    """One fit with the command's defaults (tolerance from the noise, horizons from the
    impacts of the start run), by `optimiser`."""
    scene, data = data_of(problem)
    names = list(problem["truth"])
    bounds = problem.get("bounds", {})
    specs = [
        f"{n}={g!r}" + (":{!r}:{!r}".format(*bounds[n]) if n in bounds else "")
        for n, g in zip(names, start, strict=True)
    ]
    fixed = scene.resolve_params({})
    guess = {**fixed, **dict(zip(names, start, strict=True))}
    load0, cpu0, wall0 = os.getloadavg()[0], time.process_time(), time.perf_counter()
    full = Comparison(data, ResidualSpec())
    control, record = choose_tolerance(scene, guess, full)
    horizons = impact_horizons(onset_times(record.pop("trajectory")), full.t_end,
                               float(data.t[0]))  # fmt: skip
    stages = [ResidualSpec("trajectory", ((float(data.t[0]), h),)) for h in horizons[:-1]]
    stages.append(ResidualSpec())
    result = fit(scene, data, specs, fixed=fixed, residuals=stages, control=control,
                 optimiser=OPTIMISERS[optimiser])  # fmt: skip
    report = result.report()
    truth = problem["truth"]
    reached = result.converged and all(
        abs(result.estimates[n] - truth[n]) < 3 * result.standard_errors[n] for n in names
    )
    return dict(
        start=list(start), estimates=result.estimates, standard_errors=result.standard_errors,
        converged=result.converged, adequate=result.adequate, reduced_chi2=result.reduced_chi2,
        reached_truth=bool(reached), trial_steps=result.iterations,
        evaluations=result.evaluations, message=result.message, rtol=control.rtol,
        horizons=horizons, wall_s=time.perf_counter() - wall0,
        cpu_s=time.process_time() - cpu0, load_start=load0, load_end=os.getloadavg()[0],
        flags=report["flags"],
    )  # fmt: skip


def block(results):
    by_commit = {}
    for key, r in results.items():
        by_commit.setdefault(r.get("commit", "?"), set()).add(key.split("/")[0])
    fits_at = "; ".join(f"{c}: {', '.join(sorted(p))}" for c, p in by_commit.items())
    lines = [
        f"Fits at {fits_at}, on {CPU} cores, with "
        "other users' jobs running (load average per fit in "
        "the table: wall times are inflated by that load; CPU time is this process's, all "
        "threads). Each row: one problem and optimiser over its starts (10–20 % off the "
        "truth), with the command's defaults; *reached* = converged with every truth within "
        "3 reported standard errors. Trial steps and model evaluations (each a simulation "
        "with its forward-mode Jacobian; evaluations include none of the tolerance search) "
        "are summed over the starts, as are the times. The first fit of a problem compiles the "
        "model (the Marquardt loop runs first, so its times include that); the others load the "
        "compiled program from the persistent cache.",
        "",
        "| problem | optimiser | starts reached | trial steps | evaluations | wall [s] "
        "| CPU [s] | load average |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for name, problem in PROBLEMS.items():
        for opt in OPTIMISERS:
            rows = [results.get(f"{name}/{opt}/{i}") for i in range(len(problem["starts"]))]
            done = [r for r in rows if r is not None]
            if not done:
                lines.append(f"| `{name}` | {opt} | not run | | | | | |")
                continue
            loads = [r["load_start"] for r in done] + [r["load_end"] for r in done]
            lines.append(
                f"| `{name}` | {opt} | {sum(r['reached_truth'] for r in done)}/{len(done)}"
                + (f" (of {len(rows)} starts)" if len(done) < len(rows) else "")
                + f" | {sum(r['trial_steps'] for r in done)} | "
                f"{sum(r['evaluations'] for r in done)} | {sum(r['wall_s'] for r in done):.0f} "
                f"| {sum(r['cpu_s'] for r in done):.0f} | {min(loads):.1f}–{max(loads):.1f} |"
            )
    lines += ["", "| problem | start | optimiser | estimates | (est. − truth)/s.e. | χ²/dof "
              "| trial steps | stopped because |", "|---|---|---|---|---|---|---|---|"]  # fmt: skip
    for key, r in results.items():
        name, opt, _ = key.split("/")
        truth = PROBLEMS[name]["truth"]
        est = ", ".join(f"{n} {v:.6g}" for n, v in r["estimates"].items())
        dev = ", ".join(
            f"{(v - truth[n]) / r['standard_errors'][n]:+.2g}" for n, v in r["estimates"].items()
        )
        start = ", ".join(f"{v:g}" for v in r["start"])
        lines.append(f"| `{name}` | {start} | {opt} | {est} | {dev} | {r['reduced_chi2']:.3g} "
                     f"| {r['trial_steps']} | {r['message']} |")  # fmt: skip
    return "\n".join(lines)


# What moves the numbers: the fit's optimisers and slider_crank's simulation, the data.
MEASURES = [
    "examples",
    "experiments/identification_solvers.py",
    "jaxdeploy/contact",
    "jaxdeploy/fit",
    "jaxdeploy/mechanism",
    "jaxdeploy/scenes/_contact.py",
    "jaxdeploy/scenes/base.py",
    "jaxdeploy/scenes/slider_crank.py",
    "jaxdeploy/simulation.py",
    "jaxdeploy/solvers",
]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", action="append", default=[], help="run only these problems")
    parser.add_argument("--rerun", action="store_true", help="rerun fits already recorded")
    parser.add_argument("--no-fits", action="store_true", help="only rewrite the block")
    args = parser.parse_args()
    os.makedirs(OUT, exist_ok=True)
    # The command line's persistent cache (jaxdeploy fit uses the same folder by default).
    cache = os.path.join(os.path.expanduser("~"), ".cache", "jaxdeploy", "xla")
    jax.config.update("jax_compilation_cache_dir", os.environ.get("JAXDEPLOY_CACHE_DIR", cache))
    record = pages.start(MEASURES, "python experiments/identification_solvers.py --rerun")
    commit = record["commit"][:10]
    path = os.path.join(OUT, "results.json")
    stored = json.load(open(path)) if os.path.exists(path) else {}
    results = {} if args.rerun else stored.get("results", {})
    for r in results.values():  # records written before each fit named its commit
        r.setdefault("commit", stored.get("commit", "?"))
    for name, problem in PROBLEMS.items():
        if args.only and name not in args.only:
            continue
        for i, start in enumerate(problem["starts"]):
            for opt in OPTIMISERS:
                key = f"{name}/{opt}/{i}"
                if key in results or args.no_fits:
                    continue
                print(f"{key}: start {start}", flush=True)
                results[key] = {**run_one(problem, start, opt), "commit": commit}
                print(f"  -> {json.dumps(results[key])}", flush=True)
                with open(path, "w", encoding="utf-8") as fh:
                    json.dump({"commit": commit, "results": results}, fh, indent=1)
    # Fits kept from earlier runs: the freshness test checks their commits too.
    record["runs_at"] = sorted({r["commit"] for r in results.values()} - {commit})
    pages.write_block(os.path.join(ROOT, "docs", "identification.md"), "identification_solvers",
                      block(results), record)  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
