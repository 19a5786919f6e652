"""The deployable solar array of the seed study (W24), reconstructed.

Spacecraft body (ground), panel 1 hinged to it (J1, the root hinge), panel 2 hinged to panel
1's tip (J7), and five support rods 3–7 closing three loops: 7 moving links, 10 revolute
joints, 1 degree of freedom with ideal joints. A preloaded coil spring at the root drives the
deployment angle α (between panel 1 and +y) from 45° at rest to 90°, where a latch engages.
Geometry, masses, spring and latch come from the design study
`experiments/deploy_array_geometry.py` (data in `data/deploy_array_geometry.json`, reasons in
`docs/deploy_array_geometry.md`); the paper's Fig. 8 and Table 2 are missing, so every number
is ours.

Clearance joints: by default J1 (owned by panel 1) and J7 (owned by panel 2), each with its own
roughness Ra and clearance c (`panel1_ra`, `panel1_clearance`, …); any hinge can be made a
clearance joint with `DeployArray(clearance_joints={"J3": "rod3", ...})`, which adds the
parameters `rod3_ra`, `rod3_clearance`. Contact: rough (GW-averaged) Hertz law for steel pins
of 5 mm radius, Lankarani–Nikravesh damping, smooth Coulomb friction.
"""

from __future__ import annotations

import json
import math
from importlib import resources

import jax.numpy as jnp

from .. import contact
from ..mechanism import (
    Body,
    CoilSpringDrive,
    Latch,
    Mechanism,
    PreloadedLatch,
    Revolute,
    RevoluteClearance,
    consistent_motion,
    consistent_state,
    contact_history,
    first_onset_times,
    lock_times,
    onset_counts,
)
from ..solvers.step_control import StepControl
from ._contact import (
    CONTACT_PARAMS,
    FRICTION_SHAPE_OPTION,
    IDEAL_OPTION,
    IMPACT_VELOCITY_FLOOR_SPEC,
    IMPACT_VELOCITY_RULE_OPTION,
    NORMAL_LAW_OPTION,
    SLIP_VELOCITY_SPEC,
    check_contact_options,
    clearance_contact_laws,
    clearance_spec,
)
from .base import OptionSpec, ParamSpec, Scene, is_exactly_zero

# The classical (literature) rule: docs/deploy_array.md ("Impact-velocity rule") measures both
# rules on this scene; onset does not fail there (no contact begins at rest, same lock time and
# deviations), so the literature's model stays the default.
DEFAULT_IMPACT_VELOCITY_RULE = "onset"

# The root latch: "preloaded" holds the hinge angle and presses the root hinge J1 to one side of
# its clearance with the latch spring's preload (`PreloadedLatch`), as a flight latch does;
# "angle_only" holds the angle alone (`Latch`), leaving the journal free in its clearance after
# the lock (the model before issue 24). docs/deploy_array.md shows both and why the default is
# the preloaded one.
LATCH_MODELS = ("preloaded", "angle_only")
DEFAULT_LATCH = "preloaded"
# Radius at which the latch roller bears on panel 1's root fitting [m]: a 40 mm fitting around
# the 10 mm hinge pin (our choice; it enters only through the preload's line of action).
LATCH_ROLLER_RADIUS = 0.02
LATCH_PRELOAD_PARAMS = (
    "latch_preload",
    "latch_preload_angle",
    "latch_preload_arm",
    "panel_latch_preload",
)

# How a hinge's friction depends on its roughness (docs/contact.md, "Roughness helpers"):
# "constant" uses friction_coefficient for every Ra; "ploughing" is adhesion plus Bowden–Tabor
# ploughing by the asperities of a turned surface (`contact.PloughingFriction`).
FRICTION_ROUGHNESS_MODELS = ("constant", "ploughing")
PLOUGHING_PARAMS = ("friction_adhesion", "tool_nose_radius")

# The hinges' tangential friction law (docs/contact.md, "Friction that sticks"): "coulomb", the
# regularised Coulomb law of the literature's clearance-joint models (a loaded hinge creeps at
# ~v_s), or "lugre", `contact.LuGreContactFriction` with the contact force as its normal force
# and its bristle deflections in each clearance joint's internal state (a loaded hinge sticks).
FRICTION_LAWS = ("coulomb", "lugre")
LUGRE_PARAMS = (
    "friction_static_ratio",
    "stribeck_velocity",
    "bristle_stiffness",
    "bristle_damping",
)

INF = math.inf


