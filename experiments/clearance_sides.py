"""The clearance joint at clearances comparable to the roughness (docs/contact.md, "Both sides of
the bearing"): force and stiffness of a centred journal with one contact point (the force along
n = e/|e|, as before the far side was added) and with both sides of the bore, for a steel pin
(R_j = 5 mm, E = 207 GPa, ν = 0.3, K from the geometry) with σ = 1 µm and c/σ from 0.5 to 40.

Writes the generated block `clearance_sides` of docs/contact.md.

Usage: `python experiments/clearance_sides.py`.
"""

from __future__ import annotations

import os

import jax
import jax.numpy as jnp
import numpy as np

from jaxdeploy import contact, pages
from jaxdeploy.mechanism import Body, Mechanism, RevoluteClearance

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DOC = os.path.join(ROOT, "docs", "contact.md")
SIGMA = 1e-6
RATIOS = (0.5, 1.0, 2.0, 3.0, 5.0, 10.0, 40.0)


def joint(clearance):
    stiffness = contact.journal_bearing_stiffness(5e-3, clearance, 207e9, 0.3, 207e9, 0.3)
    law = contact.Flores(contact.RoughElastic(stiffness, SIGMA), 0.9)
    return RevoluteClearance(
        "ground", "B", "journal", "c", clearance=clearance, journal_radius=5e-3, normal=law,
        friction=contact.SmoothCoulomb(0.3),
    )  # fmt: skip


def mechanism(j):
    return Mechanism([Body("journal", 1.0, 1.25e-5, {"c": (0.0, 0.0)})], [j], {"B": (0.0, 0.0)})


def one_point_force(j, e):
    """The single-contact-point elastic force on the journal, −F_e(|e| − c) n."""
    norm = jnp.sqrt(jnp.dot(e, e) + j.eccentricity_smoothing**2)
    return -j.normal.elastic.force(norm - j.clearance) * e / norm


def two_sided(j, q, v, v_minus):
    mech = mechanism(j)
    memory = ({**mech.init_memory(q, v)[0], "impact_velocity": jnp.asarray(v_minus)},)
    return mech.generalized_forces(q, v, 0.0, memory)


def _matrix(m):
    return "[[" + "], [".join(", ".join(f"{x:.2e}" for x in row) for row in m) + "]]"


# What moves the numbers: the contact laws and the clearance joint's force (not the solvers).
MEASURES = [
    "experiments/clearance_sides.py",
    "jaxdeploy/contact",
    "jaxdeploy/mechanism/clearance.py",
    "jaxdeploy/mechanism/_step_eccentricity.py",
]


def main():
    record = pages.start(MEASURES, "python experiments/clearance_sides.py")
    rows = []
    for ratio in RATIOS:
        j = joint(ratio * SIGMA)
        elastic = j.normal.elastic
        c = ratio * SIGMA
        e0 = jnp.zeros(2)
        k_one = float(-jax.jacfwd(lambda e, j=j: one_point_force(j, e))(e0)[0, 0])
        k_two = float(
            -jax.jacfwd(lambda q, j=j: two_sided(j, q, jnp.zeros(3), 0.3))(jnp.zeros(3))[0, 0]
        )
        far = float(elastic.force(-c))
        rows.append(
            f"| {ratio:g} | {float(elastic.stiffness_coefficient):.3e} | {far:.2e} | "
            f"{k_one:.1e} | {k_two:.3e} | {2 * float(elastic.stiffness(-c)):.3e} |"
        )
    # The direction-dependent damping and friction near the centre (c = σ): derivatives of the
    # generalized force at |e| = 3 nm, moving at 5 cm/s (3 radial, 4 tangential), spinning.
    j = joint(SIGMA)
    q = jnp.array([3e-9, 0.0, 0.0])
    v = jnp.array([0.03, 0.04, 3.0])
    jac = np.asarray(jax.jacfwd(lambda q: two_sided(j, q, v, 0.3))(q))[:2, :2]
    jac_rest = np.asarray(jax.jacfwd(lambda q: two_sided(j, q, jnp.zeros(3), 0.3))(q))[:2, :2]
    text = (
        "σ = 1 µm, steel pin R_j = 5 mm, "
        "E = 207 GPa, ν = 0.3, K from the geometry for each c, s0 = 0, ε = 1e-12 m; stiffness "
        "= −∂Q_x/∂x of the centred journal (`jax.jacfwd`).\n\n"
        "| c/σ | K [N/m^1.5] | F_e(−c) at the centre, each side [N] | one point: "
        "stiffness F_e(−c)/ε [N/m] | both sides: stiffness [N/m] | closed form 2 F_e'(−c) "
        "[N/m] |\n|---|---|---|---|---|---|\n"
        + "\n".join(rows)
        + "\n\nDamping and friction near the centre (c = σ, Flores c_e = 0.9, v⁻ = 0.3 m/s, "
        "μ = 0.3) at |e| = 3 nm along x: ∂Q/∂e (N/m, rows Q_x, Q_y) moving at ė = (3, 4) cm/s "
        f"and spinning at 3 rad/s: {_matrix(jac)}; at rest: {_matrix(jac_rest)}.\n"
    )
    pages.write_block(DOC, "clearance_sides", text, record)
    print(text)


if __name__ == "__main__":
    main()
