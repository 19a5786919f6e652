"""Ideal joints: holonomic constraints `Φ(q, t) = 0` (Nikravesh 1988, ch. 3–4).

Each joint names its two bodies and a point (by name, or body-frame coordinates) on each.
Either body may be `"ground"`.
"""

from __future__ import annotations

from typing import ClassVar

import jax.numpy as jnp

from ._fields import param, static
from .bodies import Kinematics, rotation
from .element import AbstractElement

PointRef = str | tuple[float, float]


class Revolute(AbstractElement):
    """Pin joint: point `point_a` of `body_a` coincides with `point_b` of `body_b`.

    `Φ = r_Pa − r_Pb` (2 equations).
    """

    body_a: str = static()
    point_a: PointRef = static()
    body_b: str = static()
    point_b: PointRef = static()
    n_constraints: ClassVar[int] = 2

    def constraint(self, kin: Kinematics, t):
        return kin.position(self.body_a, self.point_a) - kin.position(self.body_b, self.point_b)

    def bodies(self):
        return (self.body_a, self.body_b)


class Prismatic(AbstractElement):
    """Slider: `body_b` translates along `axis` (body-frame unit vector of `body_a`) without
    relative rotation.

    `Φ = [θ_b − θ_a − θ_0,  n_a · (r_Pb − r_Pa)]` with `n_a = A_a perp(axis)` and `θ_0` the
    relative angle to keep (default 0).
    """

    body_a: str = static()
    point_a: PointRef = static()
    body_b: str = static()
    point_b: PointRef = static()
    axis: tuple[float, float] = static(default=(1.0, 0.0))
    relative_angle: float = param(default=0.0)
    n_constraints: ClassVar[int] = 2

    def constraint(self, kin: Kinematics, t):
        axis = jnp.asarray(self.axis, dtype=float)
        axis = axis / jnp.linalg.norm(axis)
        normal = rotation(kin.angle(self.body_a)) @ jnp.array([-axis[1], axis[0]])
        d = kin.position(self.body_b, self.point_b) - kin.position(self.body_a, self.point_a)
        angle = kin.angle(self.body_b) - kin.angle(self.body_a) - self.relative_angle
        return jnp.stack([angle, jnp.dot(normal, d)])

    def bodies(self):
        return (self.body_a, self.body_b)


class Weld(AbstractElement):
    """Rigid connection (3 equations): `point_b` of `body_b` at `point_a` of `body_a`, and the
    relative angle `θ_b − θ_a` held at `relative_angle`."""

    body_a: str = static()
    point_a: PointRef = static()
    body_b: str = static()
    point_b: PointRef = static()
    relative_angle: float = param(default=0.0)
    n_constraints: ClassVar[int] = 3

    def constraint(self, kin: Kinematics, t):
        d = kin.position(self.body_a, self.point_a) - kin.position(self.body_b, self.point_b)
        angle = kin.angle(self.body_b) - kin.angle(self.body_a) - self.relative_angle
        return jnp.concatenate([d, angle[None]])

    def bodies(self):
        return (self.body_a, self.body_b)


class AngleDriver(AbstractElement):
    """Driving constraint: `θ_b − θ_a = angle0 + speed·t` (1 equation; rheonomic).

    Used for the slider-crank's crank at constant speed, and (with `speed = 0`) to fix a pose
    while assembling.
    """

    body_a: str = static()
    body_b: str = static()
    angle0: float = param()
    speed: float = param(default=0.0)
    n_constraints: ClassVar[int] = 1
    rheonomic: ClassVar[bool] = True

    def constraint(self, kin: Kinematics, t):
        rel = kin.angle(self.body_b) - kin.angle(self.body_a)
        return (rel - self.angle0 - self.speed * t)[None]

    def bodies(self):
        return (self.body_a, self.body_b)
