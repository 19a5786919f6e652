"""Composing a clearance joint's contact laws from scene parameters (trace time)."""

from __future__ import annotations

from .. import contact
from ..contact.damping import DEFAULT_IMPACT_VELOCITY_FLOOR
from ..mechanism.clearance import IMPACT_VELOCITY_RULES
from .base import OptionSpec, ParamSpec, is_exactly_zero

NORMAL_LAWS = {
    "hunt_crossley": contact.HuntCrossley,
    "lankarani_nikravesh": contact.LankaraniNikravesh,
    "flores": contact.Flores,
    "gonthier": contact.Gonthier,
    "hu_guo": contact.HuGuo,
}


FRICTION_SHAPES = ("algebraic", "tanh")

# Parameters every scene with clearance joints shares: the constants of the contact laws that a
# reference implementation must match (so they are parameters, with units, not hidden constants).
IMPACT_VELOCITY_FLOOR_SPEC = ParamSpec(
    DEFAULT_IMPACT_VELOCITY_FLOOR,
    0,
    10,
    "m/s",
    "smallest impact velocity v⁻ the damping term divides by",
    False,
)
SLIP_VELOCITY_SPEC = ParamSpec(
    1e-3, 0, 10, "m/s", "friction regularisation velocity v_s (sign(v) ≈ v/v_s below it)", False
)

# The smallest radial clearance a scene accepts [m]. A continuum contact model of a journal in
# a bore means nothing below a few atomic spacings (iron's lattice constant is 0.29 nm), and
# machined hinge clearances are microns (deploy_array's default 50 µm); below 1 nm a run would
# only resolve round-off of the joint's centre distance (a clearance of 1e-300 m ran and
# reported accelerations of 0 and a contact force of 1e141 N). Exact fits and zero-clearance
# limits use the ideal joint (`ideal=True`) instead.
CLEARANCE_FLOOR = 1e-9


def clearance_spec(default: float, high: float, meaning: str) -> ParamSpec:
    """A radial clearance parameter [m] in [`CLEARANCE_FLOOR`, `high`]."""
    return ParamSpec(default, CLEARANCE_FLOOR, high, "m", meaning)


# The options of scenes with clearance joints (their constructors' keywords).
NORMAL_LAW_OPTION = OptionSpec(
    "lankarani_nikravesh",
    tuple(sorted(NORMAL_LAWS)),
    "restitution-calibrated damping law of the clearance joints (docs/contact.md)",
)
IMPACT_VELOCITY_RULE_OPTION = OptionSpec(
    "onset",
    tuple(IMPACT_VELOCITY_RULES),
    "the damping law's impact velocity v⁻: onset (classical: at the located contact onset, "
    "held to separation) or running_max (largest approach speed of the contact)",
)
FRICTION_SHAPE_OPTION = OptionSpec(
    "algebraic", FRICTION_SHAPES, "the regularised Coulomb law's sign function"
)
IDEAL_OPTION = OptionSpec(False, (False, True), "true: every joint ideal (the reference)")
# Contact-law parameters of a clearance joint (irrelevant when the joint is made ideal).
CONTACT_PARAMS = (
    "youngs_modulus",
    "poisson_ratio",
    "sigma",
    "restitution",
    "friction_coefficient",
    "impact_velocity_floor",
    "friction_slip_velocity",
)

# A journal of radius R_j in a bore of radius R_b = R_j + c: two of the three sizes are
# parameters, the third follows. What users measure decides which two: a clearance is usually
# specified with the journal (or the bore) given, and a measured joint gives two diameters.
# `geometry` option value -> the two parameters.
JOINT_SIZE_NAMES = ("journal_radius", "clearance", "bore_radius")
JOINT_GEOMETRIES = {
    "journal_clearance": ("journal_radius", "clearance"),
    "bore_clearance": ("bore_radius", "clearance"),
    "bore_journal": ("bore_radius", "journal_radius"),
}


def joint_geometry_params(params: dict, geometry: str) -> dict:
    """The scene's parameter specs with the joint sizes of `geometry` (`JOINT_GEOMETRIES`):
    `params` must hold `journal_radius` and `clearance`; the bore's spec is the journal's
    default plus the clearance's, positive."""
    kept = JOINT_GEOMETRIES[geometry]
    j, c = params["journal_radius"], params["clearance"]
    bore = ParamSpec(j.default + c.default, 0, j.high, "m", "bore radius R_b = R_j + c", False)
    out = {}
    for name, spec in params.items():
        if name in JOINT_SIZE_NAMES:
            for size in JOINT_SIZE_NAMES:  # keep the scene's order, at the first size's place
                if name == "journal_radius" and size in kept:
                    out[size] = bore if size == "bore_radius" else params[size]
            continue
        out[name] = spec
    return out


