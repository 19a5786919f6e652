"""Composing a clearance joint's contact laws from scene parameters (trace time)."""

from __future__ import annotations

from .. import contact
from .base import is_exactly_zero

NORMAL_LAWS = {
    "hunt_crossley": contact.HuntCrossley,
    "lankarani_nikravesh": contact.LankaraniNikravesh,
    "flores": contact.Flores,
    "gonthier": contact.Gonthier,
    "hu_guo": contact.HuGuo,
}


def clearance_contact_laws(
    *,
    journal_radius,
    clearance,
    youngs_modulus,
    poisson_ratio,
    sigma,
    restitution,
    friction_coefficient,
    normal_law: str = "lankarani_nikravesh",
    slip_velocity=1e-3,
    roughness_offset=0.0,
):
    """Normal and friction laws for a journal in a bearing of the same material.

    Hertz stiffness `K = (4/3) E* sqrt(R*)` from the geometry (so gradients reach the
    clearance through K); the rough (GW-averaged) elastic law unless σ is exactly 0, in which
    case plain Hertz is traced; no friction law at all when μ is exactly 0.

    **Returns:** `(normal_law, friction_law_or_None)`.
    """
    if normal_law not in NORMAL_LAWS:
        raise ValueError(
            f"normal_law = {normal_law!r} is invalid; valid: {', '.join(sorted(NORMAL_LAWS))}"
        )
    stiffness = contact.journal_bearing_stiffness(
        journal_radius, clearance, youngs_modulus, poisson_ratio, youngs_modulus, poisson_ratio
    )
    if is_exactly_zero(sigma):
        elastic = contact.HertzElastic(stiffness)
    else:
        elastic = contact.RoughElastic(stiffness, sigma, offset=roughness_offset)
    normal = NORMAL_LAWS[normal_law](elastic=elastic, restitution=restitution)
    friction = (
        None
        if is_exactly_zero(friction_coefficient)
        else contact.SmoothCoulomb(mu=friction_coefficient, slip_velocity=slip_velocity)
    )
    return normal, friction
