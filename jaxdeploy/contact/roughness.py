"""Roughness parameters: Ra ↔ σ for Gaussian profiles, combining surfaces, and optional
differentiable couplings of friction and restitution to Ra.

All lengths in metres (Ra 1.6 µm = 1.6e-6).
"""

from __future__ import annotations

import math

import equinox as eqx
import jax.numpy as jnp
from jax import Array
from jax.typing import ArrayLike

from .._validation import check_nonnegative, check_positive, check_range

__all__ = [
    "ra_to_sigma",
    "sigma_to_ra",
    "combine_sigma",
    "RoughnessCoupling",
    "RestitutionRoughnessCoupling",
]

# Smallest restitution the c_e(Ra) coupling returns (keeps c_e inside (0, 1] in float64).
RESTITUTION_FLOOR = 1e-6

# For a Gaussian profile, Ra = E|z| = sqrt(2/π) σ.
_SIGMA_PER_RA = math.sqrt(math.pi / 2.0)


def ra_to_sigma(ra: ArrayLike) -> Array:
    """Standard deviation σ (= Rq) of a Gaussian profile with arithmetic roughness Ra.

    **Arguments:** `ra`: Ra ≥ 0 (m).

    **Returns:** `σ = sqrt(π/2) Ra ≈ 1.2533 Ra` (m).

    Why: for a zero-mean Gaussian height z, `Ra = E|z| = sqrt(2/π) σ`
    (Ra 0.8/1.6/3.2 µm → σ 1.00/2.01/4.01 µm).
    """
    check_nonnegative("ra", ra, unit="m")
    return _SIGMA_PER_RA * jnp.asarray(ra, dtype=float)


def sigma_to_ra(sigma: ArrayLike) -> Array:
    """Arithmetic roughness `Ra = sqrt(2/π) σ` of a Gaussian profile (inverse of `ra_to_sigma`).

    **Arguments:** `sigma`: σ ≥ 0 (m). **Returns:** Ra (m).
    """
    check_nonnegative("sigma", sigma, unit="m")
    return jnp.asarray(sigma, dtype=float) / _SIGMA_PER_RA


def combine_sigma(sigma_1: ArrayLike, sigma_2: ArrayLike) -> Array:
    """Combined roughness of two Gaussian surfaces, `σ = sqrt(σ_1² + σ_2²)`.

    Two rough surfaces in contact act as one rough surface (σ) on a smooth one.

    **Arguments:** `sigma_1`, `sigma_2`: σ ≥ 0 of each surface (m).

    **Returns:** σ (m). The gradient is finite everywhere; at `σ_1 = σ_2 = 0`, where the
    function has no derivative, it is defined as 0.

    **References:** Greenwood, Williamson, *Proc. R. Soc. A* 295 (1966) 300.
    """
    check_nonnegative("sigma_1", sigma_1, unit="m")
    check_nonnegative("sigma_2", sigma_2, unit="m")
    s1 = jnp.asarray(sigma_1, dtype=float)
    s2 = jnp.asarray(sigma_2, dtype=float)
    squared = s1 * s1 + s2 * s2
    positive = squared > 0
    return jnp.where(positive, jnp.sqrt(jnp.where(positive, squared, 1.0)), 0.0)


def _ratio_power(ra, reference_ra, exponent):
    """`(Ra/Ra_ref)^p`, finite with finite gradient at Ra = 0 (value 1 if p = 0, else 0/∞)."""
    check_nonnegative("ra", ra, unit="m")
    ra = jnp.asarray(ra, dtype=float)
    positive = ra > 0
    log_ratio = jnp.log(jnp.where(positive, ra, reference_ra) / reference_ra)
    at_zero = jnp.where(exponent == 0, 1.0, jnp.where(exponent > 0, 0.0, jnp.inf))
    return jnp.where(positive, jnp.exp(exponent * log_ratio), at_zero)


class RoughnessCoupling(eqx.Module):
    """Power-law coupling of a coefficient to roughness: `value(Ra) = base (Ra/Ra_ref)^p`.

    For μ(Ra) (W24 reports higher initial friction for rougher surfaces, without a formula).
    The default `sensitivity = 0` is the identity. Both fields are array leaves, so the
    sensitivity can be identified from data and Ra optimised through it.

    **Arguments:**

    - `reference_ra`: Ra_ref > 0 (m), where `value = base`.
    - `sensitivity`: exponent p (default 0 = no coupling).

    Call: `coupling(base_value, ra) -> base_value (Ra/Ra_ref)^p`.

    **References:** none: a proposal of ours (no published law; docs/contact.md).
    """

    reference_ra: Array = eqx.field(converter=lambda x: jnp.asarray(x, dtype=float))
    sensitivity: Array = eqx.field(converter=lambda x: jnp.asarray(x, dtype=float), default=0.0)

    def __check_init__(self):
        check_positive("reference_ra", self.reference_ra, unit="m")
        check_range("sensitivity", self.sensitivity)

    def __call__(self, base_value: ArrayLike, ra: ArrayLike) -> Array:
        return base_value * _ratio_power(ra, self.reference_ra, self.sensitivity)


class RestitutionRoughnessCoupling(eqx.Module):
    """Coupling of the restitution to roughness that keeps c_e in (0, 1].

    `c_e(Ra) = c_base^((Ra/Ra_ref)^p)`, i.e. the logarithmic loss `−ln c_e` scales as
    `(Ra/Ra_ref)^p`. Positive p: rougher surfaces dissipate more (W24's qualitative claim);
    `p = 0` (default) is the identity; `c_base = 1` stays 1 (nothing to scale). Smooth in Ra,
    p and c_base, with finite gradients for c_base ∈ (0, 1]. Results are floored at
    `RESTITUTION_FLOOR = 1e-6` (far outside any physical use; avoids underflow to 0).

    **Arguments:**

    - `reference_ra`: Ra_ref > 0 (m), where `c_e = c_base`.
    - `sensitivity`: exponent p (default 0).

    Call: `coupling(base_restitution, ra) -> c_e(Ra)`.

    **References:** none: a proposal of ours (docs/contact.md).
    """

    reference_ra: Array = eqx.field(converter=lambda x: jnp.asarray(x, dtype=float))
    sensitivity: Array = eqx.field(converter=lambda x: jnp.asarray(x, dtype=float), default=0.0)

    def __check_init__(self):
        check_positive("reference_ra", self.reference_ra, unit="m")
        check_range("sensitivity", self.sensitivity)

    def __call__(self, base_restitution: ArrayLike, ra: ArrayLike) -> Array:
        check_range("restitution", base_restitution, 0.0, 1.0, low_inclusive=False)
        scale = _ratio_power(ra, self.reference_ra, self.sensitivity)
        restitution = jnp.exp(jnp.log(jnp.asarray(base_restitution, dtype=float)) * scale)
        # Floor: c_base^huge underflows to 0, and χ(0) is infinite for Flores/Gonthier/Hu–Guo.
        return jnp.maximum(restitution, RESTITUTION_FLOOR)
