"""Roughness helpers: Ra ↔ σ, combination, couplings μ(Ra) and c_e(Ra)."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _contact_helpers import assert_grad_matches_fd

from jaxdeploy.contact import (
    RestitutionRoughnessCoupling,
    RoughnessCoupling,
    combine_sigma,
    ra_to_sigma,
    sigma_to_ra,
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


def test_couplings_are_identity_by_default():
    ras = jnp.array([0.0, 0.8e-6, 1.6e-6, 3.2e-6])
    np.testing.assert_array_equal(RoughnessCoupling(1.6e-6)(0.1, ras), 0.1)
    np.testing.assert_allclose(RestitutionRoughnessCoupling(1.6e-6)(0.9, ras), 0.9, rtol=1e-15)
    grads = jax.vmap(jax.grad(lambda ra: RoughnessCoupling(1.6e-6)(0.1, ra)))(ras)
    assert np.all(np.asarray(grads) == 0.0)


def test_power_coupling_values_and_gradients():
    coupling = RoughnessCoupling(1.6e-6, 0.5)
    assert float(coupling(0.1, 3.2e-6)) == pytest.approx(0.1 * math.sqrt(2), rel=1e-14)
    assert float(coupling(0.1, 0.0)) == 0.0
    f = lambda ra: coupling(0.1, ra)  # noqa: E731
    assert_grad_matches_fd(jax.grad(f)(0.8e-6), f, 0.8e-6, rtol=1e-7)
    assert np.isfinite(float(jax.grad(f)(0.0)))

    def by_sensitivity(p):
        return RoughnessCoupling(1.6e-6, p)(0.1, 3.2e-6)

    assert_grad_matches_fd(jax.grad(by_sensitivity)(0.0), by_sensitivity, 0.0, abs_step=1e-6)


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
        (lambda: RoughnessCoupling(0.0), r"reference_ra = 0\.0 m is invalid"),
        (lambda: RoughnessCoupling(1e-6)(0.1, -1e-6), r"ra = "),
        (lambda: RestitutionRoughnessCoupling(1e-6)(1.5, 1e-6), r"restitution = 1\.5"),
    ],
)
def test_validation(call, pattern):
    with pytest.raises(ValueError, match=pattern):
        call()
