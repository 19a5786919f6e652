"""Independent reference: one journal impacting a fixed bearing with the rough-surface
(Greenwood–Williamson-averaged) Hertz law, as a 1-DOF problem, numpy + scipy (+ mpmath).

Written from the papers' equations; it imports nothing from jaxdeploy.

**Model** (the `impact` scene's case). A free journal of mass m starts at the bearing's centre
(x = 0) moving along +x at v0; its penetration into the bearing wall is δ = x − c (c the radial
clearance). The wall is rough: Gaussian asperity heights of standard deviation σ measured from
the mean planes (Greenwood & Williamson 1966), each asperity a Hertz contact, so the Hertz law
K δ_+^1.5 of the nominal geometry is averaged over the height distribution:

    F_e(δ) = K E[(δ + σ Z)_+^1.5] = K σ^1.5 F_1.5(−δ/σ),   Z ~ N(0, 1)
    F_n(h) = ∫_h^∞ (s − h)^n φ(s) ds,   φ(s) = exp(−s²/2)/sqrt(2π)     (GW 1966, eq. for P)

F_n is computed here by adaptive quadrature with the algebraic endpoint weight (s − h)^n
(QUADPACK's `qawse` through `scipy.integrate.quad(weight="alg")`), which integrates the
endpoint singularity exactly; `gaussian_moment_mpmath` is a second, arbitrary-precision
evaluation used to check it. The potential is U_e(δ) = K σ^2.5 F_2.5(−δ/σ)/2.5, from
dF_(n+1)/dh = −(n + 1) F_n.

Only the wall ahead is modelled: at the centre the wall behind is c/σ ≥ 10 standard deviations
away, where F_1.5(10) = 3e-25 of K σ^1.5.

**Undamped** (`undamped_impact`): energy quadrature. ½ m ẋ² + U_e(x − c) = ½ m v0² + U_e(−c);
the deepest point x_max is the root of U_e(x_max − c) = ½ m v0² + U_e(−c), and the time from
one crossing of a level δ_L to the next is

    t(δ_L) = 2 ∫_{c+δ_L}^{x_max} dx / ẋ(x),   ẋ(x) = sqrt(2 (U_e(x_max − c) − U_e(x − c)) / m)

integrated in mpmath at 30 digits after x = x_max − s² (which removes the turning point's
inverse square root). The rebound speed is v0 (no loss).

**Damped** (`damped_impact`): Lankarani & Nikravesh (1990) on the rough elastic force,

    m ẍ = −F_e(δ) (1 + 3(1 − c_e²)/4 · δ̇/δ̇⁻)   while in contact,   m ẍ = −F_e(δ) outside,

"in contact" meaning δ above the onset level δ_on (−3σ by default: there F_e is 2.6e-4 of
K σ^1.5; the rough force has no true onset), δ̇⁻ the rate at the located rise through δ_on,
held until the located fall through δ_on. `solve_ivp` (DOP853, rtol 1e-12) restarts at both
events. Outside contact the elastic tail is kept undamped: it does work ≤ U_e(δ_on), a fraction
~1e-7 of the impact energy for the scene's numbers (`tail_energy_fraction` gives it), which
bounds how much any other choice for the tail can change the rebound speed.

References: J. A. Greenwood, J. B. P. Williamson, *Proc. R. Soc. A* 295 (1966) 300;
H. M. Lankarani, P. E. Nikravesh, *J. Mech. Des.* 112 (1990) 369; K. L. Johnson, *Contact
Mechanics* (1985), §11.4 (the smooth limit: t_c = 2.9433 δ_max/v0).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mpmath
import numpy as np
from scipy.integrate import quad, solve_ivp
from scipy.optimize import brentq

ONSET_SIGMAS = 3.0


def _phi(s):
    return math.exp(-0.5 * s * s) / math.sqrt(2.0 * math.pi)


def gaussian_moment(n, h):
    """`F_n(h) = ∫_h^∞ (s − h)^n φ(s) ds` by QUADPACK with the weight (s − h)^n."""
    upper = max(h, 0.0) + 40.0  # φ(40) = 1.5e-348: the rest underflows
    value, _ = quad(
        _phi, h, upper, weight="alg", wvar=(n, 0.0), epsabs=0.0, epsrel=1e-13, limit=200
    )
    return value


def gaussian_moment_mpmath(n, h, digits=30):
    """`F_n(h)` by mpmath's tanh-sinh quadrature at `digits` significant digits."""
    with mpmath.workdps(digits):
        h = mpmath.mpf(h)

        def integrand(s):
            return (s - h) ** n * mpmath.exp(-s * s / 2) / mpmath.sqrt(2 * mpmath.pi)

        return mpmath.quad(integrand, [h, h + 1, max(h, 0) + 6, mpmath.inf])


@dataclass
class RoughWall:
    """Rough Hertz wall: `K` [N/m^1.5], σ [m]."""

    stiffness: float
    sigma: float

    def force(self, delta):
        """F_e(δ) [N]."""
        return self.stiffness * self.sigma**1.5 * gaussian_moment(1.5, -delta / self.sigma)

    def potential(self, delta):
        """U_e(δ) [J]."""
        return self.stiffness * self.sigma**2.5 * gaussian_moment(2.5, -delta / self.sigma) / 2.5


