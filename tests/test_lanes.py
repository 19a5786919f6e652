"""Lane-refilled batches (`jaxdeploy.lanes`): each case's result is its result in a plain vmapped
batch (steps, saved states, statuses), however often its lane paused and was refilled."""

import diffrax as dfx
import jax
import numpy as np
import pytest

from jaxdeploy.batch import batch_function, run_scene, simulate_batch
from jaxdeploy.scenes import DeployArray, Pendulum

# Adaptive steps, so that the cases take different numbers of steps.
ADAPTIVE = {"rtol": 1e-7, "atol": 1e-9}
ANGLES = [0.3, -1.2, 2.5, 0.05, -2.9, 1.7, -0.6]
FIELDS = ("ts", "q", "v", "qdd", "lam")


def _assert_same_case(a, b, atol=0.0):
    """Same steps, statuses and counters; saved states equal (to `atol`)."""
    for name in FIELDS:
        np.testing.assert_allclose(getattr(a, name), getattr(b, name), rtol=0, atol=atol)
    for x, y in zip(jax.tree.leaves(a.memory), jax.tree.leaves(b.memory), strict=True):
        np.testing.assert_allclose(x, y, rtol=0, atol=atol)
    assert int(a.result._value) == int(b.result._value)
    for key in b.stats:
        assert int(a.stats[key]) == int(b.stats[key]), key


# One solver per test runs by default (CI budget); the other with -m slow.
@pytest.mark.parametrize(
    "solver", ["tsit5", pytest.param("generalized_alpha", marks=pytest.mark.slow)]
)
def test_pausing_and_resuming_changes_nothing(solver):
    """A case paused every 3 steps and resumed equals, bit for bit, the same case integrated
    in one segment (same lane layout: one lane per case): the step sequence, the saved
    states, the counters continue exactly."""
    scene = Pendulum()
    cases = {"initial_angle": ANGLES}
    options = dict(n_save=21, control=ADAPTIVE, solver=solver, lanes=len(ANGLES))
    whole = simulate_batch(scene, cases, 0.4, segment_steps=100_000, **options)
    paused = simulate_batch(scene, cases, 0.4, segment_steps=3, **options)
    assert int(np.min(whole.trajectory.stats["num_steps"])) > 3 * 3
    for i in range(len(ANGLES)):
        _assert_same_case(paused.case(i), whole.case(i))


@pytest.mark.parametrize(
    "solver", ["generalized_alpha", pytest.param("tsit5", marks=pytest.mark.slow)]
)
def test_refilled_lanes_give_each_case_its_own_run(solver):
    """7 cases in 2 lanes, refilled as they finish, paused every 3 steps: every case takes
    exactly the steps it takes in a plain vmapped batch and alone, and its states agree to
    round-off. (Not bit for bit: XLA's code for a batched operation may round a case
    differently with the batch's layout, e.g. the case's position in it; the pendulum's
    constrained accelerations amplify that last bit ~1e8 times, which alone vs vmapped shows
    just the same.)"""
    scene = Pendulum()
    cases = {"initial_angle": ANGLES}
    options = dict(n_save=21, control=ADAPTIVE, solver=solver)
    plain = simulate_batch(scene, cases, 0.4, **options)
    lanes = simulate_batch(scene, cases, 0.4, lanes=2, segment_steps=3, **options)
    steps = np.asarray(plain.trajectory.stats["num_steps"])
    # The cases differ in steps, so lanes finish at different times and are refilled.
    assert len(set(steps.tolist())) >= 4
    assert list(lanes.ok) == [True] * len(ANGLES)
    for i in range(len(ANGLES)):
        alone = run_scene(scene, plain.case_params(i), 0.4, **options)
        for other in (plain.case(i), alone):
            # Step counts exactly. (Modified Newton's matrix refreshes flip on round-off, so
            # its iteration counts differ by a few per cent, alone vs vmapped just as well.)
            for key in ("num_steps", "num_accepted_steps", "num_rejected_steps"):
                assert int(lanes.case(i).stats[key]) == int(other.stats[key]), key
            np.testing.assert_allclose(lanes.case(i).ts, other.ts, rtol=0, atol=0)
            np.testing.assert_allclose(lanes.case(i).q, other.q, rtol=0, atol=1e-12)
            np.testing.assert_allclose(lanes.case(i).v, other.v, rtol=0, atol=1e-9)
            np.testing.assert_allclose(lanes.case(i).lam, other.lam, rtol=0, atol=1e-5)


