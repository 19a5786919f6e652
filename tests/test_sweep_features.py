"""A sweep's per-case features (issue 22 item 6): without `--objective` every case still gets
the quantities `jaxdeploy simulate` reports, with units, as strict CSV/JSON and an overview
figure; and the sweep compiles its simulation once, whatever its number of chunks."""

import contextlib
import csv
import io
import json
import math
import re

import numpy as np
import pytest

from jaxdeploy.commands._results import describe_key
from jaxdeploy.commands._sweep_outputs import feature_table, objective_unit, overview_figure

# 5 lengths x 2 angles = 10 cases in chunks of 4: 3 chunks, the last one padded (2 of 4).
LENGTHS, ANGLES = [0.5, 1.0, 1.5, 2.0, 2.5], [0.3, 0.6]
T_END, N_SAVE = 0.3, 11


def _strict(text):
    def refuse(token):
        raise ValueError(f"non-strict JSON token {token}")

    return json.loads(text, parse_constant=refuse)


@pytest.fixture(scope="module")
def swept(tmp_path_factory):
    """One pendulum sweep through the command line, with the compilations JAX reports
    (`jax.monitoring`) counted between the chunks."""
    from jax import monitoring

    import jaxdeploy.sweep as sweep_module
    from jaxdeploy.cli import main

    compiles = []
    listening = [True]

    def record(event, duration, **kwargs):
        if listening[0] and event == "/jax/core/compile/backend_compile_duration":
            compiles.append(kwargs.get("fun_name"))

    monitoring.register_event_duration_secs_listener(record)
    # Mark where each case's summary starts and ends in the stream of compilations: what
    # compiles between the last summary of one chunk and the first of the next belongs to the
    # next chunk's simulation.
    marks = []
    original = sweep_module.sweep

    def marked_sweep(*args, summarize=None, **kwargs):
        def wrapped(params, trajectory):
            marks.append(("start", len(compiles)))
            out = summarize(params, trajectory)
            marks.append(("end", len(compiles)))
            return out

        return original(*args, summarize=wrapped, **kwargs)

    sweep_module.sweep = marked_sweep
    out = tmp_path_factory.mktemp("sweep") / "pendulum"
    printed, progress = io.StringIO(), io.StringIO()
    try:
        with contextlib.redirect_stdout(printed), contextlib.redirect_stderr(progress):
            code = main(["sweep", "--scene", "pendulum",
                         "--grid", "length=" + ",".join(map(str, LENGTHS)),
                         "--grid", "initial_angle=" + ",".join(map(str, ANGLES)),
                         "--t-end", str(T_END), "--n-save", str(N_SAVE), "--chunk-size", "4",
                         "--out", str(out)])  # fmt: skip
    finally:
        sweep_module.sweep = original
        listening[0] = False
    assert code == 0, progress.getvalue()
    # Progress (issue 22 item 2) off a terminal: a line per chunk, cases done of all, the
    # time left while cases remain (a tqdm bar on a terminal: test_progress_is_a_bar_...).
    lines = [line for line in progress.getvalue().splitlines() if line.startswith("sweep: ")]
    done = [line for line in lines if re.match(r"sweep: \d+/10 cases \(\d+ %\)", line)]
    assert len(done) == 3 and done[-1].startswith("sweep: 10/10 cases (100 %)"), lines
    assert all("left" in line for line in done[:-1]) and "left" not in done[-1], done
    assert "\r" not in progress.getvalue()
    assert "10/10 cases in 3 chunks, 0 failed" in printed.getvalue()
    assert "features.csv" in printed.getvalue() and "overview.png" in printed.getvalue()
    return out, compiles, marks


def test_sweep_compiles_its_simulation_once(swept):
    out, compiles, marks = swept
    manifest = json.loads((out / "manifest.json").read_text())
    assert [c["stop"] - c["start"] for c in manifest["chunks"]] == [4, 4, 2]
    assert manifest["definition"]["chunk_size"] == 4 and manifest["definition"]["summary"]
    starts = [n for kind, n in marks if kind == "start"]
    ends = [n for kind, n in marks if kind == "end"]
    assert len(starts) == 10
    # Chunk k's simulation runs between the last summary of chunk k-1 and the first of k.
    first_of_chunk = [starts[0], starts[4], starts[8]]
    last_before = [0, ends[3], ends[7]]
    per_chunk = [f - b for f, b in zip(first_of_chunk, last_before, strict=True)]
    assert per_chunk[0] >= 1, "the first chunk compiles the simulation"
    assert per_chunk[1:] == [0, 0], (
        f"later chunks (the last one padded) compiled {per_chunk[1:]} programs: "
        f"{compiles[last_before[1] :]}"
    )
    # Summaries after the first case reuse what the first one compiled (nothing per case).
    later = sum(e - s for s, e in zip(starts[1:], ends[1:], strict=True))
    assert later == 0, f"per-case summaries compiled {later} programs"


