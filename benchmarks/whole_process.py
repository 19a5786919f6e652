"""What a user waits for, as whole processes (issue 32's targets; `python -m benchmarks part
whole-process`): interpreter start, imports, build, compile or cache load, solve, files.

* `jaxdeploy simulate slider_crank --rtol 1e-8 --atol 1e-11` against the scipy user's script
  (`benchmarks/slider_crank_script.py`: LSODA on the minimal-coordinate model, the same two
  revolutions and 2001 saved times, no plots) at the loosest LSODA tolerance (atol = 1e-3 rtol,
  as the work–precision bench) whose slider error over the first 4 ms is at or below ours,
  both against the independent reference (`tests/data/slider_crank_reference.npz`). Each side
  runs twice in new processes: the first with jaxdeploy's caches empty (a new
  `JAXDEPLOY_CACHE_DIR`), the second with them filled by the first.
* A Python script (README's "Python" example: `jd.enable_caches(...)`, the slider-crank with
  clearance 1e-4 m, Tsit5 at rtol 1e-8) run twice in new processes with one cache folder: the
  wall and CPU time from the end of `import jaxdeploy` to its first `simulate` result.
* The README's `jaxdeploy fit` (slider_crank's clearance and restitution from
  `examples/slider_crank_slider_x.csv`) twice in new processes with one cache folder: the
  second reads the model's programs the first kept (`fit_second_process`); the README's
  `jaxdeploy optimize` alike (`optimize_second_process`: the design batch's programs).
* `jaxdeploy sweep` of 16 deploy_array cases as it runs by default (its vmapped chunk sharded
  over one device per usable core) against each case alone and the vmapped chunk on one
  device, each with empty and then filled caches (`sweep_on_every_core`).

Wall time from the parent (`time.perf_counter` around the child), CPU time of the child's
process tree (`RUSAGE_CHILDREN`, user + system, which other jobs' load does not inflate).
"""

from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
import tempfile
import time

import numpy as np

FLAGS = ("--rtol", "1e-8", "--atol", "1e-11")
LSODA_RTOLS = (1e-6, 1e-7, 1e-8, 1e-9, 1e-10, 1e-11, 1e-12)
SLIDER_X = 6  # the slider's x among slider_crank's coordinates (benchmarks/work_precision.py)

# The README's Python example as a script that reports its own times (stdout, one JSON line).
PYTHON_SCRIPT = """
import json, sys, time
began = time.perf_counter()
import jaxdeploy as jd

jd.enable_caches(sys.argv[1])
imported, cpu = time.perf_counter(), time.process_time()
scene = jd.get_scene("slider_crank")
params = scene.resolve_params({"clearance": 1e-4})
mechanism = scene.build(params)
control = jd.StepControl("tsit5", rtol=1e-8, atol=1e-11, dt_max=1e-4)
trajectory = jd.simulate(mechanism, scene.initial_state(params, mechanism), 0.024, control=control)
trajectory.q.block_until_ready()
print(json.dumps({"import_s": imported - began, "first_result_s": time.perf_counter() - imported,
                  "first_result_cpu_s": time.process_time() - cpu,
                  "status": trajectory.status()}))
"""


def _run(command, env, cwd=None) -> dict:
    """`command` as a new process: its wall and CPU time [s] and its standard output."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    done = subprocess.run(command, env=env, cwd=cwd, capture_output=True, text=True)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode != 0:
        raise RuntimeError(f"{' '.join(command)} failed: {done.stderr[-2000:]}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return {"wall_s": wall, "cpu_s": cpu, "stdout": done.stdout}


def _environment(cache: str | None) -> dict:
    env = {k: v for k, v in os.environ.items() if k not in ("EQX_ON_ERROR", "JAXDEPLOY_CACHE_DIR")}
    env["JAXDEPLOY_CACHE_DIR"] = cache or "off"
    return env


def slider_error(t, x, ts_ref, x_ref) -> float:
    """max |x − x_ref| [m] over the saved times within the reference's 0–4 ms (the saved
    times are multiples of the reference's 1 µs grid)."""
    t, x = np.asarray(t), np.asarray(x)
    step = (ts_ref[-1] - ts_ref[0]) / (ts_ref.size - 1)
    within = t <= ts_ref[-1] * (1 + 1e-12)
    index = np.rint((t[within] - ts_ref[0]) / step).astype(int)
    if not np.allclose(ts_ref[index], t[within], rtol=0, atol=1e-12):
        raise ValueError("the saved times are not on the reference's grid")
    return float(np.max(np.abs(x[within] - x_ref[index])))


