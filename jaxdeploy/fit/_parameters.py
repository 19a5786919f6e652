"""Fitted parameters: names, initial guesses and bounds, kept inside the bounds by a smooth
reparametrisation so that an unconstrained optimiser can move freely.

For bounds `0 < low < high` the parameter is moved on a log scale (clearances, roughness and
moduli span decades and are positive):

    θ = exp(ln low + (ln high − ln low) s(z)),   s(z) = 1/(1 + e^(−z))

otherwise linearly, `θ = low + (high − low) s(z)`. Both are bijections of ℝ onto (low, high),
so every iterate is a valid parameter; `z = 0` is the middle of the (log) range.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import jax.numpy as jnp
import numpy as np


@dataclass(frozen=True)
class FitParameter:
    """One fitted parameter: scene name, initial guess and open bounds `(low, high)`."""

    name: str
    guess: float
    low: float
    high: float

    @property
    def log_scale(self) -> bool:
        return self.low > 0

    def _ends(self):
        if self.log_scale:
            return math.log(self.low), math.log(self.high)
        return self.low, self.high

    def ends(self) -> tuple[float, float]:
        """`(a, b)`: the bounds on the scale the parameter moves on (ln low, ln high for a
        log-scale parameter, else low, high)."""
        return self._ends()

    def to_physical(self, z):
        """θ(z) (works on JAX values)."""
        return physical(z, *self._ends(), self.log_scale)

    def to_internal(self, value: float) -> float:
        """z(θ), the inverse of `to_physical`."""
        a, b = self._ends()
        u = math.log(value) if self.log_scale else value
        s = (u - a) / (b - a)
        return math.log(s / (1.0 - s))

    def dphysical_dz(self, z: float) -> float:
        """dθ/dz at `z` (to carry derivatives from z to physical units)."""
        a, b = self._ends()
        s = 1.0 / (1.0 + math.exp(-z))
        ds = (b - a) * s * (1.0 - s)
        return ds * float(self.to_physical(z)) if self.log_scale else ds


def physical(z, a, b, log_scale: bool):
    """θ(z) = exp(u) or u, u = a + (b − a) s(z) (module docstring), for ends `a`, `b` given
    as numbers or as data of a compiled program (`fit._model_program`: one program for every
    bound)."""
    u = a + (b - a) * (1.0 / (1.0 + jnp.exp(-z)))
    return jnp.exp(u) if log_scale else u


def _number(text: str, what: str, spec: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise ValueError(f"--params {spec!r}: {what} {text!r} is not a number (SI units)") from None
    if not math.isfinite(value):
        raise ValueError(f"--params {spec!r}: {what} {text!r} must be finite")
    return value


def parse_param_spec(spec: str) -> tuple[str, float | None, float | None, float | None]:
    """`NAME`, `NAME=guess` or `NAME=guess:low:high` → `(name, guess, low, high)` (None when
    not given)."""
    if "=" not in spec:
        name = spec.strip()
        if not name:
            raise ValueError("--params: empty parameter name")
        return name, None, None, None
    name, rest = (s.strip() for s in spec.split("=", 1))
    parts = rest.split(":")
    if len(parts) not in (1, 3):
        raise ValueError(f"--params {spec!r}: expected NAME, NAME=guess or NAME=guess:low:high")
    guess = _number(parts[0], "guess", spec)
    if len(parts) == 1:
        return name, guess, None, None
    return name, guess, _number(parts[1], "low", spec), _number(parts[2], "high", spec)


def make_parameters(scene, specs: Sequence, defaults: Mapping | None = None) -> list[FitParameter]:
    """`FitParameter`s for `scene` from specs: strings (`parse_param_spec`), tuples
    `(name, guess, low, high)` (None to default) or `FitParameter`s.

    Defaults: the guess is the scene default (or `defaults[name]`); bounds are guess/10 to
    guess·10 for a positive guess, clipped to the scene's valid range, else the valid range.
    Refused, naming parameter, value and range: unknown names, repeated names, bounds outside
    the scene's valid range or not increasing, a guess not strictly inside its bounds.
    """
    out = []
    seen = set()
    for spec in specs:
        if isinstance(spec, FitParameter):
            name, guess, low, high = spec.name, spec.guess, spec.low, spec.high
        elif isinstance(spec, str):
            name, guess, low, high = parse_param_spec(spec)
        else:
            name, guess, low, high = (tuple(spec) + (None,) * 4)[:4]
        if name not in scene.params:
            raise ValueError(
                f"unknown parameter {name!r} for scene {scene.name!r}; valid: "
                + ", ".join(sorted(scene.params))
            )
        if name in seen:
            raise ValueError(f"parameter {name!r} is given twice")
        check_not_ignored(scene, name, "fit")
        seen.add(name)
        ps = scene.params[name]
        unit = f" {ps.unit}" if ps.unit else ""
        valid = f"[{ps.low:g}, {ps.high:g}]{unit}"
        if guess is None:
            guess = float((defaults or {}).get(name, ps.default))
        if low is None or high is None:
            if guess > 0:
                low, high = max(guess / 10.0, ps.low), min(guess * 10.0, ps.high)
            else:
                low, high = ps.low, ps.high
        if not (math.isfinite(low) and math.isfinite(high)):
            raise ValueError(
                f"{name}: give finite bounds (NAME=guess:low:high); the valid range is {valid}"
            )
        if not low < high:
            raise ValueError(
                f"{name}: bounds low = {float(low)!r} and high = {float(high)!r} need low < high"
            )
        if low < ps.low or high > ps.high:
            raise ValueError(
                f"{name}: bounds [{low:g}, {high:g}]{unit} are invalid: they must lie in {valid}"
            )
        if not low < guess < high:
            raise ValueError(
                f"{name} = {float(guess)!r}{unit} (initial guess) is invalid: it must lie strictly "
                f"inside the bounds ({low:g}, {high:g}){unit}"
            )
        out.append(FitParameter(name, float(guess), float(low), float(high)))
    if not out:
        raise ValueError("no parameter to fit: give at least one with --params NAME[=guess]")
    return out


def check_not_ignored(scene, name: str, action: str) -> None:
    """Refuse to `action` ("fit", "set") a parameter the scene's options make irrelevant
    (`Scene.ignored_params`), naming the option that makes it count."""
    ignored = scene.ignored_params()
    if name in ignored:
        options = ", ".join(f"{k}={v}" for k, v in scene.options.items())
        raise ValueError(
            f"cannot {action} {name!r}: scene {scene.name!r} with {options} does not use it; "
            f"it counts with --scene-option {ignored[name]}"
        )


def internal_vector(parameters: Sequence[FitParameter], values: Mapping | None = None):
    """z for the guesses (or for `values[name]`)."""
    return np.array([p.to_internal(float((values or {}).get(p.name, p.guess))) for p in parameters])
