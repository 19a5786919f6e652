"""`fit.converged_tolerance`: the loosest rtol at which a derivative changes by at most a
fraction at rtol/10, on made-up derivatives whose tolerance error is known (cheap)."""

import math

import pytest

from jaxdeploy.fit import RTOL_FLOOR, converged_tolerance
from jaxdeploy.solvers import StepControl


def _derivatives(error_per_rtol):
    """`evaluate(control)`: a derivative 2.0 (and −3.0) off by `error_per_rtol · rtol`
    (relative), the first-order convergence of a derivative whose events sit at step ends,
    with the rtols asked for recorded."""
    asked = []

    def evaluate(control):
        asked.append(control.rtol)
        e = error_per_rtol * (control.rtol or 0.0)
        return {"k": 2.0 * (1 + e), "c": -3.0 * (1 - 2 * e)}

    return evaluate, asked


def test_the_loosest_tolerance_whose_derivative_is_converged_is_chosen():
    # Relative error 8e3·rtol in k, 1.6e4·rtol in c (the larger): 1.6e-2 at 1e-6, 1.6e-3 at
    # 1e-7, 1.6e-4 at 1e-8. The change rtol → rtol/10 is 0.9 of the looser error (relative
    # to the tighter value): 1.44e-2, 1.44e-3, 1.44e-4: > 1e-3, > 1e-3, ≤ 1e-3 → rtol 1e-8.
    evaluate, asked = _derivatives(8e3)
    control = StepControl("tsit5", rtol=1e-6, atol=1e-9)
    said = []
    found = converged_tolerance(evaluate, control, fraction=1e-3, progress=said.append)
    assert "rtol 1e-07 → 1e-08: derivatives changed by 1.4e-03 (limit 1e-03)" in said
    assert found.met is True
    assert found.rtol == pytest.approx(1e-8) and found.control.atol == pytest.approx(1e-11)
    assert asked == pytest.approx([1e-6, 1e-7, 1e-8, 1e-9])
    changes = [c["change"] for c in found.checks]
    e = [8e-3 * 10.0**-k for k in range(4)]
    expected = [2 * (e[k] - e[k + 1]) / (1 - 2 * e[k + 1]) for k in range(3)]
    assert changes == pytest.approx(expected, rel=1e-9)
    assert found.derivatives == evaluate(found.control)
    record = found.to_json()
    assert record["rtol"] == found.rtol and record["met"] and len(record["checks"]) == 3
    assert "rtol 1e-08" in found.summary() and "converged" in found.summary()


def test_a_derivative_that_never_settles_is_reported_not_converged():
    # The floor stops the search; the result says so rather than passing.
    evaluate, _ = _derivatives(1e9)
    found = converged_tolerance(evaluate, StepControl("tsit5", rtol=1e-8, atol=1e-11))
    assert found.met is False and found.rtol == pytest.approx(RTOL_FLOOR)
    assert "NOT converged" in found.summary()
    # A derivative that is NaN at the tighter tolerance is not converged either.
    found = converged_tolerance(
        lambda c: {"k": 1.0 if c.rtol > 1e-7 else math.nan},
        StepControl("tsit5", rtol=1e-6, atol=1e-9),
    )
    assert found.met is False and math.isnan(found.checks[-1]["change"])


def test_fixed_steps_and_a_bad_fraction():
    evaluate, asked = _derivatives(1.0)
    found = converged_tolerance(evaluate, StepControl("tsit5", dt=1e-4))
    assert found.met is None and asked == [None] and "not checked" in found.summary()
    with pytest.raises(ValueError, match="fraction"):
        converged_tolerance(evaluate, StepControl("tsit5", rtol=1e-6), fraction=0.0)


def test_tolerances_are_data_of_one_derivative_program():
    """`fit.gradient_at_tolerances` (what `derivative_tolerance` searches with): controls that
    differ only in rtol and atol run one compiled derivative program, give the derivative of
    `parameter_gradient` at that control, and each its own (the tolerance is not frozen into
    the program at its first value). Pendulum with adaptive Tsit5 steps (cheap)."""
    import jax.numpy as jnp

    from jaxdeploy.fit import gradient_at_tolerances, parameter_gradient
    from jaxdeploy.scenes import Pendulum

    scene = Pendulum()
    params = scene.resolve_params({"initial_angle": -0.4})

    def loss(outputs):
        return jnp.sum(outputs["rod_theta"] ** 2)

    options = dict(n_save=11, mode="forward")
    evaluate = gradient_at_tolerances(scene, params, ["length"], loss, 0.4, **options)
    loose, tight = (StepControl("tsit5", rtol=r, atol=1e-3 * r) for r in (1e-3, 1e-5))
    value_loose, grad_loose = evaluate(loose)
    value_tight, grad_tight = evaluate(tight)
    assert len(evaluate.programs) == 1
    assert next(iter(evaluate.programs.values()))._cache_size() == 1
    reference = parameter_gradient(scene, params, ["length"], loss, 0.4, control=tight, **options)
    assert float(value_tight) == pytest.approx(float(reference[0]), rel=1e-13)
    assert float(grad_tight["length"]) == pytest.approx(float(reference[1]["length"]), rel=1e-12)
    # The loose run's derivative is its own: off the tight one by its tolerance error.
    change = abs(float(grad_loose["length"]) / float(grad_tight["length"]) - 1)
    assert 1e-9 < change < 1e-1
