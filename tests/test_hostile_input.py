"""Hostile input (issue 30): every case asserts the exit code, that the message names the
problem, and what is left on disk. Refusals happen before anything is compiled, so most cases
cost little more than building a mechanism; the few that run a simulation use the shortest
horizon that shows the behaviour."""

import json
import os
import pathlib

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from jaxdeploy.cli import main

ROOT = pathlib.Path(__file__).resolve().parents[1]
DATA = ROOT / "examples" / "slider_crank_slider_x.csv"


@pytest.fixture(autouse=True)
def _no_persistent_caches(monkeypatch):
    """The commands run here with their caches off: nothing is written to the user's cache,
    and no later test in this process finds JAX's compilation cache switched on by them."""
    monkeypatch.setenv("JAXDEPLOY_CACHE_DIR", "off")


def _run(capsys, *argv):
    """`(exit code, stderr)` of `jaxdeploy ARGV` run in this process."""
    code = main([str(a) for a in argv])
    err = capsys.readouterr().err
    assert "Traceback" not in err
    return code, err


def _entries(folder) -> list[str]:
    """Everything in `folder`, hidden entries (locks, staging folders) included."""
    return sorted(os.listdir(folder))


# --- plausibility -----------------------------------------------------------------------


def test_atol_too_loose_for_the_clearance_is_refused_before_any_work(tmp_path, capsys):
    code, err = _run(capsys, "simulate", "slider_crank", "--atol", "1e5", "--out", tmp_path / "a")
    assert code == 2
    assert "--atol = 100000" in err and "clearance of 0.0005 m" in err
    assert _entries(tmp_path) == []


@settings(
    max_examples=12,
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)
@given(atol=st.floats(min_value=5.1e-6, max_value=1e12))
def test_any_atol_above_a_hundredth_of_the_clearance_is_refused(tmp_path, capsys, atol):
    code, err = _run(
        capsys, "simulate", "slider_crank", "--atol", repr(atol), "--out", tmp_path / "a"
    )
    assert code == 2 and "--atol" in err and "too loose" in err
    assert _entries(tmp_path) == []


def test_implausible_penetration_is_not_ok_and_exits_6(tmp_path, capsys):
    # 10 m/s into a 0.1 mm clearance: the journal sinks 0.69 mm, 6.9 clearances (the 1-D Hertz
    # impact δ = (5 m v² / 4K)^(2/5)); the contact is over within the horizon.
    out = tmp_path / "run"
    code = main(
        ["simulate", "impact", "--set", "impact_speed=10", "--t-end", "1.5e-4", "--out", str(out)]
    )
    err = capsys.readouterr().err
    assert code == 6
    assert "implausible: penetration_per_clearance = 6.9 exceeds its limit 2" in err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"].startswith("implausible: penetration_per_clearance = 6.9")
    failed = {c["check"] for c in summary["plausibility"] if not c["passed"]}
    assert failed == {"penetration_per_clearance", "penetration_per_radius"}
    assert _entries(tmp_path) == ["run"]


def test_an_energy_balance_that_does_not_close_is_not_ok_and_exits_6(tmp_path, capsys):
    # Generalized-α with 20 steps per second on the pendulum: its numerical dissipation and
    # error lose 2.3 % of the energy moved (the default dt = 1 ms: 9e-6); its drift (9e-5 m)
    # fails too.
    out = tmp_path / "run"
    code = main(["simulate", "pendulum", "--dt", "0.05", "--out", str(out), "--quiet"])
    err = capsys.readouterr().err
    assert code == 6
    assert "error: the run implausible: " in err
    assert "energy_balance = 0.023 exceeds its limit 0.003" in err
    summary = json.loads((out / "summary.json").read_text())
    (energy,) = [c for c in summary["plausibility"] if c["check"] == "energy_balance"]
    assert energy["passed"] is False and energy["value"] == pytest.approx(0.023, abs=5e-4)
    assert _entries(tmp_path) == ["run"]


