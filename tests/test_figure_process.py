"""The figure process of `jaxdeploy simulate` (jaxdeploy/commands/_figures.py): the figure
module imports neither JAX nor the package, the process draws a scene's figures from plain
numbers and writes the files the command lists, a failure is raised with the process's
message, and a process that was sent nothing ends without writing. Counts and files, never
times."""

import json
import os
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

from jaxdeploy.commands._figures import FIGURES_PY, FigureProcess


def _slider_crank_data(n=50):
    angle = np.linspace(0.0, 720.0, n)
    orbit = 4e-4 * np.stack([np.cos(np.radians(angle)), np.sin(np.radians(angle))], axis=1)
    return {
        "crank_angle": angle,
        "slider_acceleration": np.sin(np.radians(angle)),
        "slider_acceleration_ideal": np.cos(np.radians(angle)),
        "clearance": 5e-4,
        "joints": [{"eccentricity": orbit, "normal_force": np.abs(np.sin(angle))}],
    }


def test_the_figure_module_imports_no_jax_and_no_package():
    code = (
        "import runpy, sys; runpy.run_path(sys.argv[1]); import json; "
        "print(json.dumps([m for m in ('jax', 'jaxdeploy', 'diffrax', 'equinox', 'scipy') "
        "if m in sys.modules]))"
    )
    done = subprocess.run(
        [sys.executable, "-P", "-c", code, FIGURES_PY], capture_output=True, text=True, check=True
    )
    assert json.loads(done.stdout) == []


def test_the_process_draws_the_figures_it_is_sent(tmp_path):
    drawing = FigureProcess()
    drawing.start()
    drawing.send("slider_crank", _slider_crank_data(), str(tmp_path))
    files = drawing.files()
    drawing.close()
    names = sorted(p.rsplit("/", 1)[-1] for p in files)
    assert names == ["journal_orbit_contact_force.png", "slider_acceleration.png"]
    for path in files:
        with open(path, "rb") as f:
            assert f.read(8) == b"\x89PNG\r\n\x1a\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == names  # no temporary file left


def test_a_failed_drawing_raises_with_its_message(tmp_path):
    drawing = FigureProcess()
    drawing.start()
    broken = {**_slider_crank_data(), "crank_angle": np.zeros(3)}  # lengths differ
    drawing.send("slider_crank", broken, str(tmp_path))
    with pytest.raises(RuntimeError, match="figure process"):
        drawing.files()
    drawing.close()


def test_a_process_sent_nothing_ends_without_writing(tmp_path):
    drawing = FigureProcess()
    drawing.start()
    process = drawing._process
    drawing.close()
    assert process.poll() is not None
    assert not list(tmp_path.iterdir())


def _group_alive(pgid: int) -> list[int]:
    """The processes of group `pgid` that are not zombies (Linux's /proc)."""
    alive = []
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/stat") as f:
                stat = f.read()
        except OSError:  # ended meanwhile
            continue
        state, _ppid, group = stat.rsplit(")", 1)[1].split()[:3]
        if int(group) == pgid and state != "Z":
            alive.append(int(entry))
    return alive


# figures.py with one more drawing of two figures, the second of which (drawn by the forked
# copy) takes a minute: a copy that outlives `close` is then seen, however fast the machine.
_SLOW_FIGURES = """
import runpy, sys, time
figures = runpy.run_path({path!r})
figures["DRAWINGS"]["slow"] = (lambda data, out: [], lambda data, out: time.sleep(60) or [])
sys.exit(figures["serve"]())
"""


