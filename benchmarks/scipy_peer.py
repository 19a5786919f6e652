"""The slider-crank with a clearance joint as a scipy user would write it: the peer of the
work–precision benchmark.

Two generalised coordinates, the rod angle φ and the slider position x_s (the crank turns at
the prescribed θ = ω t, θ = 0 at top dead centre); Lagrange's equations with the crank motion as
a rheonomic constraint (Flores & Ambrósio, *Comput. Struct.* 82 (2004) 1359, case and
parameters). With u = (cos φ, sin φ), u⊥ = (−sin φ, cos φ), crank pin A = r (cos θ, sin θ):

    journal centre P = A + l u,   e = P − (x_s, 0),   δ = |e| − c,   n = e/|e|,   δ̇ = ė·n
    (I + m_r l²/4) φ̈ = −m_r (l/2) (u⊥·Ä + g cos φ) − F_N (l u × n)
    m_s ẍ_s = F_N n_x,            Ä = −ω² A

Hertz stiffness of a journal in a bearing of one material (Flores & Ambrósio 2004, eq. 20)
K = 2E/(3(1 − ν²)) sqrt(R_i R_j/c), and the classical Lankarani & Nikravesh (*J. Mech. Des.*
112 (1990) 369, eq. 17) force

    F_N = K δ^{3/2} (1 + 3(1 − c_e²)/4 · δ̇/δ̇⁻)   (δ > 0),   δ̇⁻ = δ̇ at the onset, held,

cut at 0. Onset (δ = 0 rising) and separation (δ = 0 falling) are terminal events of
`scipy.integrate.solve_ivp`; the integration restarts at each with the new force law, so no
step straddles a switch. That is all a user would do: no grazing-contact recovery, one scalar
rtol/atol, a small first step at each restart (scipy's first-step guess sees no contact
stiffness at δ = 0 and would bury the journal). The independent reference
(`tests/independent/slider_crank_minimal.py`) is written separately with those refinements.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.integrate import solve_ivp

# Flores & Ambrósio (2004), SI units: the scene's defaults.
FLORES = dict(
    crank_length=0.05,
    rod_length=0.12,
    crank_speed=5000.0 * 2.0 * math.pi / 60.0,
    rod_mass=0.21,
    rod_inertia=2.5e-4,
    slider_mass=0.14,
    journal_radius=9.5e-3,
    clearance=0.5e-3,
    youngs_modulus=207e9,
    poisson_ratio=0.3,
    restitution=0.9,
    gravity=9.81,
)
METHODS = ("LSODA", "Radau", "DOP853", "RK45", "BDF")


class SliderCrankPeer:
    """The model of the module docstring with the Flores parameters."""

    def __init__(self, **overrides):
        p = {**FLORES, **overrides}
        self.r, self.l, self.w = p["crank_length"], p["rod_length"], p["crank_speed"]
        self.m_r, self.m_s, self.g = p["rod_mass"], p["slider_mass"], p["gravity"]
        self.j = p["rod_inertia"] + p["rod_mass"] * self.l**2 / 4.0
        self.c = p["clearance"]
        r_j = p["journal_radius"]
        e_star = p["youngs_modulus"] / (2.0 * (1.0 - p["poisson_ratio"] ** 2))
        self.k = 4.0 / 3.0 * e_star * math.sqrt(r_j * (r_j + self.c) / self.c)
        self.chi = 0.75 * (1.0 - p["restitution"] ** 2)

    def y0(self):
        return np.array([0.0, self.r + self.l, -self.r * self.w / self.l, 0.0])

    def gap(self, t, y):
        """(δ, δ̇, n_x, n_y, φ)."""
        phi, x, dphi, dx = y
        th = self.w * t
        cp, sp = math.cos(phi), math.sin(phi)
        ex = self.r * math.cos(th) + self.l * cp - x
        ey = self.r * math.sin(th) + self.l * sp
        dex = -self.r * self.w * math.sin(th) - self.l * dphi * sp - dx
        dey = self.r * self.w * math.cos(th) + self.l * dphi * cp
        norm = math.hypot(ex, ey) or 1.0  # e = 0 only at the centred start
        nx, ny = ex / norm, ey / norm
        return norm - self.c, dex * nx + dey * ny, nx, ny

    def rhs(self, t, y, v_minus):
        phi, x, dphi, dx = y
        th = self.w * t
        ax, ay = -(self.w**2) * self.r * math.cos(th), -(self.w**2) * self.r * math.sin(th)
        cp, sp = math.cos(phi), math.sin(phi)
        torque = -self.m_r * 0.5 * self.l * (-sp * ax + cp * ay + self.g * cp)
        slider = 0.0
        if v_minus is not None:
            delta, ddelta, nx, ny = self.gap(t, y)
            if delta > 0.0:
                fn = max(self.k * delta**1.5 * (1.0 + self.chi * ddelta / v_minus), 0.0)
                torque -= fn * self.l * (cp * ny - sp * nx)
                slider = fn * nx
        return np.array([dphi, dx, torque / self.j, slider / self.m_s])

    def solve(self, ts, method="LSODA", rtol=1e-6, atol=1e-9):
        """x_s at the saved times `ts` (from 0, increasing) and the number of right-hand-side
        evaluations."""
        ts = np.asarray(ts, dtype=float)
        t0, t_end, y = 0.0, float(ts[-1]), self.y0()
        x_s, evaluations, v_minus = np.full(ts.size, np.nan), 0, None
        while t0 < t_end:
            in_contact = v_minus is not None
            start = t0

            def crossing(t, yy, _v, start=start, in_contact=in_contact):
                # at the restart δ is 0 to round-off: take the side the state is leaving into
                return (1.0 if in_contact else -1.0) if t == start else self.gap(t, yy)[0]

            crossing.terminal, crossing.direction = True, -1.0 if in_contact else 1.0
            first = np.searchsorted(ts, t0)
            run = solve_ivp(
                self.rhs,
                (t0, t_end),
                y,
                method=method,
                rtol=rtol,
                atol=atol,
                t_eval=ts[first:],
                events=crossing,
                args=(v_minus,),
                first_step=min(1e-8, t_end - t0),
            )
            if run.status == -1:
                raise RuntimeError(f"{method} failed at t = {run.t[-1] if run.t.size else t0}")
            x_s[first : first + run.t.size] = run.y[1]
            evaluations += run.nfev
            if run.status != 1:
                break
            t0, y = float(run.t_events[0][0]), run.y_events[0][0]
            v_minus = None if in_contact else max(self.gap(t0, y)[1], 1e-12)
        return x_s, evaluations