def slider_crank_vs_script(root: str = ".") -> dict:
    from .scipy_peer import SliderCrankPeer
    from .work_precision import load_reference

    ts_ref, x_ref = load_reference(root)
    out: dict = {"command": "jaxdeploy simulate slider_crank " + " ".join(FLAGS)}
    with tempfile.TemporaryDirectory() as tmp:
        env = _environment(os.path.join(tmp, "cache"))
        runs = {}
        for run in ("first", "second"):
            folder = os.path.join(tmp, f"ours-{run}")
            command = [sys.executable, "-m", "jaxdeploy.cli", "simulate", "slider_crank",
                       *FLAGS, "--out", folder, "--quiet"]  # fmt: skip
            runs[run] = _run(command, env)
            with open(os.path.join(folder, "summary.json")) as f:
                summary = json.load(f)
            runs[run]["phases"] = {
                "start_up_s": runs[run]["wall_s"] - summary["wall_time_s"],
                **summary["phases"],
            }
            with np.load(os.path.join(folder, "trajectory.npz")) as data:
                runs[run]["t"], runs[run]["x"] = data["t"], data["q"][:, SLIDER_X]
        ours_error = slider_error(runs["first"]["t"], runs["first"]["x"], ts_ref, x_ref)
        out["identical_runs"] = bool(
            np.array_equal(runs["first"]["x"], runs["second"]["x"], equal_nan=True)
        )
        t_save = runs["first"]["t"]
        for run in runs.values():
            del run["t"], run["x"], run["stdout"]
        out["ours"] = {**runs, "error_4ms_m": ours_error}
        # The loosest LSODA tolerance as accurate as ours over the reference's 4 ms.
        early = t_save[t_save <= ts_ref[-1] * (1 + 1e-12)]
        rtol = LSODA_RTOLS[-1]
        for candidate in LSODA_RTOLS:
            x, _ = SliderCrankPeer().solve(early, "LSODA", candidate, 1e-3 * candidate)
            if slider_error(early, x, ts_ref, x_ref) <= ours_error:
                rtol = candidate
                break
        script = {}
        for run in ("first", "second"):
            path = os.path.join(tmp, f"script-{run}.npz")
            command = [sys.executable, "-m", "benchmarks.slider_crank_script", "--rtol",
                       repr(rtol), "--atol", repr(1e-3 * rtol), "--out", path]  # fmt: skip
            script[run] = _run(command, _environment(None), cwd=root)
            del script[run]["stdout"]
            with np.load(path) as data:
                script[run]["error_4ms_m"] = slider_error(data["t"], data["x"], ts_ref, x_ref)
        out["script"] = {"method": "LSODA", "rtol": rtol, "atol": 1e-3 * rtol, **script}
    for run in ("first", "second"):
        out[f"{run}_ratio"] = out["ours"][run]["wall_s"] / out["script"][run]["wall_s"]
        out[f"{run}_cpu_ratio"] = out["ours"][run]["cpu_s"] / out["script"][run]["cpu_s"]
    return out


