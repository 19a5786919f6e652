"""The run-length probe of `jaxdeploy simulate` (issue 30): the run measures itself over the
first parts of its horizon and a run estimated past 15 minutes needs --long-run.

The estimate's logic is checked on model runs whose length is known exactly (a fixed cost per
call plus a cost per step, steps from a step density over time); the command on a real run
that the scene's table cannot judge (the pendulum at 1000x its default steps)."""

import json
import os

import pytest

from jaxdeploy.cli import main
from jaxdeploy.commands import _run_length
from jaxdeploy.commands._run_length import BUDGET_S, CAP_S, SHORT_AFTER_PART, Prefix, estimate


def _model_run(t_end, steps_over, per_step, per_call=0.03, probed=None):
    """`run_prefix(t)` of a run taking `steps_over(t)` steps to reach t, each `per_step` s,
    plus `per_call` s per call (saving the states); the calls are appended to `probed`.
    **Returns:** `(run_prefix, whole)`, `whole` the run's own length without the call."""

    def run_prefix(t):
        steps = int(steps_over(t))
        if probed is not None:
            probed.append(t)
        return Prefix(t, per_call + per_step * steps, steps)

    return run_prefix, per_step * steps_over(t_end)


def test_a_short_run_is_probed_over_a_hundredth_of_its_horizon_and_no_more():
    # slider_crank's default: ~1e5 steps per simulated second of 0.3 ms each over 0.024 s.
    probed = []
    run, whole = _model_run(0.024, lambda t: 1e5 * t, 3e-4, probed=probed)
    length = estimate(run, 0.024, short_s=30.0)
    assert max(probed) == pytest.approx(SHORT_AFTER_PART * 0.024)
    assert whole < length.seconds < 30.0  # the fixed cost of a call is counted against it
    assert sum(0.03 + 3e-4 * int(1e5 * t) for t in probed) < 0.2  # what the probe cost


def test_a_stiff_run_is_extrapolated_from_a_prefix_that_took_about_the_budget():
    # 1e9 steps per simulated second, 0.3 ms each: 2 hours for 0.024 s.
    probed = []
    run, whole = _model_run(0.024, lambda t: 1e9 * t, 3e-4, probed=probed)
    length = estimate(run, 0.024, short_s=30.0)
    assert whole == pytest.approx(7200.0)
    # The call's fixed 0.03 s in a prefix of ≥ BUDGET_S/2 = 1 s makes each step ≤ 3 % longer.
    assert length.seconds == pytest.approx(whole, rel=0.03)
    seconds = [0.03 + 3e-4 * int(1e9 * t) for t in probed]
    assert BUDGET_S / 2 <= seconds[-1] and sum(seconds) <= CAP_S
    assert max(probed) < 1e-2 * 0.024  # a 2-hour run is probed over less than 1 % of it
    assert "steps per simulated second" in length.account()


def test_the_small_steps_of_a_start_are_not_extrapolated():
    # 5000 steps in the first 2.4 µs (an initial contact at a tight tolerance: measured on
    # slider_crank with a 1e-10 m clearance at rtol 1e-12, 4566 steps), then 3e7 per second.
    def steps(t):
        return 5000 * min(t / 2.4e-6, 1.0) + 3e7 * max(t - 2.4e-6, 0.0)

    probed = []
    run, whole = _model_run(0.024, steps, 3e-4, probed=probed)
    length = estimate(run, 0.024, short_s=30.0)
    assert length.seconds == pytest.approx(whole, rel=0.05)  # from the steady part's density
    # The first prefix's own density (5648 steps in 0.1 % of the horizon) says 8x too much.
    first = 0.03 + 3e-4 * int(steps(probed[0]))
    assert first / (probed[0] / 0.024) > 5 * whole


def test_a_failed_prefix_gives_no_estimate():
    assert estimate(lambda t: Prefix(t, 0.1, 10, ok=False), 1.0, short_s=30.0) is None


@pytest.fixture
def _no_persistent_caches(monkeypatch):
    monkeypatch.setenv("JAXDEPLOY_CACHE_DIR", "off")


@pytest.mark.usefixtures("_no_persistent_caches")
def test_a_run_the_probe_times_past_its_limit_needs_long_run(tmp_path, capsys, monkeypatch):
    # The pendulum in fixed steps of 1 µs: 2e6 generalized-α steps, which the scene's table
    # (0.3 s per simulated second, at its default 1 ms steps) puts at 0.6 s; the probe measures
    # the steps themselves. The limit is lowered to 1 s (the run takes tens of seconds) and the
    # probe's budget with it, so that the case is cheap to detect.
    from jaxdeploy.commands import simulate

    monkeypatch.setattr(simulate, "LONG_RUN_S", 1.0)
    monkeypatch.setattr(simulate, "PROGRESS_BAR_S", 0.5)
    monkeypatch.setattr(_run_length, "BUDGET_S", 0.4)
    argv = ["simulate", "pendulum", "--dt", "1e-6", "--t-end", "2", "--n-save", "3"]
    code = main([*argv, "--out", str(tmp_path / "run")])
    err = capsys.readouterr().err
    assert "Traceback" not in err
    assert code == 2
    assert "error: pendulum to --t-end = 2 s would integrate for about" in err
    assert "steps per simulated second" in err and "pass --long-run" in err
    assert os.listdir(tmp_path) == []  # the folder was released as it was


