"""Tangential friction laws `F_T(v_t, F_N)` for the clearance joint, and the state-based
LuGre laws `F(v, z, F_N)` (their bristle deflection z a state of the mechanism).

Every law returns the *signed* friction magnitude along +t: odd in the sliding speed `v_t`
(m/s) and bounded by `μ_max F_N`. The caller applies it against sliding, i.e. the journal gets
`−F_T t` (Flores et al. 2008). All laws are smooth enough that gradients are finite at `v_t = 0`:
the sign is regularised with an explicit slip velocity, never `tanh(100 v)`-style hidden widths
(those gave NaN identification gradients, https://github.com/isaac-sim/IsaacSim/issues/839).
"""

from __future__ import annotations

import abc
from typing import ClassVar, Literal

import equinox as eqx
import jax.numpy as jnp
from jax import Array
from jax.typing import ArrayLike

from .._validation import check_nonnegative, check_positive, is_concrete

__all__ = [
    "AbstractFrictionLaw",
    "regularized_sign",
    "SmoothCoulomb",
    "AmbrosioCoulomb",
    "StribeckFriction",
    "LuGreFriction",
    "LuGreContactFriction",
]


def _float_array(x):
    return jnp.asarray(x, dtype=float)


def regularized_sign(v, slip_velocity, shape: str = "algebraic"):
    """Smooth sign function with width `v_s`.

    **Arguments:**

    - `v`: speed (m/s).
    - `slip_velocity`: `v_s` > 0 (m/s).
    - `shape`: `"algebraic"` → `v/sqrt(v² + v_s²)` (default), `"tanh"` → `tanh(v/v_s)`.

    **Returns:** a C^∞, odd function of `v` with values in (−1, 1).

    **References:** Pennestrì et al., *Nonlinear Dyn.* 83 (2016) 1785; Marques et al.,
    *Nonlinear Dyn.* 86 (2016) 1407 (recalled, unverified).
    """
    v = jnp.asarray(v, dtype=float)
    if shape == "algebraic":
        return v / jnp.sqrt(v * v + slip_velocity**2)
    if shape == "tanh":
        return jnp.tanh(v / slip_velocity)
    raise ValueError(f"shape = {shape!r} is invalid: use 'algebraic' or 'tanh'.")


class AbstractFrictionLaw(eqx.Module):
    """`force(v_t, normal_force) -> F_T`, signed along +t, `|F_T| ≤ μ_max F_N`."""

    @abc.abstractmethod
    def force(self, v_t: ArrayLike, normal_force: ArrayLike) -> Array:
        """Signed friction magnitude (N)."""


class SmoothCoulomb(AbstractFrictionLaw):
    """Regularised Coulomb friction `F_T = μ F_N s(v_t)`, `s` a smooth sign of width `v_s`.

    **Arguments:**

    - `mu`: μ ≥ 0.
    - `slip_velocity`: `v_s` > 0 (m/s), default 1e-3. Explicit on purpose: it is the
      regularisation width, and a differentiable hyperparameter.
    - `shape`: static, `"algebraic"` (`v/sqrt(v² + v_s²)`, default) or `"tanh"`.

    **References:** Pennestrì et al., *Nonlinear Dyn.* 83 (2016) 1785; Marques et al.,
    *Nonlinear Dyn.* 86 (2016) 1407 (recalled, unverified); docs/contact.md.
    """

    mu: Array = eqx.field(converter=_float_array)
    slip_velocity: Array = eqx.field(converter=_float_array, default=1e-3)
    shape: Literal["algebraic", "tanh"] = eqx.field(static=True, default="algebraic")

    def __check_init__(self):
        check_nonnegative("mu", self.mu)
        check_positive("slip_velocity", self.slip_velocity, unit="m/s")
        if self.shape not in ("algebraic", "tanh"):
            raise ValueError(f"shape = {self.shape!r} is invalid: use 'algebraic' or 'tanh'.")

    def force(self, v_t: ArrayLike, normal_force: ArrayLike) -> Array:
        """`μ F_N s(v_t)` (N)."""
        return self.mu * normal_force * regularized_sign(v_t, self.slip_velocity, self.shape)


