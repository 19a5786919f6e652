"""Revolute joint with radial clearance: a journal moving freely inside a bearing until their
surfaces meet (Flores & Ambrósio, *Comput. Struct.* 82 (2004) 1359; Flores et al. 2008).

With P_i the bearing centre (on `bearing_body`) and P_j the journal centre (on `journal_body`):

    e = r_Pj − r_Pi,  |e| = sqrt(e·e + ε²),  n = e/|e|,  t = (−n_y, n_x)
    δ = |e| − c                      (penetration on the near side; δ < 0 is a gap)
    Q_k = P_k + R_k n                (contact points; R_i = R_j + c is the bearing radius)
    v = ṙ_Qj − ṙ_Qi,   δ̇ = v·n,   v_t = v·t
    force on the journal −(F_N n + F_T t) at Q_j; the opposite on the bearing at Q_i.

`F_N` comes from the normal law (a `jaxdeploy.contact` damped law) and `F_T` from the friction
law; with `friction=None` no friction code is traced. ε (default 1e-12 m) keeps the centred
joint (e = 0) differentiable.

**Both sides of the bearing.** The journal also meets the bearing on the far side, along −n:

    δ' = −|e| − c,   δ̇' = −δ̇,   Q'_k = P_k − R_k n,   v' = ṙ_Q'j − ṙ_Q'i,   v'_t = −v'·t
    force on the journal +(F'_N n + F'_T t) at Q'_j (normal −n, tangent −t); opposite on the bearing

with the same laws: `F'_N = F_N(δ', δ̇', v⁻)`, `F'_T = F_T(v'_t, F'_N)`. The net normal force
on the journal is −(F_N(δ) − F_N(δ')) n. For a Hertz law (σ = 0) the far force is exactly 0; for
the rough law it is K σ^n F_n(s0 + (|e| + c)/σ), ≤ 3e-25 K σ^n for c ≥ 10σ (n = 1.5, s0 = 0)
and exactly 0 (underflow) for c ≥ 38σ: the joint is then the single-contact-point model of
the references. It matters when c ≲ 3σ: the rough law (Greenwood–Williamson average, force from
δ ≈ (s0 − 3)σ) is then active on *both* sides with the journal centred, as the asperities of a
journal in a bore with a clearance of the order of the roughness are. A single contact point
would push the centred journal with F_e(−c) along a direction n = e/|e| that flips within ε of
e = 0: a stiffness F_e(−c)/ε (docs/contact.md tabulates it) and a force discontinuous in e
as ε → 0. With both sides, the elastic part
g(r) = F_e(r − c) − F_e(−r − c) is odd in r = |e|, so g(|e|) n = (g(r)/r) e is smooth in e
(g(r)/r is even, smooth in r²) and vanishes at e = 0 with the finite stiffness 2 F_e'(−c) I,
without needing ε. The contact potential is U(δ) + U(δ'). This is a two-point (diametral)
lumping of the contact around the circumference (docs/contact.md); it does not represent the
±t sides, so the damping (along n, ∝ δ̇ = ė·n) and the friction (along t) still turn with e:
their derivative across e is of order χ (F_e(δ) + F_e(δ')) |ė| / (v⁻ |e|), zero for a journal
at rest, and inside |e| ≲ ε (where n shrinks to 0) they are regularised on the scale ε.

**State-based friction.** With a friction law that has a state (`friction.has_state`, e.g.
`contact.LuGreContactFriction`) the tangential force of each side is `F_T = F(v_t, z, F_N)`,
its normal force the side's contact force, and the bristle deflections z = [z_near, z_far]
[m] are the joint's continuous internal state, `memory["internal"]["bristle"]`, integrated
with the equations of motion (`ż = law.rate(v_t, z)`; `AbstractElement.internal_rates`),
starting at 0. Out of contact F_N = 0 and the side carries no friction, but its z goes on
following the sliding of the (separated) surfaces, so a contact closes with the bristles the
law's sliding state gives them.

Memory (for laws that need the impact velocity v⁻; a state-based friction law adds its
`internal` states): `in_contact`, `impact_velocity`,
`eccentricity` and `eccentricity_rate` (e, ė at the last step's end), `penetration`,
`penetration_rate` and `event_fraction`, updated after each accepted step. What v⁻ is, is the
joint's `impact_velocity_rule`:

* `"onset"` (default; the classical rule of Lankarani & Nikravesh 1990, used by Flores &
  Ambrósio 2004 for the clearance joint): v⁻ = δ̇(t_on), the approach speed at the onset of the
  current contact, held through the contact. Out of contact (in the memory) an approaching
  state uses its own δ̇ — inside the step that crosses the onset it is the best estimate of the
  onset speed, and the damping ratio there is χ at most — and a receding one the last
  contact's v⁻, held past its separation until the next onset ("Continuity at separation").
* `"running_max"`: v⁻(t) = max_{s ∈ [t_on, t]} δ̇(s), the largest approach speed of the current
  contact, and the law sees `max(v⁻, δ̇)` in contact; out of contact, as with `onset`, an
  approaching state's own δ̇ and a receding one the last contact's v⁻. It differs from
  `onset` only when the approach keeps speeding up after onset — a contact driven in by the
  mechanism, or one that starts at rest — and then keeps the damping ratio χ δ̇/v⁻ ≤ χ, so
  the rebound is calibrated to the speed actually reached. This rule is not from the
  literature; it is an option for such contacts.

With both rules a contact that begins at rest has v⁻ ≈ 0, and the law divides by its
`impact_velocity_floor` instead (`jaxdeploy.contact.damping`). The far side shares the joint's v⁻
(one contact episode, whichever wall).

**Continuity at separation** (both rules). A rough elastic law pushes below its onset level
((s0 − 3)σ, where "in contact" begins): 0.08 N at deploy_array's defaults, 4 % of its force
one σ deeper. Had v⁻ been reset at the separation, the receding journal's damping ratio
χ δ̇/v_eff (δ̇ < 0, v_eff the law's floor) would clip the force to 0 there: a jump of
F_e(level)(1 + χ δ̇/v⁻) at an instant that moves with the parameters. The run's values hardly
see it, but a derivative through the run misses its saltation term, (jump) × dt_sep/dθ, which
no step-end switch can carry: on deploy_array (Tsit5, rtol 1e-8, 30 ms, 8 + 3 impacts) the
AD derivatives of the later onset times with respect to restitution were 0.06–3 % off central
differences of reruns, and within 2e-4 once v⁻ is held (the lock time's: 2.6 % off before).
Holding v⁻ until the next onset makes the force continuous at the separation, as it is for
the literature's Hertz law (F_e = 0 below δ = 0, where this rule changes nothing); at the next
approach δ̇/max(δ̇, floor) rises continuously from 0, so the force stays continuous through
the turning point and at the onset.

Discretely, after each accepted step e(t) is the cubic Hermite interpolant of the step's end
values (e, ė), and δ(t) = |e(t)|_ε − c, δ̇ = ė·e/|e|_ε on it (`_step_eccentricity`; not a
Hermite of δ itself, which has a kink at the bearing's centre where δ̇ jumps from −|ė| to +|ė|:
a step holding both the centre passage and a far-side onset then overestimated v⁻ by 46 %).
The onset is located on it (where taking δ̇ at the step's start would be an O(h) error) and the
running maximum (rule `running_max`) includes the interpolant's maximum inside the step (an
interior peak missed between step ends would be O(h²)). For a smooth e(t) these are
O(h⁴)-accurate, but inside a step that crosses a Hertz onset δ(t) carries a (t − t_on)^3.5
term that no cubic follows, and at an interior peak the force's dependence on max(v⁻, δ̇) has
a kink: the interpolated v⁻ errs by an amount the step length sets and no error estimate
sees (measured on slider_crank: a tighter tolerance stopped improving the solution at ~1e-6 of
c).
**Onset times.** The memory also keeps an onset clock: `elapsed` (the sum of the accepted
steps: time since the run's start), `onsets` (contacts begun so far), `onset_time` (the
latest onset) and `first_onset_time` [s], each onset at `t₀ + s_on h` with s_on located on
the step's interpolant. They are differentiable: s_on carries the implicit-function
derivative of δ(s) = level (`_step_eccentricity`), `dt_on/dθ = −h (∂δ/∂θ)/(dδ/ds)`; the
step grid is not differentiated.

So the memory also records `event_fraction`, where in the step the onset, a v⁻-raising peak
(rule `running_max` only) or the separation (where v⁻ resets) fell, and adaptive runs redo such
a step to end just past the event (`jaxdeploy.solvers.LocateEvents`): v⁻ is then taken where
the interpolant is exact to round-off, and the reset happens where the contact ends.
"In contact" means δ beyond the elastic law's onset (0 for Hertz, about (s0 − 3)σ for the rough
law).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from .._validation import check_positive
from ._fields import param, static
from ._step_eccentricity import StepEccentricity
from .bodies import Kinematics, perp
from .element import AbstractElement, Wrench
from .joints import PointRef, Revolute

IMPACT_VELOCITY_RULES = ("onset", "running_max")


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
        # ė = ṙ_Pj − ṙ_Pi; δ̇ = ė·n (= v·n: the contact points' rotation terms are along t).
        self.eccentricity_rate = kin.velocity(
            joint.journal_body, joint.journal_point
        ) - kin.velocity(joint.bearing_body, joint.bearing_point)
        self.normal, self.tangent = n, t
        self.penetration = norm_e - joint.clearance
        self.penetration_rate = jnp.dot(v, n)
        self.sliding_velocity = jnp.dot(v, t)
        self.contact_point_bearing, self.contact_point_journal = qi, qj
        # The far side (normal −n, tangent −t); δ̇' = −δ̇ exactly (rotation terms are along t).
        qi_far = pi - radius_bearing * n
        qj_far = pj - joint.journal_radius * n
        v_far = contact_point_velocity(joint.journal_body, qj_far) - contact_point_velocity(
            joint.bearing_body, qi_far
        )
        self.far_penetration = -norm_e - joint.clearance
        self.far_penetration_rate = -self.penetration_rate
        self.far_sliding_velocity = -jnp.dot(v_far, t)
        self.far_contact_point_bearing, self.far_contact_point_journal = qi_far, qj_far


def _sliding(g: ClearanceGeometry):
    """The sliding speeds [near, far] along each side's tangent [m/s]."""
    return jnp.stack([g.sliding_velocity, g.far_sliding_velocity])


