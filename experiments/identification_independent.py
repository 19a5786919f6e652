"""Fits of the slider-crank to measurements our model did not make (issue 20): the files in
`examples/` (`experiments/slider_crank_measurements.py`: slider position of the independent
minimal-coordinate reference of `tests/independent/`, classical Lankarani–Nikravesh rule,
c = 0.5 mm, c_e = 0.9, plus 1 µm of stated white noise), each fitted by one `jaxdeploy fit`
command with the command's defaults (tolerance chosen from the noise, horizons from the
impacts), from starts 20 % off:

* `readme`: the README's worked example (0–4 ms, μ = 0; c and c_e);
* `wrong_rule`: the same, with the running-max impact-velocity rule (not the rule that made
  the data): must be flagged inadequate (exit status 3);
* `mu0_12ms`: the case of issue 20 (0–12 ms, μ = 0; c and c_e);
* `friction_12ms`: 0–12 ms with μ = 0.01 (the reference's tanh-regularised Coulomb law,
  `--scene-option friction_shape=tanh`; c, c_e and μ).

The check is the issue's: clearance within 1 %, c_e within 3 %, every truth inside 3 reported
standard errors, the fit converged, adequate and reproducible at the noise level (exit 0;
where the tolerance chosen at the start point fails the check at the estimate, the command
refits at tighter tolerances, column *tolerance refits*); `tests/test_fit_independent.py`
(slow) runs the same commands. Wall times are taken with other jobs on the machine: each
fit records the 1-minute load average before and after it and this process's CPU time.
Each fit's output stays in `docs/figures/identification_independent/<name>/`; a fit whose
`fit.json` holds the same command is not rerun (`--rerun` forces). Writes the
"identification_independent" block of `docs/identification.md` with the commit it ran at.

Usage: `PYTHONPATH=. python experiments/identification_independent.py [--rerun] [--only NAME]`.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from math import nan

from jaxdeploy import pages
from jaxdeploy.cli import main as cli
from jaxdeploy.fit import RTOL_CHECK_FLOOR

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
OUT = os.path.join("docs", "figures", "identification_independent")
TRUTH = {"clearance": 0.5e-3, "restitution": 0.9, "friction_coefficient": 0.01}
# |estimate − truth|/truth allowed (issue 20); μ only within the standard errors.
WITHIN = {"clearance": 0.01, "restitution": 0.03}
README = ["examples/slider_crank_slider_x.csv", "--scene", "slider_crank",
          "--params", "clearance=6e-4", "restitution=0.72"]  # fmt: skip
FITS = {
    "readme": ("README example: 0–4 ms, μ = 0, c and c_e", README, 0),
    "wrong_rule": (
        "the same data, running-max impact-velocity rule (the wrong model)",
        [*README, "--scene-option", "impact_velocity_rule=running_max"],
        3,
    ),
    "mu0_12ms": (
        "issue 20's case: 0–12 ms, μ = 0, c and c_e",
        [
            "examples/slider_crank_slider_x_12ms.csv",
            "--scene",
            "slider_crank",
            "--params",
            "clearance=6e-4",
            "restitution=0.72",
        ],
        0,
    ),  # fmt: skip
    "friction_12ms": (
        "0–12 ms, μ = 0.01 (tanh law), c, c_e and μ",
        [
            "examples/slider_crank_friction_slider_x_12ms.csv",
            "--scene",
            "slider_crank",
            "--scene-option",
            "friction_shape=tanh",
            "--params",
            "clearance=6e-4",
            "restitution=0.72",
            "friction_coefficient=0.012",
        ],
        0,
    ),  # fmt: skip
}


def commands() -> dict[str, list[str]]:
    """The `jaxdeploy fit` arguments of every fit, with its output folder."""
    return {
        name: [*argv, "--out", f"{OUT}/{name}", "--overwrite", "--quiet"]
        for name, (_, argv, _) in FITS.items()
    }


def run_fit(name: str, argv: list[str], rerun: bool) -> tuple[dict, int]:
    path = os.path.join(OUT, name, "fit.json")
    status_path = os.path.join(OUT, name, "exit_status.json")
    if not rerun and os.path.exists(path) and os.path.exists(status_path):
        report = json.load(open(path))
        if report.get("command", [])[1:] == ["fit", *argv]:
            print(f"{name}: kept (same command) from {path}", flush=True)
            return report, json.load(open(status_path))["exit_status"]
    print(f"{name}: jaxdeploy fit " + " ".join(argv), flush=True)
    sys.argv = ["jaxdeploy", "fit", *argv]  # recorded in fit.json as the command
    load_before, cpu = os.getloadavg()[0], time.process_time()
    status = cli(["fit", *argv])
    record = {"exit_status": status, "cpu_s": time.process_time() - cpu,
              "load_before": load_before, "load_after": os.getloadavg()[0]}  # fmt: skip
    with open(status_path, "w", encoding="utf-8") as fh:
        json.dump(record, fh)
    return json.load(open(path)), status


def run_record(name: str) -> dict:
    """Exit status, CPU time and load average of a fit's run (`exit_status.json`)."""
    return json.load(open(os.path.join(OUT, name, "exit_status.json")))


