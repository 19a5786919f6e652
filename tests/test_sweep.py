"""Sweeps: sharded over forced host devices, killed mid-sweep by a signal, resumed; every case
exactly once and equal to an uninterrupted run and to separate unbatched runs."""

import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from _traces import TRACED_COMMAND

from jaxdeploy.commands.sweep import parse_grid
from jaxdeploy.sweep import grid_cases, load_sweep

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
# 4 angles x 6 lengths = 24 cases in chunks of 4 (one per forced device): 6 chunks.
GRID = ["--grid", "initial_angle=0.0,0.3,-0.6,1.0", "--grid", "length=0.5:2.0:6"]
# A quarter of the longest pendulum's period: what is checked (sharding, kill, resume, equality
# with unbatched runs) does not depend on the length of the run; each run of the sweep costs less.
T_END = "0.5"


def _command(out, *extra):
    return [
        sys.executable,
        "-m",
        "jaxdeploy.cli",
        "sweep",
        "--scene",
        "pendulum",
        *GRID,
        "--t-end",
        T_END,
        "--n-save",
        "21",
        "--chunk-size",
        "4",
        "--policy",
        "all",  # the sharded vmap (24 cases would run one by one by default: `auto`)
        "--out",
        str(out),
        "--quiet",
        *extra,
    ]


def _env(cache):
    env = dict(os.environ)
    env["XLA_FLAGS"] = "--xla_force_host_platform_device_count=4"
    env["PYTHONPATH"] = ROOT + os.pathsep + env.get("PYTHONPATH", "")
    # The three processes compile the same program: share it through JAX's persistent cache.
    env["JAX_COMPILATION_CACHE_DIR"] = str(cache)
    env["JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS"] = "0"
    env["JAX_PERSISTENT_CACHE_MIN_ENTRY_SIZE_BYTES"] = "0"
    return env


def _chunks_done(out):
    try:
        with open(os.path.join(out, "manifest.json")) as fh:
            return len(json.load(fh)["chunks"])
    except (FileNotFoundError, json.JSONDecodeError):
        return 0


def test_grid_parsing_and_case_order():
    grid = parse_grid(["a=1,2", "b=1:3:3", "c=1e-6:1e-4:3:log"])
    assert grid["b"] == [1.0, 2.0, 3.0]
    np.testing.assert_allclose(grid["c"], [1e-6, 1e-5, 1e-4], rtol=1e-12)
    cases = grid_cases({"a": [1, 2], "b": [10, 20, 30]})
    assert list(cases["a"]) == [1, 1, 1, 2, 2, 2] and list(cases["b"]) == [10, 20, 30] * 2
    with pytest.raises(ValueError, match="LOW:HIGH:N"):
        parse_grid(["a=1:2"])
    with pytest.raises(ValueError, match="--grid a is given twice"):
        parse_grid(["a=1,2", "a=3"])
    with pytest.raises(ValueError, match="both swept .* and fixed"):
        parse_grid(["a=1,2"], fixed={"a": 1.0})


def test_chunks_hold_no_more_padding_than_a_power_of_two():
    from jaxdeploy.sweep import chunk_shape

    assert chunk_shape(64, 3, 1) == 4  # a 3-case sweep: 4 slots, not 64
    assert chunk_shape(64, 1, 1) == 1
    assert chunk_shape(64, 200, 1) == 64  # large sweeps keep the chunk size
    assert chunk_shape(4, 24, 4) == 4  # one case per device and chunk
    assert chunk_shape(64, 10, 4) == 16  # 3 cases per device -> 4
    # Few shapes: every sweep of up to 64 cases on one device uses one of 7.
    assert {chunk_shape(64, n, 1) for n in range(1, 65)} == {1, 2, 4, 8, 16, 32, 64}


