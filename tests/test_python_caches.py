"""The persistent caches from Python (`jaxdeploy.enable_caches`, or `JAXDEPLOY_CACHE_DIR` read
on import): a script's second process reads the programs the first one traced, so it traces
none of them, and gets bit-identical results. Traces are counted from JAX's own compile events
(`jax.monitoring`), never timed."""

import json
import os
import subprocess
import sys

import pytest
from _traces import RECORD_TRACES

_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


# A user's script: the scene, its initial state (an assembly program) and a run (the solve).
# It prints the names of the functions JAX traced in this process and the run's output.
_SCRIPT = (
    RECORD_TRACES
    + """
import json, sys
monitoring.register_event_time_span_listener(record)

import jaxdeploy as jd
if sys.argv[1] != "from-environment":
    jd.enable_caches(sys.argv[1])

scene = jd.get_scene("pendulum")
params = scene.resolve_params()
mechanism = scene.build(params)
trajectory = jd.simulate(
    mechanism, scene.initial_state(params, mechanism), 0.05, n_save=11,
    control=scene.default_control,
)
import numpy as np
q = np.asarray(trajectory.q)
print(json.dumps({"traced": traced, "q": q.tolist(), "bits": q.tobytes().hex(),
                  "status": trajectory.status()}))
"""
)


def _run(tmp_path, argument, **env_changes):
    env = {k: v for k, v in os.environ.items() if k not in ("EQX_ON_ERROR", "JAXDEPLOY_CACHE_DIR")}
    env.update(env_changes)
    proc = subprocess.run(
        [sys.executable, "-c", _SCRIPT, argument],
        env=env,
        capture_output=True,
        text=True,
        cwd=tmp_path,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


def test_second_process_traces_no_program_and_gives_identical_results(tmp_path):
    cache = tmp_path / "cache"
    first = _run(tmp_path, str(cache))
    # The first process traced the assembly and the solve for the program cache...
    exported_first = [name for name in first["traced"] if name.startswith("exported_")]
    assert "exported__solve" in exported_first, first["traced"]
    assert len(exported_first) >= 2, first["traced"]  # the solve and the initial assembly
    assert len(list((tmp_path / "cache-programs").glob("*.jaxexport"))) >= 2
    assert any(cache.iterdir())  # JAX's compilation cache
    # ...the second (the caches named by the environment variable alone) traced none of them
    # and did not even lower the exported programs (their executables are read back): what
    # is left are JAX's single operations on concrete arrays, no function of jaxdeploy's.
    second = _run(tmp_path, "from-environment", JAXDEPLOY_CACHE_DIR=str(cache))
    assert not [n for n in second["traced"] if n.startswith("exported_")], second["traced"]
    assert "_solve" not in second["traced"] and "call_exported" not in second["traced"]
    assert len(list((tmp_path / "cache-programs").glob("*.executable"))) >= 2
    assert first["status"] == second["status"] == "ok"
    assert second["bits"] == first["bits"]  # bit for bit


def test_executables_kept_only_when_compiled_here(tmp_path):
    """An executable JAX read from its persistent compilation cache serializes without its
    object code (read back, it fails: "NOT_FOUND: Function ... not found", jax 0.10.2): with
    the kept executables gone but JAX's cache filled, the next process finds each program in
    JAX's cache, compiles it once more under a name JAX's cache has not seen ("kept_" and
    the entry's key) and
    keeps that; the one after it reads them back and lowers nothing (before, no process kept
    one again and every later process lowered each program), with the same results."""
    cache = tmp_path / "cache"
    first = _run(tmp_path, str(cache))
    kept = sorted((tmp_path / "cache-programs").glob("*.executable"))
    assert kept
    for path in kept:
        path.unlink()
    second = _run(tmp_path, str(cache))
    assert any(n.startswith("kept_") for n in second["traced"]), second["traced"]
    assert sorted((tmp_path / "cache-programs").glob("*.executable")) == kept
    third = _run(tmp_path, str(cache))
    assert not [n for n in third["traced"] if n.startswith(("kept_", "call"))], third["traced"]
    assert first["bits"] == second["bits"] == third["bits"]


def test_caches_called_after_equinox_warn_and_keep_the_compilation_cache(tmp_path):
    """Called after equinox was imported with raising checks, `enable_caches` cannot make
    programs exportable: it says so and turns on the compilation cache alone."""
    code = (
        "import warnings, equinox, jaxdeploy as jd, jax\n"
        "from jaxdeploy import _program_cache\n"
        "with warnings.catch_warnings(record=True) as caught:\n"
        "    warnings.simplefilter('always')\n"
        f"    folder = jd.enable_caches({str(tmp_path / 'c')!r})\n"
        "print(folder == jax.config.jax_compilation_cache_dir, "
        "_program_cache.key(lambda x: x, (1.0,)) is None, "
        "any('before importing' in str(w.message) for w in caught))\n"
        "print(jd.enable_caches('off'), _program_cache.folder())\n"
    )
    env = {k: v for k, v in os.environ.items() if k not in ("EQX_ON_ERROR", "JAXDEPLOY_CACHE_DIR")}
    proc = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True
    )
    assert proc.stdout.split("\n")[:2] == ["True True True", "None None"], proc.stdout