def python_script_second_process() -> dict:
    """The README's Python example in two new processes sharing one cache folder, run as a
    user runs a script: from its file (a script's second process reads its programs ahead,
    `jaxdeploy/_read_ahead.py`, by the script's path)."""
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        env = _environment(None)
        env.pop("JAXDEPLOY_CACHE_DIR")
        script = os.path.join(tmp, "study.py")
        with open(script, "w", encoding="utf-8") as f:
            f.write(PYTHON_SCRIPT)
        for run in ("first", "second"):
            done = _run([sys.executable, script, os.path.join(tmp, "cache")], env)
            report = json.loads(done["stdout"].strip().splitlines()[-1])
            if report["status"] != "ok":
                raise RuntimeError(f"the Python script's run failed: {report['status']}")
            out[run] = {"wall_s": done["wall_s"], "cpu_s": done["cpu_s"], **report}
    return out


# The README's fit, as its tour runs it.
FIT = ("fit", "examples/slider_crank_slider_x.csv", "--scene", "slider_crank",
       "--params", "clearance=6e-4", "restitution=0.72", "--quiet")  # fmt: skip


def fit_second_process(root: str = ".") -> dict:
    """The README's fit (`FIT`) twice in new processes sharing one cache folder: each
    process's wall and CPU time and the fit's own wall time (`fit.json`'s `wall_time_s`: the
    fit and its refits, without start-up and files); the second process reads the model's
    programs (its channels' Jacobian) the first traced and kept
    (`jaxdeploy/fit/_model_program.py`), and must find the same estimates. The first makes
    the Jacobian's program in a second thread while it chooses the tolerance
    (`jaxdeploy/commands/fit.py`, `_ModelAhead`)."""
    return _twice(FIT, "fit.json", lambda report: report["estimates"], root)


# The README's optimize, as its tour runs it.
OPTIMIZE = ("optimize", "--scene", "deploy_array", "--objective", "paper_reproducible",
            "--steps", "3", "--pairs", "2", "--quiet")  # fmt: skip


def optimize_second_process(root: str = ".") -> dict:
    """The README's optimize (`OPTIMIZE`) twice in new processes sharing one cache folder,
    as `fit_second_process`: the second reads the design batch's programs
    (`jaxdeploy/_design_program.py`) the first traced and kept, and must find the same
    objective history."""
    return _twice(OPTIMIZE, "result.json", lambda r: [h["objective"] for h in r["history"]], root)


def _twice(command, result_file, result, root) -> dict:
    """`jaxdeploy COMMAND` twice in new processes sharing one cache folder: each process's
    wall and CPU time, the command's own `wall_time_s` (from `result_file`) and `result(report)`,
    whether the two are identical and the second's wall time over the first's."""
    out = {"command": "jaxdeploy " + " ".join(command)}
    with tempfile.TemporaryDirectory() as tmp:
        env = _environment(os.path.join(tmp, "cache"))
        for run in ("first", "second"):
            folder = os.path.join(tmp, run)
            argv = [sys.executable, "-m", "jaxdeploy.cli", *command, "--out", folder]
            done = _run(argv, env, root)
            with open(os.path.join(folder, result_file), encoding="utf-8") as f:
                report = json.load(f)
            out[run] = {
                "wall_s": done["wall_s"],
                "cpu_s": done["cpu_s"],
                "own_wall_s": report["wall_time_s"],
                "result": result(report),
            }
    out["identical"] = out["first"]["result"] == out["second"]["result"]
    out["second_ratio"] = out["second"]["wall_s"] / out["first"]["wall_s"]
    return out


# A sweep as a design study starts one: 16 cases of deploy_array over the first 0.6 s (the
# unfolding and the lock), one chunk.
SWEEP = ("sweep", "--scene", "deploy_array", "--grid", "spring_stiffness=1.2:1.8:16",
         "--t-end", "0.6", "--quiet", "--long-run")  # fmt: skip


# The sweep's configurations: its default (16 cases on 2 cores: `auto` takes the vmapped chunk
# sharded over one device per core), each case alone (one device, a thread per core) and the
# vmapped chunk on one device.
SWEEP_CONFIGURATIONS = (
    ("default", ()),
    ("each case alone", ("--policy", "each")),
    ("vmap, one device", ("--policy", "all", "--devices", "1")),
)


