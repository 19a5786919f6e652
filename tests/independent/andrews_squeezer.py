"""Independent reference: Andrews' squeezing mechanism, seven rigid bodies in the plane, in the
relative-angle coordinates of the benchmark (numpy + scipy only; imports nothing from jaxdeploy).

Source of the equations, parameters and initial values: the benchmark as published by Hairer &
Wanner, *Solving Ordinary Differential Equations II*, 2nd ed. (Springer 1996), §VII.7 (after
Manning/Schiehlen, *Multibody Systems Handbook*, 1990), and the Test Set for IVP Solvers
(F. Mazzia, C. Magherini et al., University of Bari, problem "andrews", index-3 DAE of
dimension 27), whose reference solution at t = 0.03 s (PSIDE at rtol = atol = 1e-14 on a
Cray C90) is `TEST_SET_SOLUTION`.

**Model.** q = (β, Θ, γ, Φ, δ, Ω, ε) [rad]: β the crank angle about the fixed origin O, Θ the
angle of the second body relative to the crank, γ the angle of the body hinged at the fixed
point B, and the pairs (Φ, δ), (Ω, ε) the two dyads hinged at the fixed point A. The equations
of motion with six constraint multipliers λ:

    M(q) q̈ = f(q, q̇) − G(q)ᵀ λ,      g(q) = 0,      G = ∂g/∂q,

with M (7 × 7, symmetric; entries as in the Test Set's `andfunc`), f the driving torque
`mom` on the crank, the velocity-product (centrifugal) terms, and the generalised force of the
spring (stiffness c0, rest length l0) between the point D = B + (sd cos γ + sc sin γ,
sd sin γ − sc cos γ) of the body at B and the fixed point C. The constraints close three loops
at the end E = O + rr (cos β, sin β) − d (cos(β+Θ), sin(β+Θ)) of the second body:

    g₁,₂ = E − B − ss (−sin γ, cos γ)
    g₃,₄ = E − A − e (sin(Φ+δ), −cos(Φ+δ)) − zt (cos δ, sin δ)
    g₅,₆ = E − A − zf (cos(Ω+ε), sin(Ω+ε)) − u (sin ε, −cos ε)

**Integration.** The index-1 form: differentiate g twice along the motion. Every constraint is
a sum of terms a·cos ψ or a·sin ψ with ψ a sum of coordinates, whose second derivative is
(∂/∂q)·q̈ − (the term)·ψ̇²; so `G q̈ = Σ term·ψ̇²` (`_constraint_terms`), and

    [[M, Gᵀ], [G, 0]] (q̈, λ) = (f, Σ term·ψ̇²)

is solved at each right-hand-side evaluation; (q, q̇) is integrated by scipy's DOP853. The
constraints drift only by the integration error (checked in the test).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.integrate import solve_ivp

# Parameters of the Test Set's `andpar` (SI units: kg, m, kg m², N/m, N m).
PARAMETERS = {
    "m1": 0.04325,
    "m2": 0.00365,
    "m3": 0.02373,
    "m4": 0.00706,
    "m5": 0.07050,
    "m6": 0.00706,
    "m7": 0.05498,
    "xa": -0.06934,
    "ya": -0.00227,
    "xb": -0.03635,
    "yb": 0.03273,
    "xc": 0.014,
    "yc": 0.072,
    "c0": 4530.0,
    "i1": 2.194e-6,
    "i2": 4.410e-7,
    "i3": 5.255e-6,
    "i4": 5.667e-7,
    "i5": 1.169e-5,
    "i6": 5.667e-7,
    "i7": 1.912e-5,
    "d": 28e-3,
    "da": 115e-4,
    "e": 2e-2,
    "ea": 1421e-5,
    "rr": 7e-3,
    "ra": 92e-5,
    "l0": 7785e-5,
    "ss": 35e-3,
    "sa": 1874e-5,
    "sb": 1043e-5,
    "sc": 18e-3,
    "sd": 2e-2,
    "ta": 2308e-5,
    "tb": 916e-5,
    "u": 4e-2,
    "ua": 1228e-5,
    "ub": 449e-5,
    "zf": 2e-2,
    "zt": 4e-2,
    "fa": 1421e-5,
    "mom": 33e-3,
}

# Consistent initial positions [rad] of the Test Set (velocities 0), and its initial
# accelerations [rad/s²] and multipliers (only λ₁ and λ₂ are nonzero at t = 0).
INITIAL_POSITIONS = np.array(
    [
        -0.0617138900142764496358948458001,
        0.0,
        0.455279819163070380255912382449,
        0.222668390165885884674473185609,
        0.487364979543842550225598953530,
        -0.222668390165885884674473185609,
        1.23054744454982119249735015568,
    ]
)
INITIAL_ACCELERATIONS = np.array(
    [14222.4439199541138705911625887, -10666.8329399655854029433719415, 0, 0, 0, 0, 0]
)
INITIAL_MULTIPLIERS = np.array([98.5668703962410896057654982170, -6.12268834425566265503114393122])

T_END = 0.03  # [s]
# The Test Set's reference solution at T_END: positions [rad], velocities [rad/s],
# accelerations [rad/s²], multipliers λ (PSIDE, rtol = atol = 1e-14).
TEST_SET_SOLUTION = {
    "q": np.array(
        [
            0.1581077119629904e2,
            -0.1575637105984298e2,
            0.4082224013073101e-1,
            -0.5347301163226948e0,
            0.5244099658805304e0,
            0.5347301163226948e0,
            0.1048080741042263e1,
        ]
    ),
    "v": np.array(
        [
            0.1139920302151208e4,
            -0.1424379294994111e4,
            0.1103291221937134e2,
            0.1929337464421385e2,
            0.5735699284790808e0,
            -0.1929337464421385e2,
            0.3231791658026955e0,
        ]
    ),
    "qdd": np.array(
        [
            -0.2463176316945196e5,
            0.5185037701610329e5,
            0.3241025686413781e6,
            0.5667493645176213e6,
            0.1674362929479361e5,
            -0.5667493645176222e6,
            0.9826520791458422e4,
        ]
    ),
    "lam": np.array(
        [
            0.1991753333731910e3,
            -0.2975531228015052e2,
            0.2306654119098399e2,
            0.3145271365475927e2,
            0.2264249232082739e2,
            0.1161740700019673e2,
        ]
    ),
}


class AndrewsSqueezer:
    """The benchmark's equations (module docstring) for parameters `params` (overrides of
    `PARAMETERS`)."""

    def __init__(self, params=None):
        p = dict(PARAMETERS)
        unknown = set(params or {}) - set(p)
        if unknown:
            raise ValueError(f"unknown parameters {sorted(unknown)}; valid: {sorted(p)}")
        p.update(params or {})
        self.p = p

    def mass_matrix(self, q):
        p = self.p
        _, th, _, ph, _, om, _ = q
        e_ea, zf_fa = p["e"] - p["ea"], p["zf"] - p["fa"]
        m = np.zeros((7, 7))
        m[0, 0] = (
            p["m1"] * p["ra"] ** 2
            + p["m2"] * (p["rr"] ** 2 - 2 * p["da"] * p["rr"] * math.cos(th) + p["da"] ** 2)
            + p["i1"]
            + p["i2"]
        )
        m[1, 0] = p["m2"] * (p["da"] ** 2 - p["da"] * p["rr"] * math.cos(th)) + p["i2"]
        m[1, 1] = p["m2"] * p["da"] ** 2 + p["i2"]
        m[2, 2] = p["m3"] * (p["sa"] ** 2 + p["sb"] ** 2) + p["i3"]
        m[3, 3] = p["m4"] * e_ea**2 + p["i4"]
        m[4, 3] = p["m4"] * (e_ea**2 + p["zt"] * e_ea * math.sin(ph)) + p["i4"]
        m[4, 4] = (
            p["m4"] * (p["zt"] ** 2 + 2 * p["zt"] * e_ea * math.sin(ph) + e_ea**2)
            + p["m5"] * (p["ta"] ** 2 + p["tb"] ** 2)
            + p["i4"]
            + p["i5"]
        )
        m[5, 5] = p["m6"] * zf_fa**2 + p["i6"]
        m[6, 5] = p["m6"] * (zf_fa**2 - p["u"] * zf_fa * math.sin(om)) + p["i6"]
        m[6, 6] = (
            p["m6"] * (zf_fa**2 - 2 * p["u"] * zf_fa * math.sin(om) + p["u"] ** 2)
            + p["m7"] * (p["ua"] ** 2 + p["ub"] ** 2)
            + p["i6"]
            + p["i7"]
        )
        return np.tril(m) + np.tril(m, -1).T

    def spring_point(self, q):
        """D, the spring's end on the body hinged at B."""
        p, ga = self.p, q[2]
        return np.array(
            [
                p["sd"] * math.cos(ga) + p["sc"] * math.sin(ga) + p["xb"],
                p["sd"] * math.sin(ga) - p["sc"] * math.cos(ga) + p["yb"],
            ]
        )

    def forces(self, q, v):
        """f(q, q̇): driving torque, velocity products and the spring's generalised force."""
        p = self.p
        _, th, ga, ph, _, om, _ = q
        bep, thp, _, php, dep, omp, epp = v
        d = self.spring_point(q)
        arm = d - np.array([p["xc"], p["yc"]])
        length = math.hypot(*arm)
        tension = -p["c0"] * (length - p["l0"]) / length
        fx, fy = tension * arm
        e_ea, zf_fa = p["e"] - p["ea"], p["zf"] - p["fa"]
        return np.array(
            [
                p["mom"] - p["m2"] * p["da"] * p["rr"] * thp * (thp + 2 * bep) * math.sin(th),
                p["m2"] * p["da"] * p["rr"] * bep**2 * math.sin(th),
                fx * (p["sc"] * math.cos(ga) - p["sd"] * math.sin(ga))
                + fy * (p["sd"] * math.cos(ga) + p["sc"] * math.sin(ga)),
                p["m4"] * p["zt"] * e_ea * dep**2 * math.cos(ph),
                -p["m4"] * p["zt"] * e_ea * php * (php + 2 * dep) * math.cos(ph),
                -p["m6"] * p["u"] * zf_fa * epp**2 * math.cos(om),
                p["m6"] * p["u"] * zf_fa * omp * (omp + 2 * epp) * math.cos(om),
            ]
        )

    def _constraint_terms(self, q):
        """Each constraint as `(terms, const)`, g_i = Σ a·f(ψ) − const over its terms
        `(a, f, ψ-coefficients)`, f = cos or sin, ψ = coefficients · q (module docstring)."""
        p = self.p
        be, beth, ga = (1, 0, 0, 0, 0, 0, 0), (1, 1, 0, 0, 0, 0, 0), (0, 0, 1, 0, 0, 0, 0)
        phde, de = (0, 0, 0, 1, 1, 0, 0), (0, 0, 0, 0, 1, 0, 0)
        omep, ep = (0, 0, 0, 0, 0, 1, 1), (0, 0, 0, 0, 0, 0, 1)
        ex = [(p["rr"], "cos", be), (-p["d"], "cos", beth)]
        ey = [(p["rr"], "sin", be), (-p["d"], "sin", beth)]
        return [
            (ex + [(-p["ss"], "sin", ga)], p["xb"]),
            (ey + [(p["ss"], "cos", ga)], p["yb"]),
            (ex + [(-p["e"], "sin", phde), (-p["zt"], "cos", de)], p["xa"]),
            (ey + [(p["e"], "cos", phde), (-p["zt"], "sin", de)], p["ya"]),
            (ex + [(-p["zf"], "cos", omep), (-p["u"], "sin", ep)], p["xa"]),
            (ey + [(-p["zf"], "sin", omep), (p["u"], "cos", ep)], p["ya"]),
        ]

    @staticmethod
    def _value(a, f, psi):
        return a * (math.cos(psi) if f == "cos" else math.sin(psi))

    @staticmethod
    def _slope(a, f, psi):
        """d/dψ of a·f(ψ)."""
        return -a * math.sin(psi) if f == "cos" else a * math.cos(psi)

    def constraints(self, q):
        return np.array(
            [
                sum(self._value(a, f, float(np.dot(k, q))) for a, f, k in terms) - const
                for terms, const in self._constraint_terms(q)
            ]
        )

    def constraint_jacobian(self, q):
        """G = ∂g/∂q = Σ a·f'(ψ) ∂ψ/∂q per constraint."""
        jac = np.zeros((6, 7))
        for i, (terms, _) in enumerate(self._constraint_terms(q)):
            for a, f, k in terms:
                jac[i] += self._slope(a, f, float(np.dot(k, q))) * np.asarray(k, dtype=float)
        return jac

    def velocity_products(self, q, v):
        """Σ a·f(ψ)·ψ̇² per constraint: `G q̈` on the motion (module docstring)."""
        return np.array(
            [
                sum(
                    self._value(a, f, float(np.dot(k, q))) * float(np.dot(k, v)) ** 2
                    for a, f, k in terms
                )
                for terms, _ in self._constraint_terms(q)
            ]
        )

    def accelerations(self, q, v):
        """(q̈, λ) from the index-1 system."""
        mass, jac = self.mass_matrix(q), self.constraint_jacobian(q)
        matrix = np.block([[mass, jac.T], [jac, np.zeros((6, 6))]])
        rhs = np.concatenate([self.forces(q, v), self.velocity_products(q, v)])
        solution = np.linalg.solve(matrix, rhs)
        return solution[:7], solution[7:]

    def rhs(self, _t, y):
        q, v = y[:7], y[7:]
        return np.concatenate([v, self.accelerations(q, v)[0]])

    def solve(self, t_end=T_END, rtol=1e-12, atol=1e-12, method="DOP853", t_eval=None):
        """scipy `solve_ivp` of (q, q̇) from the Test Set's initial state."""
        y0 = np.concatenate([INITIAL_POSITIONS, np.zeros(7)])
        return solve_ivp(
            self.rhs, (0.0, t_end), y0, method=method, rtol=rtol, atol=atol, t_eval=t_eval
        )