# The run alone, recorded: with the programs read back, `simulate` and its verdict should run
# no JAX operation outside them but the save times (JAX traces, lowers and looks up each one on
# a process's first call: ~4 ms apiece, as much as the whole run of a short slider-crank).
_RUN_ONLY_SCRIPT = (
    RECORD_TRACES
    + """
import json, sys

import jaxdeploy as jd
jd.enable_caches(sys.argv[1])
scene = jd.get_scene("slider_crank")
params = scene.resolve_params()
mechanism = scene.build(params)
initial = scene.initial_state(params, mechanism)

monitoring.register_event_time_span_listener(record)
trajectory = jd.simulate(mechanism, initial, 0.002, n_save=11, control=scene.default_control)
status = trajectory.status()
peak = trajectory.extremes["normal_force_max"]
print(json.dumps({"traced": traced, "status": status, "peak": peak.tolist()}))
"""
)


def test_second_process_simulates_a_clearance_joint_without_tracing_anything(tmp_path):
    """slider_crank (a clearance joint: located events, refined peaks): in the second process
    the run and its status trace no single operation but the save times (before,
    deciding whether to locate events, refining the peaks after the program and comparing the
    result code each traced one: a cached first call at 2x its warm call)."""
    env = {k: v for k, v in os.environ.items() if k not in ("EQX_ON_ERROR", "JAXDEPLOY_CACHE_DIR")}
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [_ROOT, env.get("PYTHONPATH")]))
    runs = []
    for _ in range(2):
        proc = subprocess.run(
            [sys.executable, "-c", _RUN_ONLY_SCRIPT, str(tmp_path / "cache")],
            env=env,
            capture_output=True,
            text=True,
            cwd=tmp_path,
        )
        assert proc.returncode == 0, proc.stderr[-3000:]
        runs.append(json.loads(proc.stdout.strip().splitlines()[-1]))
    first, second = runs
    assert "exported__solve" in first["traced"], first["traced"]
    # One operation is left on purpose: the save times, `jnp.linspace` (numpy's differs from
    # it in the last bit at most saved times, which would move every saved state).
    assert second["traced"] == ["_linspace"], second["traced"]
    assert first["status"] == second["status"] == "ok"
    assert second["peak"] == first["peak"] and all(p > 0 for p in second["peak"])


# A fit's model (`jaxdeploy.fit`): the forward-mode Jacobian of the channels, the program a
# fit evaluates at every Levenberg–Marquardt step (`fit._model_program`).
_FIT_MODEL_SCRIPT = (
    RECORD_TRACES
    + """
import json, sys
monitoring.register_event_time_span_listener(record)

import jaxdeploy as jd
jd.enable_caches(sys.argv[1])
import numpy as np
from jaxdeploy.fit._fit import Model
from jaxdeploy.fit._parameters import make_parameters

scene = jd.get_scene("impact", damping="lankarani_nikravesh")
base = scene.resolve_params({})
params = make_parameters(scene, [sys.argv[2]], base)
model = Model(scene, params, base, ["journal_x"], np.linspace(0.0, 6e-4, 31),
              {"solver": "tsit5", "rtol": 1e-8, "atol": 1e-11}, {})
channels, jacobian, ok = model(np.array([0.3]))
print(json.dumps({"traced": traced, "ok": ok,
                  "bits": [channels["journal_x"].tobytes().hex(),
                           jacobian["journal_x"].tobytes().hex()]}))
"""
)