def load_geometry() -> dict:
    """The design study's geometry and defaults (see `docs/deploy_array_geometry.md`)."""
    text = resources.files(__package__).joinpath("data/deploy_array_geometry.json").read_text()
    return json.loads(text)


GEOMETRY = load_geometry()
JOINTS = {j["name"]: j for j in GEOMETRY["joints"]}
DEFAULT_CLEARANCE_JOINTS = dict(GEOMETRY["contact_defaults"]["clearance_joints"])
# α = θ_ground − θ_panel1 − offset = π/2 − θ_panel1 (DeployArray's deployment angle).
ANGLE_OFFSET = -math.pi / 2


def _shared_params() -> dict[str, ParamSpec]:
    g = GEOMETRY
    return {
        "spring_stiffness": ParamSpec(
            g["coil_spring"]["k"], 0, INF, "N m/rad", "root coil spring k"
        ),
        "spring_free_angle": ParamSpec(
            g["coil_spring"]["alpha0"], 0, 2 * math.pi, "rad", "spring free angle α0"
        ),
        "latch_stiffness": ParamSpec(
            g["latch"]["k_latch"], 0, INF, "N m/rad", "latch stiffness k_L", False
        ),
        "latch_damping": ParamSpec(g["latch"]["c_latch"], 0, INF, "N m s/rad", "latch damping"),
        # latch="preloaded" only (docs/deploy_array.md, "The latch"):
        "latch_preload": ParamSpec(
            100.0, 0, 1e4, "N", "latch spring preload F_p pressing the root hinge J1"
        ),
        "latch_preload_angle": ParamSpec(
            math.pi,
            -math.pi,
            math.pi,
            "rad",
            "direction of the preload on panel 1, from +x (π: towards the spacecraft)",
        ),
        "panel_latch_preload": ParamSpec(
            100.0, 0, 1e4, "N", "panel latch preload pressing the panel hinge J7"
        ),
        "latch_preload_arm": ParamSpec(
            0.0,
            -LATCH_ROLLER_RADIUS,
            LATCH_ROLLER_RADIUS,
            "m",
            "offset e of the preload's line of action from the hinge axis (moment F_p e, "
            "deploying sense)",
        ),
        # The panels' mass properties are the reconstruction's estimate (W24 gives no Table 2):
        # a scale on both panels' mass and inertia, for sensitivities and fits.
        "panel_mass_scale": ParamSpec(
            1.0, 0, 100, "", "factor on both panels' mass and inertia", False
        ),
        "youngs_modulus": ParamSpec(
            g["contact_defaults"]["material"]["E"], 1e6, 1e13, "Pa", "pin/bearing modulus"
        ),
        "poisson_ratio": ParamSpec(
            g["contact_defaults"]["material"]["nu"], -1, 0.5, "", "Poisson's ratio", False, False
        ),
        "restitution": ParamSpec(0.9, 0, 1, "", "coefficient of restitution c_e", False),
        "friction_coefficient": ParamSpec(0.05, 0, 2, "", "friction μ (0: none traced)"),
        # friction_roughness="ploughing" only: μ(Ra) = μ_a + (2/π) Δa(Ra; r_ε). The defaults
        # give μ = 0.050 at Ra 1.6 µm, the constant model's value (μ_a is the free part).
        "friction_adhesion": ParamSpec(
            0.01, 0, 2, "", "adhesion part μ_a of the ploughing friction law"
        ),
        "tool_nose_radius": ParamSpec(
            0.8e-3, 1e-5, 1e-2, "m", "nose radius r_ε of the tool that turned the hinge"
        ),
        # c_e(Ra) = c_e^((Ra/Ra_ref)^p): no published relation (docs/contact.md); p = 0: off.
        "restitution_roughness_exponent": ParamSpec(
            0.0, -4, 4, "", "exponent p of the free restitution-roughness coupling (0: none)"
        ),
        "restitution_reference_ra": ParamSpec(
            1.6e-6,
            1e-8,
            1e-4,
            "m",
            "Ra at which the coupled restitution equals `restitution`",
            False,
        ),
        "roughness_offset": ParamSpec(0.0, 0, 6, "σ", "clearance reference offset s0"),
        "pin_radius": ParamSpec(
            g["contact_defaults"]["pin_radius"], 0, INF, "m", "hinge pin radius R_j", False
        ),
        "impact_velocity_floor": IMPACT_VELOCITY_FLOOR_SPEC,
        "friction_slip_velocity": SLIP_VELOCITY_SPEC,
        # friction_law="lugre" only (`contact.LuGreContactFriction`; defaults: the example of
        # Canudas de Wit et al. 1995 at μ_C = 0.05 — presliding μ_C/σ0 = 10 µm, σ1/σ0 = 3.2 ms).
        "friction_static_ratio": ParamSpec(
            1.5, 1, 10, "", "LuGre static to Coulomb friction ratio μ_S/μ_C"
        ),
        "stribeck_velocity": ParamSpec(1e-3, 0, 10, "m/s", "LuGre Stribeck velocity v_S", False),
        "bristle_stiffness": ParamSpec(
            5e3, 0, 1e9, "1/m", "LuGre bristle stiffness σ0 per unit normal force", False
        ),
        "bristle_damping": ParamSpec(
            15.811388300841896, 0, 1e6, "s/m", "LuGre bristle damping σ1 per unit normal force"
        ),
    }


