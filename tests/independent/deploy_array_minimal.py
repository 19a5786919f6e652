"""Independent reference for the ideal-joint deploy_array: one coordinate, closed-form loops.

This module shares no code with jaxdeploy and none of its formulation: it imports nothing from
the package. What it shares is the *model definition* (bodies, hinge points, spring and latch
laws), read as plain JSON from the scene's data file
`jaxdeploy/scenes/data/deploy_array_geometry.json`: body-frame hinge points, masses, inertias,
spring and latch constants, the start angle, and the 45° pose, used only to pick the assembly
branch of each loop. Where jaxdeploy integrates 21 absolute coordinates under 20 constraint
equations (Lagrange multipliers, coordinate projection), this model has one generalized
coordinate — the root-hinge angle α (panel 1 from +y) — and solves the three closed loops in
closed form as functions of α.

Kinematics (all three loops are RR dyads: a knee K joined to two known points P₁, P₂ by links
of fixed lengths l₁, l₂):

    |K − P₁| = l₁,  |K − P₂| = l₂
    K = P₁ + a e + σ h e⊥,  e = (P₂ − P₁)/L,  a = (l₁² − l₂² + L²)/(2L),  h = √(l₁² − a²)

with σ = ±1 the assembly branch. Differentiating the two length conditions once and twice in α
gives the velocity and acceleration coefficients exactly (Uicker, Pennock & Shigley, *Theory of
Machines and Mechanisms*, 2017, ch. 3–4, loop-closure differentiation):

    (K − Pᵢ) · (K′ − Pᵢ′) = 0,   (K − Pᵢ) · (K″ − Pᵢ″) + |K′ − Pᵢ′|² = 0,   i = 1, 2

(′ = d/dα), a 2 × 2 linear system for K′ and one for K″. The order of solution is

    panel 1:  θ₁ = π/2 − α, root on the ground's hinge O
    loop 1 (four-bar):   P₁ = A (panel 1), P₂ = G4 (ground), knee B   → rod 3, rod 4
    loop 2 (fold dyad):  P₁ = C (rod 4),   P₂ = tip (panel 1), knee D → rod 5, panel 2
    loop 3 (bracing):    P₁ = E (panel 1), P₂ = F (panel 2),   knee K → rod 6, rod 7

A link through its body points s_P (at P) and s_K (at K) has θ = ∠(K − P) − ∠(s_K − s_P),
θ′ = (u × u′)/l², θ″ = (u × u″)/l² with u = K − P (|u| = l is constant), and centre of mass
r = P − R(θ) s_P.

Dynamics (Lagrange's equation in the one coordinate; e.g. Greenwood, *Advanced Dynamics*,
2003, ch. 2): with the velocity coefficients r_b′, θ_b′ of each body b of mass m_b and central
inertia J_b,

    T = ½ I(α) α̇²,   I(α) = Σ_b m_b |r_b′|² + J_b θ_b′²
    I′(α) = 2 Σ_b (m_b r_b′·r_b″ + J_b θ_b′ θ_b″)
    I(α) α̈ + ½ I′(α) α̇² = M_s(α) + M_L(α, α̇)

Generalized forces in the α sense (from the scene's description, docs/deploy_array_geometry.md
§6–7; no gravity, the array deploys in orbit):

    spring  M_s = k (α₀ − α)                              (k = 1.5 N m/rad, α₀ = 180°)
    latch   M_L = −k_L (α − α_L) − c_L α̇  once α has first reached α_L = 90°, 0 before

The latch engagement is located as an event (α = α_L, rising) by `scipy.integrate.solve_ivp`;
the integration then restarts from that state with the latch on.

Units: SI throughout (m, kg, s, rad, N m).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp

DATA_FILE = (
    Path(__file__).resolve().parents[2]
    / "jaxdeploy"
    / "scenes"
    / "data"
    / "deploy_array_geometry.json"
)


def _rot(theta):
    c, s = math.cos(theta), math.sin(theta)
    return np.array([[c, -s], [s, c]])


def _perp(v):
    """v rotated by +90°."""
    return np.array([-v[1], v[0]])


def _cross(a, b):
    return a[0] * b[1] - a[1] * b[0]


@dataclass(frozen=True)
class Motion:
    """A body's pose and its first and second derivatives with respect to α."""

    r: np.ndarray  # centre of mass [m]
    th: float  # angle from world +x [rad]
    r1: np.ndarray  # dr/dα [m/rad]
    th1: float  # dθ/dα [-]
    r2: np.ndarray  # d²r/dα² [m/rad²]
    th2: float  # d²θ/dα² [1/rad]

    def point(self, s):
        """World position of body point s and its α-derivatives:
        p = r + R s, p′ = r′ + θ′ R s⊥, p″ = r″ + θ″ R s⊥ − θ′² R s."""
        rs = _rot(self.th) @ np.asarray(s, dtype=float)
        return (
            self.r + rs,
            self.r1 + self.th1 * _perp(rs),
            self.r2 + self.th2 * _perp(rs) - self.th1**2 * rs,
        )