def _fit_model(tmp_path, cache, parameter):
    env = {k: v for k, v in os.environ.items() if k not in ("EQX_ON_ERROR", "JAXDEPLOY_CACHE_DIR")}
    proc = subprocess.run(
        [sys.executable, "-c", _FIT_MODEL_SCRIPT, str(cache), parameter],
        env=env, capture_output=True, text=True, cwd=tmp_path,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


def test_a_fits_model_is_traced_by_the_first_process_only(tmp_path):
    """The fit's Jacobian program is kept by the program cache: a second process with the
    same scene, fitted parameters and step control (another guess: the program does not
    depend on it) traces nothing of it and gives the first's result bit for bit; other
    bounds are data of the same program."""
    cache = tmp_path / "cache"
    first = _fit_model(tmp_path, cache, "restitution=0.6:0.05:0.99")
    assert "exported_jacobian" in first["traced"], first["traced"]
    second = _fit_model(tmp_path, cache, "restitution=0.7:0.05:0.99")
    assert not [n for n in second["traced"] if n.startswith("exported_")], second["traced"]
    assert "jacobian" not in second["traced"]
    assert first["ok"] and second["ok"] and second["bits"] == first["bits"]
    other = _fit_model(tmp_path, cache, "restitution=0.6:0.1:0.99")
    assert not [n for n in other["traced"] if n.startswith("exported_")], other["traced"]
    assert other["ok"] and other["bits"][0] != first["bits"][0]  # z = 0.3 is another value


# A design problem's batch of designs (`optimize.BatchObjective`), split over two devices as
# `jaxdeploy optimize` splits a 2-core CPU: the programs `_design_program.run_designs` (the
# designs' runs) and `_design_program.objective_of` (their objective).
_DESIGN_BATCH_SCRIPT = (
    RECORD_TRACES
    + """
import json, sys
monitoring.register_event_time_span_listener(record)

import jaxdeploy as jd
jd.enable_caches(sys.argv[1])
import numpy as np
from jaxdeploy.objectives import parse_objective
from jaxdeploy.optimize import BatchObjective, DesignProblem

objective = parse_objective(["panel1:lock_time=1", "panel2:first_onset_time=1"])
problem = DesignProblem(jd.get_scene("deploy_array"), objective, 0.6, n_save=61)
before = len(traced)  # the ideal reference's run came before
batch = BatchObjective(problem)
values, parts, ok = batch({"panel2_ra": np.array([0.8e-6, 1.6e-6, 3.2e-6])})
print(json.dumps({"traced": traced[before:], "ok": ok.tolist(), "devices": len(batch.devices),
                  "bits": [values.tobytes().hex()] + [parts[k].tobytes().hex() for k in parts]}))
"""
)


def _twice(script, tmp_path, **env_changes):
    """`script`'s last line of output (JSON) from two new processes sharing one cache folder
    (its argument), with `env_changes` in their environment and the caches' variables unset."""
    env = {k: v for k, v in os.environ.items() if k not in ("EQX_ON_ERROR", "JAXDEPLOY_CACHE_DIR")}
    env.update(env_changes)
    runs = []
    for _ in range(2):
        proc = subprocess.run(
            [sys.executable, "-c", script, str(tmp_path / "cache")],
            env=env, capture_output=True, text=True, cwd=tmp_path,
        )  # fmt: skip
        assert proc.returncode == 0, proc.stderr[-3000:]
        runs.append(json.loads(proc.stdout.strip().splitlines()[-1]))
    return runs


@pytest.mark.slow  # ~1 CPU-min: a vmapped deploy_array program to 0.6 s traced and compiled
def test_a_design_batch_is_traced_by_the_first_process_only(tmp_path):
    """`BatchObjective` of a `DesignProblem` on two devices (`jax.shard_map`, three designs
    padded to four): a second process with the same problem traces nothing of its programs
    and gives the first's objective and parts bit for bit."""
    first, second = _twice(
        _DESIGN_BATCH_SCRIPT, tmp_path, XLA_FLAGS="--xla_force_host_platform_device_count=2"
    )
    assert "exported_run_designs" in first["traced"], first["traced"]
    assert "exported_objective_of" in first["traced"], first["traced"]
    assert not [n for n in second["traced"] if n.startswith("exported_")], second["traced"]
    assert first["devices"] == second["devices"] == 2
    assert first["ok"] == second["ok"] == [True, True, True]
    assert second["bits"] == first["bits"]


# `jaxdeploy fit` with the tolerance its own to choose (noise given): the Jacobian's program is
# made in a second thread while the main thread runs the start point (`commands.fit`).
# A command's script records what JAX traced as [function name, thread name] pairs.
_RECORD_THREAD_TRACES = """
import json, sys, threading
from jax import monitoring

traced = []
def record(event, start, end, **kwargs):
    if event == "/jax/core/compile/jaxpr_trace_duration":
        traced.append([kwargs.get("fun_name"), threading.current_thread().name])
monitoring.register_event_time_span_listener(record)
"""


def _command(script, tmp_path, out, cache):
    """`script`'s last line of output (JSON), run in a new process with `JAXDEPLOY_CACHE_DIR`
    `cache` and `out` its argument."""
    env = {k: v for k, v in os.environ.items() if k not in ("EQX_ON_ERROR", "JAXDEPLOY_CACHE_DIR")}
    env["JAXDEPLOY_CACHE_DIR"] = cache
    proc = subprocess.run(
        [sys.executable, "-c", script, out],
        env=env, capture_output=True, text=True, cwd=tmp_path,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


_FIT_COMMAND_SCRIPT = (
    _RECORD_THREAD_TRACES
    + """
import numpy as np
from jaxdeploy.cli import main
from jaxdeploy.fit import synthesize
from jaxdeploy.scenes import Impact

scene = Impact(damping="lankarani_nikravesh")
data = synthesize(scene, {"restitution": 0.7}, np.linspace(0.0, 6e-4, 61), ["journal_x"], seed=3)
data.save("impact.csv")
code = main(["fit", "impact.csv", "--scene", "impact", "--scene-option",
             "damping=lankarani_nikravesh", "--params", "restitution=0.4:0.05:0.99",
             "--out", sys.argv[1], "--quiet"])
report = json.load(open(sys.argv[1] + "/fit.json"))
print(json.dumps({"code": code, "traced": traced, "estimates": report["estimates"],
                  "errors": report["standard_errors"], "rtol": report["step_control"]["rtol"]}))
"""
)


def _fit_command(tmp_path, out, cache):
    return _command(_FIT_COMMAND_SCRIPT, tmp_path, out, cache)


@pytest.mark.slow  # ~1 CPU-min: two fits from empty caches
def test_the_fit_command_makes_its_jacobian_while_it_chooses_the_tolerance(tmp_path):
    """`jaxdeploy fit` from an empty cache traces its Jacobian's program in its second
    thread (`fit-model-ahead`), never in the main thread, at the structure of the tolerance
    it then chooses; the fit is the one made without the caches (no thread), bit for bit."""
    ahead = _fit_command(tmp_path, "ahead", str(tmp_path / "cache"))
    assert ahead["code"] == 0
    jacobians = [t for t in ahead["traced"] if "jacobian" in t[0]]
    assert jacobians == [["exported_jacobian", "fit-model-ahead"]], ahead["traced"]
    plain = _fit_command(tmp_path, "plain", "off")
    assert plain["code"] == 0 and ["jacobian", "MainThread"] in plain["traced"]
    assert not [t for t in plain["traced"] if t[1] != "MainThread"], plain["traced"]
    assert ahead["rtol"] == plain["rtol"] < 1e-6  # the tolerance chosen, below the default
    assert ahead["estimates"] == plain["estimates"] and ahead["errors"] == plain["errors"]


# `optimize`'s pathwise gradient of a `DesignProblem` (forward mode, the design runs with
# `diffrax.ForwardMode`, as `jaxdeploy optimize --gradient pathwise` runs it): the program
# `optimize._design_gradient`.
_DESIGN_GRADIENT_SCRIPT = (
    RECORD_TRACES
    + """
import json, sys
monitoring.register_event_time_span_listener(record)

import jaxdeploy as jd
jd.enable_caches(sys.argv[1])
import diffrax as dfx
from jaxdeploy.objectives import parse_objective
from jaxdeploy.optimize import DesignProblem, optimize

objective = parse_objective(["panel1:lock_time=1"])
problem = DesignProblem(jd.get_scene("deploy_array"), objective, 0.6, n_save=61,
                        adjoint=dfx.ForwardMode())
before = len(traced)  # the ideal reference's run came before
result = optimize(problem.evaluate, {"spring_stiffness": 1.5}, {"spring_stiffness": (1.0, 3.0)},
                  steps=1, mode="forward", control=problem.step_control)
print(json.dumps({"traced": traced[before:], "status": result.status,
                  "objective": result.objective, "gradient": result.gradient}))
"""
)


@pytest.mark.slow  # ~2 CPU-min: a forward-mode deploy_array program to 0.6 s traced and compiled
def test_a_design_gradient_is_traced_by_the_first_process_only(tmp_path):
    """`optimize`'s pathwise gradient of a `DesignProblem` is kept by the program cache: a
    second process with the same problem, box and mode traces nothing of it and finds the
    first's objective and gradient bit for bit."""
    first, second = _twice(_DESIGN_GRADIENT_SCRIPT, tmp_path)
    assert "exported__design_gradient" in first["traced"], first["traced"]
    assert not [n for n in second["traced"] if "design_gradient" in n], second["traced"]
    assert first["status"] == second["status"] == "ok"
    assert second["objective"] == first["objective"] and second["gradient"] == first["gradient"]
    assert first["gradient"][0]["spring_stiffness"] < 0  # a stiffer spring locks sooner


# `jaxdeploy optimize` with a smoothed gradient: the design batch's runs are made in a second
# thread while `DesignProblem` runs the ideal reference (`commands.optimize`).
_OPTIMIZE_COMMAND_SCRIPT = (
    _RECORD_THREAD_TRACES
    + """
from jaxdeploy.cli import main

code = main(["optimize", "--scene", "deploy_array", "--objective", "panel1:lock_time=1",
             "--param", "panel1_ra", "--steps", "1", "--pairs", "1", "--t-end", "0.6",
             "--n-save", "61", "--devices", "1", "--out", sys.argv[1], "--quiet"])
report = json.load(open(sys.argv[1] + "/result.json"))
print(json.dumps({"code": code, "traced": traced, "history": report["history"]}))
"""
)


def _optimize_command(tmp_path, out, cache):
    return _command(_OPTIMIZE_COMMAND_SCRIPT, tmp_path, out, cache)


@pytest.mark.slow  # ~2 CPU-min: two deploy_array optimisations from empty caches
def test_the_optimize_command_makes_its_design_batch_while_the_reference_runs(tmp_path):
    """`jaxdeploy optimize` (smoothed gradient) from an empty cache traces its design batch's
    runs in its second thread (`optimize-batch-ahead`), never in the main thread, and the
    objective of their outputs in the main thread (it needs the ideal lock time); the history
    is the one made without the caches (no thread, `evaluate` traced whole), bit for bit."""
    ahead = _optimize_command(tmp_path, "ahead", str(tmp_path / "cache"))
    assert ahead["code"] == 0
    runs = [t for t in ahead["traced"] if "run_designs" in t[0]]
    assert runs == [["exported_run_designs", "optimize-batch-ahead"]], ahead["traced"]
    assert ["exported_objective_of", "MainThread"] in ahead["traced"], ahead["traced"]
    plain = _optimize_command(tmp_path, "plain", "off")
    assert plain["code"] == 0
    assert not [t for t in plain["traced"] if t[1] != "MainThread"], plain["traced"]
    for a, p in zip(ahead["history"], plain["history"], strict=True):
        assert a["objective"] == p["objective"] and a["gradient"] == p["gradient"]
