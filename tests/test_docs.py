"""The docs' code examples run as written."""

import pathlib
import re
import warnings

import numpy as np
import pytest

from jaxdeploy.solvers import SolverChoiceWarning

DOCS = pathlib.Path(__file__).resolve().parent.parent / "docs"


def _python_blocks(name):
    text = (DOCS / name).read_text()
    return re.findall(r"```python\n(.*?)```", text, flags=re.S)


@pytest.mark.slow  # ~32 CPU-s the run, ~140 CPU-s the reverse-mode example (load ~13, 46f1f28)
def test_mechanism_page_four_bar_runs(monkeypatch):
    # The page's script turns the persistent caches on (`enable_caches()`); in this shared
    # test process they stay off (a script's second process is tests/test_python_caches.py).
    monkeypatch.setenv("JAXDEPLOY_CACHE_DIR", "off")
    namespace = {}
    with warnings.catch_warnings():
        # The page's example runs the defaults: no solver-choice warning may fire.
        warnings.simplefilter("error", SolverChoiceWarning)
        for block in _python_blocks("mechanism.md"):
            exec(compile(block, "docs/mechanism.md", "exec"), namespace)
    trajectory = namespace["trajectory"]
    assert trajectory.ok, trajectory.status()
    assert trajectory.control.solver_name() == "dopri8"  # the default for clearance joints
    # The spring turns the crank: it has moved, and every constraint still holds.
    q = np.asarray(trajectory.q)
    assert abs(q[-1, 2] - q[0, 2]) > 0.05
    mech = namespace["mechanism"]
    assert float(np.max(np.abs(mech.constraints(trajectory.q[-1], 0.2)))) < 1e-9
    assert np.isfinite(float(namespace["final_rocker_angle"](1e-4)))


@pytest.mark.slow  # 71 s on a 2-core machine (f838811): two deploy_array runs vmapped, compiled
def test_deploy_array_page_batch_example_runs():
    namespace = {}
    for block in _python_blocks("deploy_array.md"):
        exec(compile(block, "docs/deploy_array.md", "exec"), namespace)
    assert namespace["batch"].statuses() == ["ok", "ok"]
    alpha = namespace["alpha"]
    # Both cases start at 45° and are opening.
    for a in alpha:
        assert abs(a[0] - np.pi / 4) < 1e-9 and a[-1] > a[0]


@pytest.mark.slow  # ~85 s CPU at load ~28 (the fit's forward-mode model compiles for most of it)
def test_tutorial_runs_and_its_numbers_hold(monkeypatch):
    # The page turns the persistent caches on first; in this shared test process they stay off.
    monkeypatch.setenv("JAXDEPLOY_CACHE_DIR", "off")
    namespace = {}
    for block in _python_blocks("tutorial.md"):
        exec(compile(block, "docs/tutorial.md", "exec"), namespace)
    trajectory = namespace["trajectory"]
    assert trajectory.ok, trajectory.status()
    assert trajectory.control.solver_name() == "dopri8"  # the defaults ran
    # Eight impacts (tests/test_independent_pendulum.py checks them against the reference).
    assert len(namespace["episodes"]) == 8
    # The journal reaches the bore (eccentricity = clearance + penetration, µm).
    assert 1e-4 < namespace["eccentricity"].max() < 1e-4 + 2e-6
    # The energy balance closes to the meter's trapezoidal error (measured 1.6e-5).
    balance, scale = namespace["balance"], namespace["scale"]
    assert float(np.max(np.abs(balance["residual"]))) / scale < 1e-4
    assert float(balance["dissipated"][-1]) > 0
    # The fit recovers c_e = 0.8 from 0.7 within two standard errors.
    result = namespace["result"]
    estimate, error = result.estimates["restitution"], result.standard_errors["restitution"]
    assert result.converged and error < 0.05 and abs(estimate - 0.8) < 2 * error
    # Forward-mode derivative against the central difference beside it.
    np.testing.assert_allclose(float(namespace["slope"]), float(namespace["difference"]), rtol=1e-4)
