"""How long the main job takes: `jaxdeploy simulate` (deploy_array, 2 s, both hinges Ra 1.6 µm,
c 0.05 mm), split into its phases, cold and with the persistent compilation cache warm.

Run from the repository root::

    .venv/bin/python experiments/default_run_timing.py

Measures, each in a fresh Python process so that nothing is compiled beforehand:

1. the phases in-process: import, building the mechanism and assembling the initial state,
   the simulation's first call (compile + run) and second call (run only: the difference is
   the compile time), the ideal-joint reference, the outputs/summary, the plots;
2. the whole CLI command with the compilation cache off (cold), then twice with a fresh
   cache folder (the second run loads the compiled programs).

Writes `docs/default_run.md`. The machine is shared: the load average is recorded with the
numbers, and repeats are medians.
"""

from __future__ import annotations

import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "default_run.md"
REPEATS = 2

PHASES_SCRIPT = r"""
import json, sys, time, tempfile
t0 = time.perf_counter()
import jaxdeploy
from jaxdeploy.scenes import get_scene
from jaxdeploy.simulation import simulate
from jaxdeploy.analysis.deploy_array import ideal_reference
out = {"import": time.perf_counter() - t0}
scene = get_scene("deploy_array")
params = scene.resolve_params()
t = time.perf_counter()
mech = scene.build(params)
init = scene.initial_state(params, mech)
out["build_and_initial_state"] = time.perf_counter() - t
for label in ("simulate_first_call", "simulate_second_call"):
    t = time.perf_counter()
    traj = simulate(mech, init, scene.default_t_end, n_save=2001, control=scene.default_control)
    traj.q.block_until_ready()
    out[label] = time.perf_counter() - t
out["n_steps"] = int(traj.stats["num_accepted_steps"])
out["n_rejected"] = int(traj.stats["num_rejected_steps"])
out["status"] = traj.status()
out["solver"] = scene.default_control.solver_name()
t = time.perf_counter()
ideal_reference(scene, params, traj)
out["ideal_reference"] = time.perf_counter() - t
t = time.perf_counter()
scene.summary(params, mech, traj)
out["outputs_and_summary"] = time.perf_counter() - t
t = time.perf_counter()
scene.plot(params, mech, traj, tempfile.mkdtemp())
out["plots"] = time.perf_counter() - t
print("PHASES " + json.dumps(out))
"""


def run(cmd, env_extra=None) -> tuple[float, str]:
    env = {**os.environ, "PYTHONPATH": str(ROOT), **(env_extra or {})}
    start = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=ROOT, check=False)
    wall = time.perf_counter() - start
    if proc.returncode != 0:
        sys.exit(f"command failed: {' '.join(cmd)}\n{proc.stdout}\n{proc.stderr}")
    return wall, proc.stdout


def measure_phases() -> dict:
    runs = []
    for k in range(REPEATS):
        print(f"phases, repeat {k + 1}/{REPEATS} ...", flush=True)
        _, stdout = run([sys.executable, "-c", PHASES_SCRIPT], {"JAXDEPLOY_CACHE_DIR": "off"})
        line = next(x for x in stdout.splitlines() if x.startswith("PHASES "))
        runs.append(json.loads(line[len("PHASES ") :]))
    keys = [k for k, v in runs[0].items() if isinstance(v, float)]
    median = {k: statistics.median(r[k] for r in runs) for k in keys}
    median["compile"] = median["simulate_first_call"] - median["simulate_second_call"]
    return {"median": median, "runs": runs}


def measure_cli() -> dict:
    cli = [str(Path(sys.executable).with_name("jaxdeploy")), "simulate", "--quiet"]
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        cold = []
        for k in range(REPEATS):
            print(f"CLI cold, repeat {k + 1}/{REPEATS} ...", flush=True)
            wall, _ = run([*cli, "--out", f"{tmp}/cold{k}"], {"JAXDEPLOY_CACHE_DIR": "off"})
            cold.append(wall)
        out["cold"] = cold
        cache = f"{tmp}/xla-cache"
        warm = []
        for k in range(REPEATS + 1):
            print(f"CLI with cache, run {k + 1}/{REPEATS + 1} ...", flush=True)
            wall, _ = run([*cli, "--out", f"{tmp}/warm{k}"], {"JAXDEPLOY_CACHE_DIR": cache})
            warm.append(wall)
        out["filling_cache"] = warm[0]
        out["warm"] = warm[1:]
    return out


def machine() -> str:
    cpu = platform.processor() or "unknown CPU"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    allowed = len(os.sched_getaffinity(0))
    return (
        f"{cpu}, {os.cpu_count()} logical cores (this run allowed on {allowed}), "
        f"Python {platform.python_version()}"
    )


def main() -> int:
    load_before = os.getloadavg()
    phases = measure_phases()
    cli = measure_cli()
    load_after = os.getloadavg()
    m = phases["median"]
    r0 = phases["runs"][0]
    lines = [
        "# The main job: what `jaxdeploy simulate` costs",
        "",
        "<!-- generated by experiments/default_run_timing.py; do not edit by hand -->",
        "",
        "`jaxdeploy simulate` (README: `make demo`) runs deploy_array for 2 s with both hinges",
        "at Ra 1.6 µm and c 0.05 mm, the ideal-joint reference, and writes `summary.json`,",
        "`trajectory.npz` and four figures. Regenerate these numbers with",
        "`.venv/bin/python experiments/default_run_timing.py`.",
        "",
        f"Machine: {machine()}. Load average (1 min) {load_before[0]:.1f} before and",
        f"{load_after[0]:.1f} after the measurement (the machine is shared; a load above the",
        f"core count inflates every number below). Medians of {REPEATS} fresh processes.",
        "",
        f"The run: {r0['n_steps']} accepted and {r0['n_rejected']} rejected adaptive",
        f"steps of the scene's default solver, `{r0['solver']}`, status `{r0['status']}`.",
        "",
        "| phase | wall time [s] |",
        "|---|---|",
        f"| import jaxdeploy | {m['import']:.1f} |",
        f"| build mechanism, assemble initial state | {m['build_and_initial_state']:.1f} |",
        f"| simulation: compile | {m['compile']:.1f} |",
        f"| simulation: run | {m['simulate_second_call']:.1f} |",
        f"| ideal-joint reference (compile + run) | {m['ideal_reference']:.1f} |",
        f"| outputs and summary | {m['outputs_and_summary']:.1f} |",
        f"| plots | {m['plots']:.1f} |",
        "",
        "| whole command | wall time [s] |",
        "|---|---|",
        f"| cold (no compilation cache) | {statistics.median(cli['cold']):.1f} |",
        f"| first run filling the cache | {cli['filling_cache']:.1f} |",
        f"| later runs (cache warm) | {statistics.median(cli['warm']):.1f} |",
        "",
        "The command line keeps compiled programs in a persistent cache",
        "(`~/.cache/jaxdeploy/xla`, see `jaxdeploy/_compilation_cache.py`; `JAXDEPLOY_CACHE_DIR`",
        "moves or disables it). Parameter values are data, so `--set` changes reuse the cache;",
        "changing what is composed (another scene, friction exactly 0) compiles once more.",
    ]
    DOC.write_text("\n".join(lines) + "\n")
    print(f"wrote {DOC}")
    print(json.dumps({"phases": m, "cli": cli}, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
