"""A sweep plans like `simulate` (issue 30): its run length is probed by its own compiled
program over the first parts of the horizon (`commands/_run_length.py`, simulate's probe)
before its first chunk runs, and each case carries the plausibility verdict `simulate` gives a
run, the energy balance included; implausible cases are marked and left out of overview.png.

The pendulum in fixed generalized-α steps of 20 ms is the cheapest sweep with a case on each
side of the energy limit (3e-3 of the energy moved): at a length of 0.2 m (a period of 0.9 s,
45 steps) the balance leaves 0.018, at 2 m (2.8 s, 140 steps) 1.8e-3."""

import contextlib
import csv
import io
import json
import os

import pytest

from jaxdeploy.cli import main

GRID = "length=0.2,2"
ARGV = ["--scene", "pendulum", "--dt", "0.02", "--t-end", "1", "--n-save", "11"]
STORED = "[test: a chunk was stored]"


@contextlib.contextmanager
def _caches_off():
    """The command's persistent caches off (nothing written to the user's cache)."""
    before = os.environ.get("JAXDEPLOY_CACHE_DIR")
    os.environ["JAXDEPLOY_CACHE_DIR"] = "off"
    try:
        yield
    finally:
        if before is None:
            del os.environ["JAXDEPLOY_CACHE_DIR"]
        else:
            os.environ["JAXDEPLOY_CACHE_DIR"] = before


def _command(argv):
    """`(exit code, stdout, stderr)` of `jaxdeploy ARGV` in this process."""
    out, err = io.StringIO(), io.StringIO()
    with _caches_off(), contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main([str(a) for a in argv])
    assert "Traceback" not in err.getvalue()
    return code, out.getvalue(), err.getvalue()


@pytest.fixture(scope="module")
def swept(tmp_path_factory):
    """The two-case sweep in chunks of one case, its estimate always said (the limit for
    saying it, 30 s, set to 0) and every stored chunk marked in stderr."""
    import sys

    import jaxdeploy.sweep as library
    from jaxdeploy.commands import simulate

    store, bar = library._store_chunk, simulate.PROGRESS_BAR_S

    def marked(*args, **kwargs):
        store(*args, **kwargs)
        print(STORED, file=sys.stderr)

    library._store_chunk, simulate.PROGRESS_BAR_S = marked, 0.0
    out = tmp_path_factory.mktemp("plan") / "sweep"
    try:
        code, printed, err = _command(
            ["sweep", *ARGV, "--grid", GRID, "--chunk-size", "1", "--out", out]
        )
    finally:
        library._store_chunk, simulate.PROGRESS_BAR_S = store, bar
    return out, code, printed, err


def test_the_sweep_says_its_estimate_from_its_own_program_before_the_first_chunk(swept):
    out, code, _, err = swept
    lines = err.splitlines()
    estimate = [i for i, line in enumerate(lines) if line.startswith("sweep: 2 cases of pendulum")]
    assert len(estimate) == 1, err
    stored = [i for i, line in enumerate(lines) if STORED in line]  # (after a progress bar)
    assert estimate[0] < stored[0]  # said before the first chunk ran
    line = lines[estimate[0]]
    assert "to --t-end = 1 s would run for about" in line
    assert "2 chunk(s) each as long as the first" in line
    assert "steps per simulated second" in line  # simulate's account of its prefixes
    assert line.endswith("per case for its summary")  # the host work after each chunk
    assert len(stored) == 2
    manifest = json.loads((out / "manifest.json").read_text())
    assert [c["stop"] - c["start"] for c in manifest["chunks"]] == [1, 1]


