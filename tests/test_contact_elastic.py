"""Hertz stiffness of the journal bearing and the elastic laws (Hertz, rough GW average)."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _contact_helpers import assert_grad_matches_fd

from jaxdeploy.contact import (
    HertzElastic,
    RoughElastic,
    effective_modulus,
    journal_bearing_stiffness,
    ra_to_sigma,
)

STEEL = dict(E_journal=207e9, nu_journal=0.3, E_bearing=207e9, nu_bearing=0.3)
R_J, C = 5e-3, 5e-5  # the docs' hinge pin: 5 mm radius, 0.05 mm clearance
K = float(journal_bearing_stiffness(R_J, C, **STEEL))
SIGMA = float(ra_to_sigma(1.6e-6))


# ---------------------------------------------------------------- stiffness


def test_stiffness_matches_both_written_forms():
    e1, n1, e2, n2 = 207e9, 0.3, 70e9, 0.33  # steel pin in an aluminium bearing
    r_b = R_J + C
    r_star = R_J * r_b / (r_b - R_J)
    e_star = 1.0 / ((1 - n1**2) / e1 + (1 - n2**2) / e2)
    direct = 4.0 / 3.0 * e_star * math.sqrt(r_star)
    # Lankarani–Nikravesh: h_k = (1 − ν²)/(π E), K = 4/(3π(h_i + h_j)) sqrt(R*).
    h1, h2 = (1 - n1**2) / (math.pi * e1), (1 - n2**2) / (math.pi * e2)
    ln_form = 4.0 / (3.0 * math.pi * (h1 + h2)) * math.sqrt(r_star)
    got = float(journal_bearing_stiffness(R_J, C, e1, n1, e2, n2))
    assert got == pytest.approx(direct, rel=1e-13)
    assert got == pytest.approx(ln_form, rel=1e-13)
    # The trap: the π-form h_k in the π-free prefactor is off by exactly π.
    trap = 4.0 / (3.0 * (h1 + h2)) * math.sqrt(r_star)
    assert trap / got == pytest.approx(math.pi, rel=1e-13)


def test_stiffness_order_of_magnitude_and_clearance_gradient():
    # Steel pins of ~10 mm with c from 0.5 to 0.02 mm give (4/3) E* sqrt(R*) ~ 1e10–1e11 N/m^1.5.
    assert 1e10 < K < 1e12
    f = lambda c: journal_bearing_stiffness(R_J, c, **STEEL)  # noqa: E731
    g = jax.grad(f)(C)
    assert_grad_matches_fd(g, f, C, rtol=1e-7)
    assert g == pytest.approx(-float(f(C)) / (2 * C) * R_J / (R_J + C), rel=1e-12)


def test_effective_modulus_same_material():
    assert float(effective_modulus(207e9, 0.3, 207e9, 0.3)) == pytest.approx(
        207e9 / (2 * 0.91), rel=1e-14
    )


@pytest.mark.parametrize(
    "kwargs, pattern",
    [
        (dict(clearance=0.0), r"clearance = 0\.0 m is invalid.*\(0, inf\]"),
        (dict(clearance=-1e-5), r"clearance"),
        (dict(radius_journal=-1.0), r"radius_journal .*invalid"),
        (dict(nu_journal=0.5), r"nu_journal = 0\.5 is invalid.*\(-1, 0\.5\)"),
        (dict(nu_bearing=-1.0), r"nu_bearing"),
        (dict(E_bearing=0.0), r"E_bearing = 0\.0 Pa is invalid"),
        (dict(E_journal=float("nan")), r"E_journal"),
    ],
)
def test_stiffness_validation_names_parameter(kwargs, pattern):
    args = dict(radius_journal=R_J, clearance=C, **STEEL)
    args.update(kwargs)
    with pytest.raises(ValueError, match=pattern):
        journal_bearing_stiffness(**args)


# ---------------------------------------------------------------- elastic laws


def test_hertz_force_stiffness_and_gradient_at_zero():
    law = HertzElastic(K)
    d = jnp.array([-1e-6, 0.0, 1e-6, 4e-6])
    np.testing.assert_allclose(law.force(d), K * np.maximum(d, 0) ** 1.5, rtol=1e-14)
    assert float(jax.grad(law.force)(0.0)) == 0.0
    assert float(jax.grad(law.stiffness)(0.0)) == 0.0  # d/dδ of sqrt(δ_+): guarded, finite
    np.testing.assert_allclose(jax.vmap(jax.grad(law.force))(d), law.stiffness(d), rtol=1e-14)
    assert float(law.onset_penetration()) == 0.0


def test_rough_sigma_zero_is_hertz():
    hertz, rough = HertzElastic(K), RoughElastic(K, 0.0, offset=2.0)
    d = jnp.linspace(-5e-6, 5e-6, 21)
    np.testing.assert_allclose(rough.force(d), hertz.force(d), rtol=1e-14, atol=0.0)
    np.testing.assert_allclose(rough.stiffness(d), hertz.stiffness(d), rtol=1e-14, atol=0.0)


def test_rough_tends_to_hertz_as_sigma_shrinks():
    d = 3e-6
    errors = [
        abs(float(RoughElastic(K, s).force(d)) / float(HertzElastic(K).force(d)) - 1.0)
        for s in (1e-6, 1e-7, 1e-8, 1e-9)
    ]
    assert all(b < a for a, b in zip(errors, errors[1:], strict=False))
    # E[(δ + σZ)^1.5] = δ^1.5 (1 + (3/8)(σ/δ)² + ...): error ~ σ² once deep.
    assert errors[-1] < 1e-6


def test_rough_tends_to_hertz_for_deep_contact():
    rough, hertz = RoughElastic(K, SIGMA), HertzElastic(K)
    deltas = np.array([2.0, 5.0, 10.0, 30.0, 100.0]) * SIGMA
    rel = np.abs(np.asarray(rough.force(deltas)) / np.asarray(hertz.force(deltas)) - 1.0)
    assert np.all(np.diff(rel) < 0)
    assert rel[-1] < 1e-4
    # The second-order term: 3/8 (σ/δ)².
    assert rel[-1] == pytest.approx(3.0 / 8.0 * 1e-4, rel=1e-2)


@pytest.mark.parametrize("offset", [0.0, 3.0])
def test_rough_monotone_and_positive(offset):
    law = RoughElastic(K, SIGMA, offset=offset)
    d = jnp.linspace(-8 * SIGMA, 10 * SIGMA, 400)
    f = np.asarray(law.force(d))
    k = np.asarray(law.stiffness(d))
    assert np.all(f >= 0) and np.all(k >= 0)
    assert np.all(np.diff(f) >= 0)
    assert np.all(np.diff(f[f > 1e-12 * f.max()]) > 0)


@pytest.mark.parametrize("offset", [0.0, 1.5, 3.0])
def test_rough_onset_near_s0_minus_three_sigma(offset):
    law = RoughElastic(K, SIGMA, offset=offset)
    onset = float(law.onset_penetration())
    assert onset == pytest.approx((offset - 3.0) * SIGMA, rel=1e-14)
    scale = K * SIGMA**1.5  # Hertz force at one σ of interference
    # At onset the force is a few 1e-4 of that scale; 2σ earlier it is negligible.
    assert 1e-4 < float(law.force(onset)) / scale < 1e-3
    assert float(law.force(onset - 2 * SIGMA)) / scale < 1e-7
    assert float(law.force(onset + 2 * SIGMA)) / scale > 1e-2


def test_rough_force_at_onset_level_against_scipy_quadrature():
    """The onset level's force relative to one σ deeper and to δ = s0 σ, as the docstring of
    `onset_penetration` states them (4.0 %, 6.1e-4 for n = 1.5; 4.5 % one σ deeper for n = 1),
    against E[(Z − h)_+^n] by scipy's quadrature of the normal density (no shared code)."""
    from scipy import integrate, stats

    def smoothed(h, n):
        integrand = lambda z: (z - h) ** n * stats.norm.pdf(z)  # noqa: E731
        return integrate.quad(integrand, h, np.inf, epsabs=0.0, epsrel=1e-12)[0]

    for n, one_sigma, at_s0 in ((1.5, 0.0397, 6.14e-4), (1.0, 0.0450, 9.58e-4)):
        law = RoughElastic(K, SIGMA, offset=1.0, exponent=n)
        onset = float(law.onset_penetration())
        ratio = float(law.force(onset)) / float(law.force(onset + SIGMA))
        assert ratio == pytest.approx(smoothed(3.0, n) / smoothed(2.0, n), rel=1e-6)
        assert ratio == pytest.approx(one_sigma, abs=5e-5)
        ratio_s0 = float(law.force(onset)) / float(law.force(SIGMA))
        assert ratio_s0 == pytest.approx(smoothed(3.0, n) / smoothed(0.0, n), rel=1e-6)
        assert ratio_s0 == pytest.approx(at_s0, abs=5e-6)


