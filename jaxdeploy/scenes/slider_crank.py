"""The Flores slider-crank with a revolute clearance joint between connecting rod and slider.

Crank 0.05 m driven at 5000 rpm, rod 0.12 m (0.21 kg, 2.5e-4 kg m²), slider 0.14 kg; the
rod–slider joint has a bearing of radius 10 mm on the slider and a journal of 9.5 mm on the rod
(c = 0.5 mm); steel (E = 207 GPa, ν = 0.3); Lankarani–Nikravesh damping with c_e = 0.9;
frictionless by default; gravity −y. It starts at crank angle 0 (top dead centre, crank along
+x) with the journal centred in the bearing and the ideal mechanism's velocities, and runs two
revolutions. Crank mass/inertia (0.30 kg, 1e-5 kg m²) and slider inertia
(1e-4 kg m²) are the companions usually quoted with this case (Flores et al. 2006, recalled,
unverified); the crank is driven and the slider does not rotate, so they change the joint
reactions but not the motion.

References: P. Flores, J. Ambrósio, *Comput. Struct.* 82 (2004) 1359; P. Flores et al.,
*Mech. Mach. Theory* 41 (2006) 247.
"""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np

from .._validation import is_concrete
from ..mechanism import (
    AngleDriver,
    Body,
    Gravity,
    Mechanism,
    Prismatic,
    Revolute,
    RevoluteClearance,
    consistent_motion,
    consistent_state,
    first_onset_times,
    onset_counts,
)
from ..solvers.step_control import StepControl
from ._contact import (
    CONTACT_PARAMS,
    FRICTION_SHAPE_OPTION,
    IDEAL_OPTION,
    IMPACT_VELOCITY_FLOOR_SPEC,
    IMPACT_VELOCITY_RULE_OPTION,
    JOINT_GEOMETRIES,
    JOINT_SIZE_NAMES,
    NORMAL_LAW_OPTION,
    SLIP_VELOCITY_SPEC,
    check_choice,
    check_contact_options,
    check_joint_geometry,
    clearance_contact_laws,
    clearance_spec,
    complete_joint_geometry,
    joint_geometry_params,
)
from .base import OptionSpec, ParamSpec, Scene, is_exactly_zero

INF = math.inf
RPM = 2.0 * math.pi / 60.0


