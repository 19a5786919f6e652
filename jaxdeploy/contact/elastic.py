"""Elastic normal-force laws `F_e(δ)`: Hertz, and Hertz averaged over Gaussian roughness.

Each law is an `eqx.Module` whose numbers are pytree leaves (traced, batchable, differentiable)
and whose exponent is a static field (changing it recompiles). All laws share the interface

* `force(delta)`: elastic force `F_e(δ) ≥ 0` (N) at penetration δ (m; δ < 0 is a gap);
* `stiffness(delta)`: `dF_e/dδ` (N/m), in closed form;
* `potential(delta)`: elastic energy `U(δ) = ∫_{−∞}^δ F_e` (J), with `dU/dδ = F_e`, for energy
  balances;
* `onset_penetration()`: the δ where the force becomes non-negligible. The mechanism latches the
  impact velocity v⁻ of the damping laws there.
"""

from __future__ import annotations

import abc

import equinox as eqx
import jax
import jax.numpy as jnp
from jax import Array
from jax.custom_derivatives import SymbolicZero
from jax.typing import ArrayLike

from .._validation import check_nonnegative, check_positive, check_range
from .gaussian_moments import gaussian_smoothed_power, positive_power

__all__ = ["AbstractElasticLaw", "HertzElastic", "RoughElastic"]

# σ-multiples below the asperity reference plane where the rough law "starts": there
# F_e = K σ^n F_n(3), and F_1.5(3) = 2.6e-4, i.e. 2.6e-4 of the Hertz force at one σ of
# interference; 1σ shallower it is already 25x larger (F_1.5(2) = 6.6e-3).
ONSET_SIGMAS = 3.0


def _check_exponent(exponent) -> float:
    if isinstance(exponent, bool) or not isinstance(exponent, int | float):
        raise TypeError(f"exponent must be a static Python number, got {type(exponent).__name__}")
    check_range("exponent", exponent, 1.0, 10.0)
    return float(exponent)


class AbstractElasticLaw(eqx.Module):
    """Interface of an elastic normal law `F_e(δ)`; see the module docstring."""

    @abc.abstractmethod
    def force(self, delta: ArrayLike) -> Array:
        """Elastic force `F_e(δ)` (N), non-negative."""

    @abc.abstractmethod
    def stiffness(self, delta: ArrayLike) -> Array:
        """Contact stiffness `dF_e/dδ` (N/m)."""

    @abc.abstractmethod
    def potential(self, delta: ArrayLike) -> Array:
        """Elastic energy stored in the contact, `U(δ) = ∫_{−∞}^δ F_e(s) ds` (J)."""

    @abc.abstractmethod
    def onset_penetration(self) -> Array:
        """Penetration (m) at which the force becomes non-negligible."""


class HertzElastic(AbstractElasticLaw):
    """Hertz law `F_e = K δ_+^n` for smooth surfaces.

    **Arguments:**

    - `stiffness`: `K` (N/m^n), > 0, e.g. from `journal_bearing_stiffness`.
    - `exponent`: `n` (static, default 1.5), in [1, 10].

    The power is guarded so that the gradient at δ = 0 is finite (0 for n > 1).

    **References:** Hertz (1882); Johnson, *Contact Mechanics* (1985); Lankarani & Nikravesh,
    *J. Mech. Des.* 112 (1990) 369.
    """

    stiffness_coefficient: Array
    exponent: float = eqx.field(static=True)

    def __init__(self, stiffness: ArrayLike, exponent: float = 1.5):
        self.stiffness_coefficient = jnp.asarray(stiffness, dtype=float)
        self.exponent = _check_exponent(exponent)

    def __check_init__(self):
        check_positive("stiffness", self.stiffness_coefficient, unit="N/m^n")

    def force(self, delta: ArrayLike) -> Array:
        """`F_e = K δ_+^n` (N)."""
        return self.stiffness_coefficient * positive_power(delta, self.exponent)

    def stiffness(self, delta: ArrayLike) -> Array:
        """`dF_e/dδ = n K δ_+^(n−1)` (N/m)."""
        n = self.exponent
        return n * self.stiffness_coefficient * positive_power(delta, n - 1.0)

    def potential(self, delta: ArrayLike) -> Array:
        """`U = K δ_+^(n+1)/(n + 1)` (J)."""
        n = self.exponent
        return self.stiffness_coefficient * positive_power(delta, n + 1.0) / (n + 1.0)

    def onset_penetration(self) -> Array:
        """0: smooth surfaces touch at δ = 0."""
        return jnp.zeros_like(self.stiffness_coefficient)