def test_an_energy_balance_that_cannot_be_computed_is_null_not_a_number():
    from jaxdeploy.analysis.plausibility import energy_check, verdict
    from jaxdeploy.io import strict_json
    from jaxdeploy.mechanism import balance_metered, unmetered_because
    from jaxdeploy.scenes import SliderCrank

    scene = SliderCrank()
    mechanism = scene.build(scene.resolve_params({}))
    assert balance_metered(mechanism) is None  # the crank's driver does work
    check = energy_check(None, unmetered_because(mechanism))
    record = json.loads(strict_json(check.to_json()))
    assert record["value"] is None and record["passed"] is None
    assert "not computed: a driving constraint (AngleDriver)" in record["subject"]

    class Finished:
        ok = True

    assert verdict(Finished(), [check]) == "ok"  # not computed is not a failure


def test_a_contact_resolved_by_too_few_fixed_steps_is_not_ok(tmp_path, capsys):
    # The impact's Hertz contact lasts 3.2e-4 s: fixed steps of 1.6e-4 s resolve it by two.
    out = tmp_path / "run"
    code = main(["simulate", "impact", "--dt", "1.6e-4", "--out", str(out), "--quiet"])
    err = capsys.readouterr().err
    assert code == 6
    assert "implausible: step_per_contact = " in err and "exceeds its limit 0.1" in err
    summary = json.loads((out / "summary.json").read_text())
    (steps,) = [c for c in summary["plausibility"] if c["check"] == "step_per_contact"]
    assert steps["passed"] is False and "fixed step 0.00016 s" in steps["subject"]


