"""Independent reference: the Flores & Ambrósio (2004) slider-crank with a clearance joint
between connecting rod and slider, in minimal coordinates, numpy + scipy only.

Written from the papers' equations; it imports nothing from jaxdeploy and shares no modelling
shortcut with it (no absolute coordinates, no constraint solve, no interpolated memory, no
two-sided contact, no velocity regularisation).

**Model.** Crank of length r turned at the prescribed angle θ = ω t about the origin (θ = 0 at
top dead centre, crank along +x); connecting rod of length l, mass m_r, inertia I_r about its
centre of mass (mid-length), pinned to the crank pin A = r (cos θ, sin θ); slider of mass m_s on
the x axis. The rod's small end carries a journal of radius R_j in a bearing of radius
R_i = R_j + c on the slider. Generalised coordinates q = (φ, x_s): rod angle and slider
position (the ideal joint's constraint x_s = A_x + l cos φ, 0 = A_y + l sin φ is *not*
imposed; the clearance joint replaces it by a force). With u = (cos φ, sin φ),
u⊥ = (−sin φ, cos φ):

    rod centre of mass  G = A + (l/2) u,       journal centre  P_j = A + l u
    eccentricity        e = P_j − (x_s, 0),    n = e/|e|,  t = (−n_y, n_x)
    penetration         δ = |e| − c,           δ̇ = ė·n       (Flores & Ambrósio 2004, eqs. 1–6)
    contact points      Q_j = P_j + R_j n (rod), Q_i = (x_s, 0) + R_i n (slider)
    sliding velocity    v_t = (ṙ_Qj − ṙ_Qi)·t = ė·t + R_j φ̇   (the slider does not rotate)

**Equations of motion** (Lagrange's equations with the crank motion as a rheonomic constraint;
the kinetic energy T = ½ m_r |Ġ|² + ½ I_r φ̇² + ½ m_s ẋ_s², Ġ = Ȧ + (l/2) φ̇ u⊥):

    (I_r + m_r l²/4) φ̈ = −m_r (l/2) u⊥·Ä − m_r g (l/2) cos φ + (Q_j − A) × F
                  m_s ẍ_s = −F_x

with Ä = −r ω² (cos θ, sin θ), F = −(F_N n + F_T t) the contact force on the journal applied at
Q_j (so friction adds the moment −R_j F_T about the journal centre), and −F on the slider at
Q_i (its y part and moment are taken by the rail). Gravity g acts along −y.

**Contact.** Hertz stiffness of a journal in a bearing (Flores & Ambrósio 2004, eq. 20, after
Lankarani & Nikravesh 1990 without the π of their h_k):

    K = 4 / (3 (σ_i + σ_j)) · sqrt(R_i R_j / (R_i − R_j)),   σ_k = (1 − ν_k²)/E_k

Lankarani & Nikravesh (1990), eq. 17 (Flores & Ambrósio 2004, eq. 19), classical rule:

    F_N = K δ^1.5 (1 + 3(1 − c_e²)/4 · δ̇/δ̇⁻),   δ̇⁻ = δ̇ at the onset of contact (δ = 0 rising)

δ̇⁻ is held for the whole contact episode and forgotten at separation (δ = 0 falling); out of
contact F_N = 0. Both crossings are located as events of scipy's `solve_ivp` and the
integration restarts at each, so no step straddles a change of the force law. The tensile force
the law predicts when δ̇/δ̇⁻ < −4/(3(1 − c_e²)) (a contact torn open faster than it was
entered) is cut to 0 (`max(0, ·)`, a common guard; the papers' law has none); that corner is
also an event, and `Solution.n_tensile_events` counts how often it was hit.

Friction (optional): a tanh-regularised Coulomb law F_T = μ F_N tanh(v_t/v_s) (Marques et al.,
*Nonlinear Dyn.* 86 (2016) 1407, smooth Coulomb variants), v_s the regularisation velocity.

**Events located.** Onset (δ = 0 rising, out of contact), separation (δ = 0 falling, in
contact), the tensile corner (the bracket above = 0, in contact). A grazing contact whose two
crossings fall inside one integration step would be missed by a sign test at step ends, so
the extrema of δ (δ̇ = 0) are also located; an extremum on the wrong side of 0 (a maximum with
δ > 0 out of contact, a minimum with δ < 0 in contact) sends the root search back into that
step on the dense output.

**Initial state** (the scene's): crank angle 0, journal centred, the ideal mechanism's
velocities: φ = 0, x_s = r + l, φ̇ = −r ω / l, ẋ_s = 0.

References: P. Flores, J. Ambrósio, *Comput. Struct.* 82 (2004) 1359; H. M. Lankarani,
P. E. Nikravesh, *J. Mech. Des.* 112 (1990) 369; P. Flores et al., *Mech. Mach. Theory* 41
(2006) 247.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

# The Flores & Ambrósio (2004) case, SI units (m, kg, kg m², rad/s, Pa, m/s²).
PARAMETERS = {
    "crank_length": 0.05,
    "rod_length": 0.12,
    "crank_speed": 5000.0 * 2.0 * math.pi / 60.0,
    "rod_mass": 0.21,
    "rod_inertia": 2.5e-4,
    "slider_mass": 0.14,
    "journal_radius": 9.5e-3,
    "clearance": 0.5e-3,
    "youngs_modulus": 207e9,
    "poisson_ratio": 0.3,
    "restitution": 0.9,
    "gravity": 9.81,
    "friction_coefficient": 0.0,
    "friction_slip_velocity": 1e-3,
}

FIRST_STEP = 1e-8  # [s], of each segment; contacts last ~1e-5 … 1e-3 s

TWO_REVOLUTIONS = 2.0 * 2.0 * math.pi / PARAMETERS["crank_speed"]  # [s]


def _cross(a, b):
    return a[0] * b[1] - a[1] * b[0]


def hertz_stiffness(journal_radius, clearance, youngs_modulus, poisson_ratio):
    """`K = 4/(3(σ_i + σ_j)) sqrt(R_i R_j/(R_i − R_j))` [N/m^1.5], journal and bearing of one
    material (σ_i = σ_j = (1 − ν²)/E), R_i = R_j + c (Flores & Ambrósio 2004, eq. 20)."""
    sigma_k = (1.0 - poisson_ratio**2) / youngs_modulus
    r_i = journal_radius + clearance
    return 4.0 / (3.0 * (sigma_k + sigma_k)) * math.sqrt(r_i * journal_radius / clearance)


@dataclass
class Solution:
    """A reference run: `sample(ts)` gives (φ, x_s, φ̇, ẋ_s) at any time in the run."""

    segments: list  # (t0, t1, dense output)
    onsets: list = field(default_factory=list)  # contact onset times [s]
    separations: list = field(default_factory=list)  # separation times [s]
    impact_velocities: list = field(default_factory=list)  # δ̇⁻ of each contact [m/s]
    n_tensile_events: int = 0
    n_grazing_recoveries: int = 0
    n_steps: int = 0

    def sample(self, ts):
        ts = np.asarray(ts, dtype=float)
        out = np.full((ts.size, 4), np.nan)
        for t0, t1, dense in self.segments:
            inside = (ts >= t0) & (ts <= t1)
            if inside.any():
                out[inside] = dense(ts[inside]).T
        return out


class SliderCrankMinimal:
    """The model of the module docstring; `params` overrides entries of `PARAMETERS`."""

    def __init__(self, params: dict | None = None):
        p = dict(PARAMETERS)
        unknown = set(params or {}) - set(p)
        if unknown:
            raise ValueError(f"unknown parameters {sorted(unknown)}; valid: {sorted(p)}")
        p.update(params or {})
        self.p = p
        self.r, self.l, self.omega = p["crank_length"], p["rod_length"], p["crank_speed"]
        self.m_r, self.i_r, self.m_s = p["rod_mass"], p["rod_inertia"], p["slider_mass"]
        self.g = p["gravity"]
        self.c, self.r_j = p["clearance"], p["journal_radius"]
        self.K = hertz_stiffness(self.r_j, self.c, p["youngs_modulus"], p["poisson_ratio"])
        self.chi = 0.75 * (1.0 - p["restitution"] ** 2)
        self.mu, self.v_s = p["friction_coefficient"], p["friction_slip_velocity"]
        self.rod_inertia_about_pin = self.i_r + self.m_r * self.l**2 / 4.0

    def initial_state(self):
        return np.array([0.0, self.r + self.l, -self.r * self.omega / self.l, 0.0])

    # --- kinematics ------------------------------------------------------------------------

    def crank_pin(self, t):
        """A, Ȧ, Ä of the crank pin (θ = ω t)."""
        th = self.omega * t
        c, s = math.cos(th), math.sin(th)
        a = self.r * np.array([c, s])
        return a, self.r * self.omega * np.array([-s, c]), -(self.omega**2) * a

    def contact(self, t, y):
        """`(δ, δ̇, v_t, n, Q_j − A)` of the journal in the bearing."""
        phi, x_s, phi_dot, x_s_dot = y
        a, a_dot, _ = self.crank_pin(t)
        u = np.array([math.cos(phi), math.sin(phi)])
        u_perp = np.array([-u[1], u[0]])
        e = a + self.l * u - np.array([x_s, 0.0])
        e_dot = a_dot + self.l * phi_dot * u_perp - np.array([x_s_dot, 0.0])
        norm_e = math.hypot(e[0], e[1])
        # e = 0 only at the centred start (where ė = 0 too): n is then arbitrary, δ = −c.
        n = e / norm_e if norm_e > 0.0 else np.array([1.0, 0.0])
        tangent = np.array([-n[1], n[0]])
        return (
            norm_e - self.c,
            float(e_dot @ n),
            float(e_dot @ tangent) + self.r_j * phi_dot,
            n,
            self.l * u + self.r_j * n,
        )

    def damping_bracket(self, t, y, v_minus):
        """`1 + χ δ̇/δ̇⁻`, the factor of the Lankarani–Nikravesh law."""
        return 1.0 + self.chi * self.contact(t, y)[1] / v_minus

    # --- dynamics --------------------------------------------------------------------------

    def rhs(self, t, y, v_minus):
        """ẏ for y = (φ, x_s, φ̇, ẋ_s); `v_minus` is δ̇⁻ in contact, None out of contact."""
        phi, _, phi_dot, x_s_dot = y
        _, _, a_ddot = self.crank_pin(t)
        u_perp = np.array([-math.sin(phi), math.cos(phi)])
        moment = -self.m_r * 0.5 * self.l * (u_perp @ a_ddot + self.g * math.cos(phi))
        slider_force = 0.0
        if v_minus is not None:
            delta, delta_dot, v_t, n, arm = self.contact(t, y)
            bracket = 1.0 + self.chi * delta_dot / v_minus
            f_n = self.K * max(delta, 0.0) ** 1.5 * max(bracket, 0.0)
            f_t = self.mu * f_n * math.tanh(v_t / self.v_s) if self.mu else 0.0
            force = -(f_n * n + f_t * np.array([-n[1], n[0]]))
            moment += _cross(arm, force)
            slider_force = -force[0]
        return np.array(
            [phi_dot, x_s_dot, moment / self.rod_inertia_about_pin, slider_force / self.m_s]
        )

    # --- integration -----------------------------------------------------------------------

    def _events(self, t_start, in_contact, tensile):
        """The segment's event functions `(crossing, extremum, corner)` (module docstring)."""

        # A segment starts at an event, where the event function is 0 only to the root
        # finder's accuracy; a start value of the wrong sign would hide the next crossing if
        # it fell in the first step (it did: a re-contact right after a separation). At the
        # start each event function therefore takes the side the state is leaving into.
        def crossing(t, y, _v_minus):
            if t == t_start:
                return 1.0 if in_contact else -1.0
            return self.contact(t, y)[0]

        def extremum(t, y, _v_minus):
            return self.contact(t, y)[1]

        def corner(t, y, v_minus):
            if not in_contact:
                return 1.0
            if t == t_start:
                return -1.0 if tensile else 1.0
            return self.damping_bracket(t, y, v_minus)

        crossing.terminal, crossing.direction = True, -1.0 if in_contact else 1.0
        corner.terminal, corner.direction = True, 1.0 if tensile else -1.0
        return crossing, extremum, corner

    def _grazing_crossing(self, run, t0, t_stop, in_contact):
        """The first crossing of δ = 0 hidden inside a step before `t_stop` (an extremum of δ
        on the wrong side of 0: a maximum with δ > 0 out of contact, a minimum with δ < 0 in
        contact), located on the dense output; None if there is none."""
        for t_x, y_x in zip(run.t_events[1], run.y_events[1], strict=True):
            if t_x >= t_stop:
                return None
            if (self.contact(t_x, y_x)[0] > 0.0) != in_contact:
                t_start = max(run.t[run.t < t_x][-1], t0)
                return brentq(lambda s: self.contact(s, run.sol(s))[0], t_start, t_x, xtol=1e-18)
        return None

    def solve(self, t_end, rtol=1e-12, atol=(1e-14, 1e-15, 1e-11, 1e-12), method="DOP853"):
        """Integrate from the initial state to `t_end` [s], restarting at every event; `atol`
        per component of (φ [rad], x_s [m], φ̇ [rad/s], ẋ_s [m/s])."""
        sol = Solution(segments=[])
        t0, y = 0.0, self.initial_state()
        v_minus = None  # δ̇⁻ in contact, None out of contact (the journal starts centred)
        tensile = False  # in contact with the damping bracket cut to 0
        while t0 < t_end:
            in_contact = v_minus is not None
            run = solve_ivp(
                self.rhs,
                (t0, t_end),
                y,
                method=method,
                rtol=rtol,
                atol=np.asarray(atol),
                events=self._events(t0, in_contact, tensile),
                args=(v_minus,),
                dense_output=True,
                # scipy's first-step guess sees no contact stiffness at δ = 0; a step that
                # long would bury the journal (overflow before the error test rejects it).
                first_step=min(FIRST_STEP, t_end - t0),
            )
            if run.status == -1:
                raise RuntimeError(f"reference failed after t = {run.t[-1]:.9g} s: {run.message}")
            t_stop, kind = run.t[-1], None
            if run.status == 1:
                t_stop = min(run.t_events[0].tolist() + run.t_events[2].tolist())
                kind = "crossing" if t_stop in run.t_events[0] else "corner"
            grazing = self._grazing_crossing(run, t0, t_stop, in_contact)
            if grazing is not None:
                t_stop, kind = grazing, "crossing"
                sol.n_grazing_recoveries += 1
            sol.n_steps += int(np.searchsorted(run.t, t_stop))
            sol.segments.append((t0, t_stop, run.sol))
            t0, y = t_stop, run.sol(t_stop)
            if kind == "crossing" and in_contact:
                sol.separations.append(t0)
                v_minus, tensile = None, False
            elif kind == "crossing":
                v_minus = self.contact(t0, y)[1]
                if not v_minus > 0.0:
                    raise RuntimeError(f"onset at t = {t0} s with δ̇ = {v_minus} m/s ≤ 0")
                sol.onsets.append(t0)
                sol.impact_velocities.append(v_minus)
            elif kind == "corner":
                tensile = not tensile
                sol.n_tensile_events += 1
        return sol
