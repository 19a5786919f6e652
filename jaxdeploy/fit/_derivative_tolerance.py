"""A step tolerance at which a derivative, not only the value, has converged.

Why. A derivative through an adaptive run differentiates the run's discrete map; its error
against the derivative of the exact solution is not bounded by the tolerance that bounds the
value's. Impacts amplify it, and so does every event whose located time carries a derivative:
deploy_array's lock time at Tsit5 rtol 1e-6 has AD derivatives 0.5–0.8 % off converged
differences and within 4e-4 at rtol 1e-8 (24d92c1), where the lock time itself moved by 4e-7 s;
slider_crank's d/dc of Σx² over 1 ms is 0.5–3.5 % off at rtol 1e-6 and 0.035 % at 1e-10
(issue 33's audit). A value's tolerance is then no guide for its derivative.

Rule. As the fit chooses its model tolerance (`choose_tolerance`, Hairer, Nørsett & Wanner,
*Solving ODEs I*, §II.4: the run at a 10x tighter tolerance is ~10x more accurate, so the
difference of the two estimates the looser run's error): evaluate the derivative at rtol and at
rtol/10 (atol scaled alike) and take rtol when every component changed by at most `fraction`
of its magnitude (relative to the tighter one's); else tighten by 10 and check again, down to
`RTOL_FLOOR`. The chosen tolerance and each comparison are recorded (`DerivativeTolerance`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

from ._schedule import RTOL_FLOOR
from ._schedule import tighter as tighter_control

# The default largest relative change of a derivative between rtol and rtol/10. A gradient
# check judging at 1 % needs its AD converged well inside that (it must not be the AD's own
# tolerance error that decides the verdict).
DERIVATIVE_CHANGE = 1e-3
# Tightenings tried at most (each one more compile of the derivative program).
MAX_TIGHTENINGS = 4


@dataclass
class DerivativeTolerance:
    """What `converged_tolerance` found: the chosen `control` (a `StepControl`), the
    derivatives there (`derivatives`), whether the change to rtol/10 was within `fraction`
    (`met`; False when the floor or `max_tightenings` stopped the search) and each comparison
    (`checks`: `{"rtol", "rtol_check", "change", "derivatives", "derivatives_check"}`)."""

    control: object
    derivatives: dict
    met: bool | None
    fraction: float
    checks: list = field(default_factory=list)
    note: str = ""

    @property
    def rtol(self) -> float | None:
        return self.control.rtol

    def to_json(self) -> dict:
        return {
            "rtol": self.control.rtol,
            "atol": self.control.atol,
            "met": self.met,
            "fraction": self.fraction,
            "checks": self.checks,
            **({"note": self.note} if self.note else {}),
        }

    def summary(self) -> str:
        """One line: the tolerance used and the change that justified it."""
        if self.met is None:
            return f"step tolerance: not checked ({self.note})"
        last = self.checks[-1]
        verdict = "converged" if self.met else f"NOT converged to {self.fraction:.0e}"
        return (
            f"step tolerance: rtol {self.control.rtol:.0e} (derivatives changed by "
            f"{last['change']:.1e} at rtol {last['rtol_check']:.0e}, limit "
            f"{self.fraction:.0e}: {verdict})"
        )


def relative_change(a: Mapping, b: Mapping) -> float:
    """Largest over names of |a − b| / |b| (|a − b| where b = 0; NaN anywhere gives NaN)."""
    out = 0.0
    for name in b:
        x, y = float(a[name]), float(b[name])
        if not (math.isfinite(x) and math.isfinite(y)):
            return math.nan
        out = max(out, abs(x - y) / abs(y) if y != 0.0 else abs(x - y))
    return out


def converged_tolerance(
    evaluate: Callable,
    control,
    *,
    fraction: float = DERIVATIVE_CHANGE,
    max_tightenings: int = MAX_TIGHTENINGS,
    progress: Callable | None = None,
) -> DerivativeTolerance:
    """The loosest rtol, from `control`'s down, at which the derivatives `evaluate(control)`
    (`{name: value}`) change by at most `fraction` (relative) at rtol/10 (module docstring).

    **Arguments:**
    - `evaluate(control)`: the derivatives at a `StepControl`.
    - `control`: the `StepControl` to start from (fixed steps: evaluated once, not checked).
    - `fraction`: the largest relative change accepted, in (0, 1).
    - `max_tightenings`: tighter tolerances tried at most; the search also stops at
      `RTOL_FLOOR` or when a derivative is not finite.

    **Returns:** `DerivativeTolerance`.
    """
    if not 0 < fraction < 1:
        raise ValueError(f"fraction = {fraction!r} is invalid: it must be in (0, 1)")
    say = progress or (lambda _message: None)
    if control.rtol is None:
        say("derivatives at the fixed steps (no tolerance to check)")
        return DerivativeTolerance(control, evaluate(control), None, fraction, note="fixed step")
    current = control
    say(f"derivatives at rtol {current.rtol:.0e}")
    derivatives = evaluate(current)
    checks = []
    for _ in range(max_tightenings):
        if current.rtol / 10.0 < RTOL_FLOOR * (1 - 1e-9):
            break
        tighter = tighter_control(current)
        say(f"derivatives at rtol {tighter.rtol:.0e} (is rtol {current.rtol:.0e} converged?)")
        tight = evaluate(tighter)
        change = relative_change(derivatives, tight)
        say(f"rtol {current.rtol:.0e} → {tighter.rtol:.0e}: derivatives changed by {change:.1e} "
            f"(limit {fraction:.0e})")  # fmt: skip
        checks.append({
            "rtol": current.rtol, "rtol_check": tighter.rtol, "change": change,
            "derivatives": dict(derivatives), "derivatives_check": dict(tight),
        })  # fmt: skip
        if change <= fraction:
            return DerivativeTolerance(current, derivatives, True, fraction, checks)
        if not math.isfinite(change):
            break
        current, derivatives = tighter, tight
    return DerivativeTolerance(current, derivatives, False, fraction, checks)


def derivative_tolerance(
    scene,
    params: Mapping,
    wrt: Sequence[str],
    output: Callable,
    t_end: float,
    *,
    control=None,
    mode: str = "forward",
    fraction: float = DERIVATIVE_CHANGE,
    max_tightenings: int = MAX_TIGHTENINGS,
    progress: Callable | None = None,
    **options,
) -> tuple[DerivativeTolerance, float]:
    """`(tolerance, value)`: `converged_tolerance` of the AD derivatives
    `parameter_gradient(scene, params, wrt, output, t_end, mode=mode, ...)` of a scalar
    `output` (as in `output_function`), starting from `control` (the scene's default
    updated by a mapping, or a `StepControl`), and the output's value at the chosen
    tolerance. `options` go to `parameter_gradient` (`ts`, `n_save`, ...)."""
    from ..batch import step_control
    from ._derivatives import gradient_at_tolerances

    values = {}
    # One compiled derivative program for every tolerance of the search (rtol and atol are
    # its data), not one per tolerance.
    gradient = gradient_at_tolerances(scene, params, wrt, output, t_end, mode=mode, **options)

    def evaluate(c):
        value, grad = gradient(c)
        values[c.rtol] = float(value)
        return {k: float(v) for k, v in grad.items()}

    found = converged_tolerance(evaluate, step_control(scene, control), fraction=fraction,
                                max_tightenings=max_tightenings, progress=progress)  # fmt: skip
    return found, values[found.control.rtol]