def test_lanes_report_failures_per_case():
    """A step budget that some cases exceed: those fail with `max_steps_reached` and keep the
    states they reached, as in a vmapped run; the others are unaffected (1-step segments, so
    the budget is checked after every step, as `simulate` does). Round-off as in
    `test_refilled_lanes_give_each_case_its_own_run`."""
    scene = Pendulum()
    cases = {"initial_angle": ANGLES}
    budget = 350  # the cases take 286-507 steps
    options = dict(n_save=21, control={**ADAPTIVE, "max_steps": budget})
    limited = simulate_batch(scene, cases, 0.4, **options)
    lanes = simulate_batch(scene, cases, 0.4, lanes=3, segment_steps=1, **options)
    assert 0 < int(np.sum(~lanes.ok)) < len(ANGLES)
    for i in range(len(ANGLES)):
        a, b = lanes.case(i), limited.case(i)
        assert int(a.result._value) == int(b.result._value)
        assert int(a.stats["num_steps"]) == int(b.stats["num_steps"])
        np.testing.assert_array_equal(a.ts, b.ts)  # the same times reached (inf: not)
        np.testing.assert_allclose(a.q, b.q, rtol=0, atol=1e-12)
        if not lanes.case(i).ok:
            assert lanes.case(i).result == dfx.RESULTS.max_steps_reached
            assert "failed after t = " in lanes.case(i).status()


@pytest.mark.slow
def test_fixed_step_lanes_run_as_groups():
    """Fixed steps: every case takes the same steps, so lanes are vmapped groups."""
    scene = Pendulum()
    cases = {"initial_angle": ANGLES[:3]}
    plain = simulate_batch(scene, cases, 0.1, n_save=11)
    lanes = simulate_batch(scene, cases, 0.1, n_save=11, lanes=2)
    for i in range(3):
        np.testing.assert_allclose(lanes.case(i).q, plain.case(i).q, rtol=0, atol=1e-14)


def test_bad_lane_settings_are_refused():
    scene, cases = Pendulum(), {"initial_angle": ANGLES[:2]}
    for lanes in (0, -1, 2.5, True):
        with pytest.raises(ValueError, match=r"lanes = .* is invalid"):
            simulate_batch(scene, cases, 0.1, lanes=lanes)
    with pytest.raises(ValueError, match=r"segment_steps = 0 is invalid"):
        simulate_batch(scene, cases, 0.1, lanes=2, segment_steps=0)
    with pytest.raises(ValueError, match="give one batch policy"):
        simulate_batch(scene, cases, 0.1, lanes=2, group_size=2)
    with pytest.raises(ValueError, match="replay_steps are not supported"):
        simulate_batch(scene, cases, 0.1, lanes=2, control=ADAPTIVE, replay_steps=True)


@pytest.mark.slow
def test_deploy_array_tsit5_lanes():
    """The scene the policy is for (contact, event location, projection), Tsit5 over 2 ms, 6
    cases: paused every 4 steps equals one segment bit for bit (one lane per case); refilled
    in 2 lanes, every case succeeds and stays within 1e-8 m of its plain vmapped run (its
    last-bit differences grow in the contacts, but stay far below the step control's
    tolerance, rtol 1e-6)."""
    scene = DeployArray()
    rng = np.random.default_rng(0)
    defaults = scene.default_params()
    names = ("panel1_ra", "panel2_clearance")
    cases = {k: defaults[k] * np.exp(0.1 * rng.standard_normal(6)) for k in names}
    options = dict(n_save=5, solver="tsit5")
    whole = simulate_batch(scene, cases, 0.002, lanes=6, segment_steps=100_000, **options)
    paused = simulate_batch(scene, cases, 0.002, lanes=6, segment_steps=4, **options)
    plain = simulate_batch(scene, cases, 0.002, **options)
    refilled = simulate_batch(scene, cases, 0.002, lanes=2, segment_steps=4, **options)
    assert list(refilled.ok) == [True] * 6
    for i in range(6):
        _assert_same_case(paused.case(i), whole.case(i))
        np.testing.assert_allclose(refilled.case(i).q, plain.case(i).q, rtol=0, atol=1e-8)


def test_batch_function_lanes_with_features():
    """`evaluate` runs per case on the lanes' trajectories."""
    scene = Pendulum()
    run = batch_function(
        scene,
        ("initial_angle",),
        scene.resolve_params(),
        0.2,
        np.linspace(0.0, 0.2, 5),
        control=ADAPTIVE,
        evaluate=lambda params, tr: {"last": tr.q[-1, 2], "angle": params["initial_angle"]},
        lanes=2,
    )
    angles = np.array(ANGLES[:3])
    trajectory, features = run((angles,))
    np.testing.assert_array_equal(features["angle"], angles)
    np.testing.assert_array_equal(features["last"], trajectory.q[:, -1, 2])
