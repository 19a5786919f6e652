"""Figures for docs/contact.md, from the public contact API (the effective restitution of the
damped laws is measured by experiments/restitution_table.py, docs/restitution.md).

Writes into docs/figures/:
* contact_elastic.png      F_e(δ) and k_d(δ) for Ra 0.8/1.6/3.2 µm against plain Hertz
                           (steel hinge pin R_j = 5 mm, c = 0.05 mm);
* contact_friction.png     the friction laws' F_T/(μ F_N) against sliding speed;
* contact_damping.png      force–penetration hysteresis of the damped laws in a one-body impact;

and the block `contact-laws-figures` of docs/contact.md that records which commit made them.

Run: .venv/bin/python experiments/contact_laws.py
"""

from __future__ import annotations

import pathlib

import jax
import jax.numpy as jnp
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from scipy.integrate import solve_ivp  # noqa: E402

import jaxdeploy.contact as contact  # noqa: E402
from jaxdeploy import pages  # noqa: E402

OUT = pathlib.Path(__file__).resolve().parents[1] / "docs" / "figures"
DOC = OUT.parent / "contact.md"
# What moves the figures: the contact laws only (the damped impact is integrated by scipy).
MEASURES = ["experiments/contact_laws.py", "jaxdeploy/contact"]
STEEL = dict(E_journal=207e9, nu_journal=0.3, E_bearing=207e9, nu_bearing=0.3)
RADIUS, CLEARANCE = 5e-3, 5e-5
ROUGHNESS = (0.8e-6, 1.6e-6, 3.2e-6)


def elastic_figure(stiffness):
    delta = jnp.linspace(-12e-6, 10e-6, 600)
    laws = [("Hertz (smooth)", contact.HertzElastic(stiffness), "k", "-")]
    for ra, colour in zip(ROUGHNESS, ("tab:blue", "tab:orange", "tab:red"), strict=True):
        sigma = contact.ra_to_sigma(ra)
        label = f"Ra {ra * 1e6:.1f} µm (σ = {float(sigma) * 1e6:.2f} µm)"
        laws.append((label, contact.RoughElastic(stiffness, sigma), colour, "-"))
        laws.append((None, contact.RoughElastic(stiffness, sigma, offset=3.0), colour, ":"))

    fig, axes = plt.subplots(1, 3, figsize=(15, 4.6), constrained_layout=True)
    um = np.asarray(delta) * 1e6
    for label, law, colour, style in laws:
        force = np.asarray(law.force(delta))
        k_d = np.asarray(law.stiffness(delta))
        axes[0].plot(um, force, color=colour, ls=style, label=label)
        axes[1].semilogy(um, np.maximum(force, 1e-6), color=colour, ls=style)
        axes[2].plot(um, k_d / 1e6, color=colour, ls=style, label=label)
    axes[0].set(xlabel="penetration δ (µm)", ylabel="elastic force F_e (N)", ylim=(0, 4000))
    axes[0].set_title("F_e(δ): solid s0 = 0 (mean lines), dotted s0 = 3 (peak tops)", fontsize=9)
    axes[1].set(xlabel="penetration δ (µm)", ylabel="F_e (N), log scale", ylim=(1e-3, 1e4))
    axes[1].set_title("contact onset near δ = (s0 − 3)σ", fontsize=9)
    axes[2].set(xlabel="penetration δ (µm)", ylabel="dynamic contact stiffness k_d (N/µm)")
    axes[2].set_title("k_d = dF_e/dδ = K n σ^(n−1) F_(n−1)(s0 − δ/σ)", fontsize=9)
    axes[0].legend(fontsize=8, loc="upper left")
    for ax in axes:
        ax.grid(alpha=0.3)
    fig.suptitle(
        f"Steel hinge pin R_j = 5 mm, c = 0.05 mm: K = {float(stiffness):.3e} N/m^1.5", fontsize=11
    )
    fig.savefig(OUT / "contact_elastic.png", dpi=120)
    plt.close(fig)


