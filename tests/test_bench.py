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
