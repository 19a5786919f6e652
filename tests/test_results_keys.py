"""Results that describe themselves (issue 22 item 3): strict JSON, a unit for every summary
quantity and a line for every key in docs/results.md, labelled axes with units on every plot,
and default output folders that never collide."""

import json
import math
import os
import pathlib
import re

import pytest

from jaxdeploy.cli import main
from jaxdeploy.commands._results import SUMMARY_KEYS, describe_key
from jaxdeploy.io import atomic_write_json, default_output_dir, strict_json

DOC = pathlib.Path(__file__).resolve().parents[1] / "docs" / "results.md"


def _strict_load(path):
    def refuse(token):
        raise ValueError(f"{path}: bare {token} is not JSON")

    return json.loads(pathlib.Path(path).read_text(), parse_constant=refuse)


def test_every_documented_key_is_on_the_results_page_with_its_unit():
    text = DOC.read_text()
    for pattern, unit, _ in SUMMARY_KEYS:
        shown = pattern.replace(r"panel\d+", "panelN")
        row = re.search(rf"^\| `{re.escape(shown)}` \| ([^|]*) \|", text, re.M)
        assert row is not None, f"{shown} is not in docs/results.md"
        assert row.group(1).strip() == unit, (shown, row.group(1), unit)


def test_json_is_strict_nan_and_infinity_become_null(tmp_path):
    import numpy as np

    path = tmp_path / "r.json"
    atomic_write_json(str(path), {"a": math.nan, "b": [np.float64(np.inf), 1.0], "c": np.nan})
    assert _strict_load(path) == {"a": None, "b": [None, 1.0], "c": None}
    assert strict_json({"x": -math.inf}) == '{"x": null}'


def test_default_output_folders_never_collide(tmp_path):
    first = default_output_dir("simulate", "pendulum", root=str(tmp_path))
    os.makedirs(first)
    second = default_output_dir("simulate", "pendulum", root=str(tmp_path))
    assert second != first and not os.path.exists(second)
    other = default_output_dir("sweep", "pendulum", root=str(tmp_path))
    assert os.path.dirname(other) != os.path.dirname(first)


def _labelled(fig):
    """Problems with the axes of `fig`: an axes with data lacks an x or y label with a unit."""
    problems = []
    for ax in fig.axes:
        if not (ax.lines or ax.collections or ax.images):
            continue
        for which, label in (("x", ax.get_xlabel()), ("y", ax.get_ylabel())):
            shared = getattr(ax, f"get_shared_{which}_axes")().get_siblings(ax)
            labels = [label] + [a.get_xlabel() if which == "x" else a.get_ylabel() for a in shared]
            if not any(re.search(r"\[.+\]", t) for t in labels):
                problems.append(f"{ax.get_title() or '?'}: {which} label {label!r}")
    return problems


@pytest.fixture
def figures(monkeypatch):
    """Check the axes of every figure a command saves: drawn in this process (the command's
    figure process not started) to see them."""
    import jaxdeploy.analysis.figures
    import jaxdeploy.commands._figures

    problems = []
    original = jaxdeploy.analysis.figures.save

    def checking(fig, path, **kwargs):
        problems.extend(f"{os.path.basename(path)}: {p}" for p in _labelled(fig))
        original(fig, path, **kwargs)

    monkeypatch.setattr(jaxdeploy.analysis.figures, "save", checking)
    monkeypatch.setattr(jaxdeploy.commands._figures.FigureProcess, "start", lambda self: None)
    return problems


def _check_summary(out):
    summary = _strict_load(out / "summary.json")
    undocumented = [k for k in summary if describe_key(k) is None]
    assert not undocumented, f"keys missing from jaxdeploy/commands/_results.py: {undocumented}"
    assert "?" not in summary["units"].values(), summary["units"]
    assert summary["units"]["t_end_s"] == "s"
    assert set(summary["phases"]) >= {"build_s", "compile_s", "integrate_s", "outputs_s"}
    assert all(v >= 0 for v in summary["phases"].values())
    return summary


@pytest.mark.parametrize("scene", ["pendulum", "impact"])
def test_summary_keys_units_and_phases_fast_scenes(scene, tmp_path, figures):
    out = tmp_path / scene
    assert main(["simulate", scene, "--out", str(out), "--quiet"]) == 0
    _check_summary(out)
    assert not figures, figures


@pytest.mark.slow
@pytest.mark.parametrize("scene, t_end", [("slider_crank", "0.012"), ("deploy_array", "0.8")])
def test_summary_keys_units_and_plots_of_the_contact_scenes(scene, t_end, tmp_path, figures):
    out = tmp_path / scene
    assert main(["simulate", scene, "--t-end", t_end, "--out", str(out), "--quiet"]) == 0
    summary = _check_summary(out)
    assert summary["units"]["max_contact_force"] == "N"
    assert list(out.glob("*.png")), "the scene writes figures"
    assert not figures, figures


def test_quiet_prints_nothing(tmp_path, capsys):
    assert (
        main(["simulate", "pendulum", "--t-end", "0.05", "--out", str(tmp_path / "q"), "--quiet"])
        == 0
    )
    captured = capsys.readouterr()
    assert captured.out == "" and captured.err == ""
    assert main(["simulate", "pendulum", "--t-end", "0.05", "--out", str(tmp_path / "v")]) == 0
    err = capsys.readouterr().err
    # The phases, each with its duration, as they happen.
    for phase in ("build the mechanism", "integrate to t_end = 0.05 s", "outputs", "plots"):
        assert phase in err, err
    assert "compile" in err
