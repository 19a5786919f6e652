"""Friction laws: oddness, bound μF_N, finite gradients at zero sliding speed, validation."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _contact_helpers import assert_grad_matches_fd
from hypothesis import given, settings
from hypothesis import strategies as st

from jaxdeploy.contact import AmbrosioCoulomb, SmoothCoulomb, StribeckFriction

LAWS = {
    "algebraic": (SmoothCoulomb(0.1), 0.1),
    "tanh": (SmoothCoulomb(0.1, 1e-3, shape="tanh"), 0.1),
    "ambrosio": (AmbrosioCoulomb(0.1), 0.1),
    "ambrosio-c1": (AmbrosioCoulomb(0.1, transition="smoothstep"), 0.1),
    "stribeck": (StribeckFriction(0.15, 0.1, 1e-2, 1e-4), 0.15),
}

finite = dict(allow_nan=False, allow_infinity=False)


@settings(max_examples=60, deadline=None)
@given(
    name=st.sampled_from(sorted(LAWS)),
    v=st.floats(-10.0, 10.0, **finite),
    normal=st.floats(0.0, 1e5, **finite),
)
def test_odd_and_bounded(name, v, normal):
    law, mu_max = LAWS[name]
    f_pos, f_neg = float(law.force(v, normal)), float(law.force(-v, normal))
    assert f_pos == -f_neg
    assert abs(f_pos) <= mu_max * normal * (1 + 1e-15)
    assert f_pos * v >= 0.0  # along +t for positive v_t: the caller applies it against sliding


@pytest.mark.parametrize("name", sorted(LAWS))
def test_finite_gradient_at_zero_speed(name):
    """At v_t = 0 (issue 8's zero sliding speed) both partial derivatives are finite and equal
    central differences (steps far below the laws' slip widths, ≥ 1e-4 m/s)."""
    law, _ = LAWS[name]
    g_v, g_n = jax.grad(law.force, argnums=(0, 1))(0.0, 100.0)
    assert np.isfinite(float(g_v)) and np.isfinite(float(g_n))
    assert_grad_matches_fd(g_v, lambda v: law.force(v, 100.0), 0.0, rtol=1e-6, abs_step=1e-9)
    assert_grad_matches_fd(g_n, lambda f: law.force(0.0, f), 100.0, rtol=1e-6, atol=1e-12)


def test_sliding_limit_and_slip_width():
    law = SmoothCoulomb(0.2, 1e-3)
    assert float(law.force(1.0, 50.0)) == pytest.approx(0.2 * 50.0, rel=1e-6)
    assert float(law.force(1e-3, 50.0)) == pytest.approx(0.2 * 50.0 / np.sqrt(2), rel=1e-14)
    assert float(jax.grad(law.force)(0.0, 50.0)) == pytest.approx(0.2 * 50.0 / 1e-3)


def test_ambrosio_uses_speed_not_signed_velocity():
    law = AmbrosioCoulomb(0.1, 1e-4, 1e-3)
    # DyS applies c_d to signed v_t, which kills friction for negative v_t; ours is symmetric.
    assert float(law.force(-5e-4, 10.0)) == pytest.approx(-0.1 * 10.0 * 4 / 9, rel=1e-13)
    assert float(law.force(5e-5, 10.0)) == 0.0
    assert float(law.force(2e-3, 10.0)) == pytest.approx(1.0, rel=1e-14)
    smooth = AmbrosioCoulomb(0.1, 1e-4, 1e-3, transition="smoothstep")
    for v in (1e-4, 1e-3):  # C¹: zero slope at both ends of the transition
        assert abs(float(jax.grad(smooth.force)(v + 1e-12, 1.0))) < 1e-3
        assert abs(float(jax.grad(smooth.force)(v - 1e-12, 1.0))) < 1e-3


def test_stribeck_peak_between_velocities():
    law = StribeckFriction(0.15, 0.1, 1e-2, 1e-5)
    assert float(law.force(1e-3, 1.0)) == pytest.approx(0.15, rel=1e-2)
    assert float(law.force(1.0, 1.0)) == pytest.approx(0.1, rel=1e-6)


def test_gradient_wrt_mu_matches_fd_and_vmaps():
    def f(mu, v):
        return SmoothCoulomb(mu, 1e-3).force(v, 30.0)

    g = jax.jit(jax.vmap(jax.grad(f), in_axes=(None, 0)))(0.1, jnp.array([-1e-2, 0.0, 2e-4]))
    for gv, v in zip(g, (-1e-2, 0.0, 2e-4), strict=True):
        assert_grad_matches_fd(gv, lambda m: f(m, v), 0.1, rtol=1e-8, atol=1e-12)  # noqa: B023

    def g_ambrosio(mu):
        return AmbrosioCoulomb(mu).force(5e-4, 30.0)

    assert_grad_matches_fd(jax.grad(g_ambrosio)(0.1), g_ambrosio, 0.1, rtol=1e-8)


@pytest.mark.parametrize(
    "make, pattern",
    [
        (lambda: SmoothCoulomb(-0.1), r"mu = -0\.1 is invalid"),
        (lambda: SmoothCoulomb(0.1, 0.0), r"slip_velocity = 0\.0 m/s is invalid"),
        (lambda: SmoothCoulomb(0.1, shape="sign"), r"shape = 'sign' is invalid"),
        (lambda: AmbrosioCoulomb(0.1, 1e-3, 1e-4), r"v1 - v0 = .* is invalid"),
        (lambda: StribeckFriction(0.2, -0.1, 1e-2), r"mu_kinetic"),
        (lambda: StribeckFriction(0.2, 0.1, 0.0), r"stribeck_velocity"),
    ],
)
def test_validation(make, pattern):
    with pytest.raises(ValueError, match=pattern):
        make()