class AmbrosioCoulomb(AbstractFrictionLaw):
    """Ambrósio's modified Coulomb law `F_T = μ c_d(|v_t|) F_N sign(v_t)`.

    `c_d = 0` for `|v_t| ≤ v0`, `(|v_t| − v0)/(v1 − v0)` between, 1 above `v1` (no stiction).
    `transition="smoothstep"` replaces the ramp by the C¹ `c_d = s²(3 − 2s)`.

    The dynamic correction acts on the *speed* `|v_t|`: the DyS code applies it to the signed
    `v_t`, which gives `c_d = 0` for all negative `v_t` (friction only in one direction) — a
    bug we do not copy (ladisk/DyS `friction_model.py`). Since `c_d = 0` near `v_t = 0`, the
    sign's jump is never seen and the gradient at `v_t = 0` is 0.

    **Arguments:**

    - `mu`: μ ≥ 0.
    - `v0`, `v1`: tolerance velocities (m/s), `0 ≤ v0 < v1`; defaults 1e-4, 1e-3.
    - `transition`: static, `"linear"` (the published law, default) or `"smoothstep"`.

    **References:** Ambrósio, *Virtual Nonlinear Multibody Systems* (2003) (recalled, unverified);
    Flores et al. (2008).
    """

    mu: Array = eqx.field(converter=_float_array)
    v0: Array = eqx.field(converter=_float_array, default=1e-4)
    v1: Array = eqx.field(converter=_float_array, default=1e-3)
    transition: Literal["linear", "smoothstep"] = eqx.field(static=True, default="linear")

    def __check_init__(self):
        check_nonnegative("mu", self.mu)
        check_nonnegative("v0", self.v0, unit="m/s")
        check_positive("v1 - v0", self.v1 - self.v0, unit="m/s")
        if self.transition not in ("linear", "smoothstep"):
            raise ValueError(
                f"transition = {self.transition!r} is invalid: use 'linear' or 'smoothstep'."
            )

    def dynamic_correction(self, v_t: ArrayLike) -> Array:
        """`c_d(|v_t|) ∈ [0, 1]`."""
        speed = jnp.abs(jnp.asarray(v_t, dtype=float))
        s = jnp.clip((speed - self.v0) / (self.v1 - self.v0), 0.0, 1.0)
        if self.transition == "smoothstep":
            return s * s * (3.0 - 2.0 * s)
        return s

    def force(self, v_t: ArrayLike, normal_force: ArrayLike) -> Array:
        """`μ c_d(|v_t|) F_N sign(v_t)` (N)."""
        v_t = jnp.asarray(v_t, dtype=float)
        return self.mu * self.dynamic_correction(v_t) * normal_force * jnp.sign(v_t)


