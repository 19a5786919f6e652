"""`jaxdeploy bench work-precision --quick`: outputs, errors against the reference, refusals."""

import csv
import json
import os

import pytest

from jaxdeploy.cli import main


def test_bench_refuses_unknown_scene(tmp_path, capsys):
    assert main(["bench", "work-precision", "pendulum", "--out", str(tmp_path / "x")]) == 2
    assert "slider_crank" in capsys.readouterr().err
    assert not (tmp_path / "x").exists()


@pytest.mark.slow
def test_quick_work_precision_run(tmp_path):
    out = tmp_path / "bench"
    assert main(["bench", "work-precision", "slider_crank", "--quick", "--out", str(out)]) == 0
    for ext in ("csv", "md", "png", "json"):
        assert (out / f"work_precision.{ext}").stat().st_size > 0
    rows = list(csv.DictReader(open(out / "work_precision.csv")))
    kinds = {r["kind"] for r in rows}
    from jaxdeploy.benchmarks.exudyn_peer import exudyn_available

    expected = {"jaxdeploy", "scipy-numpy", "scipy-jitted"}
    assert kinds == expected | ({"exudyn"} if exudyn_available() else set())
    for r in rows:
        assert r["status"] == "ok", r
        err = float(r["error_window"])
        # Every configuration at rtol 1e-6 or h = 1e-6 is within 1 % of the clearance, and
        # none equals the reference (an error of exactly 0 would mean a comparison bug).
        assert 0 < err < 1e-2, r
        assert float(r["wall_s"]) > 0 and int(r["steps"]) > 0
    meta = json.loads(open(out / "work_precision.json").read())
    assert max(e["window"] for e in meta["reference"]["evidence"]) < 1e-6
    # No silent overwrite.
    assert main(["bench", "work-precision", "slider_crank", "--quick", "--out", str(out)]) == 2
    assert os.path.exists(out / "work_precision.csv")


def test_interrupted_run_resumes_without_repeating_finished_configurations(tmp_path, monkeypatch):
    """Rows are written after every configuration; `--resume` keeps the saved reference and
    the finished rows and runs only the rest. Two cheap scipy configurations against a
    reference from the event-based numpy model stand in for the full list."""
    from jaxdeploy.benchmarks import work_precision as wp

    out = tmp_path / "bench"
    out.mkdir()
    _peer_reference().save(str(out))
    configs = [
        wp.Config(f"scipy {m} (numpy)", "rtol=1e-06", "scipy-numpy", m, 1e-6, 1e-9)
        for m in ("DOP853", "LSODA")
    ]
    monkeypatch.setattr(wp, "configurations", lambda scene, quick: configs)
    ran = []
    run_scipy = wp._run_scipy
    monkeypatch.setattr(
        wp, "_run_scipy", lambda cfg, *a: ran.append(cfg.solver) or run_scipy(cfg, *a)
    )
    command = ["bench", "work-precision", "slider_crank", "--out", str(out), "--repeats", "1"]

    assert main(command + ["--resume"]) == 0  # a reference but no row yet: runs both
    assert ran == ["DOP853", "DOP853", "LSODA", "LSODA"]  # compiling run + one timed run
    meta = json.loads(open(out / "work_precision.json").read())
    first_row = meta["rows"][0]
    assert [r["status"] for r in meta["rows"]] == ["ok", "ok"]
    assert all(0 < r["error_window"] < 1e-2 for r in meta["rows"])
    # Interrupt after the first configuration: only its row is on disk.
    meta["rows"] = meta["rows"][:1]
    open(out / "work_precision.json", "w").write(json.dumps(meta))
    ran.clear()
    assert main(command + ["--resume"]) == 0
    assert ran == ["LSODA", "LSODA"]
    rows = json.loads(open(out / "work_precision.json").read())["rows"]
    assert [r["family"] for r in rows] == ["scipy DOP853 (numpy)", "scipy LSODA (numpy)"]
    assert rows[0] == first_row
    # Refusals: other options than the interrupted run's; nothing to resume; both flags.
    assert main(command + ["--resume", "--t-end", "1e-3"]) == 2
    assert main(["bench", "work-precision", "--out", str(tmp_path / "empty"), "--resume"]) == 2
    assert main(command + ["--resume", "--overwrite"]) == 2


