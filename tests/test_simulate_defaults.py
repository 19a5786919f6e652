"""`simulate` without a step control: the default chosen from the mechanism, what is recorded,
and the warning for a step control measured to be less accurate (issue 31, Deliver 1)."""

import warnings

import jax.numpy as jnp
import pytest

from jaxdeploy import (
    Body,
    Gravity,
    Mechanism,
    Revolute,
    RevoluteClearance,
    StepControl,
    consistent_state,
    contact,
    get_scene,
)
from jaxdeploy.simulation import prepare
from jaxdeploy.solvers import SolverChoiceWarning, default_control, solver_advice
from jaxdeploy.solvers.step_control import (
    CLEARANCE_DEFAULT,
    SMOOTH_DEFAULT,
    scene_default_choice,
)

LENGTH = 0.4


def _rod(pivot):
    rod = Body("rod", 0.5, 0.5 * LENGTH**2 / 12, {"pin": (-LENGTH / 2, 0.0)})
    gravity = Gravity(jnp.array([0.0, -9.81]))
    return Mechanism([rod], [pivot, gravity], ground_points={"O": (0.0, 0.0)})


def _clearance_pendulum():
    law = contact.LankaraniNikravesh(elastic=contact.HertzElastic(7.7e10), restitution=0.8)
    pivot = RevoluteClearance(
        "ground", "O", "rod", "pin", clearance=1e-4, journal_radius=5e-3, normal=law
    )
    return _rod(pivot)


def _state(mechanism):
    return consistent_state(mechanism, jnp.array([LENGTH / 2, 0.0, 0.0]))


def test_default_follows_the_mechanism():
    clearance = _clearance_pendulum()
    ideal = _rod(Revolute("ground", "O", "rod", "pin"))
    assert default_control(clearance) == CLEARANCE_DEFAULT
    assert default_control(ideal) == SMOOTH_DEFAULT
    # The Runge–Kutta path with event location, chosen by the tolerance: Dopri8 at rtol 1e-9.
    assert CLEARANCE_DEFAULT.locate_events and CLEARANCE_DEFAULT.solver_name() == "dopri8"
    assert SMOOTH_DEFAULT.solver_name() == "tsit5"


def test_prepare_without_a_step_control_uses_and_records_the_default():
    mechanism = _clearance_pendulum()
    run = prepare(mechanism, _state(mechanism), 0.01)
    assert run.control == CLEARANCE_DEFAULT
    # A solver given alone runs at the default tolerances; a tolerance keeps the old meaning
    # (a StepControl of exactly the keywords given).
    alone = prepare(mechanism, _state(mechanism), 0.01, solver="tsit5")
    assert alone.control == CLEARANCE_DEFAULT.replace(solver="tsit5")
    explicit = prepare(mechanism, _state(mechanism), 0.01, solver="tsit5", rtol=1e-7)
    assert explicit.control == StepControl("tsit5", rtol=1e-7)


@pytest.mark.parametrize(
    "control",
    [StepControl(rtol=1e-6, atol=1e-9), StepControl("generalized_alpha", dt=1e-5)],
)
def test_generalized_alpha_with_clearance_joints_warns_with_the_measured_reason(control):
    mechanism = _clearance_pendulum()
    with pytest.warns(SolverChoiceWarning, match="docs/solver_by_tolerance.md"):
        prepare(mechanism, _state(mechanism), 0.01, control=control)


def test_no_warning_where_generalized_alpha_is_not_known_to_be_worse():
    clearance = _clearance_pendulum()
    ideal = _rod(Revolute("ground", "O", "rod", "pin"))
    assert solver_advice(clearance, StepControl(rtol=1e-13, atol=1e-16)) is None
    assert solver_advice(ideal, StepControl(rtol=1e-6, atol=1e-9)) is None
    assert solver_advice(clearance, StepControl("tsit5", rtol=1e-6)) is None
    with warnings.catch_warnings():
        warnings.simplefilter("error", SolverChoiceWarning)
        prepare(clearance, _state(clearance), 0.01)


def test_a_scenes_own_default_is_not_judged_but_a_changed_one_is():
    scene = get_scene("impact")  # generalized-α at rtol 1e-8, verified on its single impact
    params = scene.resolve_params({})
    mechanism = scene.build(params)
    state = scene.initial_state(params, mechanism)
    default = scene.default_control
    with warnings.catch_warnings():
        warnings.simplefilter("error", SolverChoiceWarning)
        with scene_default_choice(default, default):
            prepare(mechanism, state, 1e-4, control=default)
    looser = default.replace(rtol=1e-6)
    with pytest.warns(SolverChoiceWarning), scene_default_choice(looser, default):
        prepare(mechanism, state, 1e-4, control=looser)
