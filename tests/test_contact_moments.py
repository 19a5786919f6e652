"""F_n(h) against an independent high-precision reference (mpmath), its derivative identity,
and its behaviour outside the tabulated range."""

import jax
import jax.numpy as jnp
import mpmath as mp
import numpy as np
import pytest

from jaxdeploy.contact import gaussian_moment, gaussian_smoothed_power, positive_power

ORDERS = [0.0, 0.5, 1.0, 1.5, 2.0, 2.5]


def reference(h, n):
    """F_n(h) = Γ(n+1)/sqrt(2π) exp(−h²/4) D_(−n−1)(h) (parabolic-cylinder form), 40 digits."""
    with mp.workdps(40):
        h, n = mp.mpf(h), mp.mpf(n)
        return float(mp.gamma(n + 1) / mp.sqrt(2 * mp.pi) * mp.exp(-h * h / 4) * mp.pcfd(-n - 1, h))


def reference_quad(h, n):
    """Same by direct quadrature of the definition, as a check on the reference itself."""
    with mp.workdps(30):
        h, n = mp.mpf(h), mp.mpf(n)
        f = lambda s: (s - h) ** n * mp.exp(-s * s / 2) / mp.sqrt(2 * mp.pi)  # noqa: E731
        return float(mp.quad(f, [h, h + 1, h + 4, h + 12, mp.inf]))


H_GRID = np.concatenate([np.linspace(-10.0, 8.0, 73), [-9.99999, -10.0, 0.0]])


def test_reference_is_consistent():
    for h in (-7.5, 0.0, 3.0):
        for n in (0.5, 1.5, 2.5):
            assert reference(h, n) == pytest.approx(reference_quad(h, n), rel=1e-12)


@pytest.mark.parametrize("n", ORDERS)
def test_matches_mpmath_on_tabulated_range(n):
    got = np.asarray(jax.jit(lambda h: gaussian_moment(h, n))(jnp.asarray(H_GRID)))
    ref = np.array([reference(h, n) for h in H_GRID])
    mask = ref > 1e-300
    np.testing.assert_allclose(got[mask], ref[mask], rtol=1e-8, atol=0.0)


@pytest.mark.parametrize("n", [0.5, 1.5, 2.5])
def test_accurate_beyond_tabulated_range(n):
    # Deep contact (h < -10, separate quadrature branch) and large separations (shrunk window).
    hs = np.array([-10.5, -15.0, -40.0, -1e3, 12.0, 20.0, 30.0])
    got = np.asarray(gaussian_moment(jnp.asarray(hs), n))
    ref = np.array([reference(h, n) for h in hs])
    np.testing.assert_allclose(got, ref, rtol=1e-10, atol=0.0)


def test_literature_values_of_f_three_halves():
    # F_3/2 to 5 significant digits, computed with mpmath both from the definition (quad) and
    # from Γ(n+1)/√(2π) exp(−h²/4) D_(−n−1)(h) (mpmath.pcfd); the two agree to 8 digits.
    hs = jnp.array([-1.0, 0.0, 1.0, 2.0, 3.0, 4.0, -10.0])
    table = np.array([1.40460, 0.43002, 7.5668e-2, 6.6482e-3, 2.6397e-4, 4.4392e-6, 31.7416])
    np.testing.assert_allclose(gaussian_moment(hs, 1.5), table, rtol=5e-5)


@pytest.mark.parametrize("n", [0.5, 1.5, 2.5])
def test_derivative_identity(n):
    hs = jnp.asarray(np.concatenate([H_GRID, [-10.0, -10.5, -30.0, 15.0]]))
    grad = jax.vmap(jax.grad(lambda h: gaussian_moment(h, n)))(hs)
    expected = -n * gaussian_moment(hs, n - 1.0)
    np.testing.assert_allclose(grad, expected, rtol=1e-10, atol=1e-300)


def test_derivative_of_f0_is_minus_phi():
    hs = jnp.linspace(-10.0, 8.0, 37)
    grad = jax.vmap(jax.grad(lambda h: gaussian_moment(h, 0.0)))(hs)
    np.testing.assert_allclose(grad, -jnp.exp(-0.5 * hs**2) / np.sqrt(2 * np.pi), rtol=1e-12)


@pytest.mark.parametrize("n", [0.0, 1.5, 2.5])
def test_finite_everywhere_including_extremes(n):
    hs = jnp.array([-1e6, -50.0, 38.0, 45.0, 100.0, 1e10, 1e300, jnp.inf])
    values = gaussian_moment(hs, n)
    grads = jax.vmap(jax.grad(lambda h: gaussian_moment(h, n)))(hs)
    assert np.all(np.isfinite(values[:-1]))
    assert not np.any(np.isnan(values)) and not np.any(np.isnan(grads))
    assert np.all(values[3:] == 0.0)  # underflow to exactly 0 is fine
    assert np.all(np.asarray(values) >= 0.0)


def test_rejects_bad_order():
    with pytest.raises(ValueError, match=r"order n = -1\.0 is invalid"):
        gaussian_moment(0.0, -1.0)
    with pytest.raises(TypeError, match="static Python number"):
        gaussian_moment(0.0, jnp.array(1.5))


def test_smoothed_power_limits_and_scaling():
    x = jnp.array([-3e-6, -1e-6, 0.0, 1e-6, 5e-6])
    sigma = 1e-6
    # Definition: E[(x + σZ)_+^n] = σ^n F_n(−x/σ).
    np.testing.assert_allclose(
        gaussian_smoothed_power(x, sigma, 1.5),
        sigma**1.5 * gaussian_moment(-x / sigma, 1.5),
        rtol=1e-13,
    )
    # σ = 0 is plain Hertz (to round-off).
    np.testing.assert_allclose(
        gaussian_smoothed_power(x, 0.0, 1.5), positive_power(x, 1.5), rtol=1e-15, atol=0.0
    )


def test_positive_power_gradient_at_zero_is_finite():
    for n in (0.0, 0.5, 1.0, 1.5):
        g = jax.grad(lambda x: positive_power(x, n))(0.0)  # noqa: B023
        assert np.isfinite(g)
