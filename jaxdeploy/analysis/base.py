"""What the analysis of one run is: its headline numbers and figures, computed from the
trajectory alone (plus, where the scene's analysis compares against one, the trajectory of a
reference run that the caller made and passes in). Analysis runs no simulation."""

from __future__ import annotations

from typing import ClassVar


class Analysis:
    """The analysis of one run of a scene: `summary()` (headline numbers, JSON-ready) and
    `plot(out_dir)` (figures; returns the files written), drawn from `plot_data()` by the
    matplotlib-only `jaxdeploy.analysis.figures`. This base has none; a scene's own
    analysis subclasses it and is registered by scene name in `jaxdeploy.analysis.ANALYSES`.

    **Arguments:** `scene`, `params` (complete), `mechanism`, `trajectory` of the run;
    `reference`: a `Trajectory` of the reference mechanism at the same saved times (for a
    scene whose analysis `uses_reference`: its ideal-joint counterpart,
    `Scene.ideal_counterpart()`), or None, in which case the outputs that compare against it
    are left out.
    """

    # Whether `summary`/`plot` compare against a reference run (the caller decides whether
    # to make one; the analysis never runs a simulation).
    uses_reference: ClassVar[bool] = False

    def __init__(self, scene, params, mechanism, trajectory, reference=None):
        self.scene = scene
        self.params = params
        self.mechanism = mechanism
        self.trajectory = trajectory
        self.reference = reference

    # The name of the scene's figures in `jaxdeploy.analysis.figures.DRAWINGS` (None: none).
    figures: ClassVar[str | None] = None

    def summary(self) -> dict:
        return {}

    def plot_data(self) -> dict:
        """The numbers the figures show (numpy arrays, floats and dicts of them: what
        `figures.draw(self.figures, data, out_dir)` draws, in this process or another)."""
        return {}

    def plot(self, out_dir: str) -> list[str]:
        """The figures written into `out_dir` (the files)."""
        if self.figures is None:
            return []
        from .figures import draw

        return draw(self.figures, self.plot_data(), out_dir)