class RevoluteClearance(AbstractElement):
    """Journal-in-bearing clearance joint.

    **Arguments:**
    - `bearing_body`, `bearing_point`: the body with the hole and the hole's centre.
    - `journal_body`, `journal_point`: the body with the pin and the pin's centre.
    - `clearance`: radial clearance c = R_b − R_j [m] > 0 (`contact.radial_clearance(R_b, R_j)`
      computes it from both radii and refuses a journal larger than its bearing).
    - `journal_radius`: pin radius R_j [m] > 0.
    - `normal`: a normal contact law from `jaxdeploy.contact` (e.g. `LankaraniNikravesh`).
    - `friction`: a friction law from `jaxdeploy.contact`, or `None` (frictionless); a law
      with a state (`has_state`, `contact.LuGreContactFriction`) keeps its bristle
      deflections as the joint's internal state (module docstring).
    - `eccentricity_smoothing`: ε [m] in |e| = sqrt(e·e + ε²).
    - `impact_velocity_rule`: `"onset"` (classical, default) or `"running_max"` — what the
      damping law's impact velocity v⁻ is (module docstring).
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
    impact_velocity_rule: str = static(default="onset")

    def __check_init__(self):
        if self.impact_velocity_rule not in IMPACT_VELOCITY_RULES:
            raise ValueError(
                f"impact_velocity_rule = {self.impact_velocity_rule!r} is invalid; valid: "
                + ", ".join(IMPACT_VELOCITY_RULES)
            )
        check_positive("clearance", self.clearance, "m")
        check_positive("journal_radius", self.journal_radius, "m")
        # ε = 0 would make |e| = sqrt(e·e) non-differentiable (NaN gradient) at e = 0, where
        # every clearance scene starts (journal centred).
        check_positive("eccentricity_smoothing", self.eccentricity_smoothing, "m")

    @property
    def _impact_memory(self) -> bool:
        """Whether the normal law needs the v⁻ memory."""
        return bool(getattr(self.normal, "needs_impact_velocity", False))

    @property
    def has_internal_state(self) -> bool:
        """Whether the friction law has a state (the bristle deflections, one per side)."""
        return bool(getattr(self.friction, "has_state", False))

    @property
    def has_memory(self) -> bool:
        return self._impact_memory or self.has_internal_state

    def bodies(self):
        return (self.bearing_body, self.journal_body)

    def geometry(self, kin: Kinematics) -> ClearanceGeometry:
        return ClearanceGeometry(self, kin)

    def _onset(self):
        return self.normal.elastic.onset_penetration()

    def init_memory(self, kin: Kinematics):
        if not self.has_memory:
            return None
        out = {}
        if self.has_internal_state:
            out["internal"] = {"bristle": jnp.zeros((2,), dtype=kin.q.dtype)}
        if not self._impact_memory:
            return out
        g = self.geometry(kin)
        return out | {
            "in_contact": jnp.where(g.penetration > self._onset(), 1.0, 0.0),
            "impact_velocity": jnp.maximum(g.penetration_rate, 0.0),
            "penetration": g.penetration,
            "penetration_rate": g.penetration_rate,
            "eccentricity": g.eccentricity,
            "eccentricity_rate": g.eccentricity_rate,
            "event_fraction": jnp.ones_like(g.penetration),
            **self._init_onset_times(g),
        }

    def _init_onset_times(self, g: ClearanceGeometry):
        """The onset clock (module docstring, "Onset times"): a run that starts in contact
        counts that contact as its first, begun at time 0."""
        zero = jnp.zeros_like(g.penetration)
        began = jnp.where(g.penetration > self._onset(), 1.0, 0.0)
        return {"elapsed": zero, "onsets": began, "onset_time": zero, "first_onset_time": zero}

    @staticmethod
    def _onset_times_after(memory, began, s_on, step):
        """The onset clock after an accepted step of length `step`: a contact that `began` in
        it did so at `elapsed + s_on·step` (s_on located with its implicit derivative)."""
        step = jax.lax.stop_gradient(step)
        at = memory["elapsed"] + s_on * step
        first = began & (memory["onsets"] < 0.5)
        return {
            "elapsed": memory["elapsed"] + step,
            "onsets": memory["onsets"] + jnp.where(began, 1.0, 0.0),
            "onset_time": jnp.where(began, at, memory["onset_time"]),
            "first_onset_time": jnp.where(first, at, memory["first_onset_time"]),
        }

    def memory_after_step(self, memory, kin: Kinematics, step):
        """Update v⁻ after an accepted step of length `step` that ended at `kin` (module
        docstring). `eccentricity` and `eccentricity_rate` record e and ė at the step's end, the
        start values of the next step's interpolant; `penetration` and `penetration_rate` the δ
        and δ̇ there (outputs)."""
        if not self._impact_memory:
            return memory  # the internal states (if any) are passed on
        g = self.geometry(kin)
        onset = self._onset()
        was_in = memory["in_contact"] > 0.5
        now_in = g.penetration > onset

        def step_path():
            # e = r_Pj − r_Pi is a difference of world positions: its round-off is a few ulps
            # of their magnitude.
            magnitude = jnp.linalg.norm(g.contact_point_bearing) + jnp.linalg.norm(
                g.contact_point_journal
            )
            return StepEccentricity(
                memory["eccentricity"],
                memory["eccentricity_rate"],
                g.eccentricity,
                g.eccentricity_rate,
                step,
                self.clearance,
                self.eccentricity_smoothing,
                roundoff=16.0 * jnp.finfo(g.penetration.dtype).eps * magnitude,
            )

        if self.impact_velocity_rule == "onset":
            # v⁻ = δ̇ at the onset, held; the onset is the only event inside a contact. The
            # step's path (and its root searches, µs per step) only where an onset or a
            # separation happened inside the step (built inside the branch, so a step without
            # one evaluates none of it).
            def onset_or_separation():
                path = step_path()

                def began():
                    s_on = path.crossing(onset)
                    return path.rate(s_on), s_on, s_on

                def ended():
                    # v⁻ stays held past the separation (`_impact_velocity`: the force is
                    # continuous there).
                    held = memory["impact_velocity"]
                    return held, path.separation(onset), jnp.ones_like(g.penetration)

                return jax.lax.cond(now_in, began, ended)

            unchanged = (
                memory["impact_velocity"],
                jnp.ones_like(g.penetration),
                jnp.ones_like(g.penetration),
            )
            v_minus, event, s_onset = jax.lax.cond(
                now_in != was_in, onset_or_separation, lambda: unchanged
            )
        else:
            path = step_path()

            def in_contact_at_end():
                # A contact that began inside this step counts from its onset, located on the
                # step (the root search only then).
                s_on = jax.lax.cond(
                    was_in, lambda: jnp.zeros_like(g.penetration), lambda: path.crossing(onset)
                )
                held = jnp.where(was_in, memory["impact_velocity"], 0.0)
                running_max = jnp.maximum(held, path.max_rate(s_on))
                # Events that set v⁻ inside the step, for adaptive runs to end a step on
                # (`event_fraction`): the onset, and an interior peak of δ̇ that raised v⁻ (a
                # contact the mechanism keeps driving in).
                s_peak, has_peak = path.peak(s_on)
                raised = has_peak & (path.rate(s_peak) > jnp.maximum(held, path.rate(s_on)))
                event = jnp.minimum(jnp.where(was_in, 1.0, s_on), jnp.where(raised, s_peak, 1.0))
                return running_max, event, jnp.where(was_in, 1.0, s_on)

            def out_of_contact_at_end():
                # A contact that ended inside this step: v⁻ stays held past the separation, as
                # with rule `onset` (`_impact_velocity`; module docstring, "Continuity at
                # separation"); the next onset starts a new running maximum
                # (`in_contact_at_end`). The separation is still located, so the step that
                # switches the memory ends on it (the law sees held v⁻ either side).
                event = jax.lax.cond(
                    was_in, lambda: path.separation(onset), lambda: jnp.ones_like(g.penetration)
                )
                return memory["impact_velocity"], event, jnp.ones_like(g.penetration)

            # The interpolant's root and peak searches (µs per step) only where they matter.
            v_minus, event, s_onset = jax.lax.cond(now_in, in_contact_at_end, out_of_contact_at_end)
        internal = {"internal": memory["internal"]} if self.has_internal_state else {}
        return internal | {
            "in_contact": jnp.where(now_in, 1.0, 0.0),
            "impact_velocity": jnp.maximum(v_minus, 0.0),
            "penetration": g.penetration,
            "penetration_rate": g.penetration_rate,
            "eccentricity": g.eccentricity,
            "eccentricity_rate": g.eccentricity_rate,
            "event_fraction": event,
            **self._onset_times_after(memory, now_in & ~was_in, s_onset, step),
        }

    def event_fraction(self, memory):
        """Where in the last accepted step v⁻ was set or reset — the contact's onset, an
        interior peak of δ̇ that raised it, or the separation — as a fraction of the step
        (≥ 1: none happened); `None` for laws without v⁻ memory."""
        return memory["event_fraction"] if self._impact_memory else None

    def side_forces(self, kin: Kinematics, memory):
        """`(F_N, F_T, geometry)` at state `kin`, each force an array `[near, far]` (both
        sides evaluated at once by the element-wise laws; module docstring)."""
        g = self.geometry(kin)
        delta = jnp.stack([g.penetration, g.far_penetration])
        rate = jnp.stack([g.penetration_rate, g.far_penetration_rate])
        v_minus = self._impact_velocity(memory, rate) if self._impact_memory else None
        fn = self.normal.force(delta, rate, v_minus)
        if self.friction is None:
            ft = jnp.zeros_like(fn)
        elif self.has_internal_state:
            ft = self.friction.force(_sliding(g), memory["internal"]["bristle"], fn)
        else:
            ft = self.friction.force(_sliding(g), fn)
        return fn, ft, g

    def internal_rates(self, kin: Kinematics, t, memory):
        """`ż` of the bristle deflections [near, far] (state-based friction only)."""
        z = memory["internal"]["bristle"]
        return {"bristle": self.friction.rate(_sliding(self.geometry(kin)), z)}

    def _impact_velocity(self, memory, rate):
        """v⁻ seen by the damping law at a state with penetration rates `rate` [near, far]."""
        if self.impact_velocity_rule == "onset":
            # Out of contact in memory: approaching, the state's own δ̇ (inside the step that
            # crosses the onset it is the best estimate of the onset speed, and the force is
            # continuous at the onset); receding, the last contact's v⁻, held past its
            # separation, so that the force is continuous there too (module docstring,
            # "Continuity at separation").
            held = memory["impact_velocity"]
            return jnp.where(memory["in_contact"] > 0.5, held, jnp.where(rate > 0, rate, held))
        # In contact, the running maximum of the approach speed includes the present state
        # (docstring); out of contact, as rule `onset`: the state's own δ̇ approaching (a new
        # contact's maximum starts from it), the held v⁻ receding.
        held = memory["impact_velocity"]
        return jnp.where(
            memory["in_contact"] > 0.5, jnp.maximum(held, rate), jnp.where(rate > 0, rate, held)
        )

    def contact_forces(self, kin: Kinematics, memory):
        """`(F_N, F_T, geometry)` at state `kin`: the net normal force on the journal along
        −n, `F_N(δ) − F_N(δ')`, and the net friction force along −t, `F_T − F'_T` (near side
        minus far side; the far side is zero unless c ≲ 3σ)."""
        fn, ft, g = self.side_forces(kin, memory)
        return fn[0] - fn[1], ft[0] - ft[1], g

    def wrenches(self, kin: Kinematics, t, memory):
        fn, ft, g = self.side_forces(kin, memory)
        return self._side_wrenches(fn, ft, g)

    def nonconservative_wrenches(self, kin: Kinematics, t, memory):
        """The wrenches of the contact forces less their elastic part `F_e(δ)` on each side
        (whose potential is `potential_energy`): the damping part of the normal force and
        the friction force, which an energy meter books as dissipated (`AbstractElement`)."""
        fn, ft, g = self.side_forces(kin, memory)
        delta = jnp.stack([g.penetration, g.far_penetration])
        return self._side_wrenches(fn - self.normal.elastic.force(delta), ft, g)

    def _side_wrenches(self, fn, ft, g):
        """The wrenches of normal forces `fn` and friction forces `ft` [near, far]."""
        f_near = -(fn[0] * g.normal + ft[0] * g.tangent)
        f_far = fn[1] * g.normal + ft[1] * g.tangent
        return [
            Wrench(self.journal_body, force=f_near, point=g.contact_point_journal),
            Wrench(self.bearing_body, force=-f_near, point=g.contact_point_bearing),
            Wrench(self.journal_body, force=f_far, point=g.far_contact_point_journal),
            Wrench(self.bearing_body, force=-f_far, point=g.far_contact_point_bearing),
        ]

    def potential_energy(self, kin: Kinematics, memory):
        """Elastic energy of the contact on both sides, `U(δ) + U(δ')` of the normal law's
        elastic part."""
        g = self.geometry(kin)
        return jnp.sum(self.normal.elastic.potential(jnp.stack([g.penetration, g.far_penetration])))

    def idealized(self) -> Revolute:
        return Revolute(
            self.bearing_body, self.bearing_point, self.journal_body, self.journal_point
        )
