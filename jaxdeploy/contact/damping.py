"""Damped normal-force laws `F_N(δ, δ', v⁻)` built on an elastic law `F_e(δ)`.

Restitution-calibrated family (Lankarani & Nikravesh 1990, eq. for F_N; docs/contact.md):

    F_N = max(0, F_e(δ) · (1 + χ(c_e) δ' / v⁻))

with δ' the penetration rate (> 0 approaching), v⁻ the approach speed latched at the onset of
the current contact (a memory variable the caller keeps, see `AbstractElasticLaw.
onset_penetration`) and χ the law's hysteresis factor. The `max(0, ·)` removes the spurious
tensile force these laws predict just before separation. Below the law's
`impact_velocity_floor` (m/s) the damping term divides by the floor instead of v⁻, so a contact
that begins at rest keeps a finite damping coefficient. Also a memoryless law (Hunt–Crossley
with material damping α) and an undamped one.

All laws are `eqx.Module`s: `elastic` is any elastic law module, numbers are array leaves.
`needs_impact_velocity` (ClassVar) tells the mechanism whether to carry the v⁻ memory.
"""

from __future__ import annotations

import abc
from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp
from jax import Array
from jax.typing import ArrayLike

from .._validation import check_nonnegative, check_positive, check_range
from .elastic import AbstractElasticLaw

__all__ = [
    "DEFAULT_IMPACT_VELOCITY_FLOOR",
    "AbstractNormalLaw",
    "AbstractRestitutionLaw",
    "Undamped",
    "HuntCrossley",
    "LankaraniNikravesh",
    "Flores",
    "Gonthier",
    "HuGuo",
    "HuntCrossleyMaterial",
]

# Default of `impact_velocity_floor` (m/s): the smallest impact velocity the damping term
# divides by. Hinge impacts run at mm/s to m/s; a contact that begins at rest (v⁻ = 0) would get
# an unbounded damping coefficient χ K δⁿ/v⁻. Above the floor the law is exactly the published
# one (v_eff = max(v⁻, floor)); a slower impact is damped as if it came in at the floor speed,
# i.e. less than nominal.
DEFAULT_IMPACT_VELOCITY_FLOOR = 1e-4


def _float_array(x):
    return jnp.asarray(x, dtype=float)


class AbstractNormalLaw(eqx.Module):
    """A normal contact law: `force(delta, delta_dot, impact_velocity) -> F_N ≥ 0` (N).

    `delta` (m) is the penetration (< 0: gap), `delta_dot` (m/s) its rate (> 0: approaching),
    `impact_velocity` (m/s) the approach speed latched at contact onset (ignored by laws with
    `needs_impact_velocity = False`).
    """

    elastic: eqx.AbstractVar[AbstractElasticLaw]
    needs_impact_velocity: ClassVar[bool]

    @abc.abstractmethod
    def force(self, delta: ArrayLike, delta_dot: ArrayLike, impact_velocity=None) -> Array:
        """Normal force `F_N ≥ 0` (N)."""


class AbstractRestitutionLaw(AbstractNormalLaw):
    """`F_N = max(0, F_e(δ) (1 + χ(c_e) δ'/v⁻))`; subclasses give the hysteresis factor χ.

    **References:** Hunt, Crossley, *J. Appl. Mech.* 42 (1975) 440; Lankarani, Nikravesh,
    *J. Mech. Des.* 112 (1990) 369; χ forms as collected in docs/contact.md.
    """

    restitution: eqx.AbstractVar[Array]
    impact_velocity_floor: eqx.AbstractVar[Array]
    needs_impact_velocity: ClassVar[bool] = True

    def __check_init__(self):
        check_range("restitution", self.restitution, 0.0, 1.0, low_inclusive=False)
        check_positive("impact_velocity_floor", self.impact_velocity_floor, "m/s")

    @abc.abstractmethod
    def chi(self) -> Array:
        """Dimensionless hysteresis factor χ(c_e)."""

    def force(self, delta: ArrayLike, delta_dot: ArrayLike, impact_velocity=None) -> Array:
        """`F_N = max(0, F_e(δ) (1 + χ δ'/v_eff))`, `v_eff = max(v⁻, impact_velocity_floor)`
        (N)."""
        if impact_velocity is None:
            raise TypeError(
                f"{type(self).__name__} needs impact_velocity (the approach speed at contact "
                "onset); use HuntCrossleyMaterial for a memoryless law."
            )
        v_eff = jnp.maximum(jnp.asarray(impact_velocity, dtype=float), self.impact_velocity_floor)
        ratio = jnp.asarray(delta_dot, dtype=float) / v_eff
        return jnp.maximum(0.0, self.elastic.force(delta) * (1.0 + self.chi() * ratio))


class HuntCrossley(AbstractRestitutionLaw):
    """Hunt–Crossley: `χ = 3(1 − c_e)/2`.

    **Arguments:** `elastic` (elastic law), `restitution` c_e ∈ (0, 1],
    `impact_velocity_floor` (m/s, > 0; default 1e-4).

    **References:** Hunt, Crossley, *J. Appl. Mech.* 42 (1975) 440, in the form used by MBS
    reviews (second-hand: not checked in the 1975 paper).
    """

    elastic: AbstractElasticLaw
    restitution: Array = eqx.field(converter=_float_array)
    impact_velocity_floor: Array = eqx.field(
        converter=_float_array, default=DEFAULT_IMPACT_VELOCITY_FLOOR
    )

    def chi(self) -> Array:
        return 1.5 * (1.0 - self.restitution)


