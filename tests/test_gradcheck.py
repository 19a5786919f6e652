"""`fit.gradient_check` and `jaxdeploy gradcheck`: the verdict's logic on made-up differences
(cheap), and one real check through the command line on slider_crank's first onset (slow)."""

import json
import math

import pytest

from jaxdeploy.fit._gradcheck import GradientCheck, ParameterCheck, _converged


def _check(ad, replay, switched=()):
    p = ParameterCheck(value=1.0, ad=ad, ad_reverse=None, tolerance=1e-2)
    p.fd = {"replay": dict(replay)}
    p.switched = {"replay": list(switched)}
    p.converged, p.spread, p.converged_kind = _converged(p)
    return p


def test_the_converged_difference_is_the_best_agreeing_unflagged_pair():
    # Truncation error at 1e-2, round-off at 1e-7, a flagged (impact count changed) 1e-3.
    replay = {
        "1e-02": 1.2,
        "1e-03": 7.0,
        "1e-04": 1.0001,
        "1e-05": 1.0,
        "1e-06": 0.9990,
        "1e-07": 0.8,
    }
    p = _check(1.0005, replay, switched=["1e-03"])
    assert p.converged == pytest.approx(1.00005)
    assert p.spread == pytest.approx(1e-4, rel=1e-3)
    assert p.agree
    assert p.agreeing_steps("replay") == ["1e-04", "1e-05", "1e-06"]
    # AD 3 % off the converged difference: disagree, whatever one step says.
    assert not _check(1.03, replay, switched=["1e-03"]).agree
    # Every pair flagged or scattered: no converged difference, never "agree".
    scattered = _check(1.0, {"1e-02": 1.0, "1e-03": 2.0, "1e-04": 3.0})
    assert not scattered.agree and math.isfinite(scattered.converged)
    flagged = _check(1.0, {"1e-02": 1.0, "1e-03": 1.0}, switched=["1e-02", "1e-03"])
    assert not flagged.agree and math.isnan(flagged.converged)


def test_the_json_record_says_what_the_issue_asks_and_is_strict():
    from jaxdeploy.io import strict_json

    p = _check(1.0, {"1e-03": 1.0, "1e-04": 1.0})
    check = GradientCheck("s", "lock_time", 0.5, {"k": p}, (1e-3, 1e-4), 1e-2)
    record = json.loads(strict_json(check.to_json()))
    assert record["verdict"] == "agree"
    assert set(record["params"]["k"]) >= {"ad", "fd", "agree"}
    assert record["params"]["k"]["fd"] == {"1e-03": 1.0, "1e-04": 1.0}


def test_a_step_whose_perturbed_runs_failed_is_reported_and_left_out():
    from jaxdeploy.io import strict_json

    replay = {"1e-02": math.nan, "1e-03": 1.001, "1e-04": 1.0, "1e-05": 1.0002}
    p = _check(1.0, replay)
    p.failed = {"replay": {"1e-02": "failed after t = 0.54 s: non-finite"}}
    assert p.converged == pytest.approx(1.0001) and p.agree
    assert p.agreeing_steps("replay") == ["1e-03", "1e-04", "1e-05"]
    check = GradientCheck("s", "lock_time", 0.5, {"k": p}, (1e-2, 1e-3, 1e-4, 1e-5), 1e-2)
    record = json.loads(strict_json(check.to_json()))  # strict: the NaN is null
    assert record["params"]["k"]["fd"]["1e-02"] is None
    assert record["params"]["k"]["failed_runs"] == p.failed
    assert "replay runs failed at 1e-02" in check.table()
    # Only failed steps: no converged difference, never "agree".
    none = _check(1.0, {"1e-02": math.nan, "1e-03": math.nan})
    assert math.isnan(none.converged) and not none.agree


@pytest.mark.slow  # forward mode at 2+ tolerances and 2 x 2 difference batches of slider_crank
def test_gradcheck_command_on_the_first_onset(tmp_path, capsys):
    from jaxdeploy.cli import main

    out = tmp_path / "check"
    code = main([
        "gradcheck", "slider_crank", "--output", "first_onset_time", "--params", "clearance",
        "--t-end", "2.5e-4", "--steps", "1e-3", "1e-4", "--modes", "forward", "--quiet",
        "--out", str(out),
    ])  # fmt: skip
    printed = capsys.readouterr().out
    assert code == 0, printed
    record = json.loads((out / "gradcheck.json").read_text())
    clearance = record["params"]["clearance"]
    assert record["verdict"] == "agree" and clearance["agree"]
    assert set(clearance["fd"]) == {"1e-03", "1e-04"} and set(clearance["fd_rerun"]) == {
        "1e-03",
        "1e-04",
    }
    assert (out / "gradcheck.png").stat().st_size > 0
    assert "clearance: AD" in printed and "verdict: agree" in printed
    # The step tolerance was checked for the derivative and every run used the one chosen.
    tolerance = record["step_tolerance"]
    assert tolerance["met"] is True and tolerance["checks"][-1]["change"] <= 1e-3
    assert record["step_control"]["rtol"] == tolerance["rtol"]
    assert f"step tolerance: rtol {tolerance['rtol']:.0e}" in printed
    assert "agreeing steps replay" in printed and "rerun" in printed


def test_event_steps_say_in_which_replayed_step_each_event_fell():
    """A replayed pair is flagged when an event changed step: the index of the step (its end in
    the replayed step ends) holding each located event, −1 for one not reached; counts and
    channels are not events."""
    import jax.numpy as jnp
    import numpy as np

    from jaxdeploy.fit._gradcheck import event_steps

    step_ends = np.array([0.1, 0.2, 0.3, np.inf])
    outputs = {
        "lock_time": jnp.asarray(0.15),
        "panel1_onset_times": jnp.array([0.05, 0.2, jnp.nan]),
        "panel1_impacts": jnp.asarray(2.0),
        "alpha": jnp.zeros(3),
    }
    assert np.asarray(event_steps(outputs, step_ends)).tolist() == [1, 0, 1, -1]