@pytest.mark.skipif(not os.path.isdir("/proc/self"), reason="reads process groups in /proc")
def test_closing_ends_the_forked_copy_that_draws_beside(tmp_path, monkeypatch):
    # A refusal or Ctrl-C while the figures are drawn: the figure process and the copy it
    # forked for every second figure (`draw_side_by_side`) both end at once.
    from jaxdeploy.commands import _figures

    script = tmp_path / "slow_figures.py"
    script.write_text(_SLOW_FIGURES.format(path=FIGURES_PY))
    monkeypatch.setattr(_figures, "FIGURES_PY", str(script))
    drawing = FigureProcess()
    drawing.start()
    pgid = drawing._process.pid
    assert os.getpgid(pgid) == pgid  # a session, and so a group, of its own
    drawing.send("slow", {}, str(tmp_path))
    deadline = time.monotonic() + 60.0
    while len(_group_alive(pgid)) < 2:  # until the copy is drawing
        assert time.monotonic() < deadline, "the figure process never forked its copy"
        time.sleep(0.005)
    closing = threading.Thread(target=drawing.close, daemon=True)
    closing.start()
    closing.join(10.0)  # waiting for the copy's minute would be a hang (it holds the pipe)
    assert not closing.is_alive(), "close() waits for the forked copy"
    deadline = time.monotonic() + 10.0
    while _group_alive(pgid):
        assert time.monotonic() < deadline, f"still running: {_group_alive(pgid)}"
        time.sleep(0.01)


def test_without_a_process_the_figures_are_drawn_here(tmp_path):
    drawing = FigureProcess()  # never started
    drawing.send("slider_crank", _slider_crank_data(), str(tmp_path))
    assert len(drawing.files()) == 2 and len(list(tmp_path.glob("*.png"))) == 2


_SIDE_BY_SIDE = """
import importlib.util, json, os, pickle, sys
spec = importlib.util.spec_from_file_location("figures", sys.argv[1])
figures = importlib.util.module_from_spec(spec)
spec.loader.exec_module(figures)
figures._usable_cores = lambda: 2  # fork even on a one-core machine
forks, fork = [], os.fork
def counted():
    forks.append(1)
    return fork()
os.fork = counted
with open(sys.argv[2], "rb") as f:
    kind, data, out_dir = pickle.load(f)
try:
    paths = figures.draw_side_by_side(kind, data, out_dir)
except RuntimeError as err:
    print(json.dumps({"error": str(err), "forks": len(forks)}))
else:
    print(json.dumps({"paths": paths, "forks": len(forks)}))
"""


def _side_by_side(tmp_path, data, out_dir):
    import pickle

    request = tmp_path / "request.pkl"
    request.write_bytes(pickle.dumps(("slider_crank", data, str(out_dir))))
    done = subprocess.run(
        [sys.executable, "-P", "-c", _SIDE_BY_SIDE, FIGURES_PY, str(request)],
        capture_output=True, text=True, check=True,
    )  # fmt: skip
    return json.loads(done.stdout)


def test_figures_drawn_side_by_side_are_those_drawn_in_turn(tmp_path):
    from jaxdeploy.analysis.figures import draw

    data = _slider_crank_data()
    (tmp_path / "turn").mkdir()
    (tmp_path / "side").mkdir()
    in_turn = draw("slider_crank", data, str(tmp_path / "turn"))
    side = _side_by_side(tmp_path, data, tmp_path / "side")
    assert side["forks"] == 1  # the second figure was drawn in the forked copy
    names = [p.rsplit("/", 1)[-1] for p in side["paths"]]
    assert names == [p.rsplit("/", 1)[-1] for p in in_turn]  # the same files, in order
    for name in names:
        assert (tmp_path / "side" / name).read_bytes() == (tmp_path / "turn" / name).read_bytes()


def test_a_figure_that_fails_in_the_forked_copy_is_raised(tmp_path):
    broken = {**_slider_crank_data(), "joints": [{"eccentricity": np.zeros(3),
                                                  "normal_force": np.zeros(3)}]}  # fmt: skip
    (tmp_path / "side").mkdir()
    side = _side_by_side(tmp_path, broken, tmp_path / "side")
    assert side["forks"] == 1 and "IndexError" in side["error"], side
    # The figure drawn here is written; the failed one left nothing behind.
    assert sorted(p.name for p in (tmp_path / "side").iterdir()) == ["slider_acceleration.png"]


def test_the_figure_process_is_started_by_the_scene_name_its_analysis_uses():
    # `simulate` starts the figure process before it imports the scenes, by the scene's name:
    # every analysis that draws names its figures after its scene, and figures.py has them.
    from jaxdeploy.analysis import ANALYSES
    from jaxdeploy.commands._figures import drawing_names

    drawn = {scene: cls.figures for scene, cls in ANALYSES.items() if cls.figures is not None}
    assert drawn and all(figures == scene for scene, figures in drawn.items())
    assert drawing_names() == frozenset(drawn)