def test_sweep_without_objective_writes_features_with_units(swept):
    out, _, _ = swept
    doc = _strict((out / "features.json").read_text())
    assert doc["swept"] == ["length", "initial_angle"]
    rows, units = doc["cases"], doc["units"]
    assert [r["case"] for r in rows] == list(range(10))
    assert [(r["length"], r["initial_angle"]) for r in rows] == [
        (a, b) for a in LENGTHS for b in ANGLES
    ]
    for key in ("status", "t_reached_s", "n_steps", "n_rejected", "max_constraint_violation"):
        assert key in doc["columns"]
    assert units["length"] == "m" and units["initial_angle"] == "rad"
    assert units["max_constraint_violation"] == "m" and units["t_reached_s"] == "s"
    for column in doc["columns"][3:]:  # every summary key documented (docs/results.md)
        assert describe_key(column) is not None, column
        assert units[column] == (describe_key(column)[0] or "")
    assert all(r["status"] == "ok" and r["t_reached_s"] == T_END for r in rows)

    # The CSV holds the same table, its header naming each unit.
    with open(out / "features.csv", newline="") as fh:
        table = list(csv.reader(fh))
    assert table[0][:4] == ["case [-]", "length [m]", "initial_angle [rad]", "status"]
    assert "max_constraint_violation [m]" in table[0] and len(table) == 11

    # A case's features are what a standalone run of its parameters reports.
    from jaxdeploy.analysis import analyse
    from jaxdeploy.batch import run_scene
    from jaxdeploy.commands._results import run_quantities
    from jaxdeploy.scenes import Pendulum

    scene = Pendulum()
    row = rows[7]
    params = scene.resolve_params({"length": row["length"], "initial_angle": row["initial_angle"]})
    single = run_scene(scene, params, T_END, n_save=N_SAVE)
    summary = analyse(scene, params, scene.build(params), single).summary()
    expected = {**run_quantities(single), **summary}
    for key in ("status", "t_reached_s", "n_steps", "n_rejected"):
        assert row[key] == expected[key], key
    assert row["max_constraint_violation"] == pytest.approx(
        expected["max_constraint_violation"], abs=1e-12
    )
    assert (out / "overview.png").stat().st_size > 0


def test_overview_axes_are_labelled_with_units(swept):
    from jaxdeploy.scenes import Pendulum
    from jaxdeploy.sweep import load_sweep

    out, _, _ = swept
    grid = {"length": LENGTHS, "initial_angle": ANGLES}
    fig, _ = overview_figure(Pendulum(), load_sweep(str(out)), list(grid), grid)
    visible = [ax for ax in fig.axes if ax.get_visible()]
    assert len(visible) >= 4  # t_reached_s, n_steps, n_rejected, max_constraint_violation, ...
    for ax in visible:
        assert ax.get_xlabel() == "length [m]"
        assert ax.get_ylabel().endswith("]") and " [" in ax.get_ylabel()
        assert len(ax.get_lines()) == len(ANGLES)  # one line per value of the other parameter


def test_feature_table_is_strict():
    # NaN and infinities (a failed case's summary) become null / an empty CSV cell.
    from jaxdeploy.scenes import Pendulum

    data = {
        "case": np.array([0, 1]),
        "param_length": np.array([1.0, 2.0]),
        "feature_objective": np.array([0.5, math.nan]),
        "summary": np.array(
            [
                json.dumps({"status": "ok", "max_constraint_violation": 1e-16}),
                json.dumps({"status": "failed", "max_constraint_violation": None}),
            ]
        ),
    }
    columns, units, rows = feature_table(Pendulum(), data, ["length"])
    assert columns == ["case", "length", "objective", "status", "max_constraint_violation"]
    assert units["objective"] == "-" and units["status"] == ""
    assert rows[1]["objective"] is None and rows[1]["max_constraint_violation"] is None


def test_every_preset_objective_term_has_a_unit():
    from jaxdeploy.objectives import PRESETS

    for terms in PRESETS.values():
        for term in terms:
            assert objective_unit(term.label) != "?", term.label
    assert objective_unit("panel2:peak_vibration[acceleration]") == "m/s²"
    assert objective_unit("panel2:peak_vibration") == "m"
    assert objective_unit("panel1:dominant_frequency") == "Hz"


def test_progress_is_a_bar_on_a_terminal_and_lines_elsewhere():
    """A tqdm bar where a person watches (a terminal); one line per chunk in a log or pipe,
    whose time left counts only this run's cases (a resumed sweep's earlier ones excluded)."""
    from tqdm import tqdm

    from jaxdeploy.sweep import _progress

    class Terminal(io.StringIO):
        def isatty(self):
            return True

    bar = _progress(True, 8, 0, stream=Terminal())
    assert isinstance(bar, tqdm)
    bar.close()
    assert _progress(False, 8, 0, stream=Terminal()) is None
    log = io.StringIO()
    lines = _progress(True, 8, 4, stream=log)  # resumed: 4 cases were done before
    lines.update(2)
    lines.update(2)
    first, last = log.getvalue().splitlines()
    assert first.startswith("sweep: 6/8 cases (75 %), ") and "left" in first, first
    assert last.startswith("sweep: 8/8 cases (100 %), ") and "left" not in last, last