class DeployArray(Scene):
    """Two-panel deployable array with clearance joints (see module docstring).

    **Arguments:**
    - `clearance_joints`: `{joint name: owner}`; default `{"J1": "panel1", "J7": "panel2"}`.
    - `ideal`: all joints ideal (the reference mechanism).
    - `normal_law`: damping law for the clearance joints (default Lankarani–Nikravesh).
    - `impact_velocity_rule`: the damping law's impact velocity, `"onset"` (classical) or
      `"running_max"` (`jaxdeploy.mechanism.RevoluteClearance`).
    - `friction_shape`: the regularised Coulomb law's sign function, `"algebraic"` or `"tanh"`.
    - `latch`: `"preloaded"` (default: the root latch also presses the root hinge J1 against
      one side of its clearance with `latch_preload`, and a panel latch presses the panel
      hinge J7 with `panel_latch_preload`) or `"angle_only"` (one latch holds the angle
      alone; the journals are free in their clearances after the lock).
    - `friction_roughness`: `"constant"` (default: `friction_coefficient` at every Ra) or
      `"ploughing"` (each hinge's μ from its Ra, `contact.PloughingFriction` with
      `friction_adhesion` and `tool_nose_radius`).
    - `friction_law`: `"coulomb"` (default: the regularised Coulomb law, `friction_shape` and
      `friction_slip_velocity`) or `"lugre"` (`contact.LuGreContactFriction`: μ_C the hinge's
      μ, μ_S = `friction_static_ratio` μ_C, `stribeck_velocity`, `bristle_stiffness`,
      `bristle_damping`; the bristle deflections are each clearance joint's internal state,
      so generalized-α cannot run it).
    """

    name = "deploy_array"
    default_t_end = 2.0
    # Tsit5 on the index-1 ODE with projection: more accurate than generalized-α at the same
    # tolerance on this scene (docs/generalized_alpha_error.md; against the independent
    # ideal-joint model, docs/deploy_array.md: 1.3e-9 vs 8.4e-6 relative in α at rtol 1e-6).
    # For very small clearances the stiff contact of a journal held in a tiny gap limits an
    # explicit step; `solver="generalized_alpha"` (implicit) is the alternative there.
    default_control = StepControl("tsit5", rtol=1e-6, atol=1e-9, dt_max=5e-4)
    option_specs = {
        "clearance_joints": OptionSpec(
            DEFAULT_CLEARANCE_JOINTS,
            (),
            "{joint: panel} of the joints with clearance (JSON), the others ideal; a panel's "
            "_ra and _clearance parameters exist for its joint",
        ),
        "ideal": IDEAL_OPTION,
        "normal_law": NORMAL_LAW_OPTION,
        "impact_velocity_rule": IMPACT_VELOCITY_RULE_OPTION,
        "friction_shape": FRICTION_SHAPE_OPTION,
        "friction_roughness": OptionSpec(
            "constant",
            FRICTION_ROUGHNESS_MODELS,
            "hinge friction vs roughness: constant (friction_coefficient) or ploughing "
            "(adhesion + ploughing of a turned surface, from each hinge's Ra)",
        ),
        "friction_law": OptionSpec(
            "coulomb",
            FRICTION_LAWS,
            "hinge friction law: coulomb (regularised, creeps under a steady load) or lugre "
            "(bristle state per clearance joint, sticks below the static level)",
        ),
        "latch": OptionSpec(
            DEFAULT_LATCH,
            LATCH_MODELS,
            "root latch model: preloaded (holds the angle and presses the root hinge to one "
            "side) or angle_only",
        ),
    }

    def __init__(
        self,
        clearance_joints: dict[str, str] | None = None,
        ideal: bool = False,
        normal_law: str = "lankarani_nikravesh",
        impact_velocity_rule: str = DEFAULT_IMPACT_VELOCITY_RULE,
        friction_shape: str = "algebraic",
        latch: str = DEFAULT_LATCH,
        friction_roughness: str = "constant",
        friction_law: str = "coulomb",
    ):
        check_contact_options(normal_law, impact_velocity_rule, friction_shape)
        if friction_roughness not in FRICTION_ROUGHNESS_MODELS:
            raise ValueError(
                f"friction_roughness = {friction_roughness!r} is invalid; valid: "
                f"{', '.join(FRICTION_ROUGHNESS_MODELS)}"
            )
        if friction_law not in FRICTION_LAWS:
            raise ValueError(
                f"friction_law = {friction_law!r} is invalid; valid: {', '.join(FRICTION_LAWS)}"
            )
        if latch not in LATCH_MODELS:
            raise ValueError(f"latch = {latch!r} is invalid; valid: {', '.join(LATCH_MODELS)}")
        joints = DEFAULT_CLEARANCE_JOINTS if clearance_joints is None else clearance_joints
        for name in joints:
            if name not in JOINTS:
                raise ValueError(
                    f"unknown joint {name!r} in clearance_joints; valid: {', '.join(JOINTS)}"
                )
        self.clearance_joints = {} if ideal else dict(joints)
        self.ideal = ideal
        self.normal_law = normal_law
        self.impact_velocity_rule = impact_velocity_rule
        self.friction_shape = friction_shape
        self.latch = latch
        self.friction_roughness = friction_roughness
        self.friction_law = friction_law
        params = _shared_params()
        ra = GEOMETRY["contact_defaults"]["Ra"]
        c = GEOMETRY["contact_defaults"]["clearance"]
        for owner in self.clearance_joints.values():
            params[f"{owner}_ra"] = ParamSpec(ra, 0, 1e-4, "m", f"{owner} hinge roughness Ra")
            params[f"{owner}_clearance"] = clearance_spec(
                c, 1e-2, f"{owner} hinge radial clearance"
            )
        self.params = params

    @property
    def options(self) -> dict:
        return {
            "clearance_joints": dict(self.clearance_joints),
            "ideal": self.ideal,
            "normal_law": self.normal_law,
            "impact_velocity_rule": self.impact_velocity_rule,
            "friction_shape": self.friction_shape,
            "latch": self.latch,
            "friction_roughness": self.friction_roughness,
            "friction_law": self.friction_law,
        }

    def ignored_params(self) -> dict[str, str]:
        out = {}
        if self.latch == "angle_only":
            out.update(dict.fromkeys(LATCH_PRELOAD_PARAMS, "latch=preloaded"))
        if self.friction_roughness == "ploughing":
            out["friction_coefficient"] = "friction_roughness=constant"
        else:
            out.update(dict.fromkeys(PLOUGHING_PARAMS, "friction_roughness=ploughing"))
        if self.friction_law == "lugre":
            out["friction_slip_velocity"] = "friction_law=coulomb"
        else:
            out.update(dict.fromkeys(LUGRE_PARAMS, "friction_law=lugre"))
        if self.ideal:
            used_by_contact = (*CONTACT_PARAMS, "pin_radius", "roughness_offset")
            out.update({n: "ideal=false" for n in self.params if n in used_by_contact})
        return out

    def build(self, params):
        p = params
        bodies = []
        for name in GEOMETRY["body_order"]:
            body = GEOMETRY["bodies"][name]
            scale = p["panel_mass_scale"] if name.startswith("panel") else 1.0
            bodies.append(Body(name, scale * body["mass"], scale * body["inertia"], body["points"]))
        elements = []
        for name, joint in JOINTS.items():
            ends = (joint["body_i"], joint["point_i"], joint["body_j"], joint["point_j"])
            owner = self.clearance_joints.get(name)
            if owner is None:
                elements.append(Revolute(*ends))
                continue
            clearance = p[f"{owner}_clearance"]
            ra = p[f"{owner}_ra"]
            friction_coefficient = p["friction_coefficient"]
            if self.friction_roughness == "ploughing":
                friction_coefficient = contact.PloughingFriction(
                    p["friction_adhesion"], p["tool_nose_radius"]
                )(ra)
            restitution = p["restitution"]
            if not is_exactly_zero(p["restitution_roughness_exponent"]):
                restitution = contact.RestitutionRoughnessCoupling(
                    p["restitution_reference_ra"], p["restitution_roughness_exponent"]
                )(restitution, ra)
            normal, friction = clearance_contact_laws(
                journal_radius=p["pin_radius"],
                clearance=clearance,
                youngs_modulus=p["youngs_modulus"],
                poisson_ratio=p["poisson_ratio"],
                sigma=contact.ra_to_sigma(ra),
                restitution=restitution,
                friction_coefficient=friction_coefficient,
                normal_law=self.normal_law,
                roughness_offset=p["roughness_offset"],
                slip_velocity=p["friction_slip_velocity"],
                friction_shape=self.friction_shape,
                impact_velocity_floor=p["impact_velocity_floor"],
            )
            if friction is not None and self.friction_law == "lugre":
                friction = contact.LuGreContactFriction(
                    mu_coulomb=friction_coefficient,
                    mu_static=p["friction_static_ratio"] * friction_coefficient,
                    stribeck_velocity=p["stribeck_velocity"],
                    bristle_stiffness=p["bristle_stiffness"],
                    bristle_damping=p["bristle_damping"],
                )
            elements.append(
                RevoluteClearance(
                    *ends,
                    clearance=clearance,
                    journal_radius=p["pin_radius"],
                    normal=normal,
                    friction=friction,
                    impact_velocity_rule=self.impact_velocity_rule,
                )
            )
        elements.append(
            CoilSpringDrive(
                "panel1",
                "ground",
                stiffness=p["spring_stiffness"],
                free_angle=p["spring_free_angle"],
                angle_offset=ANGLE_OFFSET,
            )
        )
        if self.latch == "preloaded":
            elements.append(self._panel_latch(p))
        elements.append(self._latch(p))
        return Mechanism(bodies, elements, ground_points=GEOMETRY["bodies"]["ground"]["points"])

    def _latch(self, p):
        """The root latch (the last element). Preloaded: the roller on the spacecraft bears on
        panel 1's root fitting at P, at `LATCH_ROLLER_RADIUS` from the hinge axis against the
        force's direction u(φ) and `latch_preload_arm` e beside it (at the lock pose, where
        panel 1's frame is the world's, θ = 0): P = root − r_L u + e perp(u), so that the
        force's moment about the hinge is F_p e in the deploying sense."""
        common = dict(
            lock_angle=GEOMETRY["latch"]["engage_alpha"],
            stiffness=p["latch_stiffness"],
            damping=p["latch_damping"],
            angle_offset=ANGLE_OFFSET,
        )
        if self.latch == "angle_only":
            return Latch("panel1", "ground", **common)
        phi = jnp.asarray(p["latch_preload_angle"], dtype=float)
        u = jnp.stack([jnp.cos(phi), jnp.sin(phi)])
        root = jnp.asarray(GEOMETRY["bodies"]["panel1"]["points"]["root"], dtype=float)
        point = root - LATCH_ROLLER_RADIUS * u + p["latch_preload_arm"] * jnp.stack([-u[1], u[0]])
        return PreloadedLatch(
            "panel1",
            "ground",
            preload=p["latch_preload"],
            preload_body="panel1",
            preload_point=point,
            preload_angle=phi,
            **common,
        )

    def _panel_latch(self, p):
        """The panel latch at J7 (panel 1 carries the roller, panel 2 the fitting): engages
        when the fold angle θ_panel2 − θ_panel1 reaches 0 (panels collinear, the same instant
        as the root latch with ideal joints) and presses J7 with `panel_latch_preload` along
        the root latch's direction u(φ), now in panel 1's frame, through the hinge axis. Its
        angular stiffness is 0: the reconstruction's one lock stiffness k_L, calibrated to the
        95 Hz post-lock mode (docs/deploy_array_geometry.md §7), stands for both latches."""
        phi = jnp.asarray(p["latch_preload_angle"], dtype=float)
        u = jnp.stack([jnp.cos(phi), jnp.sin(phi)])
        root = jnp.asarray(GEOMETRY["bodies"]["panel2"]["points"]["root"], dtype=float)
        return PreloadedLatch(
            "panel1",
            "panel2",
            lock_angle=0.0,
            stiffness=0.0,
            preload=p["panel_latch_preload"],
            preload_body="panel2",
            preload_point=root - LATCH_ROLLER_RADIUS * u,
            preload_angle=phi,
        )

    def initial_state(self, params, mechanism):
        """Half deployed (α = 45°), at rest; journals centred (the ideal pose)."""
        q_guess = jnp.asarray(GEOMETRY["initial_state"]["q"], dtype=float)
        if not self.clearance_joints:
            return consistent_state(mechanism.idealized(), q_guess, fixed=(2,))
        q, v = consistent_motion(mechanism.idealized(), q_guess, fixed=(2,))
        return consistent_state(mechanism, q, v)

    def channels(self, mechanism, trajectory):
        """Base channels plus `alpha` (deployment angle, rad); each panel's tip position
        `{panel}_tip_x/_y`, velocity `{panel}_tip_vx/_vy` and acceleration
        `{panel}_tip_ax/_ay`; and per clearance joint
        (named by owner) `{owner}_normal_force` [N] and `{owner}_penetration` [m].

        Velocity and acceleration of a point s fixed in a body (Nikravesh 1988, eq. 4.12):
        v_P = ṙ + θ̇ A′s, a_P = r̈ + θ̈ A′s − θ̇² A s, with A the rotation matrix and
        A′s = perp(A s).
        """
        out = super().channels(mechanism, trajectory)
        q, v, qdd = trajectory.q, trajectory.v, trajectory.qdd
        out["alpha"] = deployment_angle(q)
        for panel in ("panel1", "panel2"):
            k = mechanism.body_index(panel)
            tip = mechanism.point(panel, "tip")
            theta, omega, omega_dot = q[:, 3 * k + 2], v[:, 3 * k + 2], qdd[:, 3 * k + 2]
            c, s = jnp.cos(theta), jnp.sin(theta)
            arm_x = c * tip[0] - s * tip[1]
            arm_y = s * tip[0] + c * tip[1]
            out[f"{panel}_tip_x"] = q[:, 3 * k] + arm_x
            out[f"{panel}_tip_y"] = q[:, 3 * k + 1] + arm_y
            out[f"{panel}_tip_vx"] = v[:, 3 * k] - omega * arm_y
            out[f"{panel}_tip_vy"] = v[:, 3 * k + 1] + omega * arm_x
            out[f"{panel}_tip_ax"] = qdd[:, 3 * k] - omega_dot * arm_y - omega**2 * arm_x
            out[f"{panel}_tip_ay"] = qdd[:, 3 * k + 1] + omega_dot * arm_x - omega**2 * arm_y
        joint_names = list(JOINTS)  # build() appends one element per joint, in this order
        histories = contact_history(mechanism, q, v, trajectory.memory)
        for index, history in histories.items():
            owner = self.clearance_joints[joint_names[index]]
            out[f"{owner}_normal_force"] = history["normal_force"]
            out[f"{owner}_penetration"] = history["penetration"]
        return out

    def events(self, mechanism, trajectory):
        """`lock_time` [s]: when the deployment angle reached the root latch's stop (NaN if
        not by the run's end), located inside its step and differentiable
        (`jaxdeploy.mechanism.lock_times`); per clearance joint (named by owner)
        `{owner}_first_onset_time` [s] (NaN: none) and `{owner}_impacts` (contacts begun, a
        count)."""
        root_latch = len(mechanism.elements) - 1  # build() appends it last
        out = {"lock_time": lock_times(mechanism, trajectory.memory)[root_latch]}
        joint_names = list(JOINTS)
        onsets = first_onset_times(mechanism, trajectory.memory)
        counts = onset_counts(mechanism, trajectory.memory)
        for index, t_on in onsets.items():
            owner = self.clearance_joints[joint_names[index]]
            out[f"{owner}_first_onset_time"] = t_on
            out[f"{owner}_impacts"] = counts[index]
        return out

    def episode_names(self, mechanism):
        """Each clearance joint by its owner (`panel1`, `panel2`, …), as in `events`."""
        joint_names = list(JOINTS)
        return [self.clearance_joints[joint_names[i]] for i in mechanism.find(RevoluteClearance)]

    # The deployment angle α [rad] at which the root latch engages (`alpha` channel).
    lock_angle = GEOMETRY["latch"]["engage_alpha"]

    def ideal_counterpart(self):
        """The same array with ideal joints and the same latch model: the reference whose
        deviations are the study's outputs (the run differs from it by its joints only)."""
        return DeployArray(ideal=True, latch=self.latch)


def deployment_angle(q):
    """α = π/2 − θ_panel1 (panel 1 is the first body)."""
    return 0.5 * math.pi - q[..., 2]
