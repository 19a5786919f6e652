"""Contact laws for revolute clearance joints with rough surfaces.

Pure JAX, float64, jit/vmap/grad-safe. Laws are small `eqx.Module`s (numbers are array leaves,
exponents and shapes are static), so a scene composes exactly the laws it uses. See
`docs/contact.md` for the model, equations and sources.
"""

from .damping import (
    DEFAULT_IMPACT_VELOCITY_FLOOR,
    AbstractNormalLaw,
    AbstractRestitutionLaw,
    Flores,
    Gonthier,
    HuGuo,
    HuntCrossley,
    HuntCrossleyMaterial,
    LankaraniNikravesh,
    Undamped,
)
from .elastic import (
    AbstractElasticLaw,
    HertzElastic,
    RoughElastic,
)
from .friction import (
    AbstractFrictionLaw,
    AmbrosioCoulomb,
    LuGreContactFriction,
    LuGreFriction,
    SmoothCoulomb,
    StribeckFriction,
    regularized_sign,
)
from .gaussian_moments import (
    gaussian_moment,
    gaussian_smoothed_power,
    positive_power,
)
from .roughness import (
    PloughingFriction,
    RestitutionRoughnessCoupling,
    combine_sigma,
    ra_to_sigma,
    sigma_to_ra,
    turned_feed,
    turned_profile_slope,
)
from .stiffness import (
    effective_modulus,
    effective_radius,
    journal_bearing_stiffness,
    radial_clearance,
)

__all__ = [
    "DEFAULT_IMPACT_VELOCITY_FLOOR",
    "AbstractNormalLaw",
    "AbstractRestitutionLaw",
    "Flores",
    "Gonthier",
    "HuGuo",
    "HuntCrossley",
    "HuntCrossleyMaterial",
    "LankaraniNikravesh",
    "Undamped",
    "AbstractElasticLaw",
    "HertzElastic",
    "RoughElastic",
    "AbstractFrictionLaw",
    "AmbrosioCoulomb",
    "LuGreFriction",
    "LuGreContactFriction",
    "SmoothCoulomb",
    "StribeckFriction",
    "regularized_sign",
    "gaussian_moment",
    "gaussian_smoothed_power",
    "positive_power",
    "PloughingFriction",
    "RestitutionRoughnessCoupling",
    "combine_sigma",
    "ra_to_sigma",
    "sigma_to_ra",
    "turned_feed",
    "turned_profile_slope",
    "effective_modulus",
    "effective_radius",
    "journal_bearing_stiffness",
    "radial_clearance",
]
