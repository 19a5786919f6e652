"""`jaxdeploy.robustness`: the checks of docs/robustness.md on a case with known answers."""

import jax.numpy as jnp
import numpy as np
import pytest

from jaxdeploy import Impact, StepControl
from jaxdeploy.robustness import check_run, comparison_solver, relative_difference


def test_relative_difference_scales_each_output_by_its_own_scale():
    # Two outputs over three saved times; output 0 scale 10, output 1 scale 0.1.
    values = np.array([[1.0, 2.0, 3.0], [0.0, 0.0, 0.02]])
    reference = np.array([[1.0, 2.5, 3.0], [0.0, 0.0, 0.0]])
    assert relative_difference(values, reference, np.array([10.0, 0.1])) == pytest.approx(0.2)
    assert relative_difference(values[0], reference[0], 5.0) == pytest.approx(0.1)


def test_comparison_solver_is_the_other_formulation():
    assert comparison_solver(StepControl(rtol=1e-6, atol=1e-9)) == "kvaerno5"  # generalized-α
    assert comparison_solver(StepControl(solver="tsit5", rtol=1e-6)) == "generalized_alpha"


@pytest.mark.slow
def test_check_run_on_an_elastic_impact():
    """The `impact` scene with the undamped Hertz law (1 kg at 1 m/s into a wall 0.1 mm away,
    no gravity): nothing dissipates, so the energy balance closes to the integration error,
    the journal rebounds at v0 (Johnson 1985, ch. 11), the tighter run and generalized-α agree
    with Tsit5, and the derivative through the contact onset is finite."""
    scene = Impact(damping="none")
    params = scene.resolve_params()
    control = StepControl(solver="tsit5", rtol=1e-9, atol=1e-14, dt_max=1e-6)

    def outputs(traj):
        return jnp.stack([traj.q[-1, 0], traj.v[-1, 0]])

    def scale(traj):
        return jnp.stack([jnp.max(jnp.abs(traj.q[:, 0])), jnp.max(jnp.abs(traj.v[:, 0]))])

    r = check_run(scene, params, scene.default_t_end, control, outputs, scale, n_save=61)
    assert r["status"] == "ok" and r["finite"] and r["ref_status"] == "ok"
    assert r["steps"] > 0 and 0 < r["min_step"] <= r["max_step"] <= 1e-6 * (1 + 1e-12)
    assert r["energy_moved_J"] == pytest.approx(0.5, rel=1e-6)  # ½ m v0², all of it moving
    assert r["energy_residual_rel"] < 1e-6
    assert abs(r["dissipated_J"]) < 1e-15 and r["injected_J"] == 0.0  # round-off of 0.5 J
    assert r["ref_difference_rel"] < 1e-6
    other = r["other_solver"]
    assert other["solver"] == "generalized_alpha" and other["status"] == "ok"
    assert other["difference_rel"] < 1e-2
    assert r["gradient_finite"] and r["gradient_max_abs"] > 0