def rerun(name: str, report: dict) -> dict:
    """The model at the estimate re-run without derivatives, at the fit's step control and at
    10× tighter: χ²/dof of each against the data. The fit evaluates the model inside its
    forward-mode program; an adaptive run compiled differently may take other steps, and over
    many impacts a run near a grazing contact can depend on that (cached in `rerun.json`)."""
    path = os.path.join(OUT, name, "rerun.json")
    if os.path.exists(path):
        cached = json.load(open(path))
        if cached.get("params") == report["params"]:
            return cached
    from jaxdeploy.fit import load_measurements, run_channels
    from jaxdeploy.scenes import get_scene

    scene = get_scene("slider_crank", **report["scene_options"])
    data = load_measurements(report["data"])
    # The recorded step control, as settings: `solver` is the method that ran; where a rule
    # chose it (`solver_rule`), the scene's default rule chooses again at 10x tighter.
    control = {
        k: v for k, v in report["step_control"].items() if k not in ("adaptive", "solver_rule")
    }
    if report["step_control"].get("solver_rule"):
        control.pop("solver")
    out = {"params": report["params"]}
    for key, factor in (("at_fit_rtol", 1.0), ("at_tenth_rtol", 0.1)):
        ctl = {**control, "rtol": control["rtol"] * factor, "atol": control["atol"] * factor}
        if ctl["rtol"] < RTOL_CHECK_FLOOR * (1 - 1e-9):  # float64 round-off: no run
            out[key] = None
            continue
        y, _ = run_channels(scene, report["params"], data.t, ["slider_x"], ctl)
        if y is None:
            out[key] = None
            continue
        r = (y["slider_x"] - data.channels["slider_x"]) / data.noise["slider_x"]
        out[key] = float(r @ r) / (r.size - len(report["estimates"]))
    with open(path, "w", encoding="utf-8") as fh:
        json.dump(out, fh)
    return out


def verdict(report: dict, status: int, expected: int) -> tuple[bool, list[str]]:
    """Whether the fit met the issue's criterion (or, for the wrong model, was flagged)."""
    if expected != 0:
        return status == expected and not report["adequate"], []
    lines, ok = [], status == 0 and report["converged"] and report["adequate"]
    for n, est in report["estimates"].items():
        se = report["standard_errors"][n]
        rel = (est - TRUTH[n]) / TRUTH[n]
        ok &= abs(est - TRUTH[n]) < 3 * se and abs(rel) < WITHIN.get(n, float("inf"))
    return ok, lines


