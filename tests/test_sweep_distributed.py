"""A sweep run as two processes through `jax.distributed` (two CPU processes on this machine,
one device each, as two hosts would run it): every case exactly once, each equal to the same
sweep run in one process (issue 21 item 4)."""

import json
import os
import socket
import subprocess
import sys

import numpy as np
import pytest

from jaxdeploy.sweep import load_sweep

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
# 3 angles x 3 lengths = 9 cases in chunks of 2 (one per process): 5 chunks, the last padded.
GRID = ["--grid", "initial_angle=0.0,0.3,-0.6", "--grid", "length=0.5,1.0,2.0"]


def _command(out, *extra):
    return [sys.executable, "-m", "jaxdeploy.cli", "sweep", "--scene", "pendulum", *GRID,
            "--t-end", "0.2", "--n-save", "11", "--chunk-size", "2", "--out", str(out),
            "--quiet", *extra]  # fmt: skip


def _free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _environment():
    env = {**os.environ, "JAX_PLATFORMS": "cpu"}
    env["PYTHONPATH"] = ROOT + os.pathsep + env.get("PYTHONPATH", "")
    env.pop("XLA_FLAGS", None)  # one device per process
    env["JAX_COORDINATOR_ADDRESS"] = f"127.0.0.1:{_free_port()}"
    env["JAX_NUM_PROCESSES"] = "2"
    return env


def _two_processes(tmp_path, env, out):
    """Run the sweep as two `--distributed` processes into `out`: (exit codes, their output)."""
    # Output to files, not pipes: a process blocked on a full pipe that nobody reads yet
    # would miss the coordination service's shutdown barrier and take the other one down.
    logs = [tmp_path / f"process{i}.log" for i in range(2)]
    processes = []
    for i, log in enumerate(logs):
        with open(log, "w") as sink:
            command = _command(out, "--distributed")
            processes.append(subprocess.Popen(command, env={**env, "JAX_PROCESS_ID": str(i)},
                                              stdout=sink, stderr=subprocess.STDOUT))  # fmt: skip
    for proc in processes:
        proc.wait(timeout=900)
    return [proc.returncode for proc in processes], [log.read_text() for log in logs]


@pytest.mark.slow
def test_sweep_as_two_processes_loses_and_duplicates_no_case(tmp_path):
    env = _environment()
    out = tmp_path / "two"
    codes, logs = _two_processes(tmp_path, env, out)
    report = "\n".join(f"process {k}: {log[-2000:]}" for k, log in enumerate(logs))
    assert codes == [0, 0], report
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["process_count"] == 2 and len(manifest["devices"]) == 2
    assert manifest["n_cases"] == 9 and len(manifest["chunks"]) == 5
    two = load_sweep(out)  # raises on a duplicated case
    assert sorted(two["case"].tolist()) == list(range(9))

    single_env = {k: v for k, v in env.items() if not k.startswith("JAX_") or k == "JAX_PLATFORMS"}
    one = tmp_path / "one"
    done = subprocess.run(_command(one), env=single_env, capture_output=True, text=True,
                          timeout=900)  # fmt: skip
    assert done.returncode == 0, done.stderr[-3000:]
    reference = load_sweep(one)
    order, ref_order = np.argsort(two["case"]), np.argsort(reference["case"])
    for key in ("param_initial_angle", "param_length", "num_steps"):
        np.testing.assert_array_equal(two[key][order], reference[key][ref_order], err_msg=key)
    # One process vmaps a chunk's 2 cases on its one device, two processes run 1 case each:
    # other batch shapes, so the states agree to round-off (measured 3e-15 rad), not bit for bit.
    np.testing.assert_allclose(two["q"][order], reference["q"][ref_order], rtol=0, atol=1e-12)


@pytest.mark.slow
def test_two_processes_refuse_a_busy_folder_together(tmp_path):
    """Another run holds the folder: process 0 (the one that locks and writes) says so, and
    process 1 refuses with it instead of waiting for it in the first chunk (exit 2 both)."""
    from jaxdeploy._output_folder import FolderLock

    out = tmp_path / "busy"
    with FolderLock(str(out)).claim():
        codes, logs = _two_processes(tmp_path, _environment(), out)
    assert codes == [2, 2], logs
    assert "is in use by another run" in logs[0], logs[0]
    assert "process 0 of this --distributed run refused" in logs[1], logs[1]
    assert not out.exists()


def test_distributed_environment_is_read_and_checked(monkeypatch):
    from jaxdeploy.commands.sweep import _distributed_from_environment

    monkeypatch.setenv("JAX_NUM_PROCESSES", "4")
    monkeypatch.setenv("JAX_PROCESS_ID", "3")
    assert _distributed_from_environment() == {"num_processes": 4, "process_id": 3}
    monkeypatch.delenv("JAX_PROCESS_ID")
    assert _distributed_from_environment() == {"num_processes": 4}
    monkeypatch.setenv("JAX_NUM_PROCESSES", "two")
    with pytest.raises(ValueError, match="JAX_NUM_PROCESSES = 'two' is invalid"):
        _distributed_from_environment()
