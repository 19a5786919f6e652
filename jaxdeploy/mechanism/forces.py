"""Force elements: gravity, springs and dampers, the coil-spring drive, applied loads, the
latches (angle-only `Latch`, `PreloadedLatch`).

Forces enter the equations of motion as generalized forces `Q(q, v, t)`; a force `f` at point
P of body k contributes `(f_x, f_y, (r_P − r_k) × f)` to body k (Nikravesh 1988).
"""

from __future__ import annotations

from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp

from .._validation import check_nonnegative, check_positive
from ._fields import param, static
from .bodies import CLOCK, GROUND, Kinematics, rotate
from .element import AbstractElement, Wrench
from .joints import PointRef

# The latch's crossing search: samples of the step that bracket the first crossing, then
# safeguarded Newton iterations in the bracket (1/16 of the step wide), as for contact onsets.
CROSSING_GRID = 16
CROSSING_NEWTON = 10


class Gravity(AbstractElement):
    """Uniform gravity `m g` on every moving body (off in the array scenes: it deploys in orbit),
    except the step-logging clock body of `add_clock`, which is not matter.

    **Arguments:** `acceleration`: `g` as a 2-vector [m/s²], default `(0, −9.81)`.
    """

    acceleration: tuple = param(default=(0.0, -9.81))
    conservative: ClassVar[bool] = True

    def wrenches(self, kin: Kinematics, t, memory):
        return [Wrench(body=b.name, force=b.mass * self.acceleration) for b in _massive(kin)]

    def coupled_bodies(self):
        # Constant forces: they depend on no coordinate, so the iteration matrix has no term.
        return ()

    def potential_energy(self, kin: Kinematics, memory):
        """`V = −Σ m_k g·r_k`."""
        g = jnp.asarray(self.acceleration)
        return -sum(b.mass * jnp.dot(g, kin.origin(b.name)) for b in _massive(kin))


def _massive(kin: Kinematics):
    """The bodies gravity acts on: every moving body but the clock."""
    return [b for b in kin.mechanism.bodies if b.name != CLOCK]


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
    conservative: ClassVar[bool] = True

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


