"""Compiled programs read ahead (`jaxdeploy/_read_ahead.py`): a script or `jaxdeploy simulate`
run again loads the executables its last run ran in a background thread. Checked by what the
process took from the read-ahead (`_program_cache.executables_read_ahead`) and by the results'
bits, never by seconds; a damaged or foreign hint is discarded with one line and rewritten."""

import json
import os
import subprocess
import sys

import pytest

from jaxdeploy import _program_cache, _read_ahead

# A user's script (a file: a script's hint is named by its path), printing what it took from
# the read-ahead, what JAX traced and the run's bits.
_SCRIPT = """
import json, sys
from jax import monitoring

traced = []
def record(event, start, end, **kwargs):
    if event == "/jax/core/compile/jaxpr_trace_duration":
        traced.append(kwargs.get("fun_name"))
monitoring.register_event_time_span_listener(record)

import jaxdeploy as jd
from jaxdeploy import _program_cache

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
print(json.dumps({"ahead": _program_cache.executables_read_ahead(),
                  "run": list(_program_cache.executables_run()),
                  "traced": traced, "bits": q.tobytes().hex()}))
"""


def _run(script, cache):
    env = {k: v for k, v in os.environ.items() if k not in ("EQX_ON_ERROR", "JAXDEPLOY_CACHE_DIR")}
    proc = subprocess.run(
        [sys.executable, str(script), str(cache)], env=env, capture_output=True, text=True
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1]), proc.stderr


@pytest.fixture
def script(tmp_path):
    path = tmp_path / "my_study.py"
    path.write_text(_SCRIPT)
    return path


def _hints(cache):
    return list((cache.parent / (cache.name + "-programs")).glob(f"*{_read_ahead.SUFFIX}"))


def test_a_script_run_again_reads_its_programs_ahead_with_identical_results(tmp_path, script):
    cache = tmp_path / "cache"
    first, _ = _run(script, cache)
    assert first["ahead"] == [] and first["run"], first  # nothing to read ahead yet
    (hint,) = _hints(cache)
    recorded = json.loads(hint.read_text())
    assert recorded["for"] == "python " + str(script)
    assert [base for base, _ in recorded["executables"]] == [
        os.path.basename(p) for p in first["run"]
    ]
    second, stderr = _run(script, cache)
    # Every program the second process ran came from the read-ahead, none was traced, and
    # the results are those of the first process bit for bit.
    assert second["ahead"] == second["run"] == first["run"], second
    assert not [n for n in second["traced"] if n.startswith("exported_")], second["traced"]
    assert second["bits"] == first["bits"]
    assert "warning" not in stderr


@pytest.mark.parametrize(
    "damage",
    ["not json", "foreign", "digest", "a path"],
)
def test_a_damaged_or_foreign_hint_is_discarded_with_one_line_and_rewritten(
    tmp_path, script, damage
):
    cache = tmp_path / "cache"
    first, _ = _run(script, cache)
    (hint,) = _hints(cache)
    recorded = json.loads(hint.read_text())
    if damage == "not json":
        hint.write_text("{half a hint")
    elif damage == "foreign":
        recorded["for"] = "python /elsewhere/other.py"
        hint.write_text(json.dumps(recorded))
    elif damage == "digest":
        recorded["executables"] = recorded["executables"][:1]
        hint.write_text(json.dumps(recorded))
    else:  # a file outside the folder, under a valid digest
        entries = [["../../etc/passwd", False]]
        recorded["executables"] = entries
        recorded["digest"] = _read_ahead._digest(recorded["for"], entries)
        hint.write_text(json.dumps(recorded))
    second, stderr = _run(script, cache)
    lines = [line for line in stderr.splitlines() if "discarding" in line]
    assert len(lines) == 1 and str(hint) in lines[0] and "reading nothing ahead" in lines[0]
    assert second["ahead"] == [] and second["bits"] == first["bits"]
    # Rewritten by the process that discarded it: the next one reads ahead again.
    assert json.loads(hint.read_text())["for"] == "python " + str(script)
    third, stderr = _run(script, cache)
    assert third["ahead"] == third["run"] and "discarding" not in stderr


def test_a_stale_hint_costs_nothing_but_the_read(tmp_path, script):
    """A hint that names another program's executable (a script whose programs changed): the
    executable read ahead is never used for a program it does not belong to."""
    cache = tmp_path / "cache"
    first, _ = _run(script, cache)
    (hint,) = _hints(cache)
    recorded = json.loads(hint.read_text())
    # Swap the order: each executable's future now sits under its own path still (the hint
    # names files, the program cache asks by the path of the entry it runs).
    recorded["executables"] = recorded["executables"][::-1]
    recorded["digest"] = _read_ahead._digest(recorded["for"], recorded["executables"])
    hint.write_text(json.dumps(recorded))
    second, _ = _run(script, cache)
    assert sorted(second["ahead"]) == sorted(first["run"]) and second["bits"] == first["bits"]


def test_read_hint_accepts_only_its_own_executables(tmp_path):
    name = "python /x.py"
    base = "a" * 64 + "-" + "b" * 16 + ".executable"
    good = [[base, True]]
    path = tmp_path / "h.ahead.json"
    path.write_text(json.dumps({"for": name, "executables": good, "digest": _read_ahead._digest(
        name, good)}))  # fmt: skip
    assert _read_ahead.read_hint(str(path), name) == [(base, True)]
    assert _read_ahead.read_hint(str(tmp_path / "missing.json"), name) is None
    for bad in (["x.executable", True], [base], ["/abs/" + base, False]):
        path.write_text(json.dumps({"for": name, "executables": [bad],
                                    "digest": _read_ahead._digest(name, [bad])}))  # fmt: skip
        assert _read_ahead.read_hint(str(path), name) is None
        assert not path.exists()  # discarded


def test_nothing_is_read_ahead_with_the_program_cache_off(monkeypatch):
    monkeypatch.setattr(_program_cache, "_folder", None)
    _read_ahead.start("python /nowhere.py")
    assert "python /nowhere.py" not in _read_ahead._started


def test_the_command_line_reads_a_run_ahead_and_a_refusal_exits_cleanly(tmp_path):
    env = {k: v for k, v in os.environ.items() if k not in ("EQX_ON_ERROR",)}
    env["JAXDEPLOY_CACHE_DIR"] = str(tmp_path / "cache")
    command = [sys.executable, "-m", "jaxdeploy.cli", "simulate", "pendulum", "--t-end", "0.05",
               "--quiet", "--overwrite"]  # fmt: skip

    def run(*extra):
        return subprocess.run([*command, *extra], env=env, capture_output=True, text=True)

    first = run("--out", str(tmp_path / "a"))
    assert first.returncode == 0, first.stderr[-2000:]
    (hint,) = _hints(tmp_path / "cache")
    assert json.loads(hint.read_text())["for"].startswith("jaxdeploy simulate ['pendulum'")
    second = run("--out", str(tmp_path / "b"))
    assert second.returncode == 0, second.stderr[-2000:]
    import numpy as np

    a, b = (np.load(tmp_path / d / "trajectory.npz") for d in "ab")
    assert all(a[k].tobytes() == b[k].tobytes() for k in a.files)
    # A refusal while the read-ahead runs: exit 2 with its message, no crash at shutdown,
    # and the hint is kept (the refused run ran nothing).
    before = hint.read_text()
    refused = run("--out", str(tmp_path / "c"), "--set", "length=-1")
    assert refused.returncode == 2, refused.stderr[-2000:]
    assert "length" in refused.stderr and "Traceback" not in refused.stderr
    assert hint.read_text() == before