@pytest.mark.usefixtures("_no_persistent_caches")
def test_a_short_run_says_nothing_of_its_length_and_records_the_probe(tmp_path, capsys):
    out = tmp_path / "run"
    argv = ["simulate", "pendulum", "--t-end", "0.2", "--n-save", "3", "--set", "length=2"]
    code = main([*argv, "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 0
    assert "probe: the run over the first parts of its horizon" in err
    assert "would integrate for about" not in err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["phases"]["probe_s"] >= 0.0
    # The scene's defaults, with only --t-end changed, are what its rate was measured for.
    default = ["simulate", "pendulum", "--t-end", "0.2", "--n-save", "3"]
    code = main([*default, "--out", str(tmp_path / "default")])
    assert code == 0 and "probe:" not in capsys.readouterr().err


@pytest.mark.usefixtures("_no_persistent_caches")
def test_ctrl_c_in_the_probe_is_one_line_exit_130_and_leaves_nothing(tmp_path, capsys, monkeypatch):
    # The probe's first prefix is interrupted (a pendulum of another length: not the scene's
    # defaults, so it is probed); the output folder is already taken then.
    import jaxdeploy.simulation

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(jaxdeploy.simulation, "simulate", interrupted)
    argv = ["simulate", "pendulum", "--t-end", "0.2", "--n-save", "3", "--set", "length=2"]
    code = main([*argv, "--out", str(tmp_path / "run")])
    err = capsys.readouterr().err
    assert code == 130 and "Traceback" not in err
    lines = err.strip().splitlines()
    assert lines[-2].startswith("probe: the run over the first parts of its horizon")
    assert lines[-1] == "interrupted: jaxdeploy simulate stopped (Ctrl-C)"
    assert os.listdir(tmp_path) == []  # no result, no staging folder, no lock


def test_a_real_ctrl_c_during_the_probe_ends_with_one_line_and_exit_130(tmp_path):
    """SIGINT to the program while it probes a run of tens of seconds (the pendulum in steps
    of 1 µs): the signal handler's line, exit 130 (no traceback, no crash while XLA runs),
    the output folder released as it was."""
    import signal
    import subprocess
    import sys
    import time

    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    command = [sys.executable, "-m", "jaxdeploy.cli", "simulate", "pendulum", "--dt", "1e-6",
               "--t-end", "2", "--n-save", "3", "--out", str(tmp_path / "run")]  # fmt: skip
    env = {**os.environ, "PYTHONPATH": root, "JAXDEPLOY_CACHE_DIR": "off"}
    proc = subprocess.Popen(command, stderr=subprocess.PIPE, text=True, env=env)
    seen = []
    deadline = time.time() + 600
    while time.time() < deadline:
        line = proc.stderr.readline()
        if not line:
            break
        seen.append(line)
        if line.startswith("probe: the run over the first parts of its horizon"):
            proc.send_signal(signal.SIGINT)
            break
    _, rest = proc.communicate(timeout=600)
    err = "".join(seen) + rest
    assert proc.returncode == 130, err
    assert err.strip().splitlines()[-1] == "interrupted: jaxdeploy simulate stopped (Ctrl-C)"
    assert "Traceback" not in err
    assert os.listdir(tmp_path) == []


def test_the_ctrl_c_handler_writes_its_line_while_the_interrupted_code_holds_stderr(tmp_path):
    """The handler runs between two bytecodes of the main thread, which can be inside a write
    to stderr: writing to the stream again raised "reentrant call inside
    <_io.BufferedWriter name='<stderr>'>" and exit 1 in CI. Here every use of sys.stderr and
    sys.stdout raises that error, as the held streams do: the line still comes, exit 130."""
    import subprocess
    import sys

    script = tmp_path / "handler.py"
    script.write_text(
        "import sys\n"
        "from jaxdeploy import cli\n"
        "class Held:\n"
        "    def write(self, text):\n"
        "        raise RuntimeError('reentrant call inside <_io.BufferedWriter>')\n"
        "    def flush(self):\n"
        "        raise RuntimeError('reentrant call inside <_io.BufferedWriter>')\n"
        "    def fileno(self):\n"
        "        return 2\n"
        "handler = cli._interrupted('simulate')\n"
        "sys.stderr = sys.stdout = Held()\n"
        "handler(2, None)\n"
    )
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True,
                          env={**os.environ, "PYTHONPATH": root}, timeout=120)  # fmt: skip
    assert done.returncode == 130, done.stderr
    assert done.stderr.strip().splitlines() == ["interrupted: jaxdeploy simulate stopped (Ctrl-C)"]
