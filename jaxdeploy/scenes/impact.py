"""One body against a fixed bearing: the contact laws inside the mechanism machinery, checked
against closed forms.

A free journal (mass m, no gravity) starts centred in a bearing fixed to the ground and moves
along +x at `impact_speed`; it crosses the clearance, impacts, and rebounds. For the plain
Hertz law (`damping = "none"`) Johnson's closed forms hold (*Contact Mechanics*, 1985, ch. 11):
`δ_max = (5 m v0²/(4K))^(2/5)`, `F_max = K δ_max^(3/2)`, contact duration `2.9433 δ_max/v0`.
With a damped law the rebound speed over the approach speed is the law's effective
restitution.
"""

from __future__ import annotations

import math

import jax.numpy as jnp

from .. import contact
from ..mechanism import Body, Mechanism, RevoluteClearance, consistent_state
from ..mechanism.clearance import IMPACT_VELOCITY_RULES
from ..solvers.step_control import StepControl
from ._contact import (
    IMPACT_VELOCITY_FLOOR_SPEC,
    IMPACT_VELOCITY_RULE_OPTION,
    NORMAL_LAWS,
    check_choice,
    clearance_spec,
)
from .base import OptionSpec, ParamSpec, Scene, is_exactly_zero

INF = math.inf


class Impact(Scene):
    """Journal impacting a fixed bearing. `damping`: a key of `NORMAL_LAWS`,
    `"hunt_crossley_material"`, or `"none"` (undamped Hertz/rough law)."""

    name = "impact"
    params = {
        "mass": ParamSpec(1.0, 0, INF, "kg", "journal mass", False),
        "impact_speed": ParamSpec(1.0, 0, 100, "m/s", "approach speed v0", False),
        "stiffness": ParamSpec(1e10, 0, INF, "N/m^1.5", "contact stiffness K", False),
        "clearance": clearance_spec(1e-4, 0.1, "radial clearance"),
        "journal_radius": ParamSpec(5e-3, 0, INF, "m", "pin radius", False),
        "sigma": ParamSpec(0.0, 0, 1e-4, "m", "RMS roughness σ (0: Hertz)"),
        "restitution": ParamSpec(0.9, 0, 1, "", "coefficient of restitution", False),
        "material_damping": ParamSpec(0.0, 0, INF, "s/m", "α of the memoryless law"),
        "impact_velocity_floor": IMPACT_VELOCITY_FLOOR_SPEC,
    }
    default_t_end = 6e-4  # first touch at c/v0 = 1e-4 s; Hertz contact lasts ~3.2e-4 s
    default_control = StepControl(rtol=1e-8, atol=1e-13, dt_max=1e-6)
    option_specs = {
        "damping": OptionSpec(
            "none",
            ("none", "hunt_crossley_material", *sorted(NORMAL_LAWS)),
            "none (undamped Hertz or rough law), hunt_crossley_material (F = Kδ^1.5(1 + αδ̇), "
            "α = material_damping) or a restitution law (restitution, impact_velocity_floor)",
        ),
        "impact_velocity_rule": IMPACT_VELOCITY_RULE_OPTION,
    }

    def __init__(self, damping: str = "none", impact_velocity_rule: str = "onset"):
        check_choice("damping", damping, sorted({"none", "hunt_crossley_material", *NORMAL_LAWS}))
        check_choice("impact_velocity_rule", impact_velocity_rule, IMPACT_VELOCITY_RULES)
        self.damping = damping
        self.impact_velocity_rule = impact_velocity_rule

    @property
    def options(self) -> dict:
        return {"damping": self.damping, "impact_velocity_rule": self.impact_velocity_rule}

    def ignored_params(self) -> dict[str, str]:
        damped = f"damping=<one of {', '.join(sorted(NORMAL_LAWS))}>"
        out = {}
        if self.damping in ("none", "hunt_crossley_material"):
            out.update(restitution=damped, impact_velocity_floor=damped)
        if self.damping != "hunt_crossley_material":
            out["material_damping"] = "damping=hunt_crossley_material"
        return out

    def normal_law(self, params):
        if is_exactly_zero(params["sigma"]):
            elastic = contact.HertzElastic(params["stiffness"])
        else:
            elastic = contact.RoughElastic(params["stiffness"], params["sigma"])
        if self.damping == "none":
            return contact.Undamped(elastic)
        if self.damping == "hunt_crossley_material":
            return contact.HuntCrossleyMaterial(elastic, params["material_damping"])
        return NORMAL_LAWS[self.damping](
            elastic=elastic,
            restitution=params["restitution"],
            impact_velocity_floor=params["impact_velocity_floor"],
        )

    def build(self, params):
        r = params["journal_radius"]
        journal = Body("journal", params["mass"], 0.5 * params["mass"] * r**2, {"c": (0.0, 0.0)})
        joint = RevoluteClearance(
            "ground",
            "B",
            "journal",
            "c",
            clearance=params["clearance"],
            journal_radius=r,
            normal=self.normal_law(params),
            impact_velocity_rule=self.impact_velocity_rule,
        )
        return Mechanism([journal], [joint], ground_points={"B": (0.0, 0.0)})

    def initial_state(self, params, mechanism):
        v0 = jnp.asarray(params["impact_speed"], dtype=float)
        return consistent_state(
            mechanism, jnp.zeros(3), jnp.stack([v0, 0.0 * v0, 0.0 * v0]), fixed_velocities=(0,)
        )

    def time_of_first_touch(self, params):
        return params["clearance"] / params["impact_speed"]


def hertz_impact_closed_form(mass, stiffness, speed):
    """`(δ_max, F_max, t_c)` for `F = K δ^(3/2)` (Johnson, *Contact Mechanics*, 1985, ch. 11;
    the constant 2.9433 = 2 ∫_0^1 (1 − x^(5/2))^(-1/2) dx)."""
    delta_max = (5.0 * mass * speed**2 / (4.0 * stiffness)) ** 0.4
    return delta_max, stiffness * delta_max**1.5, 2.9433 * delta_max / speed