def friction_figure():
    v = jnp.linspace(-3e-3, 3e-3, 1201)
    laws = [
        ("smooth Coulomb, algebraic (v_s = 0.2 mm/s)", contact.SmoothCoulomb(0.1, 2e-4)),
        ("smooth Coulomb, tanh (v_s = 0.2 mm/s)", contact.SmoothCoulomb(0.1, 2e-4, "tanh")),
        ("Ambrósio (v0 = 0.1, v1 = 1 mm/s)", contact.AmbrosioCoulomb(0.1)),
        ("Ambrósio, C¹ smoothstep", contact.AmbrosioCoulomb(0.1, transition="smoothstep")),
        ("Stribeck (μs = 0.15, v_st = 1 mm/s)", contact.StribeckFriction(0.15, 0.1, 1e-3, 5e-5)),
    ]
    fig, ax = plt.subplots(figsize=(7.5, 4.5), constrained_layout=True)
    for label, law in laws:
        ax.plot(np.asarray(v) * 1e3, np.asarray(law.force(v, 1.0)) / 0.1, label=label)
    ax.set(xlabel="sliding speed v_t (mm/s)", ylabel="F_T / (μ_k F_N)")
    ax.set_title("Friction laws (signed along +t; applied against sliding)", fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.savefig(OUT / "contact_friction.png", dpi=120)
    plt.close(fig)


def impact(law, v0, mass):
    """One body hits a fixed bearing wall: m x'' = −F_N(x, x', v0). Returns the solution."""
    force = jax.jit(lambda d, r: law.force(d, r, v0))

    def rhs(_, y):
        return [y[1], -float(force(y[0], y[1])) / mass]

    onset = float(law.elastic.onset_penetration())

    def leave(_, y):
        return y[0] - onset + 1e-13

    leave.terminal, leave.direction = True, -1
    scale = (mass * v0**2 / float(law.elastic.stiffness_coefficient)) ** 0.4
    return solve_ivp(
        rhs,
        (0.0, 100 * scale / v0),
        [onset, v0],
        method="LSODA",
        events=leave,
        rtol=1e-9,
        atol=1e-14,
        dense_output=True,
    )


DAMPED = [
    contact.HuntCrossley,
    contact.LankaraniNikravesh,
    contact.Flores,
    contact.Gonthier,
    contact.HuGuo,
]


def damping_figure(stiffness, mass=0.2, v0=0.1):
    sigma = contact.ra_to_sigma(1.6e-6)
    fig, axes = plt.subplots(1, 2, figsize=(13, 4.6), constrained_layout=True)
    for ax, (title, elastic) in zip(
        axes,
        [
            ("Hertz, c_e = 0.7", contact.HertzElastic(stiffness)),
            ("rough, Ra 1.6 µm, c_e = 0.7", contact.RoughElastic(stiffness, sigma)),
        ],
        strict=True,
    ):
        for cls in DAMPED:
            law = cls(elastic, 0.7)
            sol = impact(law, v0, mass)
            t = np.linspace(0.0, sol.t[-1], 800)
            x, xd = sol.sol(t)
            f = np.asarray(jax.vmap(lambda d, r: law.force(d, r, v0))(x, xd))  # noqa: B023
            e_eff = -sol.y_events[0][0][1] / v0
            ax.plot(x * 1e6, f, label=f"{cls.__name__}: e_eff = {e_eff:.3f}")
        ax.set(xlabel="penetration δ (µm)", ylabel="normal force F_N (N)")
        ax.set_title(f"{title}; m = {mass} kg, v⁻ = {v0} m/s", fontsize=10)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.savefig(OUT / "contact_damping.png", dpi=120)
    plt.close(fig)


def main():
    record = pages.start(MEASURES, "python experiments/contact_laws.py")
    OUT.mkdir(parents=True, exist_ok=True)
    stiffness = contact.journal_bearing_stiffness(RADIUS, CLEARANCE, **STEEL)
    elastic_figure(stiffness)
    friction_figure()
    damping_figure(stiffness)
    text = (
        "The figures of this page (`contact_elastic.png`, `contact_friction.png`, "
        "`contact_damping.png` in docs/figures/): steel hinge pin R_j = "
        f"{RADIUS * 1e3:g} mm, c = {CLEARANCE * 1e3:g} mm, K = {float(stiffness):.4g} N/m^1.5."
    )
    pages.write_block(str(DOC), "contact-laws-figures", text, record)
    print(f"wrote figures to {OUT}")


if __name__ == "__main__":
    main()
