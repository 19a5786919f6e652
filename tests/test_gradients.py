"""Derivatives of simulation outputs with respect to contact parameters, reverse mode
(checkpointed) and forward mode through the generalized-α solver, against central finite
differences. Fixed steps, so AD and the differences differentiate the same discrete map; short
windows through one or two impacts, where pointwise derivatives are meaningful (how they
degrade over many impacts: docs/identification.md)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxdeploy.batch import simulate_batch
from jaxdeploy.fit import output_function, parameter_jacobian
from jaxdeploy.scenes import DeployArray, Impact, SliderCrank

FIXED = {"rtol": None, "atol": None, "dt_max": None}


def central_differences(scene, base, wrt, output, t_end, ts, control, rel_step):
    """(f(θ + h e_k) − f(θ − h e_k)) / 2h for each parameter, all 2p runs as one batch;
    `rel_step`: h/|θ|, one number or `{name: h/|θ|}`."""
    steps = rel_step if isinstance(rel_step, dict) else dict.fromkeys(wrt, rel_step)
    cases = []
    for name in wrt:
        h = steps[name] * abs(base[name])
        cases += [{**base, name: base[name] + h}, {**base, name: base[name] - h}]
    batch = simulate_batch(scene, cases, t_end, ts=ts, control=control)
    assert all(batch.ok), batch.statuses()
    values = [
        np.asarray(output(scene.channels(batch.mechanism(i), batch.case(i))))
        for i in range(batch.size)
    ]
    return {
        name: (values[2 * k] - values[2 * k + 1]) / (2 * steps[name] * abs(base[name]))
        for k, name in enumerate(wrt)
    }


def test_impact_forward_and_reverse_mode_match_central_differences():
    """Journal position and acceleration at times through a rough, damped impact: d/d
    (clearance c, roughness σ, restitution c_e, stiffness K), vector output."""
    scene = Impact(damping="lankarani_nikravesh")
    base = scene.resolve_params(
        {"impact_speed": 0.5, "clearance": 2e-5, "sigma": 1e-7, "restitution": 0.7}
    )
    wrt = ["clearance", "sigma", "restitution", "stiffness"]
    t_end = 2.5e-4
    ts = jnp.linspace(0.0, t_end, 11)
    control = {**FIXED, "dt": 5e-7}

    def output(ch):
        return jnp.concatenate([ch["journal_x"][4:], 1e-6 * ch["journal_ax"][4:]])

    rev = parameter_jacobian(scene, base, wrt, output, t_end, ts=ts, control=control)
    fwd = parameter_jacobian(
        scene, base, wrt, output, t_end, mode="forward", ts=ts, control=control
    )
    fd = central_differences(scene, base, wrt, output, t_end, ts, control, 1e-4)
    for name in wrt:
        scale = np.abs(fd[name]).max()
        assert scale > 0, name
        np.testing.assert_allclose(rev[name], fd[name], rtol=0, atol=1e-4 * scale, err_msg=name)
        np.testing.assert_allclose(fwd[name], rev[name], rtol=0, atol=1e-10 * scale, err_msg=name)


@pytest.mark.slow  # two slider-crank compilations: ~80 s on a quiet 2-core machine
def test_slider_crank_reverse_mode_matches_central_differences():
    """Slider-crank through its first impact (~0.25 ms): the rod and slider motion w.r.t.
    c, σ, c_e, μ and E (reverse mode, one compiled Jacobian of a vector output)."""
    scene = SliderCrank()
    base = scene.resolve_params({"sigma": 1e-6, "friction_coefficient": 0.05})
    wrt = ["clearance", "sigma", "restitution", "friction_coefficient", "youngs_modulus"]
    t_end = 5e-4
    ts = jnp.linspace(0.0, t_end, 11)
    control = {**FIXED, "dt": 5e-7}

    def output(ch):
        return jnp.concatenate(
            [ch["slider_x"][5:] - ch["crank_x"][5:], 1e-3 * ch["rod_theta"][5:],
             1e-5 * ch["slider_ax"][5:]]
        )  # fmt: skip

    rev = parameter_jacobian(scene, base, wrt, output, t_end, ts=ts, control=control)
    # Steps chosen where the differences are converged (checked over 1e-2 ... 1e-6): σ moves
    # the force so little that steps below 1e-2 σ drown in the Newton-tolerance noise; the
    # contact onset bends the map in c at 1e-3 c.
    steps = {"clearance": 1e-4, "sigma": 1e-2, "restitution": 1e-4,
             "friction_coefficient": 1e-3, "youngs_modulus": 1e-4}  # fmt: skip
    fd = central_differences(scene, base, wrt, output, t_end, ts, control, steps)
    for name in wrt:
        scale = np.abs(fd[name]).max()
        assert scale > 0, name
        np.testing.assert_allclose(rev[name], fd[name], rtol=0, atol=1e-4 * scale, err_msg=name)


@pytest.mark.slow
def test_deploy_array_reverse_and_forward_match_central_differences():
    """deploy_array over its first hinge impacts (0–30 ms): tip acceleration and deployment
    angle w.r.t. Ra, c (both hinges), c_e, μ and E."""
    scene = DeployArray()
    base = scene.resolve_params()
    wrt = ["panel1_ra", "panel1_clearance", "panel2_clearance", "restitution",
           "friction_coefficient", "youngs_modulus"]  # fmt: skip
    t_end = 0.03
    ts = jnp.linspace(0.0, t_end, 16)
    control = {**FIXED, "dt": 2e-5}

    def output(ch):
        return jnp.concatenate([ch["panel2_tip_ay"][5:], 1e3 * ch["alpha"][5:]])

    rev = parameter_jacobian(scene, base, wrt, output, t_end, ts=ts, control=control)
    fwd = parameter_jacobian(
        scene, base, wrt, output, t_end, mode="forward", ts=ts, control=control
    )
    fd = central_differences(scene, base, wrt, output, t_end, ts, control, 1e-5)
    for name in wrt:
        scale = np.abs(fd[name]).max()
        assert scale > 0, name
        np.testing.assert_allclose(rev[name], fd[name], rtol=0, atol=1e-4 * scale, err_msg=name)
        np.testing.assert_allclose(fwd[name], rev[name], rtol=0, atol=1e-9 * scale, err_msg=name)


@pytest.mark.slow
def test_scalar_loss_gradient_is_the_jacobian_contracted():
    """`output_function` gives a pure function: jax.grad of a scalar loss equals the
    contraction of the forward-mode Jacobian (two different AD paths, same numbers)."""
    scene = Impact(damping="hunt_crossley")
    base = scene.resolve_params({"impact_speed": 0.5, "clearance": 2e-5})
    ts = jnp.linspace(0.0, 2e-4, 5)
    control = {**FIXED, "dt": 1e-6}
    weights = jnp.array([0.0, 1.0, 2.0, 3.0, 4.0])

    def output(ch):
        return ch["journal_x"]

    f, x0 = output_function(scene, base, ["restitution"], output, 2e-4, ts=ts, control=control)
    grad = jax.grad(lambda x: jnp.dot(weights, f(x)))(x0)["restitution"]
    jac = parameter_jacobian(
        scene, base, ["restitution"], output, 2e-4, mode="forward", ts=ts, control=control
    )["restitution"]
    np.testing.assert_allclose(grad, jnp.dot(weights, jac), rtol=1e-10)
