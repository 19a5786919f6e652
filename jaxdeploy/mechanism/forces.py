"""Force elements: gravity, springs and dampers, the coil-spring drive, applied loads, the latch.

Forces enter the equations of motion as generalized forces `Q(q, v, t)`; a force `f` at point
P of body k contributes `(f_x, f_y, (r_P − r_k) × f)` to body k (Nikravesh 1988).
"""

from __future__ import annotations

from typing import ClassVar

import jax.numpy as jnp

from .._validation import check_nonnegative, check_positive
from ._fields import param, static
from .bodies import GROUND, Kinematics
from .element import AbstractElement, Wrench
from .joints import PointRef


class Gravity(AbstractElement):
    """Uniform gravity `m g` on every moving body (off in the array scenes: it deploys in orbit).

    **Arguments:** `acceleration`: `g` as a 2-vector [m/s²], default `(0, −9.81)`.
    """

    acceleration: tuple = param(default=(0.0, -9.81))

    def wrenches(self, kin: Kinematics, t, memory):
        return [Wrench(body=b.name, force=b.mass * self.acceleration) for b in kin.mechanism.bodies]

    def coupled_bodies(self):
        # Constant forces: they depend on no coordinate, so the iteration matrix has no term.
        return ()

    def potential_energy(self, kin: Kinematics, memory):
        """`V = −Σ m_k g·r_k`."""
        g = jnp.asarray(self.acceleration)
        return -sum(b.mass * jnp.dot(g, kin.origin(b.name)) for b in kin.mechanism.bodies)


class Spring(AbstractElement):
    """Linear point-to-point spring–damper between `point_a` of `body_a` and `point_b` of `body_b`.

    `f = (k (ℓ − ℓ₀) + c ℓ̇) u` pulls the points together when stretched, `u` the unit vector from
    P_a to P_b, `ℓ = |r_Pb − r_Pa|`.
    """

    body_a: str = static()
    point_a: PointRef = static()
    body_b: str = static()
    point_b: PointRef = static()
    stiffness: float = param()
    rest_length: float = param()
    damping: float = param(default=0.0)

    def __check_init__(self):
        check_nonnegative("Spring.stiffness", self.stiffness, "N/m")
        check_nonnegative("Spring.damping", self.damping, "N s/m")

    def wrenches(self, kin: Kinematics, t, memory):
        pa, pb = kin.position(self.body_a, self.point_a), kin.position(self.body_b, self.point_b)
        d = pb - pa
        length = jnp.sqrt(jnp.dot(d, d) + 1e-30)
        u = d / length
        rate = jnp.dot(
            kin.velocity(self.body_b, self.point_b) - kin.velocity(self.body_a, self.point_a), u
        )
        tension = self.stiffness * (length - self.rest_length) + self.damping * rate
        f = tension * u
        return [
            Wrench(self.body_a, force=f, point=pa),
            Wrench(self.body_b, force=-f, point=pb),
        ]

    def potential_energy(self, kin: Kinematics, memory):
        """`V = ½ k (ℓ − ℓ₀)²`."""
        d = kin.position(self.body_b, self.point_b) - kin.position(self.body_a, self.point_a)
        stretch = jnp.sqrt(jnp.dot(d, d) + 1e-30) - self.rest_length
        return 0.5 * self.stiffness * stretch**2

    def bodies(self):
        return (self.body_a, self.body_b)


def relative_angle(kin: Kinematics, body_a: str, body_b: str, offset):
    """`α = θ_b − θ_a − offset` and its rate."""
    angle = kin.angle(body_b) - kin.angle(body_a) - offset
    rate = kin.angular_velocity(body_b) - kin.angular_velocity(body_a)
    return angle, rate


def _torque_pair(body_a: str, body_b: str, torque) -> list[Wrench]:
    """`torque` on body_b, its reaction on body_a (the ground takes none)."""
    out = [Wrench(body_b, torque=torque)]
    if body_a != GROUND:
        out.append(Wrench(body_a, torque=-torque))
    return out


class RotationalSpring(AbstractElement):
    """Torsional spring–damper: torque `−k (α − α₀) − c α̇` on body_b (reaction on body_a),
    `α = θ_b − θ_a`."""

    body_a: str = static()
    body_b: str = static()
    stiffness: float = param()
    rest_angle: float = param(default=0.0)
    damping: float = param(default=0.0)

    def wrenches(self, kin: Kinematics, t, memory):
        alpha, rate = relative_angle(kin, self.body_a, self.body_b, self.rest_angle)
        return _torque_pair(self.body_a, self.body_b, -self.stiffness * alpha - self.damping * rate)

    def potential_energy(self, kin: Kinematics, memory):
        """`V = ½ k (α − α₀)²`."""
        alpha, _ = relative_angle(kin, self.body_a, self.body_b, self.rest_angle)
        return 0.5 * self.stiffness * alpha**2

    def bodies(self):
        return (self.body_a, self.body_b)


