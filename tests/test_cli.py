"""The command line: outputs, refusal of bad input, no silent overwrite."""

import json

import pytest

from jaxdeploy.cli import main


def test_simulate_pendulum_writes_outputs(tmp_path):
    out = tmp_path / "run"
    code = main(["simulate", "pendulum", "--t-end", "0.2", "--out", str(out), "--quiet"])
    assert code == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "ok" and summary["t_reached_s"] == 0.2
    assert summary["n_steps"] > 0 and summary["wall_time_s"] > 0
    assert summary["params"]["length"] == 1.0
    assert "jax" in summary["versions"]
    assert (out / "trajectory.npz").exists()
    # The result is not overwritten without --overwrite.
    assert main(["simulate", "pendulum", "--t-end", "0.2", "--out", str(out), "--quiet"]) == 2


def test_unknown_scene_and_parameter_are_refused(tmp_path, capsys):
    assert main(["simulate", "trebuchet", "--out", str(tmp_path / "a")]) == 2
    assert "unknown scene 'trebuchet'" in capsys.readouterr().err
    assert main(["simulate", "pendulum", "--set", "lenght=2", "--out", str(tmp_path / "b")]) == 2
    err = capsys.readouterr().err
    assert "unknown parameter 'lenght'" in err and "length" in err


