"""One step-control object (`StepControl`): checked on construction, accepted by `simulate`
and the batch functions, recorded as JSON, the scenes' defaults."""

import json

import numpy as np
import pytest

import jaxdeploy
from jaxdeploy.batch import run_scene, step_control
from jaxdeploy.scenes import SCENES, Pendulum
from jaxdeploy.simulation import simulate
from jaxdeploy.solvers import StepControl


@pytest.mark.parametrize(
    "fields, name",
    [
        ({"rtol": 0.0}, "rtol"),
        ({"rtol": 1.0}, "rtol"),
        ({"rtol": float("nan")}, "rtol"),
        ({"atol": -1e-9}, "atol"),
        ({"dt": 0.0}, "dt"),
        ({"dt": float("inf")}, "dt"),
        ({"rtol": 1e-6, "dt_max": 0.0}, "dt_max"),
        ({"rtol": 1e-6, "dt_min": -1.0}, "dt_min"),
        ({"rtol": 1e-6, "dt_min": 1e-3, "dt_max": 1e-4}, "dt_min"),
        ({"dt": 1e-3, "max_steps": 0}, "max_steps"),
        ({"dt": 1e-3, "max_steps": 2.5}, "max_steps"),
        ({"dt": 1e-3, "locate_events": "yes"}, "locate_events"),
        ({"solver": "rk4", "dt": 1e-3}, "solver"),
    ],
)
def test_invalid_fields_are_refused_naming_the_field(fields, name):
    with pytest.raises(ValueError, match=rf"^{name} = .* is invalid"):
        StepControl(**fields)


def test_neither_fixed_nor_adaptive_is_refused():
    with pytest.raises(ValueError, match="give dt"):
        StepControl()


def test_public_name_and_scene_defaults():
    assert jaxdeploy.StepControl is StepControl
    for cls in SCENES.values():
        assert isinstance(cls.default_control, StepControl), cls.name
    # The defaults are hashable (they key caches) and a variant is one replace away.
    tight = SCENES["slider_crank"].default_control.replace(rtol=1e-10, atol=1e-13)
    assert hash(tight) != hash(SCENES["slider_crank"].default_control)
    assert tight.dt_max == SCENES["slider_crank"].default_control.dt_max


def test_json_round_trip_and_strictness():
    control = StepControl("tsit5", rtol=1e-7, atol=1e-10, dt_max=1e-4, locate_events=False)
    record = json.loads(json.dumps(control.to_json(), allow_nan=False))
    assert record["solver"] == "tsit5" and record["adaptive"] is True
    assert StepControl.from_json(record) == control


def test_step_control_merges_a_mapping_over_the_scene_default():
    scene = SCENES["deploy_array"]()
    merged = step_control(scene, {"rtol": 1e-8})
    assert merged.rtol == 1e-8 and merged.solver == "tsit5" and merged.dt_max == 5e-4
    own = StepControl(dt=1e-5)
    assert step_control(scene, own) is own
    with pytest.raises(ValueError, match="unknown setting.*rtl"):
        step_control(scene, {"rtl": 1e-8})


def test_simulate_takes_the_object_or_its_keywords_not_both():
    scene = Pendulum()
    params = scene.resolve_params()
    mech = scene.build(params)
    state = scene.initial_state(params, mech)
    control = StepControl(dt=2e-3)
    by_object = simulate(mech, state, 0.05, n_save=6, control=control)
    by_keywords = simulate(mech, state, 0.05, n_save=6, **control.settings())
    np.testing.assert_array_equal(np.asarray(by_object.q), np.asarray(by_keywords.q))
    through_scene = run_scene(scene, params, 0.05, n_save=6, control=control)
    np.testing.assert_array_equal(np.asarray(by_object.q), np.asarray(through_scene.q))
    with pytest.raises(ValueError, match="control= and rtol="):
        simulate(mech, state, 0.05, control=control, rtol=1e-6)