class CoilSpringDrive(AbstractElement):
    """Preloaded coil (torsion) spring at a hinge, the drive of a deployable array.

    `M(α) = k (α₀ − α) + k₃ (α₀ − α)³`, applied to body_b with the reaction on body_a, where
    `α = θ_b − θ_a − angle_offset` is the hinge angle and `α₀ > α` is the spring's free angle
    (the preload is `k (α₀ − α_start)`). The lock time of one panel,
    `arccos((α₀ − α_L)/(α₀ − α_s))/ω`, is checked in tests/test_mechanism.py.

    **Arguments:** `stiffness` k [N m/rad] ≥ 0, `free_angle` α₀ [rad], `cubic_stiffness` k₃
    [N m/rad³] (default 0), `angle_offset` [rad] (default 0).
    """

    body_a: str = static()
    body_b: str = static()
    stiffness: float = param()
    free_angle: float = param()
    cubic_stiffness: float = param(default=0.0)
    angle_offset: float = param(default=0.0)

    def __check_init__(self):
        check_nonnegative("CoilSpringDrive.stiffness", self.stiffness, "N m/rad")

    def hinge_angle(self, kin: Kinematics):
        return relative_angle(kin, self.body_a, self.body_b, self.angle_offset)[0]

    def wrenches(self, kin: Kinematics, t, memory):
        wind = self.free_angle - self.hinge_angle(kin)
        torque = self.stiffness * wind + self.cubic_stiffness * wind**3
        return _torque_pair(self.body_a, self.body_b, torque)

    def potential_energy(self, kin: Kinematics, memory):
        """`V = ½ k (α₀ − α)² + ¼ k₃ (α₀ − α)⁴` (so that `M = −dV/dα`)."""
        wind = self.free_angle - self.hinge_angle(kin)
        return 0.5 * self.stiffness * wind**2 + 0.25 * self.cubic_stiffness * wind**4

    def bodies(self):
        return (self.body_a, self.body_b)


class AppliedTorque(AbstractElement):
    """Constant torque on a body [N m]."""

    body: str = static()
    torque: float = param()

    def wrenches(self, kin: Kinematics, t, memory):
        return [Wrench(self.body, torque=self.torque)]

    def potential_energy(self, kin: Kinematics, memory):
        """`V = −τ θ` (a constant torque is conservative)."""
        return -self.torque * kin.angle(self.body)

    def bodies(self):
        return (self.body,)


class AppliedForce(AbstractElement):
    """Constant force (global components, N) at a point of a body."""

    body: str = static()
    point: PointRef = static()
    force: tuple = param()

    def wrenches(self, kin: Kinematics, t, memory):
        return [Wrench(self.body, force=self.force, point=kin.position(self.body, self.point))]

    def potential_energy(self, kin: Kinematics, memory):
        """`V = −f·r_P` (a constant force is conservative)."""
        return -jnp.dot(jnp.asarray(self.force), kin.position(self.body, self.point))

    def bodies(self):
        return (self.body,)


class Latch(AbstractElement):
    """Deployment latch: once the hinge angle reaches `lock_angle` it engages for good and
    holds the hinge with a stiff rotational spring–damper (a penalty model of ours;
    docs/deploy_array_geometry.md §7 sets its numbers):

    `τ = −k_L (α − α_L) − c_L α̇` on body_b when engaged, 0 before; `α = θ_b − θ_a − angle_offset`.

    Memory: `engaged` ∈ {0, 1}, updated after each accepted step (the step in which α first
    reaches α_L still runs unlatched; the next one latches at the overshoot, which is bounded by
    that step's rotation). `direction = +1` latches when α rises through α_L, `−1` when falling.
    """

    body_a: str = static()
    body_b: str = static()
    lock_angle: float = param()
    stiffness: float = param()
    damping: float = param(default=0.0)
    angle_offset: float = param(default=0.0)
    direction: int = static(default=1)
    has_memory: ClassVar[bool] = True
    # Engagement happens at a step boundary, at an overshoot bounded by that step's rotation.
    switch_flags: ClassVar[tuple[str, ...]] = ("engaged",)

    def __check_init__(self):
        check_positive("Latch.stiffness", self.stiffness, "N m/rad")
        check_nonnegative("Latch.damping", self.damping, "N m s/rad")

    def _angle(self, kin: Kinematics):
        return relative_angle(kin, self.body_a, self.body_b, self.angle_offset)

    def _reached(self, kin: Kinematics):
        alpha, _ = self._angle(kin)
        return self.direction * (alpha - self.lock_angle) >= 0

    def init_memory(self, kin: Kinematics):
        return {"engaged": jnp.where(self._reached(kin), 1.0, 0.0)}

    def memory_after_step(self, memory, kin: Kinematics, step):
        engaged = jnp.maximum(memory["engaged"], jnp.where(self._reached(kin), 1.0, 0.0))
        return {"engaged": engaged}

    def wrenches(self, kin: Kinematics, t, memory):
        alpha, rate = self._angle(kin)
        torque = -self.stiffness * (alpha - self.lock_angle) - self.damping * rate
        return _torque_pair(self.body_a, self.body_b, memory["engaged"] * torque)

    def potential_energy(self, kin: Kinematics, memory):
        """`V = ½ k_L (α − α_L)²` once engaged, 0 before. Engaging at an overshoot `α − α_L`
        puts `½ k_L (α − α_L)²` into the latch at once: energy the discrete engagement adds."""
        alpha, _ = self._angle(kin)
        return memory["engaged"] * 0.5 * self.stiffness * (alpha - self.lock_angle) ** 2

    def bodies(self):
        return (self.body_a, self.body_b)