class RoughElastic(AbstractElasticLaw):
    """Hertz law averaged over Gaussian asperity heights (Greenwood–Williamson style).

    `F_e(δ) = K E[(δ − s0 σ + σ Z)_+^n] = K σ^n F_n(s0 − δ/σ)`, `Z ~ N(0, 1)`.

    **Arguments:**

    - `stiffness`: `K` (N/m^n), > 0: the Hertz stiffness of the nominal (smooth) geometry.
    - `sigma`: σ (m), ≥ 0: standard deviation of the combined peak heights
      (`roughness.ra_to_sigma`, `roughness.combine_sigma`). σ = 0 gives `HertzElastic`
      (to round-off).
    - `offset`: `s0` ≥ 0, in units of σ: where the clearance is measured from. 0 = between mean
      lines (GW convention, default); ≈ 3 = between peak tops (the force then starts at δ ≈ 0).
    - `exponent`: `n` (static, default 1.5).

    Properties: C^∞ in δ and σ for σ > 0; tends to Hertz `K (δ − s0σ)^n` for δ ≫ σ; force starts
    near `δ = (s0 − 3)σ`. The dynamic contact stiffness is
    `k_d = dF_e/dδ = K n σ^(n−1) F_(n−1)(s0 − δ/σ)`.

    Caveat: elastic asperities are an idealisation — for machined steel the plasticity index
    is ≫ 1 (ψ ~ 4–16 with GW's index; docs/contact.md), so this is a smooth, differentiable
    *phenomenological* law.

    **References:**

    - Greenwood, Williamson, *Proc. R. Soc. A* 295 (1966) 300.
    - Wang et al., *Actuators* 13 (2024) 274 (W24; states the approach, equations missing).
    - docs/contact.md, "What is reconstructed, and why" (this form is our reconstruction).
    """

    stiffness_coefficient: Array
    sigma: Array
    offset: Array
    exponent: float = eqx.field(static=True)

    def __init__(
        self,
        stiffness: ArrayLike,
        sigma: ArrayLike,
        offset: ArrayLike = 0.0,
        exponent: float = 1.5,
    ):
        self.stiffness_coefficient = jnp.asarray(stiffness, dtype=float)
        self.sigma = jnp.asarray(sigma, dtype=float)
        self.offset = jnp.asarray(offset, dtype=float)
        self.exponent = _check_exponent(exponent)

    def __check_init__(self):
        check_positive("stiffness", self.stiffness_coefficient, unit="N/m^n")
        check_nonnegative("sigma", self.sigma, unit="m")
        check_nonnegative("offset", self.offset)

    def _interference(self, delta):
        # Mean interference measured from the asperity reference plane.
        return jnp.asarray(delta, dtype=float) - self.offset * self.sigma

    def force(self, delta: ArrayLike) -> Array:
        """`F_e = K σ^n F_n(s0 − δ/σ)` (N); `K (δ)_+^n` at σ = 0.

        Differentiated in δ by the closed form `stiffness` (`_rough_force`), not through
        the quadrature."""
        return _rough_force(self, jnp.asarray(delta, dtype=float))

    def quadrature_force(self, delta: ArrayLike) -> Array:
        """`force` without its custom derivative: JAX differentiates the quadrature itself
        (the independent check of `stiffness` and of the custom rule)."""
        x = self._interference(delta)
        return self.stiffness_coefficient * gaussian_smoothed_power(x, self.sigma, self.exponent)

    def stiffness(self, delta: ArrayLike) -> Array:
        """Dynamic contact stiffness `k_d = K n σ^(n−1) F_(n−1)(s0 − δ/σ)` (N/m)."""
        n = self.exponent
        x = self._interference(delta)
        return n * self.stiffness_coefficient * gaussian_smoothed_power(x, self.sigma, n - 1.0)

    def potential(self, delta: ArrayLike) -> Array:
        """`U = K σ^(n+1) F_(n+1)(s0 − δ/σ)/(n + 1)` (J); `K δ_+^(n+1)/(n+1)` at σ = 0.

        From `dF_(n+1)/dh = −(n+1) F_n`: `dU/dδ = K σ^n F_n(s0 − δ/σ) = F_e`.
        """
        n = self.exponent
        x = self._interference(delta)
        return (
            self.stiffness_coefficient * gaussian_smoothed_power(x, self.sigma, n + 1.0) / (n + 1.0)
        )

    def onset_penetration(self) -> Array:
        """`(s0 − 3) σ`, where a clearance joint counts "in contact". The force there is not
        negligible against the force nearby: `F_n(3)/F_n(2)` = 4.0 % of its value one σ deeper
        (n = 1.5; 4.5 % for n = 1) and 6.1e-4 of its value at δ = s0 σ (`F_1.5(3)/F_1.5(0)`;
        scipy quadrature, tests/test_contact_elastic.py). Hence `RevoluteClearance` holds v⁻
        past a separation rather than switching this tail of the force off."""
        return (self.offset - ONSET_SIGMAS) * self.sigma


@jax.custom_jvp
def _rough_force(law: RoughElastic, delta):
    return law.quadrature_force(delta)


def _rough_force_jvp(primals, tangents):
    """`dF_e = k_d(δ) dδ + (∂F_e/∂law) dlaw`, elementwise in δ.

    Forward-mode derivatives along many directions of δ at once (the iteration matrix of an
    implicit step: one direction per coordinate group) would otherwise push each direction
    through the 64-node quadrature; here the quadrature of `k_d` (`stiffness`, the same rule
    of order n − 1) is evaluated once and each direction costs one product. The law's own
    parameters (K, σ, s0; e.g. gradients in Ra) are differentiated through the quadrature as
    before, and skipped when their tangents are symbolically zero (as in the iteration
    matrix)."""
    law, delta = primals
    law_dot, delta_dot = tangents
    force = law.quadrature_force(delta)
    tangent = jnp.zeros_like(force)
    if not isinstance(delta_dot, SymbolicZero):
        tangent = tangent + law.stiffness(delta) * delta_dot
    law_leaves = jax.tree_util.tree_leaves(law_dot, is_leaf=lambda x: isinstance(x, SymbolicZero))
    if not all(isinstance(leaf, SymbolicZero) for leaf in law_leaves):
        law_dot = jax.tree_util.tree_map(
            lambda t: jnp.zeros(t.shape, t.dtype) if isinstance(t, SymbolicZero) else t,
            law_dot,
            is_leaf=lambda x: isinstance(x, SymbolicZero),
        )
        tangent = tangent + jax.jvp(lambda m: m.quadrature_force(delta), (law,), (law_dot,))[1]
    return force, tangent


_rough_force.defjvp(_rough_force_jvp, symbolic_zeros=True)