class LankaraniNikravesh(AbstractRestitutionLaw):
    """Lankarani–Nikravesh: `χ = 3(1 − c_e²)/4`. Valid only for c_e near 1 (small losses).

    **Arguments:** `elastic` (elastic law), `restitution` c_e ∈ (0, 1],
    `impact_velocity_floor` (m/s, > 0; default 1e-4).

    **References:** Lankarani, Nikravesh, *J. Mech. Des.* 112 (1990) 369.
    """

    elastic: AbstractElasticLaw
    restitution: Array = eqx.field(converter=_float_array)
    impact_velocity_floor: Array = eqx.field(
        converter=_float_array, default=DEFAULT_IMPACT_VELOCITY_FLOOR
    )

    def chi(self) -> Array:
        return 0.75 * (1.0 - self.restitution**2)


class Flores(AbstractRestitutionLaw):
    """Flores et al. (2011): `χ = 8(1 − c_e)/(5 c_e)`. Diverges as c_e → 0.

    **Arguments:** `elastic` (elastic law), `restitution` c_e ∈ (0, 1],
    `impact_velocity_floor` (m/s, > 0; default 1e-4).

    **References:** Flores, Machado, Silva, Martins, *Multibody Syst. Dyn.* 25 (2011) 357.
    """

    elastic: AbstractElasticLaw
    restitution: Array = eqx.field(converter=_float_array)
    impact_velocity_floor: Array = eqx.field(
        converter=_float_array, default=DEFAULT_IMPACT_VELOCITY_FLOOR
    )

    def chi(self) -> Array:
        return 1.6 * (1.0 - self.restitution) / self.restitution


class Gonthier(AbstractRestitutionLaw):
    """Gonthier et al. (2004): `χ = (1 − c_e²)/c_e`.

    **Arguments:** `elastic` (elastic law), `restitution` c_e ∈ (0, 1],
    `impact_velocity_floor` (m/s, > 0; default 1e-4).

    **References:** Gonthier, McPhee, Lange, Piedbœuf, *Multibody Syst. Dyn.* 11 (2004) 209
    (recalled, unverified).
    """

    elastic: AbstractElasticLaw
    restitution: Array = eqx.field(converter=_float_array)
    impact_velocity_floor: Array = eqx.field(
        converter=_float_array, default=DEFAULT_IMPACT_VELOCITY_FLOOR
    )

    def chi(self) -> Array:
        return (1.0 - self.restitution**2) / self.restitution


class HuGuo(AbstractRestitutionLaw):
    """Hu–Guo (2015): `χ = 3(1 − c_e)/(2 c_e)` — **UNVERIFIED** against the paper.

    The paper's text was not available to us. `3(1 − c_e)/(2 c_e)` is the form recalled from
    the literature (recalled, unverified); the DyS code
    (ladisk/DyS `contact_model.py`) implements `(3/2)(1 − c_e)/(2 c_e) = 3(1 − c_e)/(4 c_e)`.
    We keep the recalled form: only it has the small-loss limit `χ → 3(1 − c_e)/2` shared by
    Hunt–Crossley, Lankarani–Nikravesh and Flores (the DyS form halves it). See docs/contact.md.

    **Arguments:** `elastic` (elastic law), `restitution` c_e ∈ (0, 1],
    `impact_velocity_floor` (m/s, > 0; default 1e-4).

    **References:** Hu, Guo, *Multibody Syst. Dyn.* 35 (2015) 131,
    doi:10.1007/s11044-015-9453-z (not checked).
    """

    elastic: AbstractElasticLaw
    restitution: Array = eqx.field(converter=_float_array)
    impact_velocity_floor: Array = eqx.field(
        converter=_float_array, default=DEFAULT_IMPACT_VELOCITY_FLOOR
    )

    def chi(self) -> Array:
        return 1.5 * (1.0 - self.restitution) / self.restitution


class HuntCrossleyMaterial(AbstractNormalLaw):
    """Memoryless Hunt–Crossley law with material damping: `F_N = max(0, F_e (1 + 1.5 α δ'))`.

    No impact-velocity memory; the effective restitution falls with impact speed,
    `c_e ≈ 1 − α v⁻` for small α v⁻ (Marhefka–Orin: λ = 1.5 α K).

    **Arguments:** `elastic` (elastic law), `alpha` α ≥ 0 (s/m).

    **References:** Hunt, Crossley (1975); Marhefka, Orin, *IEEE Trans. SMC A* 29 (1999) 566
    (second-hand).
    """

    elastic: AbstractElasticLaw
    alpha: Array = eqx.field(converter=_float_array)
    needs_impact_velocity: ClassVar[bool] = False

    def __check_init__(self):
        check_nonnegative("alpha", self.alpha, unit="s/m")

    def force(self, delta: ArrayLike, delta_dot: ArrayLike, impact_velocity=None) -> Array:
        """`F_N = max(0, F_e(δ)(1 + 1.5 α δ'))` (N); `impact_velocity` is ignored."""
        damping = 1.0 + 1.5 * self.alpha * jnp.asarray(delta_dot, dtype=float)
        return jnp.maximum(0.0, self.elastic.force(delta) * damping)


class Undamped(AbstractNormalLaw):
    """No dissipation: `F_N = F_e(δ)`.

    **Arguments:** `elastic` (elastic law).
    """

    elastic: AbstractElasticLaw
    needs_impact_velocity: ClassVar[bool] = False

    def force(self, delta: ArrayLike, delta_dot: ArrayLike = 0.0, impact_velocity=None) -> Array:
        """`F_N = F_e(δ)` (N); the rates are ignored."""
        return self.elastic.force(delta)