class AbstractLatch(AbstractElement):
    """What every deployment latch shares: the hinge angle `α = θ_b − θ_a − angle_offset`,
    engagement for good when `direction·(α − α_L)` first reaches 0 (memory `engaged` ∈ {0,
    1}), and from then on the lock torque `τ = −k_L (α − α_L) − c_L α̇` on body_b (reaction on
    body_a). Subclasses (`Latch`, `PreloadedLatch`) declare the fields and add what they apply
    besides. They also have `damping` c_L, `angle_offset` and `direction` (fields with
    defaults, so declared by the subclasses alone: an abstract field here would fix their place
    in the constructor before the subclasses' own fields without defaults).

    **The engagement is an event located inside the step** (the literature's model: the latch
    engages when the angle reaches the stop; Li, Wang & Huang, *Mech. Syst. Signal Process.*
    117 (2019) 188), as a clearance joint's contact onset is (`jaxdeploy.solvers.LocateEvents`,
    `mechanism/_step_eccentricity.py`):

    * the latch acts wherever it is engaged *or* its angle has reached the stop, so inside the
      step in which α crosses α_L the torque starts at the crossing, as a function of the state
      (its stiffness part is continuous there, its damping part jumps by c_L α̇);
    * after each accepted step the crossing is located on the cubic Hermite interpolant of
      α(s) through the step's end values (α, α̇), s = (t − t₀)/h ∈ [0, 1], by a bracketing
      search and safeguarded Newton iterations; `event_fraction` reports it, and an adaptive
      run ends the step just past it;
    * the lock time `t* = t₀ + s* h` (memory `lock_time`, time since the run's start, `elapsed`
      the sum of the accepted steps) is differentiable: one Newton step from the
      gradient-stopped root carries the implicit-function derivative
      `ds*/dθ = −(∂g/∂θ)/(dg/ds)`, `g(s) = direction·(α(s) − α_L)`.
    """

    body_a: eqx.AbstractVar[str]
    body_b: eqx.AbstractVar[str]
    lock_angle: eqx.AbstractVar[float]
    stiffness: eqx.AbstractVar[float]
    has_memory: ClassVar[bool] = True

    def _angle(self, kin: Kinematics):
        return relative_angle(kin, self.body_a, self.body_b, self.angle_offset)

    def _reached(self, kin: Kinematics):
        alpha, _ = self._angle(kin)
        return self.direction * (alpha - self.lock_angle) >= 0

    def _engaged_at(self, kin: Kinematics):
        """`engaged` of a state from which no step has been taken yet."""
        return jnp.where(self._reached(kin), 1.0, 0.0)

    def _active(self, kin: Kinematics, memory):
        """1 where the latch acts: engaged, or past the stop inside the step that engages it."""
        return jnp.maximum(memory["engaged"], self._engaged_at(kin))

    def _init_event_memory(self, kin: Kinematics):
        alpha, rate = self._angle(kin)
        zero = jnp.zeros_like(alpha)
        return {
            "engaged": self._engaged_at(kin),
            "angle": alpha,
            "angle_rate": rate,
            "elapsed": zero,
            "lock_time": zero,
            "event_fraction": jnp.ones_like(alpha),
        }

    def _event_memory_after(self, memory, kin: Kinematics, step):
        """The memory after an accepted step of length `step` ending at `kin`: engaged for
        good once the stop is reached, and in the step that engages, the located crossing."""
        alpha, rate = self._angle(kin)
        engaged = jnp.maximum(memory["engaged"], self._engaged_at(kin))
        newly = (engaged > 0.5) & (memory["engaged"] < 0.5)
        step = jax.lax.stop_gradient(step)
        path = (memory["angle"], memory["angle_rate"], alpha, rate, step)
        s = jax.lax.cond(newly, lambda: self._crossing(*path), lambda: jnp.ones_like(alpha))
        return {
            "engaged": engaged,
            "angle": alpha,
            "angle_rate": rate,
            "elapsed": memory["elapsed"] + step,
            "lock_time": jnp.where(newly, memory["elapsed"] + s * step, memory["lock_time"]),
            "event_fraction": s,
        }

    def _crossing(self, alpha0, rate0, alpha1, rate1, step):
        """The first s ∈ [0, 1] where `g(s) = direction·(α(s) − α_L)` rises through 0 on the
        cubic Hermite interpolant (g(0) < 0 ≤ g(1)), with its implicit derivative (class
        docstring)."""

        def g_and_slope(s, a0, r0, a1, r1, lock):
            h00, h10 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s
            h01, h11 = -2 * s**3 + 3 * s**2, s**3 - s**2
            d00, d10 = 6 * s**2 - 6 * s, 3 * s**2 - 4 * s + 1
            d01, d11 = -6 * s**2 + 6 * s, 3 * s**2 - 2 * s
            value = h00 * a0 + h10 * step * r0 + h01 * a1 + h11 * step * r1
            slope = d00 * a0 + d10 * step * r0 + d01 * a1 + d11 * step * r1
            return self.direction * (value - lock), self.direction * slope

        ends = (alpha0, rate0, alpha1, rate1, self.lock_angle)
        frozen = [jax.lax.stop_gradient(x) for x in ends]
        samples = jnp.linspace(0.0, 1.0, CROSSING_GRID + 1)
        above = g_and_slope(samples, *frozen)[0] >= 0
        k = jnp.argmax(above[1:])  # the first sample interval whose right end is past the stop

        def newton_or_bisect(_, bracket):
            lo, hi, x = bracket
            f, slope = g_and_slope(x, *frozen)
            lo, hi = jnp.where(f < 0, x, lo), jnp.where(f < 0, hi, x)
            newton = x - f / jnp.where(slope > 0, slope, jnp.inf)
            ok = (slope > 0) & (newton > lo) & (newton < hi)
            return lo, hi, jnp.where(ok, newton, 0.5 * (lo + hi))

        lo, hi = samples[k], samples[k + 1]
        _, _, x = jax.lax.fori_loop(0, CROSSING_NEWTON, newton_or_bisect, (lo, hi, 0.5 * (lo + hi)))
        # One Newton step from the converged root: the implicit derivative ds*/dθ.
        f, slope = g_and_slope(x, *ends)
        return jnp.clip(x - f / jnp.where(slope > 0, slope, jnp.inf), 0.0, 1.0)

    def event_fraction(self, memory):
        """Where in the last accepted step the latch engaged (≥ 1: it did not)."""
        return memory["event_fraction"]

    def _lock_wrenches(self, kin: Kinematics, active) -> list:
        alpha, rate = self._angle(kin)
        torque = -self.stiffness * (alpha - self.lock_angle) - self.damping * rate
        return _torque_pair(self.body_a, self.body_b, active * torque)

    def bodies(self):
        return (self.body_a, self.body_b)