def _fixed(p):
    p = np.asarray(p, dtype=float)
    return p, np.zeros(2), np.zeros(2)


def _knee(p1, p2, l1, l2, sign):
    """Knee of an RR dyad and its α-derivatives (module docstring)."""
    (a1, a1d, a1dd), (b1, b1d, b1dd) = p1, p2
    d = b1 - a1
    dist = math.hypot(*d)
    e = d / dist
    a = (l1**2 - l2**2 + dist**2) / (2 * dist)
    h2 = l1**2 - a**2
    if h2 <= 0:
        raise ValueError(f"dyad cannot close: |P2 - P1| = {dist} m, l1 = {l1} m, l2 = {l2} m")
    k = a1 + a * e + sign * math.sqrt(h2) * _perp(e)
    rows = np.array([k - a1, k - b1])
    k1 = np.linalg.solve(rows, [rows[0] @ a1d, rows[1] @ b1d])
    rhs2 = [
        rows[0] @ a1dd - (k1 - a1d) @ (k1 - a1d),
        rows[1] @ b1dd - (k1 - b1d) @ (k1 - b1d),
    ]
    k2 = np.linalg.solve(rows, rhs2)
    return k, k1, k2


def _link(p, k, s_p, s_k):
    """Motion of the body that carries point s_p at p and point s_k at k (p, k with their
    α-derivatives)."""
    (p0, p1, p2), (k0, k1, k2) = p, k
    s_p, s_k = np.asarray(s_p, dtype=float), np.asarray(s_k, dtype=float)
    u, u1, u2 = k0 - p0, k1 - p1, k2 - p2
    length2 = u @ u
    th = math.atan2(u[1], u[0]) - math.atan2(*(s_k - s_p)[::-1])
    th1 = _cross(u, u1) / length2
    th2 = _cross(u, u2) / length2
    rs = _rot(th) @ s_p
    return Motion(
        r=p0 - rs,
        th=th,
        r1=p1 - th1 * _perp(rs),
        th1=th1,
        r2=p2 - th2 * _perp(rs) + th1**2 * rs,
        th2=th2,
    )


