"""The program cache (jaxdeploy/_program_cache.py): an exported program is reused only for the
same code, composition and shapes, its results are bit-identical to the function's own, and a
corrupt entry is ignored with a warning."""

import os
import subprocess
import sys
import textwrap

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.experimental.compilation_cache import compilation_cache

from jaxdeploy import _program_cache


@eqx.filter_jit
def _toy(x, scale, power):
    """A program whose trace bakes in `scale` and `power` (static) and takes `x` as data."""
    return {"y": scale * x**power, "n": power}


@pytest.fixture
def store(tmp_path, monkeypatch):
    """The store on, in a fresh folder, as in a process whose equinox checks are not host
    callbacks (the toy program has none either way)."""
    monkeypatch.setattr(_program_cache, "equinox_on_error", lambda: "nan")
    monkeypatch.setattr(_program_cache, "_unexportable", set())
    monkeypatch.setattr(_program_cache, "_loaded", {})
    monkeypatch.setattr(_program_cache, "_compiled", {})
    # JAX's own persistent cache off: an earlier test in this process (a command's `main`)
    # may have switched it on and compiled the toy program, and an executable JAX reads from
    # it is not kept (`_program_cache._compile_and_keep`), so the kept-executable tests would
    # depend on the order the tests run in.
    enabled = jax.config.jax_enable_compilation_cache
    jax.config.update("jax_enable_compilation_cache", False)
    compilation_cache.reset_cache()  # JAX reads the setting once per process otherwise
    _program_cache.enable(str(tmp_path / "programs"))
    yield tmp_path / "programs"
    _program_cache.enable(None)
    jax.config.update("jax_enable_compilation_cache", enabled)
    compilation_cache.reset_cache()


def _entries(folder):
    return sorted(p.name for p in folder.glob("*.jaxexport"))


def test_a_hit_reads_the_stored_program_and_gives_the_functions_result(store):
    x = jnp.linspace(0.1, 2.0, 7)
    first = _program_cache.call(_toy, x, 1.5, 3)
    assert len(_entries(store)) == 1
    _program_cache._loaded.clear()  # as in a new process: read from the disk
    _program_cache._compiled.clear()
    again = _program_cache.call(_toy, x + 1.0, 1.5, 3)  # new values, same program
    assert len(_entries(store)) == 1
    direct = _toy(x + 1.0, 1.5, 3)
    assert first["n"] == again["n"] == 3  # a static output comes back as it was
    np.testing.assert_array_equal(np.asarray(again["y"]), np.asarray(direct["y"]))
    np.testing.assert_array_equal(np.asarray(first["y"]), np.asarray(_toy(x, 1.5, 3)["y"]))


_compiles = []
jax.monitoring.register_event_duration_secs_listener(
    lambda event, duration, **kw: (
        _compiles.append(event) if event == "/jax/core/compile/backend_compile_duration" else None
    )
)


def test_a_process_compiles_a_stored_program_once(store):
    """Calls after the first reuse the program read in this process (a fit or a sweep calls
    again and again): nothing is compiled again."""
    xs = [jnp.linspace(0.1, 2.0, 7) + k for k in range(3)]
    _program_cache.call(_toy, xs[0], 1.5, 3)
    before = len(_compiles)
    for x in xs:
        _program_cache.call(_toy, x, 1.5, 3)
    assert len(_compiles) == before


def test_code_options_and_shapes_each_miss(store, monkeypatch):
    x = jnp.linspace(0.1, 2.0, 7)
    base = _program_cache.key(_toy, (x, 1.5, 3))
    assert base == _program_cache.key(_toy, (x * 2.0, 1.5, 3))  # values are data
    assert base != _program_cache.key(_toy, (jnp.ones(8), 1.5, 3))  # shape
    assert base != _program_cache.key(_toy, (x.astype(jnp.float32), 1.5, 3))  # dtype
    assert base != _program_cache.key(_toy, (x, 1.5 + 1e-15, 3))  # a static float, exactly
    assert base != _program_cache.key(_toy, (x, 1.5, 3.0))  # its type
    assert base != _program_cache.key(_toy, (x, 1.5, 2))  # a composition choice
    monkeypatch.setattr(_program_cache, "_environment", lambda: "other code")
    assert base != _program_cache.key(_toy, (x, 1.5, 3))  # the package's code
    # Through `call`: every changed composition writes its own entry.
    monkeypatch.undo()
    monkeypatch.setattr(_program_cache, "equinox_on_error", lambda: "nan")
    for args in ((x, 1.5, 3), (jnp.ones(8), 1.5, 3), (x, 1.5, 2), (x, 2.5, 3)):
        out = _program_cache.call(_toy, *args)
        np.testing.assert_array_equal(np.asarray(out["y"]), np.asarray(_toy(*args)["y"]))
    assert len(_entries(store)) == 4