class Latch(AbstractLatch):
    """Deployment latch: once the hinge angle reaches `lock_angle` it engages for good and
    holds the hinge with a stiff rotational spring–damper (a penalty model of ours;
    docs/deploy_array_geometry.md §7 sets its numbers):

    `τ = −k_L (α − α_L) − c_L α̇` on body_b when engaged, 0 before; `α = θ_b − θ_a − angle_offset`.

    Memory: `engaged` ∈ {0, 1} and the located engagement (`AbstractLatch`: the torque acts
    from the crossing inside the step; `lock_time` [s since the run's start] is its
    differentiable time). `direction = +1` latches when α rises through α_L, `−1` when falling.
    """

    body_a: str = static()
    body_b: str = static()
    lock_angle: float = param()
    stiffness: float = param()
    damping: float = param(default=0.0)
    angle_offset: float = param(default=0.0)
    direction: int = static(default=1)

    def __check_init__(self):
        check_positive("Latch.stiffness", self.stiffness, "N m/rad")
        check_nonnegative("Latch.damping", self.damping, "N m s/rad")

    def init_memory(self, kin: Kinematics):
        return self._init_event_memory(kin)

    def memory_after_step(self, memory, kin: Kinematics, step):
        return self._event_memory_after(memory, kin, step)

    def wrenches(self, kin: Kinematics, t, memory):
        return self._lock_wrenches(kin, self._active(kin, memory))

    def potential_energy(self, kin: Kinematics, memory):
        """`V = ½ k_L (α − α_L)²` where the latch acts, 0 before: continuous at the stop, so
        the located engagement stores no energy."""
        alpha, _ = self._angle(kin)
        return self._active(kin, memory) * 0.5 * self.stiffness * (alpha - self.lock_angle) ** 2


