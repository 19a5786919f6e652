"""Post-processing of trajectories: contact forces, spectra, and each scene's headline
numbers and figures.

A scene's analysis is found here by the scene's name (`ANALYSES`, `analyse`); the scenes do
not import it (data flows scene → simulate → analysis, docs/architecture.md).
"""

from .base import Analysis
from .contact_forces import clearance_joint_history, episodes_csv
from .deploy_array import DeployArrayAnalysis
from .pendulum import PendulumAnalysis
from .slider_crank import SliderCrankAnalysis

# Scene name -> its analysis; a scene without an entry has none (`Analysis`).
ANALYSES: dict[str, type[Analysis]] = {
    "pendulum": PendulumAnalysis,
    "slider_crank": SliderCrankAnalysis,
    "deploy_array": DeployArrayAnalysis,
}


def analysis_class(scene) -> type[Analysis]:
    """The analysis registered for `scene` (by `scene.name`), else the empty `Analysis`."""
    return ANALYSES.get(scene.name, Analysis)


def analyse(scene, params, mechanism, trajectory, reference=None) -> Analysis:
    """The analysis of one run of `scene` (see `Analysis`): `.summary()`, `.plot(out_dir)`."""
    return analysis_class(scene)(scene, params, mechanism, trajectory, reference)


__all__ = [
    "episodes_csv",
    "ANALYSES",
    "Analysis",
    "DeployArrayAnalysis",
    "PendulumAnalysis",
    "SliderCrankAnalysis",
    "analyse",
    "analysis_class",
    "clearance_joint_history",
]