class _Composed(eqx.Module):
    x: jax.Array
    power: int = eqx.field(static=True)


def test_static_fields_key_the_structure_each_time(store):
    """The structure's string is kept per structure (`_structure`), so a second call with
    another static field must still get its own key, and NumPy data the key of jax data."""
    x = jnp.linspace(0.1, 2.0, 7)
    keys = [_program_cache.key(_toy, (_Composed(x, p),)) for p in (2, 3, 2, 3)]
    assert keys[0] == keys[2] and keys[1] == keys[3] and keys[0] != keys[1]
    assert keys[0] == _program_cache.key(_toy, (_Composed(np.asarray(x), 2),))


def test_the_kept_structures_are_bounded(store, monkeypatch):
    x = jnp.linspace(0.1, 2.0, 7)
    monkeypatch.setattr(_program_cache, "_STRUCTURES_KEPT", 2)
    first = [_program_cache.key(_toy, (_Composed(x, p),)) for p in range(5)]
    assert len(_program_cache._structures) <= 2
    assert first == [_program_cache.key(_toy, (_Composed(x, p),)) for p in range(5)]


def test_scene_options_change_the_key(store):
    """A scene option changes the mechanism's composition, hence the key."""
    from jaxdeploy.scenes import get_scene

    keys = set()
    for rule in ("onset", "running_max"):
        scene = get_scene("impact", impact_velocity_rule=rule)
        keys.add(_program_cache.key(_toy, (scene.build(scene.resolve_params()),)))
    assert len(keys) == 2 and None not in keys


def test_what_cannot_be_keyed_runs_uncached(store):
    x = jnp.ones(3)
    offset = 2.0
    closure = lambda y: y + offset  # noqa: E731 - carries data its name does not say
    assert _program_cache.key(_toy, (x, closure, 1)) is None
    assert _program_cache.key(_toy, (x, object(), 1)) is None
    assert _program_cache.key(_toy, (x, jnp.sum, 1)) is not None  # a library function

    @eqx.filter_jit
    def outer(x):
        return _program_cache.call(_toy, x, 2.0, 2)["y"]  # traced: the caller's program

    np.testing.assert_array_equal(np.asarray(outer(x)), np.asarray(_toy(x, 2.0, 2)["y"]))
    assert _entries(store) == []


def test_equinox_host_callbacks_make_it_uncached(store, monkeypatch):
    monkeypatch.setattr(_program_cache, "equinox_on_error", lambda: "raise")
    assert _program_cache.key(_toy, (jnp.ones(3), 1.0, 1)) is None


def test_a_corrupt_entry_is_ignored_with_a_warning_and_replaced(store):
    x = jnp.linspace(0.0, 1.0, 5)
    _program_cache.call(_toy, x, 1.5, 3)
    (name,) = _entries(store)
    (store / name).write_bytes(b"not a program")
    _program_cache._loaded.clear()  # as in a new process
    _program_cache._compiled.clear()
    with pytest.warns(RuntimeWarning, match="unreadable program cache entry"):
        out = _program_cache.call(_toy, x, 1.5, 3)
    np.testing.assert_array_equal(np.asarray(out["y"]), np.asarray(_toy(x, 1.5, 3)["y"]))
    assert _program_cache._load(str(store / name)) is not None  # written again


