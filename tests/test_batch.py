"""Batches: one vmapped run equals the separate runs; validation before tracing; channels
against independent computations."""

import jax
import numpy as np
import pytest

from jaxdeploy.batch import run_scene, simulate_batch
from jaxdeploy.scenes import DeployArray, Pendulum


def test_batch_equals_separate_runs_and_varies_only_what_differs():
    scene = Pendulum()
    cases = {"initial_angle": [0.0, -0.5, 0.7], "length": [1.0, 1.0, 1.0]}
    batch = simulate_batch(scene, cases, 0.3, n_save=31)
    assert batch.varied == ("initial_angle",)
    assert batch.size == 3 and list(batch.ok) == [True] * 3
    for i in range(3):
        single = run_scene(scene, batch.case_params(i), 0.3, n_save=31)
        np.testing.assert_allclose(batch.case(i).q, single.q, rtol=0, atol=1e-12)
    # The cases really differ (the batch is not one case broadcast).
    assert abs(float(batch.case(0).q[-1, 2]) - float(batch.case(2).q[-1, 2])) > 0.1


def test_identical_cases_are_broadcast():
    batch = simulate_batch(Pendulum(), [{"length": 2.0}, {"length": 2.0}], 0.1, n_save=5)
    assert batch.varied == () and batch.size == 2
    np.testing.assert_array_equal(batch.case(0).q, batch.case(1).q)


def test_bad_cases_are_refused_before_tracing():
    with pytest.raises(ValueError, match="length"):
        simulate_batch(Pendulum(), {"length": [1.0, -1.0]}, 0.1)
    with pytest.raises(ValueError, match="unknown parameter 'lenght'"):
        simulate_batch(Pendulum(), {"lenght": [1.0]}, 0.1)
    with pytest.raises(ValueError, match="same number of values"):
        simulate_batch(Pendulum(), {"length": [1.0, 2.0], "mass": [1.0]}, 0.1)
    with pytest.raises(ValueError, match="empty"):
        simulate_batch(Pendulum(), [], 0.1)


@pytest.mark.slow  # 17 s of the default suite at 844cb65 (2 cores): kept out of it
def test_run_scene_differentiates_through_parameters():
    """d θ(t_end) / d initial_angle by AD against central differences."""
    scene = Pendulum()
    base = scene.resolve_params()

    def final_angle(angle):
        return run_scene(scene, {**base, "initial_angle": angle}, 0.2, n_save=3).q[-1, 2]

    ad = float(jax.grad(final_angle)(0.3))
    h = 1e-5
    fd = float((final_angle(0.3 + h) - final_angle(0.3 - h)) / (2 * h))
    assert ad == pytest.approx(fd, rel=1e-6)


def test_deploy_array_channels_agree_with_independent_computations():
    """On the ideal-joint array (smooth motion): α from the tip's direction, tip accelerations
    against second differences of tip positions."""
    scene = DeployArray(ideal=True)
    params = scene.resolve_params()
    mech = scene.build(params)
    traj = run_scene(scene, params, 0.2, n_save=401)
    ch = scene.channels(mech, traj)
    ts = np.asarray(traj.ts)
    root = np.asarray(mech.point("ground", "O"))  # the root hinge J1
    dx = np.asarray(ch["panel1_tip_x"]) - root[0]
    dy = np.asarray(ch["panel1_tip_y"]) - root[1]
    np.testing.assert_allclose(np.arctan2(dx, dy), ch["alpha"], rtol=0, atol=1e-9)
    for panel in ("panel1", "panel2"):
        for axis in ("x", "y"):
            pos = np.asarray(ch[f"{panel}_tip_{axis}"])
            acc = np.asarray(ch[f"{panel}_tip_a{axis}"])
            fd = np.gradient(np.gradient(pos, ts), ts)
            inner = slice(5, -5)  # one-sided differences at the ends
            scale = np.abs(acc).max()
            assert np.abs(fd[inner] - acc[inner]).max() < 1e-3 * scale
    assert not any(k.endswith("_normal_force") for k in ch)  # ideal joints: no contact


def test_grouped_batch_equals_separate_runs():
    """Cases vmapped in groups (`group_size`, one group after another, the last one smaller)
    give each case's own run: 5 cases in groups of 2 against 5 separate runs."""
    scene = Pendulum()
    angles = [0.0, -0.5, 0.7, 0.2, -0.9]
    batch = simulate_batch(scene, {"initial_angle": angles}, 0.3, n_save=31, group_size=2)
    assert batch.size == 5 and list(batch.ok) == [True] * 5
    for i in range(5):
        single = run_scene(scene, batch.case_params(i), 0.3, n_save=31)
        np.testing.assert_allclose(batch.case(i).q, single.q, rtol=0, atol=1e-12)
    with pytest.raises(ValueError, match="group_size"):
        simulate_batch(scene, {"initial_angle": angles}, 0.3, group_size=0)
