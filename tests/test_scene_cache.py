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
        return scene.initial_state(params, mechanism)

    return _scene_cache.built(scene, params, build, assemble)


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


def test_a_second_command_reads_the_scene_and_gives_identical_results(tmp_path):
    env = {k: v for k, v in os.environ.items() if k != "EQX_ON_ERROR"}
    env["JAXDEPLOY_CACHE_DIR"] = str(tmp_path / "xla")
    outputs = []
    for run in ("first", "second"):
        out = tmp_path / run
        done = subprocess.run(
            [sys.executable, "-m", "jaxdeploy.cli", "simulate", "pendulum", "--t-end", "0.1",
             "--n-save", "11", "--out", str(out)],
            env=env, capture_output=True, text=True,
        )  # fmt: skip
        assert done.returncode == 0, done.stderr[-2000:]
        outputs.append((done.stderr, out))
    assert "from the scene cache" not in outputs[0][0]
    assert "from the scene cache" in outputs[1][0]
    with (
        np.load(outputs[0][1] / "trajectory.npz") as a,
        np.load(outputs[1][1] / "trajectory.npz") as b,
    ):
        for name in a.files:
            assert a[name].tobytes() == b[name].tobytes(), name
    first, second = (json.loads((out / "summary.json").read_text()) for _, out in outputs)
    assert first["status"] == second["status"] == "ok"