def test_fastest_per_error_level_compares_ours_with_the_fastest_peer_that_reaches_it():
    from jaxdeploy.benchmarks.report import fastest_per_error_level
    from jaxdeploy.benchmarks.work_precision import Row

    def row(family, kind, error, wall, status="ok"):
        return Row(family, "x", kind, error, error, wall, 0.0, 1, 0, 0, 1.0, status)

    rows = [
        row("ours fast", "jaxdeploy", 5e-4, 0.1),
        row("ours exact", "jaxdeploy", 5e-7, 2.0),
        row("peer", "scipy-numpy", 5e-5, 1.0),
        row("peer failed", "scipy-numpy", 1e-9, 0.01, status="failed"),
    ]
    table = fastest_per_error_level(rows, levels=(1e-3, 1e-4, 1e-6, 1e-8)).splitlines()
    assert table[2] == "| 1e-03 | ours fast x | 0.1 | peer x | 1 | 0.1 |"
    assert table[3] == "| 1e-04 | ours exact x | 2 | peer x | 1 | 2 |"
    assert table[4] == "| 1e-06 | ours exact x | 2 | none reaches it | – | – |"
    assert table[5] == "| 1e-08 | none reaches it | – | none reaches it | – | – |"


def test_budgeted_configurations_run_in_workers_and_one_over_budget_is_reported(tmp_path):
    """`run_benchmark(..., budget_s=...)` (`--budget`): each configuration runs in a worker
    process that loads the saved reference; one that does not finish within the budget is
    killed and its row says so, and the run goes on with the next."""
    import numpy as np

    from jaxdeploy.benchmarks import work_precision as wp

    reference = _peer_reference()
    reference.save(str(tmp_path))
    cfg = wp.Config("scipy DOP853 (numpy)", "rtol=1e-06", "scipy-numpy", "DOP853", 1e-6, 1e-9)
    # Starting a worker (imports, building the mechanism) alone takes longer than 0.2 s.
    late = wp._measure_in_worker("slider_crank", str(tmp_path), cfg, 1, 0.2)
    assert late.status.startswith("over budget") and np.isnan(late.error_window)
    row = wp._measure_in_worker("slider_crank", str(tmp_path), cfg, 1, 300.0)
    assert row.status == "ok" and 0 < row.error_window < 1e-2 and row.steps > 0
    assert row.peak_rss_mb > 0
    with pytest.raises(ValueError, match="reference_folder"):
        wp.run_benchmark("slider_crank", reference, budget_s=1.0)


def test_report_records_options_versions_and_seed_and_writes_atomically(tmp_path):
    """The work–precision JSON says what produced it (issue 8, nothing lost)."""
    import types

    import numpy as np

    from jaxdeploy.benchmarks.report import write_report
    from jaxdeploy.benchmarks.work_precision import Row

    reference = types.SimpleNamespace(
        error_bound=(1e-9, 1e-8),
        evidence=[dict(solver="dopri8", rtol=1e-11, window=1e-9, full=1e-8)],
        ts=np.linspace(0.0, 0.1, 11),
        window_end=0.05,
        rtol=1e-12,
        params={"clearance": 1e-4},
    )
    rows = [Row("ours", "rtol=1e-06", "jaxdeploy", 1e-5, 1e-4, 0.1, 1.0, 10, 1, 20, 100.0, "ok")]
    options = dict(quick=True, repeats=1, t_end=None)
    write_report(str(tmp_path), "slider_crank", reference, rows, options)
    meta = json.loads((tmp_path / "work_precision.json").read_text())
    assert meta["options"] == options and meta["reference"]["params"] == {"clearance": 1e-4}
    assert "jax" in meta["versions"] and "diffrax" in meta["versions"]
    assert "seed" in meta and meta["seed"] is None  # no random numbers drawn
    assert not [p for p in os.listdir(tmp_path) if p.startswith(".tmp-")]


def _peer_reference():
    """A cheap benchmark reference for slider_crank's first 0.3 ms: the event-based numpy
    model under scipy DOP853 at 1e-10 (stands in for the Dopri8 reference in fast tests)."""
    import numpy as np

    from jaxdeploy.benchmarks.peers import SliderCrankNumpy
    from jaxdeploy.benchmarks.reference import PEER_SCENE_OPTIONS, Reference
    from jaxdeploy.scenes import SliderCrank

    # The benchmark's rule, and the numpy model with the same one.
    scene = SliderCrank(**PEER_SCENE_OPTIONS["slider_crank"])
    p = scene.resolve_params(None)
    s0 = scene.initial_state(p, scene.build(p))
    ts = np.linspace(0.0, 0.3e-3, 31)
    peer = SliderCrankNumpy(p, scene.impact_velocity_rule).solve(
        s0, ts[-1], ts, "DOP853", 1e-10, 1e-12
    )
    evidence = [dict(solver="numpy DOP853", rtol=1e-10, window=0.0, full=0.0, steps=0)]
    return Reference("slider_crank", p, ts, peer.ys[:, :9], peer.ys[:, 9:], ts[-1], 1e-10, evidence)