def tail_energy_fraction(mass, speed, wall, onset=None):
    """`U_e(δ_on) / (½ m v0²)`: the elastic energy stored below the onset level."""
    onset = -ONSET_SIGMAS * wall.sigma if onset is None else onset
    return wall.potential(onset) / (0.5 * mass * speed**2)


def undamped_impact(mass, speed, clearance, wall, levels=(0.0,)):
    """`(δ_max, {δ_L: time between the two crossings of δ_L})` of the undamped rough impact
    (module docstring), δ in m, times in s."""
    energy = 0.5 * mass * speed**2 + wall.potential(-clearance)
    hertz_max = (5.0 * mass * speed**2 / (4.0 * wall.stiffness)) ** 0.4  # Johnson (1985)
    x_max = brentq(
        lambda x: wall.potential(x - clearance) - energy,
        clearance - 10.0 * wall.sigma,
        clearance + 2.0 * hertz_max + 10.0 * wall.sigma,
        xtol=1e-18,
        rtol=1e-15,
    )

    def gap(x):
        # U_e(x_max − c) − U_e(x − c) as ∫ F_e, not as a difference: near the turning point
        # the difference would be all round-off.
        value, _ = quad(lambda u: wall.force(u - clearance), x, x_max, epsabs=0, epsrel=1e-13)
        return value

    def duration(level):
        # ∫ dx/ẋ with the turning point's (x_max − x)^(-1/2) as QUADPACK's algebraic weight;
        # what remains, sqrt((x_max − x)/(2 gap/m)), is smooth up to x_max.
        def smooth(x):
            return math.sqrt((x_max - x) * mass / (2.0 * gap(x))) if x < x_max else 0.0

        value, _ = quad(
            smooth,
            clearance + level,
            x_max,
            weight="alg",
            wvar=(0.0, -0.5),
            epsabs=0.0,
            epsrel=1e-12,
            limit=200,
        )
        return 2.0 * value

    return x_max - clearance, {lv: duration(lv) for lv in levels}


@dataclass
class DampedImpact:
    """Result of `damped_impact`: times [s], speeds [m/s], penetration [m]."""

    onset_time: float
    separation_time: float
    impact_velocity: float
    max_penetration: float
    rebound_speed: float  # |ẋ| when the journal is back at the bearing's centre
    return_time: float  # when it is back there
    sample: object  # t -> (x, ẋ) on [0, return_time]


def damped_impact(
    mass, speed, clearance, wall, restitution, onset=None, rtol=1e-12, atol=(1e-16, 1e-13)
):
    """The Lankarani–Nikravesh rough impact (module docstring), from the centre to the return
    to the centre."""
    onset = -ONSET_SIGMAS * wall.sigma if onset is None else onset
    chi = 0.75 * (1.0 - restitution**2)

    def rhs(t, y, v_minus):
        delta, rate = y[0] - clearance, y[1]
        force = wall.force(delta)
        if v_minus is not None:
            force = max(0.0, force * (1.0 + chi * rate / v_minus))
        return np.array([y[1], -force / mass])

    def level(t, y, v_minus):
        return y[0] - clearance - onset

    def deepest(t, y, v_minus):
        return y[1]

    def centre(t, y, v_minus):
        return y[0]

    level.terminal = True
    centre.terminal, centre.direction = True, -1.0
    t0, y = 0.0, np.array([0.0, speed])
    v_minus, pieces, times = None, [], {}
    horizon = 10.0 * (clearance + abs(onset)) / speed + 1.0  # ends at the return, long before
    max_penetration = -math.inf
    for phase in ("approach", "contact", "rebound"):
        level.direction = 1.0 if phase == "approach" else -1.0
        events = (level, deepest) if phase != "rebound" else (centre,)
        run = solve_ivp(
            rhs,
            (t0, horizon),
            y,
            method="DOP853",
            rtol=rtol,
            atol=np.asarray(atol),
            events=events,
            args=(v_minus,),
            dense_output=True,
            first_step=1e-9,
        )
        if run.status != 1:
            raise RuntimeError(f"damped impact, {phase}: {run.message}")
        t1 = run.t_events[0][0]
        pieces.append((t0, t1, run.sol))
        if phase == "contact":
            max_penetration = float(run.y_events[1][0][0]) - clearance
        t0, y = t1, run.sol(t1)
        times[phase] = t1
        if phase == "approach":
            v_minus = float(y[1])
        elif phase == "contact":
            v_minus = None

    def sample(ts):
        ts = np.asarray(ts, dtype=float)
        out = np.full((ts.size, 2), np.nan)
        for a, b, dense in pieces:
            inside = (ts >= a) & (ts <= b)
            if inside.any():
                out[inside] = dense(ts[inside]).T
        return out

    return DampedImpact(
        onset_time=times["approach"],
        separation_time=times["contact"],
        impact_velocity=float(pieces[1][2](times["approach"])[1]),
        max_penetration=max_penetration,
        rebound_speed=float(-y[1]),
        return_time=times["rebound"],
        sample=sample,
    )