class StribeckFriction(AbstractFrictionLaw):
    """Smooth Coulomb friction with a Stribeck peak at low speed.

    `F_T = F_N s(v_t) [μ_k + (μ_s − μ_k) exp(−(v_t/v_st)²)]`, `s(v) = v/sqrt(v² + v_s²)`.

    **Arguments:**

    - `mu_static`: μ_s ≥ 0 (peak, reached for `v_s ≪ |v_t| ≪ v_st`).
    - `mu_kinetic`: μ_k ≥ 0 (sliding).
    - `stribeck_velocity`: `v_st` > 0 (m/s).
    - `slip_velocity`: `v_s` > 0 (m/s), regularisation width of the sign (≪ v_st).

    `|F_T| ≤ max(μ_s, μ_k) F_N`.

    **References:** Bengisu, Akay; Stribeck (1902) (recalled, unverified).
    """

    mu_static: Array = eqx.field(converter=_float_array)
    mu_kinetic: Array = eqx.field(converter=_float_array)
    stribeck_velocity: Array = eqx.field(converter=_float_array)
    slip_velocity: Array = eqx.field(converter=_float_array, default=1e-4)

    def __check_init__(self):
        check_nonnegative("mu_static", self.mu_static)
        check_nonnegative("mu_kinetic", self.mu_kinetic)
        check_positive("stribeck_velocity", self.stribeck_velocity, unit="m/s")
        check_positive("slip_velocity", self.slip_velocity, unit="m/s")

    def coefficient(self, v_t: ArrayLike) -> Array:
        """Speed-dependent coefficient `μ(v_t) = μ_k + (μ_s − μ_k) exp(−(v_t/v_st)²)`."""
        ratio = jnp.asarray(v_t, dtype=float) / self.stribeck_velocity
        return self.mu_kinetic + (self.mu_static - self.mu_kinetic) * jnp.exp(-ratio * ratio)

    def force(self, v_t: ArrayLike, normal_force: ArrayLike) -> Array:
        """`μ(v_t) F_N s(v_t)` (N)."""
        sign = regularized_sign(v_t, self.slip_velocity)
        return self.coefficient(v_t) * normal_force * sign


class LuGreFriction(eqx.Module):
    """The LuGre friction law (Canudas de Wit, Olsson, Åström & Lischinsky, *IEEE Trans.
    Autom. Control* 40 (1995) 419): contact through elastic bristles of mean deflection z [m],

        ż = v − σ0 |v| z / g(v),          g(v) = F_N (μ_C + (μ_S − μ_C) e^{−(v/v_S)²})
        F = σ0 z + σ1 ż + σ2 v            (signed along +v, N)

    with the Coulomb and static levels written as coefficients times the normal force F_N.
    At rest under a tangential load F < μ_S F_N the bristles deflect by z = F/σ0 and the
    contact sticks (no creep, unlike a regularised Coulomb law); at constant sliding speed
    z → g(v) sgn(v)/σ0 and F → g(v) sgn(v) + σ2 v (Coulomb + Stribeck + viscous). z is a
    state of the mechanism: `jaxdeploy.mechanism.HingeFriction` keeps it as a continuous
    internal state, integrated with the equations of motion.

    **Arguments** (defaults: the example of Canudas de Wit et al. 1995, §IV, recalled, with
    F_C = 1 N and F_S = 1.5 N written as μ_S = 1.5 μ_C):

    - `mu_coulomb` μ_C ≥ 0 (default 0.05, the scenes' hinge friction), `mu_static` μ_S ≥ μ_C
      (default 0.075);
    - `stribeck_velocity` v_S > 0 [m/s] (default 1e-3);
    - `bristle_stiffness` σ0 > 0 [N/m] (default 1e5);
    - `bristle_damping` σ1 ≥ 0 [N s/m] (default √1e5 ≈ 316);
    - `viscous` σ2 ≥ 0 [N s/m] (default 0.4).
    """

    mu_coulomb: Array = eqx.field(converter=_float_array, default=0.05)
    mu_static: Array = eqx.field(converter=_float_array, default=0.075)
    stribeck_velocity: Array = eqx.field(converter=_float_array, default=1e-3)
    bristle_stiffness: Array = eqx.field(converter=_float_array, default=1e5)
    bristle_damping: Array = eqx.field(converter=_float_array, default=316.22776601683796)
    viscous: Array = eqx.field(converter=_float_array, default=0.4)

    def __check_init__(self):
        check_nonnegative("mu_coulomb", self.mu_coulomb)
        check_nonnegative("mu_static", self.mu_static)
        check_positive("stribeck_velocity", self.stribeck_velocity, unit="m/s")
        check_positive("bristle_stiffness", self.bristle_stiffness, unit="N/m")
        check_nonnegative("bristle_damping", self.bristle_damping, unit="N s/m")
        check_nonnegative("viscous", self.viscous, unit="N s/m")
        if is_concrete(self.mu_static) and is_concrete(self.mu_coulomb):
            if float(self.mu_static) < float(self.mu_coulomb):
                raise ValueError(
                    f"mu_static = {float(self.mu_static)} is invalid: it must be ≥ mu_coulomb "
                    f"= {float(self.mu_coulomb)}"
                )

    def steady_level(self, v: ArrayLike, normal_force: ArrayLike) -> Array:
        """`g(v)` [N], the sliding friction without its viscous part."""
        v = jnp.asarray(v, dtype=float)
        stribeck = jnp.exp(-((v / self.stribeck_velocity) ** 2))
        return normal_force * (self.mu_coulomb + (self.mu_static - self.mu_coulomb) * stribeck)

    def rate(self, v: ArrayLike, z: ArrayLike, normal_force: ArrayLike) -> Array:
        """`ż = v − σ0 |v| z / g(v)` [m/s]."""
        v = jnp.asarray(v, dtype=float)
        return v - self.bristle_stiffness * jnp.abs(v) * z / self.steady_level(v, normal_force)

    def force(self, v: ArrayLike, z: ArrayLike, normal_force: ArrayLike) -> Array:
        """`F = σ0 z + σ1 ż + σ2 v` [N], signed along +v."""
        zdot = self.rate(v, z, normal_force)
        return self.bristle_stiffness * z + self.bristle_damping * zdot + self.viscous * v

    def steady_force(self, v: ArrayLike, normal_force: ArrayLike) -> Array:
        """The sliding force at constant `v`: `g(v) sgn(v) + σ2 v` [N]."""
        v = jnp.asarray(v, dtype=float)
        return self.steady_level(v, normal_force) * jnp.sign(v) + self.viscous * v