def test_each_case_carries_its_energy_verdict_and_implausible_ones_are_not_plotted(swept):
    from jaxdeploy.commands._sweep_outputs import overview_figure
    from jaxdeploy.scenes import Pendulum
    from jaxdeploy.sweep import load_sweep

    out, code, printed, _ = swept
    assert code == 6  # a case is implausible (EXIT_IMPLAUSIBLE)
    assert "2/2 cases in 2 chunks, 0 failed, 1 implausible" in printed
    cases = json.loads((out / "features.json").read_text())["cases"]
    short, long_ = cases
    assert short["status"].startswith("implausible: energy_balance = 0.018 exceeds its limit")
    assert short["energy_balance"] == pytest.approx(0.018, rel=0.01)
    assert long_["status"] == "ok" and 1e-3 < long_["energy_balance"] < 3e-3
    with open(out / "features.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert rows[0]["status"].startswith("implausible: energy_balance") and rows[1]["status"] == "ok"
    assert "energy_balance [-]" in rows[0]
    assert (out / "overview.png").stat().st_size > 0
    grid = {"length": [0.2, 2.0]}
    fig, left_out = overview_figure(Pendulum(), load_sweep(str(out)), ["length"], grid)
    assert left_out == 1
    assert "(1 failed or implausible, not shown: features.csv)" in fig._suptitle.get_text()
    visible = [ax for ax in fig.axes if ax.get_visible()]
    assert all(len(line.get_xdata()) == 1 for ax in visible for line in ax.get_lines())


def test_a_case_gets_the_energy_verdict_simulate_gives_the_same_run(swept, tmp_path):
    out, _, _, _ = swept
    short = json.loads((out / "features.json").read_text())["cases"][0]
    code, _, _ = _command(["simulate", "pendulum", *ARGV[2:], "--set", "length=0.2", "--quiet",
                           "--out", tmp_path / "one"])  # fmt: skip
    assert code == 6
    summary = json.loads((tmp_path / "one" / "summary.json").read_text())
    (energy,) = [c for c in summary["plausibility"] if c["check"] == "energy_balance"]
    # The sweep runs generalized-α with Newton's method proper, simulate the modified one
    # (`batch.vmapped_control`): the same equations to the same Newton tolerance.
    assert short["energy_balance"] == pytest.approx(energy["value"], rel=1e-6)
    assert summary["status"] == short["status"]


def test_a_ten_thousand_case_sweep_is_timed_before_its_first_chunk(tmp_path, monkeypatch):
    """Refused after the probe (the limit lowered to 0.1 s: the probe's measurement is of this
    machine), before any chunk: nothing is left in the folder's place. The scene's rate is
    taken out of the table, which would refuse it before compiling at that limit.

    The threshold below which a sweep is not even announced (`PROGRESS_BAR_S`, 30 s) is
    lowered with it: the probe returns quietly under it, so with only the limit lowered to
    1 s the test passed only where the estimate exceeded 30 s. On a quiet AVX-512 machine the
    probe measured 0.4 ms per one-case chunk, ~4 s for the 10,000 with their summaries, and
    the sweep started its chunks. At 0.1 s the estimate has a margin of ~40x."""
    import jaxdeploy.sweep as library
    from jaxdeploy.commands import simulate

    def no_chunk(*args, **kwargs):
        raise AssertionError("a chunk ran before the estimate")

    monkeypatch.setattr(library, "_run_chunk", no_chunk)
    monkeypatch.setattr(simulate, "LONG_RUN_S", 0.1)
    monkeypatch.setattr(simulate, "PROGRESS_BAR_S", 0.05)
    monkeypatch.delitem(simulate.INTEGRATE_S_PER_SIMULATED_S, "pendulum")
    code, _, err = _command(["sweep", *ARGV[:2], "--t-end", "0.1", "--n-save", "11",
                             "--grid", "length=1:2:10000", "--chunk-size", "1",
                             "--out", tmp_path / "s"])  # fmt: skip
    assert code == 2
    assert "error: 10000 cases of pendulum to --t-end = 0.1 s would run for about" in err
    assert "10000 chunk(s) each as long as the first" in err and "pass --long-run" in err
    assert os.listdir(tmp_path) == []


def test_ctrl_c_during_the_sweeps_probe_is_one_line_and_leaves_nothing(tmp_path, monkeypatch):
    import jaxdeploy.sweep as library

    def interrupted(run, setup, k):
        def run_to(t):
            raise KeyboardInterrupt

        return run_to

    monkeypatch.setattr(library, "_prefix_runner", interrupted)
    code, _, err = _command(["sweep", *ARGV, "--grid", GRID, "--out", tmp_path / "s"])
    assert code == 130
    lines = err.strip().splitlines()
    assert lines[-2].startswith("probe: the first chunk over the first parts of its horizon")
    assert lines[-1] == "interrupted: jaxdeploy sweep stopped (Ctrl-C)"
    assert os.listdir(tmp_path) == []  # no manifest, no lock
