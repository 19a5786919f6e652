"""Ready-made mechanisms with default parameters, initial states and outputs."""

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
    """The scene called `name` (a key of `SCENES`), built with `options`."""
    if name not in SCENES:
        raise ValueError(f"unknown scene {name!r}; valid: {', '.join(sorted(SCENES))}")
    return SCENES[name](**options)


__all__ = [
    "SCENES",
    "DeployArray",
    "Impact",
    "ParamSpec",
    "Pendulum",
    "Scene",
    "SliderCrank",
    "get_scene",
    "hertz_impact_closed_form",
    "ideal_slider_kinematics",
]
