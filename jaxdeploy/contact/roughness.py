"""Roughness parameters: Ra ↔ σ for Gaussian profiles, combining surfaces, friction from the
roughness of a turned surface (adhesion + ploughing), and a free coupling of restitution to Ra.

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
    "turned_feed",
    "turned_profile_slope",
    "PloughingFriction",
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


# Ra of a turned profile of parabolic scallops of pitch f (the feed) cut by a tool nose of
# radius r: Ra = f² / (18 √3 r) (≈ f²/(31.2 r)); derivation in `turned_feed`.
_TURNED_RA_FACTOR = 18.0 * math.sqrt(3.0)


def turned_feed(ra: ArrayLike, nose_radius: ArrayLike) -> Array:
    """Feed per revolution f that leaves a kinematic (ideal) turned profile of roughness Ra.

    The profile is a row of scallops of pitch f cut by the tool nose of radius r_ε; as
    parabolas `z = x²/(2 r_ε)`, |x| ≤ f/2, their mean height is f²/(24 r_ε) and the arithmetic
    deviation from it is

        Ra = f² / (18 √3 r_ε) ≈ f² / (31.2 r_ε),   Rz = f² / (8 r_ε),

    the machining handbooks' ideal roughness of turning (Ra ≈ 0.0321 f²/r_ε, e.g. Boothroyd &
    Knight, *Fundamentals of Machining and Machine Tools*, 3rd ed., 2006). Hence
    `f = sqrt(18 √3 r_ε Ra)`.

    **Arguments:** `ra`: Ra ≥ 0 (m); `nose_radius`: r_ε > 0 (m).

    **Returns:** f (m). Valid while the scallops are shallow arcs: for f ≤ r_ε/2 the parabola's
    Ra is within 1.3 % of the circular arc's (5.6 % at f = r_ε; tests/test_contact_roughness.py
    measures both). Real
    turned surfaces are rougher than kinematic (built-up edge, vibration, the minimum chip
    thickness), so for a measured Ra this feed is an upper bound.
    """
    check_nonnegative("ra", ra, unit="m")
    check_positive("nose_radius", nose_radius, unit="m")
    ra = jnp.asarray(ra, dtype=float)
    positive = ra > 0
    # sqrt has no derivative at 0: evaluate at a dummy value there and return 0 (gradient 0).
    f = jnp.sqrt(_TURNED_RA_FACTOR * nose_radius * jnp.where(positive, ra, 1.0))
    return jnp.where(positive, f, 0.0)


def turned_profile_slope(ra: ArrayLike, nose_radius: ArrayLike) -> Array:
    """Mean absolute profile slope Δa (ISO 4287 R∆a) of a kinematic turned profile of Ra.

    The parabolic scallop `z = x²/(2 r_ε)` has slope x/r_ε, whose mean magnitude over
    |x| ≤ f/2 is f/(4 r_ε); with f from `turned_feed`:

        Δa = f / (4 r_ε) = sqrt(18 √3 Ra / (16 r_ε)) ≈ 1.396 sqrt(Ra / r_ε).

    **Arguments:** `ra` (m), `nose_radius` r_ε (m). **Returns:** Δa (dimensionless, = tan of
    the mean slope angle). Within 1.6 % of the circular arc's for f ≤ r_ε/2 (Δa ≤ 1/8).
    """
    return turned_feed(ra, nose_radius) / (4.0 * jnp.asarray(nose_radius, dtype=float))


class PloughingFriction(eqx.Module):
    """Friction coefficient of a machined (turned) surface from its roughness: adhesion plus
    ploughing by the asperities,

        μ(Ra) = μ_a + (2/π) Δa(Ra),   Δa = sqrt(18 √3 Ra / (16 r_ε))  (`turned_profile_slope`).

    The ploughing term is Bowden and Tabor's for a hard conical asperity of semi-angle α
    sliding through a plastic counterface (*The Friction and Lubrication of Solids*, Oxford
    1950, ch. V): the flow pressure p acts on the front half of the indentation, so the normal
    load is p π a²/2 and the ploughing force p a² cot α, μ_p = (2/π) cot α; an asperity's
    slope is tan θ = cot α, and we take the profile's mean slope Δa for it. That μ follows the
    slope rather than Ra is what Menezes, Kishore and Kailas measured (*Sadhana* 33 (2008) 181:
    for one texture μ did not vary with Ra, across textures it followed Δa): the coupling to
    Ra is through the machining process, here a turned surface of tool nose radius r_ε, for
    which Δa grows as sqrt(Ra).

    **Arguments:**

    - `adhesion`: μ_a ≥ 0, the interfacial-shear (adhesion) part, a property of the pair and
      its lubricant that no roughness relation gives: it stays a free parameter.
    - `nose_radius`: r_ε > 0 (m) of the finishing tool (inserts: 0.2–1.6 mm).

    Call: `friction(ra) -> μ`. Both fields are array leaves (fit μ_a; differentiate in Ra).

    **Range of validity:** shallow asperities and a small ploughing term (Δa ≤ 1/8, i.e.
    f ≤ r_ε/2 and Ra ≤ `max_ra` = r_ε/(72 √3), where the parabolic profile is within 2 % of
    the circular one; r_ε = 0.8 mm: Ra ≤ 6.4 µm); the counterface yields at
    the asperity contacts (plasticity index above ~1: true for steel at Ra ≥ 0.1 µm with
    any realistic asperity radius); dry or boundary-lubricated sliding, not hydrodynamic.
    The two terms are simply added, as Bowden and Tabor do, ignoring their interaction.
    """

    adhesion: Array = eqx.field(converter=lambda x: jnp.asarray(x, dtype=float))
    nose_radius: Array = eqx.field(converter=lambda x: jnp.asarray(x, dtype=float))

    def __check_init__(self):
        check_nonnegative("adhesion", self.adhesion)
        check_positive("nose_radius", self.nose_radius, unit="m")

    @property
    def max_ra(self) -> Array:
        """Largest Ra of the range of validity (f = r_ε/2), m."""
        return self.nose_radius / (4.0 * _TURNED_RA_FACTOR)

    def __call__(self, ra: ArrayLike) -> Array:
        return self.adhesion + (2.0 / math.pi) * turned_profile_slope(ra, self.nose_radius)


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

    **References:** none. We found no published closed-form relation between restitution
    and Ra for metal journals: rough-surface impact models ("Normal impact model of rough
    surfaces", *J. Tribol.* 114 (1992) 439, whose abstract reports that dissipation grows with
    roughness, compliance and impact speed) need the
    asperity radius and density and a plastic unloading law, which a machining drawing does
    not give. So p is a free parameter to fit or to sweep (docs/contact.md).
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