def test_failed_run_writes_null_and_exits_1(tmp_path, capsys):
    # Generalized-α with 0.5 s steps on a 1 s pendulum: Newton's iteration diverges.
    out = tmp_path / "run"
    code = main(["simulate", "pendulum", "--dt", "0.5", "--t-end", "2", "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 1 and "Nonlinear solve diverged" in err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"].startswith("failed after t = ")
    assert summary["max_constraint_violation"] is None  # not the NaN states' number
    assert summary["plausibility"] == []


def test_a_case_taken_out_of_a_batch_names_its_failure_like_simulate():
    import diffrax as dfx
    import jax
    import jax.numpy as jnp

    from jaxdeploy.simulation import Trajectory

    results = jax.vmap(
        lambda ok: dfx.RESULTS.where(ok, dfx.RESULTS.successful, dfx.RESULTS.nonfinite)
    )(jnp.array([True, False]))
    case = jax.tree.map(lambda leaf: np.asarray(leaf)[1], results)
    zeros = np.zeros((2, 1))
    trajectory = Trajectory(
        np.array([0.0, 1.0]), zeros, zeros, zeros, zeros, (), case, {}, t_reached=0.5
    )
    assert trajectory.status() == (
        "failed after t = 0.5 s: Nonfinite (inf or nan) values detected during solve."
    )


def test_overview_leaves_out_failed_and_implausible_cases_and_says_so():
    from jaxdeploy.commands._sweep_outputs import overview_figure
    from jaxdeploy.scenes import Pendulum

    statuses = ["ok", "failed after t = 0.1 s: non-finite", "implausible: x", "ok"]
    data = {
        "case": np.arange(4),
        "param_length": np.array([1.0, 2.0, 3.0, 4.0]),
        "summary": np.array(
            [json.dumps({"status": s, "n_steps": 10 * (i + 1)}) for i, s in enumerate(statuses)]
        ),
    }
    grid = {"length": [1.0, 2.0, 3.0, 4.0]}
    fig, left_out = overview_figure(Pendulum(), data, ["length"], grid)
    assert left_out == 2
    assert "2 cases (2 failed or implausible, not shown" in fig._suptitle.get_text()
    (line,) = fig.axes[0].lines
    assert list(line.get_xdata()) == [1.0, 4.0]


# --- resources ----------------------------------------------------------------------------


def test_outputs_that_do_not_fit_in_memory_are_refused(tmp_path, capsys, monkeypatch):
    from jaxdeploy.commands import _plan

    monkeypatch.setattr(_plan, "available_memory", lambda: 24e9)
    code, err = _run(
        capsys, "simulate", "slider_crank", "--n-save", "100000000", "--out", tmp_path / "a"
    )
    assert code == 2
    # 4 copies × 8 B × 1e8 saved states × (q, q̇, q̈: 27, λ: 8, t: 1, memory: 13 numbers).
    assert "--n-save = 100000000" in err and "154 GB" in err and "12 GB a run may use" in err
    assert _entries(tmp_path) == []


GRADCHECK = ["gradcheck", "slider_crank", "--output", "first_onset_time", "--params", "clearance"]
OPTIMIZE = ["optimize", "--scene", "deploy_array"]


@pytest.mark.parametrize(
    "argv, what",
    [
        (GRADCHECK, "saved states of slider_crank (a run, its derivative and a difference run)"),
        (OPTIMIZE, "saved states of deploy_array (a run, its derivative and the ideal reference)"),
    ],
)
def test_every_command_refuses_outputs_that_do_not_fit(argv, what, tmp_path, capsys, monkeypatch):
    from jaxdeploy.commands import _plan

    monkeypatch.setattr(_plan, "available_memory", lambda: 24e9)
    code, err = _run(capsys, *argv, "--n-save", "100000000", "--out", tmp_path / "a")
    assert code == 2 and f"--n-save = 100000000 {what}" in err and "12 GB a run may use" in err
    assert _entries(tmp_path) == []


def test_fit_refuses_data_whose_states_do_not_fit(tmp_path, capsys, monkeypatch):
    from jaxdeploy.commands import _plan

    monkeypatch.setattr(_plan, "available_memory", lambda: 1e5)  # 50 kB a run may use
    code, err = _run(capsys, "fit", DATA, "--scene", "slider_crank", "--params",
                     "clearance=6e-4", "--out", tmp_path / "f")  # fmt: skip
    assert code == 2 and "data times of slider_crank" in err and "thin the data" in err
    assert _entries(tmp_path) == []


@pytest.mark.parametrize("argv", [GRADCHECK, OPTIMIZE])
def test_every_command_refuses_an_atol_too_loose_for_the_clearance(argv, tmp_path, capsys):
    code, err = _run(capsys, *argv, "--atol", "1e5", "--out", tmp_path / "a")
    assert code == 2 and "--atol = 100000 is too loose for a clearance" in err
    assert _entries(tmp_path) == []


def test_a_sweep_of_hours_needs_long_run(tmp_path, capsys):
    code, err = _run(
        capsys,
        "sweep",
        "--scene",
        "deploy_array",
        "--grid",
        "panel1_clearance=1e-5:1e-4:10000",
        "--out",
        tmp_path / "s",
    )
    assert code == 2 and "10000 cases" in err and "--long-run" in err
    assert _entries(tmp_path) == []


# --- a result folder belongs to one run ---------------------------------------------------


def test_a_second_run_into_a_held_folder_is_refused_naming_the_holder(
    tmp_path, capsys, monkeypatch
):
    from jaxdeploy._output_folder import OutputFolder
    from jaxdeploy.scenes.pendulum import Pendulum

    def build(self, params):
        raise AssertionError("built a mechanism for a run whose folder is held")

    # Refused before any work: the build (and the compile of the run beside it) never starts.
    monkeypatch.setattr(Pendulum, "build", build)
    out = tmp_path / "held"
    with OutputFolder(str(out)).claim():
        code, err = _run(capsys, "simulate", "pendulum", "--out", out, "--overwrite")
        assert code == 2 and "is in use by another run" in err and f"process {os.getpid()}" in err
        code, err = _run(capsys, "sweep", "--scene", "pendulum", "--grid", "length=1,2",
                         "--out", out)  # fmt: skip
        assert code == 2 and "is in use by another run" in err
    assert _entries(tmp_path) == []  # the holder's staging folder and lock are gone


def test_gradcheck_takes_its_folder_like_every_command(tmp_path, capsys):
    from jaxdeploy._output_folder import OutputFolder

    out = tmp_path / "held"
    with OutputFolder(str(out)).claim():
        code, err = _run(capsys, *GRADCHECK, "--out", out, "--overwrite")
        assert code == 2 and "is in use by another run" in err
    assert _entries(tmp_path) == []


def test_overwrite_replaces_the_whole_folder_and_a_crash_leaves_the_old_one(
    tmp_path, capsys, monkeypatch
):
    out = tmp_path / "run"
    out.mkdir()
    (out / "slider_crank_plot.png").write_bytes(b"an older run's figure")
    (out / "summary.json").write_text("{}")
    argv = ["simulate", "pendulum", "--t-end", "0.05", "--n-save", "11", "--out", str(out)]
    assert main([*argv, "--overwrite", "--quiet"]) == 0
    assert _entries(out) == ["summary.json", "trajectory.npz"]
    assert _entries(tmp_path) == ["run"]
    first = (out / "summary.json").read_text()

    import jaxdeploy.io

    def disk_full(*args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(jaxdeploy.io, "atomic_write_npz", disk_full)
    with pytest.raises(OSError, match="No space left"):
        main([*argv, "--overwrite", "--quiet", "--t-end", "0.04"])
    # The complete older result is intact; nothing half-written beside it.
    assert (out / "summary.json").read_text() == first
    assert _entries(tmp_path) == ["run"]


@pytest.mark.parametrize("out", ["/proc/x", "/proc/self"])
def test_an_output_folder_that_cannot_be_written_is_refused_before_the_run(out, capsys):
    code, err = _run(capsys, "simulate", "pendulum", "--out", out, "--overwrite")
    assert code == 2 and repr(out) in err
    assert not os.path.exists("/proc/x")


# --- interrupts and tracebacks ------------------------------------------------------------


def test_ctrl_c_is_one_line_exit_130_and_leaves_nothing(tmp_path, capsys, monkeypatch):
    import jaxdeploy.simulation

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(jaxdeploy.simulation, "simulate", interrupted)
    code, err = _run(capsys, "simulate", "pendulum", "--out", tmp_path / "run")
    assert code == 130
    assert err.strip().splitlines()[-1] == "interrupted: jaxdeploy simulate stopped (Ctrl-C)"
    assert _entries(tmp_path) == []


def test_optimize_refuses_an_unknown_panel_before_compiling(tmp_path, capsys):
    code, err = _run(
        capsys,
        "optimize",
        "--scene",
        "deploy_array",
        "--objective",
        "panel3:peak_vibration=1",
        "--out",
        tmp_path / "o",
    )
    assert code == 2 and "panel 'panel3' is unknown; valid: panel1, panel2" in err
    assert _entries(tmp_path) == []


def test_fit_refuses_a_window_outside_the_data(tmp_path, capsys):
    code, err = _run(capsys, "fit", DATA, "--scene", "slider_crank", "--params",
                     "clearance=6e-4", "--window", "5:6", "--out", tmp_path / "f")  # fmt: skip
    assert code == 2 and "--window 5:6: no data sample lies in it" in err and "0.004" in err
    assert _entries(tmp_path) == []


def test_fit_refuses_a_value_whose_square_overflows_naming_the_row(tmp_path, capsys):
    lines = DATA.read_text().splitlines()
    first = next(i for i, line in enumerate(lines) if line[:1].isdigit())
    lines[first + 3] = lines[first + 3].split(",")[0] + ",1e300"
    data = tmp_path / "data.csv"
    data.write_text("\n".join(lines) + "\n")
    code, err = _run(capsys, "fit", data, "--scene", "slider_crank", "--params",
                     "clearance=6e-4", "--out", tmp_path / "f")  # fmt: skip
    assert code == 2 and "column 'slider_x' row 3 holds 1e+300" in err
    assert _entries(tmp_path) == ["data.csv"]


# --- sweeps -------------------------------------------------------------------------------


def test_resume_of_a_folder_without_a_sweep_is_refused(tmp_path, capsys):
    code, err = _run(capsys, "sweep", "--scene", "pendulum", "--grid", "length=1,2",
                     "--out", tmp_path / "none", "--resume")  # fmt: skip
    assert code == 2 and "--resume" in err and "holds no sweep to continue" in err
    assert _entries(tmp_path) == []


@pytest.mark.parametrize("values", ["1,2,1", "1:1:3", "1,1.0"])
def test_a_grid_value_given_twice_is_refused(values, tmp_path, capsys):
    code, err = _run(capsys, "sweep", "--scene", "pendulum", "--grid", f"length={values}",
                     "--out", tmp_path / "s")  # fmt: skip
    assert code == 2 and "--grid length: the value 1 is given twice" in err
    assert _entries(tmp_path) == []


def test_resume_on_another_grid_names_the_differing_field(tmp_path, capsys):
    import jax

    from jaxdeploy.batch import step_control
    from jaxdeploy.scenes import Pendulum
    from jaxdeploy.sweep import _definition, chunk_shape, parse_policy

    scene = Pendulum()
    grid = {"length": [1.0, 2.0]}
    chunk = chunk_shape(64, 2, jax.device_count())
    definition = _definition(
        scene, grid, {}, 0.5, 21, step_control(scene, None), chunk, None, parse_policy("all")
    )
    definition["summary"] = True
    out = tmp_path / "s"
    out.mkdir()
    manifest = {"definition": definition, "n_cases": 2, "chunks": []}
    (out / "manifest.json").write_text(json.dumps(manifest))
    code, err = _run(capsys, "sweep", "--scene", "pendulum", "--grid", "length=1,3",
                     "--t-end", "0.5", "--n-save", "21", "--out", out, "--resume")  # fmt: skip
    assert code == 2
    assert "grid.length: [1.0, 2.0] in the folder, [1.0, 3.0] now" in err
    assert "t_end" not in err and len(err) < 400  # the differing field, not the dictionary
    assert _entries(out) == ["manifest.json"]


# --- caches -------------------------------------------------------------------------------


def test_a_damaged_compilation_cache_entry_is_discarded_once_and_rewritten(tmp_path):
    """Issue 30: damaged entries printed ~20 raw JAX warnings on every later run and were
    compiled again every time (JAX does not overwrite an existing file). Now: one line per
    entry, and the next process reads a good entry silently."""
    import subprocess
    import sys

    script = (
        "import sys\n"
        "from jaxdeploy._compilation_cache import enable_caches\n"
        "enable_caches(sys.argv[1])\n"
        "import jax, jax.numpy as jnp\n"
        "print(float(jax.jit(lambda x: jnp.sin(x) * 3.0 + x**2)(jnp.float32(0.5))))\n"
    )
    cache = tmp_path / "xla"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}

    def run():
        done = subprocess.run(
            [sys.executable, "-c", script, str(cache)], capture_output=True, text=True, env=env
        )
        assert done.returncode == 0, done.stderr
        return done.stdout, done.stderr

    first, _ = run()
    entries = sorted(cache.glob("*-cache"))
    assert entries
    for entry in entries:
        entry.write_bytes(b"damaged")
    second, err = run()
    assert second == first
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == len(entries)
    assert all(line.startswith("warning: compilation cache: discarding") for line in lines)
    third, err = run()
    assert third == first and err.strip() == ""


def test_ctrl_c_during_a_sweep_keeps_every_finished_chunk(tmp_path):
    """A real SIGINT to the program: one line, exit 130 (not a traceback, not a segfault, not
    swallowed by a callback), the chunks finished so far kept and the folder's lock gone."""
    import signal
    import subprocess
    import sys
    import time

    out = tmp_path / "sweep"
    command = [sys.executable, "-m", "jaxdeploy.cli", "sweep", "--scene", "pendulum",
               "--grid", "length=0.5:2.5:40", "--t-end", "20", "--n-save", "3",
               "--chunk-size", "1", "--no-trajectories", "--quiet", "--out", str(out)]  # fmt: skip
    env = {**os.environ, "PYTHONPATH": str(ROOT), "JAXDEPLOY_CACHE_DIR": "off"}
    proc = subprocess.Popen(command, stderr=subprocess.PIPE, text=True, env=env)
    manifest = out / "manifest.json"
    deadline = time.time() + 600
    while proc.poll() is None and time.time() < deadline:
        if manifest.exists() and json.loads(manifest.read_text())["chunks"]:
            break
        time.sleep(0.05)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=600)
    assert proc.returncode == 130, err
    assert err.strip().splitlines()[-1] == "interrupted: jaxdeploy sweep stopped (Ctrl-C)"
    assert "Traceback" not in err
    chunks = json.loads(manifest.read_text())["chunks"]
    assert 1 <= len(chunks) < 40
    assert all((out / c["file"]).exists() for c in chunks)
    assert _entries(tmp_path) == ["sweep"]  # no lock left beside it