def sweep_on_every_core() -> dict:
    """`jaxdeploy sweep` (`SWEEP`) as it runs by default against each case alone and the
    vmapped chunk on one device (`SWEEP_CONFIGURATIONS`), each twice in new processes: first
    with empty caches, then with the caches the first filled. Wall and CPU time of each
    process, its policy and devices, and the chunk's own wall time from its manifest; the
    ratio of each other configuration to the default."""
    from jaxdeploy.commands._devices import usable_cores

    out = {"command": "jaxdeploy " + " ".join(SWEEP), "cores": usable_cores()}
    with tempfile.TemporaryDirectory() as tmp:
        for name, extra in SWEEP_CONFIGURATIONS:
            slug = "".join(c if c.isalnum() else "_" for c in name)
            env = _environment(os.path.join(tmp, slug + "_cache"))
            runs = {}
            for run in ("first", "second"):
                folder = os.path.join(tmp, f"{slug}_{run}")
                command = [sys.executable, "-m", "jaxdeploy.cli", *SWEEP, "--out", folder,
                           *extra]  # fmt: skip
                done = _run(command, env)
                with open(os.path.join(folder, "manifest.json"), encoding="utf-8") as f:
                    manifest = json.load(f)
                runs[run] = {
                    "wall_s": done["wall_s"],
                    "cpu_s": done["cpu_s"],
                    "devices": len(manifest["devices"]),
                    "policy": manifest["definition"]["policy"]["kind"],
                    "chunk_wall_s": sum(c["wall_time_s"] for c in manifest["chunks"]),
                }
            out[name] = runs
    for name, _ in SWEEP_CONFIGURATIONS[1:]:
        for run in ("first", "second"):
            out[f"{name}/{run}_ratio"] = out[name][run]["wall_s"] / out["default"][run]["wall_s"]
    return out


# What `jaxdeploy simulate` imports before its first phase: the command line, the scenes (and
# with them the mechanism and the solvers), the simulation and the command's own module.
START_UP_IMPORTS = (
    "import jaxdeploy.cli, jaxdeploy.scenes, jaxdeploy.simulation, jaxdeploy.commands.simulate"
)
# The solvers' library and what it imports of its authors' others.
SOLVER_STACK = ("diffrax", "optimistix", "lineax")


def import_times(stderr: str) -> dict[str, float]:
    """Each top-level package's own import time [s] from `python -X importtime`'s report
    (the self time of each of its modules, summed; lines `import time: SELF | CUMULATIVE |
    NAME` in µs)."""
    totals: dict[str, float] = {}
    for line in stderr.splitlines():
        if not line.startswith("import time:"):
            continue
        own, _, name = line.removeprefix("import time:").split("|")
        if not own.strip().isdigit():  # the header line
            continue
        package = name.strip().split(".")[0]
        totals[package] = totals.get(package, 0.0) + int(own) * 1e-6
    return totals


def start_up_imports(runs: int = 3) -> dict:
    """The start-up's imports (`START_UP_IMPORTS`) alone, in new processes with bytecode
    present and nothing else running in them: the fastest of `runs` by total import time,
    with each top-level package's share (`import_times`)."""
    best = None
    for _ in range(runs):
        done = subprocess.run([sys.executable, "-X", "importtime", "-c", START_UP_IMPORTS],
                              env=_environment(None), capture_output=True, text=True)  # fmt: skip
        if done.returncode != 0:
            raise RuntimeError(f"{START_UP_IMPORTS} failed: {done.stderr[-2000:]}")
        packages = import_times(done.stderr)
        if best is None or sum(packages.values()) < sum(best.values()):
            best = packages
    return {"statement": START_UP_IMPORTS, "total_s": sum(best.values()), "packages": best}


def measure(root: str = ".") -> dict:
    return {
        "slider_crank": slider_crank_vs_script(root),
        "start_up_imports": start_up_imports(),
        "python_script": python_script_second_process(),
        "fit": fit_second_process(root),
        "optimize": optimize_second_process(root),
        "sweep": sweep_on_every_core(),
    }