class LuGreContactFriction(eqx.Module):
    """The LuGre law for a contact whose normal force varies (a clearance joint's): the law of
    Canudas de Wit, Olsson, Åström & Lischinsky (*IEEE Trans. Autom. Control* 40 (1995) 419,
    the equations of `LuGreFriction`) with the bristle force written per unit normal force,

        ż = v − σ0 |v| z / g(v),          g(v) = μ_C + (μ_S − μ_C) e^{−(v/v_S)²}
        F = F_N (σ0 z + σ1 ż + σ2 v)      (signed along +v, N)

    so σ0 [1/m], σ1 [s/m], σ2 [s/m] and the friction *coefficient* μ = σ0 z + σ1 ż + σ2 v is
    what the bristles carry; this is the form multibody codes use for joint friction with a
    varying normal load (e.g. Altair MotionSolve's LuGre joint friction:
    μ = σ0 z + σ1 ż + σ2 v, force μ F_N). For a constant F_N it is `LuGreFriction` with
    σ0 F_N, σ1 F_N, σ2 F_N and the levels μ F_N (tests/test_lugre.py checks this). Unlike that
    form, z does not depend on F_N: a contact that opens (F_N = 0, no friction) keeps a finite
    bristle state that relaxes along the sliding path over ~g/σ0, and a closing contact starts
    from it, with no 1/F_N in the state equation.

    At rest under a tangential load F < μ_S F_N the contact sticks (σ0 z = F/F_N, presliding
    displacement ≤ μ_S/σ0); at constant sliding speed z → g(v) sgn(v)/σ0 and
    F → F_N (g(v) sgn v + σ2 v). As σ0 → ∞ (σ1/σ0 fixed) the presliding displacement vanishes
    and the law tends to Coulomb's F_N g(v) sgn v (with μ_S = μ_C, σ2 = 0: exactly
    μ F_N sgn v).

    **Arguments** (defaults: the example of Canudas de Wit et al. 1995, §IV, recalled —
    F_C = 1 N, F_S = 1.5 N, σ0 = 1e5 N/m, σ1 = √1e5 N s/m, v_S = 1e-3 m/s — at the normal
    force F_N = F_C/μ_C = 20 N that gives μ_C = 0.05, the scenes' hinge friction: the same
    presliding displacement F_C/σ0 = 10 µm and bristle time constant σ1/σ0 = 3.2 ms; σ2 = 0,
    so that the steady sliding level is the Coulomb + Stribeck one):

    - `mu_coulomb` μ_C ≥ 0 (default 0.05), `mu_static` μ_S ≥ μ_C (default 0.075);
    - `stribeck_velocity` v_S > 0 [m/s] (default 1e-3);
    - `bristle_stiffness` σ0 > 0 [1/m] (default 5e3);
    - `bristle_damping` σ1 ≥ 0 [s/m] (default 5e3/√1e5 ≈ 15.8);
    - `viscous` σ2 ≥ 0 [s/m] (default 0).
    """

    mu_coulomb: Array = eqx.field(converter=_float_array, default=0.05)
    mu_static: Array = eqx.field(converter=_float_array, default=0.075)
    stribeck_velocity: Array = eqx.field(converter=_float_array, default=1e-3)
    bristle_stiffness: Array = eqx.field(converter=_float_array, default=5e3)
    bristle_damping: Array = eqx.field(converter=_float_array, default=15.811388300841896)
    viscous: Array = eqx.field(converter=_float_array, default=0.0)
    # A clearance joint keeps z as a continuous internal state (`RevoluteClearance`).
    has_state: ClassVar[bool] = True

    def __check_init__(self):
        check_nonnegative("mu_coulomb", self.mu_coulomb)
        check_nonnegative("mu_static", self.mu_static)
        check_positive("stribeck_velocity", self.stribeck_velocity, unit="m/s")
        check_positive("bristle_stiffness", self.bristle_stiffness, unit="1/m")
        check_nonnegative("bristle_damping", self.bristle_damping, unit="s/m")
        check_nonnegative("viscous", self.viscous, unit="s/m")
        if is_concrete(self.mu_static) and is_concrete(self.mu_coulomb):
            if float(self.mu_static) < float(self.mu_coulomb):
                raise ValueError(
                    f"mu_static = {float(self.mu_static)} is invalid: it must be ≥ mu_coulomb "
                    f"= {float(self.mu_coulomb)}"
                )
            if float(self.mu_coulomb) <= 0.0:
                raise ValueError(
                    f"mu_coulomb = {float(self.mu_coulomb)} is invalid: the bristle law "
                    "divides by the friction level; it must be > 0 (no friction: no law)"
                )

    def steady_level(self, v: ArrayLike) -> Array:
        """`g(v)`, the sliding friction coefficient without its viscous part."""
        v = jnp.asarray(v, dtype=float)
        stribeck = jnp.exp(-((v / self.stribeck_velocity) ** 2))
        return self.mu_coulomb + (self.mu_static - self.mu_coulomb) * stribeck

    def rate(self, v: ArrayLike, z: ArrayLike) -> Array:
        """`ż = v − σ0 |v| z / g(v)` [m/s] (independent of the normal force)."""
        v = jnp.asarray(v, dtype=float)
        return v - self.bristle_stiffness * jnp.abs(v) * z / self.steady_level(v)

    def coefficient(self, v: ArrayLike, z: ArrayLike) -> Array:
        """`μ = σ0 z + σ1 ż + σ2 v`, the friction force per unit normal force."""
        zdot = self.rate(v, z)
        return self.bristle_stiffness * z + self.bristle_damping * zdot + self.viscous * v

    def force(self, v: ArrayLike, z: ArrayLike, normal_force: ArrayLike) -> Array:
        """`F = F_N μ(v, z)` [N], signed along +v."""
        return normal_force * self.coefficient(v, z)

    def steady_force(self, v: ArrayLike, normal_force: ArrayLike) -> Array:
        """The sliding force at constant `v`: `F_N (g(v) sgn(v) + σ2 v)` [N]."""
        v = jnp.asarray(v, dtype=float)
        return normal_force * (self.steady_level(v) * jnp.sign(v) + self.viscous * v)