def test_solver_is_chosen_by_name_and_a_bad_name_is_refused(tmp_path, capsys):
    out = tmp_path / "tsit5"
    args = ["simulate", "pendulum", "--t-end", "0.1", "--out", str(out), "--quiet"]
    assert main([*args, "--solver", "tsit5"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "ok" and summary["step_control"]["solver"] == "tsit5"
    for command in (
        ["simulate", "pendulum", "--out", str(tmp_path / "a")],
        ["optimize", "--out", str(tmp_path / "b")],
        ["sweep", "--grid", "panel1_ra=1e-6,2e-6", "--out", str(tmp_path / "c")],
    ):
        assert main([*command, "--solver", "rk4"]) == 2
        err = capsys.readouterr().err
        assert "--solver = 'rk4' is unknown" in err and "tsit5" in err
        assert not any(tmp_path.glob(command[-1].rsplit("/", 1)[-1] + "/*"))


def test_impact_velocity_rule_is_a_scene_option_recorded_in_the_summary(tmp_path, capsys):
    """Both rules run from the command line and say which one made the result (what each rule
    does is tests/test_clearance_memory.py's); bad values are refused before any output."""
    for rule in ("onset", "running_max"):
        out = tmp_path / rule
        args = ["simulate", "impact", "--out", str(out), "--quiet"]
        options = ["--scene-option", "damping=lankarani_nikravesh"]
        assert main([*args, *options, "--scene-option", f"impact_velocity_rule={rule}"]) == 0
        summary = json.loads((out / "summary.json").read_text())
        assert summary["scene_options"] == {
            "damping": "lankarani_nikravesh",
            "impact_velocity_rule": rule,
        }
        assert summary["status"] == "ok"
    for bad, words in (
        ("impact_velocity_rule=peak", ["impact_velocity_rule = 'peak'", "running_max"]),
        ("rule=onset", ["unknown option 'rule'", "impact_velocity_rule"]),
        ("impact_velocity_rule", ["KEY=VALUE"]),
    ):
        out = tmp_path / "bad"
        assert main(["simulate", "impact", "--out", str(out), "--scene-option", bad]) == 2
        err = capsys.readouterr().err
        assert all(w in err for w in words), err
        assert not out.exists()


def test_out_of_range_parameter_names_the_range(tmp_path, capsys):
    code = main(
        ["simulate", "slider_crank", "--set", "clearance=-1e-4", "--out", str(tmp_path / "c")]
    )
    assert code == 2
    err = capsys.readouterr().err
    # The lower end is scenes/_contact.py's CLEARANCE_FLOOR (1e-9 m): below it a run cannot
    # finish (5ddc502), so the range is closed there.
    assert "clearance" in err and "-0.0001" in err and "[1e-09, 0.1]" in err


def test_set_requires_name_equals_value(tmp_path, capsys):
    assert main(["simulate", "pendulum", "--set", "length", "--out", str(tmp_path / "d")]) == 2
    assert "NAME=VALUE" in capsys.readouterr().err


def test_compiled_simulation_is_kept_in_the_persistent_cache(tmp_path):
    """A fresh `jaxdeploy simulate` stores the compiled solve (no host callbacks in it), so
    the next run with the same composition loads it instead of compiling, and the traced
    programs beside it (jaxdeploy/_program_cache.py), so that it does not trace them either:
    the solve runs as a program read back through `jax.export`, compiled, its executable kept
    beside it too."""
    import os
    import subprocess
    import sys

    cache = tmp_path / "xla"
    env = {k: v for k, v in os.environ.items() if k != "EQX_ON_ERROR"}
    env["JAXDEPLOY_CACHE_DIR"] = str(cache)
    # JAX stores only programs that took ≥ 1 s to compile (its default); a busy machine made
    # that true and a quiet one false, so the test would pass or fail with the load.
    env["JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS"] = "0"
    cmd = [sys.executable, "-m", "jaxdeploy.cli", "simulate", "pendulum", "--t-end", "0.05"]
    proc = subprocess.run(
        [*cmd, "--out", str(tmp_path / "run"), "--quiet"], env=env, capture_output=True, text=True
    )
    assert proc.returncode == 0, proc.stderr
    # the exported solve compiled (`jax.jit(exported.call)`), in JAX's cache...
    assert any(p.name.startswith("jit_call-") for p in cache.iterdir())
    # ...and the initial state's assembly and the solve, traced and compiled, beside it
    assert len(list((tmp_path / "xla-programs").glob("*.jaxexport"))) >= 2
    assert len(list((tmp_path / "xla-programs").glob("*.executable"))) >= 2


def test_save_times_are_checked_before_the_solve():
    from jaxdeploy.scenes import Pendulum
    from jaxdeploy.simulation import simulate

    scene = Pendulum()
    params = scene.resolve_params()
    mech = scene.build(params)
    init = scene.initial_state(params, mech)
    with pytest.raises(ValueError, match="non-decreasing"):
        simulate(mech, init, 0.1, dt=1e-3, ts=[0.0, 0.05, 0.02])
    with pytest.raises(ValueError, match="must lie in"):
        simulate(mech, init, 0.1, dt=1e-3, ts=[0.0, 0.2])
    with pytest.raises(ValueError, match="t_end"):
        simulate(mech, init, 0.0, dt=1e-3)


_LEAVING = """
import atexit, sys, threading, time
from jaxdeploy import cli

out = sys.argv[1]
atexit.register(lambda: open(out + "-atexit", "w").write("ran"))

def late():
    time.sleep(0.5)
    open(out + "-thread", "w").write("ran")

threading.Thread(target=late).start()  # not a daemon: an orderly exit waits for it
sys.argv = ["jaxdeploy", *sys.argv[2:]]
code = cli.main()
open(out + "-after", "w").write("ran")  # never: main ends the process itself
"""


@pytest.mark.parametrize(("argv", "expected"), [(["scenes"], 0), (["simulate", "nope"], 2)])
def test_the_program_leaves_as_an_orderly_exit_would(tmp_path, argv, expected):
    """`main()` without arguments (the `jaxdeploy` program) ends the process with the
    command's exit code, after non-daemon threads and `atexit` handlers, without the
    interpreter's teardown; `main(argv)` returns (every other test here)."""
    import subprocess
    import sys

    stem = str(tmp_path / "mark")
    done = subprocess.run(
        [sys.executable, "-c", _LEAVING, stem, *argv], capture_output=True, text=True
    )
    assert done.returncode == expected, done.stderr
    assert (tmp_path / "mark-thread").read_text() == "ran"
    assert (tmp_path / "mark-atexit").read_text() == "ran"
    assert not (tmp_path / "mark-after").exists()
    if expected == 0:
        assert "slider_crank" in done.stdout  # flushed before the process ended
