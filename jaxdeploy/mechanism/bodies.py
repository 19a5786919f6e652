"""Rigid bodies in absolute planar coordinates, and the kinematics of their points.

Each moving body k has coordinates `q_k = (x_k, y_k, θ_k)`: its centre of mass and its rotation
from the global x axis. A point with body-frame coordinates `s'` sits at `r = r_k + A(θ_k) s'`
and moves with `ṙ = ṙ_k + θ̇_k B(θ_k) s'`, `B = dA/dθ` (Nikravesh, *Computer-Aided Analysis of
Mechanical Systems*, 1988, ch. 3; Flores et al. 2008).

The ground is the body named `"ground"`; its points are given in the global frame.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array

from .._validation import check_positive

GROUND = "ground"
# The bookkeeping body `add_clock` (meters.py) adds to log accepted steps: it is not matter,
# so body forces (gravity) leave it alone.
CLOCK = "clock"


def rotation(theta):
    """`A(θ) = [[cos θ, −sin θ], [sin θ, cos θ]]`."""
    c, s = jnp.cos(theta), jnp.sin(theta)
    return jnp.array([[c, -s], [s, c]])


def rotate(theta, vector):
    """`A(θ) s` written out elementwise: under `vmap`/`jacfwd` a 2 × 2 `@` becomes a batched
    `dot` that XLA's CPU backend runs as a separate kernel (measured: 37 of them in
    deploy_array's iteration matrix), where these products fuse with their neighbours."""
    c, s = jnp.cos(theta), jnp.sin(theta)
    return jnp.stack(
        [c * vector[..., 0] - s * vector[..., 1], s * vector[..., 0] + c * vector[..., 1]], axis=-1
    )


def perp(vector):
    """Rotate a 2-vector by +90°: `(x, y) ↦ (−y, x)` (so `B s' = A perp(s')`)."""
    return jnp.stack([-vector[..., 1], vector[..., 0]], axis=-1)


def cross(a, b):
    """Scalar planar cross product `a × b = a_x b_y − a_y b_x`."""
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


class Body(eqx.Module):
    """A rigid body with its mass properties and named attachment points.

    **Arguments:**
    - `name`: unique name (static; elements refer to bodies by name). `"ground"` is reserved.
    - `mass`: m [kg] > 0.
    - `inertia`: J about the centre of mass [kg m²] > 0.
    - `points`: `{name: (x', y')}` in the body frame [m], origin at the centre of mass.
    """

    name: str = eqx.field(static=True)
    mass: Array
    inertia: Array
    points: dict[str, Array]

    def __init__(self, name: str, mass, inertia, points=None):
        if name == GROUND:
            raise ValueError(f"body name {GROUND!r} is reserved for the fixed frame")
        self.name = name
        self.mass = jnp.asarray(check_positive(f"{name}.mass", mass, "kg"), dtype=float)
        self.inertia = jnp.asarray(check_positive(f"{name}.inertia", inertia, "kg m^2"), float)
        self.points = {k: jnp.asarray(v, dtype=float) for k, v in (points or {}).items()}


class Kinematics:
    """Positions and velocities of bodies and their points for one state `(q, v)`.

    A trace-time helper (plain Python object, never a pytree): element code asks it for the
    point it needs, so only what a mechanism uses ends up in the traced computation.
    """

    def __init__(self, mechanism, q, v=None):
        self.mechanism = mechanism
        self.q = q
        self.v = jnp.zeros_like(q) if v is None else v

    def _slice(self, body: str):
        k = self.mechanism.body_index(body)
        return slice(3 * k, 3 * k + 3)

    def local_point(self, body: str, point) -> Array:
        """Body-frame coordinates of `point` (a name or explicit coordinates)."""
        if isinstance(point, str):
            return self.mechanism.point(body, point)
        return jnp.asarray(point, dtype=float)

    def angle(self, body: str):
        if body == GROUND:
            return jnp.zeros((), dtype=self.q.dtype)
        return self.q[self._slice(body)][2]

    def angular_velocity(self, body: str):
        if body == GROUND:
            return jnp.zeros((), dtype=self.q.dtype)
        return self.v[self._slice(body)][2]

    def origin(self, body: str):
        if body == GROUND:
            return jnp.zeros(2, dtype=self.q.dtype)
        return self.q[self._slice(body)][:2]

    def position(self, body: str, point):
        """`r_P = r_k + A(θ_k) s'_P`."""
        s = self.local_point(body, point)
        if body == GROUND:
            return s
        qk = self.q[self._slice(body)]
        return qk[:2] + rotate(qk[2], s)

    def velocity(self, body: str, point):
        """`ṙ_P = ṙ_k + θ̇_k B(θ_k) s'_P`."""
        s = self.local_point(body, point)
        if body == GROUND:
            return jnp.zeros(2, dtype=self.q.dtype)
        qk, vk = self.q[self._slice(body)], self.v[self._slice(body)]
        return vk[:2] + vk[2] * perp(rotate(qk[2], s))
