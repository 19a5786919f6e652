"""`jaxdeploy simulate`'s scene cache (jaxdeploy/commands/_scene_cache.py): a stored mechanism
and initial state come back with the same arrays, dtypes and weak types (so the programs they
flow into keep their keys), the key follows the scene, its options and every parameter value,
a damaged or misplaced entry is discarded with one line and built again, and a second command
run reads it instead of building (its results bit for bit the first's). Counts, never
times."""

import json
import os
import subprocess
import sys

import jax
import numpy as np
import pytest

from jaxdeploy import _program_cache
from jaxdeploy.commands import _scene_cache
from jaxdeploy.scenes import Pendulum, SliderCrank


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("JAXDEPLOY_CACHE_DIR", str(tmp_path / "xla"))
    return tmp_path / "xla-scenes"


def _built(scene, params, counts):
    def build():
        counts["build"] += 1
        return scene.build(params)

    def assemble(mechanism):
        counts["assemble"] += 1
        return scene.initial_state(params, mechanism), {"n": mechanism.n_coordinates}

    mechanism, initial, facts, source = _scene_cache.built(scene, params, build, assemble)
    assert facts == {"n": mechanism.n_coordinates}  # kept with the mechanism
    return mechanism, initial, source


def test_a_stored_scene_comes_back_with_the_same_leaves_and_program_key(cache):
    scene = SliderCrank()
    params = scene.resolve_params()
    counts = {"build": 0, "assemble": 0}
    mechanism, initial, source = _built(scene, params, counts)
    assert source == "built" and len(list(cache.glob("*.pickle"))) == 1
    again, initial_again, source = _built(scene, params, counts)
    assert source == "cache" and counts == {"build": 1, "assemble": 1}
    leaves, leaves_again = (
        jax.tree.leaves((mechanism, initial)),
        jax.tree.leaves((again, initial_again)),
    )
    assert jax.tree.structure((mechanism, initial)) == jax.tree.structure((again, initial_again))
    for a, b in zip(leaves, leaves_again, strict=True):
        assert type(a) is type(b)
        if hasattr(a, "shape"):
            assert jax.typeof(a) == jax.typeof(b)  # dtype, shape and weak type
            np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
        else:
            assert a == b

    def program(*args):
        return None

    assert _program_cache.key(program, (mechanism, initial)) == _program_cache.key(
        program, (again, initial_again)
    )


def test_the_key_follows_scene_options_and_every_value(cache):
    scene = Pendulum()
    params = scene.resolve_params()
    base = _scene_cache.key(scene, params)
    assert base == _scene_cache.key(Pendulum(), dict(params))
    for name, value in params.items():
        changed = {**params, name: float(value) * (1 + 2**-50) + 2**-1000}
        assert _scene_cache.key(scene, changed) != base, name
    assert _scene_cache.key(SliderCrank(), SliderCrank().resolve_params()) != base
    crank = SliderCrank()
    assert _scene_cache.key(crank, crank.resolve_params()) != _scene_cache.key(
        SliderCrank(ideal=True), crank.resolve_params()
    )
    # A value that is not a plain number (here an array) is not cached at all.
    assert _scene_cache.key(scene, {**params, "length": np.float64(1.0)}) is None


def test_a_damaged_or_misplaced_entry_is_discarded_and_built_again(cache, capsys):
    scene = Pendulum()
    params = scene.resolve_params()
    counts = {"build": 0, "assemble": 0}
    _built(scene, params, counts)
    (entry,) = cache.glob("*.pickle")
    entry.write_bytes(entry.read_bytes()[:-40] + b"\0" * 40)
    _, _, source = _built(scene, params, counts)
    assert source == "built" and counts["build"] == 2
    assert "scene cache: discarding" in capsys.readouterr().err
    # A good entry of other parameters under this key's name.
    other = {**params, "length": 2.0}
    _built(scene, other, counts)
    other_path = cache / f"{_scene_cache.key(scene, other)}.pickle"
    os.replace(other_path, entry)
    mechanism, _, source = _built(scene, params, counts)
    assert source == "built" and counts["build"] == 4
    assert "another scene or parameters" in capsys.readouterr().err
    _, _, source = _built(scene, params, counts)  # rewritten: read back now
    assert source == "cache" and counts["build"] == 4


def test_cache_off_stores_nothing(tmp_path, monkeypatch):
    monkeypatch.setenv("JAXDEPLOY_CACHE_DIR", "off")
    scene = Pendulum()
    counts = {"build": 0, "assemble": 0}
    _built(scene, scene.resolve_params(), counts)
    _built(scene, scene.resolve_params(), counts)
    assert counts == {"build": 2, "assemble": 2}


# `jaxdeploy simulate` in a new process, printing (on stderr's last line) the functions JAX
# traced in it.
_COMMAND = """
import json, sys
from jax import monitoring
traced = []
def record(event, start, end, **kwargs):
    if event == "/jax/core/compile/jaxpr_trace_duration":
        traced.append(kwargs.get("fun_name"))
monitoring.register_event_time_span_listener(record)
from jaxdeploy.cli import main
code = main(sys.argv[1:])
print(json.dumps(traced), file=sys.stderr)
sys.exit(code)
"""


def test_a_second_command_reads_the_scene_traces_no_program_and_gives_identical_results(
    tmp_path,
):
    """The second run reads the scene and every program back: of the functions the first
    traced (the assembly, the run, the plausibility checks' constraint residuals, the energy
    balance, the analysis's drift), it traces none; what is left are JAX's single
    operations on concrete arrays."""
    env = {k: v for k, v in os.environ.items() if k != "EQX_ON_ERROR"}
    env["JAXDEPLOY_CACHE_DIR"] = str(tmp_path / "xla")
    runs = []
    for run in ("first", "second"):
        out = tmp_path / run
        done = subprocess.run(
            [sys.executable, "-c", _COMMAND, "simulate", "pendulum", "--t-end", "0.1",
             "--n-save", "11", "--out", str(out)],
            env=env, capture_output=True, text=True,
        )  # fmt: skip
        assert done.returncode == 0, done.stderr[-2000:]
        runs.append((done.stderr, json.loads(done.stderr.strip().splitlines()[-1]), out))
    (first_err, first, first_out), (second_err, second, second_out) = runs
    assert "from the scene cache" not in first_err and "from the scene cache" in second_err
    programs = {
        "_consistent_core", "_solve", "residuals", "_metered_energy_balance", "_largest_residual"
    }  # fmt: skip
    assert {f"exported_{name}" for name in programs} <= set(first), first
    assert not [n for n in second if n.startswith(("exported_", "kept_")) or n in programs], second
    assert "init_memory" not in second  # the memory estimate is kept with the scene
    with np.load(first_out / "trajectory.npz") as a, np.load(second_out / "trajectory.npz") as b:
        for name in a.files:
            assert a[name].tobytes() == b[name].tobytes(), name
    summaries = [json.loads((out / "summary.json").read_text()) for out in (first_out, second_out)]
    assert summaries[0]["status"] == summaries[1]["status"] == "ok"
    assert summaries[0]["max_constraint_violation"] == summaries[1]["max_constraint_violation"]
