"""Batches: one vmapped run equals the separate runs; validation before tracing; channels
against independent computations."""

import jax
import numpy as np
import pytest

from jaxdeploy.batch import batch_function, run_scene, simulate_batch
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


def test_sharded_batches_refuse_accelerations_solved_after_the_loop():
    """Sharded, `batch_function` solves the saved q̈ and λ in the loop (after it, on two host
    devices, deploy_array's sweep hung: tests/test_sweep.py), and an explicit request for
    the other is refused by name before anything is traced."""
    mesh = jax.sharding.Mesh(np.array(jax.devices()[:1]), ("cases",))
    sharding = jax.sharding.NamedSharding(mesh, jax.sharding.PartitionSpec("cases"))
    scene, shared = Pendulum(), Pendulum().resolve_params({})
    shared.pop("length")
    with pytest.raises(ValueError, match="batch_saved_accelerations=True cannot be combined"):
        batch_function(scene, ("length",), shared, 0.1, np.linspace(0.0, 0.1, 3),
                       sharding=sharding, batch_saved_accelerations=True)  # fmt: skip
    run = batch_function(scene, ("length",), shared, 0.1, np.linspace(0.0, 0.1, 3),
                         sharding=sharding)  # fmt: skip
    lengths = jax.device_put(np.array([1.0, 2.0]), sharding)
    sharded = run((lengths,))
    alone = simulate_batch(scene, {"length": [1.0, 2.0]}, 0.1, ts=np.linspace(0.0, 0.1, 3))
    np.testing.assert_allclose(np.asarray(sharded.qdd), np.asarray(alone.trajectory.qdd),
                               rtol=1e-12, atol=1e-12)  # fmt: skip


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


def test_vmapped_batches_run_generalized_alpha_with_newtons_method_proper():
    """Generalized-α by name becomes Newton proper in a vmapped batch (`vmapped_control`); a
    solver object and the index-1 solvers are left as given."""
    from jaxdeploy.batch import vmapped_control
    from jaxdeploy.solvers import GeneralizedAlpha, StepControl

    control = vmapped_control(StepControl(rtol=1e-6, atol=1e-9))
    assert control.solver == GeneralizedAlpha(newton="full")
    assert (control.rtol, control.atol) == (1e-6, 1e-9)
    given = StepControl(GeneralizedAlpha(rho_inf=0.5), dt=1e-3)
    assert vmapped_control(given) is given
    assert vmapped_control(StepControl("tsit5", rtol=1e-6)).solver == "tsit5"
    # An automatic choice that resolves to generalized-α too; one that resolves to a
    # Runge-Kutta method (slider_crank's default, or a tight tolerance) is left alone.
    from jaxdeploy.scenes import SliderCrank

    loose = StepControl("auto:generalized_alpha", rtol=1e-6, atol=1e-9)
    assert vmapped_control(loose).solver == GeneralizedAlpha(newton="full")
    default = SliderCrank.default_control
    assert vmapped_control(default) is default
    tight = loose.replace(rtol=1e-12, atol=1e-15)
    assert vmapped_control(tight) is tight


@pytest.mark.slow  # ~2 min under load (two compilations of slider_crank)
def test_slider_crank_batch_is_as_accurate_as_its_cases_run_one_at_a_time():
    """A vmapped batch of slider_crank (adaptive generalized-α through the first impacts of
    its clearance joint) against its cases run alone with the scene's default step control.
    They cannot agree bit for bit: XLA rounds a batched operation differently, the batch runs
    Newton proper (`vmapped_control`), and round-off flips a few step decisions in contact.
    What must hold is that the batch is as accurate: measured against a run 1000× tighter,
    its error is within a small factor of the single run's own."""
    from jaxdeploy.scenes import SliderCrank

    scene = SliderCrank()
    t_end = 1.5e-3
    cases = {"restitution": [0.8, 0.9, 0.99]}
    # generalized-α chosen by name (no longer the scene's default), so the batch runs Newton
    # proper (`vmapped_control`) where the single runs keep modified Newton.
    control = scene.default_control.replace(solver="generalized_alpha")
    batch = simulate_batch(scene, cases, t_end, n_save=31, control=control)
    assert list(batch.ok) == [True] * 3
    tight = control.replace(rtol=1e-9, atol=1e-12)
    for i in range(3):
        params = batch.case_params(i)
        single = run_scene(scene, params, t_end, n_save=31, control=control)
        reference = run_scene(scene, params, t_end, n_save=31, control=tight)
        err_single = float(np.max(np.abs(single.q - reference.q)))
        err_batch = float(np.max(np.abs(batch.case(i).q - reference.q)))
        assert err_batch <= 3.0 * err_single, (i, err_batch, err_single)
    # The cases really differ (the restitution reached the motion).
    assert not np.allclose(batch.case(0).v, batch.case(2).v, rtol=0, atol=1e-6)