def test_rough_stiffness_is_force_gradient():
    # Against autodiff through the force's own quadrature (`quadrature_force`), which is
    # independent of `stiffness`; `force` itself is differentiated by `stiffness`.
    law = RoughElastic(K, SIGMA, offset=1.0)
    d = jnp.linspace(-6 * SIGMA, 40 * SIGMA, 97)
    np.testing.assert_allclose(
        jax.vmap(jax.grad(law.quadrature_force))(d), law.stiffness(d), rtol=1e-10, atol=1e-6
    )


def test_rough_force_custom_derivative_matches_the_quadrature():
    """`force`'s custom JVP (closed-form stiffness in δ, quadrature in the law's parameters)
    equals autodiff of the quadrature, first and second order, in δ and in σ, K, s0."""

    def force(params, delta, quadrature):
        law = RoughElastic(params[0], params[1], offset=params[2])
        return law.quadrature_force(delta) if quadrature else law.force(delta)

    params = jnp.array([K, SIGMA, 0.7])
    # Each derivative compiled once for the four depths (op by op, the hessian of the
    # quadrature compiled each operation on first use).
    derivatives = [
        jax.jit(fn(force, argnums=(0, 1)), static_argnums=2) for fn in (jax.grad, jax.hessian)
    ]
    for delta in (-4.0 * SIGMA, -1.0 * SIGMA, 0.5 * SIGMA, 12.0 * SIGMA):
        for derivative in derivatives:
            got = derivative(params, delta, False)
            want = derivative(params, delta, True)
            for a, b in zip(jax.tree.leaves(got), jax.tree.leaves(want), strict=True):
                np.testing.assert_allclose(a, b, rtol=1e-10, atol=1e-12 * np.max(np.abs(b)))