def test_the_command_line_group_names_every_solver_and_checks_each_flag(capsys):
    import argparse

    from jaxdeploy.commands._args import add_step_control
    from jaxdeploy.solvers import SOLVER_NAMES

    parser = argparse.ArgumentParser()
    add_step_control(parser)
    text = parser.format_help()
    assert all(name in text for name in SOLVER_NAMES)
    for argv, flag in (
        (["--rtol", "1"], "--rtol"),
        (["--atol", "0"], "--atol"),
        (["--dt-max", "0"], "--dt-max"),
        (["--dt", "nan"], "--dt"),
        (["--solver", "rk4"], "--solver"),
    ):
        with pytest.raises(SystemExit):
            parser.parse_args(argv)
        err = capsys.readouterr().err
        assert f"{flag} = " in err and "invalid" in err or "unknown" in err, err


def test_a_step_control_unpacks_as_its_settings():
    # Code written when scenes' step controls were dicts keeps working.
    control = StepControl("tsit5", rtol=1e-6, atol=1e-9, dt_max=5e-4)
    assert dict(control) == {"solver": "tsit5", "rtol": 1e-6, "atol": 1e-9, "dt_max": 5e-4}
    assert {**control, "rtol": 1e-8}["rtol"] == 1e-8 and control.get("dt") is None
    assert StepControl(**control) == control


def test_auto_chooses_the_method_by_the_tolerance_and_records_it():
    """`"auto"`: Tsit5 from AUTO_TIGHT_RTOL up and for fixed steps, Dopri8 below it;
    `"auto:NAME"` keeps NAME above. The run records the method that ran and the rule that
    chose it, and the record rebuilds the rule (not the method it chose)."""
    from jaxdeploy.solvers.registry import AUTO_TIGHT_RTOL

    assert StepControl("auto", rtol=AUTO_TIGHT_RTOL).solver_name() == "tsit5"
    assert StepControl("auto", rtol=0.5 * AUTO_TIGHT_RTOL).solver_name() == "dopri8"
    assert StepControl("auto", atol=1e-12).solver_name() == "tsit5"  # the controller's rtol 1e-6
    assert StepControl("auto", dt=1e-3).solver_name() == "tsit5"
    loose = StepControl("auto:kvaerno5", rtol=1e-6, atol=1e-9)
    assert loose.solver_name() == "kvaerno5"
    tight = loose.replace(rtol=1e-10, atol=1e-13)
    assert tight.solver_name() == "dopri8" and type(tight.make_solver().solver).__name__ == "Dopri8"
    record = json.loads(json.dumps(tight.to_json(), allow_nan=False))
    assert record["solver"] == "dopri8" and record["solver_rule"].startswith("auto:kvaerno5: ")
    assert StepControl.from_json(record) == tight
    assert StepControl("tsit5", rtol=1e-6).to_json()["solver_rule"] is None
    with pytest.raises(ValueError, match="after 'auto:' give one of"):
        StepControl("auto:rk4", rtol=1e-6)
    with pytest.raises(ValueError, match="after 'auto:' give one of"):
        StepControl("auto:auto", rtol=1e-6)


def test_auto_refuses_a_traced_tolerance():
    import jax

    def build(rtol):
        return StepControl("auto", rtol=rtol).make_solver()

    with pytest.raises(ValueError, match="chooses its method by rtol"):
        jax.jit(lambda r: (build(r), r)[1])(1e-9)


def test_slider_crank_default_runs_tsit5_and_a_tight_one_gets_dopri8():
    """The scene's default (rtol 1e-6) runs Tsit5 (generalized-α, its default before, misses
    impacts of the independent reference at this tolerance: docs/solver_by_tolerance.md); the
    command line's `--rtol 1e-10 --atol 1e-13` (issue 19's check) runs Dopri8 and says so."""
    import argparse

    from jaxdeploy.commands._args import add_step_control
    from jaxdeploy.commands._args import step_control as cli_step_control

    scene = SCENES["slider_crank"]()
    assert scene.default_control.to_json()["solver"] == "tsit5"
    before = StepControl("tsit5", rtol=1e-6, atol=1e-9, dt_max=1e-4)
    assert scene.default_control.make_solver() == before.make_solver()
    parser = argparse.ArgumentParser()
    add_step_control(parser)
    tight = cli_step_control(parser.parse_args(["--rtol", "1e-10", "--atol", "1e-13"]), scene)
    assert tight.to_json()["solver"] == "dopri8"
    forced = ["--rtol", "1e-10", "--atol", "1e-13", "--solver", "generalized_alpha"]
    assert cli_step_control(parser.parse_args(forced), scene).solver_name() == "generalized_alpha"