def test_sweep_definition_records_the_solver():
    # A solver given by name (or as an object) is part of the definition, so resuming a sweep
    # with another solver is refused; numbers stay numbers.
    from jaxdeploy.solvers import GeneralizedAlpha, StepControl

    record = StepControl("tsit5", rtol=1e-6, atol=1e-9).to_json()
    assert record["solver"] == "tsit5" and record["rtol"] == 1e-6 and record["dt"] is None
    full = StepControl(GeneralizedAlpha(newton="full"), dt=1e-3).to_json()
    assert full["solver"] != StepControl(GeneralizedAlpha(), dt=1e-3).to_json()["solver"]


@pytest.mark.slow  # 18 s of the default suite at 844cb65 (2 cores): kept out of it
def test_sweep_killed_and_resumed_on_four_devices(tmp_path):
    env = _env(tmp_path / "cache")
    full, killed = tmp_path / "full", tmp_path / "killed"
    done = subprocess.run(_command(full), env=env, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    manifest = json.loads((full / "manifest.json").read_text())
    assert len(manifest["devices"]) == 4 and len(manifest["chunks"]) == 6

    # Kill (SIGKILL: no clean-up runs) as soon as the first chunk is recorded.
    proc = subprocess.Popen(_command(killed), env=env, stderr=subprocess.PIPE, text=True)
    deadline = time.time() + 600
    while _chunks_done(killed) < 1 and proc.poll() is None and time.time() < deadline:
        time.sleep(0.02)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    before = _chunks_done(killed)
    assert 1 <= before < 6, f"the kill did not land mid-sweep ({before} of 6 chunks done)"

    # Without --resume the folder is refused; with it the sweep completes.
    refused = subprocess.run(_command(killed), env=env, capture_output=True, text=True)
    assert refused.returncode == 2 and "--resume" in refused.stderr
    resumed = subprocess.run(
        _command(killed, "--resume"), env=env, capture_output=True, text=True, timeout=600
    )
    assert resumed.returncode == 0, resumed.stderr
    assert resumed.stdout == "", "--quiet prints nothing"
    resumed_manifest = json.loads((killed / "manifest.json").read_text())
    assert len(resumed_manifest["chunks"]) == 6 and resumed_manifest["n_cases"] == 24

    a, b = load_sweep(full), load_sweep(killed)  # load_sweep raises on a duplicated case
    assert list(a["case"]) == list(range(24)) and list(b["case"]) == list(range(24))
    for key in ("q", "v", "param_initial_angle", "param_length", "num_steps"):
        np.testing.assert_array_equal(a[key], b[key])

    # Independent check of the sharded, padded batches: unbatched runs of three cases.
    from jaxdeploy.batch import run_scene
    from jaxdeploy.scenes import Pendulum

    scene = Pendulum()
    for i in (0, 13, 23):
        params = scene.resolve_params(
            {"initial_angle": a["param_initial_angle"][i], "length": a["param_length"][i]}
        )
        single = run_scene(scene, params, float(T_END), n_save=21)
        np.testing.assert_allclose(a["q"][i], single.q, rtol=0, atol=1e-10)

    # A different definition cannot resume this sweep.
    other = _command(killed, "--resume")
    other[other.index(T_END)] = "0.25"
    mismatch = subprocess.run(other, env=env, capture_output=True, text=True)
    assert mismatch.returncode == 2 and "defined differently" in mismatch.stderr


def test_sweep_policy_is_parsed_recorded_and_checked_on_resume(tmp_path):
    """`policy`: refused unless valid (naming the forms); recorded in the definition, so a
    sweep cannot resume under another policy; sweeps written before it was recorded ran one
    vmap per chunk and resume as `all`. Groups give the cases the steps of one vmap."""
    from jaxdeploy.scenes import Pendulum
    from jaxdeploy.sweep import parse_policy, sweep

    assert parse_policy("all") == {"kind": "all"}
    assert parse_policy("groups:8") == {"kind": "groups", "group_size": 8}
    assert parse_policy("each") == {"kind": "each"} and parse_policy("auto") == {"kind": "auto"}
    for bad in ("lanes:8", "groups", "groups:0", "groups:2.5", "groups:2:3", "vmap", "all:2", "",
                "each:2", "auto:1"):  # fmt: skip
        with pytest.raises(ValueError, match="valid: 'auto', 'each', 'all' or 'groups:G'"):
            parse_policy(bad)

    scene = Pendulum()
    grid = {"initial_angle": [0.3, -1.2, 2.5, 0.05, -2.9]}
    common = dict(t_end=0.3, n_save=11, control={"rtol": 1e-7, "atol": 1e-9}, chunk_size=5)
    with pytest.raises(ValueError, match="policy = 'groups:0' is invalid"):
        sweep(scene, grid, str(tmp_path / "bad"), policy="groups:0", **common)
    assert not (tmp_path / "bad").exists()
    groups = sweep(scene, grid, str(tmp_path / "groups"), policy="groups:2", **common)
    sweep(scene, grid, str(tmp_path / "all"), policy="all", **common)
    assert groups["definition"]["policy"] == {"kind": "groups", "group_size": 2}
    a, b = load_sweep(str(tmp_path / "groups")), load_sweep(str(tmp_path / "all"))
    assert len(set(b["num_steps"].tolist())) > 2  # the cases differ
    np.testing.assert_array_equal(a["num_steps"], b["num_steps"])
    np.testing.assert_allclose(a["q"], b["q"], rtol=0, atol=1e-12)

    with pytest.raises(ValueError, match="defined differently"):
        sweep(scene, grid, str(tmp_path / "groups"), policy="all", resume=True, **common)
    # A manifest without a policy (written before it was recorded) resumes as "all".
    path = tmp_path / "all" / "manifest.json"
    manifest = json.loads(path.read_text())
    del manifest["definition"]["policy"]
    path.write_text(json.dumps(manifest))
    assert sweep(scene, grid, str(tmp_path / "all"), policy="all", resume=True, **common)
    with pytest.raises(ValueError, match="defined differently"):
        sweep(scene, grid, str(tmp_path / "all"), policy="groups:2", resume=True, **common)


def test_auto_runs_a_small_sweep_case_by_case_and_a_large_one_vmapped():
    from jaxdeploy.sweep import AUTO_EACH_CASES_PER_CORE, resolve_policy

    auto, most = {"kind": "auto"}, 2 * AUTO_EACH_CASES_PER_CORE  # on two cores
    assert resolve_policy(auto, 1, cores=2) == resolve_policy(auto, most, cores=2)
    assert resolve_policy(auto, most, cores=2) == {"kind": "each"}
    assert resolve_policy(auto, most + 1, cores=2) == {"kind": "all"}
    assert resolve_policy(auto, most + 1, cores=4) == {"kind": "each"}
    assert resolve_policy(auto, 1, process_count=2) == {"kind": "all"}  # jax.distributed
    groups = {"kind": "groups", "group_size": 2}
    assert resolve_policy(groups, 3) == groups
    with pytest.raises(ValueError, match="every case in every process"):
        resolve_policy({"kind": "each"}, 3, process_count=2)


def test_a_case_run_alone_is_the_single_run_bit_for_bit_and_resumes_as_started(tmp_path):
    """Policy `each` (what `auto` takes for a small sweep): every case is `run_scene` of its
    parameters, bit for bit (q, q̇, steps), its features `evaluate` of that run; a chunk's
    padding (3 cases in chunks of 2) is not run twice; a sweep stopped after its first chunk
    and resumed with the default policy (`auto`) finishes as it was started, with the same
    cases."""
    from jaxdeploy.batch import run_scene
    from jaxdeploy.mechanism import without_balance_meter
    from jaxdeploy.scenes import Pendulum
    from jaxdeploy.sweep import sweep

    scene = Pendulum()
    grid = {"initial_angle": [0.3, -1.2, 2.5]}
    control = {"rtol": 1e-7, "atol": 1e-9}
    common = dict(t_end=0.3, n_save=11, control=control, chunk_size=2, energy_meter=True)
    ran = []

    def evaluate(params, trajectory):
        return {"last_angle": trajectory.q[-1, 2] + 0.0 * params["initial_angle"]}

    def summarize(params, trajectory):
        ran.append(params["initial_angle"])
        return {"steps": int(trajectory.stats["num_accepted_steps"])}

    out = str(tmp_path / "each")
    with pytest.raises(KeyboardInterrupt):
        sweep(scene, grid, out, stop_after_chunks=1, evaluate=evaluate, features="last_angle",
              summarize=summarize, policy="each", **common)  # fmt: skip
    manifest = sweep(scene, grid, out, resume=True, evaluate=evaluate, features="last_angle",
                     summarize=summarize, **common)  # fmt: skip
    assert manifest["definition"]["policy"] == {"kind": "each"}
    assert manifest["devices"] and len(manifest["chunks"]) == 2
    assert sorted(ran) == sorted(grid["initial_angle"])  # each case once, padding not run
    swept = load_sweep(out)
    for i, angle in enumerate(grid["initial_angle"]):
        params = scene.resolve_params({"initial_angle": angle})
        single = run_scene(scene, params, 0.3, n_save=11, control=control, energy_meter=True)
        np.testing.assert_array_equal(swept["q"][i], single.q)
        np.testing.assert_array_equal(swept["v"][i], single.v)
        assert swept["num_steps"][i] == int(single.stats["num_accepted_steps"])
        plain = without_balance_meter(single)
        assert swept["feature_last_angle"][i] == float(plain.q[-1, 2])


def test_sweep_cli_refuses_a_bad_policy(tmp_path):
    from jaxdeploy.cli import main

    out = tmp_path / "s"
    code = main(["sweep", "--scene", "pendulum", "--grid", "length=1,2", "--out", str(out),
                 "--policy", "groups:x", "--quiet"])  # fmt: skip
    assert code == 2 and not out.exists()


def test_a_sweep_uses_one_device_per_core_unless_told(tmp_path):
    """`jaxdeploy sweep` splits the CPU into one JAX device per usable core before JAX starts
    (chunks run their shards side by side); `--devices N` chooses the count, and a resumed
    sweep keeps the count it was started with (its later chunks are batched as its earlier
    ones were). The environment's own setting is left alone."""
    from jaxdeploy.commands._devices import usable_cores

    env = _env(tmp_path / "cache")
    del env["XLA_FLAGS"]  # the environment does not fix the device count here
    env.pop("JAX_NUM_CPU_DEVICES", None)
    small = ["--grid", "initial_angle=0.0,0.3", "--t-end", "0.05", "--n-save", "5", "--quiet",
             "--policy", "all"]  # fmt: skip

    def sweep(out, *extra):
        command = [sys.executable, "-m", "jaxdeploy.cli", "sweep", "--scene", "pendulum"]
        done = subprocess.run(
            [*command, *small, "--out", str(out), *extra],
            env=env, capture_output=True, text=True, timeout=600,
        )  # fmt: skip
        assert done.returncode == 0, done.stderr
        return json.loads((out / "manifest.json").read_text())["devices"]

    assert len(sweep(tmp_path / "default")) == usable_cores()
    assert len(sweep(tmp_path / "one", "--devices", "1")) == 1
    # A sweep whose cases run alone (`each`) keeps one device: a process of several keeps
    # no compiled program in the program cache; its cases use the cores as threads.
    small.remove("all")
    small.remove("--policy")
    assert len(sweep(tmp_path / "each")) == 1  # `auto`: two cases run alone

    from jaxdeploy.commands.sweep import _resumed_devices

    assert _resumed_devices(str(tmp_path / "one")) == 1
    assert _resumed_devices(str(tmp_path / "missing")) is None


@pytest.mark.parametrize(
    ("extra", "environment", "message"),
    [
        (["--devices", "0"], {}, "--devices = 0 is invalid: it must be ≥ 1"),
        (["--devices", "2", "--distributed"], {}, "--devices does not apply with --distributed"),
        (
            ["--devices", "2"],
            {"XLA_FLAGS": "--xla_force_host_platform_device_count=3"},
            "XLA_FLAGS=--xla_force_host_platform_device_count already sets",
        ),
    ],
)
def test_a_device_count_that_cannot_hold_is_refused(
    tmp_path, capsys, monkeypatch, extra, environment, message
):
    from jaxdeploy.cli import main

    for name, value in environment.items():
        monkeypatch.setenv(name, value)
    code = main(["sweep", "--scene", "pendulum", "--out", str(tmp_path / "s"), *extra])
    assert code == 2 and message in capsys.readouterr().err
    assert not (tmp_path / "s").exists()


def test_devices_asked_for_after_jax_started_are_refused(tmp_path, capsys):
    """In a process where JAX already runs (a script, these tests) the device count is fixed:
    an explicit --devices that differs is refused, naming the count it has."""
    import jax

    from jaxdeploy.cli import main

    other = jax.device_count() + 1
    code = main(["sweep", "--scene", "pendulum", "--out", str(tmp_path / "s"),
                 "--devices", str(other)])  # fmt: skip
    err = capsys.readouterr().err
    assert code == 2 and f"JAX already runs in this process with {jax.device_count()}" in err


@pytest.mark.slow  # ~100 s on 2 cores: compiles deploy_array's batched run and its probe
def test_a_sharded_deploy_array_sweep_finishes(tmp_path):
    """deploy_array sharded over two host devices, as `jaxdeploy sweep` runs it by default
    on two cores. With the saved accelerations solved after the loop (`batch_function`'s
    default, `simulate`'s `batch_saved_accelerations`) this hung in the run-length probe,
    every XLA thread idle: deploy_array's solve is LAPACK's `potrf` (its Schur complement
    exceeds `saddle_point.UNROLLED_MAX_SIZE`), batched there over every saved time, and the
    same run unrolled finished. `batch_function` solves them in the loop when it shards.
    A hang fails here at the timeout instead of stalling the suite."""
    env = _env(tmp_path / "cache")
    env["XLA_FLAGS"] = "--xla_force_host_platform_device_count=2"
    out = tmp_path / "out"
    command = [sys.executable, "-m", "jaxdeploy.cli", "sweep", "--scene", "deploy_array",
               "--grid", "spring_stiffness=1.2:1.8:4", "--t-end", "0.1", "--long-run",
               "--policy", "all", "--quiet", "--out", str(out)]  # fmt: skip
    # 24 s here; without the guard it was still waiting after 200 s (18 CPU-s, then idle).
    done = subprocess.run(command, env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    manifest = json.loads((out / "manifest.json").read_text())
    assert len(manifest["devices"]) == 2
    assert sorted(load_sweep(str(out))["case"]) == [0, 1, 2, 3]  # every case, once


@pytest.mark.slow  # ~1 CPU-min: three sweep processes on four forced devices
def test_a_sharded_sweeps_program_is_traced_by_the_first_process_only(tmp_path):
    """The vmapped chunk program, sharded over four devices, is kept by the program cache
    (`sweep._chunk_program`): a second process with the same definition traces nothing of
    it; both write the chunks a process without the caches (`batch_function` traced in it)
    writes, bit for bit."""

    def run(name, cache):
        env = _env(tmp_path / "jax")
        env["JAXDEPLOY_CACHE_DIR"] = cache
        argv = _command(tmp_path / name)[3:]  # what follows `python -m jaxdeploy.cli`
        done = subprocess.run([sys.executable, "-c", TRACED_COMMAND, *argv], env=env,
                              capture_output=True, text=True, timeout=600)  # fmt: skip
        assert done.returncode == 0, done.stderr[-3000:]
        report = json.loads(done.stdout.strip().splitlines()[-1])
        assert report["code"] == 0
        return report["traced"], load_sweep(tmp_path / name)

    first, a = run("first", str(tmp_path / "cache"))
    second, b = run("second", str(tmp_path / "cache"))
    plain, c = run("plain", "off")
    assert "exported__chunk_program" in first, first
    assert not [name for name in second if name.startswith("exported_")], second
    assert "run" in plain and not [name for name in plain if "chunk_program" in name], plain
    for key in ("q", "v", "num_steps", "result"):
        np.testing.assert_array_equal(a[key], b[key])
        np.testing.assert_array_equal(a[key], c[key])