class DeployArrayMinimal:
    """The ideal-joint deployable array in the single coordinate α (module docstring).

    **Arguments:** `data`: the scene's geometry dictionary (default: read from `DATA_FILE`).
    """

    # Dyads (link 1 from P1, link 2 from P2, knee): (P1 body, P1 point), (P2 body, P2 point),
    # link 1 body, link 2 body, knee point name. Order matters: each uses bodies found before.
    LOOPS = (
        (("panel1", "A"), ("ground", "G4"), "rod3", "rod4", "B"),
        (("rod4", "C"), ("panel1", "tip"), "rod5", "panel2", "D"),
        (("panel1", "E"), ("panel2", "F"), "rod6", "rod7", "K"),
    )

    def __init__(self, data: dict | None = None):
        if data is None:
            data = json.loads(DATA_FILE.read_text())
        self.bodies = data["bodies"]
        # The hinges by the pair of points they join, to find a link's point at P1/P2.
        self.hinge_points = {}
        for joint in data["joints"]:
            self.hinge_points[(joint["body_i"], joint["point_i"])] = (
                joint["body_j"],
                joint["point_j"],
            )
            self.hinge_points[(joint["body_j"], joint["point_j"])] = (
                joint["body_i"],
                joint["point_i"],
            )
        self.root = self._partner(("ground", "O"), "panel1")
        for _, _, link1, link2, knee in self.LOOPS:  # the knee is a hinge of the data file
            if self._partner((link1, knee), link2) != knee:
                raise ValueError(f"no hinge {link1}.{knee} - {link2}.{knee} in the data")
        self.k = data["coil_spring"]["k"]
        self.alpha0 = data["coil_spring"]["alpha0"]
        self.alpha_lock = data["latch"]["engage_alpha"]
        self.k_latch = data["latch"]["k_latch"]
        self.c_latch = data["latch"]["c_latch"]
        self.alpha_start = data["initial_state"]["alpha"]
        self.signs = self._branches(data["body_order"], data["initial_state"]["q"])

    def _partner(self, end, body):
        """The point of `body` joined by a hinge to point `end` = (body, point)."""
        other = self.hinge_points[end]
        if other[0] != body:
            raise ValueError(f"{end} is not hinged to {body}")
        return other[1]

    def _p(self, body, point):
        return np.asarray(self.bodies[body]["points"][point], dtype=float)

    def _branches(self, order, q):
        """Each loop's σ: the branch whose knee lies nearest the knee of the data file's 45°
        pose (the assembly drawn in docs/deploy_array_geometry.md: rods under the panels,
        bracing knee below the hinge). The pose picks a discrete branch only; it is no input to
        the positions, which the loops then give in closed form."""
        q = np.asarray(q, dtype=float).reshape(-1, 3)
        targets = {}
        for _, _, link1, _, knee in self.LOOPS:
            x, y, th = q[order.index(link1)]
            targets[knee] = np.array([x, y]) + _rot(th) @ self._p(link1, knee)
        signs = []
        self._solve(self.alpha_start, targets, signs)
        return tuple(signs)

    def motions(self, alpha) -> dict[str, Motion]:
        """Every moving body's `Motion` at deployment angle α [rad]."""
        return self._solve(alpha)

    def _solve(self, alpha, targets=None, chosen=None):
        th = 0.5 * math.pi - alpha
        # Panel 1 turns about the ground hinge O: r = O − R(θ) s_root, θ′ = −1, θ″ = 0, so
        # r′ = −θ′ R s_root⊥ = R s_root⊥ and r″ = θ′² R s_root = R s_root.
        rs = _rot(th) @ self._p("panel1", self.root)
        o = self._p("ground", "O")
        out = {"panel1": Motion(o - rs, th, _perp(rs), -1.0, rs, 0.0)}
        for index, ((b1, n1), (b2, n2), link1, link2, knee) in enumerate(self.LOOPS):
            ends = []
            for body, name in ((b1, n1), (b2, n2)):
                p = self._p(body, name)
                ends.append(_fixed(p) if body == "ground" else out[body].point(p))
            s1 = self._p(link1, self._partner((b1, n1), link1))
            s2 = self._p(link2, self._partner((b2, n2), link2))
            sk1, sk2 = self._p(link1, knee), self._p(link2, knee)
            l1, l2 = math.hypot(*(sk1 - s1)), math.hypot(*(sk2 - s2))
            if targets is None:
                sign = self.signs[index]
            else:
                sign = min(
                    (1.0, -1.0),
                    key=lambda s: np.linalg.norm(
                        _knee(ends[0], ends[1], l1, l2, s)[0] - targets[knee]
                    ),
                )
                chosen.append(sign)
            k = _knee(ends[0], ends[1], l1, l2, sign)
            out[link1] = _link(ends[0], k, s1, sk1)
            out[link2] = _link(ends[1], k, s2, sk2)
        return out

    def generalized_inertia(self, alpha):
        """`(I, I′)` at α: I [kg m²] = Σ m |r′|² + J θ′², I′ [kg m²/rad] its α-derivative."""
        inertia = slope = 0.0
        for name, m in self.motions(alpha).items():
            mass, j = self.bodies[name]["mass"], self.bodies[name]["inertia"]
            inertia += mass * (m.r1 @ m.r1) + j * m.th1**2
            slope += 2.0 * (mass * (m.r1 @ m.r2) + j * m.th1 * m.th2)
        return inertia, slope

    def torque(self, alpha, rate, latched):
        """Generalized force in the α sense [N m]: spring, plus the latch once engaged."""
        out = self.k * (self.alpha0 - alpha)
        if latched:
            out += -self.k_latch * (alpha - self.alpha_lock) - self.c_latch * rate
        return out

    def rhs(self, t, y, latched):
        """`[α̇, α̈]` from I α̈ + ½ I′ α̇² = M."""
        alpha, rate = y
        inertia, slope = self.generalized_inertia(alpha)
        return [rate, (self.torque(alpha, rate, latched) - 0.5 * slope * rate**2) / inertia]

    def energy(self, alpha, rate, latched):
        """Kinetic + spring (+ latch) energy [J]; conserved before the lock."""
        inertia, _ = self.generalized_inertia(alpha)
        out = 0.5 * inertia * rate**2 + 0.5 * self.k * (self.alpha0 - alpha) ** 2
        if latched:
            out += 0.5 * self.k_latch * (alpha - self.alpha_lock) ** 2
        return out

    def simulate(self, t_end=2.0, method="DOP853", rtol=1e-12, atol=1e-12):
        """Deploy from rest at the data file's start angle; the latch engagement located as a
        terminal event, then the locked phase. Returns a `Deployment`."""

        def reach(t, y, latched):
            return y[0] - self.alpha_lock

        reach.terminal = True
        reach.direction = 1.0
        free = solve_ivp(
            self.rhs,
            (0.0, t_end),
            [self.alpha_start, 0.0],
            method=method,
            rtol=rtol,
            atol=atol,
            events=reach,
            dense_output=True,
            args=(False,),
        )
        if free.status == -1:
            raise RuntimeError(f"deployment phase failed: {free.message}")
        if free.status != 1:
            return Deployment(free, None, math.nan, math.nan)
        t_lock = float(free.t_events[0][0])
        y_lock = free.y_events[0][0]
        locked = solve_ivp(
            self.rhs,
            (t_lock, t_end),
            y_lock,
            method=method,
            rtol=rtol,
            atol=atol,
            dense_output=True,
            args=(True,),
        )
        if locked.status != 0:
            raise RuntimeError(f"locked phase failed: {locked.message}")
        return Deployment(free, locked, t_lock, float(y_lock[1]))


@dataclass(frozen=True)
class Deployment:
    """A reference run: the two `solve_ivp` results, the lock time [s] and α̇ at lock [rad/s]."""

    free: object
    locked: object
    lock_time: float
    lock_rate: float

    def state(self, t):
        """`(α, α̇)` [rad, rad/s] at times t [s] (the solver's dense output)."""
        t = np.asarray(t, dtype=float)
        out = np.empty((2, t.size))
        before = t <= self.lock_time if self.locked is not None else np.ones(t.size, bool)
        out[:, before] = self.free.sol(t[before])
        if self.locked is not None and (~before).any():
            out[:, ~before] = self.locked.sol(t[~before])
        return out

    def alpha(self, t):
        return self.state(t)[0]