def test_the_compiled_program_is_kept_and_a_damaged_one_compiled_again(store):
    """Each entry's executable is kept beside it and run by a later process; a damaged one is
    ignored with a warning, compiled again and replaced, with the same results."""
    x = jnp.linspace(0.0, 1.0, 5)
    expected = np.asarray(_toy(x, 1.5, 3)["y"])
    _program_cache.call(_toy, x, 1.5, 3)
    (executable,) = store.glob("*.executable")
    _program_cache._loaded.clear()  # as in a new process: the executable read back
    _program_cache._compiled.clear()
    np.testing.assert_array_equal(np.asarray(_program_cache.call(_toy, x, 1.5, 3)["y"]), expected)
    executable.write_bytes(b"not an executable")
    _program_cache._loaded.clear()
    _program_cache._compiled.clear()
    with pytest.warns(RuntimeWarning, match="unreadable compiled program"):
        out = _program_cache.call(_toy, x, 1.5, 3)
    np.testing.assert_array_equal(np.asarray(out["y"]), expected)
    assert _program_cache._load_executable(str(executable)) is not None  # written again


def test_a_valid_entry_under_another_key_is_discarded_and_rewritten(store):
    """A valid entry of another program under this key's name (issue 30: every later run
    failed, blaming the user's parameters) is discarded with a warning naming the cache and
    the remedy, and the right program is traced and written in its place."""
    x = jnp.linspace(0.0, 1.0, 5)
    _program_cache.call(_toy, x, 1.5, 3)
    _program_cache.call(_toy, x, 2.0, 2)
    wanted = store / f"{_program_cache.key(_toy, (x, 1.5, 3))}.jaxexport"
    (other,) = [p for p in store.glob("*.jaxexport") if p != wanted]
    wanted.write_bytes(other.read_bytes())
    _program_cache._loaded.clear()  # as in a new process
    _program_cache._compiled.clear()
    with pytest.warns(RuntimeWarning, match="program cache: discarding .* another program"):
        out = _program_cache.call(_toy, x, 1.5, 3)
    np.testing.assert_array_equal(np.asarray(out["y"]), np.asarray(_toy(x, 1.5, 3)["y"]))
    assert _program_cache._load(str(wanted), _program_cache.key(_toy, (x, 1.5, 3))) is not None


def test_a_folder_other_users_can_write_is_not_read(store, monkeypatch):
    monkeypatch.setattr(_program_cache, "_unsafe_seen", set())
    x = jnp.linspace(0.0, 1.0, 5)
    _program_cache.call(_toy, x, 1.5, 3)
    os.chmod(store, 0o777)
    _program_cache._loaded.clear()
    _program_cache._compiled.clear()
    with pytest.warns(RuntimeWarning, match="not reading .* writable by other users"):
        out = _program_cache.call(_toy, x, 1.5, 3)
    np.testing.assert_array_equal(np.asarray(out["y"]), np.asarray(_toy(x, 1.5, 3)["y"]))
    assert not _program_cache._loaded  # ran as the function itself


def test_the_command_line_puts_it_beside_the_compilation_cache(tmp_path, monkeypatch):
    from jaxdeploy import _compilation_cache

    monkeypatch.setattr(_compilation_cache, "cache_dir", lambda: str(tmp_path / "xla"))
    try:
        _compilation_cache.enable_compilation_cache()
        assert _program_cache.folder() == str(tmp_path / "xla-programs")
        monkeypatch.setattr(_compilation_cache, "cache_dir", lambda: None)  # =off
        _compilation_cache.enable_compilation_cache()
        assert _program_cache.folder() is None
    finally:
        _program_cache.enable(None)


# In a fresh process with EQX_ON_ERROR=nan (as the command line runs): a scene simulated
# without the store, then through it twice (the entry written, then read back from the disk).
_SIMULATE_THREE_WAYS = """
import sys
import numpy as np
from jaxdeploy import _program_cache
from jaxdeploy.scenes import get_scene
from jaxdeploy.simulation import simulate

scene = get_scene(sys.argv[2])
params = scene.resolve_params()
mechanism = scene.build(params)
initial = scene.initial_state(params, mechanism)
t_end = float(sys.argv[3])
run = lambda: simulate(mechanism, initial, t_end, control=scene.default_control, n_save=21)
runs = [run()]
_program_cache.enable(sys.argv[1])
runs.append(run())
_program_cache._loaded.clear()  # the third reads the entry back from the disk
runs.append(run())
for name in ("ts", "q", "v", "qdd", "lam"):
    a, b, c = (np.asarray(getattr(r, name)) for r in runs)
    assert a.tobytes() == b.tobytes() == c.tobytes(), name
for leaf in ("num_steps", "num_rejected_steps"):
    assert int(runs[0].stats[leaf]) == int(runs[2].stats[leaf]), leaf
assert int(runs[2].stats["num_steps"]) > 0
assert runs[0].ok and runs[2].ok
print("identical", int(runs[0].stats["num_steps"]))
"""