def _force(delta, sigma, k=K, offset=0.5):
    return RoughElastic(k, sigma, offset=offset).force(delta)


@pytest.mark.parametrize(
    "delta, sigma",
    [
        (0.0, SIGMA),
        (-3.0 * SIGMA, SIGMA),  # onset with s0 = 0.5 is at -2.5σ; also check slightly before
        (-2.5 * SIGMA, SIGMA),
        (2e-6, SIGMA),
        (10.0 * SIGMA, SIGMA),  # deep branch
        (10.5 * SIGMA, SIGMA),  # the branch switch h = -10 (s0 = 0.5)
        (2e-6, 1e-9),
    ],
)
def test_rough_gradients_match_finite_differences(delta, sigma):
    g_delta, g_sigma, g_k = jax.grad(_force, argnums=(0, 1, 2))(delta, sigma, K)
    assert_grad_matches_fd(g_delta, lambda x: _force(x, sigma), delta, rtol=1e-5, abs_step=1e-12)
    assert_grad_matches_fd(g_sigma, lambda s: _force(delta, s), sigma, rtol=1e-5, abs_step=1e-15)
    assert_grad_matches_fd(g_k, lambda k: _force(delta, sigma, k), K, rtol=1e-7)


def test_rough_gradients_finite_at_sigma_zero():
    for delta in (-1e-6, 0.0, 2e-6):
        grads = jax.grad(_force, argnums=(0, 1, 2, 3))(delta, 0.0, K, 0.5)
        assert all(np.isfinite(float(g)) for g in grads)
    # One-sided derivative in σ at σ = 0 for δ > 0: dF/dσ = −K n s0 δ^(n−1).
    g_sigma = jax.grad(_force, argnums=1)(2e-6, 0.0)
    assert float(g_sigma) == pytest.approx(-K * 1.5 * 0.5 * (2e-6) ** 0.5, rel=1e-10)


def test_gradient_through_clearance_and_roughness_jit_vmap():
    def peak_force(clearance, ra):
        k = journal_bearing_stiffness(R_J, clearance, **STEEL)
        return RoughElastic(k, ra_to_sigma(ra)).force(1e-6)

    f = jax.jit(jax.vmap(jax.grad(peak_force, argnums=(0, 1))))
    cs = jnp.array([1e-5, 5e-5, 1e-4])
    ras = jnp.array([0.8e-6, 1.6e-6, 3.2e-6])
    g_c, g_ra = f(cs, ras)
    for c, ra, gc, gr in zip(cs, ras, g_c, g_ra, strict=True):
        assert_grad_matches_fd(gc, lambda x: peak_force(x, ra), c, rtol=1e-6)  # noqa: B023
        assert_grad_matches_fd(gr, lambda x: peak_force(c, x), ra, rtol=1e-6)  # noqa: B023
    assert np.all(np.asarray(g_c) < 0) and np.all(np.asarray(g_ra) > 0)


def test_elastic_law_is_a_pytree_and_vmaps_over_parameters():
    sigmas = jnp.array([0.0, 1e-6, 2e-6, 4e-6])
    laws = jax.vmap(lambda s: RoughElastic(K, s))(sigmas)
    forces = jax.vmap(lambda law: law.force(1e-6))(laws)
    for s, f in zip(sigmas, forces, strict=True):
        assert float(f) == pytest.approx(float(RoughElastic(K, s).force(1e-6)), rel=1e-14)


@pytest.mark.parametrize(
    "make, pattern",
    [
        (lambda: RoughElastic(K, -1e-6), r"sigma = -1e-06 m is invalid.*\[0, inf\]"),
        (lambda: RoughElastic(K, 1e-6, offset=-1.0), r"offset"),
        (lambda: RoughElastic(-K, 1e-6), r"stiffness = .* is invalid"),
        (lambda: HertzElastic(0.0), r"stiffness = 0\.0"),
        (lambda: HertzElastic(K, exponent=0.5), r"exponent = 0\.5 is invalid.*\[1, 10\]"),
    ],
)
def test_elastic_validation(make, pattern):
    with pytest.raises(ValueError, match=pattern):
        make()
