"""Andrews' squeezing mechanism built with the public mechanism API (issue 21): seven bodies in
absolute coordinates, ten revolute joints, a point-to-point spring and a driving torque.

The benchmark (Hairer & Wanner, *Solving ODEs II*, 1996, §VII.7; the Test Set for IVP Solvers
of Mazzia & Magherini, problem "andrews") is given in relative angles
q = (β, Θ, γ, Φ, δ, Ω, ε) (`independent.andrews_squeezer`). Read off its constraints and mass
matrix, the bodies are (angle of each body's frame; points in the body frame, origin at the
centre of mass):

    1 crank, angle β, pivot O fixed, centre of mass at ra along the crank, pin P at rr
    2 rod, angle β + Θ, pin P, centre of mass da from P towards E, the joint E at d from P
    3 angle γ, pivot B fixed, E at (0, −ss), spring point D at (sd, −sc) from B;
      centre of mass at √(sa² + sb²) from B
    4 angle Φ + δ, hinged to body 5 at H, E at (0, −e) from H, centre of mass at (0, −(e − ea))
    5 angle δ, pivot A fixed, H at (zt, 0); centre of mass at √(ta² + tb²) from A
    6 angle Ω + ε, hinged to body 7 at G, E at (zf, 0) from G, centre of mass at (zf − fa, 0)
    7 angle ε, pivot A fixed, G at (0, −u); centre of mass at √(ua² + ub²) from A

(a body turning about a fixed pivot without gravity depends only on the distance of its centre
of mass from the pivot, so where the benchmark gives two offsets, (sa, sb) etc., they are used
as the body-frame offset; for bodies 2, 4 and 6 the directions are fixed by the cross terms of
the benchmark's mass matrix, e.g. M₅₄ = m₄((e − ea)² + zt (e − ea) sin Φ) + i₄). Bodies 2, 3, 4
and 6 meet at E (three revolutes); the spring c0, l0 joins D to the fixed point C; the torque
`mom` drives the crank.
"""

from __future__ import annotations

import math

import numpy as np
from independent.andrews_squeezer import INITIAL_POSITIONS, PARAMETERS

from jaxdeploy.mechanism import (
    AppliedTorque,
    Body,
    Mechanism,
    Revolute,
    Spring,
    consistent_state,
)


def _rotate(angle, point):
    c, s = math.cos(angle), math.sin(angle)
    return np.array([c * point[0] - s * point[1], s * point[0] + c * point[1]])


def _local(points, centre):
    """Points given relative to a reference point, re-expressed about the centre of mass."""
    return {k: (v[0] - centre[0], v[1] - centre[1]) for k, v in points.items()}


def build(params=None) -> Mechanism:
    p = dict(PARAMETERS)
    p.update(params or {})
    bodies = [
        Body("crank", p["m1"], p["i1"], _local({"O": (0, 0), "P": (p["rr"], 0)}, (p["ra"], 0))),
        Body("rod", p["m2"], p["i2"], _local({"P": (0, 0), "E": (-p["d"], 0)}, (-p["da"], 0))),
        Body(
            "b3",
            p["m3"],
            p["i3"],
            _local({"B": (0, 0), "E": (0, -p["ss"]), "D": (p["sd"], -p["sc"])}, (p["sa"], p["sb"])),
        ),
        Body(
            "b4",
            p["m4"],
            p["i4"],
            _local({"H": (0, 0), "E": (0, -p["e"])}, (0, -(p["e"] - p["ea"]))),
        ),
        Body("b5", p["m5"], p["i5"], _local({"A": (0, 0), "H": (p["zt"], 0)}, (p["ta"], p["tb"]))),
        Body(
            "b6",
            p["m6"],
            p["i6"],
            _local({"G": (0, 0), "E": (p["zf"], 0)}, (p["zf"] - p["fa"], 0)),
        ),
        Body("b7", p["m7"], p["i7"], _local({"A": (0, 0), "G": (0, -p["u"])}, (p["ua"], p["ub"]))),
    ]
    elements = [
        Revolute("ground", "O", "crank", "O"),
        Revolute("crank", "P", "rod", "P"),
        Revolute("ground", "B", "b3", "B"),
        Revolute("rod", "E", "b3", "E"),
        Revolute("ground", "A", "b5", "A"),
        Revolute("b5", "H", "b4", "H"),
        Revolute("rod", "E", "b4", "E"),
        Revolute("ground", "A", "b7", "A"),
        Revolute("b7", "G", "b6", "G"),
        Revolute("rod", "E", "b6", "E"),
        Spring("b3", "D", "ground", "C", stiffness=p["c0"], rest_length=p["l0"]),
        AppliedTorque("crank", p["mom"]),
    ]
    ground = {
        "O": (0.0, 0.0),
        "A": (p["xa"], p["ya"]),
        "B": (p["xb"], p["yb"]),
        "C": (p["xc"], p["yc"]),
    }
    return Mechanism(bodies, elements, ground_points=ground)


def body_angles(angles):
    """Absolute body angles from the benchmark's (β, Θ, γ, Φ, δ, Ω, ε)."""
    be, th, ga, ph, de, om, ep = angles
    return np.array([be, be + th, ga, ph + de, de, om + ep, ep])


def benchmark_angles(q):
    """(β, Θ, γ, Φ, δ, Ω, ε) from absolute coordinates `q` (3 per body)."""
    t = np.asarray(q)[..., 2::3]
    return np.stack(
        [
            t[..., 0],
            t[..., 1] - t[..., 0],
            t[..., 2],
            t[..., 3] - t[..., 4],
            t[..., 4],
            t[..., 5] - t[..., 6],
            t[..., 6],
        ],
        axis=-1,
    )


def initial_state(mechanism: Mechanism, params=None):
    """The benchmark's consistent initial state (velocities 0) in absolute coordinates: each
    body's centre of mass placed from its pivot and angle, then `consistent_state` with the
    crank angle held."""
    p = dict(PARAMETERS)
    p.update(params or {})
    theta = body_angles(INITIAL_POSITIONS)
    by_name = {b.name: b for b in mechanism.bodies}
    placed = {}

    def place(name, angle, point, at):
        # centre of mass such that body point `point` lies at global position `at`
        local = np.asarray(by_name[name].points[point])
        placed[name] = (np.asarray(at) - _rotate(angle, local), angle)

    def world(name, point):
        centre, angle = placed[name]
        return centre + _rotate(angle, np.asarray(by_name[name].points[point]))

    place("crank", theta[0], "O", (0.0, 0.0))
    place("rod", theta[1], "P", world("crank", "P"))
    place("b3", theta[2], "B", (p["xb"], p["yb"]))
    place("b5", theta[4], "A", (p["xa"], p["ya"]))
    place("b4", theta[3], "H", world("b5", "H"))
    place("b7", theta[6], "A", (p["xa"], p["ya"]))
    place("b6", theta[5], "G", world("b7", "G"))
    q = np.concatenate([[*placed[b.name][0], placed[b.name][1]] for b in mechanism.bodies])
    return consistent_state(mechanism, q, fixed=(2,))
