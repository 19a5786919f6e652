"""Derivatives of simulation outputs with respect to contact parameters, reverse mode
(checkpointed) and forward mode through the generalized-α solver, against central finite
differences. Fixed steps, or adaptive steps replayed (`replay_steps`: the differentiated run
and every finite-difference run step over the unperturbed run's accepted steps), so AD and
the differences differentiate the same discrete map; short windows through one or a few
impacts, where pointwise derivatives are meaningful (how they degrade over many impacts:
docs/identification.md)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _derivative_helpers import jacobian_and_differences

from jaxdeploy.fit import central_differences as fit_central_differences
from jaxdeploy.fit import output_function, parameter_jacobian
from jaxdeploy.scenes import Impact, SliderCrank

FIXED = {"rtol": None, "atol": None, "dt_max": None}


def _impact_case():
    """A rough, damped impact (scene, parameters, the four differentiated parameter names,
    t_end, save times) and its output: journal position and scaled acceleration at the
    saved times through the impact."""
    scene = Impact(damping="lankarani_nikravesh")
    base = scene.resolve_params(
        {"impact_speed": 0.5, "clearance": 2e-5, "sigma": 1e-7, "restitution": 0.7}
    )
    wrt = ["clearance", "sigma", "restitution", "stiffness"]
    t_end = 2.5e-4

    def output(ch):
        return jnp.concatenate([ch["journal_x"][4:], 1e-6 * ch["journal_ax"][4:]])

    return scene, base, wrt, t_end, jnp.linspace(0.0, t_end, 11), output


def central_differences(scene, base, wrt, output, t_end, ts, control, rel_step):
    return fit_central_differences(
        scene, base, wrt, output, t_end, rel_step, ts=ts, control=control
    )


@pytest.mark.slow  # 81 s on a 2-core machine (f838811), the longest of the quick set: make test
def test_impact_forward_and_reverse_mode_match_central_differences():
    """Journal position and acceleration at times through a rough, damped impact: d/d
    (clearance c, roughness σ, restitution c_e, stiffness K), vector output."""
    scene, base, wrt, t_end, ts, output = _impact_case()
    control = {**FIXED, "dt": 5e-7}

    rev = parameter_jacobian(scene, base, wrt, output, t_end, ts=ts, control=control)
    # Forward mode and the run's outputs from one compiled program (`has_aux`: the primal
    # outputs of the same pass), evaluated at θ for the Jacobian and at θ ± h e_k for the
    # central differences (h = 1e-4 θ_k), instead of compiling a separate batch of plain runs.
    f, x0 = output_function(scene, base, wrt, output, t_end, mode="forward", ts=ts, control=control)

    def value_twice(x):
        y = f(x)
        return y, y

    jacobian_and_value = jax.jit(jax.jacfwd(value_twice, has_aux=True))
    fwd, _ = jacobian_and_value(x0)
    fd = {}
    for name in wrt:
        h = 1e-4 * abs(x0[name])
        _, plus = jacobian_and_value({**x0, name: x0[name] + h})
        _, minus = jacobian_and_value({**x0, name: x0[name] - h})
        fd[name] = (np.asarray(plus) - np.asarray(minus)) / (2 * h)
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
    grad = jax.jit(jax.grad(lambda x: jnp.dot(weights, f(x))))(x0)["restitution"]
    jac = parameter_jacobian(
        scene, base, ["restitution"], output, 2e-4, mode="forward", ts=ts, control=control
    )["restitution"]
    np.testing.assert_allclose(grad, jnp.dot(weights, jac), rtol=1e-10)


@pytest.mark.slow
def test_impact_adaptive_steps_replayed_match_central_differences():
    """Adaptive steps (the impact scene's default control), replayed: forward mode through the
    run over the unperturbed run's accepted steps matches central differences over the same
    steps. The differences' runs are the primal outputs of the forward-mode program at θ ± h
    (one compilation, no separate batch). That forward and reverse mode of this replayed run
    agree to round-off is checked by test_gradient_function_forward_equals_reverse_to_roundoff
    (same impact, same replay), and their independence of the checkpoint count on a full
    slider-crank revolution by the slow test below."""
    scene, base, wrt, t_end, ts, output = _impact_case()
    # Adaptive steps end just past the contact onset (`LocateEvents`: 1e-3 of the step, ~1 ns
    # here). A relative change of 1e-4 in c moves the onset by Δc/v ≈ 4 ns, across that step
    # end, and the difference then straddles two discrete maps; 1e-6 stays inside one. The
    # other parameters keep 1e-4: at 1e-6, σ (0.1 µm) would move the outputs by ~1e-14 m,
    # below the Newton tolerance.
    steps = {name: 1e-6 if name == "clearance" else 1e-4 for name in wrt}
    fwd, fd = jacobian_and_differences(scene, base, wrt, output, t_end, steps, ts=ts)
    for name in wrt:
        scale = np.abs(fd[name]).max()
        assert scale > 0, name
        np.testing.assert_allclose(fwd[name], fd[name], rtol=0, atol=1e-5 * scale, err_msg=name)


# Forward against reverse mode on one slider-crank revolution, what agreement can mean.
# Over the same steps the two modes differentiate the same discrete map in different
# operation orders, so they differ by round-off times the derivative's conditioning, and both
# depend on the instruction set XLA compiles for. Measured at this test's setting (its own
# step times given to both modes, c_e = 0.9, rows relative):
# * AVX-512 (this project's machines): the modes differ by 8.0e-10 and 2.1e-9 at 1.2 and
#   2.4 ms, up to 2.0e-6 over the revolution; the forward program itself, at c_e(1 ± 1e-14),
#   moves the same rows by 7.0e-11 / 6.2e-11 and up to 5.3e-6.
# * AVX2 (`XLA_FLAGS=--xla_cpu_max_isa=AVX2`): the modes agree to 1e-10 at 1.2 and 2.4 ms.
# * SSE4.2: another step sequence, far worse conditioned: the modes differ by 1.9e-11 and
#   2.9e-6 at 1.2 and 2.4 ms and up to 2.0e-3 later, the forward program at c_e(1 ± 1e-14)
#   moves the same rows by 1.7e-9 / 3.6e-6 and up to 3.6e-3.
# The first bound, 1e-10 (one AVX2 build's round-off), failed on AVX-512 (2.1e-9): a bound
# set on one build's round-off cannot hold. So the bound of each row is measured here, on
# the build that runs: twice the larger move of that row under c_e(1 ± 1e-14) (a perturbation
# of ~90 ulp, the scale of the round-off the two orders accumulate), and no tighter than
# MODES_AGREE_FLOOR, 5x the largest difference measured where the derivative is well
# conditioned (AVX-512's 2.1e-9 at 2.4 ms; the input perturbation moves that row by 34x
# less: there the two orders' own rounding dominates, not the input's).
# What the test is for: decided separately, the modes differentiated different step
# sequences and differed by 1-3 % (before replayed steps). The steps are decided once here,
# by `replayed_step_times`, and given to every program as data: `parameter_jacobian`'s own
# `replay_steps=True` decides them inside each differentiated program, whose fusion differs
# between the modes, and on SSE4.2 that flipped a decision (the modes then differed by
# 1.1e-4 at 2.4 ms, against 2.9e-6 over shared steps: a defect of `parameter_jacobian`).
# Reverse mode with 7 checkpoints recomputes the primal between them inside the backward
# pass, a program compiled apart from the forward one, whose round-off perturbs the
# trajectory at each recomputed step, where the input probe perturbs it at t = 0 only: its
# bound is RECOMPUTED_FACTOR times the probe's. Measured on AVX-512 (rows relative, the
# largest (reverse − forward)/probe move): default checkpoints 34 before the first impact
# (under the floor) and 0.8 after it, 7 checkpoints 0.81 after it, with the Schur complement
# solves differentiated through their Cholesky factor (the derivative of the computed map);
# with the solves differentiated implicitly (`saddle_point.schur_system_solve`, 2026-12-07)
# 0.61 and 2.74 (at 3.6 ms, right after the first impacts, where the input moves the row
# 30x less than later ones), while the largest relative difference over the revolution fell
# from 1.1e-6 to 6.4e-7.
MODES_AGREE_FLOOR = 1e-8
CONDITIONING_PROBE = 1e-14
RECOMPUTED_FACTOR = 5


@pytest.mark.slow  # a primal, a forward and two reverse compilations: ~100 CPU-s
def test_slider_crank_adaptive_derivative_independent_of_mode_and_checkpoints():
    """One crank revolution (12 ms, ~800 adaptive steps, many impacts), over steps decided
    once: forward mode and reverse mode with default and with 7 checkpoints differentiate the
    same discrete map and agree, row by row, to the round-off of its derivative: twice the
    move of the row when c_e is perturbed by 1e-14 relative (RECOMPUTED_FACTOR times that
    with 7 checkpoints), and no tighter than MODES_AGREE_FLOOR (the comments above: measured
    on three instruction sets)."""
    import diffrax as dfx

    from jaxdeploy.fit._derivatives import replayed_step_times

    scene = SliderCrank()
    base = scene.resolve_params({"sigma": 1e-6, "friction_coefficient": 0.05})
    t_end = 0.012
    ts = jnp.linspace(0.0, t_end, 11)

    def output(ch):
        return jnp.concatenate([ch["slider_x"][1:] - ch["crank_x"][1:], 1e-3 * ch["rod_theta"][1:]])

    wrt = ["restitution"]
    times = replayed_step_times(scene, base, t_end, ts=ts)
    options = dict(ts=ts, replay_steps=times)
    f, x0 = output_function(scene, base, wrt, output, t_end, mode="forward", **options)
    derivative = jax.jit(jax.jacfwd(f))
    fwd = np.asarray(derivative(x0)["restitution"])
    assert np.abs(fwd).max() > 0
    c_e = x0["restitution"]
    moves = [
        np.abs(np.asarray(derivative({"restitution": c_e * (1 + e)})["restitution"]) - fwd)
        for e in (CONDITIONING_PROBE, -CONDITIONING_PROBE)
    ]
    floor = MODES_AGREE_FLOOR * np.abs(fwd)
    for checkpoints, factor in ((None, 2), (7, 2 * RECOMPUTED_FACTOR)):
        bound = np.maximum(factor * np.maximum(*moves), floor)
        rev = parameter_jacobian(
            scene, base, wrt, output, t_end, **options,
            adjoint=dfx.RecursiveCheckpointAdjoint(checkpoints=checkpoints),
        )  # fmt: skip
        rev = np.asarray(rev["restitution"])
        assert np.all(np.abs(rev - fwd) <= bound), (checkpoints, np.abs(rev - fwd) / bound)


@pytest.mark.slow
def test_slider_crank_adaptive_matches_central_differences():
    """Slider-crank, adaptive steps (scene default rtol 1e-6), through its first impact:
    w.r.t. c, σ, c_e, μ and E, forward mode against central differences over the same steps
    (the differences' runs from the same compiled program). Reverse mode on this scene: against
    differences at fixed steps (test_slider_crank_reverse_mode_matches_central_differences),
    and equal to forward mode on replayed adaptive steps over a revolution (the test above)."""
    scene = SliderCrank()
    base = scene.resolve_params({"sigma": 1e-6, "friction_coefficient": 0.05})
    wrt = ["clearance", "sigma", "restitution", "friction_coefficient", "youngs_modulus"]
    t_end = 5e-4
    ts = jnp.linspace(0.0, t_end, 11)

    def output(ch):
        return jnp.concatenate(
            [ch["slider_x"][5:] - ch["crank_x"][5:], 1e-3 * ch["rod_theta"][5:],
             1e-5 * ch["slider_ax"][5:]]
        )  # fmt: skip

    steps = {"clearance": 1e-4, "sigma": 1e-2, "restitution": 1e-4,
             "friction_coefficient": 1e-3, "youngs_modulus": 1e-4}  # fmt: skip
    fwd, fd = jacobian_and_differences(scene, base, wrt, output, t_end, steps, ts=ts)
    for name in wrt:
        scale = np.abs(fd[name]).max()
        assert scale > 0, name
        np.testing.assert_allclose(fwd[name], fd[name], rtol=0, atol=1e-4 * scale, err_msg=name)


@pytest.mark.slow  # minutes of reverse-mode compilation; the default suite checks the Kvaerno
# path's gradient against differences in test_diffrax_path.py (Kvaerno3, reverse mode).
def test_impact_diffrax_path_kvaerno5_matches_central_differences():
    """The index-1 ODE path (`solver="kvaerno5"`, fixed step; its stage equations then solved
    to 1e-10/1e-12) through a rough, damped impact: reverse mode matches central
    differences. (Independence of the checkpoint count is tested on generalized-α above; a
    second reverse-mode Kvaerno5 program here cost minutes of compilation. Forward mode does
    not go through diffrax's implicit solvers: their stage solve is a `custom_vjp`. Replayed
    adaptive steps are not used here: at the controller's tolerances the perturbed replays'
    Chord iteration fails to converge at the contact onset.)"""
    scene, base, wrt, t_end, ts, output = _impact_case()
    control = {**FIXED, "dt": 5e-7}

    # The differences' runs are the primal outputs of the reverse-mode program at θ ± h.
    rev, fd = jacobian_and_differences(
        scene, base, wrt, output, t_end, 1e-4, ts=ts, control=control, mode="reverse",
        solver="kvaerno5",
    )  # fmt: skip
    for name in wrt:
        scale = np.abs(fd[name]).max()
        assert scale > 0, name
        np.testing.assert_allclose(rev[name], fd[name], rtol=0, atol=1e-4 * scale, err_msg=name)


def test_gradient_mode_rule_and_bad_input():
    """`mode="auto"` is forward mode up to FORWARD_MODE_MAX_PARAMETERS parameters, reverse
    above; bad modes and counts are refused by name."""
    from jaxdeploy.fit import FORWARD_MODE_MAX_PARAMETERS, gradient_function, gradient_mode

    assert gradient_mode(1) == "forward"
    assert gradient_mode(FORWARD_MODE_MAX_PARAMETERS) == "forward"
    assert gradient_mode(FORWARD_MODE_MAX_PARAMETERS + 1) == "reverse"
    with pytest.raises(ValueError, match="n_parameters"):
        gradient_mode(0)
    scene, base, wrt, t_end, ts, _ = _impact_case()
    with pytest.raises(ValueError, match="mode"):
        gradient_function(scene, base, wrt, lambda ch: 0.0, t_end, mode="sideways")


@pytest.mark.slow  # two replayed-run compilations: 98 s at load 2.5 (64 s CPU)
def test_gradient_function_forward_equals_reverse_to_roundoff():
    """A scalar loss through a rough, damped impact, adaptive steps replayed: the gradient
    from forward mode (the loss and four tangents in one pass) equals the reverse-mode one
    to round-off, the loss equals the plain run's, and a vector output is refused."""
    from jaxdeploy.batch import run_scene
    from jaxdeploy.fit import gradient_function

    scene, base, wrt, t_end, ts, output = _impact_case()

    def loss(ch):
        return jnp.sum(output(ch) ** 2)

    results = {}
    for mode in ("forward", "reverse"):
        g, x0 = gradient_function(scene, base, wrt, loss, t_end, mode=mode, ts=ts)
        results[mode] = jax.jit(g)(x0)
    (v_fwd, g_fwd), (v_rev, g_rev) = results["forward"], results["reverse"]
    plain = loss(scene.channels(scene.build(base), run_scene(scene, base, t_end, ts=ts)))
    np.testing.assert_allclose(v_fwd, plain, rtol=1e-12)
    np.testing.assert_allclose(v_rev, plain, rtol=1e-12)
    scale = max(abs(float(g_rev[k])) * abs(x0[k]) for k in wrt)
    assert scale > 0
    for k in wrt:
        # Relative to the largest parameter-scaled component (the units differ by 1e12).
        assert abs(float(g_fwd[k]) - float(g_rev[k])) * abs(x0[k]) <= 1e-10 * scale, k
        assert float(g_rev[k]) != 0.0, k
    g, x0 = gradient_function(scene, base, wrt, output, t_end, mode="forward", ts=ts)
    with pytest.raises(ValueError, match="scalar"):
        jax.jit(g)(x0)


@pytest.mark.slow  # ~45 s CPU: one compile of the 5-run batch
def test_central_differences_at_a_zero_parameter_take_an_absolute_one_sided_step():
    """σ = 0 (its lower bound, Hertz's law) used to give NaN (a relative step of 0): it now
    takes the absolute step rel_step × its range's width, one-sided (σ − h is invalid), and
    the other parameters keep their central differences."""
    from jaxdeploy.fit._derivatives import _stencil, difference_steps

    scene, base, _, t_end, ts, _ = _impact_case()
    base = {**base, "sigma": 0.0}
    steps = difference_steps(scene, base, ["sigma", "clearance"], 1e-3)
    assert steps == pytest.approx({"sigma": 1e-3 * 1e-4, "clearance": 1e-3 * 2e-5})
    assert [o for o, _ in _stencil(scene, "sigma", 0.0, steps["sigma"])] == [0, 1, 2]
    assert [o for o, _ in _stencil(scene, "clearance", 2e-5, steps["clearance"])] == [1, -1]
    with pytest.raises(ValueError, match="material_damping = 0 .* unbounded"):
        difference_steps(scene, {**base, "material_damping": 0.0}, ["material_damping"], 1e-3)

    def output(ch):
        return ch["journal_x"][-1]

    control = {**FIXED, "dt": 5e-7}
    fd = {
        h: fit_central_differences(
            scene, base, ["sigma", "clearance"], output, t_end, h, ts=ts, control=control
        )
        for h in (1e-3, 1e-4)
    }
    assert all(np.isfinite(v) for d in fd.values() for v in d.values())
    # Smooth in c: second-order differences at two steps agree (measured 1.9e-5 relative).
    assert fd[1e-4]["clearance"] == pytest.approx(fd[1e-3]["clearance"], rel=1e-4)
    # A rougher surface is softer at first touch: the journal ends further out (−2.1e-5 and
    # −1.3e-5 m/m: the rough law is not smooth at σ = 0, so the one-sided slope varies with h).
    assert fd[1e-3]["sigma"] < 0 and fd[1e-4]["sigma"] < 0
