"""How long a run will integrate, measured by the run itself over a growing first part of its
horizon (the probe of `jaxdeploy simulate`).

A table of each scene's rate per simulated second (`simulate.INTEGRATE_S_PER_SIMULATED_S`)
sees a mistyped --t-end but not what a parameter or a tolerance does to the step size: a
clearance of 1e-10 m at rtol 1e-12 takes millions of steps where the default takes 2500. No
closed form sees it either: the step size of an adaptive run is set by the tolerance and the
contact's time scale together (the same 1e-10 m clearance runs 9248 steps at atol 1e-12 and
tens of thousands more at atol 1e-15, with the same contact stiffness and masses). So the
run measures itself: its own compiled program (the end time is data, so the probe compiles
nothing the run does not) integrates [0, f t_end] for growing f, and the whole horizon is
extrapolated from the steps the last part of that prefix took per simulated second and the
wall time each step took.

It is an extrapolation, not a bound: a run whose stiff part starts after the probe's prefix
(a contact that begins late) is estimated from its quiet start. The estimate is of the order
of the run's time: refusing a run of hours, showing progress on a run of minutes.

Keep this module light (no JAX at import): `estimate` takes the run as a function.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

# The first prefix, as a part of the horizon: small enough that a run of hours probes for
# seconds (a run of 10 hours: 36 s), large enough that a short run needs two prefixes (each
# call has a fixed cost: its saved states).
FIRST_PART = 1e-3
# The probe covers at least this part of the horizon before it calls a run short: the first
# contact of slider_crank (journal centred, 0.5 mm clearance) comes after 0.1 % of its
# horizon, and a prefix without a contact says nothing about the contacts' steps.
SHORT_AFTER_PART = 1e-2
# ... and at most this part.
LAST_PART = 0.1
# A prefix that ran this long [s] measures the run's rate well enough (the fixed cost of a
# call, about 0.03 s for slider_crank's 2001 saved states, is then a small part of it); the
# next prefix is sized to take about this long, at most 10x the last.
BUDGET_S = 2.0
# The probe stops after this long [s] whatever it found.
CAP_S = 30.0


@dataclasses.dataclass(frozen=True)
class Prefix:
    """The run over [0, `t`] [s]: `seconds` of wall time, `steps` (accepted and rejected),
    `ok` whether it finished."""

    t: float
    seconds: float
    steps: int
    ok: bool = True


@dataclasses.dataclass(frozen=True)
class RunLength:
    """The estimated integration time `seconds` of a run to `t_end`, extrapolated from the
    `prefixes` it ran."""

    seconds: float
    t_end: float
    prefixes: tuple[Prefix, ...]

    @property
    def steps_per_s(self) -> float:
        """Steps per simulated second over the last part of the probe (after the previous
        prefix: a start's small first steps are not extrapolated)."""
        return _steps_per_s(self.prefixes)

    def account(self) -> str:
        """Where the estimate comes from, in words."""
        last = self.prefixes[-1]
        return (
            f"its first {last.t / self.t_end:.2g} of the horizon ({last.t:.3g} s) took "
            f"{last.steps} steps in {last.seconds:.3g} s, {self.steps_per_s:.3g} steps per "
            "simulated second at its end"
        )


def _steps_per_s(prefixes) -> float:
    last = prefixes[-1]
    before = prefixes[-2] if len(prefixes) > 1 else Prefix(0.0, 0.0, 0)
    return (last.steps - before.steps) / (last.t - before.t)


def extrapolate(prefixes: tuple[Prefix, ...], t_end: float) -> float:
    """Wall seconds of the run to `t_end`: the last prefix's time plus the rest of the
    horizon at the last part's steps per simulated second, each step as long as the last
    prefix's steps were on average (`T = w_k + (w_k/n_k) · r (t_end − t_k)`, r the steps per
    simulated second between the last two prefixes)."""
    last = prefixes[-1]
    per_step = last.seconds / max(last.steps, 1)
    return last.seconds + per_step * max(_steps_per_s(prefixes), 0.0) * (t_end - last.t)


def estimate(
    run_prefix: Callable[[float], Prefix], t_end: float, short_s: float
) -> RunLength | None:
    """The run length of a run to `t_end`, probed by `run_prefix(t)` (the run over [0, t]).
    Prefixes grow from `FIRST_PART` of the horizon, each sized to take about `BUDGET_S`
    (×2 to ×10 the last), until one reached `LAST_PART`, or the probe spent `CAP_S`, or
    one took `BUDGET_S`/2 with its density `settled`, or one covered `SHORT_AFTER_PART`
    with an estimate ≤ `short_s` (a short run is not probed further). None when a prefix
    failed (the run will fail and say why)."""
    part, prefixes, spent = FIRST_PART, (), 0.0
    while True:
        prefix = run_prefix(part * t_end)
        if not prefix.ok:
            return None
        prefixes, spent = (*prefixes, prefix), spent + prefix.seconds
        seconds = extrapolate(prefixes, t_end)
        if (
            part >= LAST_PART
            or spent >= CAP_S
            or (prefix.seconds >= BUDGET_S / 2 and settled(prefixes))
            or (part >= SHORT_AFTER_PART and seconds <= short_s)
        ):
            return RunLength(seconds, t_end, prefixes)
        growth = BUDGET_S / prefix.seconds if prefix.seconds > 0 else 10.0
        part = min(LAST_PART, part * min(max(growth, 2.0), 10.0))


def settled(prefixes: tuple[Prefix, ...]) -> bool:
    """Whether the steps per simulated second of the last part (between the last two
    prefixes) are at least half those of the part before it (the first prefix: from the
    start): a density still falling faster is the run's start (many small steps of an
    initial contact at a tight tolerance: slider_crank with a 1e-10 m clearance at rtol
    1e-12 took 5624 steps over its first 2.4e-5 s and 728 over the next 2.2e-4 s), not what
    the rest of the run will do."""
    if len(prefixes) < 2:
        return False
    return _steps_per_s(prefixes) >= 0.5 * _steps_per_s(prefixes[:-1])
