"""What a scene is: a mechanism builder with default parameters, an initial state, a default
step control and named output channels. Its headline numbers and figures are analysis
(`jaxdeploy.analysis`), which finds them by the scene's name.

Parameters are a flat `{name: value}` mapping in SI units. `build(params)` runs at trace time:
it may read concrete values to decide what to compose (a friction coefficient that is exactly
0.0 traces no friction code), and treats everything else as data, so the same scene jits,
vmaps and differentiates over its parameters.
"""

from __future__ import annotations

import abc
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import ClassVar

from .._validation import check_range, is_concrete
from ..mechanism import ConsistentState, Mechanism
from ..solvers.step_control import StepControl


@dataclass(frozen=True)
class ParamSpec:
    """A scene parameter: default value, valid range, unit and meaning."""

    default: float
    low: float = -math.inf
    high: float = math.inf
    unit: str = ""
    doc: str = ""
    low_inclusive: bool = True
    high_inclusive: bool = True


@dataclass(frozen=True)
class OptionSpec:
    """A scene option (a constructor keyword, fixed at trace time): default, the valid
    choices (empty: any value of the default's type) and meaning."""

    default: object
    choices: tuple = ()
    doc: str = ""


def is_exactly_zero(value) -> bool:
    """True only for a concrete zero: composition decisions never depend on traced values."""
    return is_concrete(value) and float(value) == 0.0


class Scene(abc.ABC):
    """Base of the scenes (`pendulum`, `impact`, `slider_crank`, `deploy_array`)."""

    name: ClassVar[str]
    params: ClassVar[dict[str, ParamSpec]]
    default_t_end: ClassVar[float]
    # The solver and step control of a run unless the caller gives its own.
    default_control: ClassVar[StepControl]

    @property
    def options(self) -> dict:
        """The scene's options (its constructor's keyword arguments), as recorded in results."""
        return {}

    # The scene's options (constructor keywords): `jaxdeploy scenes SCENE` lists them.
    option_specs: ClassVar[dict[str, OptionSpec]] = {}

    def default_params(self) -> dict[str, float]:
        return {k: spec.default for k, spec in self.params.items()}

    def ignored_params(self) -> dict[str, str]:
        """Parameters the scene's options make irrelevant (the run does not depend on them),
        each with the option setting that would make it count, e.g. `{"restitution":
        "damping=lankarani_nikravesh"}`. A fit refuses to fit or set these (its derivative is
        exactly zero, so it would be reported "not identified" or silently unused)."""
        return {}

    def resolve_params(self, overrides: Mapping[str, float] | None = None) -> dict:
        """Defaults updated with `overrides`; unknown names and out-of-range values raise
        `ValueError` naming the parameter, the value and the valid range."""
        params = self.default_params()
        for key, value in (overrides or {}).items():
            if key not in self.params:
                raise ValueError(
                    f"unknown parameter {key!r} for scene {self.name!r}; valid: "
                    + ", ".join(sorted(self.params))
                )
            params[key] = value
        for key, spec in self.params.items():
            check_range(
                key,
                params[key],
                spec.low,
                spec.high,
                low_inclusive=spec.low_inclusive,
                high_inclusive=spec.high_inclusive,
                unit=spec.unit,
            )
        self.check_params(params)
        return params

    def check_params(self, params: Mapping) -> None:
        """Cross-parameter checks (override where needed)."""
        return None

    @abc.abstractmethod
    def build(self, params: Mapping) -> Mechanism:
        """The mechanism for these parameters (trace-time composition)."""

    @abc.abstractmethod
    def initial_state(self, params: Mapping, mechanism: Mechanism) -> ConsistentState:
        """A consistent initial state."""

    def channels(self, mechanism: Mechanism, trajectory) -> dict:
        """Named output signals of one trajectory, each an array `(N,)` over the saved times.

        Pure JAX, so losses and objectives built on them differentiate and vmap. The base set
        is every body's coordinates and accelerations, `{body}_x`, `{body}_y`, `{body}_theta`
        and `{body}_ax`, `{body}_ay`, `{body}_atheta` (SI units); scenes add their own
        quantities (e.g. `deploy_array`'s deployment angle `alpha`).
        """
        out = {}
        for k, body in enumerate(mechanism.bodies):
            for j, coordinate in enumerate(("x", "y", "theta")):
                out[f"{body.name}_{coordinate}"] = trajectory.q[:, 3 * k + j]
                out[f"{body.name}_a{coordinate}"] = trajectory.qdd[:, 3 * k + j]
        return out

    def events(self, mechanism: Mechanism, trajectory) -> dict:
        """Named event outputs of one trajectory, each a scalar: located event times [s since
        the run's start] and counts (`jaxdeploy.mechanism.events`). Pure JAX, differentiable
        (event times by the implicit-function theorem) and independent of the save grid; none
        by default, scenes add theirs (e.g. `deploy_array`'s `lock_time`)."""
        return {}

    def episode_names(self, mechanism: Mechanism) -> list[str]:
        """The name of each clearance joint in the episode outputs (the order of
        `mechanism.find(RevoluteClearance)`): by default `joint{k}` (k from 1), "" for a
        scene with one clearance joint (its outputs then carry no prefix)."""
        from ..mechanism import RevoluteClearance

        joints = mechanism.find(RevoluteClearance)
        return [""] if len(joints) == 1 else [f"joint{k + 1}" for k in range(len(joints))]

    def episode_outputs(self, mechanism: Mechanism, trajectory) -> dict:
        """Per clearance joint (`episode_names`), differentiable outputs of its contact
        episodes (`jaxdeploy.solvers.episodes.episode_outputs`): `{name}_onset_times`,
        `{name}_impact_velocities`, `{name}_peak_forces`, `{name}_peak_penetrations` (arrays
        over its first episodes, NaN-padded) and the run's `{name}_peak_force`,
        `{name}_peak_penetration` (scalars)."""
        from ..solvers.episodes import episode_outputs

        if trajectory.episodes is None:
            return {}
        return episode_outputs(trajectory.episodes, self.episode_names(mechanism))

    def outputs(self, mechanism: Mechanism, trajectory) -> dict:
        """What a loss or objective reads by name: the `channels` (arrays over the saved
        times), the `events` (scalars) and the `episode_outputs` (per contact episode)."""
        return {
            **self.channels(mechanism, trajectory),
            **self.events(mechanism, trajectory),
            **self.episode_outputs(mechanism, trajectory),
        }

    def select_channels(self, mechanism: Mechanism, trajectory, names) -> dict:
        """`{name: channel}` for the requested `names`; an unknown name raises `ValueError`
        listing the scene's channels."""
        channels = self.channels(mechanism, trajectory)
        missing = [n for n in names if n not in channels]
        if missing:
            raise ValueError(
                f"channel {missing[0]!r} is not an output of scene {self.name!r}; valid: "
                + ", ".join(sorted(channels))
            )
        return {n: channels[n] for n in names}

    def ideal_counterpart(self) -> Scene | None:
        """The scene's mechanism with ideal joints (a reference its runs are compared with),
        or None for a scene without one."""
        return None