@pytest.mark.parametrize(
    "scene, t_end",
    [
        ("pendulum", 0.5),
        # a clearance joint: events, contact memory, tracked extremes
        pytest.param("slider_crank", 2e-3, marks=pytest.mark.slow),
    ],
)
def test_simulate_through_the_store_is_bit_identical(tmp_path, scene, t_end):
    env = {**os.environ, "EQX_ON_ERROR": "nan", "JAX_PLATFORMS": "cpu"}
    script = textwrap.dedent(_SIMULATE_THREE_WAYS)
    done = subprocess.run(
        [sys.executable, "-c", script, str(tmp_path / "p"), scene, str(t_end)],
        env=env,
        capture_output=True,
        text=True,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    assert "identical" in done.stdout
    assert len(list((tmp_path / "p").glob("*.jaxexport"))) == 1


def test_when_traced_calls_back_once_after_the_trace_and_before_the_compile(store):
    """`when_traced`'s callback runs once, when the first call through the store has its
    program and has compiled nothing yet (jaxdeploy simulate starts its reference run's trace
    there, in a second thread)."""
    seen = []
    compiled_before = []

    def callback():
        seen.append(len(_entries(store)))  # the entry is written: traced and exported
        compiled_before.append(len(_compiles))

    x = jnp.linspace(0.1, 2.0, 5)
    with _program_cache.when_traced(callback):
        count = len(_compiles)
        _program_cache.call(_toy, x, 2.5, 2)
        _program_cache.call(_toy, x, 2.5, 2)
    assert seen == [1]
    assert compiled_before == [count]  # before the backend compile of the program
    with _program_cache.when_traced(callback):
        _program_cache.enable(None)  # store off: the call is `fn(*args)`, no callback
        _program_cache.call(_toy, x, 2.5, 4)
    assert seen == [1]


def test_when_traced_calls_back_ahead_of_time_before_the_compile_and_for_a_read_back(store):
    """Inside `ahead_of_time` the callback comes once the program is lowered for XLA and
    before XLA's compile (the command's assembly traces then, while XLA compiles without the
    GIL: commands/_ahead.py); for an executable read back, which compiles nothing, once it is
    loaded."""
    shape = jax.ShapeDtypeStruct((7,), jnp.float64)
    compiled_before = []

    def make():
        with (
            _program_cache.ahead_of_time(),
            _program_cache.when_traced(lambda: compiled_before.append(len(_compiles))),
            pytest.raises(_program_cache.ProgramReady),
        ):
            _program_cache.call(_toy, shape, 0.75, 2)

    count = len(_compiles)
    make()
    assert compiled_before == [count] and len(_compiles) > count  # then it compiled
    _program_cache._loaded.clear()  # as in a new process: the kept executable is read back
    _program_cache._compiled.clear()
    count = len(_compiles)
    make()
    assert compiled_before[1:] == [count] and len(_compiles) == count


def test_compile_ahead_lets_the_assembly_go_on_once_the_run_is_traced(store, monkeypatch):
    """`CompileAhead.wait_traced` returns while the run's program is still in XLA's compile
    (the compile here waits until the caller has gone on: it would wait for ever, up to the
    timeout, were `wait_traced` to wait for the compile), and the thread finishes it."""
    import threading

    import jaxdeploy.simulation
    import jaxdeploy.solvers
    from jaxdeploy.commands import _ahead

    went_on = threading.Event()
    lowered = _program_cache._lowered

    def lowered_then_held(fn, arrays):
        program = lowered(fn, arrays)

        class Held:
            def compile(self):
                assert went_on.wait(30), "the caller did not go on before the compile"
                return program.compile()

        return Held()

    def run(mechanism, initial, t_end, **_):
        return _program_cache.call(_toy, initial, t_end, 3)

    shape = jax.ShapeDtypeStruct((5,), jnp.float64)
    monkeypatch.setattr(_program_cache, "_lowered", lowered_then_held)
    monkeypatch.setattr(_ahead, "abstract_state", lambda mechanism: shape)
    monkeypatch.setattr(jaxdeploy.solvers, "solver_advice", lambda *a: None)
    monkeypatch.setattr(jaxdeploy.simulation, "simulate", run)
    ahead = _ahead.CompileAhead(1.25, 11, control=None)
    assert ahead.wait_traced() == 0.0  # nothing started: nothing to wait for
    compiles = len(_compiles)
    ahead.start(mechanism=None)
    ahead.wait_traced()
    assert len(_compiles) == compiles  # gone on before the compile
    went_on.set()
    ahead.wait()
    assert len(_compiles) > compiles and len(_entries(store)) == 1


def test_a_command_called_from_python_leaves_the_program_cache_as_it_found_it(
    tmp_path, monkeypatch
):
    """`jaxdeploy.cli.main([...])` turns the caches on for its command only: a test or script
    that simulates after it (with a setting the store's key does not see, e.g. a monkeypatched
    factor size) must not read the command's stored programs."""
    from jaxdeploy.cli import main

    monkeypatch.setenv("JAXDEPLOY_CACHE_DIR", str(tmp_path / "xla"))
    before = _program_cache.folder()
    assert main(["scenes"]) == 0
    assert _program_cache.folder() == before


def test_the_energy_meters_initial_state_is_a_stored_program(store):
    """`jaxdeploy simulate` initialises the energy meter of a metered mechanism through the
    store (commands/simulate.py `_metered`): run operation by operation it cost a warm
    deploy_array run 0.9 s of tracing and dispatch. A second process reads the program back
    and gets the same state as the operations give (the pendulum's, bit for bit)."""
    from jaxdeploy.commands import simulate as command
    from jaxdeploy.mechanism import balance_metered, balance_metered_state
    from jaxdeploy.scenes import get_scene

    scene = get_scene("pendulum")
    params = scene.resolve_params({})
    mechanism = scene.build(params)
    initial = scene.initial_state(params, mechanism)  # its assembly is stored too
    before = len(_entries(store))
    first = command._metered(mechanism, initial)
    assert first.metered is not None and len(_entries(store)) == before + 1
    _program_cache._loaded.clear()  # as in a new process: read from the disk
    _program_cache._compiled.clear()
    again = command._metered(mechanism, initial)
    assert len(_entries(store)) == before + 1
    expected = balance_metered_state(balance_metered(mechanism), initial)
    for run in (first, again):
        for got, want in zip(jax.tree.leaves(run.initial), jax.tree.leaves(expected), strict=True):
            np.testing.assert_array_equal(np.asarray(got), np.asarray(want))


_traces = []
jax.monitoring.register_event_duration_secs_listener(
    lambda event, duration, **kw: (
        _traces.append(kw.get("fun_name"))
        if event == "/jax/core/compile/jaxpr_trace_duration"
        else None
    )
)


def _exported_traces(name="exported__toy"):
    return sum(1 for n in _traces if n == name)


def test_ahead_of_time_makes_the_program_from_shapes_and_a_later_call_only_runs_it(store):
    """`ahead_of_time`: from `ShapeDtypeStruct`s alone the program is traced, stored and
    compiled, and nothing runs (`ProgramReady`); the call with real arrays then neither
    traces nor compiles, and gives `fn`'s result bit for bit."""
    x = jnp.linspace(0.1, 2.0, 6)
    shape = jax.ShapeDtypeStruct(x.shape, x.dtype)
    assert _program_cache.key(_toy, (shape, 1.5, 3)) == _program_cache.key(_toy, (x, 1.5, 3))
    traced = _exported_traces()
    with _program_cache.ahead_of_time(), pytest.raises(_program_cache.ProgramReady) as made:
        _program_cache.call(_toy, shape, 1.5, 3)
    assert made.value.ready
    assert _exported_traces() == traced + 1 and len(_entries(store)) == 1
    compiles = len(_compiles)
    out = _program_cache.call(_toy, x, 1.5, 3)
    assert _exported_traces() == traced + 1 and len(_compiles) == compiles
    np.testing.assert_array_equal(np.asarray(out["y"]), np.asarray(_toy(x, 1.5, 3)["y"]))
    # A weak-typed shape is another program (the key says so), made separately.
    weak = jax.ShapeDtypeStruct(x.shape, x.dtype, weak_type=True)
    assert _program_cache.key(_toy, (weak, 1.5, 3)) != _program_cache.key(_toy, (x, 1.5, 3))


def test_ahead_of_time_makes_nothing_when_the_call_is_not_cacheable(store):
    shape = jax.ShapeDtypeStruct((4,), jnp.float64)
    _program_cache.enable(None)
    with _program_cache.ahead_of_time(), pytest.raises(_program_cache.ProgramReady) as made:
        _program_cache.call(_toy, shape, 1.5, 3)
    assert not made.value.ready


def test_a_call_while_its_program_is_made_ahead_waits_for_it(store, monkeypatch):
    """A call that comes while another thread makes the same program ahead waits for it (one
    lock per program) instead of tracing it a second time."""
    import threading

    x = jnp.linspace(0.1, 2.0, 9)
    exporting, release = threading.Event(), threading.Event()
    export = _program_cache._export

    def slow_export(fn, args, cache_key):
        exporting.set()
        release.wait(30)
        return export(fn, args, cache_key)

    monkeypatch.setattr(_program_cache, "_export", slow_export)

    def ahead():
        with _program_cache.ahead_of_time():
            try:
                _program_cache.call(_toy, jax.ShapeDtypeStruct(x.shape, x.dtype), 0.5, 2)
            except _program_cache.ProgramReady:
                pass

    traced = _exported_traces()
    thread = threading.Thread(target=ahead)
    thread.start()
    assert exporting.wait(30)
    threading.Timer(0.2, release.set).start()
    out = _program_cache.call(_toy, x, 0.5, 2)  # blocks until the ahead thread is done
    thread.join()
    assert _exported_traces() == traced + 1
    np.testing.assert_array_equal(np.asarray(out["y"]), np.asarray(_toy(x, 0.5, 2)["y"]))


# `jaxdeploy simulate` in a fresh process with an empty cache folder, its traces counted:
# with the run's program compiled ahead (beside the assembly), or with that turned off.
_SIMULATE_COMMAND = """
import json, sys
import jax

traces = []
jax.monitoring.register_event_duration_secs_listener(
    lambda event, duration, **kw: traces.append(kw.get("fun_name"))
    if event == "/jax/core/compile/jaxpr_trace_duration" else None
)
from jaxdeploy.cli import main
from jaxdeploy.commands import _ahead

if sys.argv[1] == "off":
    _ahead.CompileAhead.start = lambda self, mechanism: None
code = main(["simulate", *sys.argv[3:], "--quiet", "--out", sys.argv[2]])
print(json.dumps({"code": code, "solve_traces": traces.count("exported__solve")}))
"""


@pytest.mark.parametrize(
    "command",
    [
        ["pendulum"],  # with the energy meter
        # a clearance joint (its events and episodes), no meter (a driven crank)
        pytest.param(["slider_crank", "--t-end", "0.002"], marks=pytest.mark.slow),
    ],
)
def test_simulate_compiles_its_run_ahead_once_and_runs_it_unchanged(tmp_path, command):
    """The command compiles the run's program beside the assembly (commands/_ahead.py):
    summary.json reports that thread's time, the run's program is traced once in the
    process (the run reads what was made ahead), and the run's files are bit for bit those
    of the command with the compile ahead turned off."""
    import json

    results = {}
    for mode in ("on", "off"):
        env = {**os.environ, "JAX_PLATFORMS": "cpu",
               "JAXDEPLOY_CACHE_DIR": str(tmp_path / f"cache-{mode}")}  # fmt: skip
        out = tmp_path / f"out-{mode}"
        done = subprocess.run(
            [sys.executable, "-c", textwrap.dedent(_SIMULATE_COMMAND), mode, str(out), *command],
            env=env,
            capture_output=True,
            text=True,
        )
        assert done.returncode == 0, done.stderr[-3000:]
        report = json.loads(done.stdout.strip().splitlines()[-1])
        assert report["code"] == 0
        assert report["solve_traces"] == 1, report
        results[mode] = (out, json.loads((out / "summary.json").read_text()))
    (on, summary_on), (off, summary_off) = results["on"], results["off"]
    assert summary_on["phases"]["compile_ahead_s"] > 0
    assert "compile_ahead_s" not in summary_off["phases"]
    assert (on / "trajectory.npz").read_bytes() == (off / "trajectory.npz").read_bytes()
    for name in ("status", "n_steps", "n_rejected"):
        assert summary_on[name] == summary_off[name]