def complete_joint_geometry(params, geometry: str) -> dict:
    """`params` with all three joint sizes, the missing one from R_b = R_j + c (traceable)."""
    p = dict(params)
    if geometry == "bore_clearance":
        p["journal_radius"] = p["bore_radius"] - p["clearance"]
    elif geometry == "bore_journal":
        p["clearance"] = p["bore_radius"] - p["journal_radius"]
    else:
        p["bore_radius"] = p["journal_radius"] + p["clearance"]
    return p


def check_joint_geometry(params, geometry: str) -> None:
    """Refuse (concrete values) a bore not larger than the journal, naming both."""
    from .._validation import is_concrete

    if geometry == "journal_clearance":
        return  # both positive by their ranges
    p = complete_joint_geometry(params, geometry)
    b, j, c = p["bore_radius"], p["journal_radius"], p["clearance"]
    if is_concrete((b, j, c)) and not (float(j) > 0 and float(c) >= CLEARANCE_FLOOR):
        raise ValueError(
            f"bore_radius = {float(b)!r} m is invalid with "
            + (f"clearance = {float(c)!r} m" if geometry == "bore_clearance"
               else f"journal_radius = {float(j)!r} m")
            + f" (geometry={geometry}): the bore must be larger than the journal "
            f"(journal_radius = bore_radius − clearance > 0 and clearance ≥ "
            f"{CLEARANCE_FLOOR:g} m, CLEARANCE_FLOOR)"
        )  # fmt: skip


def check_choice(name: str, value: str, valid) -> str:
    """`value` if it is one of `valid`; else a ValueError naming the option and the choices."""
    if value not in valid:
        raise ValueError(f"{name} = {value!r} is invalid; valid: {', '.join(valid)}")
    return value


def check_contact_options(normal_law: str, impact_velocity_rule: str, friction_shape: str):
    """Refuse unknown scene options before anything is built."""
    check_choice("normal_law", normal_law, sorted(NORMAL_LAWS))
    check_choice("impact_velocity_rule", impact_velocity_rule, IMPACT_VELOCITY_RULES)
    check_choice("friction_shape", friction_shape, FRICTION_SHAPES)


def clearance_contact_laws(
    *,
    journal_radius,
    clearance,
    youngs_modulus,
    poisson_ratio,
    sigma,
    restitution,
    friction_coefficient,
    normal_law: str = "lankarani_nikravesh",
    slip_velocity=1e-3,
    friction_shape: str = "algebraic",
    roughness_offset=0.0,
    impact_velocity_floor=DEFAULT_IMPACT_VELOCITY_FLOOR,
):
    """Normal and friction laws for a journal in a bearing of the same material.

    Hertz stiffness `K = (4/3) E* sqrt(R*)` from the geometry (so gradients reach the
    clearance through K); the rough (GW-averaged) elastic law unless σ is exactly 0, in which
    case plain Hertz is traced; no friction law at all when μ is exactly 0.

    **Returns:** `(normal_law, friction_law_or_None)`.
    """
    if normal_law not in NORMAL_LAWS:
        raise ValueError(
            f"normal_law = {normal_law!r} is invalid; valid: {', '.join(sorted(NORMAL_LAWS))}"
        )
    stiffness = contact.journal_bearing_stiffness(
        journal_radius, clearance, youngs_modulus, poisson_ratio, youngs_modulus, poisson_ratio
    )
    if is_exactly_zero(sigma):
        elastic = contact.HertzElastic(stiffness)
    else:
        elastic = contact.RoughElastic(stiffness, sigma, offset=roughness_offset)
    normal = NORMAL_LAWS[normal_law](
        elastic=elastic, restitution=restitution, impact_velocity_floor=impact_velocity_floor
    )
    friction = (
        None
        if is_exactly_zero(friction_coefficient)
        else contact.SmoothCoulomb(
            mu=friction_coefficient, slip_velocity=slip_velocity, shape=friction_shape
        )
    )
    return normal, friction