class SliderCrank(Scene):
    """Slider-crank with one clearance joint (rod–slider); `ideal=True` makes it ideal."""

    name = "slider_crank"
    params = {
        "crank_length": ParamSpec(0.05, 0, INF, "m", "crank length r", False),
        "rod_length": ParamSpec(0.12, 0, INF, "m", "connecting-rod length l", False),
        "crank_speed": ParamSpec(5000 * RPM, -1e4, 1e4, "rad/s", "crank angular speed"),
        "crank_mass": ParamSpec(0.30, 0, INF, "kg", "crank mass", False),
        "crank_inertia": ParamSpec(1e-5, 0, INF, "kg m^2", "crank inertia", False),
        "rod_mass": ParamSpec(0.21, 0, INF, "kg", "rod mass", False),
        "rod_inertia": ParamSpec(2.5e-4, 0, INF, "kg m^2", "rod inertia", False),
        "slider_mass": ParamSpec(0.14, 0, INF, "kg", "slider mass", False),
        "slider_inertia": ParamSpec(1e-4, 0, INF, "kg m^2", "slider inertia", False),
        "journal_radius": ParamSpec(9.5e-3, 0, INF, "m", "pin radius R_j", False),
        "clearance": clearance_spec(0.5e-3, 0.1, "radial clearance c = R_b − R_j"),
        "youngs_modulus": ParamSpec(207e9, 1e6, 1e13, "Pa", "Young's modulus (pin and bearing)"),
        "poisson_ratio": ParamSpec(0.3, -1, 0.5, "", "Poisson's ratio", False, False),
        "sigma": ParamSpec(0.0, 0, 1e-4, "m", "combined RMS roughness σ (0: smooth, Hertz)"),
        "restitution": ParamSpec(0.9, 0, 1, "", "coefficient of restitution c_e", False),
        "friction_coefficient": ParamSpec(0.0, 0, 2, "", "friction μ (0: no friction traced)"),
        "gravity": ParamSpec(9.81, 0, 1e3, "m/s^2", "gravity (−y)"),
        "impact_velocity_floor": IMPACT_VELOCITY_FLOOR_SPEC,
        "friction_slip_velocity": SLIP_VELOCITY_SPEC,
    }
    default_t_end = 2.0 * 2.0 * math.pi / (5000 * RPM)  # two revolutions
    # The tolerance chooses the method (`"auto"`, jaxdeploy.solvers.resolve_solver): Tsit5 at
    # the default rtol 1e-6, Dopri8 below AUTO_TIGHT_RTOL. Measured against the independent
    # minimal-coordinate reference over two revolutions (docs/solver_by_tolerance.md): at
    # rtol 1e-6 Tsit5 finds all 26 impacts with x_s within 1.8e-5 m, where generalized-α
    # (this scene's default until then) found 23 with x_s off by 4.9e-4 m (about the
    # clearance) for about the same CPU time; a second-order method's error at this
    # tolerance is too large for the case. `--solver generalized_alpha` still runs it.
    default_control = StepControl("auto", rtol=1e-6, atol=1e-9, dt_max=1e-4)
    option_specs = {
        "ideal": IDEAL_OPTION,
        "normal_law": NORMAL_LAW_OPTION,
        "impact_velocity_rule": IMPACT_VELOCITY_RULE_OPTION,
        "friction_shape": FRICTION_SHAPE_OPTION,
        "geometry": OptionSpec(
            "journal_clearance",
            tuple(JOINT_GEOMETRIES),
            "which two of the joint's sizes are parameters (journal_radius, clearance, "
            "bore_radius); the third follows",
        ),
    }

    def __init__(
        self,
        ideal: bool = False,
        normal_law: str = "lankarani_nikravesh",
        impact_velocity_rule: str = "onset",
        friction_shape: str = "algebraic",
        geometry: str = "journal_clearance",
    ):
        check_contact_options(normal_law, impact_velocity_rule, friction_shape)
        check_choice("geometry", geometry, tuple(JOINT_GEOMETRIES))
        self.ideal = ideal
        self.normal_law = normal_law
        self.impact_velocity_rule = impact_velocity_rule
        self.friction_shape = friction_shape
        self.geometry = geometry
        # The joint's two independent sizes (JOINT_GEOMETRIES); the third follows from them.
        self.params = joint_geometry_params(type(self).params, geometry)

    def ignored_params(self) -> dict[str, str]:
        if not self.ideal:
            return {}
        contact = [n for n in self.params if n in CONTACT_PARAMS or n in JOINT_SIZE_NAMES]
        return dict.fromkeys(contact, "ideal=false")

    def complete(self, params) -> dict:
        """`params` with the joint's three sizes (journal_radius, clearance, bore_radius [m]),
        whichever two the geometry option made parameters."""
        return complete_joint_geometry(params, self.geometry)

    @property
    def options(self) -> dict:
        return {
            "ideal": self.ideal,
            "normal_law": self.normal_law,
            "impact_velocity_rule": self.impact_velocity_rule,
            "friction_shape": self.friction_shape,
            "geometry": self.geometry,
        }

    def check_params(self, params):
        """The crank must be shorter than the rod, or the mechanism locks before a revolution;
        the bore must be larger than the journal."""
        check_joint_geometry(params, self.geometry)
        r, ell = params["crank_length"], params["rod_length"]
        if is_concrete((r, ell)) and not float(r) < float(ell):
            raise ValueError(
                f"crank_length = {float(r)!r} m is invalid with rod_length = {float(ell)!r} m: "
                f"it must be in (0, {float(ell)!r}) m (a crank as long as its rod cannot turn a "
                "full revolution)"
            )

    def build(self, params):
        p = self.complete(params)
        r, ell = p["crank_length"], p["rod_length"]
        zero = 0.0 * r
        crank = Body(
            "crank",
            p["crank_mass"],
            p["crank_inertia"],
            {"pivot": jnp.stack([-0.5 * r, zero]), "pin": jnp.stack([0.5 * r, zero])},
        )
        rod = Body(
            "rod",
            p["rod_mass"],
            p["rod_inertia"],
            {"big_end": jnp.stack([-0.5 * ell, zero]), "small_end": jnp.stack([0.5 * ell, zero])},
        )
        slider = Body(
            "slider", p["slider_mass"], p["slider_inertia"], {"centre": jnp.stack([zero, zero])}
        )
        elements = [
            Revolute("ground", "O", "crank", "pivot"),
            AngleDriver("ground", "crank", angle0=0.0, speed=p["crank_speed"]),
            Revolute("crank", "pin", "rod", "big_end"),
            Prismatic("ground", "O", "slider", "centre", axis=(1.0, 0.0)),
        ]
        if self.ideal:
            elements.append(Revolute("slider", "centre", "rod", "small_end"))
        else:
            normal, friction = clearance_contact_laws(
                journal_radius=p["journal_radius"],
                clearance=p["clearance"],
                youngs_modulus=p["youngs_modulus"],
                poisson_ratio=p["poisson_ratio"],
                sigma=p["sigma"],
                restitution=p["restitution"],
                friction_coefficient=p["friction_coefficient"],
                normal_law=self.normal_law,
                slip_velocity=p["friction_slip_velocity"],
                friction_shape=self.friction_shape,
                impact_velocity_floor=p["impact_velocity_floor"],
            )
            elements.append(
                RevoluteClearance(
                    "slider",
                    "centre",
                    "rod",
                    "small_end",
                    clearance=p["clearance"],
                    journal_radius=p["journal_radius"],
                    normal=normal,
                    friction=friction,
                    impact_velocity_rule=self.impact_velocity_rule,
                )
            )
        if not is_exactly_zero(p["gravity"]):
            elements.append(Gravity(jnp.stack([zero, -p["gravity"]])))
        return Mechanism([crank, rod, slider], elements, ground_points={"O": (0.0, 0.0)})

    def events(self, mechanism, trajectory):
        """`first_onset_time` [s]: the onset of the rod–slider joint's first contact (NaN if
        none by the run's end), located inside its step and differentiable
        (`jaxdeploy.mechanism.first_onset_times`), and `impacts`: contacts begun (a count);
        none for the ideal mechanism."""
        onsets = first_onset_times(mechanism, trajectory.memory)
        if not onsets:
            return {}
        (index, t_on), counts = (
            next(iter(onsets.items())),
            onset_counts(mechanism, trajectory.memory),
        )
        return {"first_onset_time": t_on, "impacts": counts[index]}

    def initial_state(self, params, mechanism):
        """Crank angle 0; the ideal mechanism's pose and velocities (journal centred)."""
        r, ell = params["crank_length"], params["rod_length"]
        q_guess = jnp.array(
            [0.5 * r, 0.0, 0.0, r + 0.5 * ell, 0.0, 0.0, r + ell, 0.0, 0.0], dtype=float
        )
        ideal = mechanism.idealized()
        if mechanism.n_constraints == ideal.n_constraints:  # already ideal
            return consistent_state(ideal, q_guess)
        q, v = consistent_motion(ideal, q_guess)
        return consistent_state(mechanism, q, v)


def ideal_slider_kinematics(crank_length, rod_length, crank_speed, t):
    """Closed-form in-line slider-crank kinematics from top dead centre (`x(θ)` differentiated
    twice; tests/test_mechanism.py checks v and a by complex-step differentiation):

    `x = r cos θ + l S`, `v = −r ω sin θ (1 + λ cos θ / S)`,
    `a = −r ω² [cos θ + λ cos 2θ / S + λ³ sin² 2θ / (4 S³)]`, `S = sqrt(1 − λ² sin² θ)`,
    `λ = r/l`, `θ = ω t`.
    """
    r, ell, w = crank_length, rod_length, crank_speed
    theta = w * np.asarray(t)
    lam = r / ell
    s = np.sqrt(1.0 - lam**2 * np.sin(theta) ** 2)
    x = r * np.cos(theta) + ell * s
    v = -r * w * np.sin(theta) * (1.0 + lam * np.cos(theta) / s)
    a = (
        -r
        * w**2
        * (
            np.cos(theta)
            + lam * np.cos(2 * theta) / s
            + lam**3 * np.sin(2 * theta) ** 2 / (4 * s**3)
        )
    )
    return x, v, a
