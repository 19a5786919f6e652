"""Independent reference: a uniform rod hanging from a pivot with radial clearance (the
mechanism of docs/tutorial.md), in the journal's own coordinates, numpy + scipy only.

Written from the papers' equations; it imports nothing from jaxdeploy and shares no modelling
shortcut with it (no centre-of-mass coordinates, no constraint solve, no interpolated memory,
no two-sided contact, no eccentricity regularisation).

**Model.** A uniform rod of mass m and length L (inertia m L²/12 about its centre) carries at
one end a journal of radius R_j inside a bearing of radius R_j + c fixed to the ground at the
origin. Generalised coordinates q = (x, y, θ): the journal centre p = (x, y) (which is also the
bearing eccentricity e) and the rod angle θ from +x. With u = (cos θ, sin θ),
u⊥ = (−sin θ, cos θ) and a = L/2 the rod's centre of mass is G = p + a u, and

    T = ½ m |ṗ + a θ̇ u⊥|² + ½ (m L²/12) θ̇²,   V = m g G_y.

Lagrange's equations with the contact force F on the journal (applied at the contact point
p + R_j n, along −n: it has no moment about p, and the contact point does not depend on θ):

    m p̈ + m a (θ̈ u⊥ − θ̇² u) = F + (0, −m g)
    m a u⊥·p̈ + (m L²/12 + m a²) θ̈ = −m g a cos θ

**Contact** (Flores & Ambrósio, *Comput. Struct.* 82 (2004) 1359, eqs. 1–6 and 19–20):
δ = |p| − c, n = p/|p|, δ̇ = ṗ·n (the bearing is the ground), F = −F_N n with the Hertz
stiffness of a journal in a bearing

    K = 4 / (3 (σ_i + σ_j)) · sqrt(R_i R_j / (R_i − R_j)),   σ_k = (1 − ν_k²)/E_k,

and the Lankarani–Nikravesh (*J. Mech. Des.* 112 (1990) 369, eq. 17) law with the classical
rule (δ̇⁻ the approach speed at the onset, held until separation):

    F_N = K δ^1.5 (1 + 3(1 − c_e²)/4 · δ̇/δ̇⁻),

cut to 0 where the bracket is negative (the tensile corner; the paper's law has none, the cut
is the common guard), and with δ̇⁻ replaced by `impact_velocity_floor` when it is smaller (an
input of the case, as the contact law's parameter; it does not act when every onset is faster).

**Events located** (scipy `solve_ivp`, DOP853, restarted at each): onset (δ = 0 rising, out of
contact), separation (δ = 0 falling, in contact), the tensile corner; inside contact, not
terminal, the maxima of δ (δ̇ = 0) and of F_N (dF_N/dt = 0, with δ̈ from the equations of
motion). A grazing contact whose two crossings fall inside one step would be missed by a sign
test at step ends (and a step that starts at a separation, δ = 0, could span the whole dip
below 0 and the next rise), so δ is also sampled 32 times per step on the dense output of
every out-of-contact segment, and its first rise above 0 is refined by brentq and taken as
the onset. The normal impulse ∫F_N dt is integrated
as an extra state.

**Initial state** (the tutorial's): journal centred, rod horizontal along +x, at rest.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import brentq


@dataclass(frozen=True)
class Pendulum:
    """The case, SI units (defaults: the tutorial's mechanism)."""

    length: float = 0.4
    mass: float = 0.5
    journal_radius: float = 5e-3
    clearance: float = 1e-4
    young: float = 207e9
    poisson: float = 0.3
    restitution: float = 0.8
    gravity: float = 9.81
    impact_velocity_floor: float = 1e-4

    @property
    def stiffness(self) -> float:
        sigma = (1.0 - self.poisson**2) / self.young
        r_i, r_j = self.journal_radius + self.clearance, self.journal_radius
        return 4.0 / (3.0 * 2.0 * sigma) * np.sqrt(r_i * r_j / (r_i - r_j))

    @property
    def chi(self) -> float:
        return 0.75 * (1.0 - self.restitution**2)


@dataclass
class Episode:
    onset_time: float
    impact_velocity: float
    separation_time: float = np.nan
    peak_force: float = 0.0
    peak_force_time: float = np.nan
    peak_penetration: float = -np.inf
    impulse: float = 0.0


@dataclass
class Solution:
    ts: np.ndarray  # (N,)
    journal: np.ndarray  # (N, 2) journal centre [m]
    angle: np.ndarray  # (N,) rod angle [rad]
    episodes: list = field(default_factory=list)
    steps: int = 0

    @property
    def centre_of_mass(self) -> np.ndarray:
        return self.journal + 0.5 * self.length * np.stack(
            [np.cos(self.angle), np.sin(self.angle)], axis=-1
        )

    length: float = 0.4


def _kinematics(y):
    p, pd = y[0:2], y[3:5]
    r = np.hypot(p[0], p[1])
    n = p / r if r > 0 else np.array([1.0, 0.0])
    return p, pd, r, n, float(pd @ n)


def _normal_force(case, y, v_minus, in_contact):
    p, pd, r, n, rate = _kinematics(y)
    delta = r - case.clearance
    if not in_contact or delta <= 0.0:
        return 0.0
    v = max(v_minus, case.impact_velocity_floor)
    return max(0.0, case.stiffness * delta**1.5 * (1.0 + case.chi * rate / v))


def _accelerations(case, y, force_vector):
    """(p̈, θ̈) from the two Lagrange equations (a 3×3 linear solve)."""
    m, a = case.mass, 0.5 * case.length
    theta, thetad = y[2], y[5]
    u = np.array([np.cos(theta), np.sin(theta)])
    up = np.array([-np.sin(theta), np.cos(theta)])
    inertia = m * case.length**2 / 12.0 + m * a * a
    matrix = np.array(
        [[m, 0.0, m * a * up[0]], [0.0, m, m * a * up[1]], [m * a * up[0], m * a * up[1], inertia]]
    )
    rhs = np.array(
        [
            force_vector[0] + m * a * thetad**2 * u[0],
            force_vector[1] - m * case.gravity + m * a * thetad**2 * u[1],
            -m * case.gravity * a * np.cos(theta),
        ]
    )
    return np.linalg.solve(matrix, rhs)


def _rhs(case, v_minus, in_contact):
    def f(t, y):
        fn = _normal_force(case, y, v_minus, in_contact)
        _, _, _, n, _ = _kinematics(y)
        acc = _accelerations(case, y, -fn * n)
        return np.array([y[3], y[4], y[5], acc[0], acc[1], acc[2], fn])

    return f


def _penetration(case):
    def g(t, y):
        return np.hypot(y[0], y[1]) - case.clearance

    return g


def _rate(t, y):
    return _kinematics(y)[4]


def _force_slope(case, v_minus):
    """dF_N/dt in contact (δ > 0, bracket > 0): K[1.5 δ^½ δ̇ B + δ^1.5 χ δ̈/v], B the bracket,
    δ̈ = p̈·n + (|ṗ|² − δ̇²)/|p|."""

    def g(t, y):
        p, pd, r, n, rate = _kinematics(y)
        delta = max(r - case.clearance, 0.0)
        v = max(v_minus, case.impact_velocity_floor)
        bracket = 1.0 + case.chi * rate / v
        fn = case.stiffness * delta**1.5 * max(bracket, 0.0)
        acc = _accelerations(case, y, -fn * n)
        rate_dot = acc[:2] @ n + (pd @ pd - rate**2) / r
        return case.stiffness * (
            1.5 * np.sqrt(delta) * rate * bracket + delta**1.5 * case.chi * rate_dot / v
        )

    return g


def _first_missed_onset(pen, clearance, sol, per_step=32):
    """The first onset inside a step of an out-of-contact segment that a sign test at the
    step's ends cannot see (δ rises above 0 and falls back, or the segment starts at a
    separation and spans the dip and the next rise): δ sampled `per_step` times per step on
    the dense output, the first rise above 0 refined by brentq. None if there is none."""
    for a, b in zip(sol.t[:-1], sol.t[1:], strict=True):
        grid = np.linspace(a, b, per_step + 1)
        values = np.hypot(*sol.sol(grid)[:2]) - clearance
        rising = np.flatnonzero((values[:-1] <= 0.0) & (values[1:] > 0.0))
        if rising.size:
            k = rising[0]
            return brentq(
                lambda s: pen(s, sol.sol(s)), grid[k], grid[k + 1], xtol=1e-16, rtol=1e-15
            )
    return None


def _terminal(fun, direction):
    fun.terminal, fun.direction = True, direction
    return fun


def solve(case: Pendulum, t_end: float, ts, *, rtol=1e-12, atol=1e-15) -> Solution:
    """The motion over [0, t_end], saved at `ts` (increasing, within it), and the contact
    episodes (onset time and δ̇⁻, separation, peak force and its time, peak penetration,
    impulse)."""
    ts = np.asarray(ts, dtype=float)
    y = np.zeros(7)
    y[0:3] = (0.0, 0.0, 0.0)
    t, in_contact, v_minus = 0.0, False, 0.0
    saved = np.full((ts.size, 6), np.nan)
    episodes: list[Episode] = []
    steps = stalled = 0
    while t < t_end:
        f = _rhs(case, v_minus, in_contact)
        pen = _penetration(case)
        if in_contact:

            def separation(t, y, pen=pen):
                return pen(t, y)

            def corner(t, y, v_minus=v_minus):
                v = max(v_minus, case.impact_velocity_floor)
                return 1.0 + case.chi * _rate(t, y) / v

            events = [_terminal(separation, -1), _terminal(corner, -1)]
            # Not terminal: the peaks of δ and of F_N inside the contact.
            peak_delta = _rate
            peak_delta.terminal, peak_delta.direction = False, -1
            peak_force = _force_slope(case, v_minus)
            peak_force.terminal, peak_force.direction = False, -1
            events += [peak_delta, peak_force]
        else:

            def onset(t, y, pen=pen):
                return pen(t, y)

            events = [_terminal(onset, 1)]
        window = (ts >= t) & (ts <= t_end)
        sol = solve_ivp(
            f, (t, t_end), y, method="DOP853", rtol=rtol, atol=atol, events=events,
            dense_output=True,
        )  # fmt: skip
        steps += sol.t.size - 1
        t_stop = sol.t[-1]
        fired = [k for k, te in enumerate(sol.t_events) if te.size and te[-1] == t_stop]
        if not in_contact:
            grazing = _first_missed_onset(pen, case.clearance, sol)
            if grazing is not None and grazing < t_stop:
                t_stop, fired = grazing, [0]
        keep = window & (ts <= t_stop)
        if keep.any():
            saved[keep] = sol.sol(ts[keep])[:6].T
        y_stop = sol.sol(t_stop) if t_stop != sol.t[-1] else sol.y[:, -1]
        if in_contact:
            episode = episodes[-1]
            for t_peak, y_peak in zip(sol.t_events[2], sol.y_events[2], strict=True):
                depth = pen(t_peak, y_peak)
                episode.peak_penetration = max(episode.peak_penetration, depth)
            for t_peak, y_peak in zip(sol.t_events[3], sol.y_events[3], strict=True):
                force = _normal_force(case, y_peak, v_minus, True)
                if force > episode.peak_force:
                    episode.peak_force, episode.peak_force_time = force, t_peak
            episode.impulse += y_stop[6] - y[6]
        stalled = stalled + 1 if t_stop <= t else 0
        if stalled > 2:
            # Contacts that close and open again at one instant: the bounces have accumulated
            # (the intervals shrink geometrically with c_e) and the episode count is no longer
            # defined. A case must end before that.
            raise RuntimeError(f"contact episodes accumulate at t = {t:.9g} s: end earlier")
        t, y = t_stop, np.array(y_stop)
        if t >= t_end:
            break
        if not in_contact and 0 in fired:
            in_contact, v_minus = True, _rate(t, y)
            episodes.append(Episode(onset_time=t, impact_velocity=v_minus))
        elif in_contact and 0 in fired:
            in_contact = False
            episodes[-1].separation_time = t
        # The tensile corner (event 1 in contact) and a maximum of δ below 0 out of contact only
        # restart the integration.
    out = Solution(ts, saved[:, 0:2], saved[:, 2], episodes, steps, length=case.length)
    return out