def block(results: dict) -> str:
    lines = [
        f"Outputs in `{OUT}/`. Truth: c = 0.5 mm, c_e = 0.9, μ = 0 or 0.01; noise "
        "σ = 1 µm, stated in each file. Criterion (issue 20): c within 1 %, c_e within 3 %, "
        "every truth within 3 reported standard errors, converged, adequate and reproducible "
        "at the noise level (exit 0); the wrong model must exit 3. *rtol chosen*: at the start "
        "point; *tolerance refits*: where the check at the estimate failed, the refits at 10× "
        "tighter (rtol: model change in noise levels RMS, largest estimate change in standard "
        "errors, of each refit's own check). Wall and CPU times (this process, all threads) "
        "were taken on 2 cores shared with other jobs (1-minute load average before → after "
        "each fit): they are not performance figures.",
        "",
        "| fit | exit | converged | adequate | reproducible | χ²/dof | whiteness p | rtol chosen "
        "| tolerance refits | horizons [ms] | trial steps | wall [s] | CPU [s] | load "
        "| criterion met | χ²/dof re-run: same rtol, 10× tighter |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for name, (report, status, ok) in results.items():
        again = rerun(name, report)
        fmt = lambda v: "–" if v is None else f"{v:.3g}"  # noqa: E731
        white = report["adequacy"].get("whiteness", {})
        p = min((w["p_value_corrected"] for w in white.values()), default=float("nan"))
        horizons = report["schedule"].get("horizons") or []
        refits = "; ".join(
            f"{r['rtol']:g}: {check.get('rms_model_change_over_sigma', nan):.2g} σ, "
            f"{check.get('largest_estimate_change_in_standard_errors', nan):.2g} s.e."
            for r in report["schedule"].get("tolerance_refits", [])
            for check in [r["tolerance"] or {}]
        )
        chosen = report["schedule"].get("tolerance", {}).get("chosen_rtol")
        timing = run_record(name)
        load = (
            f"{timing['load_before']:.1f} → {timing['load_after']:.1f}"
            if "load_before" in timing
            else "not recorded"
        )
        cpu = f"{timing['cpu_s']:.0f}" if "cpu_s" in timing else "–"
        lines.append(
            f"| `{name}` | {status} | {'yes' if report['converged'] else 'no'} | "
            f"{'yes' if report['adequate'] else 'NO'} | "
            f"{ {True: 'yes', False: 'NO', None: 'not checked'}[report.get('reproducible')] } | "
            f"{report['reduced_chi2']:.3g} | "
            f"{p:.2g} | {chosen or report['step_control']['rtol']:g}"
            + {True: "", False: " (floor; 0.2 σ not met)", None: ""}[
                report["schedule"].get("tolerance", {}).get("met")
            ]
            + f" | {refits or 'none'} | "
            + (", ".join(f"{h * 1e3:.3g}" for h in horizons) or "whole record")
            + f" | {report['iterations']} | {report['wall_time_s']:.0f} | {cpu} | {load} | "
            f"{'**yes**' if ok else '**no**'} | {fmt(again['at_fit_rtol'])}, "
            f"{fmt(again['at_tenth_rtol'])} |"
        )
    lines += [
        "",
        "| fit | parameter | truth | start | estimate | (est. − truth)/truth | std. error "
        "| × √(χ²/dof) | (est. − truth)/s.e. | refit at 10× tighter rtol [s.e.] |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for name, (report, _, _) in results.items():
        check = report.get("tolerance") or {}
        moves = check.get("estimate_change_in_standard_errors", {})
        for n, est in report["estimates"].items():
            se = report["standard_errors"][n]
            lines.append(
                f"| `{name}` | `{n}` | {TRUTH[n]:g} | {report['initial_guess'][n]:g} | "
                f"{est:.6g} | {(est - TRUTH[n]) / TRUTH[n]:+.3%} | {se:.2g} | "
                f"{report['standard_errors_inflated'][n]:.2g} | {(est - TRUTH[n]) / se:+.2f} | "
                + (f"{moves[n]:+.2g}" if n in moves else check.get("note", "–"))
                + " |"
            )
    lines += ["", "| fit | correlations | singular values of ∂r/∂ln θ | flags |"]
    lines += ["|---|---|---|---|"]
    for name, (report, _, _) in results.items():
        names = list(report["estimates"])
        corr = report["correlation"]
        pairs = [f"{a}–{b} {corr[a][b]:+.5f}" for i, a in enumerate(names) for b in names[i + 1 :]]
        singular = ", ".join(f"{s:.3g}" for s in report["singular_values_relative_jacobian"])
        flags = "; ".join(report["flags"]) or "none"
        lines.append(f"| `{name}` | {'; '.join(pairs)} | {singular} | {flags} |")
    lines += ["", "Commands (each `jaxdeploy fit`, from the repository root):", "", "```text"]
    lines += [f"jaxdeploy fit {' '.join(argv)}" for argv in commands().values()]
    lines += ["```"]
    return "\n".join(lines)


# What moves the numbers: the fit command, slider_crank's simulation, the independent data.
MEASURES = [
    "examples",
    "experiments/identification_independent.py",
    "jaxdeploy/cli.py",
    "jaxdeploy/commands/fit.py",
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
    parser.add_argument("--rerun", action="store_true", help="rerun fits already done")
    parser.add_argument("--only", action="append", default=[], help="run only these fits")
    args = parser.parse_args()
    os.chdir(ROOT)  # paths in the recorded commands are relative to the repository
    record = pages.start(MEASURES, "python experiments/identification_independent.py --rerun")
    results, all_ok = {}, True
    for name, argv in commands().items():
        if args.only and name not in args.only:
            continue
        report, status = run_fit(name, argv, args.rerun)
        ok, _ = verdict(report, status, FITS[name][2])
        results[name] = (report, status, ok)
        all_ok &= ok
        print(f"{name}: exit {status}, criterion met: {ok}", flush=True)
    if not args.only:
        pages.write_block(
            os.path.join(ROOT, "docs", "identification.md"),
            "identification_independent",
            block(results),
            record,
        )
    return 0 if all_ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
