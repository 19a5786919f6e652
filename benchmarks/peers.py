"""Peers for the work–precision benchmark: scipy `solve_ivp` on the slider-crank.

Two right-hand sides of the *same* model (absolute coordinates, index-1 with Baumgarte
stabilisation, Hertz contact with Lankarani–Nikravesh damping, `jaxdeploy.mechanism.clearance`):

* `SliderCrankNumpy`: written the way a scipy user would (Flores & Ambrósio 2004; Nikravesh
  1988): hand-derived constraint Jacobian and `γ`, numpy arrays, `numpy.linalg.solve`. It
  shares no code with jaxdeploy's mechanism (only the scene's parameter values).
* `jitted_rhs(mechanism)`: jaxdeploy's own index-1 field, jitted, called from scipy — the same
  integrator on a cheaper or dearer function call tells integrator quality from call cost.

v⁻ is kept exactly by events, as a scipy user would keep a memory variable. With the classical
rule (`impact_velocity_rule="onset"`, the default; Lankarani & Nikravesh 1990, Flores &
Ambrósio 2004) contact onset (δ = 0 crossing upward) stops the integration and sets v⁻ = δ̇
there, held until separation (δ = 0 crossing downward) stops it again. With
`"running_max"` (jaxdeploy's other rule, not from the literature) the force uses `max(v⁻, δ̇)`
while the approach speeds up beyond v⁻, and its peak (δ̈ = 0 crossing downward) is a third
event that sets v⁻ = δ̇ there. The damping term divides by `max(v⁻, v_floor)`, v_floor the
scene's `impact_velocity_floor` [m/s].
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

BAUMGARTE = 5.0  # α = β = 5 s⁻¹ as used by Flores & Ambrósio (2004) (recalled, unverified)
IMPACT_VELOCITY_RULES = ("onset", "running_max")


def _rot(theta):
    c, s = math.cos(theta), math.sin(theta)
    return np.array([[c, -s], [s, c]])


def _perp(x):
    return np.array([-x[1], x[0]])


def _cross(a, b):
    return a[0] * b[1] - a[1] * b[0]


class SliderCrankNumpy:
    """The Flores slider-crank with a rod–slider clearance joint, in numpy.

    State `y = (q, q̇)`, `q = (x₁, y₁, θ₁, x₂, y₂, θ₂, x₃, y₃, θ₃)` for crank, rod, slider
    (centres of mass). Seven constraints: ground–crank pin (2), crank angle `θ₁ = ω t` (1),
    crank–rod pin (2), slider `θ₃ = 0`, `y₃ = 0` (2). Index-1 system
    `[[M, Φ_qᵀ], [Φ_q, 0]] [q̈; λ] = [Q; γ − 2α Φ̇ − β² Φ]`. `impact_velocity_rule`: what v⁻
    is (module docstring), `"onset"` (classical, default) or `"running_max"`.
    """

    def __init__(self, params: dict, impact_velocity_rule: str = "onset"):
        if impact_velocity_rule not in IMPACT_VELOCITY_RULES:
            raise ValueError(
                f"impact_velocity_rule = {impact_velocity_rule!r} is invalid; valid: "
                + ", ".join(IMPACT_VELOCITY_RULES)
            )
        self.impact_velocity_rule = impact_velocity_rule
        p = {k: float(v) for k, v in params.items()}
        # The scene's parameter (m/s); 1e-4 is its default.
        self.velocity_floor = p.get("impact_velocity_floor", 1e-4)
        self.r, self.l = p["crank_length"], p["rod_length"]
        self.omega = p["crank_speed"]
        self.g = p["gravity"]
        self.mass = np.array(
            [p["crank_mass"]] * 2
            + [p["crank_inertia"]]
            + [p["rod_mass"]] * 2
            + [p["rod_inertia"]]
            + [p["slider_mass"]] * 2
            + [p["slider_inertia"]]
        )
        self.c = p["clearance"]
        self.rj = p["journal_radius"]
        rb = self.rj + self.c
        e_star = p["youngs_modulus"] / (2.0 * (1.0 - p["poisson_ratio"] ** 2))
        self.K = 4.0 / 3.0 * e_star * math.sqrt(self.rj * rb / self.c)
        self.chi = 0.75 * (1.0 - p["restitution"] ** 2)  # Lankarani–Nikravesh
        if p.get("friction_coefficient", 0.0) != 0.0 or p.get("sigma", 0.0) != 0.0:
            raise ValueError("SliderCrankNumpy models the frictionless, smooth (Hertz) case only")
        self.s_pivot = np.array([-self.r / 2, 0.0])
        self.s_pin = np.array([self.r / 2, 0.0])
        self.s_big = np.array([-self.l / 2, 0.0])
        self.s_small = np.array([self.l / 2, 0.0])

    # --- kinematics of the clearance joint --------------------------------------------------

    def contact_kinematics(self, q, v):
        """`(δ, δ̇, n, Q_j, Q_i)`: penetration, its rate, normal, contact points."""
        a2 = _rot(q[5])
        pj = q[3:5] + a2 @ self.s_small  # journal centre (rod small end)
        pi = q[6:8]  # bearing centre (slider)
        e = pj - pi
        norm_e = math.sqrt(e @ e + 1e-24)
        n = e / norm_e
        qj = pj + self.rj * n
        qi = pi + (self.rj + self.c) * n
        vj = v[3:5] + v[5] * _perp(qj - q[3:5])
        vi = v[6:8] + v[8] * _perp(qi - q[6:8])
        return norm_e - self.c, (vj - vi) @ n, n, qj, qi

    def penetration(self, t, y):
        return self.contact_kinematics(y[:9], y[9:])[0]

    def penetration_rate(self, y):
        return self.contact_kinematics(y[:9], y[9:])[1]

    def solve(self, initial, t_end, ts, method="DOP853", rtol=1e-10, atol=1e-12) -> PeerRun:
        """`solve_with_onset_events` on this model from `initial` (a state with `q`, `v`, e.g.
        jaxdeploy's `consistent_state`) over [0, `t_end`], states at `ts`."""
        y0 = np.concatenate([np.asarray(initial.q), np.asarray(initial.v)])
        return solve_with_onset_events(
            self.rhs,
            self.penetration,
            self.penetration_rate,
            self.penetration_acceleration,
            y0,
            (0.0, t_end),
            ts,
            method,
            rtol,
            atol,
            running_max=self.impact_velocity_rule == "running_max",
        )

    def penetration_acceleration(self, t, y, v_minus):
        """`δ̈ = ë·n + (|ė|² − (ė·n)²)/|e|`, `e` = journal centre − bearing centre (δ̇ = ė·n:
        the contact points' rotation terms are normal to n)."""
        q, v = y[:9], y[9:]
        qdd = self.accelerations(t, q, v, v_minus)
        a2 = _rot(q[5])
        arm = a2 @ self.s_small
        e = q[3:5] + arm - q[6:8]
        e_dot = v[3:5] + v[5] * _perp(arm) - v[6:8]
        e_ddot = qdd[3:5] + qdd[5] * _perp(arm) - v[5] ** 2 * arm - qdd[6:8]
        norm_e = math.sqrt(e @ e + 1e-24)
        n = e / norm_e
        return e_ddot @ n + (e_dot @ e_dot - (e_dot @ n) ** 2) / norm_e

    # --- equations of motion ----------------------------------------------------------------

    def forces(self, q, v, v_minus):
        f = np.zeros(9)
        f[[1, 4, 7]] = -self.mass[[0, 3, 6]] * self.g
        delta, rate, n, qj, qi = self.contact_kinematics(q, v)
        if delta > 0.0:
            if self.impact_velocity_rule == "running_max":
                v_minus = max(v_minus, rate)  # the running maximum includes the present state
            v_eff = max(v_minus, self.velocity_floor)
            fn = max(0.0, self.K * delta**1.5 * (1.0 + self.chi * rate / v_eff))
            fj = -fn * n
            f[3:5] += fj
            f[5] += _cross(qj - q[3:5], fj)
            f[6:8] -= fj
            f[8] += _cross(qi - q[6:8], -fj)
        return f

    def constraints(self, q, t):
        a1, a2 = _rot(q[2]), _rot(q[5])
        return np.concatenate(
            [
                q[0:2] + a1 @ self.s_pivot,
                [q[2] - self.omega * t],
                q[0:2] + a1 @ self.s_pin - q[3:5] - a2 @ self.s_big,
                [q[8], q[7]],
            ]
        )

    def jacobian(self, q):
        a1, a2 = _rot(q[2]), _rot(q[5])
        jac = np.zeros((7, 9))
        jac[0:2, 0:2] = np.eye(2)
        jac[0:2, 2] = _perp(a1 @ self.s_pivot)
        jac[2, 2] = 1.0
        jac[3:5, 0:2] = np.eye(2)
        jac[3:5, 2] = _perp(a1 @ self.s_pin)
        jac[3:5, 3:5] = -np.eye(2)
        jac[3:5, 5] = -_perp(a2 @ self.s_big)
        jac[5, 8] = 1.0
        jac[6, 7] = 1.0
        return jac

    def gamma(self, q, v):
        a1, a2 = _rot(q[2]), _rot(q[5])
        g = np.zeros(7)
        g[0:2] = a1 @ self.s_pivot * v[2] ** 2
        g[3:5] = a1 @ self.s_pin * v[2] ** 2 - a2 @ self.s_big * v[5] ** 2
        return g

    def accelerations(self, t, q, v, v_minus):
        jac = self.jacobian(q)
        phi = self.constraints(q, t)
        phi_dot = jac @ v - np.array([0, 0, self.omega, 0, 0, 0, 0])
        rhs = self.gamma(q, v) - 2 * BAUMGARTE * phi_dot - BAUMGARTE**2 * phi
        kkt = np.zeros((16, 16))
        kkt[:9, :9] = np.diag(self.mass)
        kkt[:9, 9:] = jac.T
        kkt[9:, :9] = jac
        sol = np.linalg.solve(kkt, np.concatenate([self.forces(q, v, v_minus), rhs]))
        return sol[:9]

    def rhs(self, t, y, v_minus):
        q, v = y[:9], y[9:]
        return np.concatenate([v, self.accelerations(t, q, v, v_minus)])


def jitted_rhs(mechanism, baumgarte: float = BAUMGARTE):
    """jaxdeploy's index-1 field of `mechanism` (one clearance joint with v⁻ memory), jitted,
    as numpy-in/numpy-out `(rhs(t, y, v_minus), penetration(t, y), penetration_rate(y),
    penetration_acceleration(t, y, v_minus))`."""
    import jax
    import jax.numpy as jnp

    from jaxdeploy.mechanism import RevoluteClearance
    from jaxdeploy.solvers import stabilised_accelerations

    (index,) = mechanism.find(RevoluteClearance)
    joint = mechanism.elements[index]
    n = mechanism.n_coordinates

    def memory_with(v_minus):
        memory = [None] * len(mechanism.elements)
        memory[index] = {"in_contact": jnp.array(1.0), "impact_velocity": v_minus}
        return tuple(memory)

    @jax.jit
    def f(t, y, v_minus):
        q, v = y[:n], y[n:]
        qdd, _ = stabilised_accelerations(mechanism, q, v, t, memory_with(v_minus), baumgarte)
        return jnp.concatenate([v, qdd])

    @jax.jit
    def geometry(y):
        g = joint.geometry(mechanism.kinematics(y[:n], y[n:]))
        return jnp.stack([g.penetration, g.penetration_rate])

    @jax.jit
    def rate_derivative(t, y, v_minus):
        # d/dt δ̇ along the field: a JVP of the rate in the direction (q̇, q̈).
        return jax.jvp(lambda z: geometry(z)[1], (y,), (f(t, y, v_minus),))[1]

    def rhs(t, y, v_minus):
        return np.asarray(f(t, y, v_minus))

    def penetration(t, y):
        return float(geometry(y)[0])

    def penetration_rate(y):
        return float(geometry(y)[1])

    def penetration_acceleration(t, y, v_minus):
        return float(rate_derivative(t, y, v_minus))

    return rhs, penetration, penetration_rate, penetration_acceleration


@dataclass
class PeerRun:
    ys: np.ndarray  # (len(ts), 2n) states at the requested times
    n_steps: int
    n_rhs: int
    n_jac: int
    n_events: int
    wall: float
    ok: bool
    message: str
    events: list  # (t, "onset" | "peak", v⁻ after the event)


def solve_with_onset_events(
    rhs,
    penetration,
    penetration_rate,
    penetration_acceleration,
    y0,
    t_span,
    ts,
    method,
    rtol,
    atol,
    max_restarts=10_000,
    running_max=False,
) -> PeerRun:
    """`scipy.integrate.solve_ivp` from event to event, keeping v⁻ exactly:

    * onset, δ = 0 rising (armed out of contact): v⁻ = δ̇ there;
    * with `running_max` only, the peak of the approach, δ̈ = 0 falling while in contact with
      δ̇ above v⁻ (between the two the right-hand side's `max(v⁻, δ̇)` *is* the running
      maximum): v⁻ = δ̇ there;
    * separation, δ = 0 falling (armed in contact): the contact ends, the onset is re-armed.

    Each event stops the integration, updates v⁻ and restarts. Returns the states at `ts`
    (from each segment's dense output); `n_events` counts every kind."""
    from scipy.integrate import solve_ivp

    # A segment starts at an event with δ = 0 or δ̈ = 0 only to the root finder's accuracy, so
    # an event function that is armed at a restart could fire again at once, forever (it did:
    # 10 000 onsets within 1.5 ms). Hence each event is armed only in the state it leaves:
    # onset out of contact, separation in contact, and the peak only while δ̇ exceeds v⁻ by
    # more than 1e-12 m/s, which a segment starting at a peak (δ̇ = v⁻) does not. A disarmed
    # event returns a constant (no sign change is invented); arming changes only at restarts.
    in_contact = [False]

    def onset(t, y, v_minus):
        return 1.0 if in_contact[0] else penetration(t, y)

    def separation(t, y, v_minus):
        return penetration(t, y) if in_contact[0] else 1.0

    def peak(t, y, v_minus):
        if running_max and in_contact[0] and penetration_rate(y) > v_minus + 1e-12:
            return penetration_acceleration(t, y, v_minus)
        return 1.0

    kinds = ("onset", "peak", "separation")
    for event, direction in ((onset, 1.0), (peak, -1.0), (separation, -1.0)):
        event.terminal = True
        event.direction = direction

    ts = np.asarray(ts, dtype=float)
    out = np.full((ts.size, y0.size), np.nan)
    t0, t1 = t_span
    y = np.asarray(y0, dtype=float)
    in_contact[0] = penetration(t0, y) > 0.0
    v_minus = max(penetration_rate(y), 0.0) if in_contact[0] else 0.0
    steps = nfev = njev = 0
    events = []
    ok, message = True, "ok"
    start = time.perf_counter()
    for _ in range(max_restarts):
        sol = solve_ivp(
            rhs,
            (t0, t1),
            y,
            method=method,
            rtol=rtol,
            atol=atol,
            events=(onset, peak, separation),
            args=(v_minus,),
            dense_output=True,
        )
        steps += len(sol.t) - 1
        nfev += sol.nfev
        njev += sol.njev
        t_end = sol.t[-1]
        inside = (ts >= t0) & (ts <= t_end)
        if inside.any():
            out[inside] = sol.sol(ts[inside]).T
        if sol.status == -1:
            ok, message = False, f"failed after t = {t_end:.6g} s: {sol.message}"
            break
        if sol.status == 0:
            break
        fired = next(k for k in range(3) if sol.t_events[k].size)
        t0, y = sol.t_events[fired][0], sol.y_events[fired][0]
        if kinds[fired] == "onset":
            in_contact[0], v_minus = True, max(penetration_rate(y), 0.0)
        elif kinds[fired] == "peak":
            v_minus = max(penetration_rate(y), v_minus)
        else:
            in_contact[0], v_minus = False, 0.0
        events.append((float(t0), kinds[fired], v_minus))
        if t0 >= t1:
            break
    else:
        ok, message = False, f"more than {max_restarts} restarts"
    wall = time.perf_counter() - start
    return PeerRun(out, steps, nfev, njev, len(events), wall, ok, message, events)