class PreloadedLatch(AbstractLatch):
    """Deployment latch that holds the hinge angle *and* presses the hinge to one side of its
    clearance, as the spring-loaded latches of deployable arrays do (a roller or pawl driven
    by the latch spring into a notch of the hinge fitting; preloading the hinge removes its
    free play, a design principle of deployable mechanisms: Lake & Hachkowski, AIAA 2000-1409,
    "Mechanism design principles for optical-precision, deployable instruments", recalled).

    Once engaged (as `Latch`: for good, from the located instant at which
    `direction·(α − α_L)` reaches 0, `α = θ_b − θ_a − angle_offset`) it applies

    * the lock torque of the notch/stop `τ = −k_L (α − α_L) − c_L α̇` on body_b, the reaction
      on body_a (the latch model of Li, Wang & Huang, *Mech. Syst. Signal Process.* 117 (2019)
      188: a rotational spring–damper from the lock on);
    * the latch spring's preload `f = F_p A_r u(φ)`, `u(φ) = (cos φ, sin φ)`, on
      `preload_body` at its point P (the roller's contact point, body-frame coordinates
      `preload_point`), with the reaction `−f` on the other body (the roller's carrier, the
      "roller body" r, whose rotation A_r turns the direction). Its moment about the hinge
      is taken by the lock torque; its net force is taken by the hinge: an otherwise free
      journal is pressed into its bearing with F_p along u.

    The roller spring is modelled as a constant force: its rate times the travel left to it
    once the hinge is seated (at most the hinge clearance, tens of µm) is far below F_p.

    Memory: the located engagement (`AbstractLatch`) and `anchor`, P's position at the end of
    the engaging step in the roller body's frame (the reference of the preload's potential).

    **Arguments:** `body_a`, `body_b`: the hinge's bodies; `lock_angle` α_L [rad];
    `stiffness` k_L [N m/rad] ≥ 0 (0: the preload alone, for a hinge whose angle another
    latch holds); `damping` c_L [N m s/rad] ≥ 0; `preload` F_p [N] ≥ 0; `preload_body`
    (`body_a` or `body_b`); `preload_point` P [m, body frame of `preload_body`];
    `preload_angle` φ [rad], the direction of the force on `preload_body` in the roller
    body's frame; `angle_offset` [rad]; `direction` ±1.
    """

    body_a: str = static()
    body_b: str = static()
    lock_angle: float = param()
    stiffness: float = param()
    preload: float = param()
    preload_body: str = static()
    preload_point: tuple = param()
    preload_angle: float = param()
    damping: float = param(default=0.0)
    angle_offset: float = param(default=0.0)
    direction: int = static(default=1)

    def __check_init__(self):
        check_nonnegative("PreloadedLatch.stiffness", self.stiffness, "N m/rad")
        check_nonnegative("PreloadedLatch.damping", self.damping, "N m s/rad")
        check_nonnegative("PreloadedLatch.preload", self.preload, "N")
        if self.preload_body not in (self.body_a, self.body_b):
            raise ValueError(
                f"PreloadedLatch.preload_body = {self.preload_body!r} is invalid; valid: "
                f"{self.body_a!r} (body_a) or {self.body_b!r} (body_b)"
            )

    @property
    def roller_body(self) -> str:
        return self.body_b if self.preload_body == self.body_a else self.body_a

    def _point(self, kin: Kinematics):
        return kin.position(self.preload_body, self.preload_point)

    def _in_roller_frame(self, kin: Kinematics, world_point):
        """Body-frame coordinates, in the roller body, of a world point."""
        theta = kin.angle(self.roller_body)
        return rotate(-theta, world_point - kin.origin(self.roller_body))

    def _force(self, kin: Kinematics):
        """`f = F_p A_r u(φ)` on `preload_body` [N]."""
        u = jnp.stack([jnp.cos(self.preload_angle), jnp.sin(self.preload_angle)])
        return self.preload * rotate(kin.angle(self.roller_body), u)

    def init_memory(self, kin: Kinematics):
        anchor = self._in_roller_frame(kin, self._point(kin))
        return self._init_event_memory(kin) | {"anchor": anchor}

    def memory_after_step(self, memory, kin: Kinematics, step):
        out = self._event_memory_after(memory, kin, step)
        newly = (out["engaged"] > 0.5) & (memory["engaged"] < 0.5)
        here = self._in_roller_frame(kin, self._point(kin))
        return out | {"anchor": jnp.where(newly, here, memory["anchor"])}

    def wrenches(self, kin: Kinematics, t, memory):
        active = self._active(kin, memory)
        out = self._lock_wrenches(kin, active)
        f = active * self._force(kin)
        p = self._point(kin)
        out.append(Wrench(self.preload_body, force=f, point=p))
        if self.roller_body != GROUND:
            out.append(Wrench(self.roller_body, force=-f, point=p))
        return out

    def potential_energy(self, kin: Kinematics, memory):
        """Once engaged, `V = ½ k_L (α − α_L)² − f·(r_P − r_anchor)`, `r_anchor` the world
        position of the memory's anchor (fixed in the roller body): exact for a roller on the
        ground, and for a moving roller body up to the rotation of `f` times P's offset from
        the anchor (µm).

        Inside the step that engages the latch (acting from the crossing, its memory not yet
        engaged) the anchor is not set yet: the preload's potential is 0 there, so an energy
        meter books the preload's work over the rest of that step as work done, not as a jump
        of the potential measured from the run's initial anchor (on deploy_array that bogus
        jump was −2.7 J of a 4.2 J deployment, the whole balance's residual)."""
        alpha, _ = self._angle(kin)
        theta = kin.angle(self.roller_body)
        anchor = kin.origin(self.roller_body) + rotate(theta, memory["anchor"])
        work = jnp.dot(self._force(kin), self._point(kin) - anchor)
        work = jnp.where(memory["engaged"] > 0.5, work, 0.0)
        elastic = 0.5 * self.stiffness * (alpha - self.lock_angle) ** 2
        return self._active(kin, memory) * (elastic - work)


