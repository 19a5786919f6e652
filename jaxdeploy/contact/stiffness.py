"""Hertz contact stiffness of a journal (pin) in a bearing (hole), from material and geometry.

**The π-convention trap.** The same stiffness is written two ways in the clearance-joint
literature:

* Flores et al.: `K = 4 / (3 (s_b + s_j)) · sqrt(R*)` with `s_k = (1 − ν_k²)/E_k`, i.e.
  `K = (4/3) E* sqrt(R*)`;
* Lankarani & Nikravesh (1990): `K = 4 / (3π (h_b + h_j)) · sqrt(R*)` with
  `h_k = (1 − ν_k²)/(π E_k)`.

The two are the same number because the π in `h_k` cancels the π in the prefactor. Mixing them
— a π-containing `h_k` in the formula without π, or the reverse — changes K by a factor π
(≈ 3.14). Published code does this (ladisk/DyS `contact_model.py`: its plane–sphere K carries
the π, its sphere–sphere K does not). We compute `(4/3) E* sqrt(R*)` directly and test it
against both written forms.
"""

from __future__ import annotations

import jax.numpy as jnp

from .._validation import check_positive, check_range, is_concrete

__all__ = [
    "effective_modulus",
    "journal_bearing_stiffness",
    "effective_radius",
    "radial_clearance",
]


def _check_material(name: str, modulus, poisson):
    check_positive(f"E_{name}", modulus, unit="Pa")
    check_range(f"nu_{name}", poisson, -1.0, 0.5, low_inclusive=False, high_inclusive=False)


def effective_modulus(E_journal, nu_journal, E_bearing, nu_bearing):
    """Effective (contact) modulus `E*` of two elastic bodies.

    **Arguments:**

    - `E_journal`, `E_bearing`: Young's moduli (Pa), > 0.
    - `nu_journal`, `nu_bearing`: Poisson's ratios, in (−1, 0.5).

    **Returns:** `E*` (Pa), from `1/E* = (1 − ν_j²)/E_j + (1 − ν_b²)/E_b`.

    **References:** Johnson, *Contact Mechanics* (1985), eq. 4.22.
    """
    _check_material("journal", E_journal, nu_journal)
    _check_material("bearing", E_bearing, nu_bearing)
    compliance = (1.0 - nu_journal**2) / E_journal + (1.0 - nu_bearing**2) / E_bearing
    return 1.0 / compliance


def radial_clearance(radius_bearing, radius_journal):
    """Radial clearance `c = R_b − R_j` of a journal (pin) in a bearing (hole), checked.

    **Arguments:** `radius_bearing` `R_b` (m) > 0, `radius_journal` `R_j` (m) > 0, `R_j < R_b`.

    **Returns:** `c` (m). Raises `ValueError` naming both radii when the journal does not fit.

    **References:** Flores et al., *Kinematics and Dynamics of Multibody Systems with Imperfect
    Joints* (Springer, 2008).
    """
    check_positive("radius_bearing", radius_bearing, unit="m")
    check_positive("radius_journal", radius_journal, unit="m")
    if is_concrete((radius_bearing, radius_journal)):
        r_b = float(radius_bearing)
        r_j = float(radius_journal)
        if not r_j < r_b:
            raise ValueError(
                f"radius_journal = {r_j!r} m is invalid: the journal must be smaller than its "
                f"bearing, i.e. in (0, {r_b!r}) m (radius_bearing = {r_b!r} m); the radial "
                f"clearance R_b - R_j = {r_b - r_j!r} m must be > 0."
            )
    return jnp.asarray(radius_bearing, dtype=float) - jnp.asarray(radius_journal, dtype=float)


def effective_radius(radius_journal, clearance):
    """Effective radius of a journal in a bearing, `R* = R_j R_b / (R_b − R_j) = R_j R_b / c`.

    **Arguments:**

    - `radius_journal`: pin radius `R_j` (m), > 0.
    - `clearance`: radial clearance `c = R_b − R_j` (m), > 0.

    **Returns:** `R*` (m). Conformal contact: `R*` is large (≈ R_j²/c), hence a stiff joint.

    **References:** Flores et al., *Kinematics and Dynamics of Multibody Systems with Imperfect
    Joints* (Springer, 2008).
    """
    check_positive("radius_journal", radius_journal, unit="m")
    check_positive("clearance", clearance, unit="m")
    radius_bearing = radius_journal + clearance
    return radius_journal * radius_bearing / clearance


def journal_bearing_stiffness(
    radius_journal, clearance, E_journal, nu_journal, E_bearing, nu_bearing
):
    """Hertz stiffness `K` of a journal in a bearing, for the force law `F = K δ^(3/2)`.

    **Arguments:**

    - `radius_journal`: pin radius `R_j` (m), > 0.
    - `clearance`: radial clearance `c` (m), > 0; the bearing radius is `R_b = R_j + c`.
    - `E_journal`, `nu_journal`, `E_bearing`, `nu_bearing`: elastic constants (Pa, −).

    **Returns:** `K = (4/3) E* sqrt(R*)` in N/m^1.5, with `R* = R_j R_b/(R_b − R_j)` and
    `1/E* = Σ (1 − ν_k²)/E_k`. Differentiable in all arguments (`∂K/∂c = −K/(2c)·R_j/R_b`).

    This is the point-contact (sphere) law applied to the conformal cylinder pair, as throughout
    the clearance-joint literature; it over-predicts stiffness for very small c (Pereira et al.,
    *Nonlinear Dyn.* 63 (2011) 681). Do **not** insert the Lankarani–Nikravesh
    `h_k = (1 − ν_k²)/(π E_k)` here: that form needs a `1/π` in the prefactor as well (module
    docstring).

    **References:**

    - Lankarani, Nikravesh, *J. Mech. Des.* 112 (1990) 369 (the π form).
    - Flores et al. (2008), *Kinematics and Dynamics of Multibody Systems with Imperfect Joints*.
    - Johnson, *Contact Mechanics* (1985), eq. 4.22.
    """
    e_star = effective_modulus(E_journal, nu_journal, E_bearing, nu_bearing)
    r_star = effective_radius(radius_journal, clearance)
    return (4.0 / 3.0) * e_star * jnp.sqrt(r_star)
