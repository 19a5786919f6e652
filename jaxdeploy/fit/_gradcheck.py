"""A gradient check a user runs: the derivative of one scalar output of a scene by AD (forward
and reverse mode through the solver) against central differences over a sweep of steps.

Why a sweep and two kinds of differences. A difference quotient has a truncation error that
falls with the step h (O(h²)) and a noise that grows as it falls (the run's round-off and
tolerance over h); in between lies the range of steps where it is the derivative. Two kinds
are taken at every step (`central_differences`): *replayed* — every perturbed run steps over
the unperturbed run's accepted steps, the discrete map AD differentiates — and *rerun* — each
run re-adapts its steps, what a user perturbing the model sees (its noise is O(tol/h)). A
perturbed run that has another number of contact onsets than its partner (`Scene.events`'
counts, e.g. `impacts`) differences across a jump of the output: such steps are flagged and
left out of the verdict. A replayed pair is flagged too when a located event (the latch's
engagement, a contact onset: `event_steps`) fell in another step than in its partner: the
unperturbed run's steps end just past its events (`LocateEvents`), so a perturbation that
moves an event later puts it in the next step, where the model switches (the latch acts, v⁻ is
taken) in another place — a jump of the replayed map that grows relative to h as h shrinks,
not a derivative (deploy_array's lock time: replayed differences drifted from 0.7 % to 29 %
off AD between h = 1e-4 and 1e-6 while no impact count changed). Separations are not counted
(their located times carry no derivative and are not outputs). A perturbed run that fails
(a large step can make an explicit method unstable over the unperturbed run's steps once the
latch engages elsewhere) gives no difference at that step: it is reported (`failed_runs` in
`to_json`, crosses in the plot) and left out, and the sweep goes on.

Verdict. The converged difference is the mean of the pair of consecutive unflagged steps of
one kind that agree best, over both kinds (their relative spread and their kind are
reported); AD agrees when it is within `tolerance` (relative) of it. Forward and reverse mode
are reported side by side. The agreeing range is the set of steps whose difference lies
within `tolerance` of AD. Both kinds count because with located events neither is always the
better one: a replayed run keeps the unperturbed run's step ends, which were placed just past
its events, so a perturbation that moves an event leaves it inside a step (deploy_array's
lock time: replayed differences scatter by ~1 % where rerun ones settle).

Step tolerance. By default the check runs at the loosest rtol, from the caller's down, at
which the judged AD derivatives change by at most `derivative_change` (default a tenth of
`tolerance`) at rtol/10 (`derivative_tolerance`), and every difference run at that rtol too:
a derivative through an adaptive run needs a tighter tolerance than its value (deploy_array's
lock time: AD at Tsit5 rtol 1e-6 is 0.8 % off in the clearance, 0.4 % in the restitution,
from AD at 1e-8, while the lock time moved by 4e-7 s), and a check at a tolerance where only
the value has converged judges the tolerance, not the derivative. The rtol used and the
comparisons that chose it are reported (`GradientCheck.step_tolerance`).

The usual check of a hand-written gradient (e.g. `torch.autograd.gradcheck`, JAX's
`jax.test_util.check_grads`) compares at one step; over a solver with events one step can sit
across an impact or below the tolerance noise, hence the sweep (Griewank & Walther,
*Evaluating Derivatives*, 2nd ed., SIAM 2008, §1 on difference quotients' step choice).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from functools import partial

# Top level: jaxdeploy.fit (this package, which _derivative_tolerance's own imports load)
# imports this module, so a function-level import here would hide that cycle.
from ._derivative_tolerance import derivative_tolerance

DEFAULT_STEPS = (1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 1e-7)
DEFAULT_TOLERANCE = 1e-2
KINDS = ("replay", "rerun")


def step_label(h: float) -> str:
    return f"{h:.0e}"


def count_names(outputs: Mapping) -> list[str]:
    """The outputs that count events (`impacts`, `{owner}_impacts`): a change of one between
    two runs is a jump of the discrete map."""
    return sorted(k for k in outputs if k == "impacts" or k.endswith("_impacts"))


def event_time_names(outputs: Mapping) -> list[str]:
    """The outputs that are located event times: `*_time` scalars (`lock_time`,
    `{owner}_first_onset_time`) and `*onset_times` arrays (every episode's onset)."""
    return sorted(k for k in outputs if k == "onset_times" or k.endswith(("_time", "_onset_times")))


def event_steps(outputs: Mapping, step_times):
    """The index of the step (in `step_times`, the replayed run's step ends, padded with
    +inf) in which each located event of `outputs` fell, −1 for an event not reached. Two
    replayed runs whose indices differ have an event on different sides of a step end: the
    step that holds it switches the model (the latch engages, v⁻ is taken) in another place,
    so their difference is not that of one discrete map."""
    import jax.numpy as jnp

    names = event_time_names(outputs)
    if not names:
        return jnp.zeros((0,))
    times = jnp.concatenate([jnp.ravel(outputs[k]) for k in names])
    index = jnp.searchsorted(jnp.asarray(step_times), times)
    return jnp.where(jnp.isfinite(times), index, -1).astype(float)


@dataclass
class ParameterCheck:
    """One parameter's check (`GradientCheck.params`)."""

    value: float
    ad: float
    ad_reverse: float | None
    fd: dict = field(default_factory=dict)  # {kind: {step label: difference}}
    switched: dict = field(default_factory=dict)  # {kind: [step labels]}
    # {kind: {step label: status}}: steps whose perturbed runs failed (difference NaN)
    failed: dict = field(default_factory=dict)
    absolute_steps: dict = field(default_factory=dict)  # {step label: h in the unit}
    converged: float = math.nan
    spread: float = math.nan
    converged_kind: str = ""
    tolerance: float = DEFAULT_TOLERANCE

    @property
    def relative_error(self) -> float:
        """|AD − converged difference| / |converged difference|."""
        return abs(self.ad - self.converged) / max(abs(self.converged), 1e-300)

    @property
    def agree(self) -> bool:
        ok = math.isfinite(self.converged) and self.spread <= self.tolerance
        return bool(ok and self.relative_error <= self.tolerance)

    def agreeing_steps(self, kind: str) -> list[str]:
        """The unflagged steps of `kind` whose difference is within the tolerance of AD."""
        scale = max(abs(self.ad), 1e-300)
        return [
            h
            for h, v in self.fd.get(kind, {}).items()
            if h not in self.switched.get(kind, [])
            and math.isfinite(v)
            and abs(v - self.ad) <= self.tolerance * scale
        ]

    def to_json(self) -> dict:
        return {
            "value": self.value,
            "ad": self.ad,
            "ad_reverse": self.ad_reverse,
            "fd": self.fd["replay"],
            "fd_rerun": self.fd.get("rerun", {}),
            "switched": self.switched,
            "failed_runs": self.failed,
            "absolute_steps": self.absolute_steps,
            "converged_fd": self.converged,
            "converged_spread": self.spread,
            "converged_kind": self.converged_kind,
            "relative_error": self.relative_error,
            "agreeing_steps": {kind: self.agreeing_steps(kind) for kind in self.fd},
            "agree": self.agree,
        }


@dataclass
class GradientCheck:
    """What `gradient_check` found: `params` `{name: ParameterCheck}`, the `output`'s value,
    the relative `steps` swept and the `tolerance`."""

    scene: str
    output: str
    value: float
    params: dict
    steps: tuple
    tolerance: float
    # The step tolerance the check ran at and how it was chosen (`DerivativeTolerance`), or
    # None when the caller's was taken unchecked.
    step_tolerance: object = None

    @property
    def verdict(self) -> str:
        return "agree" if all(p.agree for p in self.params.values()) else "disagree"

    def to_json(self) -> dict:
        return {
            "scene": self.scene,
            "output": self.output,
            "value": self.value,
            "steps": [step_label(h) for h in self.steps],
            "tolerance": self.tolerance,
            "step_tolerance": (
                self.step_tolerance.to_json() if self.step_tolerance is not None else None
            ),
            "verdict": self.verdict,
            "params": {name: p.to_json() for name, p in self.params.items()},
        }

    def table(self) -> str:
        """A plain-text summary, one line per parameter."""
        lines = [f"d {self.output} / d θ  ({self.scene}; {self.output} = {self.value:.10g})"]
        if self.step_tolerance is not None:
            lines.append(self.step_tolerance.summary())
        for name, p in self.params.items():
            reverse = "" if p.ad_reverse is None else f"  reverse {p.ad_reverse:.8g}"
            spans = []
            for kind in p.fd:
                steps = p.agreeing_steps(kind)
                spans.append(f"{kind} " + (f"{steps[0]}…{steps[-1]}" if steps else "none"))
            for kind, steps in p.failed.items():
                spans.append(f"{kind} runs failed at {', '.join(steps)}")
            lines.append(
                f"  {name}: AD {p.ad:.8g}{reverse}  FD {p.converged:.8g} ({p.converged_kind}, "
                f"spread {p.spread:.1e})  rel. error {p.relative_error:.1e}  agreeing steps "
                + ", ".join(spans)
                + ("  agree" if p.agree else "  DISAGREE")
            )
        lines.append(f"verdict: {self.verdict}")
        return "\n".join(lines)

    def plot(self, path: str) -> None:
        """|FD − AD|/|AD| against the relative step, per parameter, replayed and rerun;
        flagged steps (an impact count changed) as open markers, steps whose perturbed runs
        failed as crosses at the top."""
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        from ..io import atomic_savefig

        fig, ax = plt.subplots(figsize=(6.5, 4.2))
        for k, (name, p) in enumerate(self.params.items()):
            color = f"C{k}"
            scale = max(abs(p.ad), 1e-300)
            for kind, style in zip(KINDS, ("-", ":"), strict=True):
                if kind not in p.fd:
                    continue
                hs = [float(h) for h in p.fd[kind]]
                err = [max(abs(v - p.ad) / scale, 1e-17) for v in p.fd[kind].values()]
                ax.loglog(hs, err, style, color=color, label=f"{name} ({kind})")
                failed = [hs[i] for i, h in enumerate(p.fd[kind]) if h in p.failed.get(kind, {})]
                if failed:  # no difference: marked at the top of the axes
                    ax.plot(failed, [1.0] * len(failed), "x", color=color,
                            transform=ax.get_xaxis_transform())  # fmt: skip
                flagged = [i for i, h in enumerate(p.fd[kind]) if h in p.switched.get(kind, [])]
                ax.loglog(
                    [hs[i] for i in flagged],
                    [err[i] for i in flagged],
                    "o",
                    mfc="none",
                    color=color,
                )
        ax.axhline(self.tolerance, color="grey", lw=0.8, ls="--", label="tolerance")
        ax.set_xlabel("relative step h/|θ| (absolute for θ = 0: × range)")
        ax.set_ylabel("|FD − AD| / |AD|")
        ax.set_title(f"{self.scene}: d {self.output}/dθ — {self.verdict}")
        ax.legend(fontsize=7)
        fig.tight_layout()
        atomic_savefig(fig, path, dpi=120)
        plt.close(fig)


def gradient_check(
    scene,
    params: Mapping,
    wrt: Sequence[str],
    output: str | Callable,
    t_end: float,
    *,
    steps: Sequence[float] = DEFAULT_STEPS,
    tolerance: float = DEFAULT_TOLERANCE,
    modes: Sequence[str] = ("forward", "reverse"),
    kinds: Sequence[str] = KINDS,
    abs_step=None,
    ts=None,
    n_save: int = 2,
    control: Mapping | None = None,
    check_step_tolerance: bool = True,
    derivative_change: float | None = None,
    progress: Callable | None = None,
) -> GradientCheck:
    """Check d output/dθ for the parameters `wrt` of `scene` at `params` (module docstring).

    **Arguments:**
    - `output`: a name of `Scene.outputs` (a scalar event output such as deploy_array's
      `lock_time` or slider_crank's `first_onset_time`) or a function of the outputs
      returning a scalar.
    - `steps`: relative steps h/|θ| of the sweep (a parameter at 0 takes `abs_step`, default
      the step times its range's width: `central_differences`).
    - `tolerance`: relative agreement required of AD with the converged difference.
    - `modes`: AD modes to evaluate (the first is the one judged; the others are reported).
    - `kinds`: `"replay"` (the verdict's) and/or `"rerun"`.
    - `ts`, `n_save`, `control`: the runs' saved times and step control (as `simulate`).
    - `check_step_tolerance`: (default) AD and every difference run at the loosest rtol, from
      `control`'s down, at which the judged mode's derivatives change by at most
      `derivative_change` (default `tolerance`/10) at rtol/10 (`derivative_tolerance`): at
      a tolerance where only the value has converged, AD is off the derivative by more than
      the check judges (deploy_array's lock time, rtol 1e-6: 0.8 % in the clearance). False:
      `control` as given, unchecked.
    - `progress(message)`: called before each stage (a command prints it).

    **Returns:** `GradientCheck` (`.verdict`, `.to_json()`, `.table()`, `.plot(path)`).
    """
    import numpy as np

    from ._derivatives import MODES, central_differences, difference_steps, parameter_gradient

    say = progress or (lambda _message: None)
    for mode in modes:
        if mode not in MODES:
            raise ValueError(f"mode = {mode!r} is invalid; valid: {', '.join(MODES)}")
    for kind in kinds:
        if kind not in KINDS:
            raise ValueError(f"kind = {kind!r} is invalid; valid: {', '.join(KINDS)}")
    if "replay" not in kinds:
        raise ValueError("kinds must include 'replay' (the verdict's differences)")
    if not steps or any(not (0 < h < 1) for h in steps):
        raise ValueError(f"steps = {list(steps)!r} are invalid: each must be in (0, 1)")
    if not 0 < tolerance < 1:
        raise ValueError(f"tolerance = {tolerance!r} is invalid: it must be in (0, 1)")
    if derivative_change is None:
        derivative_change = tolerance / 10.0
    base = scene.resolve_params(params)
    name = output if isinstance(output, str) else getattr(output, "__name__", "output")
    scalar = _scalar_output(output)
    options = dict(ts=ts, n_save=n_save, control=control)

    ad, found = {}, None
    if check_step_tolerance:
        found, value = derivative_tolerance(
            scene, base, wrt, scalar, t_end, mode=modes[0], fraction=derivative_change,
            progress=lambda message: say(f"AD, {modes[0]} mode: {message}"), **options,
        )  # fmt: skip
        ad[modes[0]] = found.derivatives
        options["control"] = found.control
    for mode in modes:
        if mode in ad:
            continue
        say(f"AD, {mode} mode")
        value, grad = parameter_gradient(scene, base, wrt, scalar, t_end, mode=mode, **options)
        ad[mode] = {k: float(v) for k, v in grad.items()}
    value = float(value)
    if not math.isfinite(value):
        raise ValueError(
            f"{name} = {value} at these parameters (not reached by t_end = {t_end} s?)"
        )

    def with_counts(outputs, step_times=None):
        """The output, the event counts and (replayed runs) the steps holding each event:
        a difference of the counts or steps that is not 0 flags the step h."""
        import jax.numpy as jnp

        values = jnp.stack([scalar(outputs), *(outputs[k] for k in count_names(outputs))])
        if step_times is None:
            return values
        return jnp.concatenate([values, event_steps(outputs, step_times)])

    checks = {
        k: ParameterCheck(
            value=float(base[k]),
            ad=ad[modes[0]][k],
            ad_reverse=ad["reverse"][k] if "reverse" in ad and modes[0] != "reverse" else None,
            tolerance=tolerance,
        )
        for k in wrt
    }
    from ..batch import step_control
    from ._derivatives import replayed_step_times

    replayed = {}
    if step_control(scene, options["control"]).adaptive:
        say("the unperturbed run's steps (the replayed differences step over them)")
        replayed = {"replay_steps": replayed_step_times(scene, base, t_end, **options)}
    else:
        kinds = ("replay",)  # fixed steps: rerunning is replaying
    for h in steps:
        label = step_label(h)
        widths = difference_steps(scene, base, wrt, h, abs_step)
        for k in wrt:
            checks[k].absolute_steps[label] = widths[k]
        for kind in kinds:
            say(f"central differences, relative step {label}, {kind}")
            extra = replayed if kind == "replay" else {}
            flags = with_counts
            if kind == "replay" and replayed:
                flags = partial(with_counts, step_times=replayed["replay_steps"])
            failed = {}
            d = central_differences(
                scene, base, wrt, flags, t_end, h, replay=False, abs_step=abs_step,
                failed=failed, **options, **extra,
            )  # fmt: skip
            for k, status in failed.items():
                say(f"  {k}: a perturbed run failed ({status}); no difference at step {label}")
                checks[k].failed.setdefault(kind, {})[label] = status
            for k in wrt:
                row = np.asarray(d[k])
                checks[k].fd.setdefault(kind, {})[label] = float(row[0])
                if k not in failed and np.any(row[1:] != 0):
                    checks[k].switched.setdefault(kind, []).append(label)
    for check in checks.values():
        check.converged, check.spread, check.converged_kind = _converged(check)
    return GradientCheck(scene.name, name, value, checks, tuple(steps), tolerance, found)


def _scalar_output(output):
    """`output` as a function of the outputs: a callable as it is, a name `NAME` (a scalar
    output) or `NAME[k]` (entry k of a per-episode output, e.g. `panel1_peak_forces[0]`)."""
    import re

    if callable(output):
        return output
    indexed = re.fullmatch(r"(\w+)\[(\d+)\]", output)
    name, index = (indexed[1], int(indexed[2])) if indexed else (output, None)

    def named(outputs):
        if name not in outputs:
            raise ValueError(
                f"output {name!r} is not an output of the scene; valid: "
                + ", ".join(sorted(outputs))
            )
        value = outputs[name]
        if index is None:
            return value
        if not (getattr(value, "ndim", 0) == 1 and index < value.shape[0]):
            raise ValueError(f"output {output!r}: {name} has shape {value.shape}")
        return value[index]

    return named


def _converged(check: ParameterCheck) -> tuple[float, float, str]:
    """`(value, spread, kind)`: the mean of the two consecutive unflagged differences of one
    kind that agree best over both kinds, their relative difference, and that kind (NaN, inf,
    "" when no such pair)."""
    best = (math.nan, math.inf, "")
    for kind, values in check.fd.items():
        flagged = check.switched.get(kind, [])
        order = list(values)
        for a, b in zip(order, order[1:], strict=False):
            if a in flagged or b in flagged:
                continue
            va, vb = values[a], values[b]
            spread = abs(va - vb) / max(abs(va), abs(vb), 1e-300)
            if spread < best[1]:
                best = (0.5 * (va + vb), spread, kind)
    return best