def _cache_warnings(err: str) -> list[str]:
    return [line for line in err.splitlines() if line.startswith("warning: ")]


@pytest.fixture
def _no_compilation_cache_yet():
    """JAX's compilation cache unset for the test (another test in this process may have
    set it; then the command would keep it and not judge its own folder), reset after."""
    import jax

    before = jax.config.jax_compilation_cache_dir
    jax.config.update("jax_compilation_cache_dir", None)
    yield
    jax.config.update("jax_compilation_cache_dir", before)


def test_a_cache_folder_that_cannot_be_created_is_reported_and_the_run_goes_on(
    tmp_path, capsys, monkeypatch, _no_compilation_cache_yet
):
    from jaxdeploy import _compilation_cache, _program_cache

    blocked = tmp_path / "a-file"
    blocked.write_text("not a folder")
    monkeypatch.setenv("JAXDEPLOY_CACHE_DIR", str(blocked / "xla"))
    monkeypatch.setattr(_compilation_cache, "_judged", {})
    out = tmp_path / "run"
    code, err = _run(capsys, "simulate", "pendulum", "--t-end", "0.01", "--n-save", "3",
                     "--out", out, "--quiet")  # fmt: skip
    assert code == 0
    lines = _cache_warnings(err)
    assert len(lines) == 2  # the program cache and the compilation cache, once each
    assert all("it cannot be created" in line and "running without it" in line for line in lines)
    assert _program_cache.folder() is None
    assert _entries(tmp_path) == ["a-file", "run"]


