"""Revolute joint with radial clearance: a journal moving freely inside a bearing until their
surfaces meet (Flores & Ambrósio 2004; Flores et al. 2008; DESIGN §2.2; LITERATURE §1.1).

With P_i the bearing centre (on `bearing_body`) and P_j the journal centre (on `journal_body`):

    e = r_Pj − r_Pi,  |e| = sqrt(e·e + ε²),  n = e/|e|,  t = (−n_y, n_x)
    δ = |e| − c                      (penetration; δ < 0 is a gap)
    Q_k = P_k + R_k n                (contact points; R_i = R_j + c is the bearing radius)
    v = ṙ_Qj − ṙ_Qi,   δ̇ = v·n,   v_t = v·t
    force on the journal −(F_N n + F_T t) at Q_j; the opposite on the bearing at Q_i.

`F_N` comes from the normal law (a `jaxdeploy.contact` damped law) and `F_T` from the friction
law; with `friction=None` no friction code is traced. ε (default 1e-12 m) keeps the centred
joint (e = 0) differentiable.

Memory (only for laws that need the impact velocity v⁻): `in_contact` and `impact_velocity`.
During a step that starts out of contact, v⁻ is the approach speed δ̇ at the step's start
(the speed just before impact); once in contact it is held until the surfaces separate, as in
Flores & Ambrósio (2010), except that it rises to any larger approach speed met during the
contact: v⁻ is the largest approach speed of the current contact. In an ordinary impact the
approach decelerates from v⁻ and nothing changes; but a contact that starts at rest (a centred
journal whose rough law is already past its onset, σ ≳ c/3, has δ̇ = 0 at t = 0) and is then
driven in would otherwise keep v⁻ = 0, i.e. the floor `VELOCITY_FLOOR`, and a damping term
χ δ̇/v⁻ thousands of times too large (it captured a 10 m/s impact). "In contact" means δ
beyond the elastic law's onset (0 for Hertz, about (s0 − 3)σ for the rough law).
"""

from __future__ import annotations

import jax.numpy as jnp

from .._validation import check_positive
from ._fields import param, static
from .bodies import Kinematics, perp
from .element import AbstractElement, Wrench
from .joints import PointRef, Revolute


class ClearanceGeometry:
    """Trace-time bundle of the joint's kinematic quantities for one state."""

    def __init__(self, joint: RevoluteClearance, kin: Kinematics):
        pi = kin.position(joint.bearing_body, joint.bearing_point)
        pj = kin.position(joint.journal_body, joint.journal_point)
        e = pj - pi
        norm_e = jnp.sqrt(jnp.dot(e, e) + joint.eccentricity_smoothing**2)
        n = e / norm_e
        t = perp(n)
        radius_bearing = joint.journal_radius + joint.clearance
        qi = pi + radius_bearing * n
        qj = pj + joint.journal_radius * n

        def contact_point_velocity(body, q_point):
            if body == "ground":
                return jnp.zeros(2)
            return kin.velocity(body, (0.0, 0.0)) + kin.angular_velocity(body) * perp(
                q_point - kin.origin(body)
            )

        v = contact_point_velocity(joint.journal_body, qj) - contact_point_velocity(
            joint.bearing_body, qi
        )
        self.eccentricity = e
        self.normal, self.tangent = n, t
        self.penetration = norm_e - joint.clearance
        self.penetration_rate = jnp.dot(v, n)
        self.sliding_velocity = jnp.dot(v, t)
        self.contact_point_bearing, self.contact_point_journal = qi, qj


class RevoluteClearance(AbstractElement):
    """Journal-in-bearing clearance joint.

    **Arguments:**
    - `bearing_body`, `bearing_point`: the body with the hole and the hole's centre.
    - `journal_body`, `journal_point`: the body with the pin and the pin's centre.
    - `clearance`: radial clearance c = R_b − R_j [m] > 0 (`contact.radial_clearance(R_b, R_j)`
      computes it from both radii and refuses a journal larger than its bearing).
    - `journal_radius`: pin radius R_j [m] > 0.
    - `normal`: a normal contact law from `jaxdeploy.contact` (e.g. `LankaraniNikravesh`).
    - `friction`: a friction law from `jaxdeploy.contact`, or `None` (frictionless).
    - `eccentricity_smoothing`: ε [m] in |e| = sqrt(e·e + ε²).
    """

    bearing_body: str = static()
    bearing_point: PointRef = static()
    journal_body: str = static()
    journal_point: PointRef = static()
    clearance: float = param()
    journal_radius: float = param()
    normal: object
    friction: object = None
    eccentricity_smoothing: float = param(default=1e-12)

    def __check_init__(self):
        check_positive("clearance", self.clearance, "m")
        check_positive("journal_radius", self.journal_radius, "m")
        # ε = 0 would make |e| = sqrt(e·e) non-differentiable (NaN gradient) at e = 0, where
        # every clearance scene starts (journal centred).
        check_positive("eccentricity_smoothing", self.eccentricity_smoothing, "m")

    @property
    def has_memory(self) -> bool:
        return bool(getattr(self.normal, "needs_impact_velocity", False))

    def bodies(self):
        return (self.bearing_body, self.journal_body)

    def geometry(self, kin: Kinematics) -> ClearanceGeometry:
        return ClearanceGeometry(self, kin)

    def _onset(self):
        return self.normal.elastic.onset_penetration()

    def init_memory(self, kin: Kinematics):
        if not self.has_memory:
            return None
        g = self.geometry(kin)
        return {
            "in_contact": jnp.where(g.penetration > self._onset(), 1.0, 0.0),
            "impact_velocity": jnp.maximum(g.penetration_rate, 0.0),
        }

    def memory_for_step(self, memory, kin: Kinematics):
        if not self.has_memory:
            return memory
        g = self.geometry(kin)
        approach = jnp.maximum(g.penetration_rate, 0.0)
        held = memory["in_contact"] > 0.5
        return {
            "in_contact": memory["in_contact"],
            "impact_velocity": jnp.where(
                held, jnp.maximum(memory["impact_velocity"], approach), approach
            ),
        }

    def memory_after_step(self, memory, kin: Kinematics):
        if not self.has_memory:
            return memory
        g = self.geometry(kin)
        return {
            "in_contact": jnp.where(g.penetration > self._onset(), 1.0, 0.0),
            "impact_velocity": memory["impact_velocity"],
        }

    def contact_forces(self, kin: Kinematics, memory):
        """`(F_N, F_T, geometry)` at state `kin`."""
        g = self.geometry(kin)
        v_minus = None if memory is None else memory["impact_velocity"]
        fn = self.normal.force(g.penetration, g.penetration_rate, v_minus)
        ft = 0.0 if self.friction is None else self.friction.force(g.sliding_velocity, fn)
        return fn, ft, g

    def wrenches(self, kin: Kinematics, t, memory):
        fn, ft, g = self.contact_forces(kin, memory)
        f_journal = -(fn * g.normal + ft * g.tangent)
        return [
            Wrench(self.journal_body, force=f_journal, point=g.contact_point_journal),
            Wrench(self.bearing_body, force=-f_journal, point=g.contact_point_bearing),
        ]

    def potential_energy(self, kin: Kinematics, memory):
        """Elastic energy of the contact, `U(δ)` of the normal law's elastic part."""
        return self.normal.elastic.potential(self.geometry(kin).penetration)

    def idealized(self) -> Revolute:
        return Revolute(
            self.bearing_body, self.bearing_point, self.journal_body, self.journal_point
        )
