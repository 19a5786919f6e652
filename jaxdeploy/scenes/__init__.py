"""Ready-made mechanisms with default parameters, initial states and outputs."""

import inspect

from .base import ParamSpec, Scene
from .deploy_array import DeployArray
from .impact import Impact, hertz_impact_closed_form
from .pendulum import Pendulum
from .slider_crank import SliderCrank, ideal_slider_kinematics

SCENES = {
    "pendulum": Pendulum,
    "impact": Impact,
    "slider_crank": SliderCrank,
    "deploy_array": DeployArray,
}


def get_scene(name: str, **options) -> Scene:
    """The scene called `name` (a key of `SCENES`), built with `options`; an unknown scene or
    option, or an invalid option value, raises `ValueError` naming the valid ones."""
    if name not in SCENES:
        raise ValueError(f"unknown scene {name!r}; valid: {', '.join(sorted(SCENES))}")
    valid = scene_options(name)
    unknown = [key for key in options if key not in valid]
    if unknown:
        raise ValueError(
            f"unknown option {unknown[0]!r} for scene {name!r}; valid: "
            + (", ".join(valid) or "none")
        )
    return SCENES[name](**options)


def scene_options(name: str) -> list[str]:
    """The option names (constructor keywords) scene `name` accepts."""
    signature = inspect.signature(SCENES[name].__init__)
    kinds = (inspect.Parameter.POSITIONAL_OR_KEYWORD, inspect.Parameter.KEYWORD_ONLY)
    # A scene without its own __init__ has object's (*args, **kwargs): no options.
    return [k for k, p in signature.parameters.items() if k != "self" and p.kind in kinds]


__all__ = [
    "SCENES",
    "DeployArray",
    "Impact",
    "ParamSpec",
    "Pendulum",
    "Scene",
    "SliderCrank",
    "get_scene",
    "scene_options",
    "hertz_impact_closed_form",
    "ideal_slider_kinematics",
]