def test_a_cache_folder_other_users_can_write_is_not_read(
    tmp_path, capsys, monkeypatch, _no_compilation_cache_yet
):
    from jaxdeploy import _compilation_cache, _program_cache
    from jaxdeploy.commands import _reference_cache

    base = tmp_path / "cache" / "xla"
    shared = [base, tmp_path / "cache" / "xla-programs", tmp_path / "cache" / "xla-references"]
    for folder in shared:
        folder.mkdir(parents=True)
        folder.chmod(0o777)
    monkeypatch.setenv("JAXDEPLOY_CACHE_DIR", str(base))
    monkeypatch.setattr(_compilation_cache, "_judged", {})
    code, err = _run(capsys, "simulate", "pendulum", "--t-end", "0.01", "--n-save", "3",
                     "--out", tmp_path / "run", "--quiet")  # fmt: skip
    assert code == 0
    lines = _cache_warnings(err)
    assert len(lines) == 2
    assert all("writable by other users (mode 777" in line for line in lines)
    assert all(f"chmod go-w {base}" in line for line in lines)
    assert _program_cache.folder() is None
    assert _reference_cache.folder() is None  # reported once, when first asked
    assert "reference cache: not using" in capsys.readouterr().err
    assert all(os.listdir(folder) == [] for folder in shared)  # nothing read, nothing written
