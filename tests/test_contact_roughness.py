"""Roughness helpers: Ra ↔ σ, combination, ploughing friction μ(Ra), coupling c_e(Ra)."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _contact_helpers import assert_grad_matches_fd

from jaxdeploy.contact import (
    PloughingFriction,
    RestitutionRoughnessCoupling,
    combine_sigma,
    ra_to_sigma,
    sigma_to_ra,
    turned_feed,
    turned_profile_slope,
)


def test_ra_sigma_gaussian_relation():
    ra = jnp.array([0.8e-6, 1.6e-6, 3.2e-6])
    np.testing.assert_allclose(ra_to_sigma(ra), [1.0027e-6, 2.0053e-6, 4.0106e-6], rtol=1e-4)
    np.testing.assert_allclose(sigma_to_ra(ra_to_sigma(ra)), ra, rtol=1e-15)
    # Ra = E|σZ| for a Gaussian profile, checked by sampling.
    z = np.random.default_rng(0).standard_normal(400_000)
    assert np.mean(np.abs(z)) == pytest.approx(float(sigma_to_ra(1.0)), rel=5e-3)


def test_combine_sigma_and_its_gradient():
    assert float(combine_sigma(3e-6, 4e-6)) == pytest.approx(5e-6, rel=1e-15)
    assert float(combine_sigma(0.0, 2e-6)) == pytest.approx(2e-6, rel=1e-15)
    g = jax.grad(combine_sigma, argnums=(0, 1))
    assert [float(x) for x in g(0.0, 0.0)] == [0.0, 0.0]
    assert [float(x) for x in g(0.0, 2e-6)] == [0.0, 1.0]
    assert_grad_matches_fd(g(3e-6, 4e-6)[0], lambda s: combine_sigma(s, 4e-6), 3e-6, rtol=1e-8)


def test_restitution_coupling_is_identity_by_default():
    ras = jnp.array([0.0, 0.8e-6, 1.6e-6, 3.2e-6])
    np.testing.assert_allclose(RestitutionRoughnessCoupling(1.6e-6)(0.9, ras), 0.9, rtol=1e-15)


def _circular_scallops(feed, nose_radius, n=400_001):
    """Ra and mean |slope| of one exact circular scallop (not the parabola the law uses)."""
    x = np.linspace(-feed / 2, feed / 2, n)
    z = nose_radius - np.sqrt(nose_radius**2 - x**2)
    slope = x / np.sqrt(nose_radius**2 - x**2)
    return np.mean(np.abs(z - z.mean())), np.mean(np.abs(slope))


@pytest.mark.parametrize("feed_over_radius, tolerance", [(0.05, 2e-4), (0.25, 4e-3), (0.5, 2e-2)])
def test_turned_profile_against_circular_scallops(feed_over_radius, tolerance):
    # The law's parabolic scallop against the exact arc, inside the stated range (f <= r/2).
    r = 0.8e-3
    ra, slope = _circular_scallops(feed_over_radius * r, r)
    assert float(turned_feed(ra, r)) == pytest.approx(feed_over_radius * r, rel=tolerance)
    assert float(turned_profile_slope(ra, r)) == pytest.approx(slope, rel=tolerance)


def test_turned_profile_leaves_its_range_beyond_half_the_nose_radius():
    # The limit is real: at f = r the slope inferred from the arc's Ra is 4 % off (0.4 % at r/4).
    r = 0.8e-3
    ra, slope = _circular_scallops(r, r)
    assert abs(float(turned_profile_slope(ra, r)) / slope - 1) > 0.03
    friction = PloughingFriction(0.01, r)
    ra_half, _ = _circular_scallops(r / 2, r)
    assert float(friction.max_ra) == pytest.approx(ra_half, rel=2e-2)


def test_handbook_turning_example():
    # f = 0.2 mm with r = 0.8 mm gives Ra ≈ 1.6 µm (handbook Ra = f²/(31.2 r)).
    assert float(turned_feed(0.2e-3**2 / (31.2 * 0.8e-3), 0.8e-3)) == pytest.approx(0.2e-3, 1e-3)


def test_cone_ploughing_coefficient_by_quadrature():
    # Bowden–Tabor: a cone of semi-angle α ploughing at flow pressure p carries the load on the
    # front half of its contact circle (p π a²/2) and pushes p × (vertical projection of the
    # front half-cone). The projection is measured here by quadrature of the cone's surface.
    for alpha in np.radians([60.0, 75.0, 85.0]):
        a = 1.0
        depth = a / np.tan(alpha)
        # Front half-cone z = depth (1 - ρ/a), ρ ≤ a, |φ| ≤ π/2: its projection on the plane
        # normal to sliding is ∫∫ ∂z/∂ρ-weighted area: ∫_{-π/2}^{π/2} ∫_0^a (depth/a) cos φ ρ dρ dφ.
        phi = np.linspace(-np.pi / 2, np.pi / 2, 20001)
        rho = np.linspace(0.0, a, 20001)
        vertical = np.trapezoid(np.cos(phi), phi) * np.trapezoid(rho, rho) * depth / a
        horizontal = np.pi * a**2 / 2
        tan_slope = 1 / np.tan(alpha)
        friction = PloughingFriction(0.0, 1.0)
        mu_law = float(friction.adhesion) + 2 / np.pi * tan_slope
        assert vertical / horizontal == pytest.approx(mu_law, rel=1e-6)


def test_ploughing_friction_values_limits_and_gradients():
    r = 0.8e-3
    friction = PloughingFriction(0.01, r)
    assert float(friction(0.0)) == 0.01  # smooth: adhesion only
    mu = np.asarray(jax.vmap(friction)(jnp.array([0.8e-6, 1.6e-6, 3.2e-6])))
    # Δa ∝ sqrt(Ra): each doubling of Ra multiplies the ploughing part by sqrt(2).
    np.testing.assert_allclose((mu[1:] - 0.01) / (mu[:-1] - 0.01), math.sqrt(2), rtol=1e-12)
    assert 0.045 < mu[1] < 0.055  # Ra 1.6 µm, r 0.8 mm: about the study's μ = 0.05
    assert_grad_matches_fd(jax.grad(friction)(1.6e-6), friction, 1.6e-6, rtol=1e-7)
    assert float(jax.grad(friction)(0.0)) == 0.0
    by_adhesion = jax.grad(lambda m: PloughingFriction(m, r)(1.6e-6))(0.01)
    assert float(by_adhesion) == 1.0


def test_restitution_coupling_stays_in_unit_interval():
    coupling = RestitutionRoughnessCoupling(1.6e-6, 2.0)
    ras = jnp.array([0.0, 0.1e-6, 1.6e-6, 3.2e-6, 100e-6])
    for base in (0.05, 0.5, 0.9, 1.0):
        c = np.asarray(coupling(base, ras))
        assert np.all((c > 0) & (c <= 1))
        assert np.all(np.diff(c) <= 0)  # rougher -> more loss
    assert float(coupling(0.9, 1.6e-6)) == pytest.approx(0.9, rel=1e-15)
    assert float(coupling(0.9, 3.2e-6)) == pytest.approx(0.9**4, rel=1e-14)

    def f(base, ra):
        return coupling(base, ra)

    g_base, g_ra = jax.grad(f, argnums=(0, 1))(0.9, 0.8e-6)
    assert_grad_matches_fd(g_base, lambda b: f(b, 0.8e-6), 0.9, rtol=1e-8)
    assert_grad_matches_fd(g_ra, lambda r: f(0.9, r), 0.8e-6, rtol=1e-7)
    assert all(np.isfinite(float(x)) for x in jax.grad(f, argnums=(0, 1))(1.0, 0.0))


@pytest.mark.parametrize(
    "call, pattern",
    [
        (lambda: ra_to_sigma(-1e-6), r"ra = -1e-06 m is invalid.*\[0, inf\]"),
        (lambda: sigma_to_ra(float("inf")), r"sigma"),
        (lambda: combine_sigma(1e-6, -1e-6), r"sigma_2"),
        (lambda: RestitutionRoughnessCoupling(0.0), r"reference_ra = 0\.0 m is invalid"),
        (lambda: PloughingFriction(-0.1, 1e-3), r"adhesion = -0\.1 is invalid"),
        (lambda: PloughingFriction(0.01, 0.0), r"nose_radius = 0\.0 m is invalid"),
        (lambda: turned_feed(-1e-6, 1e-3), r"ra = "),
        (lambda: RestitutionRoughnessCoupling(1e-6)(1.5, 1e-6), r"restitution = 1\.5"),
    ],
)
def test_validation(call, pattern):
    with pytest.raises(ValueError, match=pattern):
        call()