class HingeFriction(AbstractElement):
    """Friction torque of a hinge with a state-based friction law (e.g.
    `jaxdeploy.contact.LuGreFriction`) whose state z is integrated with the mechanism.

    The pin of radius r is pressed into its bore with the normal force F_N (e.g. a latch's
    preload); the sliding speed at the pin's surface is `v = r (θ̇_b − θ̇_a)` and the friction
    force `F(v, z, F_N)` of the law gives the torque `−r F` on body_b (reaction on body_a).
    The law's state z (for LuGre the bristle deflection, m) is the element's continuous
    internal state, `memory["internal"]["bristle"]`, with `ż` from `law.rate(v, z, F_N)`:
    only the index-1 solvers integrate it (`jaxdeploy.solvers.MechanismODESolver`;
    generalized-α refuses such mechanisms). It starts at 0 (unloaded bristles).

    Energy: no potential (the bristles' elastic energy ½ σ0 z² ≤ ½ (μ_S F_N)²/σ0 depends on
    the state z, not on q); `EnergyMeter` refuses elements with internal states.

    **Arguments:** `body_a`, `body_b`; `law` (duck-typed: `rate(v, z, F_N)` and
    `force(v, z, F_N)`); `normal_force` F_N [N] > 0; `radius` r [m] > 0.
    """

    body_a: str = static()
    body_b: str = static()
    law: object
    normal_force: float = param()
    radius: float = param()
    has_memory: ClassVar[bool] = True
    has_internal_state: ClassVar[bool] = True

    def __check_init__(self):
        check_positive("HingeFriction.normal_force", self.normal_force, "N")
        check_positive("HingeFriction.radius", self.radius, "m")

    def _speed(self, kin: Kinematics):
        """Sliding speed at the pin's surface [m/s]."""
        return self.radius * (kin.angular_velocity(self.body_b) - kin.angular_velocity(self.body_a))

    def init_memory(self, kin: Kinematics):
        return {"internal": {"bristle": jnp.zeros((), dtype=kin.q.dtype)}}

    def internal_rates(self, kin: Kinematics, t, memory):
        z = memory["internal"]["bristle"]
        return {"bristle": self.law.rate(self._speed(kin), z, self.normal_force)}

    def friction_force(self, kin: Kinematics, memory):
        """`F(v, z, F_N)` [N], signed along the relative sliding of body_b."""
        z = memory["internal"]["bristle"]
        return self.law.force(self._speed(kin), z, self.normal_force)

    def wrenches(self, kin: Kinematics, t, memory):
        torque = -self.radius * self.friction_force(kin, memory)
        return _torque_pair(self.body_a, self.body_b, torque)

    def bodies(self):
        return (self.body_a, self.body_b)
